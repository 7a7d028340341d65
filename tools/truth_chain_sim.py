"""In-process torque-tracking conditions on the simulated rig (shared by tools/bench_truth_chain.py).

Each condition runs the controller stage against :class:`sashil.drivers.sim.SimulatedRig` on simulated
time (1 kHz), the command of cycle k acting over the next period, exactly as the loop runs it, and
records the controller's T*_k, T-hat_k and the plant's true damper torque at each sample
(seed 001 eq. 9 on the true state). Conditions: a drop from -5 deg, the road sine at 1.2 Hz, a chirp
0.5-5 Hz and sines at 1, 2, 3 Hz (the stepped sine's frequencies), road amplitude 1 deg.

Figures (after the settling time of each condition):

* tracking NRMSE = RMS(T_true,k+1 - T*_k) / RMS(T*_k) (the command of cycle k acts over the next period);
* the same RMS as a fraction of the mean torque authority |T(i_max) - T(0)| along the run;
* observer NRMSE = RMS(T_hat,k - T_true,k) / RMS(T_true,k).

Run on its own it prints those figures for the seed damper, the controller on its exact model:

    .venv/bin/python tools/truth_chain_sim.py [--quick]

``--quick``: every condition cut to 1 s (the chirp to 2.5 s), figures over its last 0.5 s (seconds; the
figures mean little).
"""

from __future__ import annotations

import argparse
import copy
import math
import random
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from sashil.config.parts import StageParts
from sashil.control.registry import make_controller
from sashil.drivers.interface import RigCommand
from sashil.drivers.sim import SimulatedRig
from sashil.engine.resolve import default_config
from sashil.lab._sweep import chirp_profile, sine_profile
from sashil.models.hysteresis import BoucWenParams
from sashil.models.plant import RigPlant

RATE_HZ = 1000.0
STALL_S = 0.034  # a host stall as seen on this shared machine over the link
ROAD_DEG = 1.0


@dataclass(frozen=True)
class Condition:
    name: str
    kind: str  # "drop" | "sine" | "chirp"
    f_hz: float = 0.0
    duration_s: float = 12.0
    keep_after_s: float = 3.0


CONDITIONS = (
    Condition("drop -5 deg", "drop", duration_s=5.0, keep_after_s=0.55),
    Condition("sine 1.2 Hz", "sine", 1.2, 15.0),
    Condition("chirp 0.5-5 Hz", "chirp", 0.0, 24.0, 2.0),
    Condition("sine 1 Hz", "sine", 1.0, 12.0),
    Condition("sine 2 Hz", "sine", 2.0, 10.0),
    Condition("sine 3 Hz", "sine", 3.0, 10.0),
)


def quick_conditions() -> tuple[Condition, ...]:
    """The conditions cut to 1 s (the chirp to 2.5 s: its sweep starts after 2 s), figures over the last
    0.5 s (``--quick``: the code path only)."""
    return tuple(
        replace(c, duration_s=2.5 if c.kind == "chirp" else 1.0, keep_after_s=2.0 if c.kind == "chirp" else 0.5)
        for c in CONDITIONS
    )


def damper_config(params: dict[str, float], counts_per_rev: int = 4096, **controller: Any) -> dict[str, Any]:
    """The default config with the model ``params`` (the controller's) and the encoder resolution."""
    config = default_config()
    config["model"] = {"name": "bouc-wen", "params": dict(params)}
    config["rig"]["encoder_counts_per_rev"] = int(counts_per_rev)
    config["controller"].update(controller)
    return config


def run_condition(
    config: dict[str, Any],
    true_params: dict[str, float],
    cond: Condition,
    law: str = "torque-tracking",
    command_road: bool = True,
    stalls_s: tuple[float, ...] = (),
) -> dict[str, np.ndarray]:
    """Run ``law`` (the config's model) on a plant with ``true_params``; returns recorded columns."""
    cfg = copy.deepcopy(config)
    rig_cfg = cfg["rig"]
    if cond.kind == "drop":
        road = None
    elif cond.kind == "sine":
        road = sine_profile(math.radians(ROAD_DEG), cond.f_hz, 1.0)
    else:
        road = chirp_profile(math.radians(ROAD_DEG), 0.5, 5.0, cond.duration_s - 2.0, 1.0)
    plant = RigPlant(
        BoucWenParams.from_mapping(true_params),
        coil_tau_s=rig_cfg["coil_tau_s"],
        current_max_a=rig_cfg["current_max_a"],
        max_step_s=rig_cfg["plant_max_step_s"],
    )
    rig = SimulatedRig(plant, counts_per_rev=rig_cfg["encoder_counts_per_rev"])
    ctl = make_controller(law, StageParts.read(cfg))
    rig.configure()
    rig.activate()
    dt_ns = int(round(1e9 / RATE_HZ))
    if cond.kind == "drop":
        rig.operator_hold(math.radians(-5.0), 0.5)
    count = int(round(cond.duration_s * RATE_HZ))
    out = {name: np.empty(count) for name in ("time_s", "cmd", "hat", "true", "lo", "hi", "current")}
    paused = set()
    for start in stalls_s:  # host stalls: no cycle for STALL_S (the rig runs on, the command held)
        first = round(start * RATE_HZ)
        paused.update(range(first, first + round(STALL_S * RATE_HZ)))
    last_ns = -dt_ns
    for k in range(count):
        t_ns = k * dt_ns
        if k in paused:
            for key in out:
                out[key][k] = math.nan
            out["time_s"][k] = k / RATE_HZ
            continue
        sample = rig.read(t_ns, t_ns - last_ns)
        ctl.held = plant.held
        out["true"][k] = plant.damper_torque()
        cmd = ctl.step(sample, t_ns, t_ns - last_ns)
        last_ns = t_ns
        speed = road(k / RATE_HZ)[1] if road is not None else None  # the road wheel follows the profile
        if command_road:
            cmd.road_speed_rad_s = speed  # the controller is told the road's speed, as the sweep plan does
        rig.write(RigCommand(cmd.current_a, speed), t_ns, dt_ns)
        out["time_s"][k] = k / RATE_HZ
        out["cmd"][k] = ctl.torque_cmd_nm
        out["hat"][k] = ctl.torque_hat_nm
        out["lo"][k], out["hi"][k] = ctl.band_lo_nm, ctl.band_hi_nm
        out["current"][k] = plant.state.current_a
    rig.close()
    return out


def figures(cols: dict[str, np.ndarray], keep_after_s: float) -> dict[str, float]:
    keep = cols["time_s"] >= keep_after_s
    target = cols["cmd"][keep][:-1]
    true_next = cols["true"][keep][1:]
    err = true_next - target
    ok = np.isfinite(err)
    target, hat_ok = target[ok], np.isfinite(cols["hat"][keep])
    rmse = float(np.sqrt(np.mean(err[ok] ** 2)))
    authority = float(np.nanmean(np.abs(cols["hi"][keep] - cols["lo"][keep])))
    hat, true = cols["hat"][keep][hat_ok], cols["true"][keep][hat_ok]
    return {
        "tracking": rmse / float(np.sqrt(np.mean(target**2))),
        "authority": rmse / authority,
        "observer": float(np.sqrt(np.mean((hat - true) ** 2)) / np.sqrt(np.mean(true**2))),
    }


#: a spread of dampers (not the seed alone): n 0.1-0.6, yield torque alpha(1 A)*z_u 0.2-2.5 N m, J 0.8-1.2:
#: the seed, four chosen to span the corners, six drawn at random (seed 7)
def _damper(J, k, c1, c2, n, delta, beta, gamma, yield0, yield1) -> dict[str, float]:
    z_u = (delta / (beta + gamma)) ** (1.0 / n)
    return {
        "J": J, "k": k, "c1": c1, "c2": c2,
        "alpha1": yield0 / z_u, "alpha2": (yield1 - yield0) / z_u,
        "beta": beta, "gamma": gamma, "delta": delta, "n": n,
    }  # fmt: skip


def _drawn_dampers(count: int, seed: int = 7) -> dict[str, dict[str, float]]:
    """``count`` dampers drawn at random over the spread (n 0.1-0.6, J 0.8-1.2, yield at 1 A 0.2-2.5 N m)."""
    rng = random.Random(seed)
    out = {}
    for index in range(count):
        n, J, yield1 = rng.uniform(0.1, 0.6), rng.uniform(0.8, 1.2), rng.uniform(0.2, 2.5)
        yield0 = yield1 * rng.uniform(0.15, 0.6)
        delta, ratio, gamma_fraction = rng.uniform(150, 900), rng.uniform(0.7, 0.9), rng.uniform(0.0, 0.3)
        gamma = delta / ratio * gamma_fraction
        beta = delta / ratio - gamma
        k, c1, c2 = rng.uniform(80, 130), rng.uniform(0.3, 1.0), rng.uniform(0.8, 2.5)
        out[f"V{index} n{n:.2f} J{J:.2f} y{yield1:.1f}"] = _damper(J, k, c1, c2, n, delta, beta, gamma, yield0, yield1)
    return out


DAMPERS = {
    "seed": _damper(1.0, 109.0, 0.7, 1.5, 0.099, 700.0, 873.0, 1.0, 0.1066, 0.2132),
    "A n0.3 J0.8": _damper(0.8, 95.0, 0.5, 2.0, 0.3, 300.0, 330.0, 30.0, 0.38, 1.2),
    "B n0.6 J1.2": _damper(1.2, 130.0, 0.9, 1.0, 0.6, 150.0, 160.0, 40.0, 0.62, 2.5),
    "C n0.45 J1.1": _damper(1.1, 80.0, 0.4, 1.2, 0.45, 500.0, 600.0, 50.0, 0.15, 0.6),
    "D n0.2 J0.9": _damper(0.9, 120.0, 0.6, 2.5, 0.2, 800.0, 900.0, 100.0, 0.49, 1.8),
}
DAMPERS.update(_drawn_dampers(6))


def mismatched(params: dict[str, float], fraction: float = 0.10) -> dict[str, float]:
    """Every Bouc-Wen parameter off by ``fraction``, signs alternating (J+, k-, c1+, ...): a stress model."""
    keys = ("J", "k", "c1", "c2", "alpha1", "alpha2", "beta", "gamma", "delta", "n")
    return {key: params[key] * (1.0 + fraction if index % 2 == 0 else 1.0 - fraction) for index, key in enumerate(keys)}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="every condition cut to about 1 s (seconds)")
    args = parser.parse_args()
    true = DAMPERS["seed"]
    print("seed damper, torque tracking on the exact model, 4096 counts/rev [%]:")
    for cond in quick_conditions() if args.quick else CONDITIONS:
        row = figures(run_condition(damper_config(true), true, cond), cond.keep_after_s)
        print(
            f"  {cond.name:16s} tracking {100 * row['tracking']:6.1f}  of authority {100 * row['authority']:6.1f}  "
            f"observer {100 * row['observer']:6.1f}"
        )


if __name__ == "__main__":
    main()
