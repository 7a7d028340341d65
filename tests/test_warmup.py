"""The warm-up before the loop's first deadline: every numba kernel a cycle can call is compiled (or
loaded) for the signature the cycle calls it with, and the law is called once and left reset.

Kernel state is per process, so the checks of what a fresh process has compiled run in a
subprocess (a kernel this test process already called would pass whatever the warm-up did)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import pytest

from sashil.control.law_api import Law, LawState
from sashil.models import _jit
from sashil.runtime import warmup

pytestmark = pytest.mark.skipif(not _jit.JIT, reason="numba kernels are plain Python (SASHIL_NO_JIT)")

#: every module a loop cycle can reach whose kernels count (the simulated backend, the plant and
#: damper models, the estimators, observer, inverse and laws); a kernel defined in any of them must
#: be warmed
SCAN = textwrap.dedent(
    """
    import importlib, json, pkgutil
    import sashil.control, sashil.models
    from numba.core.registry import CPUDispatcher
    names = ["sashil.drivers.sim", "sashil.drivers.encoder_edges", "sashil.safety", "sashil.runtime.loop"]
    for package in (sashil.models, sashil.control):
        names += [package.__name__ + "." + info.name for info in pkgutil.iter_modules(package.__path__)]
    kernels = {}
    for name in names:
        module = importlib.import_module(name)
        for attr, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == name:
                kernels[name + "." + attr] = value
    """
)


def _run(code: str) -> dict:
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout.strip().splitlines()[-1])


def test_warm_up_compiles_every_kernel_a_cycle_can_call_in_a_fresh_process():
    result = _run(
        SCAN
        + textwrap.dedent(
            """
            before = {name: len(k.signatures) for name, k in kernels.items()}
            from sashil.runtime.warmup import warm_kernels
            warmed = warm_kernels()
            after = {name: [str(s) for s in k.signatures] for name, k in kernels.items()}
            print(json.dumps({"before": before, "warmed": warmed, "after": after}))
            """
        )
    )
    kernels = set(result["after"])
    # the scan finds the loop's kernels (the z-update, the plant's sub-step, the edge Kalman cycle)
    assert {
        "sashil.models.hysteresis.advance_z",
        "sashil.models.plant.rig_substep",
        "sashil.control.edge_kalman.edge_cycle",
    } <= kernels
    assert not any(result["before"].values())  # importing compiles nothing: the warm-up does it
    assert kernels <= set(result["warmed"])  # every kernel of those modules is registered for the warm-up
    for name, signatures in result["after"].items():
        assert signatures, f"{name} not compiled by the warm-up"
    assert result["after"]["sashil.control.edge_kalman.edge_cycle"] == [
        "(Array(float64, 1, 'C', False, aligned=True), Array(float64, 2, 'C', False, aligned=True), "
        "Array(float64, 2, 'C', False, aligned=True), " + ", ".join(["float64"] * 15) + ")"
    ]


def test_a_run_after_the_warm_up_compiles_no_other_signature():
    """The warm-up's signatures are those the cycle uses: a drop test under a law with edge events
    (the Kalman edge cycle), the plant and the observer adds none."""
    result = _run(
        SCAN
        + textwrap.dedent(
            """
            from sashil.runtime.warmup import warm_kernels
            warm_kernels()
            before = {name: [str(s) for s in k.signatures] for name, k in kernels.items()}
            from sashil.engine.resolve import default_config
            from sashil.config.parts import StageParts
            from sashil.control.registry import make_controller
            from sashil.lab._drop_test import run_drop_test
            config = default_config()
            config["controller"].update(law="skyhook", c_sky=2.0)
            assert config["controller"]["edge_timing"]
            record = run_drop_test(config, -5.0, 0.0, 0.3, controller=make_controller(None, StageParts.read(config)))
            after = {name: [str(s) for s in k.signatures] for name, k in kernels.items()}
            calls = {name: sum(k.stats.cache_hits.values()) + sum(k.stats.cache_misses.values()) for name, k in kernels.items()}
            print(json.dumps({"before": before, "after": after, "cycles": record.summary["timing"]["cycles"],
                              "edges": record.summary["timing"]["cycles"] and int((record.stream["arm_edge_dir"] != 0).sum())}))
            """
        )
    )
    assert result["cycles"] > 500 and result["edges"] > 0  # the arm moved: edge events reached the filter
    assert result["after"] == result["before"]


class Counting(Law):
    """A law that keeps state between cycles (its calls) and clears it on reset."""

    name = "counting"

    def __init__(self) -> None:
        super().__init__()
        self.calls = 0
        self.resets = 0
        self.seen: list[float] = []

    def torque(self, state: LawState) -> float:
        self.calls += 1
        self.seen.append(state.theta_dot_rad_s)
        return 1.0

    def reset(self) -> None:
        self.calls = 0
        self.resets += 1


class Failing(Counting):
    def torque(self, state: LawState) -> float:
        raise RuntimeError("no")


class Stage:
    def __init__(self, law: Law) -> None:
        self.law, self.state, self.direct = law, LawState(), False


def test_the_law_is_called_once_on_a_representative_state_and_left_reset():
    law = Counting()
    assert warmup.warm_up(type("Plan", (), {"controller": Stage(law)})()) is None
    assert law.seen == [warmup.REPRESENTATIVE_STATE["theta_dot_rad_s"]]  # called once, on the probe state
    assert law.calls == 0 and law.resets == 1  # and reset after: no state left for the run
    failing = Failing()
    assert warmup.warm_law(Stage(failing))  # what the law raises there is left to the run's first cycle
    assert failing.resets == 1
    assert not warmup.warm_law(None)


def test_a_kernel_to_compile_is_announced_before_it_compiles(monkeypatch):
    from numba import njit

    order: list[str] = []

    @njit
    def doubled(x: float) -> float:
        return 2.0 * x

    monkeypatch.setattr(_jit, "LOOP_KERNELS", {"test.doubled": (doubled, lambda: (1.0,))})
    monkeypatch.setattr(warmup, "LOOP_KERNELS", _jit.LOOP_KERNELS)
    monkeypatch.setattr(warmup, "_cached", lambda kernel: False)
    assert warmup.warm_kernels(lambda line: order.append(line)) == ["test.doubled"]
    assert len(order) == 1 and order[0].startswith("compiling 1 numba kernel(s) for the loop")
    assert [str(s) for s in doubled.signatures] == ["(float64,)"]
    order.clear()
    warmup.warm_kernels(lambda line: order.append(line))
    assert order == []  # compiled: nothing to announce
