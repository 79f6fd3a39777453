"""The torque-versus-settling frontier: which points are accurate and non-dominated, the
study's point placed from our PID, the shaped-PID specs."""

from __future__ import annotations

import math

import pandas as pd
import pytest

from myoexo.studies import frontier as F


def _pts(rows):
    return pd.DataFrame(
        rows,
        columns=[
            "controller",
            "level",
            "abs_final_error_deg",
            "settling_time_s",
            "peak_interaction_torque_nm",
            "rms_interaction_torque_nm",
        ],
    )


def test_frontier_keeps_accurate_non_dominated_points():
    pts = _pts(
        [
            ("pid", 0, 0.0, 1.0, 140.0, 100.0),
            ("fast_hard", 0, 0.2, 0.5, 150.0, 110.0),  # faster, harder: on the frontier
            ("slow_soft", 0, 0.3, 2.0, 100.0, 60.0),  # slower, softer: on the frontier
            ("dominated", 0, 0.1, 1.5, 145.0, 90.0),  # slower and harder than the PID
            ("inaccurate", 0, 5.0, 0.4, 50.0, 40.0),  # best torque but misses the target
            ("never", 0, 0.0, math.nan, 80.0, 70.0),  # never settled
        ]
    )
    marked = F.mark_frontier(pts, accuracy_deg=1.0).set_index("controller")
    assert marked.loc[["pid", "fast_hard", "slow_soft"], "on_frontier"].all()
    assert not marked.loc["dominated", "on_frontier"] and marked.loc["dominated", "accurate"]
    assert not marked.loc["inaccurate", "accurate"] and not marked.loc["never", "accurate"]


def test_accuracy_is_relative_to_the_best_of_the_level():
    """At a level where the motor limit stalls everyone ~6 deg short, 6-7 deg is accurate."""
    pts = _pts([("pid", 2, 6.2, 1.5, 210.0, 170.0), ("other", 2, 7.5, 1.0, 200.0, 160.0)])
    marked = F.mark_frontier(pts, accuracy_deg=1.0).set_index("controller")
    assert marked.loc["pid", "accurate"] and not marked.loc["other", "accurate"]


def test_paper_point_uses_our_pid_and_the_reported_reductions():
    from myoexo.evaluation.paper import PAPER_RESULTS

    pts = _pts([("pid", lv, 0.0, 1.0, 200.0, 100.0) for lv in (0, 1, 2, 3)])
    paper = F.paper_points(pts).set_index("level")
    res = PAPER_RESULTS[0]
    assert paper.loc[0, "peak_interaction_torque_nm"] == pytest.approx(
        200.0 * (1 - res.peak_reduction_pct / 100)
    )
    assert paper.loc[0, "settling_time_s"] == res.sac_settling_time_s
    assert math.isnan(paper.loc[3, "rms_interaction_torque_nm"])  # the paper gives none there


def test_shaped_pid_specs_parse():
    from myoexo.control.specs import parse_controller_spec, pid_config

    specs = F.shaped_pid_specs()
    assert specs[:2] == ["pid", "pid:feedback=exo"]
    configs = [pid_config(parse_controller_spec(s).options) for s in specs]
    assert {c.ramp_s for c in configs} >= set(F.RAMPS_S)
    assert {c.output_limit for c in configs} >= set(F.LIMITS)
    minjerk = {c.ramp_s for c in configs if c.reference == "minjerk"}
    assert minjerk == set(F.MINJERK_RAMPS_S) and max(F.RAMPS_S) >= 3.0


def test_classical_specs_add_the_impedance_grid():
    from myoexo.control.impedance import ImpedanceConfig
    from myoexo.control.specs import parse_controller_spec

    specs = F.classical_specs()
    assert specs[: len(F.shaped_pid_specs())] == F.shaped_pid_specs()
    assert len(set(specs)) == len(specs)
    parsed = [parse_controller_spec(s) for s in specs]
    grid = [ImpedanceConfig(**p.options) for p in parsed if p.kind == "impedance"]
    assert len(grid) == len(F.IMPEDANCE_STIFFNESSES) * len(F.IMPEDANCE_DURATIONS_S)
    assert {(c.stiffness_nm_per_rad, c.duration_s) for c in grid} == {
        (k, t) for k in F.IMPEDANCE_STIFFNESSES for t in F.IMPEDANCE_DURATIONS_S
    }
    for c in grid:  # the paper's damping ratio Kd / Kp = 0.05 / 7
        assert c.damping_nm_s_per_rad / c.stiffness_nm_per_rad == pytest.approx(0.05 / 7, rel=1e-2)


def test_seed_checkpoints_of_several_seeds_folders_get_distinct_labels(tmp_path):
    """Two weight sweeps each have a seed_0: their points must not share a label."""
    import json

    from myoexo.control.specs import parse_controller_spec, seeds_controllers

    labels = []
    for name in ("inter0p1", "inter1p0"):
        ckpt = tmp_path / name / "seed_0" / "checkpoints" / "step_0000000100"
        ckpt.mkdir(parents=True)
        (ckpt / "model.zip").write_bytes(b"")
        (ckpt.parent.parent / "config.json").write_text(
            json.dumps({"preset": {"algorithm": "sbx_sac"}, "seed": 0})
        )
        (tmp_path / name / "aggregate.json").write_text(
            json.dumps({"selected_checkpoints": {"0": str(ckpt)}})
        )
        (spec,) = seeds_controllers(tmp_path / name)
        assert spec.startswith("sbx_sac:")
        parsed = parse_controller_spec(spec)
        labels.append(parsed.label)
        assert parsed.seed_group == name
        assert parse_controller_spec(f"guard:{spec}").seed_group == f"guard:{name}"
    assert labels == ["inter0p1-seed_0-step_0000000100", "inter1p0-seed_0-step_0000000100"]


def test_seeds_of_one_folder_share_a_legend_entry():
    from myoexo.studies.frontier import point_group

    assert point_group("inter0p3-seed_2-step_0000100000", "inter0p3") == "inter0p3 (seeds)"
    assert point_group("sac") == "sac" and point_group("sac", float("nan")) == "sac"
    assert point_group("run-step_0000100000") == "run-step_0000100000"


def test_a_point_on_the_bound_is_not_accurate():
    """Accuracy is strict: a level-0 mean of exactly 1.00 deg does not meet "< 1 deg"."""
    pts = _pts([("pid", 0, 0.0, 1.0, 140.0, 100.0), ("edge", 0, 1.0, 0.5, 90.0, 60.0)])
    marked = F.mark_frontier(pts).set_index("controller")
    assert marked.loc["edge", "accuracy_deg"] == 1.0
    assert not marked.loc["edge", "accurate"] and marked.loc["pid", "on_frontier"]


def test_a_picked_point_is_reachable_only_if_the_evaluation_subjects_confirm_it():
    picked = F.mark_frontier(
        _pts(
            [
                ("pid", 0, 0.0, 0.3, 140.0, 100.0),  # faster, harder: on the frontier too
                ("lucky", 0, 0.9, 0.5, 90.0, 60.0),  # accurate on the selection subjects
            ]
        )
    )
    confirmed = _pts(
        [("pid", 0, 0.0, 1.1, 141.0, 101.0), ("lucky", 0, 1.2, 0.6, 92.0, 61.0)]
    ).assign(settled_share=1.0, episodes=10)
    out = F.confirm(picked, confirmed).set_index("controller")
    assert out.loc["lucky", "on_frontier"] and not out.loc["lucky", "reachable"]
    assert out.loc["lucky", "confirmed_abs_final_error_deg"] == 1.2
    assert out.loc["pid", "reachable"]


def test_the_frontier_picks_on_the_selection_root_and_confirms_on_the_evaluation_root(tmp_path):
    import json

    from myoexo.envs.options import TwinOptions

    twin = TwinOptions(task=(("episode_duration_s", 1.5),))  # the PID settles in ~1 s
    with pytest.raises(ValueError, match="evaluation root"):
        F.build_frontier(tmp_path, 1, levels=(0,), twin=twin, selection_root_seed=0)
    pts = F.build_frontier(
        tmp_path, 2, levels=(0,), twin=twin, progress=False, workers=1, confirm_subjects=1
    )
    picking = json.loads((tmp_path / "selection" / "config.json").read_text())["config"]
    checking = json.loads((tmp_path / "evaluation" / "config.json").read_text())["config"]
    assert (picking["root_seed"], picking["selection"], picking["subjects"]) == (1, True, 2)
    assert (checking["root_seed"], checking["selection"], checking["subjects"]) == (0, False, 1)
    front = set(pts.controller[pts.on_frontier])
    assert front and set(checking["controllers"]) >= {"pid"}
    assert set(checking["controllers"]) - {"pid"} <= front
    assert "reachable" in pts and (tmp_path / "frontier.md").read_text().count("confirmed")


def test_the_committed_frontier_table_is_what_its_file_gives():
    """docs/studies/frontier: `myoexo frontier` writes frontier.md from frontier.csv."""
    from pathlib import Path

    folder = Path(__file__).resolve().parents[1] / "docs" / "studies" / "frontier"
    committed = (folder / "frontier.md").read_text()
    assert committed == F.markdown(pd.read_csv(folder / "frontier.csv")) + "\n"
    pts = pd.read_csv(folder / "frontier.csv")
    assert pts.reachable.dtype == bool and (pts.reachable <= pts.on_frontier).all()
