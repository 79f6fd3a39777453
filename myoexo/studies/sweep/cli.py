"""``myoexo sweep FILE``: run or continue a sweep and list its best trials (the sweep file:
:mod:`myoexo.studies.sweep`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from myoexo.studies.sweep.spec import DEFAULT_OUT, RESULTS_STEM, read_sweep_file
from myoexo.studies.sweep.tune import run_sweep


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo sweep``."""
    parser.add_argument("file", type=Path, help="sweep file (.yaml or .toml)")
    parser.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"parent folder of the sweep (default: {DEFAULT_OUT}); the sweep lives in "
        "OUT/<name>, and running the same command again continues it",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster to join: HOST:PORT or 'auto' (default: the RAY_ADDRESS environment "
        "variable, else a local cluster that ends with the command)",
    )
    parser.add_argument(
        "--num-cpus",
        type=int,
        default=None,
        help="CPUs of the local cluster (default: every core; ignored with --address)",
    )
    parser.add_argument(
        "-v", "--verbose", type=int, default=1, help="0 quiet, 1 status and evaluations"
    )


#: Trials listed on the terminal at the end of a sweep (the table holds them all).
SHOWN_TRIALS = 5


def _lines(table: Any) -> Iterator[str]:
    for _, row in table.head(SHOWN_TRIALS).iterrows():
        if row["evaluations"] == 0:
            yield f"  {row['rank']}. {row['trial']} ({row['status']}): no evaluation"
            continue
        yield (
            f"  {row['rank']}. {row['trial']} ({row['status']}): shortfall "
            f"{row['shortfall']:.3f}, mean peak-torque reduction "
            f"{row['mean_peak_reduction_pct']:+.1f} % at step {int(row['best_step'])}"
        )


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo sweep``; 1 if a trial failed (its error is listed), else 0."""
    if args.num_cpus is not None and args.num_cpus <= 0:
        raise ValueError(f"--num-cpus {args.num_cpus} must be > 0")
    spec = read_sweep_file(args.file)
    result = run_sweep(spec, args.out, args.address, args.num_cpus, args.verbose)
    what = "continued" if result.restored else "ran"
    print(f"[sweep] {what} {spec.name}: {len(result.table)} trials, ranked:")
    for line in _lines(result.table):
        print(line)
    print(f"[sweep] table: {result.sweep_dir / RESULTS_STEM}.md (and .parquet)")
    for trial_id, error in result.errors.items():
        print(f"[sweep] trial {trial_id} failed: {error}", file=sys.stderr)
    return 1 if result.errors else 0
