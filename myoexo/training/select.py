"""Pick the checkpoint to ship: evaluate candidates against the PID with the evaluation
harness and check the issue's acceptance criteria.

Criteria (per level, means over the same simulated subjects, SPEC section 5):

* peak interaction torque lower than the PID's at every level;
* RMS interaction torque up to settling lower than the PID's at levels 0-2;
* mean absolute final error below 1 deg at levels 0-2, and below the paper's 11.45 deg at
  level 3.

    python -m myoexo.training.select runs/cpu_main --subjects 10 --last 2 --top 4
    python -m myoexo.training.select results/eval --table    # after `myoexo evaluate`
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.training import checkpoints as ck

LEVELS: tuple[int, ...] = (0, 1, 2, 3)


@dataclass(frozen=True)
class Criteria:
    """The acceptance criteria of a shipped policy.

    Attributes:
        final_error_deg: Bound on the mean absolute final error per level (1 deg at levels
            0-2; the paper's own SAC result, 11.45 deg, at level 3).
        rms_levels: Levels where the RMS-to-settling must be lower than the PID's.
        peak_levels: Levels where the peak interaction torque must be lower than the PID's.
    """

    final_error_deg: tuple[float, ...] = (1.0, 1.0, 1.0, 11.45)
    rms_levels: tuple[int, ...] = (0, 1, 2)
    peak_levels: tuple[int, ...] = (0, 1, 2, 3)


_METRICS = (
    "abs_final_error_deg",
    "final_error_deg",
    "settling_time_s",
    "rms_interaction_torque_nm",
    "peak_interaction_torque_nm",
)


def level_means(table: Any) -> Any:
    """Per-level means of the criteria's metrics from an evaluation table."""
    return table.groupby("level")[list(_METRICS)].mean()


def compare(sac: Any, pid: Any, criteria: Criteria = Criteria()) -> Any:
    """Side-by-side table per level (pandas) with reductions vs the PID and pass flags.

    Args:
        sac: Per-level means of the policy (:func:`level_means`).
        pid: Per-level means of the PID on the same subjects.
        criteria: Bounds.
    """
    import pandas as pd

    rows = []
    for level in sac.index:
        s, p = sac.loc[level], pid.loc[level]
        peak_red = 100 * (p.peak_interaction_torque_nm - s.peak_interaction_torque_nm)
        rms_red = 100 * (p.rms_interaction_torque_nm - s.rms_interaction_torque_nm)
        row = {
            "level": int(level),
            "sac_final_error_deg": s.final_error_deg,
            "sac_abs_final_error_deg": s.abs_final_error_deg,
            "pid_final_error_deg": p.final_error_deg,
            "sac_settling_time_s": s.settling_time_s,
            "pid_settling_time_s": p.settling_time_s,
            "sac_rms_nm": s.rms_interaction_torque_nm,
            "pid_rms_nm": p.rms_interaction_torque_nm,
            "rms_reduction_pct": rms_red / p.rms_interaction_torque_nm,
            "sac_peak_nm": s.peak_interaction_torque_nm,
            "pid_peak_nm": p.peak_interaction_torque_nm,
            "peak_reduction_pct": peak_red / p.peak_interaction_torque_nm,
        }
        ok_err = s.abs_final_error_deg < criteria.final_error_deg[int(level)]
        ok_peak = level not in criteria.peak_levels or peak_red > 0
        ok_rms = level not in criteria.rms_levels or rms_red > 0
        row.update(final_error_ok=ok_err, peak_ok=ok_peak, rms_ok=ok_rms)
        row["pass"] = bool(ok_err and ok_peak and ok_rms)
        rows.append(row)
    return pd.DataFrame(rows).set_index("level")


def shortfall(table: Any, criteria: Criteria = Criteria()) -> float:
    """How far a :func:`compare` table is from passing (0 when it passes; larger is worse):
    the sum over levels of the relative excess of the final error over its bound and of the
    relative peak / RMS increase over the PID."""
    total = 0.0
    for level, row in table.iterrows():
        total += max(0.0, row.sac_abs_final_error_deg / criteria.final_error_deg[level] - 1.0)
        if level in criteria.peak_levels:
            total += max(0.0, -row.peak_reduction_pct / 100)
        if level in criteria.rms_levels:
            total += max(0.0, -row.rms_reduction_pct / 100)
    return total


def evaluate_pid(subjects: int, levels: Sequence[int] = LEVELS, root_seed: int = 0) -> Any:
    """Per-level means of the paper's PID on subjects ``0..subjects-1``."""
    import gymnasium as gym
    import pandas as pd

    from myoexo.control import build_controller, parse_controller_spec
    from myoexo.evaluation import evaluate_controller

    tables = []
    for level in levels:
        env = gym.make(f"MyoExoKnee-v{level}")
        pid = build_controller(parse_controller_spec("pid"), env)
        env.close()
        table, _ = evaluate_controller(pid, level, subjects, root_seed, label="pid")
        tables.append(table)
    return level_means(pd.concat(tables))


def evaluate_checkpoint(
    checkpoint: Path, subjects: int, levels: Sequence[int] = LEVELS, root_seed: int = 0
) -> Any:
    """Per-level means of a checkpoint's deterministic actor on subjects ``0..subjects-1``."""
    import pandas as pd

    from myoexo.control import CallableController
    from myoexo.evaluation import evaluate_controller
    from myoexo.training.export import load_checkpoint_actor

    actor = load_checkpoint_actor(checkpoint, with_reference=False)
    controller = CallableController(actor, name=checkpoint.name)
    tables = [
        evaluate_controller(controller, lv, subjects, root_seed, label=checkpoint.name)[0]
        for lv in levels
    ]
    return level_means(pd.concat(tables))


def select_checkpoint(
    run_dir: Path,
    subjects: int = 10,
    last: int = 2,
    top: int = 4,
    root_seed: int = 0,
    verbose: bool = True,
    levels: Sequence[int] = LEVELS,
) -> tuple[Path, Any]:
    """Evaluate the ``last`` newest checkpoints and the ``top`` best by small-evaluation
    score (``eval.csv``) on ``subjects`` subjects per level of ``levels``, and return the one
    with the smallest :func:`shortfall` (ties: the largest mean peak torque reduction) with
    its comparison table."""
    import csv

    ckpts = ck.list_checkpoints(run_dir)
    if not ckpts:
        raise ValueError(f"{str(run_dir)!r} holds no checkpoint")
    candidates = list(ckpts[-last:]) if last > 0 else []
    eval_path = Path(run_dir) / ck.EVAL_FILE
    if top > 0 and eval_path.is_file():
        with open(eval_path, newline="") as f:
            scores = {int(r["step"]): float(r["score"]) for r in csv.DictReader(f)}
        scored = sorted(
            (c for c in ckpts if ck.step_of(c) in scores), key=lambda c: -scores[ck.step_of(c)]
        )
        candidates += [c for c in scored[:top] if c not in candidates]
    pid = evaluate_pid(subjects, levels, root_seed=root_seed)
    results = []
    for c in candidates:
        table = compare(evaluate_checkpoint(c, subjects, levels, root_seed=root_seed), pid)
        key = (shortfall(table), -table.peak_reduction_pct.mean())
        results.append((key, c, table))
        if verbose:
            print(
                f"{c.name}: shortfall {key[0]:.3f}, mean peak reduction "
                f"{-key[1]:+.1f} %, |final err| "
                + " ".join(f"{v:.2f}" for v in table.sac_abs_final_error_deg),
                flush=True,
            )
    _, chosen, table = min(results, key=lambda r: r[0])
    return chosen, table


def compare_evaluation(out_dir: Path, sac: str = "sac", pid: str = "pid") -> Any:
    """:func:`compare` table of two controllers of a ``myoexo evaluate`` output folder."""
    from myoexo.evaluation import load_table

    table = load_table(out_dir)
    missing = {sac, pid} - set(table.controller)
    if missing:
        raise ValueError(f"{str(out_dir)!r} has no episodes of {sorted(missing)}")
    means = {c: level_means(table[table.controller == c]) for c in (sac, pid)}
    return compare(means[sac], means[pid])


def markdown_table(table: Any) -> str:
    """The comparison as a Markdown table, each of our numbers next to the paper's."""
    from myoexo.evaluation.paper import PAPER_RESULTS

    def num(x: float | None, fmt: str = ".2f") -> str:
        return "n/a" if x is None else format(x, fmt)

    lines = [
        "| level | final error SAC (deg) [paper] | final error PID (deg) [paper] "
        "| peak SAC / PID (Nm) | peak reduction % [paper] | RMS SAC / PID (Nm) "
        "| RMS reduction % [paper] | settling SAC (s) [paper] | criteria |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for level, r in table.iterrows():
        ref = PAPER_RESULTS[int(level)]
        flags = [
            name
            for name, ok in (
                ("final error", r.final_error_ok),
                ("peak", r.peak_ok),
                ("RMS", r.rms_ok),
            )
            if not ok
        ]
        lines.append(
            f"| {level} | {r.sac_final_error_deg:.2f} [{ref.sac_final_error_text}] "
            f"| {r.pid_final_error_deg:.2f} [{ref.pid_final_error_text}] "
            f"| {r.sac_peak_nm:.1f} / {r.pid_peak_nm:.1f} "
            f"| {r.peak_reduction_pct:.1f} [{num(ref.peak_reduction_pct, '.1f')}] "
            f"| {r.sac_rms_nm:.1f} / {r.pid_rms_nm:.1f} "
            f"| {r.rms_reduction_pct:.1f} [{num(ref.rms_reduction_pct, '.1f')}] "
            f"| {r.sac_settling_time_s:.2f} [{ref.sac_settling_time_s}] "
            f"| {'pass' if not flags else 'fails: ' + ', '.join(flags)} |"
        )
    return "\n".join(lines)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo select`` (and ``python -m myoexo.training.select``)."""
    parser.add_argument("run", type=Path, help="run folder, or an evaluation folder with --table")
    parser.add_argument(
        "--table",
        action="store_true",
        help="print the Markdown criteria table of `myoexo "
        "evaluate --controllers pid sac` output in RUN instead",
    )
    parser.add_argument("--subjects", type=int, default=10, help="subjects per level")
    parser.add_argument(
        "--levels",
        type=int,
        nargs="+",
        choices=LEVELS,
        default=list(LEVELS),
        metavar="LEVEL",
        help="spasticity levels to evaluate (default: 0 1 2 3)",
    )
    parser.add_argument("--last", type=int, default=2, help="newest checkpoints to consider")
    parser.add_argument("--top", type=int, default=4, help="best-scored checkpoints to consider")
    parser.add_argument("--root-seed", type=int, default=0)
    parser.add_argument(
        "--out",
        type=Path,
        metavar="FILE",
        help="also write the comparison table: FILE.md (Markdown, next to the paper's "
        "numbers) or FILE.csv (with the chosen checkpoint in a column)",
    )


def run(args: argparse.Namespace) -> int:
    """Print the chosen checkpoint and its table (or, with ``--table``, the criteria table
    of an evaluation folder); write it to ``--out`` if given."""
    levels = sorted(set(args.levels))
    if args.out is not None and args.out.suffix not in (".md", ".csv"):
        raise ValueError(f"--out {str(args.out)!r} must end in .md or .csv")
    chosen = None
    if args.table:
        table = compare_evaluation(args.run)
        table = table[table.index.isin(levels)]
        print(markdown_table(table))
    else:
        if args.subjects < 1:
            raise ValueError(f"--subjects {args.subjects} must be at least 1")
        if args.last < 0 or args.top < 0 or args.last + args.top < 1:
            raise ValueError("--last and --top must be >= 0 and name at least one candidate")
        if args.last == 0 and not (args.run / ck.EVAL_FILE).is_file():
            raise ValueError(f"--top needs the run's {ck.EVAL_FILE}; {args.run} has none")
        chosen, table = select_checkpoint(
            args.run, args.subjects, args.last, args.top, args.root_seed, levels=levels
        )
        print(f"chosen: {chosen}")
        print(table.round(2).to_string())
    if args.out is not None:
        args.out.parent.mkdir(parents=True, exist_ok=True)
        if args.out.suffix == ".md":
            head = "" if chosen is None else f"chosen: `{chosen}`\n\n"
            args.out.write_text(head + markdown_table(table) + "\n")
        else:
            table = table if chosen is None else table.assign(checkpoint=str(chosen))
            table.to_csv(args.out)
        print(f"wrote {args.out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m myoexo.training.select RUN`` (same as ``myoexo select RUN``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
