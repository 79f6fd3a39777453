"""Tail risk and uncertainty of an evaluation: what the means hide.

A controller that is good on average can still fail a few people badly. Per controller and
level, :func:`tail_risk` gives the worst subject, the 95th and 99th percentiles of the
absolute final error, the count of *failures* (an episode that ends farther than
:data:`FAILURE_DEG` from the target) and of *catastrophic* subjects (beyond the failure
bound or beyond the reference PID's own worst on the same subjects, whichever is larger),
and the unstable episodes. :func:`crossed_interval` gives a 95 % interval of a paired
statistic over training seeds *and* subjects (:data:`INTERVAL_METHOD`), and :func:`verdict`
calls a criterion met, missed or a tie by its interval.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

#: An episode that ends farther than this from the target has failed, deg.
FAILURE_DEG = 20.0
#: Bootstrap resamples of each stage of :func:`crossed_interval`.
N_RESAMPLES = 2000
#: Confidence level of the intervals.
CONFIDENCE = 0.95


def tail_risk(table: Any, reference: str | None = "pid", failure_deg: float = FAILURE_DEG) -> Any:
    """Per (controller, level): the tail of the absolute final error.

    Args:
        table: Episode table (one row per episode: ``controller``, ``level``, ``subject``,
            ``abs_final_error_deg``, ``unstable``).
        reference: The controller whose worst subject at a level raises that level's
            catastrophic bound (``None``: the failure bound alone).
        failure_deg: The failure bound, deg.

    Returns:
        A DataFrame with ``controller``, ``level``, ``n``, ``worst_subject``,
        ``worst_abs_final_error_deg`` (``inf`` for an unstable episode),
        ``p95_abs_final_error_deg``, ``p99_abs_final_error_deg`` (of the episodes that
        ended stably), ``failures`` (episodes beyond *failure_deg*),
        ``limit_deg`` (``max(failure_deg, reference's worst)``), ``catastrophic`` (episodes
        beyond ``limit_deg``) and ``unstable``.
    """
    import pandas as pd

    worst_ref: dict[int, float] = {}
    if reference is not None:
        ref = table[table.controller == reference]
        worst_ref = {
            int(lv): float(g["abs_final_error_deg"].max()) for lv, g in ref.groupby("level")
        }
    rows = []
    for (label, level), g in table.groupby(["controller", "level"], sort=False):
        err = g["abs_final_error_deg"].to_numpy(dtype=float)
        finite = np.where(np.isfinite(err), err, np.inf)  # an unstable episode is the worst
        i = int(np.argmax(finite))
        limit = max(failure_deg, worst_ref.get(int(level), failure_deg))
        stable = err[np.isfinite(err)]  # percentiles of the episodes that ended
        p95, p99 = np.percentile(stable, [95, 99]) if stable.size else (math.nan, math.nan)
        rows.append(
            {
                "controller": label,
                "level": int(level),
                "n": len(g),
                "worst_subject": int(g["subject"].iloc[i]),
                "worst_abs_final_error_deg": float(finite[i]),
                "p95_abs_final_error_deg": float(p95),
                "p99_abs_final_error_deg": float(p99),
                "failures": int((finite > failure_deg).sum()),
                "limit_deg": float(limit),
                "catastrophic": int((finite > limit).sum()),
                "unstable": int(g["unstable"].astype(bool).sum()),
            }
        )
    return pd.DataFrame(rows)


def catastrophic_lines(risk: Any) -> list[str]:
    """One line per (controller, level) with catastrophic subjects (empty if none)."""
    lines = []
    for r in risk.itertuples():
        if r.catastrophic:
            lines.append(
                f"`{r.controller}` at level {r.level}: {r.catastrophic} of {r.n} subjects end "
                f"beyond {r.limit_deg:.1f} deg (worst: subject {r.worst_subject}, "
                f"{r.worst_abs_final_error_deg:.1f} deg)"
            )
    return lines


#: How :func:`crossed_interval` computes an interval, in words (the tables state it).
INTERVAL_METHOD = (
    "95 % Student-t interval whose standard error adds two bootstrap variances "
    "(scipy.stats.bootstrap, 2000 resamples each, bias-corrected by n/(n-1)): one resampling "
    "the training seeds with the subjects fixed, one resampling the subjects (pairs kept "
    "together, every seed's episode of a subject with it) with the seeds fixed; degrees of "
    "freedom by Welch-Satterthwaite, so 5 seeds give a t with about 4 of them where the seeds "
    "dominate (a percentile bootstrap over 5 seeds covers about 84 %)"
)


def _stage_variance(
    data: Sequence[np.ndarray], statistic: Callable[..., Any], axis: int, seed: int
) -> float:
    """Bias-corrected bootstrap variance of *statistic* resampling one axis of the 2-D
    arrays of *data* (0: the seeds, of the arrays with several; 1: the subjects, of all)."""
    from scipy.stats import bootstrap

    n = max(a.shape[axis] for a in data)

    def pick(a: np.ndarray, idx: np.ndarray) -> np.ndarray:
        if axis == 1:
            return np.moveaxis(a[:, idx], 1, 0)  # (batch, seeds_i, n)
        if a.shape[0] == 1:
            return np.broadcast_to(a, (idx.shape[0], *a.shape))  # no seeds to resample
        return a[idx]  # (batch, n, subjects)

    def stat(idx: np.ndarray, axis: int = -1) -> Any:
        idx = np.atleast_2d(idx).astype(np.intp)  # (batch, n) resampled indices
        flat = [pick(a, idx).reshape(idx.shape[0], -1) for a in data]
        return statistic(*flat, axis=-1)

    res = bootstrap(
        (np.arange(n),),
        stat,
        vectorized=True,
        n_resamples=N_RESAMPLES,
        confidence_level=CONFIDENCE,
        method="percentile",
        batch=200,
        random_state=np.random.default_rng(seed),
    )
    return float(res.standard_error) ** 2 * n / (n - 1)


def crossed_interval(
    arrays: Sequence[np.ndarray], statistic: Callable[..., Any], seed: int = 0
) -> tuple[float, float]:
    """95 % interval of ``statistic(*arrays, axis=-1)`` over training seeds and subjects
    (:data:`INTERVAL_METHOD`).

    Args:
        arrays: One array per argument of *statistic*, each ``(subjects,)`` or ``(seeds,
            subjects)``: row ``s`` is training seed ``s`` and column ``i`` is subject ``i``,
            the same person in every array (a controller without seeds, such as the PID, has
            one row). Arrays with several rows have the same number of them.
        statistic: Vectorized statistic of flattened arrays (``axis=-1``), e.g.
            :func:`reduction_pct`.
        seed: Seed of the resampling.

    Returns:
        ``(low, high)``; ``(nan, nan)`` with fewer than 3 subjects or arrays of unequal
        shapes. With one seed the interval resamples subjects only.
    """
    from scipy.stats import t

    data = [np.atleast_2d(np.asarray(a, dtype=float)) for a in arrays]
    n_subjects = {a.shape[1] for a in data}
    n_seeds = {a.shape[0] for a in data} - {1}
    if len(n_subjects) != 1 or len(n_seeds) > 1 or next(iter(n_subjects)) < 3:
        return math.nan, math.nan
    n, s = next(iter(n_subjects)), (next(iter(n_seeds)) if n_seeds else 1)
    estimate = float(statistic(*(a.reshape(-1) for a in data), axis=-1))
    if not math.isfinite(estimate):
        return math.nan, math.nan
    var_subj = _stage_variance(data, statistic, axis=1, seed=seed)
    var_seed = _stage_variance(data, statistic, axis=0, seed=seed + 1) if s > 1 else 0.0
    var = var_subj + var_seed
    if not var > 0:
        return estimate, estimate
    terms = var_subj**2 / (n - 1) + (var_seed**2 / (s - 1) if s > 1 else 0.0)
    dof = var**2 / terms
    half = float(t.ppf(0.5 + CONFIDENCE / 2, dof)) * math.sqrt(var)
    return estimate - half, estimate + half


def reduction_pct(reference: np.ndarray, other: np.ndarray, axis: int = -1) -> Any:
    """``100 (mean(reference) - mean(other)) / mean(reference)``: the reduction in % of the
    reference's mean (vectorized over *axis*)."""
    ref = np.mean(reference, axis=axis)
    return 100.0 * (ref - np.mean(other, axis=axis)) / ref


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


def mean_reduction_pct(*pairs: np.ndarray, axis: int = -1) -> Any:
    """The mean over levels of :func:`reduction_pct`: *pairs* is ``reference_1, other_1,
    reference_2, other_2, ...``, one reference and one other array per level."""
    levels = [reduction_pct(pairs[i], pairs[i + 1], axis=axis) for i in range(0, len(pairs), 2)]
    return np.mean(levels, axis=0)


def mean_ratio(reference: np.ndarray, other: np.ndarray, axis: int = -1) -> Any:
    """``mean(other) / mean(reference)`` (e.g. settling time relative to the PID's)."""
    return np.mean(other, axis=axis) / np.mean(reference, axis=axis)
