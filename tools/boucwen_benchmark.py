#!/usr/bin/env python3
"""The Bouc-Wen hysteretic benchmark (Noel & Schoukens 2016): identify the oscillator from
input/output data and report the simulation RMSE on a held-out noiseless multisine.

By default the estimation data (5 periods of a random-phase multisine, 8e-3 mm output noise) and the
test period are generated to the benchmark's specification (sashil.identify.boucwen_benchmark).
Official or other data: ``--estimation FILE.csv`` (periodic, N samples per period, first period
discarded) and ``--test FILE.csv`` (simulated from rest; the last ``--test-skip`` samples... see
--help), with columns ``u``,``y`` or ``torque_in_nm``,``theta_rad``, sampled at 750 Hz.

    python tools/boucwen_benchmark.py
    python tools/boucwen_benchmark.py --write-data /tmp/bw    # also save the generated CSVs
    python tools/boucwen_benchmark.py --quick                 # 2 generated periods instead of 5 (seconds)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

from sashil.errors import DataFileError
from sashil.identify import boucwen_benchmark as B
from sashil.recording.data_file import read_data_csv, write_data_csv


def read_io(path: str) -> tuple[np.ndarray, np.ndarray]:
    """(u, y) from a CSV with u,y or torque_in_nm,theta_rad columns."""
    for pair in (("u", "y"), ("torque_in_nm", "theta_rad")):
        try:
            cols = read_data_csv(path, required=pair, min_rows=16)
        except DataFileError as err:
            if "missing column" in str(err):
                continue
            raise
        return cols[pair[0]], cols[pair[1]]
    raise DataFileError(f"{path}: missing columns u,y (or torque_in_nm,theta_rad)")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--estimation", metavar="CSV", help="periodic estimation data (default: generated)")
    parser.add_argument("--period", type=int, default=B.N_PERIOD, help="samples per period of the estimation data")
    parser.add_argument("--test", metavar="CSV", help="test data simulated from rest (default: generated multisine)")
    parser.add_argument(
        "--test-steady",
        action="store_true",
        help="the --test file is one steady-state period (simulate it twice, score the second)",
    )
    parser.add_argument("--seed", type=int, default=7, help="seed of the generated estimation multisine")
    parser.add_argument("--write-data", metavar="DIR", help="write the generated estimation/test CSVs here")
    parser.add_argument("--quick", action="store_true", help="generate 2 periods of estimation data instead of 5")
    args = parser.parse_args()
    periods = 2 if args.quick else 5
    try:
        t0 = time.perf_counter()
        if args.estimation:
            u, y = read_io(args.estimation)
            source = args.estimation
        else:
            u, y = B.generate(args.seed, periods, B.NOISE_M)
            source = (
                f"generated: {periods} periods x {B.N_PERIOD} samples, multisine seed {args.seed}, noise 8e-3 mm RMS"
            )
        gen_s = time.perf_counter() - t0
        fit = B.identify(u, y, n=args.period)
    except (DataFileError, ValueError) as err:
        print(f"boucwen_benchmark: error: {err}")
        return 2
    print(f"estimation data: {source} ({gen_s:.2f} s to generate/read)")
    print(
        f"identification wall time: {fit.wall_s:.2f} s (global stage {fit.global_s:.2f} s), {fit.evaluations} evaluations; "
        "published white-box (Brunot et al. 2017, Nelder-Mead): 44 min"
    )
    print(f"training output RMSE (periods 2..): {fit.train_rmse_m:.3e} m (noise floor 8e-6 m)")
    for name in B.NAMES:
        print(f"  {name:>5} = {fit.params[name]:>14.6g} +- {fit.stderr[name]:.3g}   (true {B.TRUE[name]:g})")
    beta = 1e3
    print(
        f"  (nu = 1 fixed; with beta = {beta:g}: gamma = {fit.params['a'] / beta:.5g}, delta = {fit.params['d'] / beta:.5g})"
    )
    if args.test:
        ut, yt = read_io(args.test)
        if args.test_steady:
            ym = B.simulate(np.tile(ut, 2), fit.params, periodic_n=ut.size)[ut.size :]
        else:
            ym = B.simulate(ut, fit.params)
        rmse, std = float(np.sqrt(np.mean((ym - yt) ** 2))), float(np.std(yt))
        print(f"test {args.test}: simulation RMSE {rmse:.3e} m ({100 * rmse / std:.3g} % of output std)")
    else:
        rmse, std = B.test_rmse(fit.params)
        print(
            f"held-out noiseless multisine (steady-state period): simulation RMSE {rmse:.3e} m "
            f"({100 * rmse / std:.3g} % of std {std:.3e} m); acceptance <= 2e-6 m; best published "
            "black-box on the official test 7.5e-6 m"
        )
    if args.write_data:
        out = Path(args.write_data)
        out.mkdir(parents=True, exist_ok=True)
        if not args.estimation:
            write_data_csv(out / "estimation.csv", {"u": u, "y": y})
        ut, yt = B.generate(12345, 2)
        write_data_csv(out / "test_multisine.csv", {"u": ut[B.N_PERIOD :], "y": yt[B.N_PERIOD :]})
        print(f"wrote {out}/estimation.csv, {out}/test_multisine.csv")
    return 0


if __name__ == "__main__":
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from bench_record import keep_output

    raise SystemExit(keep_output("boucwen_benchmark", main))
