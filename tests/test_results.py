"""Result sets (myoexo.evaluation.results): an evaluation folder collected into small files
and the tables computed from them; the repository's tool (tools/render_tables.py) that
writes them into the docs, the README and the model cards, and fails its check when a
committed table differs from what its files give."""

from __future__ import annotations

import argparse
import importlib.util
import json
import shutil
import sys
from pathlib import Path

import pandas as pd
import pytest

from myoexo.envs.options import TwinOptions
from myoexo.evaluation import EvaluationConfig, evaluate
from myoexo.evaluation.config import load_config
from myoexo.evaluation.results import collect, command_of, render

REPO = Path(__file__).resolve().parents[1]


def _tool():
    """tools/render_tables.py, the repository's tool (not a module of the package)."""
    spec = importlib.util.spec_from_file_location("render_tables", REPO / "tools/render_tables.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = module
    spec.loader.exec_module(module)
    return module


tool = _tool()
RESULTS_DIR = tool.RESULTS_DIR
README_SET = "eval_1000"
BLOCK = tool.Block("README.md", README_SET, ("sac",))


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory):
    out = tmp_path_factory.mktemp("results") / "eval"
    config = EvaluationConfig(
        controllers=("pid", "sac"),
        levels=(1, 2),
        subjects=3,
        twin=TwinOptions().replace(episode_duration_s=0.5),
    )
    evaluate(config, out, workers=1, progress=False, log=lambda m: None)
    return out


def test_a_result_set_holds_the_tables_inputs_and_its_provenance(evaluation, tmp_path):
    dest = collect(evaluation, tmp_path / README_SET)
    meta = (dest / "meta.json").read_text()
    assert "myoexo evaluate --controllers pid sac --levels 1 2 --subjects 3" in meta
    assert '"root_seed": 0' in meta and '"reference": "pid"' in meta
    red = pd.read_csv(dest / "reductions.csv")
    assert list(red.controller) == ["sac", "sac"] and {"peak_reduction_pct_low"} <= set(red)
    heads = pd.read_csv(dest / "headline.csv", dtype={"levels": str})
    assert list(heads.scope) == ["study", "all"] and heads.levels.iloc[0] == "1, 2"
    assert command_of(load_config(evaluation)).endswith("--episode-duration-s 0.5")


def test_a_set_states_the_peak_reduction_the_references_hold_allows(evaluation, tmp_path):
    """The hold bound: at level 2 the reference's mean torque over the end of its episodes,
    from its traces, against its mean peak; a peak claim above the bound reads "out of
    reach" in the tables, one below it keeps its verdict."""
    import numpy as np

    from myoexo.evaluation.bound import HOLD_WINDOW_S
    from myoexo.evaluation.storage import load_table, load_traces

    dest = collect(evaluation, tmp_path / "set")
    meta = json.loads((dest / "meta.json").read_text())
    (bound,) = meta["hold_bounds"]  # level 2 only
    traces = load_traces(evaluation, "pid", 2)
    t = traces.time_s.astype(float)
    end = t >= t[-1] - HOLD_WINDOW_S - 1e-12  # the last 0.5 s, its first sample included
    hold = float(traces["interaction_torque_nm"][:, end].mean())
    table = load_table(evaluation)
    peak = float(
        table[(table.controller == "pid") & (table.level == 2)].peak_interaction_torque_nm.mean()
    )
    assert bound["level"] == 2 and bound["subjects"] == 3
    assert np.isclose(bound["hold_torque_nm"], hold) and np.isclose(
        bound["reference_peak_nm"], peak
    )
    assert np.isclose(bound["peak_reduction_bound_pct"], 100 * (1 - hold / peak))
    assert "`myoexo.evaluation.bound.hold_bounds`" in render(dest)
    for value, reads in ((1.0, "(>= 8.8: out of reach, at most 1.0)"), (50.0, "(>= 8.8: ")):
        meta["hold_bounds"][0]["peak_reduction_bound_pct"] = value
        (dest / "meta.json").write_text(json.dumps(meta))
        peak_cell = _level_2_cells(render(dest))[6]
        assert reads in peak_cell
        assert ("out of reach" in peak_cell) == (value < 8.8)
    meta.pop("hold_bounds")  # a set collected before the bound: its tables as they were
    (dest / "meta.json").write_text(json.dumps(meta))
    assert "out of reach" not in render(dest) and "hold_bounds" not in render(dest)


def _level_2_cells(markdown: str) -> list[str]:
    (line,) = [line for line in markdown.splitlines() if line.startswith("| 2 |")]
    return [cell.strip() for cell in line.strip("|").split("|")]


def test_where_the_reference_stalls_the_final_error_is_judged_against_it(evaluation, tmp_path):
    """At level 2, where the reference holds the knee short of the study's 1-deg bound, the
    bound reads "out of reach" and the cell judges "no worse than the reference" by the
    paired difference of the absolute final errors (met only below 0)."""
    dest = collect(evaluation, tmp_path / "set")
    red = pd.read_csv(dest / "reductions.csv").set_index("level").loc[2]
    ref_error = red.abs_final_error_deg - red.abs_final_error_diff_deg
    assert ref_error > 1.0  # 0.5-s episodes: the PID is far from the target at level 2
    cell = _level_2_cells(render(dest))[2]
    low, high = red.abs_final_error_diff_deg_low, red.abs_final_error_diff_deg_high
    call = "met" if high < 0 else "missed" if low > 0 else "tie"
    assert f"(< 1: out of reach, `pid` stalls {ref_error:.2f} short; vs `pid` " in cell
    assert cell.endswith(f"[{low:+.2f}, {high:+.2f}]: {call})")
    meta = json.loads((dest / "meta.json").read_text())
    meta.pop("hold_bounds")  # no hold measured: the study's bound as it stands
    (dest / "meta.json").write_text(json.dumps(meta))
    cell = _level_2_cells(render(dest))[2]
    assert "out of reach" not in cell and cell.endswith(("(< 1: missed)", "(< 1: tie)"))


def _evaluation(out: Path, controllers: tuple[str, ...], subjects: int = 3) -> Path:
    config = EvaluationConfig(
        controllers=controllers,
        levels=(1, 2),
        subjects=subjects,
        twin=TwinOptions().replace(episode_duration_s=0.5),
    )
    evaluate(config, out, workers=1, progress=False, log=lambda m: None)
    return out


def test_a_set_takes_controllers_run_later_on_its_own_subjects_only(evaluation, tmp_path):
    """collect --update: the new controller's rows join the set, the others stay, the
    provenance lists both commands; a run on other subjects is refused."""
    dest = collect(evaluation, tmp_path / "set")
    before = pd.read_csv(dest / "summary.csv")
    later = _evaluation(tmp_path / "later", ("pid", "pid:ramp_s=0.2"))
    collect(later, dest, update=True)
    summary = pd.read_csv(dest / "summary.csv")
    assert list(dict.fromkeys(summary.controller)) == ["pid", "sac", "pid:ramp_s=0.2"]
    kept = summary[summary.controller != "pid:ramp_s=0.2"].reset_index(drop=True)
    pd.testing.assert_frame_equal(kept, before)
    red = pd.read_csv(dest / "reductions.csv")
    assert list(red.controller) == ["sac", "sac", "pid:ramp_s=0.2", "pid:ramp_s=0.2"]
    meta = json.loads((dest / "meta.json").read_text())
    assert len(meta["commands"]) == 2 and meta["commands"][1].endswith(
        "pid:ramp_s=0.2 --levels 1 2 --subjects 3 --episode-duration-s 0.5"
    )
    assert meta["episodes"] == 18
    assert "Commands: `myoexo evaluate --controllers pid sac" in render(dest)
    collect(later, dest, update=True)  # again: replaced, not repeated
    assert len(pd.read_csv(dest / "summary.csv")) == len(summary)
    assert json.loads((dest / "meta.json").read_text())["commands"] == meta["commands"]
    collect(evaluation, dest, update=True)  # sac again: replaced in its place
    assert list(dict.fromkeys(pd.read_csv(dest / "summary.csv").controller)) == [
        "pid",
        "sac",
        "pid:ramp_s=0.2",
    ]
    with pytest.raises(ValueError, match="subjects_per_level"):
        collect(_evaluation(tmp_path / "fewer", ("pid", "sac"), subjects=2), dest, update=True)
    other = tmp_path / "other"
    shutil.copytree(dest, other)
    frame = pd.read_csv(other / "summary.csv")
    frame.loc[frame.controller == "pid", "final_error_deg_mean"] += 0.1
    frame.to_csv(other / "summary.csv", index=False)
    with pytest.raises(
        ValueError, match=r"at levels \[1, 2\]: it did not run on the set.s subjects"
    ):
        collect(later, other, update=True)


def test_a_reference_rerun_that_differs_at_named_levels_is_paired_and_said(evaluation, tmp_path):
    """collect --update --rerun-levels: where the set's reference rows differ from the
    evaluation's (a reference that never settles, re-run by later code), the added
    controller is paired with its own run there, the set keeps its rows and says so; the
    other levels must still repeat, and the named ones count the same subjects."""
    dest = collect(evaluation, tmp_path / "set")
    frame = pd.read_csv(dest / "summary.csv")
    frame.loc[(frame.controller == "pid") & (frame.level == 1), "final_error_deg_mean"] += 0.003
    frame.to_csv(dest / "summary.csv", index=False)
    set_pid = frame[frame.controller == "pid"].reset_index(drop=True)
    later = _evaluation(tmp_path / "later", ("pid", "pid:ramp_s=0.2"))
    with pytest.raises(ValueError, match=r"levels \[1\]"):
        collect(later, dest, update=True)
    with pytest.raises(ValueError, match=r"levels \[1\]"):
        collect(later, dest, update=True, rerun_levels=(2,))
    with pytest.raises(ValueError, match="update"):
        collect(later, tmp_path / "new", rerun_levels=(1,))
    collect(later, dest, update=True, rerun_levels=(1,))
    summary = pd.read_csv(dest / "summary.csv")
    pd.testing.assert_frame_equal(
        summary[summary.controller == "pid"].reset_index(drop=True), set_pid
    )
    red = pd.read_csv(dest / "reductions.csv")
    assert list(red.controller) == ["sac", "sac", "pid:ramp_s=0.2", "pid:ramp_s=0.2"]
    (rerun,) = json.loads((dest / "meta.json").read_text())["reference_reruns"]
    assert rerun["levels"] == [1] and rerun["controllers"] == ["pid:ramp_s=0.2"]
    (mean,) = rerun["final_error_deg_mean"]
    assert mean["set"] == pytest.approx(mean["run"] + 0.003)
    assert "are paired with their own run of `pid`" in render(dest)
    fewer = _evaluation(tmp_path / "fewer", ("pid", "pid:ramp_s=0.2"), subjects=2)
    with pytest.raises(ValueError, match="subjects_per_level"):
        collect(fewer, dest, update=True, rerun_levels=(1,))


def test_a_set_older_than_a_metric_still_takes_runs_on_its_subjects(evaluation, tmp_path):
    """A set collected before a metric existed (its summary lacks the metric's columns)
    takes a later evaluation on its subjects: the reference is compared on the columns both
    have; a changed number in a shared column is still refused."""
    dest = collect(evaluation, tmp_path / "set")
    frame = pd.read_csv(dest / "summary.csv")
    swing = [c for c in frame.columns if c.startswith("final_swing_deg")]
    assert swing  # the metric the set is made to lack
    frame.drop(columns=swing).to_csv(dest / "summary.csv", index=False)
    later = _evaluation(tmp_path / "later", ("pid", "pid:ramp_s=0.2"))
    collect(later, dest, update=True)
    red = pd.read_csv(dest / "reductions.csv")
    assert "pid:ramp_s=0.2" in set(red.controller)
    frame = pd.read_csv(dest / "summary.csv")
    frame.loc[frame.controller == "pid", "settling_time_s_mean"] += 0.01
    frame.drop(columns=swing).to_csv(dest / "summary.csv", index=False)
    with pytest.raises(ValueError, match=r"other summary\.csv rows"):
        collect(later, dest, update=True)


def test_an_evaluation_of_the_reference_alone_is_refused_with_a_reason(tmp_path):
    """A result set compares controllers with the reference: a run of the PID alone gets one
    message saying so, not pandas' error about an empty concatenation."""
    alone = _evaluation(tmp_path / "alone", ("pid",))
    with pytest.raises(ValueError, match="holds only the reference 'pid'"):
        collect(alone, tmp_path / "set")


def test_a_metric_empty_in_the_sets_reference_rows_is_not_compared(evaluation, tmp_path):
    """A set whose reference rows predate a metric that later controllers brought in (the
    column is there, NaN in every reference row) takes a run on its subjects; a changed
    number in a column the reference rows have is still refused."""
    dest = collect(evaluation, tmp_path / "set")
    frame = pd.read_csv(dest / "summary.csv")
    swing = [c for c in frame.columns if c.startswith("final_swing_deg")]
    frame.loc[frame.controller == "pid", swing] = float("nan")
    frame.to_csv(dest / "summary.csv", index=False)
    later = _evaluation(tmp_path / "later", ("pid", "pid:ramp_s=0.2"))
    collect(later, dest, update=True)
    assert "pid:ramp_s=0.2" in set(pd.read_csv(dest / "reductions.csv").controller)
    frame = pd.read_csv(dest / "summary.csv")
    frame.loc[frame.controller == "pid", swing] = float("nan")
    frame.loc[frame.controller == "pid", "settling_time_s_mean"] += 0.01
    frame.to_csv(dest / "summary.csv", index=False)
    with pytest.raises(ValueError, match=r"other summary\.csv rows"):
        collect(later, dest, update=True)


def test_a_run_that_lacks_a_column_of_the_set_is_refused_by_name(evaluation, tmp_path):
    """A set with a column a later evaluation does not have (a metric this code no longer
    computes) does not take that evaluation: the reference's rows could not be compared on
    it, and the error names the column."""
    dest = collect(evaluation, tmp_path / "set")
    frame = pd.read_csv(dest / "summary.csv")
    frame["retired_metric"] = 1.0
    frame.to_csv(dest / "summary.csv", index=False)
    later = _evaluation(tmp_path / "later", ("pid", "pid:ramp_s=0.2"))
    with pytest.raises(ValueError, match=r"lack the set's columns \['retired_metric'\]"):
        collect(later, dest, update=True)


def test_a_sets_hold_bounds_come_again_from_its_references_traces(evaluation, tmp_path):
    """results bound: a set's hold bounds recomputed from a run of its reference on its own
    subjects (the other files untouched, the command recorded); a run on other subjects, or
    one whose reference rows differ, is refused."""
    from myoexo.evaluation.results import bound

    dest = collect(evaluation, tmp_path / "set")
    meta = json.loads((dest / "meta.json").read_text())
    assert meta["hold_bounds_command"] == meta["commands"][0]  # the run the bounds came from
    before = {f: (dest / f).read_text() for f in ("summary.csv", "reductions.csv")}
    later = _evaluation(tmp_path / "pid_again", ("pid",))
    stripped = {**meta, "hold_bounds": []}
    (dest / "meta.json").write_text(json.dumps(stripped))
    bound(later, dest)
    again = json.loads((dest / "meta.json").read_text())
    assert again["hold_bounds"] == meta["hold_bounds"]
    assert again["hold_bounds_command"].startswith("myoexo evaluate --controllers pid --levels")
    assert again["commands"] == meta["commands"]
    assert {f: (dest / f).read_text() for f in before} == before
    assert "`myoexo results bound`" in render(dest)
    collect(evaluation, dest, update=True)  # traces whose bounds repeat the set's: run kept
    kept = json.loads((dest / "meta.json").read_text())
    assert kept["hold_bounds_command"] == again["hold_bounds_command"]
    moved = {**again, "hold_bounds": [{**b, "hold_torque_nm": 0.5} for b in meta["hold_bounds"]]}
    (dest / "meta.json").write_text(json.dumps(moved))
    collect(evaluation, dest, update=True)  # bounds that differ: the new run's, named
    renewed = json.loads((dest / "meta.json").read_text())
    assert renewed["hold_bounds"] == meta["hold_bounds"]
    assert renewed["hold_bounds_command"] == meta["commands"][0]
    bound(later, dest)
    with pytest.raises(ValueError, match="subjects_per_level"):
        bound(_evaluation(tmp_path / "fewer", ("pid",), subjects=2), dest)
    traceless = tmp_path / "traceless"
    shutil.copytree(later, traceless)
    shutil.rmtree(traceless / "traces")
    with pytest.raises(ValueError, match=r"no hold bound at levels \[2\]"):
        bound(traceless, dest)  # the set keeps the bounds it has
    assert json.loads((dest / "meta.json").read_text())["hold_bounds"] == meta["hold_bounds"]
    # an update without traces keeps the set's bounds and the run they came from
    untraced = tmp_path / "untraced"
    shutil.copytree(evaluation, untraced)
    shutil.rmtree(untraced / "traces")
    collect(untraced, dest, update=True)
    kept = json.loads((dest / "meta.json").read_text())
    assert kept["hold_bounds"] == meta["hold_bounds"]
    assert kept["hold_bounds_command"] == again["hold_bounds_command"]
    frame = pd.read_csv(dest / "summary.csv")
    frame.loc[(frame.controller == "pid") & (frame.level == 2), "final_error_deg_mean"] += 0.1
    frame.to_csv(dest / "summary.csv", index=False)
    with pytest.raises(ValueError, match="did not run on the set's subjects"):
        bound(later, dest)


def test_tables_are_rendered_and_a_stale_one_is_caught(evaluation, tmp_path):
    root = tmp_path / "repo"
    collect(evaluation, root / RESULTS_DIR / README_SET)
    (root / "README.md").write_text(f"intro\n{BLOCK.start}\nold\n{BLOCK.end}\nrest\n")
    blocks = (BLOCK,)
    write_tables = tool.write_tables
    assert write_tables(root, check=True, blocks=blocks) == [
        f"{RESULTS_DIR}/{README_SET}/tables.md",
        "README.md",
    ]
    assert write_tables(root, blocks=blocks) and write_tables(root, True, blocks) == []
    readme = (root / "README.md").read_text()
    assert readme.startswith("intro\n") and readme.endswith("rest\n") and "old" not in readme
    assert "| 2 |" in readme and "(the study's aggregation)" in readme
    tables = root / RESULTS_DIR / README_SET / "tables.md"
    tables.write_text(tables.read_text().replace("| 1 |", "| 1 (edited) |", 1))
    assert write_tables(root, True, blocks) == [f"{RESULTS_DIR}/{README_SET}/tables.md"]
    absent = tool.Block("NOTES.md", README_SET, ("student_exo",))
    (root / "NOTES.md").write_text(f"{absent.start}\n{absent.end}\n")
    with pytest.raises(ValueError, match=r"NOTES\.md: .* has no \['student_exo'\]"):
        write_tables(root, True, (absent,))
    (root / "README.md").write_text("no markers\n")
    with pytest.raises(ValueError, match="lacks the markers"):
        write_tables(root, True, blocks)
    shutil.rmtree(root / RESULTS_DIR / README_SET)
    (root / RESULTS_DIR / "broken").mkdir()
    with pytest.raises(ValueError, match="is no result set"):
        write_tables(root, True, ())


def test_myoexo_results_collects_into_the_folder_named_and_prints_the_tables(
    evaluation, tmp_path, capsys
):
    """``myoexo results``: collect writes the set into the folder the user names and nowhere
    else; ``tables`` prints what the repository's tool writes into ``tables.md`` and between
    a block's markers."""
    from myoexo.evaluation import results

    parser = argparse.ArgumentParser()
    results.add_arguments(parser)
    work = tmp_path / "work"
    work.mkdir()
    dest = work / "my_set"
    assert results.run(parser.parse_args(["collect", str(evaluation), str(dest)])) == 0
    assert [p.name for p in work.iterdir()] == ["my_set"]
    capsys.readouterr()
    assert results.run(parser.parse_args(["tables", str(dest)])) == 0
    assert capsys.readouterr().out == render(dest)
    assert results.run(parser.parse_args(["tables", str(dest), "--controllers", "sac"])) == 0
    printed = capsys.readouterr().out
    root = tmp_path / "repo"
    shutil.copytree(dest, root / RESULTS_DIR / README_SET)
    (root / "README.md").write_text(f"{BLOCK.start}\n{BLOCK.end}\n")
    tool.write_tables(root, blocks=(BLOCK,))
    block = BLOCK.render(root).removeprefix(f"{BLOCK.start}\n").removesuffix(f"\n{BLOCK.end}")
    label = f"{RESULTS_DIR.as_posix()}/{README_SET}"
    assert printed == block.replace(label, dest.as_posix()) + "\n"


def test_the_committed_calibrations_are_the_constants_the_twin_uses():
    """docs/studies/calibration_*: the output of `myoexo twin calibrate` on the calibration root,
    whose fitted values and provenance are the package's constants."""
    from myoexo.spasticity import CALIBRATION, PERSISTENT
    from myoexo.spasticity.spindle import SPINDLE_CALIBRATION

    studies = REPO / "docs" / "studies"
    for folder, calibration in (
        ("calibration_stretch", CALIBRATION),
        ("calibration_spindle", SPINDLE_CALIBRATION),
    ):
        record = (studies / folder / "calibration.md").read_text()
        assert calibration.note in record and "**The fit** (in-sample" in record
        for level, c in calibration.levels.items():
            line = (
                f"{level}: LevelCalibration(flexor_gain={c.flexor_gain:g}, "
                f"extensor_gain={c.extensor_gain:g}, "
                f"flexor_threshold_shift_deg={c.flexor_threshold_shift_deg:.2f})"
            )
            assert line in record, (folder, line)
    persistent = (studies / "calibration_persistent" / "calibration.md").read_text()
    gains = ", ".join(f"{lv}: {g:.4f}" for lv, g in sorted(PERSISTENT.gains.items()))
    assert PERSISTENT.note in persistent and f"gains=MappingProxyType({{{gains}}})" in persistent


def test_the_command_names_a_seeds_folder_once():
    specs = [
        "pid",
        "sbx_sac:runs/s5/seed_0/checkpoints/step_0000000100/model.zip",
        "sbx_sac:runs/s5/seed_1/checkpoints/step_0000000200/model.zip",
        "guard:sbx_sac:runs/s5/seed_1/checkpoints/step_0000000200/model.zip",
    ]
    config = {"config": {"controllers": specs, "levels": [0], "subjects": 5}}
    assert command_of(config) == (
        "myoexo evaluate --controllers pid guard:sbx_sac:runs/s5/seed_1/checkpoints/"
        "step_0000000200/model.zip --seeds-dir runs/s5 --levels 0 --subjects 5"
    )


def test_an_episode_table_without_seed_groups_gets_them_from_its_labels(tmp_path):
    """An evaluation folder written before the ``seed_group`` column: the groups come from
    the members' labels, once, at load."""
    from myoexo.evaluation.storage import load_table

    labels = [
        "pid",
        "s5-seed_0-step_0000000100",
        "guard:s5-seed_1-step_2",
        "st_3seeds-seed_2-round_04",
    ]
    pd.DataFrame({"controller": labels, "level": 0}).to_parquet(tmp_path / "episodes.parquet")
    table = load_table(tmp_path)
    assert list(table.columns) == ["controller", "seed_group", "level"]
    assert table.seed_group.isna().tolist() == [True, False, False, False]
    assert list(table.seed_group[1:]) == ["s5", "guard:s5", "st_3seeds"]


def test_the_goals_table_judges_by_the_intervals_and_the_tails(tmp_path):
    """The deployable controller's goals table: verdicts follow the files (an interval moved
    under the goal turns a miss into met, a catastrophic subject turns met into missed)."""
    from myoexo.evaluation.results import goals_table

    nominal, perturbed = tmp_path / "nom", tmp_path / "per"
    shutil.copytree(REPO / RESULTS_DIR / "eval_500", nominal)
    shutil.copytree(REPO / RESULTS_DIR / "eval_200_perturbed", perturbed)

    def row(text: str, goal: str) -> str:
        return next(line for line in text.splitlines() if line.startswith(f"| {goal}"))

    args = ("student_exo", "guard:sac", "pid:tuned=exo")
    red = pd.read_csv(nominal / "reductions.csv")
    at = (red.controller == "student_exo") & (red.level == 3)
    red.loc[at, ["abs_final_error_diff_deg", "abs_final_error_diff_deg_low"]] = [1.0, 0.9]
    red.loc[at, "abs_final_error_diff_deg_high"] = 1.6  # straddles 1.5: a tie
    red.to_csv(nominal / "reductions.csv", index=False)
    assert "**tie**" in row(goals_table(nominal, perturbed, *args), "level 3").split("|")[2]
    red.loc[at, "abs_final_error_diff_deg_high"] = 1.4
    red.to_csv(nominal / "reductions.csv", index=False)
    text = goals_table(nominal, perturbed, *args)
    assert "+1.00 [+0.90, +1.40] deg vs `pid`: **met**" in row(text, "level 3")
    risk = pd.read_csv(nominal / "tail_risk.csv")
    assert "**met**" in row(text, "no catastrophic").split("|")[2]
    risk.loc[(risk.controller == "student_exo") & (risk.level == 0), "catastrophic"] = 2
    risk.to_csv(nominal / "tail_risk.csv", index=False)
    text = goals_table(nominal, perturbed, *args)
    assert "2 / 0 / 0 / 0" in row(text, "no catastrophic") and "**missed**" in text
    with pytest.raises(ValueError, match="has no"):
        goals_table(nominal, perturbed, "student_exo", "nobody", "pid:tuned=exo")
    # smoothness: judged by the intervals of the means (missed, tie, met)
    summary = pd.read_csv(nominal / "summary.csv")
    tv = ["command_total_variation_mean", "command_total_variation_std"]
    for controller, values in (("student_exo", (5.0, 1.0)), ("guard:sac", (5.05, 1.0))):
        summary.loc[summary.controller == controller, tv] = values
    summary.to_csv(nominal / "summary.csv", index=False)
    smooth = row(goals_table(nominal, perturbed, *args), "command total").split("|")[2]
    assert "5.0 [4.9, 5.1] / " in smooth and "**tie at levels 0, 1, 2, 3**" in smooth
    summary.loc[summary.controller == "student_exo", tv] = (6.0, 1.0)
    summary.to_csv(nominal / "summary.csv", index=False)
    smooth = row(goals_table(nominal, perturbed, *args), "command total").split("|")[2]
    assert "**missed at levels 0, 1, 2, 3**" in smooth
    # the device baseline: beaten where the intervals part, a tie where they overlap
    cols = ["abs_final_error_deg", "abs_final_error_deg_low", "abs_final_error_deg_high"]
    for level, (ours, theirs) in enumerate(
        [((1.0, 0.9, 1.1), (2.0, 1.9, 2.1)), ((1.0, 0.9, 1.1), (1.05, 1.0, 1.2))]
        + [((1.0, 0.9, 1.1), (0.5, 0.4, 0.6))] * 2
    ):
        red.loc[(red.controller == "student_exo") & (red.level == level), cols] = ours
        red.loc[(red.controller == "pid:tuned=exo") & (red.level == level), cols] = theirs
    red.to_csv(nominal / "reductions.csv", index=False)
    device = row(goals_table(nominal, perturbed, *args), "beats the device PID")
    assert "1.00 [0.90, 1.10] vs 2.00 [1.90, 2.10]" in device
    assert "**missed at levels 2, 3, tie at level 1**" in device


def test_a_set_of_an_earlier_twin_says_so(tmp_path):
    """A result set records the twin version it was measured on; one that records none, or
    another than today's, is labelled in its generated tables; today's is not."""
    import json
    import shutil
    from pathlib import Path

    from myoexo.evaluation.results import earlier_twin_note, render
    from myoexo.model import TWIN_VERSION

    src = Path(__file__).resolve().parents[1] / "docs" / "results" / "eval_seeds_100"
    folder = tmp_path / "set"
    shutil.copytree(src, folder)
    meta = json.loads((folder / "meta.json").read_text())
    assert "twin_version" not in meta  # measured before the twin had versions
    assert "Measured on an earlier twin" in render(folder)
    meta["twin_version"] = TWIN_VERSION
    (folder / "meta.json").write_text(json.dumps(meta))
    assert "Measured on an earlier twin" not in render(folder)
    assert earlier_twin_note({"twin_version": TWIN_VERSION}) is None
    assert f"version {TWIN_VERSION - 1}" in earlier_twin_note({"twin_version": TWIN_VERSION - 1})
    # a set measured with another reflex than today's default says so too
    from myoexo.spasticity.reflex import DEFAULT_REFLEX

    today = {"twin_version": TWIN_VERSION, "twin": {"reflex": DEFAULT_REFLEX}}
    assert earlier_twin_note(today) is None
    other = {"twin_version": TWIN_VERSION, "twin": {"reflex": "stretch"}}
    note = earlier_twin_note(other)
    assert note is not None and "Measured with the `stretch` reflex" in note


def test_todays_full_sets_state_what_the_motor_allows_at_levels_2_and_3():
    """Every committed set of today's default twin that ran levels 2-3 carries the hold bound
    of both levels, and its level-3 bound uses the package's measured hold slope."""
    from myoexo.evaluation.bound import hold_slope_nm_per_deg
    from myoexo.evaluation.paper import PAPER_RESULTS
    from myoexo.evaluation.results import earlier_twin_note

    root = REPO / RESULTS_DIR
    todays = []
    for meta_file in sorted(root.glob("*/meta.json")):
        meta = json.loads(meta_file.read_text())
        levels = set(pd.read_csv(meta_file.parent / "summary.csv").level)
        if earlier_twin_note(meta) is None and {2, 3} <= levels:
            todays.append(meta_file.parent.name)
            bounds = {int(b["level"]): b for b in meta["hold_bounds"]}
            assert set(bounds) == {2, 3}, meta_file
            assert bounds[2]["slack_deg"] == 0.0
            assert bounds[3]["hold_slope_nm_per_deg"] == hold_slope_nm_per_deg(3)
            # the tables read the study's level-3 claim "out of reach"
            assert bounds[3]["peak_reduction_bound_pct"] < PAPER_RESULTS[3].peak_reduction_pct
    assert {"eval_1000_tone", "eval_1000_tone_perturbed"} <= set(todays)
