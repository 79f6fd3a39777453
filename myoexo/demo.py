"""``myoexo demo`` (what ``make demo`` runs): the paper's evaluation protocol, small.

Evaluates the PID baseline and, when the package ships one, the SAC policy on 20 subjects
per spasticity level (paper: 1000), then writes the figures and the Markdown report and
prints where they are. A few minutes on 2 cores. Re-running continues or reuses the
finished episodes in the output folder (default ``results/demo``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

#: Defaults of the demo.
DEMO_SUBJECTS = 20
DEMO_CONTROLLERS = ("pid", "sac")
DEMO_OUT = Path("results") / "demo"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo demo``."""
    parser.add_argument(
        "--subjects",
        type=int,
        default=DEMO_SUBJECTS,
        help=f"subjects per level (default: {DEMO_SUBJECTS})",
    )
    parser.add_argument(
        "--controllers",
        nargs="+",
        default=list(DEMO_CONTROLLERS),
        metavar="SPEC",
        help="controller specs as for 'myoexo evaluate' (default: pid sac)",
    )
    parser.add_argument("--workers", type=int, default=None, help="default: all cores")
    parser.add_argument("--out", type=Path, default=DEMO_OUT, help=f"default: {DEMO_OUT}")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar")


def run(args: argparse.Namespace) -> int:
    """Run the demo evaluation and report; 0 on success, 2 on bad arguments."""
    from myoexo.evaluation import EvaluationConfig, available_cores, evaluate
    from myoexo.evaluation.report import summarize, write_report

    workers = args.workers or available_cores()
    t0 = time.perf_counter()
    print(
        f"myoexo demo: {args.subjects} subjects x levels 0-3 x controllers "
        f"{' '.join(args.controllers)} on {workers} worker(s) -> {args.out}"
    )
    try:
        config = EvaluationConfig(controllers=tuple(args.controllers), subjects=args.subjects)
        result = evaluate(config, args.out, workers=workers, progress=not args.no_progress)
        report = write_report(result.out_dir)
    except ValueError as exc:
        print(f"myoexo demo: error: {exc}", file=sys.stderr)
        return 2
    summary = summarize(result.table)
    print("\ncontroller  level  final error (deg)  overshoot (deg)  settling (s)  peak (Nm)")
    for s in summary.itertuples():
        print(
            f"{s.controller:<10s}  {s.level:5d}  {s.final_error_deg_mean:17.2f}  "
            f"{s.target_overshoot_deg_mean:15.2f}  {s.settling_time_s_mean:12.2f}  "
            f"{s.peak_interaction_torque_nm_mean:9.1f}"
        )
    print(f"\n{len(result.table)} episodes in {time.perf_counter() - t0:.0f} s")
    print(f"report:  {report.resolve()}")
    print(f"figures: {(report.parent / 'figures').resolve()}")
    print(f"table:   {(result.out_dir / 'episodes.csv').resolve()}")
    return 0
