"""Tail risk, paired reductions and intervals of an evaluation (myoexo.evaluation.stats), and
the verdicts of an interval (myoexo.evaluation.criteria), with expectations worked out by
hand on small tables, not by the code under test."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from myoexo.evaluation.criteria import (
    combined_verdict,
    verdict,
    verdict_against,
    verdict_by_level,
)
from myoexo.evaluation.stats import (
    MEMBER,
    catastrophic_lines,
    crossed_interval,
    headline,
    mean_interval,
    pool_seed_groups,
    reduction_pct,
    reductions,
    tail_risk,
)


def _table(rows):
    cols = ["controller", "level", "subject", "abs_final_error_deg", "unstable"]
    return pd.DataFrame(rows, columns=cols)


def test_the_tail_names_the_worst_subject_and_counts_against_the_pids_worst():
    table = _table(
        [
            ("pid", 2, 0, 1.0, False),
            ("pid", 2, 1, 25.0, False),  # the PID's worst: 25 deg, beyond 20
            ("pid", 2, 2, 3.0, False),
            ("rl", 2, 0, 2.0, False),
            ("rl", 2, 1, 30.0, False),
            ("rl", 2, 2, 19.0, False),
            ("rl", 3, 0, math.nan, True),  # unstable: counted as the worst
            ("rl", 3, 1, 5.0, False),
        ]
    )
    risk = tail_risk(table).set_index(["controller", "level"])
    rl = risk.loc[("rl", 2)]
    assert rl.worst_subject == 1 and rl.worst_abs_final_error_deg == 30.0
    # sorted 2, 19, 30: p95 at position 1.9 = 19 + 0.9 * 11, p99 at 1.98 = 19 + 0.98 * 11
    assert rl.p95_abs_final_error_deg == pytest.approx(28.9)
    assert rl.p99_abs_final_error_deg == pytest.approx(29.78)
    assert rl.failures == 1 and rl.limit_deg == 25.0 and rl.catastrophic == 1
    assert risk.loc[("pid", 2)].catastrophic == 0 and risk.loc[("pid", 2)].failures == 1
    unstable = risk.loc[("rl", 3)]
    assert unstable.unstable == 1 and unstable.worst_subject == 0
    assert unstable.failures == 1 and unstable.limit_deg == 20.0  # no PID at level 3
    lines = catastrophic_lines(tail_risk(table))
    assert lines == [
        "`rl` at level 2: 1 of 3 subjects end beyond 25.0 deg (worst: subject 1, 30.0 deg)",
        "`rl` at level 3: 1 of 2 subjects end beyond 20.0 deg (worst: subject 0, inf deg)",
    ]


def test_a_subject_at_the_pids_own_worst_error_is_not_beyond_it():
    """Where the motor holds every controller at the PID's worst subject's angle, another
    controller ending there to within the tables' 0.01 deg is at the bound; 0.02 deg further
    is beyond."""
    worst = 20.606952
    table = _table(
        [
            ("pid", 2, 0, worst, False),
            ("pid", 2, 1, 3.0, False),
            ("rl", 2, 0, worst + 0.0011, False),  # the same angle, to 0.01 deg
            ("rl", 2, 1, 3.0, False),
            ("far", 2, 0, worst + 0.02, False),
            ("far", 2, 1, 3.0, False),
        ]
    )
    risk = tail_risk(table).set_index(["controller", "level"])
    assert risk.loc[("rl", 2)].catastrophic == 0 and risk.loc[("rl", 2)].failures == 1
    assert risk.loc[("far", 2)].catastrophic == 1


def test_verdicts_follow_the_whole_interval():
    assert verdict(11.0, 14.0, 10.6) == "met"
    assert verdict(5.0, 9.0, 10.6) == "missed"
    assert verdict(9.0, 12.0, 10.6) == "tie"
    assert verdict(0.5, 0.9, 1.0, higher_is_better=False) == "met"  # an error below 1 deg
    assert verdict(1.1, 2.0, 1.0, higher_is_better=False) == "missed"
    assert verdict(math.nan, 1.0, 1.0) == "n/a"


def test_an_interval_against_another_is_a_tie_where_they_overlap():
    assert verdict_against(0.9, 1.1, 1.9, 2.1) == "met"  # lower is better by default
    assert verdict_against(1.9, 2.1, 0.9, 1.1) == "missed"
    assert verdict_against(0.9, 1.1, 1.0, 1.2) == "tie"
    assert verdict_against(1.9, 2.1, 0.9, 1.1, higher_is_better=True) == "met"
    assert verdict_against(0.9, 1.1, math.nan, 1.2) == "n/a"


def test_verdicts_join_into_one():
    assert combined_verdict(["met", "met"]) == "met"
    assert combined_verdict(["met", "tie", "missed"]) == "missed"
    assert combined_verdict(["met", "tie"]) == "tie"
    assert verdict_by_level([0, 1], ["met", "met"]) == "met"
    calls = ["met", "tie", "missed", "n/a"]
    assert verdict_by_level([0, 1, 2, 3], calls) == "missed at level 2, tie at levels 1, 3"


def test_the_interval_of_a_mean_from_its_summary():
    low, high = mean_interval(5.0, 1.0, 100)  # t(99) at 97.5 % = 1.984
    assert low == pytest.approx(5.0 - 0.1984, abs=1e-4) and high == pytest.approx(
        5.0 + 0.1984, abs=1e-4
    )
    assert all(math.isnan(v) for v in mean_interval(5.0, 1.0, 1))


def test_a_paired_interval_keeps_the_pairs_together():
    ref = np.array([100.0, 120.0, 80.0, 110.0, 90.0])
    # the same 10 % lower on every subject: every resample gives exactly 10 %
    low, high = crossed_interval((ref, 0.9 * ref), reduction_pct)
    assert low == pytest.approx(10.0) and high == pytest.approx(10.0)
    assert reduction_pct(ref, 0.9 * ref) == pytest.approx(10.0)
    # independent noise: the interval brackets the sample value and has a width
    rng = np.random.default_rng(0)
    other = ref * (0.9 + 0.05 * rng.standard_normal(ref.size))
    low, high = crossed_interval((ref, other), reduction_pct)
    assert low < reduction_pct(ref, other) < high
    assert all(math.isnan(v) for v in crossed_interval((ref[:2], other[:2]), reduction_pct))
    # shapes that do not pair: no interval
    assert math.isnan(crossed_interval((ref, other[:4]), reduction_pct)[0])


def _mean(x, axis=-1):
    return np.mean(x, axis=axis)


def test_the_interval_over_seeds_and_subjects_covers_95_percent(monkeypatch):
    """Crossed data: value = seed effect + subject effect + noise, true mean 0. A 95 %
    interval must contain 0 in about 95 % of repetitions (a binomial 95 % band for 200
    repetitions is about 92-98 %); resampling the seeds alone with 5 of them covers less.

    The coverage is the method's (a t interval on two bootstrap variances), not the resample
    count's: 500 resamples a stage instead of the tables' 2000 (each standard error then
    within about 3 % instead of 1.6 %) check it in a quarter of the time."""
    from myoexo.evaluation import stats

    monkeypatch.setattr(stats, "N_RESAMPLES", 500)
    hits = seeds_only_hits = 0
    repetitions = 200
    for r in range(repetitions):
        rng = np.random.default_rng(1000 + r)
        x = rng.normal(0, 1, (5, 1)) + rng.normal(0, 1, (1, 100)) + rng.normal(0, 1, (5, 100))
        low, high = crossed_interval((x,), _mean, seed=r)
        hits += low <= 0.0 <= high
        seed_means = np.sort(x.mean(axis=1))
        seeds_only_hits += seed_means[0] <= 0.0 <= seed_means[-1]  # the seeds' full range
    assert 0.90 <= hits / repetitions <= 0.99
    assert seeds_only_hits / repetitions < hits / repetitions


def test_a_seed_spread_widens_the_interval():
    rng = np.random.default_rng(3)
    ref = rng.normal(100, 5, 200)
    same = ref * 0.9 + rng.normal(0, 1, (5, 200))  # five seeds that agree
    spread = same + np.array([[-4.0], [-2.0], [0.0], [2.0], [4.0]])  # five that do not
    lo1, hi1 = crossed_interval((ref, same), reduction_pct)
    lo2, hi2 = crossed_interval((ref, spread), reduction_pct)
    assert hi2 - lo2 > 3 * (hi1 - lo1)
    assert lo2 < reduction_pct(ref, spread.ravel()) < hi2


def test_a_seed_group_is_one_controller_over_its_seeds_and_subjects():
    rows = []
    for subject in range(6):
        rows.append(("pid", None, 2, subject, 100.0))
        rows.append(("s5-seed_0-step_100", "s5", 2, subject, 80.0))
        rows.append(("s5-seed_1-step_250", "s5", 2, subject, 90.0))
    cols = ["controller", "seed_group", "level", "subject", "peak"]
    table = pd.DataFrame(rows, columns=cols)
    table["peak_interaction_torque_nm"] = table["peak"]
    table["rms_interaction_torque_nm"] = table["peak"] / 2
    table["settling_time_s"] = 1.0
    table["abs_final_error_deg"] = table["peak"] / 10
    table["unstable"] = False
    # the group is the column's, not the labels': a table without it has no groups
    assert set(pool_seed_groups(table.drop(columns="seed_group")).controller) == set(
        table.controller
    )
    grouped = pool_seed_groups(table)
    assert list(dict.fromkeys(grouped.controller)) == ["pid", "s5"]
    assert set(grouped.loc[grouped.controller == "s5", MEMBER]) == {
        "s5-seed_0-step_100",
        "s5-seed_1-step_250",
    }
    red = reductions(grouped, "pid", "s5").set_index("level")
    # (20 % + 10 %) / 2 over 2 seeds x 6 subjects
    assert red.loc[2, "peak_reduction_pct"] == pytest.approx(15.0)
    assert red.loc[2, "seeds"] == 2 and red.loc[2, "n_paired"] == 12
    risk = tail_risk(grouped).set_index(["controller", "level"])
    assert risk.loc[("s5", 2), "n"] == 12 and risk.loc[("s5", 2), "worst_abs_final_error_deg"] == 9


def test_the_study_aggregation_is_the_mean_of_levels_1_and_2_and_settling_is_a_ratio():
    rows = []
    for subject in range(4):
        for level, ref_peak, oth_peak in ((1, 100.0, 90.0), (2, 100.0, 80.0), (3, 100.0, 50.0)):
            for label, peak, settle in (("pid", ref_peak, 1.0), ("rl", oth_peak, 2.0)):
                rows.append(
                    {
                        "controller": label,
                        "level": level,
                        "subject": subject,
                        "peak_interaction_torque_nm": peak,
                        "rms_interaction_torque_nm": peak / 2,
                        "abs_final_error_deg": 0.5 if label == "rl" else 0.2,
                        # rl never settles at level 3: counted, not dropped
                        "settling_time_s": math.nan if (label, level) == ("rl", 3) else settle,
                    }
                )
    table = pd.DataFrame(rows)
    study = headline(table, "pid", "rl", (1, 2))
    assert study["peak"] == pytest.approx(15.0) and study["rms"] == pytest.approx(15.0)
    assert study["peak_low"] == pytest.approx(15.0) == study["peak_high"]
    every = headline(table, "pid", "rl", (1, 2, 3))
    assert every["peak"] == pytest.approx((10 + 20 + 50) / 3)
    red = reductions(table, "pid", "rl").set_index("level")
    assert red.loc[1, "settling_ratio"] == pytest.approx(2.0)
    assert red.loc[3, "other_settled_pct"] == 0.0 and red.loc[3, "reference_settled_pct"] == 100
    assert red.loc[3, "n_both_settled"] == 0 and math.isnan(red.loc[3, "settling_ratio"])
    assert red.loc[2, "peak_reduction_pct"] == pytest.approx(20.0)
    # the final error and its paired difference from the PID's (0.5 - 0.2 on every subject)
    assert red.loc[1, "abs_final_error_deg"] == pytest.approx(0.5)
    assert red.loc[1, "abs_final_error_diff_deg"] == pytest.approx(0.3)
    assert red.loc[1, "abs_final_error_diff_deg_low"] == pytest.approx(0.3)
    assert red.loc[1, "abs_final_error_diff_deg_high"] == pytest.approx(0.3)


def test_the_studys_headline_is_its_levels_1_2_mean():
    from myoexo.evaluation.paper import PAPER_HEADLINES, PAPER_RESULTS
    from myoexo.evaluation.stats import HEADLINE_LEVELS

    assert HEADLINE_LEVELS == (1, 2)
    peak = np.mean([PAPER_RESULTS[lv].peak_reduction_pct for lv in HEADLINE_LEVELS])
    rms = np.mean([PAPER_RESULTS[lv].rms_reduction_pct for lv in HEADLINE_LEVELS])
    assert abs(peak - PAPER_HEADLINES.peak_reduction_pct) < 0.051  # (12.5 + 8.8) / 2 = 10.65
    assert abs(rms - PAPER_HEADLINES.rms_reduction_pct) <= 0.05  # (9.7 + 8.1) / 2 = 8.9
    four = np.mean([PAPER_RESULTS[lv].peak_reduction_pct for lv in range(4)])
    assert abs(four - PAPER_HEADLINES.peak_reduction_pct) > 3  # not the four-level mean
