"""The simulated drop test's figures stay where they were recorded: a change to how the simulated
rig steps (its read as one compiled call, the loop's per-cycle code) may move floats in their last
digits, never a drop's period, peaks or damping ratio by more than 0.1 %.

The figures were recorded from the plant and the edge search stepped in Python, one call per
sub-step (10 s record, the seed parameters, the default config on simulated time). The peaks are
encoder counts (360/4096 deg each), so 0.1 % of them is no count at all.
"""

from __future__ import annotations

import copy

import pytest

from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.engine.resolve import default_config
from sashil.lab._drop_test import run_drop_test

#: law, current [A] -> (period [s], first peaks [deg], first troughs [deg], damping ratio)
RECORDED = {
    ("passive", 0.0): (
        0.5995,
        [4.39453125, 3.33984375, 2.548828125, 1.9335937499999998],
        [3.8671874999999996, 2.900390625, 2.197265625, 1.58203125],
        0.04330734206755561,
    ),
    ("passive", 1.0): (
        0.5878333333333333,
        [3.427734375, 1.494140625, 0.52734375],
        [2.28515625, 0.87890625],
        0.1310149213530214,
    ),
    ("skyhook", 1.0): (
        0.59825,
        [3.69140625, 2.021484375, 1.142578125, 0.615234375],
        [2.724609375, 1.494140625, 0.87890625, 0.52734375],
        0.09291837646748433,
    ),
}


@pytest.mark.parametrize("law, current", sorted(RECORDED), ids=lambda v: str(v))
def test_a_simulated_drop_keeps_its_recorded_period_peaks_and_damping(law, current):
    config = copy.deepcopy(default_config())
    config["controller"]["law"] = law
    controller = None
    if law == "skyhook":
        config["controller"]["c_sky"] = 2.0
        controller = make_controller(law, StageParts.read(config))
    metrics = run_drop_test(config, -5.0, current, 10.0, controller=controller).metrics
    period, peaks, troughs, zeta = RECORDED[(law, current)]
    assert metrics.period_s == pytest.approx(period, rel=1e-3)
    assert metrics.peaks_deg[: len(peaks)] == pytest.approx(peaks, rel=1e-3)
    assert metrics.troughs_deg[: len(troughs)] == pytest.approx(troughs, rel=1e-3)
    assert metrics.damping_ratio == pytest.approx(zeta, rel=1e-3)
