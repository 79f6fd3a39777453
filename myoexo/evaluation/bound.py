"""Each controller's distance to the achievable bound (the oracle, :mod:`myoexo.control.oracle`).

The oracle is slow, so it usually runs on the first few subjects of a level while the other
controllers run on many; the distance is taken on the subjects both have (subject *i* is the
same person for every controller of an evaluation with the same root seed and twin).

    table = load_table("results/eval")            # pid, sac, student_exo: 1000 subjects/level
    bound = load_table("results/oracle")          # oracle: 10 subjects/level
    distance_to_bound(pd.concat([table, bound]))
"""

from __future__ import annotations

from typing import Any

#: Controller labels that are the bound (``oracle`` or ``oracle:<options>``).
BOUND_PREFIX = "oracle"


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
