"""Pick the checkpoint to ship: evaluate candidates against the PID with the evaluation
harness on the selection subjects; the fewest catastrophic subjects first (with
``--perturbed-subjects N``, those of N perturbed selection subjects per level counted too),
then the acceptance criteria (:mod:`myoexo.evaluation.criteria`), then the peak reduction
(:func:`selection_key`).

    myoexo policy select runs/cpu_main --subjects 10 --last 2 --top 4
    myoexo policy select runs/res/seed_0 --subjects 50 --last 4 --top 4 --gentleness 0
    myoexo policy select runs/res/seed_0 --subjects 20 --perturbed-subjects 100 \
        --perturbed-levels 2 3 --gentleness 0
    myoexo policy select results/eval --table    # after `myoexo evaluate`
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.evaluation.config import SELECTION_ROOT_SEED, check_fit_root
from myoexo.evaluation.criteria import compare_with_pid, level_means, shortfall
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    add_positional,
    check_fields,
    from_options,
    option,
)
from myoexo.spasticity.levels import VALID_LEVELS
from myoexo.training import checkpoints as ck


@dataclass(frozen=True)
class SelectionConfig:
    """Which checkpoints of a run are candidates and on which subjects they are compared
    (each field is an option of ``myoexo policy select``; ``subjects``, ``last`` and
    ``top`` also of ``myoexo policy seeds aggregate``)."""

    subjects: int = option(10, "selection subjects per level", low=1)
    levels: tuple[int, ...] = option(
        VALID_LEVELS, "spasticity levels to evaluate", choices=VALID_LEVELS, metavar="LEVEL"
    )
    last: int = option(2, "newest checkpoints to consider", low=0)
    top: int = option(4, "best checkpoints by the run's small evaluation (eval.csv)", low=0)
    root_seed: int = option(
        SELECTION_ROOT_SEED,
        "root seed of the selection subjects (the reported evaluation uses another)",
        low=0,
    )
    gentleness: float | None = option(
        None,
        "the weight a policy trained over the gentleness range is selected at (its default "
        "weight, from `myoexo policy gentleness`); required for such a policy",
        low=0.0,
        high=1.0,
        metavar="WEIGHT",
    )
    perturbed_subjects: int = option(
        0,
        "perturbed selection subjects per level (robustness on) whose catastrophic subjects "
        "count too, against the PID on the same perturbed subjects (0: none)",
        low=0,
    )
    perturbed_levels: tuple[int, ...] = option(
        VALID_LEVELS,
        "levels of the perturbed selection subjects",
        choices=VALID_LEVELS,
        metavar="LEVEL",
    )
    workers: int = option(
        1, "seeds selected at once, one process each (`policy seeds aggregate`)", low=1
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "levels", tuple(sorted(set(self.levels))))
        object.__setattr__(self, "perturbed_levels", tuple(sorted(set(self.perturbed_levels))))
        check_fields(self)
        outside = sorted(set(self.perturbed_levels) - set(self.levels))
        if self.perturbed_subjects and outside:
            raise FieldError(
                "SelectionConfig", "perturbed_levels", self.perturbed_levels,
                f"must be among the selection levels {list(self.levels)} (not {outside})",
            )  # fmt: skip
        if self.last + self.top < 1:
            raise FieldError(
                "SelectionConfig", "top", self.top, "names no candidate checkpoint (last = 0)"
            )
        check_fit_root(self.root_seed, "checkpoint selection")


def _episodes(
    controller: Any,
    label: str,
    subjects: int,
    levels: Sequence[int],
    root_seed: int,
    robustness: bool = False,
) -> Any:
    """Episode table of *controller* (column ``controller`` = *label*) on subjects
    ``0..subjects-1`` of each level (perturbed twins with *robustness*)."""
    import pandas as pd

    from myoexo.evaluation import evaluate_controller

    kwargs = {"robustness": True} if robustness else None
    tables = [
        evaluate_controller(controller, lv, subjects, root_seed, label=label, env_kwargs=kwargs)[0]
        for lv in levels
    ]
    return pd.concat(tables, ignore_index=True)


def pid_episodes(
    subjects: int,
    levels: Sequence[int] = VALID_LEVELS,
    root_seed: int = SELECTION_ROOT_SEED,
    robustness: bool = False,
) -> Any:
    """Episode table (controller ``"pid"``) of the paper's PID on subjects
    ``0..subjects-1`` (perturbed twins with *robustness*)."""
    from myoexo.control import PID
    from myoexo.envs import TaskParams

    pid = PID(dt_s=TaskParams().control_period_s)  # the paper's gains
    return _episodes(pid, "pid", subjects, levels, root_seed, robustness)


def evaluate_pid(
    subjects: int, levels: Sequence[int] = VALID_LEVELS, root_seed: int = SELECTION_ROOT_SEED
) -> Any:
    """Per-level means of the paper's PID on subjects ``0..subjects-1``."""
    return level_means(pid_episodes(subjects, levels, root_seed))


def checkpoint_episodes(
    checkpoint: Path,
    subjects: int,
    levels: Sequence[int] = VALID_LEVELS,
    root_seed: int = SELECTION_ROOT_SEED,
    gentleness: float | None = None,
    robustness: bool = False,
) -> Any:
    """Episode table (controller: the checkpoint's folder name) of a checkpoint's
    deterministic actor on subjects ``0..subjects-1`` (perturbed twins with *robustness*); a
    policy trained over the gentleness range runs at weight *gentleness*
    (:func:`~myoexo.training.export.load_checkpoint_controller`)."""
    from myoexo.training.export import load_checkpoint_controller

    controller = load_checkpoint_controller(checkpoint, gentleness)
    return _episodes(controller, checkpoint.name, subjects, levels, root_seed, robustness)


def evaluate_checkpoint(
    checkpoint: Path,
    subjects: int,
    levels: Sequence[int] = VALID_LEVELS,
    root_seed: int = SELECTION_ROOT_SEED,
    gentleness: float | None = None,
) -> Any:
    """Per-level means of :func:`checkpoint_episodes`."""
    return level_means(checkpoint_episodes(checkpoint, subjects, levels, root_seed, gentleness))


def catastrophic_per_level(episodes: Any, pid: Any) -> Any:
    """Per level (a pandas Series), the subjects of *episodes* (one controller) that end
    beyond the catastrophic bound (:func:`~myoexo.evaluation.stats.tail_risk`: 20 deg, or
    the paper's PID's worst subject at the level in *pid*'s episodes, whichever is
    larger)."""
    import pandas as pd

    from myoexo.evaluation.stats import tail_risk

    risk = tail_risk(pd.concat([pid, episodes], ignore_index=True), reference="pid")
    return risk[risk.controller != "pid"].set_index("level").catastrophic


def selection_key(table: Any) -> tuple[int, float, float]:
    """The order of :func:`select_checkpoint` on a :func:`compare_with_pid` table with a
    ``catastrophic`` column and, if the perturbed subjects were run, a
    ``catastrophic_perturbed`` one (smaller is better): catastrophic subjects summed over
    levels (and over both twins), then :func:`shortfall`, then minus the mean peak torque
    reduction."""
    perturbed = table.get("catastrophic_perturbed")
    return (
        int(table.catastrophic.sum()) + (0 if perturbed is None else int(perturbed.sum())),
        shortfall(table),
        -float(table.peak_reduction_pct.mean()),
    )


def select_checkpoint(
    run_dir: Path,
    subjects: int = 10,
    last: int = 2,
    top: int = 4,
    root_seed: int = SELECTION_ROOT_SEED,
    verbose: bool = True,
    levels: Sequence[int] = VALID_LEVELS,
    gentleness: float | None = None,
    perturbed_subjects: int = 0,
    perturbed_levels: Sequence[int] = VALID_LEVELS,
) -> tuple[Path, Any]:
    """Evaluate the ``last`` newest checkpoints and the ``top`` best by small-evaluation
    score (``eval.csv``) on ``subjects`` subjects per level of ``levels``, and return the one
    with the fewest catastrophic subjects (:func:`catastrophic_per_level`), then the smallest
    :func:`shortfall`, then the largest mean peak torque reduction, with its comparison
    table (its ``catastrophic`` column: the count per level). With *perturbed_subjects*,
    each candidate also runs on that many perturbed subjects per level of
    *perturbed_levels* (the same root, robustness on), and their catastrophic subjects,
    against the PID on the same perturbed subjects, count beside the nominal ones (column
    ``catastrophic_perturbed``, 0 at a level not run). A policy trained over the gentleness
    range is selected at weight *gentleness*.

    Raises:
        ValueError: *run_dir* holds no checkpoint, *root_seed* is the evaluation root, or a
            perturbed level is not one of *levels* (its count would have no row).
    """
    import csv

    root_seed = check_fit_root(root_seed, "checkpoint selection")
    perturbed = perturbed_subjects > 0
    outside = sorted(set(perturbed_levels) - set(levels)) if perturbed else []
    if outside:
        raise ValueError(
            f"perturbed levels {outside} are not among the selection levels {list(levels)}"
        )
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
    pid_runs = pid_episodes(subjects, levels, root_seed=root_seed)
    pid = level_means(pid_runs)
    if perturbed:
        pid_perturbed = pid_episodes(perturbed_subjects, perturbed_levels, root_seed, True)
    results = []
    for c in candidates:
        episodes = checkpoint_episodes(c, subjects, levels, root_seed, gentleness)
        table = compare_with_pid(level_means(episodes), pid)
        per_level = catastrophic_per_level(episodes, pid_runs)
        table["catastrophic"] = per_level.reindex(table.index).fillna(0).astype(int)
        if perturbed:
            runs = checkpoint_episodes(
                c, perturbed_subjects, perturbed_levels, root_seed, gentleness, True
            )
            per_level = catastrophic_per_level(runs, pid_perturbed)
            table["catastrophic_perturbed"] = per_level.reindex(table.index).fillna(0).astype(int)
        key = selection_key(table)
        results.append((key, c, table))
        if verbose:
            on_perturbed = (
                f" ({int(table.catastrophic_perturbed.sum())} on perturbed subjects)"
                if perturbed
                else ""
            )
            print(
                f"{c.name}: catastrophic {key[0]}{on_perturbed}, shortfall {key[1]:.3f}, mean peak "
                f"reduction {-key[2]:+.1f} %, |final err| "
                + " ".join(f"{v:.2f}" for v in table.sac_abs_final_error_deg),
                flush=True,
            )
    _, chosen, table = min(results, key=lambda r: r[0])
    # the chosen checkpoint records its selection root, so that an evaluation of its
    # model.zip on these subjects is refused (control.specs.check_no_selection_leak)
    ck.record_selection(chosen, root_seed)
    return chosen, table


def select_with(run_dir: Path, config: SelectionConfig, verbose: bool = True) -> tuple[Path, Any]:
    """:func:`select_checkpoint` of *run_dir* with every option of *config* (but its
    ``workers``)."""
    return select_checkpoint(
        run_dir,
        config.subjects,
        config.last,
        config.top,
        config.root_seed,
        verbose=verbose,
        levels=config.levels,
        gentleness=config.gentleness,
        perturbed_subjects=config.perturbed_subjects,
        perturbed_levels=config.perturbed_levels,
    )


def compare_evaluation(out_dir: Path, sac: str = "sac", pid: str = "pid") -> Any:
    """:func:`compare` table of two controllers of a ``myoexo evaluate`` output folder, with
    the stricter reading of the paper's numbers added (:func:`paper_checks`)."""
    from myoexo.evaluation import load_table

    table = load_table(out_dir)
    missing = {sac, pid} - set(table.controller)
    if missing:
        raise ValueError(f"{str(out_dir)!r} has no episodes of {sorted(missing)}")
    means = {c: level_means(table[table.controller == c]) for c in (sac, pid)}
    return paper_checks(compare_with_pid(means[sac], means[pid]), table[table.controller == sac])


#: Levels where the final error must be below 1 deg in the mean and 2 deg at the 95th
#: percentile, and where the RMS reduction must reach the paper's.
_PRECISE_LEVELS = (0, 1, 2)


def paper_checks(table: Any, episodes: Any) -> Any:
    """Add the per-subject and at-least-the-paper's checks to a :func:`compare` table.

    Columns added: ``sac_p95_abs_final_error_deg`` (95th percentile over subjects),
    ``settled_pct`` (subjects whose response settled), ``p95_ok`` (< 2 deg at levels 0-2),
    ``paper_peak_ok`` / ``paper_rms_ok`` (reduction against the PID at least the paper's;
    RMS where the paper gives one), ``settling_ok`` (mean settling time no longer than the paper's
    SAC) and ``all_ok`` (these and :func:`compare`'s ``pass``).
    """
    from myoexo.evaluation.paper import PAPER_RESULTS

    out = table.copy()
    err = episodes.groupby("level").abs_final_error_deg
    out["sac_p95_abs_final_error_deg"] = err.quantile(0.95)
    settled = episodes.groupby("level").settling_time_s.apply(lambda s: 100 * s.notna().mean())
    out["settled_pct"] = settled
    for level in out.index:
        ref = PAPER_RESULTS[int(level)]
        row = out.loc[level]
        precise = int(level) in _PRECISE_LEVELS
        out.loc[level, "p95_ok"] = (not precise) or row.sac_p95_abs_final_error_deg < 2.0
        peak_ref = ref.peak_reduction_pct
        out.loc[level, "paper_peak_ok"] = peak_ref is None or row.peak_reduction_pct >= peak_ref
        rms_ref = ref.rms_reduction_pct
        out.loc[level, "paper_rms_ok"] = (
            not precise or rms_ref is None or row.rms_reduction_pct >= rms_ref
        )
        out.loc[level, "settling_ok"] = bool(
            row.sac_settling_time_s <= ref.sac_settling_time_s and row.settled_pct == 100.0
        )
    flags = ["pass", "p95_ok", "paper_peak_ok", "paper_rms_ok", "settling_ok"]
    for f in flags[1:]:
        out[f] = out[f].astype(bool)
    out["all_ok"] = out[flags].all(axis=1)
    return out


def markdown_table(table: Any) -> str:
    """The comparison as a Markdown table, each of our numbers next to the paper's."""
    import pandas as pd

    from myoexo.evaluation.paper import PAPER_RESULTS

    def num(x: float | None, fmt: str = ".2f") -> str:
        return "n/a" if x is None else format(x, fmt)

    rows = []
    for level, r in table.iterrows():
        ref = PAPER_RESULTS[int(level)]
        failed = [
            name
            for name, ok in (
                ("final error", r.final_error_ok),
                ("peak", r.peak_ok),
                ("RMS", r.rms_ok),
                ("p95 error", getattr(r, "p95_ok", True)),
                ("peak < paper's", getattr(r, "paper_peak_ok", True)),
                ("RMS < paper's", getattr(r, "paper_rms_ok", True)),
                ("settling", getattr(r, "settling_ok", True)),
            )
            if not ok
        ]
        rows.append(
            {
                "level": int(level),
                "final error SAC (deg) [paper]": (
                    f"{r.sac_final_error_deg:.2f} [{ref.sac_final_error_text}]"
                ),
                "p95 abs final error (deg)": (
                    f"{r.sac_p95_abs_final_error_deg:.2f}"
                    if hasattr(r, "sac_p95_abs_final_error_deg")
                    else "n/a"
                ),
                "final error PID (deg) [paper]": (
                    f"{r.pid_final_error_deg:.2f} [{ref.pid_final_error_text}]"
                ),
                "peak SAC / PID (Nm)": f"{r.sac_peak_nm:.1f} / {r.pid_peak_nm:.1f}",
                "peak reduction % [paper]": (
                    f"{r.peak_reduction_pct:.1f} [{num(ref.peak_reduction_pct, '.1f')}]"
                ),
                "RMS SAC / PID (Nm)": f"{r.sac_rms_nm:.1f} / {r.pid_rms_nm:.1f}",
                "RMS reduction % [paper]": (
                    f"{r.rms_reduction_pct:.1f} [{num(ref.rms_reduction_pct, '.1f')}]"
                ),
                "settling SAC (s) [paper]": (
                    f"{r.sac_settling_time_s:.2f} [{ref.sac_settling_time_s}]"
                ),
                "criteria": "pass" if not failed else "fails: " + ", ".join(failed),
            }
        )
    return str(pd.DataFrame(rows).to_markdown(index=False))


@dataclass(frozen=True)
class SelectRun:
    """What ``myoexo policy select`` reads (a run folder, or with ``table`` an evaluation
    folder) and where it writes its table."""

    run: Path = option(Path(), "run folder, or an evaluation folder with --table", flag="")
    table: bool = option(
        False,
        "print the Markdown criteria table of `myoexo evaluate --controllers pid sac` output "
        "in RUN instead",
    )
    controller: str = option(
        "sac", "with --table: the controller compared with the PID", metavar="CONTROLLER"
    )
    out: Path | None = option(
        None,
        "also write the comparison table: FILE.md (Markdown, next to the paper's numbers) or "
        "FILE.csv (with the chosen checkpoint in a column)",
        metavar="FILE",
    )

    def __post_init__(self) -> None:
        check_fields(self)
        if self.out is not None and self.out.suffix not in (".md", ".csv"):
            raise FieldError("SelectRun", "out", str(self.out), "must end in .md or .csv")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo policy select`` (and ``python -m myoexo.training.select``):
    :class:`SelectRun` and :class:`SelectionConfig`."""
    add_positional(parser, SelectRun, "run")
    add_options(parser, SelectRun, exclude=("out",))
    add_options(parser, SelectionConfig, exclude=("workers",))
    add_options(parser, SelectRun, exclude=("table", "controller"))


def run(args: argparse.Namespace) -> int:
    """Print the chosen checkpoint and its table (or, with ``--table``, the criteria table
    of an evaluation folder); write it to ``--out`` if given."""
    config = from_options(SelectionConfig, args)
    options: SelectRun = from_options(SelectRun, args, run=args.run)
    chosen = None
    if options.table:
        table = compare_evaluation(options.run, sac=options.controller)
        table = table[table.index.isin(config.levels)]
        print(markdown_table(table))
    else:
        if config.last == 0 and not (options.run / ck.EVAL_FILE).is_file():
            raise ValueError(f"--top needs the run's {ck.EVAL_FILE}; {options.run} has none")
        chosen, table = select_with(options.run, config)
        print(f"chosen: {chosen}")
        print(table.round(2).to_string())
    if options.out is not None:
        options.out.parent.mkdir(parents=True, exist_ok=True)
        if options.out.suffix == ".md":
            head = "" if chosen is None else f"chosen: `{chosen}`\n\n"
            options.out.write_text(head + markdown_table(table) + "\n")
        else:
            table = table if chosen is None else table.assign(checkpoint=str(chosen))
            table.to_csv(options.out)
        print(f"wrote {options.out}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m myoexo.training.select RUN`` (same as ``myoexo policy select RUN``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
