"""The acceptance criteria: what a controller must meet, and the verdicts that say whether
it does.

:class:`Criteria` holds a controller against the PID, per level, on the same simulated
subjects (means over subjects; docs/reference.md section 5):

* mean absolute final error below the paper's SAC bound: 1 deg at levels 0-2, 11.45 deg at
  level 3 (:attr:`~myoexo.evaluation.paper.PaperLevelResults.sac_final_error_bound_deg`);
* peak interaction torque lower than the PID's at every level;
* RMS interaction torque up to settling lower than the PID's at every level (the study
  claims a lower RMS at all four levels, though its table gives no level-3 percentage).

:func:`compare_with_pid` makes the per-level table, :func:`shortfall` says how far a table is
from passing (0 = passes; checkpoint selection minimises it), :func:`ranking_score` ranks
policies during training (mean peak-torque reduction minus the final-error excess; higher is
better).

:class:`DeployableGoals` holds a controller that reads only the device's own sensors against
fixed accuracies and the paper's PID on held-out subjects.

A number measured with an interval is judged by the whole interval (:func:`verdict` against
a target, :func:`verdict_against` against another interval): met when it lies on the good
side, missed when it lies wholly on the other, a tie otherwise; :func:`combined_verdict` and
:func:`verdict_by_level` join several verdicts into one.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from myoexo.evaluation.paper import PAPER_RESULTS
from myoexo.spasticity.levels import VALID_LEVELS

#: The per-episode metrics the criteria use (columns of the evaluation table).
CRITERIA_METRICS: tuple[str, ...] = (
    "abs_final_error_deg",
    "final_error_deg",
    "settling_time_s",
    "rms_interaction_torque_nm",
    "peak_interaction_torque_nm",
)


def _paper_bounds() -> dict[int, float]:
    return {lv: PAPER_RESULTS[lv].sac_final_error_bound_deg for lv in VALID_LEVELS}


@dataclass(frozen=True)
class Criteria:
    """The acceptance criteria of a controller against the PID.

    Attributes:
        final_error_deg: Bound on the mean absolute final error per level, deg (default:
            the paper's SAC results).
        rms_levels: Levels where the RMS-to-settling must be lower than the PID's.
        peak_levels: Levels where the peak interaction torque must be lower than the PID's.
    """

    final_error_deg: Mapping[int, float] = field(default_factory=_paper_bounds)
    rms_levels: tuple[int, ...] = VALID_LEVELS
    peak_levels: tuple[int, ...] = VALID_LEVELS


@dataclass(frozen=True)
class DeployableGoals:
    """What a deployable controller (one that reads only the device's own sensors) must
    reach on held-out subjects, against the paper's PID, which reads the human knee.

    Attributes:
        easy_levels: Levels held to an absolute accuracy.
        easy_mean_deg: Bound on their mean absolute final error, nominal twin (deg).
        easy_p95_deg: Bound on their 95th-percentile absolute final error, nominal (deg).
        easy_mean_perturbed_deg: :attr:`easy_mean_deg` on perturbed twins (deg).
        easy_p95_perturbed_deg: :attr:`easy_p95_deg` on perturbed twins (deg).
        hard_levels: Levels held relative to the PID (the motor stalls against the reflex
            there, so no controller reaches the target).
        within_pid_deg: Bound on the mean absolute final error's excess over the PID's at
            those levels, on the same subjects (deg).
    """

    easy_levels: tuple[int, ...] = (0, 1)
    easy_mean_deg: float = 0.5
    easy_p95_deg: float = 1.0
    easy_mean_perturbed_deg: float = 1.0
    easy_p95_perturbed_deg: float = 2.0
    hard_levels: tuple[int, ...] = (2, 3)
    within_pid_deg: float = 1.5

    def easy_bounds(self, perturbed: bool) -> tuple[float, float]:
        """``(mean, p95)`` bounds of the easy levels' absolute final error on a nominal or a
        perturbed twin (deg)."""
        if perturbed:
            return self.easy_mean_perturbed_deg, self.easy_p95_perturbed_deg
        return self.easy_mean_deg, self.easy_p95_deg


def level_means(table: Any) -> Any:
    """Per-level means of :data:`CRITERIA_METRICS` from an evaluation table (pandas)."""
    return table.groupby("level")[list(CRITERIA_METRICS)].mean()


def _as_frame(means: Any) -> Any:
    """A per-level means table, from a DataFrame or a ``{level: {metric: value}}`` dict."""
    import pandas as pd

    if isinstance(means, Mapping):
        return pd.DataFrame.from_dict(dict(means), orient="index")
    return means


def compare_with_pid(policy: Any, pid: Any, criteria: Criteria | None = None) -> Any:
    """Side-by-side table per level with reductions against the PID and pass flags.

    Args:
        policy: Per-level means of the controller (:func:`level_means`, or a
            ``{level: {metric: value}}`` dict).
        pid: Per-level means of the PID on the same subjects.
        criteria: Bounds (default :class:`Criteria`).

    Returns:
        A DataFrame indexed by level: the policy's and the PID's final error, settling time,
        RMS and peak torque, ``rms_reduction_pct`` and ``peak_reduction_pct`` (positive =
        less than the PID), and the flags ``final_error_ok``, ``peak_ok``, ``rms_ok``,
        ``pass``.
    """
    import pandas as pd

    c = criteria or Criteria()
    pol, ref = _as_frame(policy), _as_frame(pid)
    rows = []
    for level in pol.index:
        s, p = pol.loc[level], ref.loc[level]
        pid_peak = float(p["peak_interaction_torque_nm"])
        pid_rms = float(p["rms_interaction_torque_nm"])
        peak_red = 100 * (pid_peak - float(s["peak_interaction_torque_nm"])) / max(pid_peak, 1e-9)
        rms_red = 100 * (pid_rms - float(s["rms_interaction_torque_nm"])) / max(pid_rms, 1e-9)
        row = {
            "level": int(level),
            "sac_final_error_deg": s.get("final_error_deg", float("nan")),
            "sac_abs_final_error_deg": float(s["abs_final_error_deg"]),
            "pid_final_error_deg": p.get("final_error_deg", float("nan")),
            "sac_settling_time_s": s.get("settling_time_s", float("nan")),
            "pid_settling_time_s": p.get("settling_time_s", float("nan")),
            "sac_rms_nm": float(s["rms_interaction_torque_nm"]),
            "pid_rms_nm": pid_rms,
            "rms_reduction_pct": rms_red,
            "sac_peak_nm": float(s["peak_interaction_torque_nm"]),
            "pid_peak_nm": pid_peak,
            "peak_reduction_pct": peak_red,
        }
        ok_err = row["sac_abs_final_error_deg"] < c.final_error_deg[int(level)]
        ok_peak = int(level) not in c.peak_levels or peak_red > 0
        ok_rms = int(level) not in c.rms_levels or rms_red > 0
        row.update(final_error_ok=ok_err, peak_ok=ok_peak, rms_ok=ok_rms)
        row["pass"] = bool(ok_err and ok_peak and ok_rms)
        rows.append(row)
    return pd.DataFrame(rows).set_index("level")


def final_error_excess(table: Any, criteria: Criteria | None = None) -> Any:
    """Per level, how far the mean absolute final error exceeds its bound, in units of the
    bound (0 where it is met)."""
    c = criteria or Criteria()
    bounds = table.index.map(lambda lv: c.final_error_deg[int(lv)])
    return (table.sac_abs_final_error_deg / bounds - 1.0).clip(lower=0.0)


def shortfall(table: Any, criteria: Criteria | None = None) -> float:
    """How far a :func:`compare_with_pid` table is from passing (0 when it passes; larger is worse):
    the sum over levels of the relative excess of the final error over its bound and of the
    relative peak / RMS increase over the PID."""
    c = criteria or Criteria()
    total = float(final_error_excess(table, c).sum())
    for level, row in table.iterrows():
        if level in c.peak_levels:
            total += max(0.0, -row.peak_reduction_pct / 100)
        if level in c.rms_levels:
            total += max(0.0, -row.rms_reduction_pct / 100)
    return total


def ranking_score(table: Any, criteria: Criteria | None = None) -> float:
    """Rank of a controller (higher is better): the mean over levels of its relative
    peak-torque reduction against the PID minus its final-error excess
    (:func:`final_error_excess`). A controller meeting every final-error bound scores its
    mean peak-torque reduction (a fraction)."""
    per_level = table.peak_reduction_pct / 100 - final_error_excess(table, criteria)
    return float(per_level.mean())


# ----------------------------------------------------------------------------- verdicts
def verdict(low: float, high: float, target: float, higher_is_better: bool = True) -> str:
    """``"met"`` if the whole interval ``[low, high]`` is on the good side of *target*,
    ``"missed"`` if it is wholly on the other side, else ``"tie"`` (``"n/a"`` without an
    interval)."""
    if not (math.isfinite(low) and math.isfinite(high)):
        return "n/a"
    if not higher_is_better:
        low, high, target = -high, -low, -target
    if low > target:
        return "met"
    if high < target:
        return "missed"
    return "tie"


def verdict_against(
    low: float, high: float, other_low: float, other_high: float, higher_is_better: bool = False
) -> str:
    """:func:`verdict` of an interval against another's instead of a number: ``"met"`` if
    ``[low, high]`` lies wholly on the good side of ``[other_low, other_high]``, ``"missed"``
    if wholly on the other, ``"tie"`` where they overlap (``"n/a"`` without both)."""
    if not all(math.isfinite(v) for v in (low, high, other_low, other_high)):
        return "n/a"
    if higher_is_better:
        low, high, other_low, other_high = -high, -low, -other_high, -other_low
    if high < other_low:
        return "met"
    if low > other_high:
        return "missed"
    return "tie"


def combined_verdict(calls: Sequence[str]) -> str:
    """One verdict of several: ``"met"`` if every one is met, ``"missed"`` if any is missed,
    else ``"tie"``."""
    if all(c == "met" for c in calls):
        return "met"
    return "missed" if "missed" in calls else "tie"


def verdict_by_level(levels: Sequence[int], calls: Sequence[str]) -> str:
    """One verdict over levels from each level's: ``"met"`` when no level misses or ties,
    else ``"missed at level(s) ..."`` and/or ``"tie at level(s) ..."`` (a level without an
    interval, ``"n/a"``, counts as a tie)."""
    missed = [lv for lv, c in zip(levels, calls, strict=True) if c == "missed"]
    ties = [lv for lv, c in zip(levels, calls, strict=True) if c in ("tie", "n/a")]
    if not missed and not ties:
        return "met"
    parts = [
        f"{word} at level{'s' if len(group) > 1 else ''} {', '.join(map(str, group))}"
        for word, group in (("missed", missed), ("tie", ties))
        if group
    ]
    return ", ".join(parts)
