"""``myoexo twin recovery``: does ``fit-subject`` recover simulated people, and does the
fitted twin predict what a controller does to them?

The method's own test, on subjects of a root nothing else uses (:data:`RECOVERY_ROOT_SEED`)::

    myoexo twin recovery --subjects 50 --out docs/studies/recovery [--budget 500] [--workers N]

**Per subject** (subject ``i`` has level ``i mod 4`` and the seed
:func:`~myoexo.evaluation.subject_seed` ``(level, i, root)``):

1. *Recordings*, made through the public API
   (:func:`~myoexo.clinical.recording.record_from_twin`, the default sensor noise:
   goniometer 0.5 deg and 2 deg/s, torque 0.5 Nm): the seated pendulum, the slow and the fast
   passive stretch (with the exo's torque), the Tardieu R1/R2 and the MAS grade.
2. *The fit* (:func:`~myoexo.studies.fit_subject.fit_subject`, CMA-ES with ``--budget``
   evaluations, the diagonal Hessian for the intervals). At level 0 the reflex is off (its
   gains are zero), so only the passive knee's two scales are fitted there.
3. *Recovery*: each fitted parameter against its truth (the synthetic subject's reflex
   record; the passive knee's scales are 1: the recordings are made on the twin's own knee),
   as an error in the parameter's unit and as a fraction of its bounds.
4. *Prediction*: one episode of each controller (``--controllers``: the paper's PID and the
   shipped learned controller) on the subject's true twin and on the fitted twin (the point
   fit, :class:`~myoexo.spasticity.personal.PersonalSubject`), from the same episode seed
   (the same start angle): the final error and the peak interaction torque on each.

**Targets** (:data:`TARGETS`): the fitted twin predicts the paper's PID's final error within
1.5 deg and its peak interaction torque within 10 % for at least 90 % of the subjects; the
fit's RMS angle error on the stretches is at most van der Krogt et al. 2016's 1.1 / 5.9 deg
(slow / fast).

**Output** (``--out``): ``subjects.csv`` (one row per subject: truth, fit, errors, the RMS of
each trace, the predictions), ``parameters.csv`` (each parameter's recovery error by level),
``predictions.csv`` (each controller's prediction errors and pass rates by level),
``recovery.json`` (the summary, the targets and the provenance) and ``recovery.md``. Each
subject's recordings, fit report and row are kept under ``subjects/`` and a row found there
is not recomputed, so a stopped run continues where it stopped; the tables are made from the
rows present (``--summarise-only`` makes them without running anything).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.evaluation.config import RECOVERY_ROOT_SEED, subject_seed
from myoexo.runtime.fields import add_options, from_options, option
from myoexo.spasticity.levels import VALID_LEVELS

__all__ = [
    "RECORDED_TESTS",
    "TARGETS",
    "RecoverySettings",
    "add_arguments",
    "recover_subject",
    "run",
    "run_recovery",
    "summarise",
]

#: The recordings made of every subject.
RECORDED_TESTS: tuple[str, ...] = ("pendulum", "stretch-slow", "stretch-fast", "tardieu", "mas")

#: The issue's targets: prediction of the paper's PID, and the share of subjects that must
#: meet both.
TARGETS: Mapping[str, float] = {
    "final_error_within_deg": 1.5,
    "peak_torque_within_fraction": 0.10,
    "subjects_fraction": 0.90,
}

#: Fitted at level 0, where the reflex's gains are zero.
_LEVEL0_PARAMETERS = ("stiffness_scale", "damping_scale")


@dataclasses.dataclass(frozen=True)
class RecoverySettings:
    """What ``myoexo twin recovery`` runs."""

    out: Path = option(Path("recovery"), "output folder", metavar="DIR", folder=True)
    subjects: int = option(50, "simulated subjects, levels 0-3 in turn", low=1, high=10000)
    root_seed: int = option(
        RECOVERY_ROOT_SEED, "root seed of the subjects (the recovery root)", low=0, flag="seed"
    )
    budget: int = option(500, "CMA-ES evaluations per fit (whole generations)", low=10)
    level0_budget: int = option(
        60, "CMA-ES evaluations at level 0 (the passive knee's two scales)", low=10
    )
    controllers: tuple[str, ...] = option(
        ("pid", "sac"), "controllers whose outcome the fitted twin predicts", metavar="SPEC"
    )
    workers: int = option(1, "processes (one subject each at a time)", low=1, high=256, metavar="N")
    summarise_only: bool = option(False, "make the tables from the rows present; run nothing")


# ----------------------------------------------------------------------------- one subject
def _subject_plan(index: int, root: int) -> tuple[int, int]:
    level = VALID_LEVELS[index % len(VALID_LEVELS)]
    return level, subject_seed(level, index, root)


def _episode(env_id: str, subject: Any, spec: str, seed: int) -> dict[str, float]:
    import gymnasium as gym

    from myoexo.control.specs import build_controller, parse_controller_spec
    from myoexo.evaluation.engine import run_episode

    env = gym.make(env_id, subject=subject)
    try:
        result = run_episode(env, build_controller(parse_controller_spec(spec), env), seed)
    finally:
        env.close()
    m = result.metrics
    return {
        "final_error_deg": float(m.abs_final_error_deg),
        "peak_torque_nm": float(m.peak_interaction_torque_nm),
    }


def recover_subject(index: int, settings: RecoverySettings) -> dict[str, Any]:
    """Record, fit and predict subject *index* (module docstring); its row, also written to
    ``subjects/sNNN/row.json`` (read back instead of recomputed if present)."""
    from myoexo.clinical.recording import record_from_twin, write_recording
    from myoexo.spasticity.levels import SpasticityParams
    from myoexo.spasticity.personal import PersonalSubject, load_subject
    from myoexo.studies import fit_subject as fs

    folder = settings.out / "subjects" / f"s{index:03d}"
    row_path = folder / "row.json"
    if row_path.exists():
        return json.loads(row_path.read_text())
    folder.mkdir(parents=True, exist_ok=True)
    level, seed = _subject_plan(index, settings.root_seed)
    t0 = time.perf_counter()
    paths = [folder / f"{test}.csv" for test in RECORDED_TESTS]
    for test, path in zip(RECORDED_TESTS, paths, strict=True):
        if not path.exists():  # a stopped run's recordings are its partial fit's
            write_recording(record_from_twin(test, level, seed), path)
    names = _LEVEL0_PARAMETERS if level == 0 else fs.PARAMETER_NAMES
    fit = fs.FitSettings(
        out=folder / "subject.json",
        level=level,
        budget=settings.budget if level else settings.level0_budget,
        parameters=names,
        uncertainty="diagonal",
        progress=False,
    )
    report = fs.fit_subject(paths, fit)
    fit_s = time.perf_counter() - t0
    truth_subject = report_truth(report)
    person = load_subject(fit.out)
    truth = PersonalSubject.of(level, SpasticityParams(**truth_subject), reflex=person.reflex)
    row: dict[str, Any] = {"index": index, "level": level, "seed": seed, "fit_s": fit_s}
    row["evaluations"] = report["optimiser"]["evaluations"]
    for p in report["parameters"]:
        true_value = float(p["truth"])
        low, high = p["bounds"]
        row[f"{p['name']}_truth"] = true_value
        row[f"{p['name']}_fit"] = float(p["fitted"])
        row[f"{p['name']}_error"] = float(p["fitted"]) - true_value
        row[f"{p['name']}_error_fraction"] = (float(p["fitted"]) - true_value) / (high - low)
        row[f"{p['name']}_identifiable"] = bool(p["identifiable"])
    for t in report["traces"]:
        row[f"{t['test']}_angle_rms_deg"] = t["angle_rms_deg"]
        if "torque_rms_nm" in t:
            row[f"{t['test']}_torque_rms_nm"] = t["torque_rms_nm"]
    env_id = f"MyoExoKnee-v{level}"
    for spec in settings.controllers:
        on_truth = _episode(env_id, truth, spec, seed)
        on_fit = _episode(env_id, person, spec, seed)
        for key in ("final_error_deg", "peak_torque_nm"):
            row[f"{spec}_{key}_truth"] = on_truth[key]
            row[f"{spec}_{key}_fit"] = on_fit[key]
    row["total_s"] = time.perf_counter() - t0
    row_path.write_text(json.dumps(row, indent=1))
    return row


def report_truth(report: Mapping[str, Any]) -> dict[str, float]:
    """The synthetic subject's reflex record a fit report carries (every
    :class:`~myoexo.spasticity.SpasticityParams` field: the fitted ones' ``truth``, the
    others' fit, which is their start, the level's nominal value)."""
    truth = {k: float(v) for k, v in report["subject"].items()}
    for p in report["parameters"]:
        if p["name"] in truth and "truth" in p:
            truth[p["name"]] = float(p["truth"])
    return truth


# ----------------------------------------------------------------------------- the run
def _work(args: tuple[int, RecoverySettings]) -> dict[str, Any]:
    index, settings = args
    return recover_subject(index, settings)


def run_recovery(settings: RecoverySettings) -> list[dict[str, Any]]:
    """Every subject's row (computed, or read from ``subjects/``)."""
    indices = list(range(settings.subjects))
    # the spastic subjects' fits are the long ones: start them first
    indices.sort(key=lambda i: _subject_plan(i, settings.root_seed)[0] == 0)
    if settings.workers == 1:
        return [recover_subject(i, settings) for i in indices]
    import multiprocessing as mp

    from tqdm import tqdm

    ctx = mp.get_context("spawn")
    rows = []
    with ctx.Pool(settings.workers, maxtasksperchild=4) as pool:
        jobs = pool.imap_unordered(_work, [(i, settings) for i in indices])
        for row in tqdm(jobs, total=len(indices), desc="recovery", unit="subject"):
            rows.append(row)
    return rows


def _rows_present(out: Path) -> list[dict[str, Any]]:
    return [json.loads(p.read_text()) for p in sorted((out / "subjects").glob("s*/row.json"))]


def _ci(x: np.ndarray) -> list[float]:
    """Mean and its 95 % interval (normal approximation over subjects)."""
    n = x.size
    mean = float(np.mean(x))
    half = 1.96 * float(np.std(x, ddof=1)) / math.sqrt(n) if n > 1 else math.nan
    return [mean, mean - half, mean + half]


def summarise(rows: Sequence[Mapping[str, Any]], settings: RecoverySettings) -> dict[str, Any]:
    """The tables and the summary of the rows (module docstring); writes them to ``--out``."""
    import pandas as pd

    from myoexo.model.params import TWIN_VERSION
    from myoexo.runtime.fits import provenance
    from myoexo.studies.fit_subject import PARAMETERS, VAN_DER_KROGT_2016_RMS_DEG

    out = settings.out
    df = pd.DataFrame(list(rows)).sort_values("index").reset_index(drop=True)
    df.to_csv(out / "subjects.csv", index=False)
    param_rows = []
    for p in PARAMETERS:
        col = f"{p.name}_error"
        if col not in df:
            continue
        for level, g in [*df.groupby("level"), ("all", df)]:
            e = g[col].dropna()
            if e.empty:
                continue
            param_rows.append({
                "parameter": p.name, "unit": p.unit, "level": level, "subjects": int(e.size),
                "mean_abs_error": float(e.abs().mean()),
                "median_abs_error": float(e.abs().median()),
                "mean_abs_error_fraction_of_bounds": float(g[f"{col}_fraction"].abs().mean()),
                "bias": float(e.mean()),
                "identifiable_fraction": float(g[f"{p.name}_identifiable"].mean()),
            })  # fmt: skip
    params = pd.DataFrame(param_rows)
    params.to_csv(out / "parameters.csv", index=False)

    pred_rows = []
    tol_deg, tol_frac = TARGETS["final_error_within_deg"], TARGETS["peak_torque_within_fraction"]
    for spec in settings.controllers:
        fe_t, fe_f = df[f"{spec}_final_error_deg_truth"], df[f"{spec}_final_error_deg_fit"]
        pk_t, pk_f = df[f"{spec}_peak_torque_nm_truth"], df[f"{spec}_peak_torque_nm_fit"]
        df[f"{spec}_final_error_miss_deg"] = (fe_f - fe_t).abs()
        df[f"{spec}_peak_miss_fraction"] = (pk_f - pk_t).abs() / pk_t
        df[f"{spec}_both_within"] = (df[f"{spec}_final_error_miss_deg"] <= tol_deg) & (
            df[f"{spec}_peak_miss_fraction"] <= tol_frac
        )
        for level, g in [*df.groupby("level"), ("all", df)]:
            pred_rows.append({
                "controller": spec, "level": level, "subjects": len(g),
                "final_error_miss_deg_mean": float(g[f"{spec}_final_error_miss_deg"].mean()),
                "final_error_miss_deg_max": float(g[f"{spec}_final_error_miss_deg"].max()),
                "final_error_within_fraction": float(
                    (g[f"{spec}_final_error_miss_deg"] <= tol_deg).mean()),
                "peak_miss_fraction_mean": float(g[f"{spec}_peak_miss_fraction"].mean()),
                "peak_miss_fraction_max": float(g[f"{spec}_peak_miss_fraction"].max()),
                "peak_within_fraction": float((g[f"{spec}_peak_miss_fraction"] <= tol_frac).mean()),
                "both_within_fraction": float(g[f"{spec}_both_within"].mean()),
            })  # fmt: skip
    preds = pd.DataFrame(pred_rows)
    preds.to_csv(out / "predictions.csv", index=False)

    fits = {}
    for test, speed in (("stretch-slow", "slow"), ("stretch-fast", "fast")):
        col = f"{test}_angle_rms_deg"
        if col in df:
            x = df[col].to_numpy(float)
            fits[test] = {
                "angle_rms_deg": _ci(x),
                "max": float(x.max()),
                "van_der_krogt_2016_rms_deg": VAN_DER_KROGT_2016_RMS_DEG[speed],
                "met": bool(np.all(x <= VAN_DER_KROGT_2016_RMS_DEG[speed])),
            }
    pid = settings.controllers[0]
    share = float(df[f"{pid}_both_within"].mean())
    summary = {
        "subjects": len(df),
        "subjects_by_level": {
            str(k): int(v) for k, v in df["level"].value_counts().sort_index().items()
        },
        "root_seed": settings.root_seed,
        "budget": settings.budget,
        "level0_budget": settings.level0_budget,
        "targets": dict(TARGETS),
        "prediction_target": {
            "controller": pid,
            "both_within_fraction": share,
            "met": share >= TARGETS["subjects_fraction"],
        },
        "stretch_fits": fits,
        "fit_minutes_per_subject": _ci(df["fit_s"].to_numpy(float) / 60.0),
        "provenance": provenance(_command(settings), TWIN_VERSION),
    }
    (out / "recovery.json").write_text(json.dumps(summary, indent=1, default=str))
    (out / "recovery.md").write_text(format_summary(summary, params, preds))
    return summary


def format_summary(summary: Mapping[str, Any], params: Any, preds: Any) -> str:
    """The Markdown page of a recovery run."""
    t = summary["prediction_target"]
    lines = [
        "# Parameter recovery of `myoexo twin fit-subject`",
        "",
        f"{summary['subjects']} simulated subjects (root {summary['root_seed']}, by level "
        f"{summary['subjects_by_level']}), CMA-ES budget {summary['budget']} "
        f"({summary['level0_budget']} at level 0). Command: "
        f"`{summary['provenance']['command']}`.",
        "",
        f"**Prediction target** ({t['controller']}: final error within "
        f"{TARGETS['final_error_within_deg']:g} deg and peak interaction torque within "
        f"{TARGETS['peak_torque_within_fraction']:.0%} for at least "
        f"{TARGETS['subjects_fraction']:.0%} of the subjects): "
        f"{t['both_within_fraction']:.0%} of the subjects, "
        f"**{'met' if t['met'] else 'missed'}**.",
        "",
        "## Fit quality on the stretches (RMS angle error, deg; mean [95 % CI], max)",
        "",
        "| recording | mean [95 % CI] | max | van der Krogt 2016 | met (every subject) |",
        "|---|---|---|---|---|",
    ]
    for test, f in summary["stretch_fits"].items():
        m, lo, hi = f["angle_rms_deg"]
        lines.append(
            f"| {test} | {m:.2f} [{lo:.2f}, {hi:.2f}] | {f['max']:.2f} | "
            f"{f['van_der_krogt_2016_rms_deg']:g} | {'yes' if f['met'] else 'no'} |"
        )
    lines += ["", "## Predictions (fitted twin against the true twin, same episode seed)", ""]
    lines.append(preds.to_markdown(index=False, floatfmt=".3g"))
    lines += ["", "## Recovery error of each parameter (fit - truth)", ""]
    lines.append(params.to_markdown(index=False, floatfmt=".3g"))
    lines.append("")
    return "\n".join(lines)


def _command(settings: RecoverySettings) -> str:
    return (
        f"myoexo twin recovery --subjects {settings.subjects} --seed {settings.root_seed} "
        f"--budget {settings.budget} --level0-budget {settings.level0_budget} --controllers "
        + " ".join(settings.controllers)
    )


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin recovery``: :class:`RecoverySettings`' fields."""
    add_options(parser, RecoverySettings)


def run(args: argparse.Namespace) -> int:
    """Run the subjects (or only summarise), write the tables, print the page."""
    settings = from_options(RecoverySettings, args)
    settings.out.mkdir(parents=True, exist_ok=True)
    if not settings.summarise_only:
        os.environ.setdefault("OMP_NUM_THREADS", "1")
        run_recovery(settings)
    rows = _rows_present(settings.out)
    if not rows:
        print(f"myoexo twin recovery: no subject rows in {settings.out}", file=sys.stderr)
        return 2
    summarise(rows, settings)
    print((settings.out / "recovery.md").read_text())
    return 0
