"""The gentleness setting of a policy trained over the weight range: its points across the
range, per level, against the paper's PID, and the default weight chosen on the selection
root.

    myoexo policy gentleness sbx_sac:runs/g/checkpoints/step_0001500000/model.zip \\
        --subjects 20 --out results/gentleness
    myoexo policy gentleness POLICY --no-classical   # against the paper's PID alone

A policy trained with ``--gentleness random`` (:class:`~myoexo.envs.options.TwinOptions`)
takes a weight in [0, 1] as its last input: 0 prices speed alone (the study's reward), 1
prices the interaction torque's peak and square in full (the env's ``gentle`` reward term).
This command runs the policy at each of ``--weights`` (``POLICY@W``,
:class:`~myoexo.control.policy.GentleController`) and the paper's PID on the same subjects
of the **selection root** (root seed 1; the evaluation root is refused) through the
evaluation protocol (resumable, in ``OUT/selection``), and compares each weight with the PID
per level (:func:`~myoexo.evaluation.criteria.compare_with_pid`: final error, peak and RMS
interaction torque) and on settling time. With the classical controllers (the default: the
frontier's, :func:`~myoexo.studies.frontier.classical_specs`, on the same subjects) it also
says, per level, which weight is at least as good as the most of them on peak torque, RMS
torque and settling time at an equal or better final error (:func:`dominance`).

The **default weight** is the one closest to meeting the study's claims against the PID:
the smallest :func:`~myoexo.evaluation.criteria.shortfall` plus the relative excess of the
settling time over the PID's, summed over levels; a tie goes to the larger mean peak and RMS
reductions at levels 1-2 (the study's headline). It is written with its provenance to
``OUT/gentleness.json``, which ``myoexo policy export --gentleness-record`` copies into the
exported policy's metadata (``default_gentleness``). Files: ``gentleness.json``,
``gentleness.md`` (one row per weight and level) and ``gentleness.png`` (settling time
against peak torque per level: the weights as one curve, the PID and the classical
controllers) and ``dominance.csv``. :func:`recount` counts a finished study's matches again
from these files, without running an episode.
"""

from __future__ import annotations

import argparse
import json
import math
import shlex
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.envs.options import TwinOptions, add_twin_arguments, twin_from_args, twin_words
from myoexo.evaluation.config import SELECTION_ROOT_SEED, check_fit_root
from myoexo.runtime.fields import (
    Execution,
    add_options,
    add_positional,
    check_fields,
    from_options,
    option,
    option_words,
)
from myoexo.spasticity.levels import VALID_LEVELS
from myoexo.studies.frontier import classical_specs
from myoexo.training.export import GENTLENESS_RECORD_FILE as RECORD_FILE

#: The weights a default run compares (the range's ends and three between).
DEFAULT_WEIGHTS: tuple[float, ...] = (0.0, 0.25, 0.5, 0.75, 1.0)
#: Levels of the study's headline (the mean of its peak and RMS reductions over them).
HEADLINE_LEVELS: tuple[int, ...] = (1, 2)
#: The measures a weight must match a classical controller on (means over subjects).
DOMINANCE_METRICS: tuple[str, ...] = (
    "abs_final_error_deg",
    "settling_time_s",
    "peak_interaction_torque_nm",
    "rms_interaction_torque_nm",
)


@dataclass(frozen=True)
class GentlenessConfig:
    """What ``myoexo policy gentleness`` runs (each field is an option of the command)."""

    policy: str = option("", "spec of a policy trained over the gentleness range", flag="")
    weights: tuple[float, ...] = option(
        DEFAULT_WEIGHTS, "weights to compare", low=0.0, high=1.0, metavar="W"
    )
    subjects: int = option(20, "selection subjects per level", low=1)
    levels: tuple[int, ...] = option(
        VALID_LEVELS, "spasticity levels", choices=VALID_LEVELS, metavar="LEVEL"
    )
    root_seed: int = option(
        SELECTION_ROOT_SEED, "root seed of the subjects (never the evaluation root)", low=0
    )
    out: Path = option(Path("results/gentleness"), "output folder", folder=True, metavar="DIR")
    classical: bool = option(
        True,
        "also run the frontier's classical controllers on the same subjects and say which of "
        "them some weight matches or beats (--no-classical: the PID alone)",
    )

    def __post_init__(self) -> None:
        object.__setattr__(self, "weights", tuple(sorted({float(w) for w in self.weights})))
        object.__setattr__(self, "levels", tuple(sorted(set(self.levels))))
        check_fields(self)
        check_fit_root(self.root_seed, "the default gentleness weight")

    def spec(self, weight: float) -> str:
        """The controller spec of the policy at *weight*."""
        return f"{self.policy}@{weight:g}"


def weight_table(table: Any, config: GentlenessConfig) -> Any:
    """One row per weight and level: the policy's per-level means against the PID's
    (:func:`~myoexo.evaluation.criteria.compare_with_pid`) and its settling ratio."""
    import pandas as pd

    from myoexo.control.specs import parse_controller_spec
    from myoexo.evaluation.criteria import compare_with_pid, level_means

    pid = level_means(table[table.controller == "pid"])
    rows = []
    for weight in config.weights:
        label = parse_controller_spec(config.spec(weight)).label
        means = level_means(table[table.controller == label])
        compared = compare_with_pid(means, pid).reset_index()
        compared.insert(0, "weight", weight)
        compared["settling_ratio"] = compared.sac_settling_time_s / compared.pid_settling_time_s
        rows.append(compared)
    return pd.concat(rows, ignore_index=True)


def weight_key(rows: Any) -> tuple[float, float]:
    """Sort key of one weight's rows (lower is better): the shortfall against the study's
    claims plus the settling excess over the PID (infinite at a level where none of its
    episodes settled), then minus the headline reductions."""
    from myoexo.evaluation.criteria import shortfall

    table = rows.set_index("level")
    # a level where no episode settled (NaN): an excess no settling weight has
    excess = float((table.settling_ratio - 1.0).clip(lower=0.0).fillna(math.inf).sum())
    headline = table[table.index.isin(HEADLINE_LEVELS)]
    gain = float((headline.peak_reduction_pct + headline.rms_reduction_pct).mean() / 2)
    return shortfall(table) + excess, -gain if math.isfinite(gain) else math.inf


def classical_means(table: Any, specs: Sequence[str]) -> Any:
    """Per level and classical controller: the means of :data:`DOMINANCE_METRICS`."""
    from myoexo.control.specs import parse_controller_spec

    labels = [parse_controller_spec(s).label for s in specs]
    rows = table[table.controller.isin(labels)]
    return rows.groupby(["level", "controller"])[list(DOMINANCE_METRICS)].mean().reset_index()


def dominance(weights: Any, classical: Any) -> Any:
    """Per level and classical controller: the weights that are at least as good on peak
    torque, RMS torque and settling time at an equal or better final error (lower or equal,
    or both within the level's accuracy bound, :class:`~myoexo.evaluation.criteria.Criteria`).
    A mean settling time of NaN (no episode settled) is slower than any finite one.

    Returns:
        One row per level and classical controller: its means and ``matched_by`` (the
        weights, space-separated; empty: none).
    """
    import pandas as pd

    from myoexo.evaluation.criteria import Criteria

    bounds = Criteria().final_error_deg
    rows = []
    for _, c in classical.iterrows():
        mine = weights[weights.level == c.level]
        bound = bounds[int(c.level)]
        err = mine.sac_abs_final_error_deg
        accurate = (err <= c.abs_final_error_deg) | (
            (err < bound) & (c.abs_final_error_deg < bound)
        )
        # a mean settling time of NaN: settled in no episode, slower than any that settles
        their_settling = c.settling_time_s if math.isfinite(c.settling_time_s) else math.inf
        ok = (
            accurate
            & (mine.sac_peak_nm <= c.peak_interaction_torque_nm)
            & (mine.sac_rms_nm <= c.rms_interaction_torque_nm)
            & (mine.sac_settling_time_s.fillna(math.inf) <= their_settling)
        )
        rows.append({**c.to_dict(), "matched_by": " ".join(f"{w:g}" for w in mine.weight[ok])})
    return pd.DataFrame(rows)


def level_verdicts(table: Any) -> Any:
    """Per level, from a :func:`dominance` table: the weight that matches or beats the most
    classical controllers, how many it does of how many, and those no weight does."""
    import pandas as pd

    rows = []
    for level, group in table.groupby("level"):
        counts: dict[str, int] = {}
        for matched in group.matched_by.fillna(""):
            for w in str(matched).split():
                counts[w] = counts.get(w, 0) + 1
        best = max(counts, key=lambda w: counts[w]) if counts else ""
        unmatched = group.controller[group.matched_by.fillna("").astype(str).str.len() == 0]
        rows.append(
            {
                "level": int(level),
                "best_weight": best,
                "matched": counts.get(best, 0),
                "classical": len(group),
                "every_one": counts.get(best, 0) == len(group),
                "matched_by_no_weight": " ".join(unmatched),
            }
        )
    return pd.DataFrame(rows)


def choose_default(weights: Any) -> float:
    """The default weight of a :func:`weight_table` (:func:`weight_key`'s best)."""
    return float(min(weights.groupby("weight"), key=lambda item: weight_key(item[1]))[0])


def plot(weights: Any, classical: Any = None) -> Any:
    """Settling time against peak interaction torque per level: the policy's weights as a
    curve (each point labelled with its weight), the paper's PID, and the classical
    controllers (a :func:`classical_means` table) if given."""
    import matplotlib.pyplot as plt

    levels = sorted(weights.level.unique())
    fig, axes = plt.subplots(1, len(levels), figsize=(4 * len(levels), 3.6), squeeze=False)
    for ax, level in zip(axes[0], levels, strict=True):
        rows = weights[weights.level == level].sort_values("weight")
        if classical is not None:
            mine = classical[classical.level == level]
            ax.scatter(
                mine.settling_time_s,
                mine.peak_interaction_torque_nm,
                s=14,
                color="0.6",
                label="classical",
            )
        ax.plot(rows.sac_settling_time_s, rows.sac_peak_nm, "o-", color="tab:blue", label="policy")
        for _, r in rows.iterrows():
            ax.annotate(f"{r.weight:g}", (r.sac_settling_time_s, r.sac_peak_nm), fontsize=7)
        first = rows.iloc[0]
        ax.scatter(
            [first.pid_settling_time_s], [first.pid_peak_nm], marker="s", color="k", label="PID"
        )
        ax.set_title(f"level {level}")
        ax.set_xlabel("settling time (s)")
        ax.set_ylabel("peak interaction torque (Nm)")
        ax.grid(alpha=0.3)
    axes[0][0].legend(fontsize=7)
    fig.suptitle("The gentleness weight's points (selection subjects)", fontsize=9)
    fig.tight_layout()
    return fig


def run_gentleness(
    config: GentlenessConfig,
    twin: TwinOptions | None = None,
    execution: Execution | None = None,
) -> dict[str, Any]:
    """Evaluate the weights and the PID, choose the default weight and write the files.

    Returns:
        The record written to ``OUT/gentleness.json``.

    Raises:
        ValueError: The policy takes no weight, or the evaluation was stopped.
    """

    from myoexo.evaluation.config import EvaluationConfig
    from myoexo.evaluation.runner import evaluate
    from myoexo.runtime.files import package_versions

    execution = execution or Execution()
    classical = [s for s in classical_specs() if s != "pid"] if config.classical else []
    specs = ("pid", *classical, *(config.spec(w) for w in config.weights))
    evaluation = EvaluationConfig(
        controllers=specs,
        levels=config.levels,
        subjects=config.subjects,
        root_seed=config.root_seed,
        twin=twin or TwinOptions(),
        selection=True,
    )
    run = evaluate(
        evaluation,
        config.out / "selection",
        workers=execution.workers,
        progress=execution.progress,
    )
    if run.table is None:
        raise ValueError(f"the evaluation was stopped ({run.stopped_by}); run again to finish")
    weights = weight_table(run.table, config)
    means = classical_means(run.table, ["pid", *classical]) if classical else None
    options = [*option_words(config, exclude=("policy",)), *twin_words(evaluation.twin)]
    record = {
        "policy": config.policy,
        "default_gentleness": choose_default(weights),
        "weights": list(config.weights),
        "subjects": config.subjects,
        "levels": list(config.levels),
        "root_seed": config.root_seed,
        "against_classical": [],  # written by write_record
        "rule": "smallest shortfall against the study's claims plus settling excess over the "
        "PID; ties: largest mean peak and RMS reduction at levels 1-2",
        "command": shlex.join(["myoexo", "policy", "gentleness", config.policy, *options]),
        "versions": package_versions(),
    }
    return write_record(config.out, record, weights, means)


def write_record(
    out: Path, record: dict[str, Any], weights: Any, means: Any | None, figure: bool = True
) -> dict[str, Any]:
    """Write a study's files from its per-weight table *weights* (:func:`weight_table`) and
    the classical controllers' means (:func:`classical_means`; ``None``: none were run):
    ``gentleness.csv``, ``dominance.csv``, ``gentleness.md``, ``gentleness.png`` (unless not
    *figure*) and the record *record* (its ``against_classical`` set here). Returns the
    record."""
    default = record["default_gentleness"]
    weights.to_csv(out / "gentleness.csv", index=False)
    cols = [
        "weight", "level", "sac_abs_final_error_deg", "sac_settling_time_s",
        "pid_settling_time_s", "sac_peak_nm", "pid_peak_nm", "peak_reduction_pct",
        "sac_rms_nm", "pid_rms_nm", "rms_reduction_pct", "pass",
    ]  # fmt: skip
    header = (
        f"Policy `{record['policy']}` at each gentleness weight against the paper's PID, "
        f"{record['subjects']} subjects per level of root {record['root_seed']} (selection, "
        f"in-sample). Default weight: **{default:g}**.\n\n"
    )
    text = header + str(weights[cols].round(2).to_markdown(index=False)) + "\n"
    verdicts: list[dict[str, Any]] = []
    if means is not None:
        matched = dominance(weights, means)
        matched.to_csv(out / "dominance.csv", index=False)
        summary = level_verdicts(matched)
        verdicts = summary.to_dict(orient="records")
        text += (
            "\nAgainst the classical controllers on the same subjects: per level, the weight "
            "that is at least as good as the most of them on peak torque, RMS torque and "
            "settling time at an equal or better final error (`dominance.csv`: each one).\n\n"
            + str(summary.to_markdown(index=False))
            + "\n"
        )
    (out / "gentleness.md").write_text(text)
    if figure:
        import matplotlib.pyplot as plt

        fig = plot(weights, means)
        fig.savefig(out / "gentleness.png", dpi=130)
        plt.close(fig)
    record = {**record, "against_classical": verdicts}
    (out / RECORD_FILE).write_text(json.dumps(record, indent=1) + "\n")
    return record


def recount(out: Path | str) -> dict[str, Any]:
    """Count a finished study's matches again from its own files (``gentleness.csv`` and
    the classical means in ``dominance.csv``; no episode is run) and rewrite them
    (:func:`write_record`; the figure, which shows no count, is kept), e.g. after a change
    of :func:`dominance`. The record keeps its command and versions and gains
    ``recounted_with`` (the versions that counted)."""
    import pandas as pd

    from myoexo.runtime.files import package_versions

    out = Path(out)
    record = json.loads((out / RECORD_FILE).read_text())
    weights = pd.read_csv(out / "gentleness.csv")
    path = out / "dominance.csv"
    means = pd.read_csv(path).drop(columns="matched_by") if path.exists() else None
    record["recounted_with"] = package_versions()
    return write_record(out, record, weights, means, figure=False)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo policy gentleness``."""
    add_positional(parser, GentlenessConfig, "policy")
    add_options(parser, GentlenessConfig, exclude=("policy",))
    add_twin_arguments(parser)
    add_options(parser.add_argument_group("how to run"), Execution)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo policy gentleness``."""
    config = from_options(GentlenessConfig, args, policy=args.policy)
    record = run_gentleness(config, twin_from_args(args), from_options(Execution, args))
    print((config.out / "gentleness.md").read_text())
    print(f"default weight {record['default_gentleness']:g}; wrote {config.out}/{RECORD_FILE}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    """``python -m myoexo.studies.gentleness POLICY`` (same as ``myoexo policy gentleness``)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
