"""``myoexo evaluate``: run the paper's evaluation protocol from the command line.

    myoexo evaluate --controllers pid sac runs/sac/best_model.zip --levels 0 1 2 3 \\
        --subjects 1000 --workers 8 --out results/eval
    myoexo report results/eval

Interrupting and re-running the same command continues where it stopped: finished chunks of
episodes are kept on disk and not recomputed (:mod:`myoexo.evaluation.engine`). Bad
arguments (an unknown level, ``--subjects 0``, an unreadable policy file) or a folder in use
by another run stop the command with a one-line error (exit status 2) before anything is
written. SIGTERM or Ctrl-C (SIGINT) stops it after the chunks in flight with one line on
stderr and exit status 128 + the signal number (143, 130); see ``docs/long_runs.md``.
Backends: ``--backend process`` (default, this machine) or ``--backend ray`` (a Ray cluster,
``docs/cluster.md``; ``--backend ray`` without Ray installed is a one-line error).
"""

from __future__ import annotations

import argparse
import signal
import sys
from dataclasses import dataclass
from pathlib import Path

from myoexo.envs.options import add_twin_arguments, twin_from_args
from myoexo.evaluation.config import EvaluationConfig
from myoexo.evaluation.ray_backend import BACKENDS
from myoexo.runtime.docs import docs_url
from myoexo.runtime.fields import Execution, add_options, check_fields, from_options, option

#: Default output folder of ``myoexo evaluate`` (``results/`` is git-ignored).
DEFAULT_OUT = Path("results") / "evaluation"

#: Defaults of ``myoexo evaluate`` that differ from :class:`EvaluationConfig`'s.
DEFAULTS: dict[str, object] = {"controllers": ("pid", "sac")}
#: :class:`EvaluationRunOptions`'s fields listed under "where and how to run".
_RUN_FIELDS = ("out", "backend", "address", "report")


@dataclass(frozen=True)
class EvaluationRunOptions:
    """What ``myoexo evaluate`` adds to the controllers, where it writes and where it runs
    (each field is an option of the command; :class:`EvaluationConfig`'s fields, the twin's
    options and :class:`~myoexo.runtime.fields.Execution`'s are its other options)."""

    seeds_dir: tuple[Path, ...] = option(
        (),
        "aggregated `myoexo policy seeds` folders: each seed's selected checkpoint is added to "
        "the controllers, and the report and result sets treat a folder's seeds as one "
        "controller (intervals over seeds and subjects)",
        metavar="DIR",
    )
    out: Path = option(DEFAULT_OUT, "output folder", folder=True)
    backend: str = option(
        "process",
        "where the episodes run, 'process': worker processes on this machine; 'ray': Ray tasks "
        f"(the 'ray' extra, {docs_url('cluster')}) on a local cluster of --workers CPUs or on "
        "the cluster of --address, where --workers is the most chunks in flight, else the "
        "cluster's CPUs",
        choices=BACKENDS,
    )
    address: str | None = option(
        None,
        "Ray cluster to join with --backend ray: HOST:PORT or 'auto' (default: the "
        "RAY_ADDRESS environment variable, else a local cluster that ends with the command)",
    )
    report: bool = option(False, "write the report when done")

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo evaluate``: :class:`EvaluationConfig`'s fields, the twin's
    options, and :class:`EvaluationRunOptions`'s and
    :class:`~myoexo.runtime.fields.Execution`'s (how and where to run)."""
    add_options(parser, EvaluationConfig, exclude=("twin", "selection"), defaults=DEFAULTS)
    add_options(parser, EvaluationRunOptions, exclude=_RUN_FIELDS)
    add_twin_arguments(parser)
    run = parser.add_argument_group("where and how to run")
    add_options(run, EvaluationRunOptions, exclude=("seeds_dir",))
    add_options(run, Execution)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo evaluate``; 0 on success, 2 on bad arguments or a folder in use,
    128 + the signal number when stopped by SIGINT / SIGTERM."""
    from myoexo.control.specs import seeds_controllers
    from myoexo.evaluation.runner import evaluate

    options = from_options(EvaluationRunOptions, args)
    execution = from_options(Execution, args)
    seeds = [spec for folder in options.seeds_dir for spec in seeds_controllers(folder)]
    config = from_options(
        EvaluationConfig,
        args,
        controllers=(*args.controllers, *seeds),
        twin=twin_from_args(args),
    )
    result = evaluate(
        config,
        options.out,
        workers=execution.workers,
        progress=execution.progress,
        backend=options.backend,
        address=options.address,
    )
    if result.stopped_by is not None:
        from myoexo.runtime.lifecycle import signal_exit_status

        print(
            f"myoexo evaluate: stopped by {result.stopped_by}: {result.stored} of "
            f"{result.total} episodes stored in {result.out_dir} ({result.computed} computed "
            "now), no table written; run the same command again to continue",
            file=sys.stderr,
        )
        return signal_exit_status(signal.Signals[result.stopped_by])
    n = len(result.table)
    print(
        f"{n} episodes ({result.computed} computed now) of {', '.join(result.controllers)} "
        f"in {result.out_dir}/episodes.parquet (and .csv)"
    )
    if options.report:
        from myoexo.evaluation.report import write_report

        path = write_report(result.out_dir)
        print(f"report: {path}")
    else:
        print(f"next: myoexo report {result.out_dir}")
    return 0
