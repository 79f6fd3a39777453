"""What a controller can reach at most: the distance to the oracle (:mod:`myoexo.control.oracle`)
and the bound the reference's hold torque sets on the peak reduction.

**Hold bound.** Where the motor stalls against the reflex (level 2: the knee ends short of the
target), the strap carries the hold at the end of the episode. A controller that ends where
the reference ends holds the same torque there, so its peak interaction torque (over the
whole episode) is at least that hold: its peak reduction against the reference (in % of the
reference's mean peak) is at most ``100 (1 - mean hold / mean reference peak)``
(:func:`hold_bounds`, from the reference's stored traces). It binds at the levels where the
study's claims keep a controller at the reference's own final error
(:data:`HOLD_BOUND_LEVELS`); the result tables then say "out of reach" for a claim above it.

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

#: Levels where the study's claims keep a controller at the reference's own final error
#: (level 2: "no worse than the PID"), so the reference's hold bounds its peak reduction.
#: Not levels 0-1 (within 1 deg of the target) nor 3 (within 11.45 deg: a controller may end
#: further out than the PID and hold less).
HOLD_BOUND_LEVELS: tuple[int, ...] = (2,)


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
    interaction torque over the last *window_s*), ``reference_peak_nm`` (the reference's
    mean peak on the same subjects) and ``peak_reduction_bound_pct``. A level without traces
    is left out.
    """
    import numpy as np

    from myoexo.evaluation.storage import load_traces

    rows = []
    for level in sorted(set(int(v) for v in levels) & set(HOLD_BOUND_LEVELS)):
        try:
            traces = load_traces(eval_dir, reference, level)
        except ValueError:  # the evaluation stored no traces
            continue
        end = np.asarray(traces.time_s) >= traces.time_s[-1] - window_s + 1e-9
        hold = traces["interaction_torque_nm"][:, end].mean(axis=1)
        ref = table[(table.controller == reference) & (table.level == level)]
        peak = ref.set_index("subject").loc[traces.subjects, "peak_interaction_torque_nm"]
        hold_nm, peak_nm = float(hold.mean()), float(peak.mean())
        rows.append(
            {
                "level": level,
                "subjects": len(hold),
                "window_s": float(window_s),
                "hold_torque_nm": hold_nm,
                "reference_peak_nm": peak_nm,
                "peak_reduction_bound_pct": 100.0 * (1.0 - hold_nm / peak_nm),
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
