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
from pathlib import Path

from myoexo.envs.options import add_twin_arguments, twin_from_args
from myoexo.evaluation.backends import available_cores
from myoexo.evaluation.config import EvaluationConfig
from myoexo.evaluation.ray_backend import BACKENDS
from myoexo.runtime.docs import docs_url
from myoexo.spasticity.levels import VALID_LEVELS

#: Default output folder of ``myoexo evaluate`` (``results/`` is git-ignored).
DEFAULT_OUT = Path("results") / "evaluation"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo evaluate``."""
    d = EvaluationConfig()
    parser.add_argument(
        "--controllers",
        nargs="+",
        default=["pid", "sac"],
        metavar="SPEC",
        help="controllers: 'pid[:kp=..,ki=..,kd=..,feedback=exo,anti_windup=..,ramp_s=..,"
        "limit=..,tuned=..]' (ramp_s: a ramped setpoint; limit: a clipped command; tuned=exo: "
        "gains tuned on the exo encoder, tuned=latency: tuned for the perturbed twins' 10 ms "
        "latency), 'sac' / 'student_exo' (the shipped policies; skipped with a "
        "message if absent), "
        "'oracle[:samples=..,horizon_s=..]' (MPC on a copy of the twin: the achievable bound, "
        "slow) or paths of SB3 .zip models (default: pid sac)",
    )
    parser.add_argument(
        "--levels",
        nargs="+",
        type=int,
        default=list(d.levels),
        metavar="L",
        help=f"spasticity levels, from {VALID_LEVELS} (default: all)",
    )
    parser.add_argument(
        "--subjects", type=int, default=d.subjects, help="subjects per level (default: 1000)"
    )
    parser.add_argument(
        "--workers",
        type=int,
        default=None,
        help=f"worker processes (default: all cores, here {available_cores()}); with "
        "--backend ray and --address: the most chunks in flight (default: the cluster's CPUs)",
    )
    parser.add_argument(
        "--backend",
        choices=BACKENDS,
        default="process",
        help="'process': worker processes on this machine (default); 'ray': Ray tasks, on a "
        "local cluster of --workers CPUs or on the cluster of --address (needs the 'ray' "
        f"extra; {docs_url('cluster')})",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster to join with --backend ray: HOST:PORT or 'auto' (default: the "
        "RAY_ADDRESS environment variable, else a local cluster that ends with the command)",
    )
    parser.add_argument(
        "--out", type=Path, default=DEFAULT_OUT, help=f"output folder (default: {DEFAULT_OUT})"
    )
    parser.add_argument(
        "--seed", type=int, default=d.root_seed, help="root seed of the subjects (default: 0)"
    )
    parser.add_argument(
        "--trace-stride",
        type=int,
        default=d.trace_stride,
        help="store every n-th control step of the traces (default: 2, i.e. 50 Hz)",
    )
    parser.add_argument(
        "--chunk-size", type=int, default=d.chunk_size, help="subjects per resumable chunk"
    )
    parser.add_argument(
        "--env-id",
        default=d.env_id,
        help="gymnasium id of a level's env, with '{level}' (default: %(default)s)",
    )
    parser.add_argument(
        "--seeds-dir",
        type=Path,
        nargs="+",
        default=[],
        metavar="DIR",
        help="aggregated `myoexo seeds` folders: each seed's selected checkpoint is added to "
        "the controllers, and the report and result sets treat a folder's seeds as one "
        "controller (intervals over seeds and subjects)",
    )
    add_twin_arguments(parser)
    parser.add_argument("--report", action="store_true", help="write the report when done")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo evaluate``; 0 on success, 2 on bad arguments or a folder in use,
    128 + the signal number when stopped by SIGINT / SIGTERM."""
    from myoexo.control.specs import seeds_controllers
    from myoexo.evaluation.runner import evaluate

    try:
        seeds = [spec for folder in args.seeds_dir for spec in seeds_controllers(folder)]
        config = EvaluationConfig(
            controllers=(*args.controllers, *seeds),
            levels=tuple(args.levels),
            subjects=args.subjects,
            root_seed=args.seed,
            trace_stride=args.trace_stride,
            chunk_size=args.chunk_size,
            env_id=args.env_id,
            twin=twin_from_args(args),
        )
        result = evaluate(
            config,
            args.out,
            workers=args.workers,
            progress=not args.no_progress,
            backend=args.backend,
            address=args.address,
        )
    except ValueError as exc:
        print(f"myoexo evaluate: error: {exc}", file=sys.stderr)
        return 2
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
    if args.report:
        from myoexo.evaluation.report import write_report

        path = write_report(result.out_dir)
        print(f"report: {path}")
    else:
        print(f"next: myoexo report {result.out_dir}")
    return 0
