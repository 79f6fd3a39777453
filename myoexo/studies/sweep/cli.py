"""``myoexo policy sweep FILE``: run or continue a sweep and list its best trials (the sweep file:
:mod:`myoexo.studies.sweep`)."""

from __future__ import annotations

import argparse
import sys
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.runtime.fields import add_options, add_positional, check_fields, from_options, option
from myoexo.studies.sweep.spec import DEFAULT_OUT, RESULTS_STEM, read_sweep_file
from myoexo.studies.sweep.tune import run_sweep


@dataclass(frozen=True)
class SweepRun:
    """The sweep ``myoexo policy sweep`` runs or continues, where, and on which cluster."""

    file: Path = option(Path(), "sweep file (.yaml or .toml)", flag="")
    out: Path = option(
        DEFAULT_OUT,
        "parent folder of the sweep; the sweep lives in OUT/<name>, and running the same "
        "command again continues it",
        metavar="OUT",
        folder=True,
    )
    address: str | None = option(
        None,
        "Ray cluster to join: HOST:PORT or 'auto' (default: the RAY_ADDRESS environment "
        "variable, else a local cluster that ends with the command)",
        metavar="ADDRESS",
    )
    num_cpus: int | None = option(
        None,
        "CPUs of the local cluster (default: every core; ignored with --address)",
        low=0,
        above=True,
    )
    verbose: int = option(1, "0 quiet, 1 status and evaluations", low=0, short="v")

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo policy sweep`` (:class:`SweepRun`)."""
    add_positional(parser, SweepRun, "file")
    add_options(parser, SweepRun)


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
    """Run ``myoexo policy sweep``; 1 if a trial failed (its error is listed), else 0."""
    options: SweepRun = from_options(SweepRun, args, file=args.file)
    spec = read_sweep_file(options.file)
    result = run_sweep(spec, options.out, options.address, options.num_cpus, options.verbose)
    what = "continued" if result.restored else "ran"
    print(f"[sweep] {what} {spec.name}: {len(result.table)} trials, ranked:")
    for line in _lines(result.table):
        print(line)
    print(f"[sweep] table: {result.sweep_dir / RESULTS_STEM}.md (and .parquet)")
    for trial_id, error in result.errors.items():
        print(f"[sweep] trial {trial_id} failed: {error}", file=sys.stderr)
    return 1 if result.errors else 0
