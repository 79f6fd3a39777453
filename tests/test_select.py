"""Checkpoint selection against the acceptance criteria: the criterion logic on crafted
tables, the candidate choice on a run folder written the way training writes it (with
policies whose actions are known), ``myoexo policy select`` and its ``--table`` mode, and a tiny
real training run."""

from __future__ import annotations

import csv
import math
import re
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest

from myoexo.cli import main
from myoexo.envs.options import TwinOptions
from myoexo.evaluation.criteria import Criteria, compare_with_pid, level_means, shortfall
from myoexo.runtime.fields import FieldError
from myoexo.training import checkpoints as ck
from myoexo.training.select import (
    SelectionConfig,
    catastrophic_per_level,
    checkpoint_episodes,
    compare_evaluation,
    evaluate_checkpoint,
    evaluate_pid,
    markdown_table,
    paper_checks,
    pid_episodes,
    select_checkpoint,
    selection_key,
)

METRICS = (
    "abs_final_error_deg",
    "final_error_deg",
    "settling_time_s",
    "rms_interaction_torque_nm",
    "peak_interaction_torque_nm",
)


# ---------------------------------------------------------------------------- crafted tables
def _means(rows: dict[int, tuple[float, float, float]]) -> pd.DataFrame:
    """Per-level means from ``level -> (abs final error, RMS, peak)`` (signed error = abs,
    settling 1 s), through :func:`level_means` of a two-subject episode table whose two
    subjects lie symmetrically around those values."""
    episodes = []
    for level, (err, rms, peak) in rows.items():
        for sign in (-1.0, 1.0):
            episodes.append(
                {
                    "level": level,
                    "subject": int(sign > 0),
                    "abs_final_error_deg": err + 0.25 * sign,
                    "final_error_deg": err + 0.25 * sign,
                    "settling_time_s": 1.0 + 0.5 * sign,
                    "rms_interaction_torque_nm": rms + sign,
                    "peak_interaction_torque_nm": peak - 2 * sign,
                    "controller": "x",
                }
            )
    return level_means(pd.DataFrame(episodes))


PID = _means({lv: (0.5, 50.0, 100.0) for lv in range(4)})


def test_level_means_average_each_metric_per_level():
    assert list(PID.columns) == list(METRICS)
    assert PID.index.tolist() == [0, 1, 2, 3]
    expected = [0.5, 0.5, 1.0, 50.0, 100.0]
    for level in range(4):
        assert PID.loc[level].tolist() == pytest.approx(expected, abs=1e-12)


def test_the_acceptance_bounds_are_the_papers():
    c = Criteria()
    assert dict(c.final_error_deg) == {0: 1.0, 1: 1.0, 2: 1.0, 3: 11.45}
    assert c.rms_levels == (0, 1, 2, 3)  # the study claims a lower RMS at all four levels
    assert c.peak_levels == (0, 1, 2, 3)


def test_compare_reductions_and_per_level_flags():
    bound = Criteria().final_error_deg
    sac = _means(
        {
            0: (0.5 * bound[0], 40.0, 80.0),  # everything better: passes
            1: (bound[1] + 0.5, 40.0, 80.0),  # final error above the 1 deg bound
            2: (0.5 * bound[2], 60.0, 120.0),  # more torque than the PID
            3: (bound[3] - 0.45, 60.0, 90.0),  # level 3: 11 deg is fine, the RMS is not
        }
    )
    table = compare_with_pid(sac, PID)
    assert table.index.tolist() == [0, 1, 2, 3]
    # reductions in % of the PID, positive = less torque than the PID
    assert table.peak_reduction_pct.tolist() == pytest.approx([20.0, 20.0, -20.0, 10.0])
    assert table.rms_reduction_pct.tolist() == pytest.approx([20.0, 20.0, -20.0, -20.0])
    assert table.sac_abs_final_error_deg.tolist() == pytest.approx(
        [0.5 * bound[0], bound[1] + 0.5, 0.5 * bound[2], bound[3] - 0.45]
    )
    assert table.pid_peak_nm.tolist() == pytest.approx([100.0] * 4)
    assert table.final_error_ok.tolist() == [True, False, True, True]
    assert table.peak_ok.tolist() == [True, True, False, True]
    assert table.rms_ok.tolist() == [True, True, False, False]
    assert table["pass"].tolist() == [True, False, False, False]
    # shortfall: relative excess of the final error + relative torque increases
    assert shortfall(table) == pytest.approx(0.5 / bound[1] + 0.2 + 0.2 + 0.2)
    assert shortfall(table.loc[[0]]) == 0.0
    assert shortfall(table.loc[[3]]) == pytest.approx(0.2)


def test_final_error_bounds_are_per_level_and_strict():
    bound = Criteria().final_error_deg
    # 5 deg passes at level 3 only; exactly on a bound fails; above 11.45 fails at level 3
    sac = _means({0: (5.0, 40.0, 80.0), 1: (bound[1], 40.0, 80.0), 3: (5.0, 40.0, 80.0)})
    table = compare_with_pid(sac, PID.loc[[0, 1, 3]])
    assert table.final_error_ok.tolist() == [False, False, True]
    table = compare_with_pid(_means({3: (bound[3] + 0.5, 40.0, 80.0)}), PID.loc[[3]])
    assert not table.loc[3, "final_error_ok"] and not table.loc[3, "pass"]
    assert shortfall(table) == pytest.approx(0.5 / bound[3])


def test_other_criteria_change_the_flags():
    sac = _means({0: (1.5, 60.0, 120.0), 3: (1.5, 60.0, 120.0)})
    pid = PID.loc[[0, 3]]
    assert not compare_with_pid(sac, pid)["pass"].any()
    lenient = Criteria(
        final_error_deg=dict.fromkeys(range(4), 2.0), rms_levels=(), peak_levels=(3,)
    )
    table = compare_with_pid(sac, pid, lenient)
    assert table["pass"].tolist() == [True, False]
    assert shortfall(table, lenient) == pytest.approx(0.2)


def test_markdown_table_names_the_failed_criteria():
    sac = _means({0: (0.5, 40.0, 80.0), 2: (3.0, 60.0, 120.0)})
    text = markdown_table(compare_with_pid(sac, PID.loc[[0, 2]]))
    lines = text.splitlines()
    assert len(lines) == 2 + 2
    cells = [[c.strip() for c in line.strip("|").split("|")] for line in lines]
    assert cells[0][0] == "level" and cells[0][-1] == "criteria"
    assert cells[2][0] == "0" and cells[2][-1] == "pass"
    assert cells[3][0] == "2" and cells[3][-1] == "fails: final error, peak, RMS"


def test_paper_checks_read_subjects_and_the_papers_reductions():
    """Level 0: mean error 0.9 passes, but two subjects at 9 deg fail the 95th percentile;
    level 1: a 20 % peak reduction beats the paper's 12.5 %, and a 5 % RMS reduction is
    below its 9.7 %; a settling time of 0.2 s is within the paper's 0.78 s only with every
    subject settled."""
    rows = []
    for level, errors, settle, rms, peak in (
        (0, [0.0] * 18 + [9.0, 9.0], 0.2, 30.0, 70.0),
        (1, [0.5] * 20, 0.2, 47.5, 80.0),
    ):
        for i, e in enumerate(errors):
            rows.append(
                {
                    "controller": "sac",
                    "level": level,
                    "subject": i,
                    "abs_final_error_deg": e,
                    "final_error_deg": e,
                    "settling_time_s": settle if (level == 0 or i) else float("nan"),
                    "rms_interaction_torque_nm": rms,
                    "peak_interaction_torque_nm": peak,
                }
            )
    episodes = pd.DataFrame(rows)
    table = paper_checks(compare_with_pid(level_means(episodes), PID.loc[[0, 1]]), episodes)
    assert table.loc[0, "final_error_ok"] and not table.loc[0, "p95_ok"]
    assert table.loc[0, "sac_p95_abs_final_error_deg"] == pytest.approx(
        np.quantile([0.0] * 18 + [9.0, 9.0], 0.95)
    )
    assert table.loc[0, "paper_peak_ok"] and table.loc[0, "paper_rms_ok"]
    assert table.loc[1, "paper_peak_ok"] and not table.loc[1, "paper_rms_ok"]
    assert table.loc[0, "settling_ok"] and not table.loc[1, "settling_ok"]
    assert table.loc[1, "settled_pct"] == pytest.approx(95.0)
    assert not table.all_ok.any()
    assert "p95 error" in markdown_table(table)


# ---------------------------------------------------------------------------- a crafted run
#: checkpoint step -> (constant action of its policy, small-evaluation score in eval.csv)
CRAFTED = {100: (-0.5, -10.0), 200: (0.0, -50.0), 300: (0.0, -60.0)}


@pytest.fixture(scope="module")
def crafted_run(tmp_path_factory):
    """A run folder written with the training code (vector env, SB3 SAC, checkpoints), the
    policies set to constant actions: step 100 extends the knee with a -0.5 command, steps
    200 and 300 do nothing. eval.csv ranks step 100 best."""
    import torch

    from myoexo.training import get_preset
    from myoexo.training.train import build_model, make_vec_env

    run_dir = tmp_path_factory.mktemp("select") / "run"
    run_dir.mkdir()
    preset = get_preset(
        "cpu",
        n_envs=1,
        algorithm_kwargs={"buffer_size": 1_000, "batch_size": 16, "learning_starts": 10},
    )
    venv = make_vec_env(preset)
    model = build_model(preset, venv)
    ck.write_json_atomic(run_dir / ck.CONFIG_FILE, {"seed": 0, "env_id": preset.env_id})
    mu = model.policy.actor.mu
    for step, (action, _) in CRAFTED.items():
        with torch.no_grad():
            mu.weight.zero_()
            mu.bias.fill_(float(np.arctanh(action)))  # deterministic action = tanh(mu)
        model.num_timesteps = step
        ck.save_checkpoint(model, run_dir, {"num_timesteps": step}, with_replay=False)
    venv.close()
    with open(run_dir / ck.EVAL_FILE, "w", newline="") as f:
        writer = csv.writer(f)
        writer.writerow(["step", "level", "score"])
        for step, (_, score) in CRAFTED.items():
            writer.writerows([[step, 0, score], [step, 3, score]])
    return run_dir


def _printed_candidates(text: str) -> list[str]:
    return re.findall(r"^(step_\d+): catastrophic", text, flags=re.MULTILINE)


def test_selection_takes_the_newest_and_the_best_scored_and_picks_the_smallest_shortfall(
    crafted_run, capsys
):
    chosen, table = select_checkpoint(crafted_run, subjects=1, last=1, top=1, levels=(0,))
    candidates = _printed_candidates(capsys.readouterr().out)
    assert candidates == ["step_0000000300", "step_0000000100"]  # newest, then best score
    assert chosen == crafted_run / ck.CHECKPOINTS_DIR / "step_0000000100"
    assert table.index.tolist() == [0]
    assert {"final_error_ok", "peak_ok", "rms_ok", "pass", "peak_reduction_pct"} <= set(table)
    assert table.catastrophic.tolist() == [0]
    # the table is the comparison of the chosen checkpoint with the PID on the same subject
    pid = evaluate_pid(1, (0,))
    expected = compare_with_pid(evaluate_checkpoint(chosen, 1, (0,)), pid)
    pd.testing.assert_frame_equal(table.drop(columns="catastrophic"), expected)
    idle = compare_with_pid(
        evaluate_checkpoint(crafted_run / ck.CHECKPOINTS_DIR / "step_0000000300", 1, (0,)), pid
    )
    assert shortfall(table) < shortfall(idle)
    # a knee left hanging is far from the target: the final-error criterion fails
    assert idle.loc[0, "sac_abs_final_error_deg"] > 30.0
    assert not idle.loc[0, "final_error_ok"] and not idle.loc[0, "pass"]
    # ... and beyond the catastrophic bound (20 deg, or the PID's worst subject)
    hanging = checkpoint_episodes(crafted_run / ck.CHECKPOINTS_DIR / "step_0000000300", 1, (0,))
    assert catastrophic_per_level(hanging, pid_episodes(1, (0,))).tolist() == [1]


def test_a_catastrophic_subject_outranks_any_shortfall():
    """The selection prefers a checkpoint with fewer catastrophic subjects, whatever its
    shortfall; among equals, the smaller shortfall, then the larger peak reduction."""
    pid = _means({0: (0.0, 50.0, 100.0), 3: (9.0, 50.0, 100.0)})
    gentle = compare_with_pid(_means({0: (0.0, 40.0, 80.0), 3: (9.0, 40.0, 80.0)}), pid)
    rough = compare_with_pid(_means({0: (0.5, 60.0, 120.0), 3: (9.0, 60.0, 120.0)}), pid)
    assert shortfall(gentle) < shortfall(rough)
    keys = {
        "gentle, one catastrophe": selection_key(gentle.assign(catastrophic=[0, 1])),
        "rough, none": selection_key(rough.assign(catastrophic=[0, 0])),
        "gentle, none": selection_key(gentle.assign(catastrophic=[0, 0])),
        "gentle, one perturbed catastrophe": selection_key(
            gentle.assign(catastrophic=[0, 0], catastrophic_perturbed=[0, 1])
        ),
    }
    assert sorted(keys, key=keys.__getitem__)[:2] == ["gentle, none", "rough, none"]
    # a catastrophic subject on a perturbed twin counts as one on the nominal twin
    assert keys["gentle, one perturbed catastrophe"] == keys["gentle, one catastrophe"]


def test_perturbed_selection_subjects_count_their_catastrophic_subjects(crafted_run, capsys):
    chosen, table = select_checkpoint(
        crafted_run, subjects=1, last=1, top=1, levels=(0, 3), perturbed_subjects=1,
        perturbed_levels=(3,),
    )  # fmt: skip
    assert chosen == crafted_run / ck.CHECKPOINTS_DIR / "step_0000000100"
    assert table.catastrophic.tolist() == [0, 1]
    assert table.catastrophic_perturbed.tolist() == [0, 1]  # level 0: not run
    printed = capsys.readouterr().out  # both twins' count
    assert "step_0000000100: catastrophic 2 (1 on perturbed subjects)," in printed
    with pytest.raises(ValueError, match=r"perturbed levels \[1, 2, 3\] are not among"):
        select_checkpoint(crafted_run, 1, 1, 1, levels=(0,), perturbed_subjects=1)
    with pytest.raises(FieldError, match="perturbed_levels"):
        SelectionConfig(levels=(0,), perturbed_subjects=1, perturbed_levels=(3,))
    # a perturbed twin is another twin: the hanging checkpoint ends elsewhere there
    hanging = crafted_run / ck.CHECKPOINTS_DIR / "step_0000000300"
    perturbed = checkpoint_episodes(hanging, 1, (3,), robustness=True)
    nominal = checkpoint_episodes(hanging, 1, (3,))
    assert not np.allclose(perturbed.final_error_deg, nominal.final_error_deg)
    pid = pid_episodes(1, (3,), robustness=True)
    assert catastrophic_per_level(perturbed, pid).tolist() == [1]


def test_select_cli_writes_the_chosen_checkpoint_and_its_table(crafted_run, tmp_path, capsys):
    out = tmp_path / "sel" / "selection.csv"
    argv = ["policy", "select", str(crafted_run), "--subjects", "1", "--levels", "3", "--last", "1"]
    assert main([*argv, "--top", "0", "--out", str(out)]) == 0
    printed = capsys.readouterr().out
    assert _printed_candidates(printed) == ["step_0000000300"]
    newest = crafted_run / ck.CHECKPOINTS_DIR / "step_0000000300"
    assert f"chosen: {newest}" in printed
    written = pd.read_csv(out, index_col="level")
    assert written.index.tolist() == [3]
    assert written.checkpoint.tolist() == [str(newest)]
    assert written.loc[3, "final_error_ok"] == (
        written.loc[3, "sac_abs_final_error_deg"] < Criteria().final_error_deg[3]
    )
    md = tmp_path / "selection.md"
    assert main([*argv, "--top", "0", "--out", str(md)]) == 0
    text = md.read_text()
    assert text.startswith(f"chosen: `{newest}`") and re.search(r"\n\|\s+3 \|", text)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--subjects", "0"], "--subjects = 0 must be >= 1"),
        (["--last", "0", "--top", "0"], "--top = 0 names no candidate checkpoint"),
        (["--root-seed", "0"], "evaluation"),
        (["--out", "table.txt"], "must end in .md or .csv"),
    ],
)
def test_select_cli_refuses_bad_arguments(crafted_run, args, message, capsys):
    assert main(["policy", "select", str(crafted_run), *args]) == 2
    err = capsys.readouterr().err
    assert err.startswith("myoexo policy select: error: ") and message in err


def test_select_cli_on_a_folder_without_checkpoints(tmp_path, capsys):
    assert main(["policy", "select", str(tmp_path), "--levels", "0"]) == 2
    assert "holds no checkpoint" in capsys.readouterr().err
    assert (
        main(["policy", "select", str(tmp_path), "--last", "0"]) == 2
    )  # --top alone needs eval.csv
    assert "eval.csv" in capsys.readouterr().err
    with pytest.raises(SystemExit):  # argparse: not a level
        main(["policy", "select", str(tmp_path), "--levels", "4"])


def test_table_mode_on_an_evaluation_folder(tmp_path, capsys):
    from myoexo.evaluation import EvaluationConfig, evaluate

    out = tmp_path / "eval"
    config = EvaluationConfig(
        controllers=("pid", "sac"),
        levels=(0, 3),
        subjects=1,
        twin=TwinOptions().replace(episode_duration_s=0.5),
    )
    run = evaluate(config, out, workers=1, progress=False)
    table = compare_evaluation(out)
    t = run.table
    bounds = {0: 1.0, 3: 11.45}  # the paper's SAC final errors (< 1 deg; 11.45 deg)
    for level in (0, 3):
        sac = t[(t.controller == "sac") & (t.level == level)].iloc[0]  # one subject
        pid = t[(t.controller == "pid") & (t.level == level)].iloc[0]
        row = table.loc[level]
        for metric in ("peak_interaction_torque_nm", "rms_interaction_torque_nm"):
            key = "peak" if metric.startswith("peak") else "rms"
            assert row[f"{key}_reduction_pct"] == pytest.approx(
                100 * (pid[metric] - sac[metric]) / pid[metric]
            )
        assert row.sac_abs_final_error_deg == pytest.approx(sac.abs_final_error_deg)
        assert row.sac_p95_abs_final_error_deg == pytest.approx(sac.abs_final_error_deg)
        assert row.final_error_ok == (sac.abs_final_error_deg < bounds[level])
        assert row.settled_pct == (0.0 if math.isnan(sac.settling_time_s) else 100.0)
    with pytest.raises(ValueError, match="no episodes of"):
        compare_evaluation(out, sac="nope")

    md = tmp_path / "criteria.md"
    assert main(["policy", "select", str(out), "--table", "--levels", "3", "--out", str(md)]) == 0
    printed = capsys.readouterr().out
    assert re.search(r"\|\s+3 \|", printed) and not re.search(r"\|\s+0 \|", printed)
    assert md.read_text() == markdown_table(table.loc[[3]]) + "\n"


# ---------------------------------------------------------------------------- a real run
@pytest.mark.slow
def test_selection_on_a_tiny_training_run(tmp_path, capsys):
    from myoexo.training import get_preset, train

    preset = get_preset(
        "cpu",
        episode_duration_s=0.5,
        total_timesteps=200,
        n_envs=1,
        algorithm_kwargs={"buffer_size": 1_000, "batch_size": 16, "learning_starts": 100},
        checkpoint_every_s=0.0,
        checkpoint_every_steps=100,
        eval_every_steps=100,
        eval_subjects=1,
        eval_levels=(0,),
    )
    run_dir = tmp_path / "run"
    train(preset, run_dir, verbose=0)
    ckpts = ck.list_checkpoints(run_dir)
    assert [c.name for c in ckpts] == ["step_0000000100", "step_0000000200"]
    evals = pd.read_csv(run_dir / ck.EVAL_FILE)
    best = ck.checkpoint_name(int(evals.loc[evals.score.idxmax(), "step"]))
    capsys.readouterr()

    chosen, table = select_checkpoint(run_dir, subjects=1, last=1, top=1, levels=(3,))
    candidates = _printed_candidates(capsys.readouterr().out)
    assert candidates == list(dict.fromkeys(["step_0000000200", best]))
    assert chosen.name in candidates
    assert table.index.tolist() == [3]
    row = table.loc[3]
    assert row["pass"] == (row.final_error_ok and row.peak_ok and row.rms_ok)
    assert row.final_error_ok == (row.sac_abs_final_error_deg < 11.45)


def test_seeds_selected_in_processes_are_the_seeds_selected_in_turn(crafted_run, tmp_path):
    import shutil

    from myoexo.training.seeds import per_seed_table

    for seed in (0, 1):
        shutil.copytree(crafted_run, tmp_path / f"seed_{seed}")
    config = SelectionConfig(1, levels=(0,), last=1, top=1)
    in_turn, chosen = per_seed_table(tmp_path, config)
    in_processes, chosen_too = per_seed_table(tmp_path, replace(config, workers=2))
    assert chosen == chosen_too
    assert chosen[1] == str(tmp_path / "seed_1" / ck.CHECKPOINTS_DIR / "step_0000000100")
    pd.testing.assert_frame_equal(in_turn, in_processes)
