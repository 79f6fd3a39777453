"""``myoexo demo`` (what ``make demo`` runs): the paper's evaluation protocol, small.

Evaluates the paper's PID, the device's own PID closed on the exo encoder (what a real
exoskeleton can run) with the paper's gains (``pid:feedback=exo``) and with gains tuned on the
encoder by Ziegler-Nichols (``pid:tuned=exo``, :mod:`myoexo.control.tuned`), the paper's PID
with its setpoint ramped over 1 s (``pid:ramp_s=1``), the full-state ``sac`` alone and with
its stall guard as deployed (``guard:sac``, :mod:`myoexo.control.guard`), and the
deployable ``student_exo`` (the exoskeleton's own sensors with memory) alone and with its
guard on the encoder (``guard:student_exo``) on 20 subjects per spasticity level (paper: 1000),
and the achievable bound (the oracle MPC, :mod:`myoexo.control.oracle`) on the first 2 of them;
then writes the figures and the Markdown report (with each controller's distance to the
bound) and prints where they are. About 5 minutes on 2 cores, most of it the oracle.
Re-running continues or reuses the finished episodes in the output folder (default
``results/demo``; the oracle's in ``results/demo/bound``).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from myoexo.envs.options import add_twin_arguments, twin_from_args

#: Defaults of the demo.
DEMO_SUBJECTS = 20
DEMO_CONTROLLERS = (
    "pid",
    "pid:feedback=exo",
    "pid:tuned=exo",
    "pid:ramp_s=1",
    "sac",
    "guard:sac",
    "student_exo",
    "guard:student_exo",
)
#: Subjects per level of the oracle (the bound); it costs ~15 s of a quiet core per episode.
DEMO_BOUND_SUBJECTS = 2
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
        help="controller specs as for 'myoexo evaluate' (default: %(default)s)",
    )
    parser.add_argument(
        "--bound-subjects",
        type=int,
        default=DEMO_BOUND_SUBJECTS,
        help=f"subjects per level of the oracle bound (default: {DEMO_BOUND_SUBJECTS}; "
        "0: no bound)",
    )
    parser.add_argument("--workers", type=int, default=None, help="default: all cores")
    parser.add_argument("--out", type=Path, default=DEMO_OUT, help=f"default: {DEMO_OUT}")
    add_twin_arguments(parser)
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
    bound_dir = args.out / "bound" if args.bound_subjects > 0 else None
    try:
        twin = twin_from_args(args)
        config = EvaluationConfig(
            controllers=tuple(args.controllers), subjects=args.subjects, twin=twin
        )
        result = evaluate(config, args.out, workers=workers, progress=not args.no_progress)
        if bound_dir is not None:
            print(f"achievable bound: oracle MPC on {args.bound_subjects} subjects per level")
            bound_config = EvaluationConfig(
                controllers=("oracle",), subjects=args.bound_subjects, chunk_size=1, twin=twin
            )
            evaluate(bound_config, bound_dir, workers=workers, progress=not args.no_progress)
        report = write_report(result.out_dir, bound_dir=bound_dir)
    except ValueError as exc:
        print(f"myoexo demo: error: {exc}", file=sys.stderr)
        return 2
    summary = summarize(result.table)
    print("\ncontroller        level  final error (deg)  overshoot (deg)  settling (s)  peak (Nm)")
    for s in summary.itertuples():
        print(
            f"{s.controller:<16s}  {s.level:5d}  {s.final_error_deg_mean:17.2f}  "
            f"{s.target_overshoot_deg_mean:15.2f}  {s.settling_time_s_mean:12.2f}  "
            f"{s.peak_interaction_torque_nm_mean:9.1f}"
        )
    if bound_dir is not None:
        import pandas as pd

        from myoexo.evaluation import load_table
        from myoexo.evaluation.bound import distance_to_bound

        both = pd.concat([result.table, load_table(bound_dir)], ignore_index=True)
        d = distance_to_bound(both)
        print(
            "\ncontroller        level  |final error| (deg)  bound (deg)  distance (deg)  subjects"
        )
        for r in d.itertuples():
            print(
                f"{r.controller:<16s}  {r.level:5d}  {r.abs_final_error_deg:19.2f}  "
                f"{r.bound_abs_final_error_deg:11.2f}  {r.distance_deg:14.2f}  {r.subjects:8d}"
            )
    print(f"\n{len(result.table)} episodes in {time.perf_counter() - t0:.0f} s")
    print(f"report:  {report.resolve()}")
    print(f"figures: {(report.parent / 'figures').resolve()}")
    print(f"table:   {(result.out_dir / 'episodes.csv').resolve()}")
    return 0
