"""The road option's syntax, and ``sashil run``'s default road on a simulated rig (the config's
own default, which its resolution applies); no numerics imported: the command line's help reads these."""

from sashil.config.sections import DEFAULT_SIM_ROAD

__all__ = ["DEFAULT_SIM_ROAD", "SYNTAX"]

#: what ``--road`` and ``run.road`` accept
SYNTAX = (
    "sine:F_HZ[:AMP_DEG], chirp:F0_HZ:F1_HZ:SECONDS[:AMP_DEG], iso8608:CLASS[:SPEED_M_S] (class A-H), "
    "bump:HEIGHT_DEG, FILE.csv (time_s, theta_road_rad) or none"
)
