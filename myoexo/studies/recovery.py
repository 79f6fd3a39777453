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
5. *Personalisation* (``--personalise``): on the true twin, the paper's PID against the PID
   the project's tuner (Ziegler-Nichols, ``myoexo twin tune-pid``) sets on the fitted twin,
   and, as a control, on the true twin (where the tuner finds no sustained oscillation, the
   paper's PID is kept).

**Targets** (:data:`TARGETS`): the fitted twin predicts the paper's PID's final error within
1.5 deg and its peak interaction torque within 10 % for at least 90 % of the subjects; the
fit's RMS angle error on the stretches is at most van der Krogt et al. 2016's 1.1 / 5.9 deg
(slow / fast).

**Output** (``--out``): ``subjects.csv`` (one row per subject: truth, fit, errors, the RMS of
each trace, the predictions), ``parameters.csv`` (each parameter's recovery error by level),
``predictions.csv`` (each controller's prediction errors and pass rates by level),
``personalisation.csv`` (the person's PID against the paper's), ``recovery.json`` (the
summary, the targets and the provenance) and ``recovery.md``. Each subject's recordings, fit
report, row and personalisation are kept under ``subjects/`` and what is found there is not
recomputed, so a stopped run continues where it stopped; the tables are made from the rows
present (``--summarise-only`` makes them without running anything).
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import shlex
import sys
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.evaluation.config import RECOVERY_ROOT_SEED, check_fit_root, subject_seed
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    check_fields,
    from_options,
    option,
    option_words,
)
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
    personalise: bool = option(
        True,
        "also compare, on each true twin, the paper's PID with the PID the project's tuner "
        "sets on the fitted twin (and on the true one)",
    )
    summarise_only: bool = option(False, "make the tables from the rows present; run nothing")

    def __post_init__(self) -> None:
        check_fields(self)
        check_fit_root(self.root_seed, "a recovery run (it fits its subjects)")
        object.__setattr__(self, "controllers", tuple(self.controllers))
        if not self.controllers:
            raise FieldError(type(self).__name__, "controllers", (), "is empty: name one")


# ----------------------------------------------------------------------------- one subject
def _subject_plan(index: int, root: int) -> tuple[int, int]:
    level = VALID_LEVELS[index % len(VALID_LEVELS)]
    return level, subject_seed(level, index, root)


def _episode(env_id: str, subject: Any, spec: str, seed: int) -> dict[str, float]:
    """One episode of *spec* on the twin of *subject*: final error, peak and RMS interaction
    torque, settling time (NaN: not settled)."""
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
        "rms_torque_nm": float(m.rms_interaction_torque_nm),
        "settling_time_s": float(m.settling_time_s),
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


def _truth_of(folder: Path, level: int) -> Any:
    from myoexo.spasticity.levels import SpasticityParams
    from myoexo.spasticity.personal import PersonalSubject

    report = json.loads((folder / "subject.json").read_text())
    subject = SpasticityParams(**report_truth(report))
    return PersonalSubject.of(level, subject, reflex=str(report["reflex"]))


def _tuned_spec(env_id: str, subject: Any, level: int, seed: int) -> tuple[str, str]:
    """The PID spec the project's tuner (Ziegler-Nichols, ``myoexo twin tune-pid``) gives on
    the twin of *subject*, and why not (``""``: tuned). A twin on which the tuner finds no
    sustained oscillation keeps the paper's PID."""
    import gymnasium as gym

    from myoexo.control.ziegler_nichols import ZieglerNicholsSettings, tune

    env = gym.make(env_id, subject=subject)
    try:
        g = tune(ZieglerNicholsSettings(level=level, seed=seed), env=env).gains
    except RuntimeError as exc:
        return "pid", str(exc)
    finally:
        env.close()
    return f"pid:kp={g.kp:.6g},ki={g.ki:.6g},kd={g.kd:.6g}", ""


def personalise_subject(index: int, settings: RecoverySettings) -> dict[str, Any]:
    """Personalisation on subject *index* (module docstring): the paper's PID (generic)
    against the PID the project's tuner sets on the fitted twin (personal) and on the true
    twin (the tuner's own effect, free of the fit's error), each run on the true twin; also
    written to ``subjects/sNNN/personal.json`` (read back if present)."""
    folder = settings.out / "subjects" / f"s{index:03d}"
    path = folder / "personal.json"
    if path.exists():
        return json.loads(path.read_text())
    row = recover_subject(index, settings)
    level, seed = int(row["level"]), int(row["seed"])
    env_id = f"MyoExoKnee-v{level}"
    truth = _truth_of(folder, level)
    out: dict[str, Any] = {"index": index, "level": level, "seed": seed}
    specs = {"generic": "pid"}
    for name, subject in (("personal", str(folder / "subject.json")), ("tuned_on_truth", truth)):
        specs[name], why = _tuned_spec(env_id, subject, level, seed)
        out[f"{name}_tuner_failed"] = why
    for name, spec in specs.items():
        out[f"{name}_spec"] = spec
        for key, value in _episode(env_id, truth, spec, seed).items():
            out[f"{name}_{key}"] = value
    path.write_text(json.dumps(out, indent=1))
    return out


# ----------------------------------------------------------------------------- the run
def _work(args: tuple[int, RecoverySettings]) -> dict[str, Any]:
    index, settings = args
    row = recover_subject(index, settings)
    if settings.personalise:
        personalise_subject(index, settings)
    return row


def run_recovery(settings: RecoverySettings) -> list[dict[str, Any]]:
    """Every subject's row (computed, or read from ``subjects/``)."""
    indices = list(range(settings.subjects))
    # the spastic subjects' fits are the long ones: start them first
    indices.sort(key=lambda i: _subject_plan(i, settings.root_seed)[0] == 0)
    if settings.workers == 1:
        return [_work((i, settings)) for i in indices]
    import multiprocessing as mp

    from tqdm import tqdm

    ctx = mp.get_context("spawn")
    rows = []
    with ctx.Pool(settings.workers, maxtasksperchild=4) as pool:
        jobs = pool.imap_unordered(_work, [(i, settings) for i in indices])
        for row in tqdm(jobs, total=len(indices), desc="recovery", unit="subject"):
            rows.append(row)
    return rows


def _rows_present(out: Path, name: str = "row.json") -> list[dict[str, Any]]:
    return [json.loads(p.read_text()) for p in sorted((out / "subjects").glob(f"s*/{name}"))]


#: The metrics compared in the personalisation table, and whether lower is better.
_PERSONAL_METRICS: Mapping[str, str] = {
    "final_error_deg": "deg",
    "peak_torque_nm": "Nm",
    "rms_torque_nm": "Nm",
    "settling_time_s": "s",
}


def personalisation_table(rows: Sequence[Mapping[str, Any]]) -> Any:
    """Per level and over all: each metric of the generic PID, of the personal PIDs, and the
    personal minus generic difference (negative: the person's PID is lower) with its 95 %
    interval over subjects; settling over the subjects where both settled."""
    import pandas as pd

    df = pd.DataFrame(list(rows))
    out = []
    for level, g in [*df.groupby("level"), ("all", df)]:
        for who in ("personal", "tuned_on_truth"):
            for metric, unit in _PERSONAL_METRICS.items():
                a, b = g[f"generic_{metric}"].to_numpy(float), g[f"{who}_{metric}"].to_numpy(float)
                both = np.isfinite(a) & np.isfinite(b)
                d = b[both] - a[both]
                mean, lo, hi = _ci(d) if d.size else [math.nan] * 3
                out.append({
                    "level": level, "pid": who, "metric": metric, "unit": unit,
                    "subjects": int(both.sum()), "generic": float(np.mean(a[both])),
                    "personal": float(np.mean(b[both])), "difference": mean,
                    "ci_low": lo, "ci_high": hi,
                    "tuner_failed": int((g[f"{who}_tuner_failed"] != "").sum()),
                })  # fmt: skip
    return pd.DataFrame(out)


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
    pid = "pid" if "pid" in settings.controllers else settings.controllers[0]
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
    personal_rows = _rows_present(out, "personal.json")
    personal = personalisation_table(personal_rows) if personal_rows else None
    if personal is not None:
        personal.to_csv(out / "personalisation.csv", index=False)
        summary["personalisation_subjects"] = len(personal_rows)
    (out / "recovery.json").write_text(json.dumps(summary, indent=1, default=str))
    (out / "recovery.md").write_text(format_summary(summary, params, preds, personal))
    return summary


def format_summary(
    summary: Mapping[str, Any], params: Any, preds: Any, personal: Any = None
) -> str:
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
    if personal is not None:
        lines += [
            "",
            "## Personalisation: the person's PID against the paper's, on the true twin",
            "",
            "`personal`: the PID the project's tuner (Ziegler-Nichols, `myoexo twin tune-pid`) "
            "sets on the fitted twin; `tuned_on_truth`: the same tuner on the true twin. "
            "`difference` = personal - generic (negative: lower), mean over subjects with "
            "its 95 % interval; `tuner_failed`: subjects on which the tuner found no "
            "sustained oscillation and the paper's PID was kept.",
            "",
            personal.to_markdown(index=False, floatfmt=".3g"),
        ]
    lines.append("")
    return "\n".join(lines)


def _command(settings: RecoverySettings) -> str:
    options = option_words(settings, exclude=("workers", "summarise_only"))
    return shlex.join(["myoexo", "twin", "recovery", *options])


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
