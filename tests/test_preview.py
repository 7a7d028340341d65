"""The road ahead: a law that reads it gets the commanded road (before the run, and a window each
cycle), only under a plan that commands a road; ``preview-optimal`` plans on it and tracks."""

from __future__ import annotations

import itertools
import json
import math
import textwrap

import numpy as np
import pytest

from sashil.cli import main
from sashil.config.parts import StageParts
from sashil.control import LawContext, LawState
from sashil.control.law_registry import find_law
from sashil.control.laws_preview import PreviewOptimal
from sashil.control.plan_boucwen import BoucWenPlanModel
from sashil.control.preview import RoadWindow, commanded_road
from sashil.control.preview_plan import Horizon, Model, PlanModel, plan_current, simulate_plan
from sashil.control.registry import make_controller
from sashil.drivers import open_rig, rig_parts
from sashil.engine import assemble
from sashil.engine.resolve import apply_overrides, default_config
from sashil.models.hysteresis import rig_params
from sashil.roads.option import RoadParts, RoadStage, parse_road
from sashil.runtime.clock import default_clock
from sashil.runtime.runner import run_plan

AHEAD_LAW = """
from sashil.control import Law

class Ahead(Law):
    name = "ahead"
    reads_road_ahead = True

    def preview_cycles(self):
        return 3

    def torque(self, state):
        return 0.0
"""


def test_the_commanded_road_and_its_window_are_the_speeds_to_come_and_the_measured_angle_plus_their_motion():
    # speed(t) = t at dt = 0.5: speeds 0, 0.5, 1, 1.5, ... ; angles dt*sum of the speeds before: 0, 0, 0.25, 0.75, 1.5
    road = commanded_road(lambda t: t, 0.5, 1.5, 2)
    assert road.rate_rad_s.tolist() == [0.0, 0.5, 1.0, 1.5, 2.0, 2.5]
    assert road.theta_rad.tolist() == [0.0, 0.0, 0.25, 0.75, 1.5, 2.5]
    window, state = RoadWindow(road, 2), LawState()
    window.fill(state, 1, 10.0)  # cycle 1, the road encoder reads 10 rad (the motor's offset)
    assert state.road_ahead_dot_rad_s.tolist() == [0.5, 1.0]
    assert state.road_ahead_rad.tolist() == [10.25, 10.75]  # 10 + (0.25 - 0), 10 + (0.75 - 0)
    window.fill(state, 5, 3.0)  # the last sampled cycle: then the road at rest, its angle held
    assert state.road_ahead_dot_rad_s.tolist() == [2.5, 0.0]
    assert state.road_ahead_rad.tolist() == [4.25, 4.25]  # 3 + (2.5 + 0.5*2.5 - 2.5)


def test_a_runs_road_is_sampled_beyond_its_duration_so_a_run_that_outlasts_it_on_the_wall_clock_stays_planned():
    from sashil.control.preview import OVERRUN_FRACTION, run_road

    road = run_road(lambda t: t, 1e-3, 2.0, 0)
    exact = commanded_road(lambda t: t, 1e-3, 2.0 * (1.0 + OVERRUN_FRACTION), 0)
    assert road.rate_rad_s.size == exact.rate_rad_s.size == int(round(2.0 * (1.0 + OVERRUN_FRACTION) / 1e-3)) + 1
    assert np.array_equal(road.rate_rad_s, exact.rate_rad_s)
    # a run of no set duration: the unbounded span, no margin on it
    assert (
        run_road(lambda t: 0.0, 0.5, None, 0).rate_rad_s.size
        == commanded_road(lambda t: 0.0, 0.5, None, 0).rate_rad_s.size
    )


@pytest.mark.parametrize(
    ("argv", "where"),
    [
        (["run", "--road", "none", "--duration", "1"], "--road none: law"),
        (["compare", "--road", "none", "--duration", "3"], "compare.road none: law"),
        (["drop-test", "--duration", "1"], "controller.law"),
    ],
)
def test_a_law_reading_the_road_ahead_under_a_plan_with_no_road_is_refused_in_one_line(tmp_path, capsys, argv, where):
    path = tmp_path / "ahead.py"
    path.write_text(textwrap.dedent(AHEAD_LAW))
    out = tmp_path / "out"
    spec = f"{path}:Ahead"
    law = ["--controller", spec] if argv[0] != "drop-test" else ["--set", f"controller.law={spec}"]
    code = main([*argv, *law, "--out", str(out)])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and where in err and "reads the road ahead" in err, err
    assert not out.exists()


def test_sashil_laws_says_which_laws_read_the_road_ahead(capsys):
    assert main(["laws", "--json"]) == 0
    laws = {law["name"]: law for law in json.loads(capsys.readouterr().out)}
    assert laws["preview-optimal"]["reads_road_ahead"] is True
    assert laws["lqr-clipped"]["reads_road_ahead"] is False
    assert main(["laws"]) == 0
    text = capsys.readouterr().out
    assert "preview-optimal  (current; reads the road ahead" in text
    assert "skyhook  (torque; built-in" in text


RECORDER_LAW = """
from sashil.control import Law

class Recorder(Law):
    name = "recorder"
    reads_road_ahead = True
    seen = []

    def preview_cycles(self):
        return 4

    def torque(self, state):
        self.seen.append((state.road_ahead_dot_rad_s.tolist(), state.road_rad, state.road_ahead_rad.tolist()))
        return 0.0
"""


def test_a_run_on_a_road_gives_the_law_each_cycle_the_speeds_it_will_command(tmp_path):
    path = tmp_path / "recorder.py"
    path.write_text(textwrap.dedent(RECORDER_LAW))
    spec = f"{path}:Recorder"
    config = apply_overrides(default_config(), [f"controller.law={spec}"])
    controller = make_controller(None, StageParts.read(config))
    road, _ = parse_road("sine:2:1", RoadParts.read(config))
    stage = RoadStage(controller, road, 0.3)
    outcome = run_plan(
        assemble(config),
        open_rig(rig_parts(config)),
        stage,
        default_clock(assemble(config)),
        0.3,
        read_stream=True,
        realtime=False,
        say=lambda _: None,
    )
    assert outcome.exit_status == "ok"
    seen = [call for call in find_law(spec).cls.seen if call[0]]  # not the warm-up's call before the run
    commanded = np.asarray(outcome.stream["road_speed_cmd_rad_s"], dtype=float)[:-1]  # the last row: the safe state
    assert len(seen) == commanded.size
    for k in range(commanded.size - 4):
        rates, road_rad, angles = seen[k]
        # the window's first speed is the one this cycle commands, the next three the cycles after it
        assert rates == pytest.approx(commanded[k : k + 4].tolist(), abs=1e-12)
        # the angles: the estimated road angle now plus the commanded motion, 1 ms per speed
        assert angles == pytest.approx((road_rad + 1e-3 * np.cumsum(commanded[k : k + 4])).tolist(), abs=1e-12)


def _seed_context() -> LawContext:
    config = default_config()
    return LawContext(rig_params(config["model"]), float(config["rig"]["current_max_a"]), 1000.0)


def test_the_plan_of_a_road_at_rest_is_at_rest_and_any_plan_stays_in_the_coils_range():
    p = _seed_context().model
    model = PlanModel.of(p, hysteresis=True, coil_tau_s=0.01)
    assert model.f1 == pytest.approx(p.alpha1 * (p.delta / (p.beta + p.gamma)) ** (1.0 / p.n))
    assert model.rho == pytest.approx(1.0 - math.exp(-0.1))  # 1 ms steps of a 10 ms coil
    rest = plan_current(model, 1.0, np.zeros(500), 1e-3, Horizon(0.2, 0.05))
    assert np.all(rest.theta_rad == 0.0) and np.all(rest.accel_rad_s2 == 0.0)
    rng = np.random.default_rng(3)
    w = np.cumsum(rng.normal(0.0, 0.05, 3000))  # a rough road speed
    plan = plan_current(model, 1.0, w, 1e-3, Horizon(1.0, 0.3, 50))
    assert np.all(plan.command_a >= 0.0) and np.all(plan.command_a <= 1.0)
    # the plan is no worse than any constant current on the same road and model
    costs = [simulate_plan(model, np.full(w.size, i), w, 1e-3).rms_accel for i in np.linspace(0.0, 1.0, 11)]
    assert plan.rms_accel <= min(costs)


def _models() -> list[Model]:
    from dataclasses import replace

    p = _seed_context().model
    return [
        PlanModel.of(p, hysteresis=True, coil_tau_s=0.01),
        BoucWenPlanModel.of(p, coil_tau_s=0.01),
        BoucWenPlanModel.of(replace(p, n=1.0), coil_tau_s=0.01),  # z turns over 10⁻³ rad: a spring below
    ]


def _gradients(model: Model, n: int = 300) -> tuple[np.ndarray, np.ndarray]:
    """The adjoint's gradient of the mean of θ̈2² and its central finite differences, on a rough road."""
    rng = np.random.default_rng(5)
    w = np.cumsum(rng.normal(0.0, 0.05, n))
    u = rng.uniform(0.0, 1.0, n)
    m, x0 = model.vector(), np.array([0.001, -0.02, 0.05, 0.3])
    bufs = [np.empty(n) for _ in range(5)]
    grad = np.empty(n)
    model.forward(u, w, m, 1e-3, x0, *bufs)
    model.adjoint(u, w, m, 1e-3, *bufs[:4], 2.0 * bufs[4] / n, grad)
    numeric = np.empty(n)
    for k in range(n):
        step = np.zeros(n)
        step[k] = 1e-6
        up = model.forward(u + step, w, m, 1e-3, x0, *[np.empty(n) for _ in range(5)])
        down = model.forward(u - step, w, m, 1e-3, x0, *[np.empty(n) for _ in range(5)])
        numeric[k] = (up - down) / 2e-6
    return grad, numeric


def test_the_plans_gradient_is_the_cost_s_own_by_finite_differences():
    grad, numeric = _gradients(_models()[0])
    assert grad == pytest.approx(numeric, rel=2e-3, abs=1e-10)
    assert grad[-1] == 0.0  # the last command acts after the block's last step


@pytest.mark.parametrize("which", [1, 2], ids=["seed", "n 1"])
def test_the_bouc_wen_plans_gradient_is_the_flows_within_a_few_per_cent(which):
    # the Bouc-Wen step's derivatives are its exact flow's, not those of advance_z's Runge-Kutta
    # sub-steps, which differ where z crosses 0 (with n ≈ 0.1 |ζ|ⁿ is steep there)
    grad, numeric = _gradients(_models()[which])
    assert float(grad @ numeric) / float(np.linalg.norm(grad) * np.linalg.norm(numeric)) > 0.995
    assert float(np.linalg.norm(grad - numeric) / np.linalg.norm(numeric)) < 0.1


def test_the_bouc_wen_plan_model_steps_the_rigs_own_z_over_each_angle_increment():
    p = _seed_context().model
    model = BoucWenPlanModel.of(p)  # no coil lag: the command is the next step's current
    w = np.full(40, -0.5)  # the road turning back under a free arm: θ grows, z climbs to its bound
    plan = simulate_plan(model, np.full(40, 1.0), w, 1e-3)
    from sashil.models.hysteresis import BoucWenZ

    assert plan.z[1:].tolist() == pytest.approx(
        BoucWenZ.from_params(p).trajectory(plan.theta_rad[1:], plan.z[1]).tolist()
    )
    assert plan.z[-1] == pytest.approx(p.z_bound, rel=1e-4)
    # θ̈2 is eq. 13 with the torque of eq. 9 at the coil's current
    k = 20
    torque = p.torque(plan.z[k], plan.body_dot_rad_s[k] - w[k], plan.current_a[k])
    assert plan.accel_rad_s2[k] == pytest.approx((-p.k * plan.theta_rad[k] - torque) / p.J)


def test_preview_optimal_commands_the_plan_and_feeds_back_the_state_error_through_the_torques_slope():
    ctx = _seed_context()
    law = PreviewOptimal(ctx, plan="open-loop", feedback_gain=1.0, block_s=0.1, tail_s=0.0, plan_iterations=5)
    road = commanded_road(lambda t: 0.1 * math.sin(10.0 * t), 1e-3, 0.2, 0)
    law.plan_road(road)
    k = 50
    s = LawState()
    s.time_s, s.theta_dot_rad_s, s.z_hat = k * 1e-3, 0.3, 0.1
    s.theta_rad, s.body_dot_rad_s = law._theta[k], law._body[k]  # on the plan: its command
    assert law.current(s) == law._i[k]
    s.theta_rad += 0.001  # off the plan: k_theta times the error, over dT/di = alpha2*z + c2*theta_dot
    slope = ctx.model.alpha2 * 0.1 + ctx.model.c2 * 0.3
    assert law.current(s) == pytest.approx(min(1.0, max(0.0, law._i[k] - law.k_theta * 0.001 / slope)))
    s.time_s = 10.0  # past the plan: its last command
    assert law.current(s) == law._i[-1]


def test_the_share_of_the_bound_runs_from_the_best_passive_run_to_the_bound_on_one_scale():
    from sashil.lab.compare_metrics import LawResult
    from sashil.lab.compare_report import Scale, share_of_bound, shares_of_bound

    assert share_of_bound(2.0, 2.0, 1.5) == 0.0  # the best passive run itself
    assert share_of_bound(1.5, 2.0, 1.5) == 100.0  # the bound reached
    assert share_of_bound(1.75, 2.0, 1.5) == 50.0
    assert share_of_bound(1.4, 2.0, 1.5) == pytest.approx(120.0)  # beyond the bound: said, not hidden
    assert math.isnan(share_of_bound(1.0, 2.0, 2.5))  # a bound above the passive run gives no scale
    runs = [
        LawResult("passive 0 A", metrics={"rms_accel_rad_s2": 2.5}),
        LawResult("passive 1 A", metrics={"rms_accel_rad_s2": 2.0}),
        LawResult("law", metrics={"rms_accel_rad_s2": 1.8}),
    ]
    # the 0 % is the passive baseline the scale names (compare's best constant current), not a row's minimum
    scale = Scale("passive 1 A", 2.0, 1.6)
    assert shares_of_bound(runs, scale) == pytest.approx({"passive 0 A": -125.0, "passive 1 A": 0.0, "law": 50.0})


def test_the_bound_on_a_chain_adds_the_chains_floor_in_quadrature_so_a_law_at_the_bound_reads_100_percent():
    from sashil.lab.compare_report import share_of_bound
    from sashil.lab.hysteretic_bound import bound_on_chain

    # the model's passive run 2.0 and bound 1.0; a chain adding a floor of 1.0 in quadrature reads
    # the passive run as sqrt(5) and a law at the bound as sqrt(2)
    floor = 1.0
    passive, law = math.hypot(2.0, floor), math.hypot(1.0, floor)
    bound = bound_on_chain(1.0, passive, 2.0)
    assert bound == pytest.approx(law)
    assert share_of_bound(law, passive, bound) == pytest.approx(100.0)
    # on the model's own chain nothing changes; a chain that reads below the model takes its floor off
    assert bound_on_chain(1.0, 2.0, 2.0) == 1.0
    assert bound_on_chain(1.0, math.sqrt(3.5), 2.0) == pytest.approx(math.sqrt(0.5))
    assert math.isnan(bound_on_chain(1.0, 1.0, 2.0))  # no positive bound left: no scale
    assert math.isnan(bound_on_chain(1.0, math.nan, 2.0))


def test_the_models_passive_run_is_the_bounds_model_at_a_constant_current_and_stiffer_damping_lowers_it():
    from sashil.lab.hysteretic_bound import hysteretic_bound, model_passive

    config = default_config()
    config["road"]["period_s"] = 10.0
    road, _ = parse_road("iso8608:C", RoadParts.read(config))
    seed = _seed_context().model
    soft, hard = (model_passive(seed, i, 0.0, road, 4.0, 1.0) for i in (0.0, 1.0))
    # on this road the seed's passive runs: 1 A is the better (compare's sim runs: 3.99 and 2.39)
    assert hard < soft
    # the bound is the best plan of the same model: never above the best constant current
    assert hysteretic_bound(seed, 1.0, 0.0, road, 4.0, 1.0) <= min(soft, hard) * (1.0 + 1e-9)


def test_the_hysteretic_bound_without_hysteresis_or_coil_lag_is_the_envelopes_and_with_them_lies_lower():
    from dataclasses import replace

    from sashil.lab.hysteretic_bound import hysteretic_bound
    from sashil.lab.optimal_bound import optimal_bound

    config = default_config()
    config["road"]["period_s"] = 10.0
    road, _ = parse_road("iso8608:C", RoadParts.read(config))
    seed = _seed_context().model
    viscous = replace(seed, alpha1=0.0, alpha2=0.0)
    envelope = optimal_bound(viscous, 1.0, road, 4.0, 1.0).rms_accel_bound
    # the same problem: the damping c1 + c2*i of every millisecond (the command acting one step later)
    assert hysteretic_bound(viscous, 1.0, 0.0, road, 4.0, 1.0) == pytest.approx(envelope, rel=0.02)
    # the seed's hysteresis: a friction of (alpha1 + alpha2*i)*z_u gives the rig a harder hard end
    assert hysteretic_bound(seed, 1.0, 0.0, road, 4.0, 1.0) < optimal_bound(seed, 1.0, road, 4.0, 1.0).rms_accel_bound


def test_the_comfort_low_pass_is_its_own_transpose_so_the_filtered_costs_gradient_is_exact():
    from sashil.control.preview_plan import comfort_filter, lowpass

    sos = comfort_filter(20.0, 1e-3)
    rng = np.random.default_rng(7)
    x, y = rng.normal(size=400), rng.normal(size=400)
    assert float(y @ lowpass(x, sos)) == pytest.approx(float(x @ lowpass(y, sos)), rel=1e-9)
    assert comfort_filter(0.0, 1e-3) is None and comfort_filter(600.0, 1e-3) is None
    model = PlanModel.of(_seed_context().model, hysteresis=True, coil_tau_s=0.01)
    n = 300
    w = np.cumsum(rng.normal(0.0, 0.05, n))
    u = rng.uniform(0.0, 1.0, n)
    m, x0 = model.vector(), np.array([0.001, -0.02, 0.05, 0.3])

    def cost(commands):
        bufs = [np.empty(n) for _ in range(5)]
        model.forward(commands, w, m, 1e-3, x0, *bufs)
        filtered = lowpass(bufs[4], sos)
        return float(np.mean(filtered**2)), bufs

    _, bufs = cost(u)
    grad = np.empty(n)
    model.adjoint(u, w, m, 1e-3, *bufs[:4], (2.0 / n) * lowpass(lowpass(bufs[4], sos), sos), grad)
    for k in (0, 100, 250):
        step = np.zeros(n)
        step[k] = 1e-6
        numeric = (cost(u + step)[0] - cost(u - step)[0]) / 2e-6
        assert grad[k] == pytest.approx(numeric, rel=2e-3, abs=1e-10)


def test_the_re_planned_horizon_moves_on_by_whole_slots_and_takes_the_plans_next_slot_at_its_end():
    from sashil.control.preview_mpc import RecedingPlan

    model = PlanModel.of(_seed_context().model, hysteresis=True, coil_tau_s=0.01)
    plan = np.repeat([0.1, 0.2, 0.3, 0.4, 0.5], 2)  # five slots of two cycles: their means 0.1 .. 0.5
    receding = RecedingPlan(model, 1.0, plan, np.zeros(10), 1e-3, cycles=2, slots=3)
    assert receding.u.tolist() == pytest.approx([0.1, 0.2, 0.3]) and receding.h == 2e-3
    receding.u[:] = [0.9, 0.8, 0.7]  # as iterations left it
    receding.move_to(1, 0.01, -0.1, 0.05, 0.3)
    assert receding.u.tolist() == pytest.approx([0.8, 0.7, 0.4])  # shifted; slot 3's plan enters
    assert receding.x0.tolist() == [0.01, -0.1, 0.05, 0.3]
    assert receding.change() == pytest.approx(0.8 - 0.2)  # the horizon's first slot less the plan's
    receding.move_to(4, 0.0, 0.0, 0.0, 0.0)  # past the road: the plan's last command held
    assert receding.u.tolist() == pytest.approx([0.5, 0.5, 0.5])
    receding.restart()
    assert receding.u.tolist() == pytest.approx([0.1, 0.2, 0.3]) and receding.slot == 0


def test_each_re_planning_step_keeps_the_horizon_in_the_coils_range_and_never_raises_its_cost():
    from sashil.control.preview_mpc import RecedingPlan

    model = BoucWenPlanModel.of(_seed_context().model, coil_tau_s=0.01)
    rng = np.random.default_rng(11)
    w = np.cumsum(rng.normal(0.0, 0.05, 1000))
    receding = RecedingPlan(model, 1.0, np.full(1000, 0.5), w, 1e-3, cycles=5, slots=60)
    receding.move_to(0, 0.02, 0.3, 0.05, 0.5)  # off the plan: a state the plan did not expect

    def cost() -> float:
        bufs = [np.empty(60) for _ in range(5)]
        return model.forward(receding.u, receding.w, receding.m, receding.h, receding.x0, *bufs)

    costs = [cost()]
    for _ in range(30):
        receding.iterate()
        costs.append(cost())
        assert np.all(receding.u >= 0.0) and np.all(receding.u <= 1.0)
    assert all(b <= a for a, b in itertools.pairwise(costs))
    assert costs[-1] < costs[0]
