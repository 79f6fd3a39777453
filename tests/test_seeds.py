"""Seeds of one configuration: the aggregation over seeds (mean, IQM, bootstrap CI, pass
fraction, the ship rule) and the per-seed train commands."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from myoexo.evaluation.stats import bootstrap_ci, summarize_seeds, wilson_interval
from myoexo.training import seeds as S


def _per_seed(values_by_seed: dict[int, float], passed: set[int]) -> pd.DataFrame:
    rows = []
    for seed, v in values_by_seed.items():
        for level in (0, 1):
            rows.append(
                {
                    "seed": seed,
                    "level": level,
                    "abs_final_error_deg": v + level,
                    "peak_reduction_pct": 10.0 * v,
                    "rms_reduction_pct": -v,
                    "settling_time_s": math.nan if seed == 0 else 0.5 + v,
                    "pass": seed in passed,
                }
            )
    return pd.DataFrame(rows)


def test_summary_has_mean_iqm_and_a_ci_that_contains_the_mean():
    per_seed = _per_seed({0: 0.1, 1: 0.2, 2: 0.3, 3: 0.4, 4: 5.0}, passed={1, 2, 3})
    summary = summarize_seeds(per_seed, S.AGGREGATED)
    row = summary.loc[0]
    assert row["abs_final_error_deg_mean"] == pytest.approx(np.mean([0.1, 0.2, 0.3, 0.4, 5.0]))
    # the IQM drops the outlier seed 4 (and the best one): the middle three
    assert row["abs_final_error_deg_iqm"] == pytest.approx(0.3)
    assert row["abs_final_error_deg_ci_low"] <= row["abs_final_error_deg_mean"]
    assert row["abs_final_error_deg_mean"] <= row["abs_final_error_deg_ci_high"]
    assert summary.loc[1, "abs_final_error_deg_mean"] == pytest.approx(
        row["abs_final_error_deg_mean"] + 1
    )
    # a never-settled seed (NaN) is left out of the settling time, not counted as 0
    assert row["settling_time_s_mean"] == pytest.approx(np.mean([0.7, 0.8, 0.9, 5.5]))
    assert row["p_pass"] == pytest.approx(0.6)
    assert 0.0 <= row["p_pass_ci_low"] < 0.6 < row["p_pass_ci_high"] <= 1.0
    text = S.markdown_summary(summary)
    assert "P(pass criteria)" in text and text.startswith("**In-sample**")


def test_bootstrap_is_reproducible_and_degenerate_inputs_are_handled():
    a = bootstrap_ci([1.0, 2.0, 3.0, 4.0])
    assert a == bootstrap_ci([1.0, 2.0, 3.0, 4.0]) and a[0] < 2.5 < a[1]
    assert bootstrap_ci([2.0, 2.0]) == (2.0, 2.0)
    low, high = bootstrap_ci([1.0])
    assert low == high == 1.0
    assert all(math.isnan(v) for v in bootstrap_ci([]))


def test_wilson_interval():
    low, high = wilson_interval(0, 5)
    assert low == pytest.approx(0.0, abs=1e-12) and 0.4 < high < 0.5
    low, high = wilson_interval(5, 5)
    assert 0.5 < low < 0.6 and high == pytest.approx(1.0)


def test_the_ship_rule_picks_the_typical_seed_not_the_best():
    per_seed = _per_seed({0: 0.0, 1: 1.0, 2: 2.0, 3: 3.0, 4: 4.0}, passed=set())
    assert S.closest_seed(per_seed) == 2  # the middle one, not seed 0 (the best)


def test_train_command_starts_resumes_or_restarts(tmp_path):
    from myoexo.training import checkpoints as ck

    new = S.train_command(tmp_path, 3, 1000)
    assert new[-6:] == [
        "--config", str(tmp_path / S.SEEDS_FILE), "--seed", "3", "--run-dir",
        str(S.seed_dir(tmp_path, 3)),
    ]  # fmt: skip
    assert "--total-timesteps" not in new  # a new seed's budget is the folder's config's
    run_dir = S.seed_dir(tmp_path, 3)
    run_dir.mkdir()
    (run_dir / ck.CONFIG_FILE).write_text("{}")
    assert "--restart" in S.train_command(tmp_path, 3, 1000)  # no checkpoint yet
    step = run_dir / ck.CHECKPOINTS_DIR / ck.checkpoint_name(100)
    step.mkdir(parents=True)
    (step / ck.REPLAY_FILE).write_bytes(b".")
    (step / ck.STATE_FILE).write_text("{}")
    assert ck.resumable_checkpoints(run_dir) == [step]
    assert S.train_command(tmp_path, 3, None)[-2:] == ["--resume", str(run_dir)]
    assert S.train_command(tmp_path, 3, 2000)[-2:] == ["--total-timesteps", "2000"]


def test_a_seeds_folder_refuses_another_configuration(tmp_path):
    import json

    from myoexo.training import get_preset
    from myoexo.training.config import read_config_file

    config = get_preset("cpu", algorithm="sbx_sac")
    S._record_config(tmp_path, config, [0, 1])
    S._record_config(tmp_path, config.replace(total_timesteps=10), [2])  # a new budget
    saved = json.loads((tmp_path / S.SEEDS_FILE).read_text())
    assert saved["seeds"] == [0, 1, 2]
    assert read_config_file(tmp_path / S.SEEDS_FILE).total_timesteps == 10
    with pytest.raises(ValueError, match=r"another configuration \(it differs in \['algorithm'\]"):
        S._record_config(tmp_path, get_preset("cpu"), [0])
    # a seeds.json of an earlier version (a preset name and --set items) is its config
    (tmp_path / S.SEEDS_FILE).write_text(
        json.dumps({"preset": "cpu", "set": ["algorithm=sbx_sac", "train_freq=16"], "seeds": [0]})
    )
    S._record_config(tmp_path, config.replace(algorithm_kwargs={"train_freq": 16}), [1])
    saved = json.loads((tmp_path / S.SEEDS_FILE).read_text())
    assert set(saved) == {"config", "seeds"} and saved["seeds"] == [0, 1]


def test_the_seeds_train_options_are_the_train_options(tmp_path):
    import argparse

    from myoexo.training import get_preset
    from myoexo.training.cli import config_from_args

    parser = argparse.ArgumentParser()
    S.add_arguments(parser)
    args = parser.parse_args(
        ["train", str(tmp_path), "--seeds", "0", "2", "--algorithm", "sbx_sac",
         "--algorithm-kwargs", "train_freq=16", "--reward-weights", "inter:-0.1"]
    )  # fmt: skip
    assert S.from_options(S.SeedRuns, args) == S.SeedRuns(seeds=(0, 2), workers=2)
    assert config_from_args(args) == get_preset(
        "cpu", algorithm="sbx_sac", algorithm_kwargs={"train_freq": 16}, reward_weights="inter:-0.1"
    )
    with pytest.raises(ValueError, match="repeats a seed"):
        S.SeedRuns(seeds=(1, 1))


def _fake_seed_run(out, seed, algorithm, wall_s, steps, updates, preset_extra=None):
    """A seed run folder with a config and one checkpoint state (no model)."""
    import json

    from myoexo.training import checkpoints as ck

    run = S.seed_dir(out, seed)
    step = run / ck.CHECKPOINTS_DIR / ck.checkpoint_name(steps)
    step.mkdir(parents=True)
    preset = {"algorithm": algorithm, "name": "x", **(preset_extra or {})}
    (run / ck.CONFIG_FILE).write_text(json.dumps({"preset": preset, "seed": seed}))
    state = {"num_timesteps": steps, "n_updates": updates, "wall_time_s": wall_s}
    (step / ck.STATE_FILE).write_text(json.dumps(state))


def test_compare_reads_speed_from_checkpoints_and_criteria_from_the_aggregate(tmp_path):
    for name, algorithm, extra in (
        ("sac", "sbx_sac", None),
        ("ppo", "ppo", {"n_steps": 256, "n_envs": 16, "batch_size": 512}),
    ):
        out = tmp_path / name
        for seed in (0, 1):
            _fake_seed_run(out, seed, algorithm, 600.0, 60_000 * (seed + 1), 1_000, extra)
        summary = summarize_seeds(_per_seed({0: 1.0, 1: 3.0}, passed={1}), S.AGGREGATED)
        summary.to_csv(out / "aggregate.csv")
    table = S.compare_configurations([tmp_path / "sac", tmp_path / "ppo"])
    sac, ppo = table.iloc[0], table.iloc[1]
    assert sac["configuration"] == "sbx_sac (x)" and sac["seeds"] == 2
    assert sac["wall_time_min"] == pytest.approx(10.0)
    assert sac["env_steps_per_s"] == pytest.approx(150.0)  # (100 + 200) / 2
    assert sac["updates_per_s"] == pytest.approx(1_000 / 600)
    # PPO counts epochs: 8 minibatches of 512 in a 4096-transition rollout
    assert ppo["updates_per_s"] == pytest.approx(8 * 1_000 / 600)
    assert sac["L0_p_pass"] == 0.5 and sac["p_pass_mean"] == 0.5
    text = S.markdown_comparison(table)
    assert text.count("\n") == 4 and "| sbx_sac (x) | 2 | 10.0 |" in text
    with pytest.raises(ValueError, match="seeds aggregate"):
        S.compare_configurations([tmp_path / "nothing"])
