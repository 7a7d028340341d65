"""The receding-horizon preview law: each re-plan starts from the estimated state over the road a
finite preview shows; on simulated time it plans inline and hands the plan over one re-plan period
later, and on the real clock a planner process beside the loop makes the same plans."""

from __future__ import annotations

import math
import time
from pathlib import Path

import numpy as np
import pytest

from sashil.control.law_api import LawContext, LawState
from sashil.control.laws_preview import PreviewOptimal
from sashil.control.preview import commanded_road
from sashil.control.preview_horizon import HorizonPlan, HorizonPlanner, HorizonSpec, InlinePlanner
from sashil.errors import ConfigError
from sashil.models.hysteresis import BoucWenParams

SPEC = HorizonSpec(dt_s=1e-3, slot_cycles=5, slots=40, preview_cycles=100, delay_cycles=10, iterations=20)


def _planner(spec: HorizonSpec = SPEC) -> HorizonPlanner:
    return HorizonPlanner(BoucWenParams(), 0.01, 1.0, spec)


def _road(n: int = 400) -> np.ndarray:
    return np.sin(np.arange(n) * 2e-2) * 2.0


def test_the_road_of_each_slot_is_its_cycles_mean_within_the_preview_and_at_rest_past_it():
    planner = _planner(HorizonSpec(1e-3, 5, 6, preview_cycles=12, delay_cycles=5))
    ahead = np.arange(1.0, 31.0)  # 1, 2, ..., 30: only the first 12 are known
    slots = planner.road_slots(ahead)
    # slot 0: mean(1..5) = 3; slot 1: mean(6..10) = 8; slot 2: (11 + 12) / 5 of its cycles known; then rest
    assert slots.tolist() == pytest.approx([3.0, 8.0, 23.0 / 5.0, 0.0, 0.0, 0.0])
    assert _planner(HorizonSpec(1e-3, 5, 3, preview_cycles=0, delay_cycles=5)).road_slots(ahead).tolist() == [0.0] * 3


def test_a_re_plan_keeps_the_commands_in_force_until_it_arrives_stays_in_range_and_lowers_the_horizons_cost():
    planner = _planner()
    w = _road()
    first = planner.plan(0, (0.0, 0.0, 0.0, 0.0), w, at_once=True)
    state = (0.02, -0.3, 0.05, 0.4)
    before = planner._start(20).copy()
    planner.road_slots(w[20:])
    planner._x0[:] = state
    cost_before = planner._cost(before, planner._road.copy())[0]
    plan = planner.plan(20, state, w[20:])
    assert plan.start == 20
    fixed = SPEC.fixed_slots
    assert fixed == 2
    # the slots the loop runs while the plan is made are the first plan's commands from cycle 20 on
    assert plan.command_a[:fixed].tolist() == [first.command_at(20), first.command_at(25)]
    assert np.all(plan.command_a >= 0.0) and np.all(plan.command_a <= 1.0)
    planner.road_slots(w[20:])
    assert planner._cost(plan.command_a, planner._road.copy())[0] < cost_before


def test_a_plan_reads_the_command_of_each_cycle_from_its_slot_and_holds_its_ends():
    plan = HorizonPlan(start=100, slot_cycles=5, command_a=np.array([0.1, 0.2, 0.3]))
    assert [plan.command_at(k) for k in (99, 100, 104, 105, 114, 115, 500)] == [0.1, 0.1, 0.1, 0.2, 0.3, 0.3, 0.3]


def test_inline_a_plan_comes_into_force_exactly_one_delay_after_its_request():
    planner = _planner()
    w = _road()
    inline = InlinePlanner(planner)
    first = planner.plan(0, (0.0, 0.0, 0.0, 0.0), w, at_once=True)
    inline.start(first)
    inline.request(20, (0.01, 0.1, 0.0, 0.2), w[20:])
    assert [inline.latest(k) is first for k in (20, 25, 29)] == [True, True, True]
    second = inline.latest(30)
    assert second is not first and second is not None and second.start == 20
    # a request at the very cycle its predecessor is due starts from the predecessor
    inline.request(40, (0.0, 0.0, 0.0, 0.0), w[40:])
    inline.request(50, (0.0, 0.0, 0.0, 0.0), w[50:])
    assert planner.last is not None and planner.last.start == 50
    assert inline.latest(59).start == 40 and inline.latest(60).start == 50


def _context() -> LawContext:
    return LawContext(BoucWenParams(), 1.0, 1000.0, 0.01)


def _run_law(law: PreviewOptimal, cycles: int) -> list[float]:
    """The law's commands over ``cycles`` on a plant it steps itself (the plan's own model)."""
    road = commanded_road(lambda t: 2.0 * math.sin(7.0 * t), 1e-3, cycles * 1e-3, law.preview_cycles())
    law.plan_road(road)
    law.reset()
    s = LawState()
    out = []
    theta = v = 0.0
    for k in range(cycles):
        s.time_s = k * 1e-3
        s.theta_rad, s.body_dot_rad_s, s.current_a = theta, v, out[-1] if out else 0.0
        s.road_ahead_dot_rad_s = road.rate_rad_s[k : k + law.preview_cycles()]
        out.append(law.current(s))
        a = -109.0 * theta - (0.7 + 1.5 * out[-1]) * (v - road.rate_rad_s[k])
        v += 1e-3 * a
        theta += 1e-3 * (v - road.rate_rad_s[k])
    return out


def test_the_receding_law_reads_its_preview_and_gives_the_same_commands_on_every_run():
    law = PreviewOptimal(
        _context(), plan="receding", preview_s=0.2, horizon_s=0.2, replan_cycles=20, replan_iterations=5
    )
    assert law.plan == "receding" and law.preview_cycles() == 200
    once = _run_law(law, 120)
    again = _run_law(law, 120)
    assert once == again
    assert all(0.0 <= u <= 1.0 for u in once)
    assert once[:20] == [law._first.command_at(k) for k in range(20)]  # the first re-plan arrives at cycle 40
    assert PreviewOptimal(_context()).plan == "receding"  # the default: a rig is never its model
    assert PreviewOptimal(_context(), plan="open-loop").preview_cycles() == 0


def test_a_re_plan_period_that_is_not_whole_slots_is_refused_naming_the_key():
    with pytest.raises(ConfigError, match=r"controller\.replan_cycles: expected a multiple of controller\.slot_cycles"):
        PreviewOptimal(_context(), plan="receding", slot_cycles=5, replan_cycles=12)


def test_on_simulated_time_the_law_keeps_planning_inline():
    from sashil.runtime.planner import plan_beside_loop

    law = PreviewOptimal(_context(), plan="receding", preview_s=0.1, horizon_s=0.1, replan_iterations=2)
    law.plan_road(commanded_road(lambda t: 1.0, 1e-3, 0.1, law.preview_cycles()))
    assert plan_beside_loop(law, virtual=True) is None
    assert isinstance(law.planner, InlinePlanner)


@pytest.mark.e2e
def test_beside_the_loop_a_planner_process_makes_the_inline_plans_and_leaves_nothing_behind():
    from sashil.runtime.planner import PlannerProcess, plan_beside_loop

    law = PreviewOptimal(_context(), plan="receding", preview_s=0.1, horizon_s=0.2, replan_iterations=10)
    w_speed = lambda t: 2.0 * math.sin(7.0 * t)  # noqa: E731
    law.plan_road(commanded_road(w_speed, 1e-3, 1.0, law.preview_cycles()))
    reference = InlinePlanner(HorizonPlanner(BoucWenParams(), 0.01, 1.0, law._spec))
    reference.start(law._first)
    beside = plan_beside_loop(law, virtual=False)
    assert isinstance(beside, PlannerProcess) and law.planner is beside
    try:
        assert beside.wait_ready(120.0), "the planner process never became ready"
        ahead = commanded_road(w_speed, 1e-3, 1.0, 0).rate_rad_s[20:]
        state = (0.01, 0.2, 0.05, 0.3)
        in_force = beside.latest(20)  # nothing made yet: the first plan stays in force
        assert in_force is not None and in_force.start == 0
        assert in_force.command_a.tolist() == law._first.command_a.tolist()
        beside.request(20, state, ahead)
        reference.request(20, state, ahead)
        for _ in range(1200):  # up to a minute on a busy machine
            if beside.plans_made:
                break
            time.sleep(0.05)
        due = 20 + law._spec.delay_cycles
        made = beside.latest(due)
        expected = reference.latest(due)
        assert made is not None and expected is not None
        assert made.start == expected.start == 20
        assert made.command_a.tolist() == expected.command_a.tolist()
    finally:
        path = beside.shared.path
        beside.close()
    assert beside.process.returncode == 0
    assert not Path(path).exists()


def test_the_dahl_plant_of_the_benchmark_is_bouc_wen_with_n_1_beta_0_and_gamma_delta_rho():
    """Dahl's w' = ρ·(θ̇ − |θ̇|·w) (seed 001 eq. 20) is Bouc-Wen's z' = δ·θ̇ − γ·|θ̇|·z − β·θ̇·|z|
    (eq. 17 at n = 1, as sashil.models.hysteresis writes it) at β = 0, γ = δ = ρ; the benchmark's Dahl plant keeps the damper's yield torque α·z_u and
    its stiffness before yield α·δ."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tools"))
    from bench_preview import dahl_plant

    from sashil.models.dahl import dahl_w_advance
    from sashil.models.hysteresis import advance_z

    seed = BoucWenParams()
    plant = BoucWenParams(**dahl_plant({}))
    rho = plant.delta
    assert (plant.n, plant.beta, plant.gamma, plant.z_bound) == (1.0, 0.0, rho, 1.0)
    assert plant.alpha1 * plant.z_bound == pytest.approx(seed.alpha1 * seed.z_bound)
    assert plant.alpha1 * plant.delta == pytest.approx(seed.alpha1 * seed.delta)
    for w, step in ((0.0, 1e-4), (0.5, -3e-4), (-0.9, 2e-3), (0.99, 1e-2)):
        bouc_wen = advance_z(w, step, plant.beta, plant.gamma, plant.delta, plant.n, plant.z_bound)
        # advance_z integrates by Runge-Kutta in the travel, Dahl's is the exact solution
        assert bouc_wen == pytest.approx(dahl_w_advance(w, step, rho), rel=1e-5, abs=1e-9)


def test_a_preview_past_a_second_is_read_whole_and_its_model_stepped_every_two_cycles():
    law = PreviewOptimal(_context(), preview_s=2.5, horizon_s=3.5)
    assert law.plan == "receding" and law.preview_cycles() == 2500
    # 3.5 s of 2-cycle slots of 1 ms
    assert (law._spec.slot_cycles, law._spec.slots, law._spec.preview_cycles) == (2, 1750, 2500)
    with pytest.raises(ConfigError, match=r"controller\.preview_s"):
        PreviewOptimal(_context(), preview_s=4.5)
