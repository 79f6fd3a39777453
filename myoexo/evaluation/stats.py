"""Statistics of an evaluation: summaries, paired reductions, intervals and the tail.

Everything the tables report of a set of episodes is computed here, and nothing here judges
(the acceptance criteria and the verdicts of an interval are :mod:`myoexo.evaluation.criteria`):

* summaries: :func:`summarize_episodes` (per controller and level, the mean, std and
  quantiles of :data:`SUMMARY_METRICS`) and :func:`summarize_seeds` (per level, over the seeds
  of one configuration: mean, interquartile mean, bootstrap interval, pass fraction);
* seed groups: :func:`pool_seed_groups` makes the checkpoints of one group of training seeds
  one controller, so that its numbers are over the seeds *and* the subjects;
* paired comparisons on the same subjects: :func:`reductions` (per level, against the PID)
  and :func:`headline` (the mean over levels, the study's aggregation);
* intervals: :func:`crossed_interval` (over training seeds and subjects,
  :data:`INTERVAL_METHOD`), :func:`bootstrap_ci` (percentile bootstrap),
  :func:`wilson_interval` (a proportion), :func:`mean_interval` (Student-t, from a mean and a
  standard deviation);
* the tail: :func:`tail_risk` (the worst subject, the 95th and 99th percentiles of the
  absolute final error, the failures beyond :data:`FAILURE_DEG` and the catastrophic
  subjects, beyond that or the reference PID's own worst on the same subjects).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Collection, Sequence
from typing import Any

import numpy as np

#: An episode that ends farther than this from the target has failed, deg.
FAILURE_DEG = 20.0
#: An episode this close to the catastrophic bound is at it, not beyond it, deg (the
#: resolution the tables give final errors in): where the bound is the reference's own worst
#: subject, another controller that ends there too (the motor holds every controller at
#: nearly the same angle) differs from it by rounding or by thousandths of a degree.
AT_BOUND_DEG = 0.01
#: Resamples of a bootstrap (each stage of :func:`crossed_interval`, :func:`bootstrap_ci`).
N_RESAMPLES = 2000
#: Confidence level of the intervals.
CONFIDENCE = 0.95


# ----------------------------------------------------------------------------- summaries
#: Metrics summarized per controller and level (column -> label in the report).
SUMMARY_METRICS: dict[str, str] = {
    "final_error_deg": "final error (deg)",
    "final_swing_deg": "knee swing over the last second (deg)",
    "target_overshoot_deg": "overshoot past target (deg)",
    "settling_time_s": "settling time (s)",
    "rms_interaction_torque_nm": "RMS torque to settling (Nm)",
    "peak_interaction_torque_nm": "peak torque (Nm)",
    "peak_misalignment_deg": "peak misalignment (deg)",
    "command_rms": "command RMS (-)",
    "command_total_variation": "command total variation (-)",
}


def summarize_episodes(table: Any) -> Any:
    """Per (controller, level): count, unstable episodes, and mean / std / median / q25 /
    q75 of every metric of :data:`SUMMARY_METRICS` (NaN settling times ignored; NaN for a
    metric an older table lacks)."""
    import pandas as pd

    rows = []
    for (label, level), episodes in table.groupby(["controller", "level"], sort=False):
        row: dict[str, Any] = {
            "controller": label,
            "level": int(level),
            "n": len(episodes),
            "unstable": int(episodes["unstable"].sum()),
            "not_settled": int(episodes["settling_time_s"].isna().sum()),
        }
        for col in SUMMARY_METRICS:
            if col not in episodes:
                values = np.empty(0)
            else:
                values = episodes[col].to_numpy(dtype=float)
            values = values[np.isfinite(values)]
            stats = (
                (
                    values.mean(),
                    values.std(ddof=1) if values.size > 1 else 0.0,
                    *np.percentile(values, [50, 25, 75]),
                )
                if values.size
                else (math.nan,) * 5
            )
            for name, value in zip(("mean", "std", "median", "q25", "q75"), stats, strict=True):
                row[f"{col}_{name}"] = float(value)
        rows.append(row)
    return pd.DataFrame(rows)


def summarize_seeds(per_seed: Any, metrics: Collection[str]) -> Any:
    """Per level, over the seeds of one configuration (*per_seed*: one row per ``seed`` and
    ``level``, with the columns *metrics* and a boolean ``pass``): the mean, the interquartile
    mean and the bootstrap interval (:func:`bootstrap_ci`) of each of *metrics*, and the
    fraction of seeds that pass with its Wilson interval (:func:`wilson_interval`); indexed by
    level."""
    import pandas as pd

    rows = []
    for level, group in per_seed.groupby("level"):
        row: dict[str, Any] = {"level": int(level), "seeds": len(group)}
        for metric in metrics:
            values = group[metric].to_numpy(dtype=float)
            finite = values[np.isfinite(values)]
            lo, hi = bootstrap_ci(finite, seed=int(level))
            row[f"{metric}_mean"] = float(finite.mean()) if finite.size else math.nan
            row[f"{metric}_iqm"] = float(interquartile_mean(finite)) if finite.size else math.nan
            row[f"{metric}_ci_low"], row[f"{metric}_ci_high"] = lo, hi
        passed = int(group["pass"].sum())
        row["p_pass"] = passed / len(group)
        row["p_pass_ci_low"], row["p_pass_ci_high"] = wilson_interval(passed, len(group))
        rows.append(row)
    return pd.DataFrame(rows).set_index("level")


# ----------------------------------------------------------------------------- seed groups
#: Column of the episode table naming the seed group of an episode's controller
#: (:attr:`~myoexo.control.specs.ControllerSpec.seed_group`; empty for a controller of its
#: own).
SEED_GROUP = "seed_group"
#: Column of a pooled episode table (:func:`pool_seed_groups`) naming the controller an
#: episode was run with; ``controller`` then names its seed group.
MEMBER = "member"


def pool_seed_groups(table: Any) -> Any:
    """The episode table with the members of every seed group as one controller.

    An episode whose :data:`SEED_GROUP` is set (a checkpoint of a ``myoexo policy seeds``
    folder, a distillation seed's student) gets its group as ``controller`` and keeps its own
    label in the column :data:`MEMBER`, so means, tails and intervals are over the seeds
    *and* the subjects. Every other controller is a group of one, as is every controller of
    a table without the column.
    """
    out = table.copy()
    out[MEMBER] = out["controller"]
    if SEED_GROUP in out:
        group = out[SEED_GROUP]
        out["controller"] = group.where(group.notna() & (group != ""), out[MEMBER])
    return out


# ----------------------------------------------------------------------------- paired
def _paired_values(table: Any, reference: str, other: str, level: int, col: str) -> tuple:
    """``(reference, other)`` values of *col* on the subjects both ran at *level*: the
    reference's as ``(subjects,)``, the other's as ``(members, subjects)`` (one row per seed
    of a group, :func:`pool_seed_groups`), subject ``i`` the same person in both; only subjects
    that every member ran and whose values are all finite."""
    member = MEMBER if MEMBER in table else "controller"
    ref = table[(table.controller == reference) & (table.level == level)]
    ref = ref.drop_duplicates("subject").set_index("subject")[col]
    oth = table[(table.controller == other) & (table.level == level)]
    wide = oth.pivot_table(index=member, columns="subject", values=col, dropna=False)
    common = ref.index.intersection(wide.columns).sort_values()
    ref_v = ref.loc[common].to_numpy(dtype=float)
    oth_v = wide.loc[:, common].to_numpy(dtype=float)
    ok = np.isfinite(ref_v) & np.isfinite(oth_v).all(axis=0)
    return ref_v[ok], oth_v[:, ok]


def _mean(values: np.ndarray, axis: int = -1) -> Any:
    return np.mean(values, axis=axis)


def _mean_difference(reference: np.ndarray, other: np.ndarray, axis: int = -1) -> Any:
    return np.mean(other, axis=axis) - np.mean(reference, axis=axis)


def reductions(table: Any, reference: str, other: str) -> Any:
    """Per level, ``other`` (a controller, or a seed group: :func:`pool_seed_groups`) against
    ``reference`` on the same subjects:

    * the reduction of the RMS to settling and of the peak interaction torque, in % of the
      reference's mean, with a 95 % interval over seeds and subjects
      (:func:`crossed_interval`), and the paired difference
      (reference - other) as mean and std in Nm;
    * the mean absolute final error and its paired difference from the reference's (other -
      reference, deg), each with its interval (unstable episodes are left to the tail);
    * settling: the share of episodes that settle for each, and the ratio of the mean
      settling times on the subjects where both settle (with its interval); unsettled
      episodes are counted, not dropped."""
    import pandas as pd

    rows = []
    cols = {"rms": "rms_interaction_torque_nm", "peak": "peak_interaction_torque_nm"}
    levels = sorted(
        set(table.level[table.controller == reference])
        & set(table.level[table.controller == other])
    )
    for level in levels:
        row: dict[str, Any] = {"level": int(level)}
        for key, col in cols.items():
            ref, oth = _paired_values(table, reference, other, level, col)
            row["n_paired"] = int(oth.size)
            row["seeds"] = int(oth.shape[0])
            diff = ref - oth
            row[f"{key}_reduction_pct"] = (
                float(reduction_pct(ref, oth.ravel())) if ref.size and ref.mean() else math.nan
            )
            low, high = crossed_interval((ref, oth), reduction_pct, seed=int(level))
            row[f"{key}_reduction_pct_low"], row[f"{key}_reduction_pct_high"] = low, high
            row[f"{key}_paired_diff_nm_mean"] = float(diff.mean()) if diff.size else math.nan
            row[f"{key}_paired_diff_nm_std"] = (
                float(diff.std(ddof=1)) if diff.size > 1 else math.nan
            )
        ref_e, oth_e = _paired_values(table, reference, other, level, "abs_final_error_deg")
        row["abs_final_error_deg"] = float(oth_e.mean()) if oth_e.size else math.nan
        row["abs_final_error_deg_low"], row["abs_final_error_deg_high"] = crossed_interval(
            (oth_e,), _mean, seed=int(level)
        )
        row["abs_final_error_diff_deg"] = (
            float(oth_e.mean() - ref_e.mean()) if oth_e.size else math.nan
        )
        row["abs_final_error_diff_deg_low"], row["abs_final_error_diff_deg_high"] = (
            crossed_interval((ref_e, oth_e), _mean_difference, seed=int(level))
        )
        level_rows = table[table.level == level]
        settled = np.isfinite(level_rows["settling_time_s"].to_numpy(dtype=float))
        for who, name in (("reference", reference), ("other", other)):
            mine = (level_rows.controller == name).to_numpy()
            row[f"{who}_settled_pct"] = 100.0 * float(settled[mine].mean())
        ref_s, oth_s = _paired_values(table, reference, other, level, "settling_time_s")
        row["n_both_settled"] = int(oth_s.size)
        row["settling_ratio"] = float(mean_ratio(ref_s, oth_s.ravel())) if ref_s.size else math.nan
        row["settling_ratio_low"], row["settling_ratio_high"] = crossed_interval(
            (ref_s, oth_s), mean_ratio, seed=int(level)
        )
        rows.append(row)
    return pd.DataFrame(rows)


#: The levels whose mean is the study's headline (its peak 10.6 % and RMS 8.9 % are the
#: means over the spastic levels where its SAC reaches the target: (12.5 + 8.8) / 2 and
#: (9.7 + 8.1) / 2).
HEADLINE_LEVELS: tuple[int, ...] = (1, 2)


def headline(table: Any, reference: str, other: str, levels: Sequence[int]) -> dict[str, Any]:
    """The mean over *levels* of the per-level peak and RMS reductions of ``other`` against
    ``reference``, each with a 95 % interval over seeds and subjects (the levels' subject
    ``i`` together; ``nan`` where a level is missing or the levels have other subjects)."""
    out: dict[str, Any] = {"levels": tuple(levels)}
    cols = {"rms": "rms_interaction_torque_nm", "peak": "peak_interaction_torque_nm"}
    for key, col in cols.items():
        arrays: list[np.ndarray] = []
        for level in levels:
            arrays += list(_paired_values(table, reference, other, level, col))
        subjects = {a.shape[-1] for a in arrays}
        if not arrays or len(subjects) != 1 or 0 in subjects:
            out[key] = out[f"{key}_low"] = out[f"{key}_high"] = math.nan
            continue
        out[key] = float(mean_reduction_pct(*(a.ravel() for a in arrays)))
        out[f"{key}_low"], out[f"{key}_high"] = crossed_interval(arrays, mean_reduction_pct)
    return out


# ----------------------------------------------------------------------------- intervals
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


def mean_reduction_pct(*pairs: np.ndarray, axis: int = -1) -> Any:
    """The mean over levels of :func:`reduction_pct`: *pairs* is ``reference_1, other_1,
    reference_2, other_2, ...``, one reference and one other array per level."""
    levels = [reduction_pct(pairs[i], pairs[i + 1], axis=axis) for i in range(0, len(pairs), 2)]
    return np.mean(levels, axis=0)


def mean_ratio(reference: np.ndarray, other: np.ndarray, axis: int = -1) -> Any:
    """``mean(other) / mean(reference)`` (e.g. settling time relative to the PID's)."""
    return np.mean(other, axis=axis) / np.mean(reference, axis=axis)


def interquartile_mean(x: Any, axis: int = -1) -> Any:
    """Mean of the middle 50 % (``scipy.stats.trim_mean(x, 0.25)``), rliable's IQM."""
    from scipy.stats import trim_mean

    return trim_mean(x, 0.25, axis=axis)


def bootstrap_ci(values: Sequence[float], statistic: Any = np.mean, seed: int = 0) -> tuple:
    """95 % percentile-bootstrap interval of ``statistic`` over *values* (resampling them);
    ``(nan, nan)`` for fewer than two finite values."""
    from scipy.stats import bootstrap

    x = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if x.size < 2 or np.all(x == x[0]):
        v = float(x[0]) if x.size else math.nan
        return (v, v) if x.size else (math.nan, math.nan)
    res = bootstrap(
        (x,),
        lambda s, axis=-1: statistic(s, axis=axis),
        n_resamples=N_RESAMPLES,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson 95 % interval of a proportion."""
    if n == 0:
        return math.nan, math.nan
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return centre - half, centre + half


def mean_interval(mean: float, std: float, n: int) -> tuple[float, float]:
    """The Student-t 95 % interval of a mean over *n* values from the mean and their
    standard deviation; ``(nan, nan)`` for fewer than two values."""
    from scipy.stats import t

    if n < 2:
        return math.nan, math.nan
    half = float(t.ppf(0.975, n - 1)) * std / math.sqrt(n)
    return mean - half, mean + half


# ----------------------------------------------------------------------------- the tail
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
        beyond ``limit_deg`` by more than :data:`AT_BOUND_DEG`) and ``unstable``.
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
                "catastrophic": int((finite > limit + AT_BOUND_DEG).sum()),
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
