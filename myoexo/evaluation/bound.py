"""What a controller can reach at most: the distance to the oracle (:mod:`myoexo.control.oracle`)
and the bound the reference's hold torque sets on the peak reduction.

**Hold bound.** Where the motor stalls against the reflex (levels 2-3: the knee ends short of
the target), the strap carries the hold at the end of the episode, and a controller's peak
interaction torque (over the whole episode) is at least its own hold. How far short the
study's accuracy claim lets a controller end sets how little it may hold:

* **level 2**: the claim (< 1 deg) is below the reference's own final error, the motor's
  stall; the study's claims are read there as "no worse than the reference", so a controller
  that meets them ends where the reference ends and holds the reference's torque;
* **level 3**: the claim (< 11.45 deg) lies ``slack`` deg beyond the reference's mean absolute
  final error, and a knee held ``x`` deg further short needs at most ``x`` times the twin's
  steepest **hold slope** less torque (Nm/deg, measured by ``myoexo twin hold-slope``, the
  package's fit :data:`HOLD_SLOPE_FIT`; a level it has not measured gets no bound there).

So its mean peak is at least ``hold - slope x slack`` (the reference's mean hold over the last
:data:`HOLD_WINDOW_S`, from its stored traces), and its peak reduction against the reference
(in % of the reference's mean peak) at most ``100 (1 - (hold - slope x slack) / mean reference
peak)`` (:func:`hold_bound`, :func:`hold_bounds`). The result tables then say "out of reach" for
a claim above it. Levels 0-1 (the knee reaches the target) are not bounded
(:data:`HOLD_BOUND_LEVELS`). Two assumptions stand behind it: no controller holds the knee
further extended than the reference, whose motor is at its limit there; and the slope is the
steepest the fit's subjects show (a measurement on 20 subjects per level of root 3, nominal
and perturbed, not a proof for every subject).

**Distance to the oracle.**

The oracle is slow, so it usually runs on the first few subjects of a level while the other
controllers run on many; the distance is taken on the subjects both have (subject *i* is the
same person for every controller of an evaluation with the same root seed and twin).

    table = load_table("results/eval")            # pid, sac, student_exo: 1000 subjects/level
    bound = load_table("results/oracle")          # oracle: 10 subjects/level
    distance_to_bound(pd.concat([table, bound]))
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

#: Controller labels that are the bound (``oracle`` or ``oracle:<options>``).
BOUND_PREFIX = "oracle"

#: The end of an episode over which the reference's hold torque is averaged, s.
HOLD_WINDOW_S = 0.5

#: Levels where the motor stalls against the reflex, so the reference's hold bounds the peak
#: reduction of a controller that meets the study's accuracy claim (module docstring).
HOLD_BOUND_LEVELS: tuple[int, ...] = (2, 3)

#: The package's fit of the hold slope per level (``myoexo twin hold-slope --write``).
HOLD_SLOPE_FIT = "hold_slope"


def mean_over_end(time_s: Any, values: Any, window_s: float = HOLD_WINDOW_S) -> Any:
    """The mean of *values* (their last axis along *time_s*: one episode, or one row per
    episode) over the episode's last *window_s*, the window of the final values
    (:func:`~myoexo.evaluation.metrics.end_window`); of the interaction torque over
    :data:`HOLD_WINDOW_S`, the hold."""
    import numpy as np

    from myoexo.evaluation.metrics import end_window

    return np.asarray(values)[..., end_window(time_s, window_s)].mean(axis=-1)


def hold_slope_nm_per_deg(level: int) -> float | None:
    """The twin's steepest hold slope at *level* (Nm per degree further short, the package's
    fit :data:`HOLD_SLOPE_FIT`); ``None`` where it has not been measured."""
    from myoexo.runtime.fits import fit_path, read_fit

    if not fit_path(HOLD_SLOPE_FIT).exists():
        return None
    entry = read_fit(HOLD_SLOPE_FIT)["result"]["levels"].get(str(int(level)))
    return None if entry is None else float(entry["max_nm_per_deg"])


def hold_bound(
    hold_nm: float,
    reference_peak_nm: float,
    reference_error_deg: float,
    claim_deg: float,
    slope_nm_per_deg: float | None,
) -> dict[str, float] | None:
    """The hold bound of one level (module docstring): ``slack_deg`` (how much further short
    than the reference, on average, *claim_deg* lets a controller end: 0 where the reference
    ends beyond the claim), ``hold_slope_nm_per_deg`` (0 without slack), ``least_hold_nm``
    and ``peak_reduction_bound_pct``; ``None`` where there is slack and no measured slope.

    Args:
        hold_nm: The reference's mean hold.
        reference_peak_nm: The reference's mean peak on the same subjects.
        reference_error_deg: The reference's mean absolute final error on them.
        claim_deg: The study's bound on the mean absolute final error at that level.
        slope_nm_per_deg: The twin's steepest hold slope there (``None``: not measured).
    """
    slack = max(0.0, claim_deg - reference_error_deg)
    if slack > 0.0 and slope_nm_per_deg is None:
        return None
    slope = float(slope_nm_per_deg or 0.0) if slack > 0.0 else 0.0
    least = hold_nm - slope * slack
    return {
        "slack_deg": slack,
        "hold_slope_nm_per_deg": slope,
        "least_hold_nm": least,
        "peak_reduction_bound_pct": 100.0 * (1.0 - least / reference_peak_nm),
    }


def hold_bounds(
    eval_dir: str | Path,
    table: Any,
    reference: str,
    levels: Sequence[int],
    window_s: float = HOLD_WINDOW_S,
) -> list[dict[str, float]]:
    """Per level of *levels* in :data:`HOLD_BOUND_LEVELS`, the hold bound of the module
    docstring, from the reference's stored traces in the evaluation folder *eval_dir* and its
    episodes in *table* (that folder's :func:`~myoexo.evaluation.storage.load_table`):
    ``level``, ``subjects``, ``window_s``, ``hold_torque_nm`` (the mean over subjects of the
    interaction torque over the last *window_s*), ``reference_peak_nm`` and
    ``reference_abs_final_error_deg`` (the reference's means on the same subjects), and
    :func:`hold_bound`'s fields. A level without traces, or with slack and no measured hold
    slope, is left out.
    """

    from myoexo.evaluation.paper import PAPER_RESULTS
    from myoexo.evaluation.storage import load_traces

    rows = []
    for level in sorted(set(int(v) for v in levels) & set(HOLD_BOUND_LEVELS)):
        try:
            traces = load_traces(eval_dir, reference, level)
        except ValueError:  # the evaluation stored no traces
            continue
        hold = mean_over_end(traces.time_s, traces["interaction_torque_nm"], window_s)
        ref = table[(table.controller == reference) & (table.level == level)]
        ref = ref.set_index("subject").loc[traces.subjects]
        hold_nm = float(hold.mean())
        peak_nm = float(ref.peak_interaction_torque_nm.mean())
        error_deg = float(ref.abs_final_error_deg.mean())
        bound = hold_bound(
            hold_nm,
            peak_nm,
            error_deg,
            PAPER_RESULTS[level].sac_final_error_bound_deg,
            hold_slope_nm_per_deg(level),
        )
        if bound is None:
            continue
        rows.append(
            {
                "level": level,
                "subjects": len(hold),
                "window_s": float(window_s),
                "hold_torque_nm": hold_nm,
                "reference_peak_nm": peak_nm,
                "reference_abs_final_error_deg": error_deg,
                **bound,
            }
        )
    return rows


def bound_label(labels: Any) -> str | None:
    """The first label naming the oracle, else ``None``."""
    return next((str(c) for c in labels if str(c).startswith(BOUND_PREFIX)), None)


def distance_to_bound(table: Any, bound: str | None = None) -> Any:
    """Per controller and level, on the subjects the bound ran: the mean absolute final
    error, the bound's, their difference, and both peak / RMS interaction torques.

    Args:
        table: Episode table(s) (:func:`~myoexo.evaluation.load_table`) holding the bound's
            episodes too.
        bound: The bound's label (default: :func:`bound_label`).

    Returns:
        DataFrame with columns ``controller, level, subjects, abs_final_error_deg,
        bound_abs_final_error_deg, distance_deg, peak_nm, bound_peak_nm, rms_nm,
        bound_rms_nm`` (one row per controller other than the bound and level).

    Raises:
        ValueError: No oracle in the table.
    """
    import pandas as pd

    bound = bound or bound_label(table["controller"].unique())
    if bound is None:
        raise ValueError("the table holds no oracle episodes (controller 'oracle...')")
    cols = ["abs_final_error_deg", "peak_interaction_torque_nm", "rms_interaction_torque_nm"]
    ref = table[table.controller == bound].set_index(["level", "subject"])[cols]
    rows = []
    for (ctrl, level), group in table[table.controller != bound].groupby(["controller", "level"]):
        g = group.set_index(["level", "subject"])[cols]
        common = g.index.intersection(ref.index)
        if common.empty:
            continue
        mine, best = g.loc[common].mean(), ref.loc[common].mean()
        rows.append(
            {
                "controller": ctrl,
                "level": int(level),
                "subjects": len(common),
                "abs_final_error_deg": mine.abs_final_error_deg,
                "bound_abs_final_error_deg": best.abs_final_error_deg,
                "distance_deg": mine.abs_final_error_deg - best.abs_final_error_deg,
                "peak_nm": mine.peak_interaction_torque_nm,
                "bound_peak_nm": best.peak_interaction_torque_nm,
                "rms_nm": mine.rms_interaction_torque_nm,
                "bound_rms_nm": best.rms_interaction_torque_nm,
            }
        )
    return pd.DataFrame(rows)


def bound_markdown(table: Any) -> str:
    """:func:`distance_to_bound` as a Markdown table (deg and Nm, 2 decimals)."""
    d = distance_to_bound(table)
    if d.empty:
        return "(no subject in common with the bound)"
    out = d.rename(
        columns={
            "abs_final_error_deg": "|final error| (deg)",
            "bound_abs_final_error_deg": "bound (deg)",
            "distance_deg": "distance (deg)",
            "peak_nm": "peak (Nm)",
            "bound_peak_nm": "bound peak (Nm)",
            "rms_nm": "RMS (Nm)",
            "bound_rms_nm": "bound RMS (Nm)",
        }
    )
    return str(out.round(2).to_markdown(index=False))
