"""The results of a sweep: the evaluations of each trial's run (its ``eval.csv``) scored on
the acceptance criteria (:func:`evaluation_metrics`), and the table that ranks the trials on
their best evaluation (:func:`results_table`; ``results.parquet`` and ``results.md``)."""

from __future__ import annotations

import csv
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

from myoexo.evaluation import criteria
from myoexo.evaluation.criteria import CRITERIA_METRICS
from myoexo.studies.sweep.spec import RESULTS_STEM, RUNS_DIR, SweepSpec, trial_config
from myoexo.training import checkpoints as ck


# ----------------------------------------------------------------------------- metrics
def read_eval_rows(run_dir: Path) -> dict[tuple[int, int], dict[str, float]]:
    """The rows of a run's ``eval.csv`` keyed by ``(step, level)``: a step evaluated again
    after a resume keeps its newest row, and a row cut short by a kill is skipped."""
    path = Path(run_dir) / ck.EVAL_FILE
    rows: dict[tuple[int, int], dict[str, float]] = {}
    if not path.is_file():
        return rows
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            try:
                values = {k: float(v) for k, v in row.items() if k is not None}
                if None in row or len(values) != len(row):
                    continue
                rows[(int(values["step"]), int(values["level"]))] = values
            except (KeyError, TypeError, ValueError):
                continue
    return rows


def evaluation_metrics(
    run_dir: Path, levels: Sequence[int], after: int = -1
) -> list[dict[str, Any]]:
    """One dict per evaluated step after step ``after`` of a run (every level present),
    oldest first: the step, :func:`~myoexo.evaluation.criteria.ranking_score`,
    :func:`~myoexo.evaluation.criteria.shortfall`, ``passes`` (every criterion met), the mean
    peak-torque reduction against the PID, the fraction of unstable episodes, and per level
    ``L<l>_abs_final_error_deg``, ``L<l>_peak_reduction_pct``, ``L<l>_rms_reduction_pct``
    and ``L<l>_pass``."""
    pid_path = Path(run_dir) / ck.EVAL_PID_FILE
    rows = read_eval_rows(run_dir)
    if not rows or not pid_path.is_file():
        return []
    pid = {int(k): v for k, v in json.loads(pid_path.read_text()).items()}
    out = []
    for step in sorted({s for s, _ in rows if s > after}):
        if not all((step, lv) in rows and lv in pid for lv in levels):
            continue
        sac = {lv: {m: rows[(step, lv)][m] for m in CRITERIA_METRICS} for lv in levels}
        table = criteria.compare_with_pid(sac, {lv: pid[lv] for lv in levels})
        metrics: dict[str, Any] = {
            "step": int(step),
            "score": criteria.ranking_score(table),
            "shortfall": criteria.shortfall(table),
            "passes": bool(table["pass"].all()),
            "mean_peak_reduction_pct": float(table.peak_reduction_pct.mean()),
            "unstable_fraction": float(
                sum(rows[(step, lv)].get("unstable", 0.0) for lv in levels) / len(levels)
            ),
        }
        for lv, r in table.iterrows():
            metrics[f"L{lv}_abs_final_error_deg"] = float(r.sac_abs_final_error_deg)
            metrics[f"L{lv}_peak_reduction_pct"] = float(r.peak_reduction_pct)
            metrics[f"L{lv}_rms_reduction_pct"] = float(r.rms_reduction_pct)
            metrics[f"L{lv}_pass"] = bool(r["pass"])
        out.append(metrics)
    return out


def rank_key(metrics: Mapping[str, Any]) -> tuple[float, float]:
    """Order of evaluations and trials (smaller is better): shortfall, then the negated
    mean peak-torque reduction (as ``myoexo policy select`` orders checkpoints)."""
    shortfall = float(metrics.get("shortfall", math.inf))
    peak = float(metrics.get("mean_peak_reduction_pct", -math.inf))
    return (shortfall if math.isfinite(shortfall) else math.inf, -peak)


# ----------------------------------------------------------------------------- the table
def _scalar(value: Any) -> Any:
    """A table cell: numbers and text as they are, anything else as text."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return json.dumps(value)


def _run_steps(run_dir: Path) -> int:
    last = ck.latest_checkpoint(run_dir)
    return int(ck.read_state(last)["num_timesteps"]) if last is not None else 0


def results_table(spec: SweepSpec, sweep_dir: Path, trials: Sequence[Mapping[str, Any]]) -> Any:
    """The ranked table of a sweep: one row per trial (``trials``: dicts with ``trial_id``,
    ``config`` and ``error``), on each trial's best evaluation (:func:`rank_key`)."""
    import pandas as pd

    rows = []
    for trial in trials:
        config = trial["config"]
        run_dir = sweep_dir / RUNS_DIR / trial["trial_id"]
        train_config = trial_config(config)
        evals = evaluation_metrics(run_dir, train_config.eval_levels) if run_dir.is_dir() else []
        steps = _run_steps(run_dir) if run_dir.is_dir() else 0
        if trial.get("error"):
            status = "error"
        elif steps >= train_config.total_timesteps:
            status = "done"
        else:
            status = "stopped"  # by the scheduler, or interrupted
        row: dict[str, Any] = {
            "trial": trial["trial_id"],
            "status": status,
            "preset": config["preset"],
            "seed": train_config.seed,
        }
        for key, value in config["search"].items():
            if key == "algorithm_kwargs":
                row.update({k: _scalar(v) for k, v in value.items()})
            else:
                row[key] = _scalar(value)
        row.update({f"w_{k}": float(v) for k, v in config["reward_weights"].items()})
        row.update(steps=steps, evaluations=len(evals))
        best = min(evals, key=rank_key) if evals else {}
        row["best_step"] = best.get("step")
        for key in ("shortfall", "passes", "mean_peak_reduction_pct", "score"):
            row[key] = best.get(key)
        for lv in train_config.eval_levels:
            for metric in ("abs_final_error_deg", "peak_reduction_pct"):
                row[f"L{lv}_{metric}"] = best.get(f"L{lv}_{metric}")
        row["last_step"] = evals[-1]["step"] if evals else None
        row["last_score"] = evals[-1]["score"] if evals else None
        row["run_dir"] = str(Path(RUNS_DIR) / trial["trial_id"])
        row["_key"] = rank_key(best)
        rows.append(row)
    rows.sort(key=lambda r: r["_key"])
    for i, row in enumerate(rows, start=1):
        row.pop("_key")
        row["rank"] = i
    table = pd.DataFrame(rows)
    if not table.empty:
        table = table[["rank", *[c for c in table.columns if c != "rank"]]]
    return table


def write_results(sweep_dir: Path, table: Any, spec: SweepSpec) -> tuple[Path, Path]:
    """``results.parquet`` and ``results.md`` (the table under a short heading)."""
    from myoexo.runtime.files import atomic_path, write_text_atomic

    parquet = sweep_dir / f"{RESULTS_STEM}.parquet"
    with atomic_path(parquet) as tmp:
        table.to_parquet(tmp, index=False)
    md = sweep_dir / f"{RESULTS_STEM}.md"
    heading = (
        f"# Sweep {spec.name}\n\n{len(table)} trials ranked on their best periodic "
        "evaluation against the PID: shortfall from the acceptance criteria (0 = every "
        "criterion met), then mean peak interaction-torque reduction (%).\n\n"
    )
    write_text_atomic(md, heading + table.to_markdown(index=False, floatfmt=".4g") + "\n")
    return parquet, md
