"""Result sets: the small files a results table is computed from.

A *result set* is a folder of small CSV files computed from one evaluation folder
(``myoexo results collect EVAL_DIR DEST``): ``summary.csv`` (mean, std, quantiles per
controller and level, :func:`~myoexo.evaluation.stats.summarize_episodes`), ``tail_risk.csv``
(:func:`~myoexo.evaluation.stats.tail_risk`), ``reductions.csv`` (each controller against the
PID on the same subjects, with intervals, :func:`~myoexo.evaluation.stats.reductions`),
``headline.csv`` (the study's levels 1-2 aggregation and the mean over every level run) and
``meta.json`` (the command that produced the evaluation, its twin, subjects and root seed,
and the package versions).

The tables of a set are computed from its files, as text: :func:`render` (every table of the
set), :func:`headline_block` (the short tables of some of its controllers),
:func:`goals_table` (a deployable controller against
:class:`~myoexo.evaluation.criteria.DeployableGoals`, from a nominal and a perturbed set).
``myoexo results tables`` and ``myoexo results goals`` print them; nothing here writes
outside the set folder that ``collect`` is given.

The members of a seed group (the checkpoints of a ``myoexo policy seeds`` folder, a
distillation's seed copies) are one controller of a set, named after the group
(:func:`~myoexo.evaluation.stats.pool_seed_groups`): its means, tails and intervals are over
the seeds and the subjects.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.control.specs import seeds_folder_of_spec
from myoexo.envs.options import TwinOptions, twin_words
from myoexo.evaluation.bound import HOLD_BOUND_LEVELS, hold_bounds
from myoexo.evaluation.config import EVALUATION_ROOT_SEED, load_config
from myoexo.evaluation.criteria import (
    DeployableGoals,
    combined_verdict,
    verdict,
    verdict_against,
    verdict_by_level,
)
from myoexo.evaluation.paper import PAPER_HEADLINES, PAPER_RESULTS
from myoexo.evaluation.report import fmt_ci, fmt_num, reference_controller
from myoexo.evaluation.stats import (
    FAILURE_DEG,
    HEADLINE_LEVELS,
    INTERVAL_METHOD,
    headline,
    mean_interval,
    pool_seed_groups,
    reductions,
    summarize_episodes,
    tail_risk,
)
from myoexo.evaluation.storage import load_table
from myoexo.model import recorded_twin_version
from myoexo.runtime.fields import add_options, add_positional, check_fields, from_options, option
from myoexo.runtime.files import write_json_atomic

_FILES = ("summary.csv", "tail_risk.csv", "reductions.csv", "headline.csv", "meta.json")


def command_of(config: dict[str, Any]) -> str:
    """The ``myoexo evaluate`` command line of an evaluation's ``config.json``."""
    cfg = config.get("config", {})
    controllers, seeds_dirs = [], []
    for spec in map(str, cfg.get("controllers", [])):
        folder = seeds_folder_of_spec(spec)
        if folder is None:
            controllers.append(spec)
        elif folder not in seeds_dirs:
            seeds_dirs.append(folder)  # --seeds-dir added the folder's checkpoints
    parts = ["myoexo evaluate", "--controllers", *controllers]
    if seeds_dirs:
        parts += ["--seeds-dir", *seeds_dirs]
    parts += ["--levels", *map(str, cfg.get("levels", [])), "--subjects", str(cfg.get("subjects"))]
    if cfg.get("root_seed", 0) != 0:
        parts += ["--seed", str(cfg["root_seed"])]
    parts += twin_words(TwinOptions.from_dict(cfg.get("twin") or {}))
    return " ".join(parts)


def collect(
    eval_dir: str | Path,
    dest: str | Path,
    update: bool = False,
    rerun_levels: Sequence[int] = (),
) -> Path:
    """Write the result set of the evaluation folder *eval_dir* into *dest* (created).

    With *update*, *dest* is an existing set and *eval_dir* an evaluation of more (or
    retrained) controllers on the same subjects: its controllers' rows are added to the set,
    replacing rows of the same name in their place, and the other controllers' rows are
    kept. "The same subjects" is checked, not assumed: the two must agree on the root seed,
    the subjects per level, the levels and the twin, and *eval_dir* must hold the set's
    reference controller with the same summary and tail rows (an episode depends only on
    controller, level, subject and root seed, so the reference's rows repeat, to 1e-6
    relative). The set's ``meta.json`` lists every command it was built from.

    *rerun_levels* (with *update*) names levels where the evaluation's reference may differ
    from the set's: where a reference that never settles (the PIDs that limit-cycle under
    the perturbed twins' latency at level 0) amplifies a last-digit change of the code into
    another trajectory. The reference's rows must still repeat at every other level and
    count as many subjects at these; the set keeps its own reference rows, the added
    controllers are paired with the evaluation's own run of it there, and ``meta.json``
    (``reference_reruns``) and the set's tables say so, with both means of the final error.

    Raises:
        ValueError: *eval_dir* is no evaluation folder, holds no episodes, or no PID; with
            *update*, *dest* is no result set or *eval_dir* is not on its subjects.
    """
    import pandas as pd

    config = load_config(eval_dir)
    table = pool_seed_groups(load_table(eval_dir))
    if table.empty:
        raise ValueError(f"{str(eval_dir)!r} holds no episodes yet")
    cfg = config.get("config", {})
    if cfg.get("selection") or int(cfg.get("root_seed", 0)) != EVALUATION_ROOT_SEED:
        raise ValueError(
            f"{str(eval_dir)!r} ran on root seed {cfg.get('root_seed')}"
            f"{' as a selection run' if cfg.get('selection') else ''}: a result set holds "
            f"evaluations on the evaluation root {EVALUATION_ROOT_SEED} only (numbers on other "
            "roots are in-sample)"
        )
    labels = list(dict.fromkeys(table["controller"]))
    reference = reference_controller(labels)
    if reference is None:
        raise ValueError(f"{str(eval_dir)!r} has no PID to compare with")
    others = [c for c in labels if c != reference]
    if not others:
        raise ValueError(
            f"{str(eval_dir)!r} holds only the reference {reference!r}: a result set compares "
            "other controllers with it (evaluate one or more beside it)"
        )
    levels = sorted(int(v) for v in set(table.level))
    heads = []
    for c in others:
        for scope, scope_levels in (
            ("study", [lv for lv in HEADLINE_LEVELS if lv in levels]),
            ("all", levels),
        ):
            h = headline(table, reference, c, scope_levels)
            h["levels"] = ", ".join(map(str, scope_levels))
            heads.append({"controller": c, "scope": scope, **h})
    files = {
        "summary.csv": summarize_episodes(table),
        "tail_risk.csv": tail_risk(table, reference),
        "reductions.csv": pd.concat(
            [reductions(table, reference, c).assign(controller=c) for c in others],
            ignore_index=True,
        ),
        "headline.csv": pd.DataFrame(heads),
    }
    meta = {
        "commands": [command_of(config)],
        "reference": reference,
        **_subjects_of(config),
        "episodes": len(table),
        "versions": config.get("versions", {}),
        "hold_bounds": hold_bounds(eval_dir, table, reference, levels),
    }
    if meta["hold_bounds"]:  # the run whose reference traces gave the bounds
        meta["hold_bounds_command"] = meta["commands"][0]
    dest = Path(dest)
    if rerun_levels and not update:
        raise ValueError("rerun_levels applies to an update of an existing set (update=True)")
    if update:
        files, meta = _updated(dest, files, meta, others, tuple(sorted(set(rerun_levels))))
    dest.mkdir(parents=True, exist_ok=True)
    for name, frame in files.items():
        frame.to_csv(dest / name, index=False)
    write_json_atomic(dest / "meta.json", meta, indent=2)
    return dest


def bound(eval_dir: str | Path, dest: str | Path) -> Path:
    """Recompute the hold bounds (:func:`~myoexo.evaluation.bound.hold_bounds`) of the result
    set *dest* from *eval_dir*, an evaluation of the set's reference with stored traces on the
    set's subjects, at some of the bound's levels (:data:`~myoexo.evaluation.bound
    .HOLD_BOUND_LEVELS`). "The set's subjects" is checked as :func:`collect` checks an update:
    the same root seed, subjects per level and twin, and the reference's summary and tail rows
    at those levels equal to the set's. The set's other files are left as they are; its
    ``meta.json`` gets the new bounds (those of other levels kept) and the evaluation's
    command as ``hold_bounds_command``.

    Raises:
        ValueError: *dest* is no result set, or *eval_dir* holds no reference episodes at the
            bound's levels, is not on the set's subjects, or gives no bound at one of them
            (no traces, or no measured hold slope where the claim leaves slack).
    """
    dest = Path(dest)
    summary, risk, _, _, meta = _read(dest)
    config = load_config(eval_dir)
    table = pool_seed_groups(load_table(eval_dir))
    ref = meta["reference"]
    mine = table[table.controller == ref]
    levels = sorted(set(int(v) for v in mine.level) & set(HOLD_BOUND_LEVELS))
    if not levels:
        raise ValueError(
            f"{str(eval_dir)!r} holds no {ref!r} episodes at levels {list(HOLD_BOUND_LEVELS)}"
        )

    def at_levels(frame: Any) -> Any:
        return frame[frame.level.isin(levels)]

    _check_same_subjects(
        dest,
        meta,
        {"reference": ref, **_subjects_of(config)},
        at_levels(summary),
        at_levels(risk),
        at_levels(summarize_episodes(mine)),
        at_levels(tail_risk(mine, ref)),
    )
    fresh = hold_bounds(eval_dir, mine, ref, levels)
    missing = sorted(set(levels) - {int(b["level"]) for b in fresh})
    if missing:
        raise ValueError(
            f"{str(eval_dir)!r} gives no hold bound at levels {missing} (no stored traces of "
            f"{ref!r}, or a level without a measured hold slope: myoexo twin hold-slope)"
        )
    bounds = _merged_bounds(meta.get("hold_bounds", []), fresh)
    meta = {**meta, "hold_bounds": bounds, "hold_bounds_command": command_of(config)}
    write_json_atomic(dest / "meta.json", meta, indent=2)
    return dest


def _merged_bounds(old: list[dict[str, Any]], fresh: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """A set's hold bounds *old* with those of *fresh*'s levels replaced by *fresh*'s, by
    level."""
    levels = {int(b["level"]) for b in fresh}
    kept = [b for b in old if int(b["level"]) not in levels]
    return sorted([*kept, *fresh], key=lambda b: b["level"])


def _same_bounds(a: list[dict[str, Any]], b: list[dict[str, Any]]) -> bool:
    """Whether the hold bounds *a* and *b* are at the same levels with the same numbers, to
    1e-6 relative (:func:`_same_rows`' tolerance: a re-run of the reference repeats them)."""
    import math

    if [x["level"] for x in a] != [x["level"] for x in b]:
        return False
    return all(
        x.keys() == y.keys()
        and all(
            math.isclose(x[k], y[k], rel_tol=1e-6) if isinstance(x[k], float) else x[k] == y[k]
            for k in x
        )
        for x, y in zip(a, b, strict=True)
    )


#: What names a set's subjects in its ``meta.json`` (:func:`_subjects_of`).
_SUBJECT_KEYS = ("subjects_per_level", "root_seed", "twin", "twin_version")


def _subjects_of(config: dict[str, Any]) -> dict[str, Any]:
    """The fields of :data:`_SUBJECT_KEYS` of an evaluation folder's config: an episode
    depends only on them, the controller, the level and the subject index."""
    cfg = config.get("config", {})
    return {
        "subjects_per_level": int(cfg.get("subjects", 0)),
        "root_seed": int(cfg.get("root_seed", 0)),
        "twin": cfg.get("twin"),
        "twin_version": recorded_twin_version(config),
    }


def _check_same_subjects(
    dest: Path,
    meta: dict[str, Any],
    theirs: dict[str, Any],
    summary: Any,
    risk: Any,
    new_summary: Any,
    new_risk: Any,
    rerun_levels: Sequence[int] = (),
) -> None:
    """Refuse an evaluation (its reference and :func:`_subjects_of` fields *theirs*, its
    reference's summary and tail rows) that did not run on the subjects of the set *dest*
    (its *meta*, *summary* and *risk*): the fields must agree, the reference's rows repeat
    (:func:`_same_rows`) at every level but *rerun_levels*, where they must count as many
    subjects (:func:`collect`)."""
    ours = {**meta, "twin_version": recorded_twin_version(meta)}
    for key, value in theirs.items():
        if ours.get(key) != value:
            raise ValueError(
                f"the evaluation's {key} ({value!r}) is not the set's ({ours.get(key)!r}): "
                f"{str(dest)!r} can only take runs on its own subjects"
            )
    ref = theirs["reference"]

    def rows(frame: Any, keep: bool) -> Any:
        return frame[frame.level.isin(rerun_levels) == keep]

    for name, old, new in (
        ("summary.csv", summary, new_summary),
        ("tail_risk.csv", risk, new_risk),
    ):
        set_ref = old[old.controller == ref]  # a metric empty in all of them came later
        later = [c for c in old.columns if len(set_ref) and set_ref[c].isna().all()]
        if not _same_rows(rows(old, False), rows(new, False), ref, later):
            differ = [
                lv
                for lv in sorted(set(old.level))
                if not _same_rows(old[old.level == lv], new[new.level == lv], ref, later)
            ]
            raise ValueError(
                f"the reference {ref!r} has other {name} rows in the evaluation than in "
                f"{str(dest)!r} at levels {differ}: it did not run on the set's subjects and "
                "twin (or, where it never settles, a later code's last digits gave another "
                "trajectory: name those levels with --rerun-levels)"
            )
    a = rows(summary, True)
    b = rows(new_summary, True)
    a, b = a[a.controller == ref], b[b.controller == ref]
    if list(a.level) != list(b.level) or list(a.n) != list(b.n):
        raise ValueError(
            f"the reference {ref!r} is not at levels {list(rerun_levels)} with the set's "
            f"subjects in the evaluation ({list(zip(b.level, b.n, strict=False))} against "
            f"{list(zip(a.level, a.n, strict=False))} (level, episodes))"
        )


def _same_rows(old: Any, new: Any, controller: str, later: Sequence[str] = ()) -> bool:
    """Whether *old* and *new* hold the same numbers for *controller*, to 1e-6 relative: a
    CSV round trip may change the last digit, and a re-run of the perturbed 1000-subject set's
    PID gave two quantiles that differ in the ninth significant digit (every mean agreed to
    1e-9); other subjects or another twin differ in the first few. A metric added since the
    set's rows of *controller* were made is not compared: it is in the new rows alone, or one
    of *later* (the caller's: empty in every one of the set's rows of *controller*, the set
    having taken later controllers that have it).

    Raises:
        ValueError: If *new* lacks a column *old* has (a run of an older code or another
            table: its rows cannot stand beside the set's).
    """
    import numpy as np

    lacking = [c for c in old.columns if c not in new.columns]
    if lacking:
        raise ValueError(
            f"the evaluation's rows lack the set's columns {lacking}: it was made by another "
            "code than the set's; re-run it with this one"
        )
    shared = [c for c in old.columns if c not in later]
    a = old.loc[old.controller == controller, shared].reset_index(drop=True)
    b = new.loc[new.controller == controller, shared].reset_index(drop=True)
    if a.shape != b.shape:
        return False
    num = a.select_dtypes("number").columns
    return bool(
        np.allclose(a[num].to_numpy(float), b[num].to_numpy(float), rtol=1e-6, equal_nan=True)
        and (a.drop(columns=num).astype(str) == b.drop(columns=num).astype(str)).all().all()
    )


def _updated(
    dest: Path,
    files: dict[str, Any],
    meta: dict[str, Any],
    added: list[str],
    rerun_levels: tuple[int, ...] = (),
) -> tuple[dict[str, Any], dict[str, Any]]:
    """The set *dest* with the controllers *added* of a new evaluation (*files*, *meta*)
    put in; see :func:`collect`."""
    import pandas as pd

    summary, risk, red, heads, old = _read(dest)
    if set(summary.level) != set(files["summary.csv"].level):
        raise ValueError(
            f"the evaluation's levels {sorted(set(files['summary.csv'].level))} are not the "
            f"set's {sorted(set(summary.level))}"
        )
    _check_same_subjects(
        dest,
        old,
        {k: meta.get(k) for k in ("reference", *_SUBJECT_KEYS)},
        summary,
        risk,
        files["summary.csv"],
        files["tail_risk.csv"],
        rerun_levels,
    )
    merged = {}
    for (name, new), frame in zip(files.items(), (summary, risk, red, heads), strict=True):
        kept = frame[~frame.controller.isin(added)]
        rows = pd.concat([kept, new[new.controller.isin(added)]], ignore_index=True)
        # a replaced controller keeps its place in the set, an added one comes last
        order = {c: i for i, c in enumerate(dict.fromkeys([*frame.controller, *added]))}
        rank = rows.controller.map(order)
        merged[name] = rows.iloc[rank.argsort(kind="stable")].reset_index(drop=True)
    bounds = _merged_bounds(old.get("hold_bounds", []), meta["hold_bounds"])
    if old.get("hold_bounds_command") and _same_bounds(bounds, old.get("hold_bounds", [])):
        # the set's bounds stay (none in the run, or the run's repeat them), and so does
        # the run they came from
        meta = {**meta, "hold_bounds_command": old["hold_bounds_command"]}
    reruns = list(old.get("reference_reruns", []))
    if rerun_levels:
        ref = meta["reference"]
        mean = {
            key: frame[frame.controller == ref].set_index("level").final_error_deg_mean
            for key, frame in (("set", summary), ("run", files["summary.csv"]))
        }
        reruns.append(
            {
                "command": meta["commands"][0],
                "levels": list(rerun_levels),
                "controllers": list(added),
                "final_error_deg_mean": [
                    {"level": lv, "set": float(mean["set"][lv]), "run": float(mean["run"][lv])}
                    for lv in rerun_levels
                ],
            }
        )
    meta = {
        **meta,
        "hold_bounds": bounds,
        "commands": [*old["commands"], *(c for c in meta["commands"] if c not in old["commands"])],
        "episodes": int(merged["summary.csv"].n.sum()),
        **({"reference_reruns": reruns} if reruns else {}),
    }
    return merged, meta


# ----------------------------------------------------------------------------- rendering
def _ci_of(row: Any, name: str, digits: int = 1) -> str:
    """:func:`_ci` of the columns ``name``, ``name_low`` and ``name_high`` of *row*."""
    return fmt_ci(row[name], row[f"{name}_low"], row[f"{name}_high"], digits)


def _commands(meta: dict[str, Any]) -> str:
    """How a set's provenance names the evaluation command(s) it was built from."""
    commands = meta["commands"]
    if len(commands) == 1:
        return f"Command: `{commands[0]}`"
    later = ", then ".join(f"`{c}`" for c in commands[1:])
    return (
        f"Commands: `{commands[0]}`, then {later} (controllers added on the same subjects, "
        "checked by the reference's identical rows: `myoexo results collect --update`)"
    )


def _rerun_line(ref: str, rerun: dict[str, Any]) -> str:
    """The sentence of a set's tables on controllers paired with their own run of the
    reference where it differs from the set's (:func:`collect`'s *rerun_levels*)."""
    means = "; ".join(
        f"level {m['level']}: {m['run']:.3f} against the set's {m['set']:.3f} deg"
        for m in rerun["final_error_deg_mean"]
    )
    names = ", ".join(f"`{c}`" for c in rerun["controllers"])
    return (
        f"At levels {', '.join(map(str, rerun['levels']))}, {names} are paired with their own "
        f"run of `{ref}` (`{rerun['command']}`), which differs there from the set's rows "
        f"(mean final error {means}): a reference that never settles there turns a later "
        "code's last digits into another trajectory. The set's rows of "
        f"`{ref}` are its own run's (`myoexo results collect --update --rerun-levels`)."
    )


def _md(headers: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _read(folder: Path) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
    import pandas as pd

    missing = [f for f in _FILES if not (folder / f).is_file()]
    if missing:
        raise ValueError(f"{str(folder)!r} is no result set: it lacks {missing}")
    return (
        pd.read_csv(folder / "summary.csv"),
        pd.read_csv(folder / "tail_risk.csv"),
        pd.read_csv(folder / "reductions.csv"),
        pd.read_csv(folder / "headline.csv", dtype={"levels": str}),
        json.loads((folder / "meta.json").read_text()),
    )


def _judged(
    row: Any,
    name: str,
    target: float | None,
    higher: bool,
    digits: int = 1,
    reachable: float | None = None,
) -> str:
    """``value [low, high]`` and, against *target*, the verdict by the interval; "out of
    reach" where *reachable* (the most any controller can reach, :mod:`~myoexo.evaluation.bound`)
    falls short of a target to exceed."""
    cell = _ci_of(row, name, digits)
    if target is None:
        return cell
    if higher and reachable is not None and reachable < target:
        return f"{cell} (>= {target:g}: out of reach, at most {reachable:.1f})"
    call = verdict(row[f"{name}_low"], row[f"{name}_high"], target, higher_is_better=higher)
    return f"{cell} ({'>=' if higher else '<'} {target:g}: {call})"


def _final_error_judged(row: Any, target: float, ref: str, ref_error: float, stall: bool) -> str:
    """The final-error cell: the mean absolute final error with its interval, judged against
    the study's bound *target*. Where the reference stalls against the reflex short of that
    bound (*stall*: a level with a hold bound, :mod:`~myoexo.evaluation.bound`, and
    *ref_error*, the reference's mean absolute final error on the same subjects, beyond the
    bound), the bound reads "out of reach" and the cell judges the study's reading there
    instead, no worse than the reference: the paired difference of the absolute final
    errors, met when its whole interval is below 0."""
    name = "abs_final_error_deg"
    if not (stall and ref_error > target):
        return _judged(row, name, target, False, 2)
    diff = "abs_final_error_diff_deg"
    low, high = row[f"{diff}_low"], row[f"{diff}_high"]
    call = verdict(low, high, 0.0, higher_is_better=False)
    return (
        f"{_ci_of(row, name, 2)} (< {target:g}: out of reach, `{ref}` stalls "
        f"{ref_error:.2f} short; vs `{ref}` {row[diff]:+.2f} [{low:+.2f}, {high:+.2f}]: {call})"
    )


def headline_table(folder: str | Path, controller: str) -> str:
    """The short table of one controller against the PID (the README's): per level its mean
    absolute final error, peak and RMS reductions and settling ratio, each with its interval
    and its verdict against the study's per-level claim, and the tail."""
    summary, risk, red, _, meta = _read(Path(folder))
    ref = meta["reference"]
    s = summary.set_index(["controller", "level"])
    k = risk.set_index(["controller", "level"])
    r = red[red.controller == controller].set_index("level")
    bounds = {int(b["level"]): b["peak_reduction_bound_pct"] for b in meta.get("hold_bounds", [])}
    rows = []
    for level in sorted(r.index):
        paper = PAPER_RESULTS[int(level)]
        row = r.loc[level]
        rows.append(
            [
                str(level),
                str(int(row.seeds)) if "seeds" in row else "1",
                _final_error_judged(
                    row,
                    paper.sac_final_error_bound_deg,
                    ref,
                    float(row.abs_final_error_deg - row.abs_final_error_diff_deg),
                    int(level) in bounds,
                ),
                fmt_num(s.loc[(ref, level), "final_error_deg_mean"]),
                f"{fmt_num(k.loc[(ref, level), 'worst_abs_final_error_deg'], 1)} / "
                f"{fmt_num(k.loc[(controller, level), 'worst_abs_final_error_deg'], 1)}",
                str(int(k.loc[(controller, level), "catastrophic"])),
                _judged(
                    row,
                    "peak_reduction_pct",
                    paper.peak_reduction_pct,
                    True,
                    1,
                    bounds.get(int(level)),
                ),
                _judged(row, "rms_reduction_pct", paper.rms_reduction_pct, True),
                _judged(row, "settling_ratio", 1.0, False, 2),
                f"{row.reference_settled_pct:.0f} / {row.other_settled_pct:.0f}",
            ]
        )
    return _md(
        [
            "level",
            "seeds",
            f"{controller} abs final error (deg) [95 % CI] (paper)",
            f"{ref} final error (deg)",
            f"worst subject (deg): {ref} / {controller}",
            "catastrophic subjects",
            "peak reduction % (paper)",
            "RMS reduction % (paper)",
            f"settling time / {ref}'s (faster than the PID)",
            "settled %",
        ],
        rows,
    )


def aggregation_lines(folder: str | Path) -> list[str]:
    """One line per controller: the study's levels 1-2 aggregation with its verdicts, and
    the mean over every level run."""
    _, _, _, heads, meta = _read(Path(folder))
    paper = PAPER_HEADLINES
    lines = []
    for controller, h in heads.groupby("controller", sort=False):
        study = h[h.scope == "study"].iloc[0]
        every = h[h.scope == "all"].iloc[0]
        peak_v = verdict(study.peak_low, study.peak_high, paper.peak_reduction_pct)
        rms_v = verdict(study.rms_low, study.rms_high, paper.rms_reduction_pct)
        lines.append(
            f"`{controller}` vs `{meta['reference']}`, mean over levels {study.levels} (the "
            f"study's aggregation): peak {fmt_ci(study.peak, study.peak_low, study.peak_high)} % "
            f"(paper {paper.peak_reduction_pct} %: {peak_v}), RMS "
            f"{fmt_ci(study.rms, study.rms_low, study.rms_high)} % (paper "
            f"{paper.rms_reduction_pct} %: {rms_v}); over levels {every.levels}: peak "
            f"{fmt_ci(every.peak, every.peak_low, every.peak_high)} %, RMS "
            f"{fmt_ci(every.rms, every.rms_low, every.rms_high)} %."
        )
    return lines


def earlier_twin_note(meta: dict[str, Any]) -> str | None:
    """A warning line for a result set measured on another twin than today's default: another
    twin version (:data:`~myoexo.model.TWIN_VERSION`; a set that records none was measured
    on version 1) or another reflex model than the default
    (:data:`~myoexo.spasticity.reflex.DEFAULT_REFLEX`); ``None`` for a set of today's
    default twin."""
    from myoexo.model import TWIN_VERSION
    from myoexo.spasticity.reflex import DEFAULT_REFLEX

    notes = []
    version = recorded_twin_version(meta)
    if version != TWIN_VERSION:
        notes.append(
            f"**Measured on an earlier twin** (version {version}; today's default twin is "
            f"version {TWIN_VERSION}, CHANGELOG.md): these numbers are not those of today's twin "
            "until the set is re-run."
        )
    reflex = (meta.get("twin") or {}).get("reflex")
    if reflex is not None and reflex != DEFAULT_REFLEX:
        notes.append(
            f"**Measured with the `{reflex}` reflex** (today's default twin's is "
            f"`{DEFAULT_REFLEX}`, CHANGELOG.md): these numbers are not those of today's default "
            "twin until the set is re-run."
        )
    return " ".join(notes) or None


def hold_bound_line(meta: dict[str, Any]) -> str:
    """The sentence that states a set's hold bounds (:func:`~myoexo.evaluation.bound.hold_bounds`;
    empty for a set without one)."""
    bounds = meta.get("hold_bounds") or []
    if not bounds:
        return ""
    ref = meta["reference"]

    def one(b: dict[str, Any]) -> str:
        text = (
            f"level {b['level']}: {b['hold_torque_nm']:.1f} Nm held against a mean peak of "
            f"{b['reference_peak_nm']:.1f} Nm"
        )
        if b.get("slack_deg", 0.0) > 0.0:
            text += (
                f", less at most {b['hold_slope_nm_per_deg']:.2f} Nm/deg over the "
                f"{b['slack_deg']:.2f} deg the claim lets a controller end further short "
                f"({b['least_hold_nm']:.1f} Nm)"
            )
        return f"{text}, so at most {b['peak_reduction_bound_pct']:.1f} %"

    return (
        f"What the motor allows (`myoexo.evaluation.bound.hold_bounds`): where the motor stalls "
        f"against the reflex, a controller that meets the study's accuracy claim ends where "
        f"`{ref}` ends (level 2) or at most as far beyond it as the claim allows (level 3, with "
        f"the twin's steepest hold slope, `myoexo twin hold-slope`), and its peak is at least "
        f"the torque that holds it there (`{ref}`'s mean over the last "
        f"{bounds[0]['window_s']:g} s of its episodes): {'; '.join(map(one, bounds))}. A peak "
        f'claim above it reads "out of reach". Where `{ref}`, which holds that torque, ends '
        'beyond the study\'s final-error bound, the bound reads "out of reach" too, and the '
        f"final error is judged against the study's reading there, no worse than `{ref}`: the "
        "paired difference, met when its whole interval is below 0."
        + (
            f" (The reference's traces for these bounds: `{meta['hold_bounds_command']}`, "
            "on the set's subjects, `myoexo results bound`.)"
            if meta.get("hold_bounds_command")
            else ""
        )
    )


def render(folder: str | Path, label: str | None = None) -> str:
    """The Markdown of a result set: provenance (*label*: how the set's folder is named in
    it, default its path), one table per controller, the study's aggregation, the tail."""
    folder = Path(folder)
    _, risk, red, _, meta = _read(folder)
    versions = ", ".join(f"{k} {v}" for k, v in sorted(meta.get("versions", {}).items()))
    parts = [
        f"<!-- generated by `myoexo results tables` from {label or folder.as_posix()}: do not "
        "edit -->",
        f"{_commands(meta)} ({meta['subjects_per_level']} subjects per level, root "
        f"seed {meta['root_seed']}, {meta['episodes']} episodes; {versions}). A `myoexo "
        "policy seeds` folder's checkpoints are one controller named after the folder: its numbers "
        "are over the seeds and the subjects. Intervals: "
        f"{INTERVAL_METHOD}. A criterion is met when its whole interval is on the good side "
        "of the paper's number, missed when wholly on the other, a tie otherwise.",
    ]
    if (note := earlier_twin_note(meta)) is not None:
        parts.append(note)
    if line := hold_bound_line(meta):
        parts.append(line)
    parts += [_rerun_line(meta["reference"], r) for r in meta.get("reference_reruns", [])]
    for controller in dict.fromkeys(red.controller):
        parts.append(f"**`{controller}`** against `{meta['reference']}` on the same subjects:")
        parts.append(headline_table(folder, controller))
    parts.append("\n".join(f"- {line}" for line in aggregation_lines(folder)))
    rows = [
        [
            str(r.controller),
            str(r.level),
            fmt_num(r.worst_abs_final_error_deg, 1),
            str(r.worst_subject),
            fmt_num(r.p95_abs_final_error_deg),
            fmt_num(r.p99_abs_final_error_deg),
            str(r.failures),
            fmt_num(r.limit_deg, 1),
            str(r.catastrophic),
            str(r.unstable),
        ]
        for r in risk.itertuples()
    ]
    parts.append(
        f"Tail of the absolute final error (beyond {FAILURE_DEG:g} deg: failures; catastrophic: "
        "beyond that or the PID's own worst, whichever is larger):"
    )
    parts.append(
        _md(
            [
                "controller",
                "level",
                "worst (deg)",
                "worst subject",
                "p95 (deg)",
                "p99 (deg)",
                f"beyond {FAILURE_DEG:g} deg",
                "limit (deg)",
                "catastrophic",
                "unstable",
            ],
            rows,
        )
    )
    return "\n\n".join(parts) + "\n"


def _twin_goals(
    result_set: tuple[Any, Any, Any, Any, dict[str, Any]],
    name: str,
    controller: str,
    teacher: str,
    goals: DeployableGoals,
    perturbed: bool,
) -> list[str]:
    """The goal cells of one result set (:func:`_read`'s tables, *name* for the messages),
    in the order of :func:`goals_table`'s rows."""
    summary, risk, red, _, meta = result_set
    ref = meta["reference"]
    r = red[red.controller == controller].set_index("level")
    k = risk.set_index(["controller", "level"])
    s = summary.set_index(["controller", "level"])
    missing = [c for c in (controller, teacher) if c not in set(summary.controller)]
    if missing:
        raise ValueError(f"the result set {name!r} has no {missing}")
    mean_bound, p95_bound = goals.easy_bounds(perturbed)
    cells, calls = [], []
    for level in goals.easy_levels:
        row = r.loc[level]
        p95 = float(k.loc[(controller, level), "p95_abs_final_error_deg"])
        cells.append(f"L{level} {_ci_of(row, 'abs_final_error_deg', 2)}, p95 {fmt_num(p95, 2)}")
        calls.append(
            verdict(row.abs_final_error_deg_low, row.abs_final_error_deg_high, mean_bound, False)
        )
        calls.append("met" if p95 < p95_bound else "missed")
    out = [f"{'; '.join(cells)}: **{combined_verdict(calls)}**"]
    for level in goals.hard_levels:
        row = r.loc[level]
        diff, low, high = (
            row.abs_final_error_diff_deg,
            row.abs_final_error_diff_deg_low,
            row.abs_final_error_diff_deg_high,
        )
        call = verdict(low, high, goals.within_pid_deg, higher_is_better=False)
        cell = f"{diff:+.2f} [{low:+.2f}, {high:+.2f}] deg vs `{ref}`"
        if call != "met":
            cell += f", {diff - goals.within_pid_deg:+.2f} deg beyond the goal"
        out.append(f"{cell}: **{call}**")
    levels = sorted(r.index)
    counts = [int(k.loc[(controller, lv), "catastrophic"]) for lv in levels]
    worst = [float(k.loc[(controller, lv), "worst_abs_final_error_deg"]) for lv in levels]
    out.append(
        f"{' / '.join(map(str, counts))} (worst {' / '.join(fmt_num(w, 1) for w in worst)} "
        f"deg): **{'met' if not any(counts) else 'missed'}**"
    )
    mine = [_summary_mean(s.loc[(controller, lv)], "command_total_variation") for lv in levels]
    theirs = [_summary_mean(s.loc[(teacher, lv)], "command_total_variation") for lv in levels]
    calls = [verdict_against(*a[1:], *b[1:]) for a, b in zip(mine, theirs, strict=True)]
    out.append(
        f"{' / '.join(fmt_ci(*v, 1) for v in mine)} vs `{teacher}`'s "
        f"{' / '.join(fmt_ci(*v, 1) for v in theirs)}: **{verdict_by_level(levels, calls)}**"
    )
    return out


def _summary_mean(row: Any, name: str) -> tuple[float, float, float]:
    """``(mean, low, high)`` of a summary row's *name*: its mean over the row's ``n``
    episodes with the interval of :func:`~myoexo.evaluation.stats.mean_interval`."""
    mean = float(row[f"{name}_mean"])
    return (mean, *mean_interval(mean, float(row[f"{name}_std"]), int(row["n"])))


def _beats(red: Any, controller: str, baseline: str) -> str:
    """The goals table's cell of *controller* against *baseline* (reductions rows): each
    level's mean abs final error with its interval, met where the intervals part in its
    favour, a tie where they overlap, missed where they part against it."""
    if baseline not in set(red.controller):
        return f"`{baseline}` is not in this set"
    r = red.set_index(["controller", "level"])
    levels = sorted(red[red.controller == controller].level)
    cells, calls = [], []
    for level in levels:
        a, b = r.loc[(controller, level)], r.loc[(baseline, level)]
        name = "abs_final_error_deg"
        cells.append(f"{_ci_of(a, name, 2)} vs {_ci_of(b, name, 2)}")
        calls.append(
            verdict_against(
                a[f"{name}_low"], a[f"{name}_high"], b[f"{name}_low"], b[f"{name}_high"]
            )
        )
    return f"{' / '.join(cells)} deg: **{verdict_by_level(levels, calls)}**"


def goals_table(
    nominal: Path,
    perturbed: Path,
    controller: str,
    teacher: str,
    device_baseline: str,
    goals: DeployableGoals | None = None,
) -> str:
    """The Markdown table of *controller* against *goals* (default
    :class:`~myoexo.evaluation.criteria.DeployableGoals`) on a nominal and a perturbed
    result set: each cell the measured values with their 95 % intervals and the verdict (met
    when the whole interval is on the goal's side, missed when wholly on the other)."""
    goals = goals or DeployableGoals()
    nom_set, per_set = _read(Path(nominal)), _read(Path(perturbed))
    nom = _twin_goals(nom_set, Path(nominal).name, controller, teacher, goals, perturbed=False)
    per = _twin_goals(per_set, Path(perturbed).name, controller, teacher, goals, perturbed=True)
    _, _, red, _, meta = nom_set
    easy = ", ".join(map(str, goals.easy_levels))
    rows = [
        [
            f"levels {easy}: mean < {goals.easy_mean_deg:g} deg and p95 < "
            f"{goals.easy_p95_deg:g} deg (perturbed < {goals.easy_mean_perturbed_deg:g} / "
            f"< {goals.easy_p95_perturbed_deg:g} deg)",
            nom[0],
            per[0],
        ]
    ]
    for i, level in enumerate(goals.hard_levels):
        rows.append(
            [
                f"level {level}: mean within {goals.within_pid_deg:g} deg of the paper's PID "
                f"(`{meta['reference']}`, which reads the human knee)",
                nom[1 + i],
                per[1 + i],
            ]
        )
    n = 1 + len(goals.hard_levels)
    rows.append(["no catastrophic subject (per level)", nom[n], per[n]])
    rows.append(
        [
            "command total variation no larger than the teacher's (per level, mean [95 % CI]; "
            "a tie where the intervals overlap)",
            nom[n + 1],
            per[n + 1],
        ]
    )
    rows.append(
        [
            f"beats the device PID tuned on the encoder (`{device_baseline}`): mean abs "
            "final error per level [95 % CI] (a tie where the intervals overlap)",
            _beats(red, controller, device_baseline),
            _beats(per_set[2], controller, device_baseline),
        ]
    )
    n_nom = meta["subjects_per_level"]
    n_per = per_set[4]["subjects_per_level"]
    return _md(
        [
            "goal",
            f"nominal ({n_nom} subjects per level)",
            f"perturbed ({n_per} subjects per level)",
        ],
        rows,
    )


def goals_block(
    nominal: str | Path,
    perturbed: str | Path,
    controller: str,
    teacher: str,
    device_baseline: str,
    labels: tuple[str, str] | None = None,
) -> str:
    """:func:`goals_table` with the line that names its sets (*labels*: how the nominal and
    the perturbed set are named there, default their paths) and the goals."""
    nominal, perturbed = Path(nominal), Path(perturbed)
    names = labels or (nominal.as_posix(), perturbed.as_posix())
    table = goals_table(nominal, perturbed, controller, teacher, device_baseline)
    note = (
        f"(Generated by `myoexo results goals` from `{names[0]}` and `{names[1]}`; goals: "
        "`myoexo.evaluation.criteria.DeployableGoals`.)"
    )
    return "\n".join([table, "", note])


def headline_block(folder: str | Path, controllers: Sequence[str], label: str | None = None) -> str:
    """The short tables of *controllers* of a result set (the README's and the model cards'):
    for each, :func:`headline_table` and its line of :func:`aggregation_lines`, then the
    set's subjects and root seed (*label*: how the set's folder is named there, default its
    path).

    Raises:
        ValueError: The set lacks one of *controllers*.
    """
    folder = Path(folder)
    _, _, red, _, meta = _read(folder)
    label = label or folder.as_posix()
    missing = [c for c in controllers if c not in set(red.controller)]
    if missing:
        raise ValueError(f"the result set {label!r} has no {missing}")
    lines: list[str] = []
    aggregation = aggregation_lines(folder)
    for controller in controllers:
        lines += [
            f"**`{controller}`** against `{meta['reference']}` on the same subjects:",
            "",
            headline_table(folder, controller),
            "",
            *(f"- {line}" for line in aggregation if line.startswith(f"`{controller}`")),
            "",
        ]
    robust = " perturbed twins," if (meta.get("twin") or {}).get("robustness") else ""
    if (note := earlier_twin_note(meta)) is not None:
        lines += [note, ""]
    lines.append(
        f"({meta['subjects_per_level']} evaluation subjects per level,{robust} root seed "
        f"{meta['root_seed']}; generated by `myoexo results tables` from `{label}`.)"
    )
    return "\n".join(lines)


# ----------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class CollectOptions:
    """What ``myoexo results collect EVAL_DIR DEST`` reads and writes (its positional
    arguments and its option)."""

    eval_dir: Path = option(doc="a myoexo evaluate output folder", flag="")
    dest: Path = option(doc="the set's folder (created)", flag="", folder=True)
    update: bool = option(
        False,
        "add the evaluation's controllers to the existing set DEST (replacing rows of the "
        "same name) instead of writing a new one; it must hold the set's reference on the "
        "same subjects",
    )
    rerun_levels: tuple[int, ...] = option(
        (),
        "with --update: levels where the evaluation's reference may differ from the set's (a "
        "reference that never settles there, re-run by later code); the added controllers "
        "are paired with the evaluation's own reference there, and the set says so",
        metavar="LEVEL",
        low=0,
        high=3,
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class BoundOptions:
    """What ``myoexo results bound EVAL_DIR SET`` reads and writes (its positional
    arguments)."""

    eval_dir: Path = option(
        doc="a myoexo evaluate output folder of the set's reference on its subjects, with traces",
        flag="",
    )
    set: Path = option(doc="the result set whose hold bounds it recomputes", flag="")

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TablesOptions:
    """What ``myoexo results tables SET`` prints."""

    set: Path = option(doc="a result set folder (myoexo results collect)", flag="")
    controllers: tuple[str, ...] = option(
        (),
        "only the short table of each of these controllers (one row per level)",
        metavar="LABEL",
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class GoalsOptions:
    """What ``myoexo results goals NOMINAL PERTURBED`` judges (``--controller`` and
    ``--teacher`` are required)."""

    nominal: Path = option(doc="result set on the nominal twin", flag="")
    perturbed: Path = option(doc="result set of the same subjects, perturbed", flag="")
    controller: str = option(doc="the deployable controller (required, no default)")
    teacher: str = option(
        doc="the controller whose command smoothness it must match (required, no default)"
    )
    device_baseline: str = option("pid:tuned=exo", "the device's own baseline it must beat")

    def __post_init__(self) -> None:
        check_fields(self)


def _positionals(parser: argparse.ArgumentParser, cls: type, names: Sequence[str]) -> None:
    for name in names:
        add_positional(parser, cls, name)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo results``: each sub-command's are the fields of its options class
    (:class:`CollectOptions`, :class:`BoundOptions`, :class:`TablesOptions`,
    :class:`GoalsOptions`)."""
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    c = sub.add_parser("collect", help="write the result set of an evaluation folder")
    _positionals(c, CollectOptions, ("eval_dir", "dest"))
    add_options(c, CollectOptions)
    b = sub.add_parser(
        "bound", help="recompute a result set's hold bounds from its reference's traces"
    )
    _positionals(b, BoundOptions, ("eval_dir", "set"))
    add_options(b, BoundOptions)
    t = sub.add_parser("tables", help="print a result set's tables (Markdown)")
    _positionals(t, TablesOptions, ("set",))
    add_options(t, TablesOptions)
    g = sub.add_parser(
        "goals", help="print a deployable controller's table against its goals (Markdown)"
    )
    _positionals(g, GoalsOptions, ("nominal", "perturbed"))
    add_options(g, GoalsOptions)
    for action in g._actions:  # the fields have no default: their options are required
        if action.dest in ("controller", "teacher"):
            action.required = True


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo results``."""
    if args.action == "collect":
        co = from_options(CollectOptions, args, eval_dir=args.eval_dir, dest=args.dest)
        dest = collect(co.eval_dir, co.dest, update=co.update, rerun_levels=co.rerun_levels)
        print(f"result set: {dest}")
    elif args.action == "bound":
        bo = from_options(BoundOptions, args, eval_dir=args.eval_dir, set=args.set)
        print(f"hold bounds of: {bound(bo.eval_dir, bo.set)}")
    elif args.action == "tables":
        to = from_options(TablesOptions, args, set=args.set)
        if to.controllers:
            print(headline_block(to.set, to.controllers))
        else:
            print(render(to.set), end="")
    else:
        go = from_options(GoalsOptions, args, nominal=args.nominal, perturbed=args.perturbed)
        print(goals_block(go.nominal, go.perturbed, go.controller, go.teacher, go.device_baseline))
    return 0
