"""An example law for sashil: skyhook that eases in over a ramp and ignores slow arm motion.

T* = r(t) * c_sky * theta2_dot when |theta2_dot| > dead_band, else 0, with r(t) rising linearly
from 0 to 1 over ``ramp_s`` seconds. It needs nothing from sashil but the public law API.
"""

from sashil.control import Law, Param


class SoftSkyhook(Law):
    """Skyhook with a soft start and a dead band on the arm's rate."""

    name = "soft-skyhook"
    c_sky = Param(1.0, unit="N m s/rad", low=0.0, doc="sky damping")
    ramp_s = Param(0.5, unit="s", low=0.0, doc="time to reach full sky damping")
    dead_band_rad_s = Param(0.0, unit="rad/s", low=0.0, doc="arm rates below this get no torque")

    def torque(self, state):
        rate = state.body_dot_rad_s
        if abs(rate) <= self.dead_band_rad_s:
            return 0.0
        ramp = 1.0 if self.ramp_s == 0.0 else min(1.0, state.time_s / self.ramp_s)
        return ramp * self.c_sky * rate
