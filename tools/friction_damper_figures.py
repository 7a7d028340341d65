#!/usr/bin/env python3
"""Friction damper of seed 000: F-D and F-V loops of the Table 1 harmonic test plan with the
Bouc-Wen friction model of Tables 2-3, the Coulomb/MSTV/Bouc-Wen comparison at 10 Hz, 1 mm
(cf. the seed's Fig. 13), and the seed's two-stage identification from synthetic loops.

    python tools/friction_damper_figures.py --out figures/friction_damper
    python tools/friction_damper_figures.py --quick    # one training loop, PNGs to a temporary folder
"""

from __future__ import annotations

import argparse
import tempfile
from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

from sashil.identify.friction import identify_two_stage, simulate_harmonic, table1_tests
from sashil.models.friction_damper import TABLE1, FrictionDamperParams
from sashil.stats import nrmse


def loops_figure(p: FrictionDamperParams, path: Path) -> None:
    fig, axes = plt.subplots(2, len(TABLE1), figsize=(4 * len(TABLE1), 7))
    for col, (f, amps) in enumerate(TABLE1.items()):
        for a in amps:
            _t, Y, Yd, _X, F = simulate_harmonic(p, "bouc-wen", f, a)
            axes[0, col].plot(Y, F, lw=1, label=f"{a:g} mm")
            axes[1, col].plot(Yd, F, lw=1, label=f"{a:g} mm")
        axes[0, col].set_title(f"{f:g} Hz")
        axes[0, col].set_xlabel("displacement Y [mm]")
        axes[1, col].set_xlabel("velocity Y' [mm/s]")
        for row in (0, 1):
            axes[row, col].grid(alpha=0.3)
            axes[row, col].legend(fontsize=7)
    axes[0, 0].set_ylabel("force F [N]")
    axes[1, 0].set_ylabel("force F [N]")
    fig.suptitle("Bouc-Wen friction damper (seed 000 Tables 2-3), harmonic test plan of Table 1")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def comparison_figure(p: FrictionDamperParams, path: Path) -> None:
    fig, axes = plt.subplots(1, 2, figsize=(10, 4))
    for law in ("coulomb", "mstv", "bouc-wen"):
        _t, Y, Yd, _X, F = simulate_harmonic(p, law, 10.0, 1.0)
        axes[0].plot(Y, F, lw=1, label=law)
        axes[1].plot(Yd, F, lw=1, label=law)
    axes[0].set_xlabel("displacement Y [mm]")
    axes[1].set_xlabel("velocity Y' [mm/s]")
    for ax in axes:
        ax.set_ylabel("force F [N]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
    fig.suptitle("10 Hz, 1 mm: Coulomb (eq. 9), MSTV (eqs. 5-6), Bouc-Wen (eq. 8) friction")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument(
        "--out", help="folder for the PNGs (default figures/friction_damper; with --quick a temporary folder)"
    )
    parser.add_argument("--noise", type=float, default=0.5, help="RMS force noise [N] on the identification loops")
    parser.add_argument(
        "--quick", action="store_true", help="identify from one loop (10 Hz 1 mm), PNGs to a temporary folder"
    )
    args = parser.parse_args()
    if args.quick and args.out is None:
        with tempfile.TemporaryDirectory(prefix="friction_damper_figures-") as tmp:
            return figures(Path(tmp), args.noise, args.quick)
    return figures(Path(args.out or "figures/friction_damper"), args.noise, args.quick)


def figures(out: Path, noise: float, quick: bool) -> int:
    out.mkdir(parents=True, exist_ok=True)
    p = FrictionDamperParams()
    loops_figure(p, out / "bouc_wen_loops_table1.png")
    comparison_figure(p, out / "friction_laws_10hz_1mm.png")
    print(f"wrote {out}/bouc_wen_loops_table1.png, {out}/friction_laws_10hz_1mm.png")

    train = [(10.0, 1.0)] if quick else [(10.0, 1.0), (3.0, 1.0)]
    rng = np.random.default_rng(0)
    forces = [simulate_harmonic(p, "bouc-wen", f, a)[4] + rng.normal(0.0, noise, 401) for f, a in train]
    start = replace(p, k1=150.0, c1=1.0, c2=1.0, f_max=50.0, alpha=20.0, beta=20.0, gamma=0.0, n=2.0)
    fit = identify_two_stage(train, forces, start)
    print(
        f"two-stage identification from {len(train)} synthetic loops "
        f"({', '.join(f'{f:g} Hz {a:g} mm' for f, a in train)}; {noise:g} N RMS noise): wall {fit.wall_s:.1f} s"
    )
    for stage in fit.stages:
        print("  " + stage)
    q = fit.params
    for name in ("k1", "c1", "c2", "alpha", "beta", "gamma", "n"):
        print(
            f"  {name:>5} = {getattr(q, name):9.4g}   (Table 2/3: {getattr(p, name):g})   [A fixed at {p.A:g}]"
            if name == "alpha"
            else f"  {name:>5} = {getattr(q, name):9.4g}   (Table 2/3: {getattr(p, name):g})"
        )
    worst = 0.0
    print("force NRMSE of the identified model against the noiseless Table-1 loops:")
    for f, a in table1_tests():
        value = nrmse(simulate_harmonic(q, "bouc-wen", f, a)[4], simulate_harmonic(p, "bouc-wen", f, a)[4])
        worst = max(worst, value)
        print(f"  {f:5g} Hz {a:5g} mm: {100 * value:.3f} %")
    print(f"worst {100 * worst:.3f} % (acceptance <= 1 %)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
