"""The road option's syntax and ``sashil run``'s default road on a simulated rig (no numerics
imported: the command line's help and the config's resolution read these)."""

#: the excitation of ``sashil run`` on a simulated rig when no road is given (below resonance)
DEFAULT_SIM_ROAD = "sine:1.0"
#: what ``--road`` and ``run.road`` accept
SYNTAX = (
    "sine:F_HZ[:AMP_DEG], chirp:F0_HZ:F1_HZ:SECONDS[:AMP_DEG], iso8608:CLASS[:SPEED_M_S] (class A-H), "
    "bump:HEIGHT_DEG, FILE.csv (time_s, theta_road_rad) or none"
)
