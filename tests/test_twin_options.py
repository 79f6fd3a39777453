"""One record of the twin's options (myoexo.envs.options.TwinOptions): built from the command
line, carried by training, written into every checkpoint, read back from a policy's own
files, applied to any env id that takes it, and compared by the evaluation, which warns when
a policy runs on another twin than the one it was trained on."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import warnings

import gymnasium as gym
import pytest

from myoexo.envs.options import TwinOptions, twin_mismatch


def test_the_record_parses_validates_and_round_trips():
    twin = TwinOptions.from_overrides(
        [
            "reflex=persistent",
            "episode_duration_s=4",
            "reward_weights=inter:-0.5",
            "robustness=true",
            "obs_preset=exo",
        ]
    )
    assert twin.reflex == "persistent" and twin.robustness and twin.episode_duration_s == 4.0
    assert json.loads(json.dumps(twin.to_dict())) == twin.to_dict()
    assert TwinOptions.from_dict(twin.to_dict()) == twin
    assert twin.to_dict()["reflex_parameters"]["class"].endswith("PersistentReflex")
    assert twin.env_kwargs() == {
        "episode_duration_s": 4.0,
        "reward_weights": {"inter": -0.5},
        "obs_preset": "exo",
        "reflex": "persistent",
        "robustness": True,
    }
    assert TwinOptions().env_kwargs() == {}  # the default twin adds nothing
    assert twin.replace(episode_duration_s=None).task == ()
    for bad, match in (
        (
            "reflex=clonus",
            "registered: persistent, spindle, spindle_tone, spindle_tsrt, stretch, tsrt, uniform",
        ),
        ("episode_duration_s=-1", r"is outside \[0.001, 3600\] s"),
        ("reward_weights=nope:1", "accepted"),
        ("obs_preset=nope", "accepted"),
        ("robustness=maybe", "true or false"),
        ("perturbed=true", "expected NAME=VALUE with NAME in"),
    ):
        with pytest.raises(ValueError, match=match):
            TwinOptions().with_override(bad)


def test_a_mismatch_names_both_twins_and_ignores_reward_and_observation():
    trained = TwinOptions(reward_weights=(("inter", -0.1),), obs_preset="exo")
    assert twin_mismatch(trained, TwinOptions()) is None
    message = twin_mismatch(trained, TwinOptions(reflex="persistent", robustness=True))
    assert message == "trained on [default twin], evaluated on [reflex=persistent robustness=true]"


def test_a_policy_trained_on_a_twin_and_its_nominal_one_matches_either():
    perturbed = TwinOptions(robustness=True)
    assert perturbed.nominal() == TwinOptions()
    assert twin_mismatch(perturbed, TwinOptions(), nominal_too=True) is None
    assert twin_mismatch(perturbed, TwinOptions()) == (
        "trained on [robustness=true], evaluated on [default twin]"
    )
    assert twin_mismatch(perturbed, TwinOptions(reflex="persistent"), nominal_too=True) == (
        "trained on [robustness=true and default twin], evaluated on [reflex=persistent]"
    )


def test_the_options_reach_any_env_id_that_takes_them_and_are_refused_by_one_that_does_not():
    import myoexo  # noqa: F401
    from myoexo.training.train import make_env_fn

    gym.register("OtherKnee-v7", entry_point="myoexo.envs.knee_exo:MyoExoKneeEnv")
    twin = TwinOptions(reflex="uniform", task=(("episode_duration_s", 0.3),))
    env = make_env_fn("OtherKnee-v7", 0, twin)()
    assert env.unwrapped.spasticity.reflex_name == "uniform"
    assert env.unwrapped.task.episode_duration_s == 0.3
    env.close()
    with pytest.raises(ValueError, match=r"'CartPole-v1' does not take the twin options \[reflex"):
        make_env_fn("CartPole-v1", 0, TwinOptions(reflex="uniform"))()
    make_env_fn("CartPole-v1", 0)().close()  # the default twin: any id


def _myoexo(*args: str, cwd, debug: bool = True) -> subprocess.CompletedProcess:
    env = {**os.environ, "MYOEXO_DEBUG": "1" if debug else ""}
    return subprocess.run(
        [sys.executable, "-m", "myoexo.cli", *args],
        capture_output=True,
        text=True,
        cwd=cwd,
        env=env,
        timeout=900,
    )


@pytest.mark.slow
def test_a_policy_trains_checkpoints_and_evaluates_on_the_persistent_twin_through_the_cli(
    tmp_path,
):
    from myoexo.control.specs import parse_controller_spec, policy_twin, spec_env_kwargs

    run_dir = tmp_path / "run"
    settings = [
        "--env-id", "MyoExoKneeRandom-v0", "--total-timesteps", "300", "--n-envs", "2",
        "--algorithm-kwargs", "buffer_size=2000,batch_size=32,learning_starts=100",
        "--checkpoint-every-s", "0", "--checkpoint-every-steps", "200",
        "--eval-every-steps", "200", "--eval-subjects", "1", "--eval-levels", "2",
        "--reflex", "persistent", "--episode-duration-s", "0.5", "--obs-preset", "exo",
    ]  # fmt: skip
    args = ["policy", "train", "--run-dir", str(run_dir), "--no-progress", "-v", "0"]
    out = _myoexo(*args, *settings, cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "reflex=persistent" in out.stdout
    config = json.loads((run_dir / "config.json").read_text())
    assert config["config"]["twin"]["reflex"] == "persistent"
    checkpoint = sorted((run_dir / "checkpoints").glob("step_*"))[-1]
    state = json.loads((checkpoint / "state.json").read_text())
    assert TwinOptions.from_dict(state["twin"]) == TwinOptions(
        task=(("episode_duration_s", 0.5),), obs_preset="exo", reflex="persistent"
    )

    # the checkpoint alone rebuilds its env: moved away from its run folder
    alone = tmp_path / "elsewhere" / checkpoint.name
    shutil.copytree(checkpoint, alone)
    spec = parse_controller_spec(str(alone / "model.zip"))
    assert policy_twin(spec).reflex == "persistent"
    assert spec_env_kwargs(spec) == {"obs_preset": "exo"}

    evaluation = [
        "evaluate", "--controllers", str(alone / "model.zip"), "--levels", "2",
        "--subjects", "1", "--workers", "1", "--no-progress",
    ]  # fmt: skip
    same = _myoexo(
        *evaluation, "--reflex", "persistent", "--episode-duration-s", "0.5",
        "--out", str(tmp_path / "same"), cwd=tmp_path,
    )  # fmt: skip
    assert same.returncode == 0, same.stderr
    assert "trained on" not in same.stdout + same.stderr
    record = json.loads((tmp_path / "same" / "config.json").read_text())
    entry = next(iter(record["controllers"].values()))
    assert entry["twin"]["reflex"] == "persistent" and entry["twin"]["obs_preset"] == "exo"
    assert entry["trained_on"]["reflex"] == "persistent"

    other = _myoexo(
        *evaluation, "--episode-duration-s", "0.5", "--out", str(tmp_path / "other"), cwd=tmp_path
    )
    assert other.returncode == 0, other.stderr
    assert (
        "was trained on [episode_duration_s=0.5 reflex=persistent], evaluated on "
        "[episode_duration_s=0.5]" in other.stdout + other.stderr
    )


def test_the_evaluation_warns_in_the_api_too(tmp_path):
    from myoexo.evaluation import EvaluationConfig, evaluate
    from myoexo.evaluation.engine import TwinMismatchWarning

    config = EvaluationConfig(
        controllers=("pid", "student_exo"),
        levels=(1,),
        subjects=1,
        twin=TwinOptions(task=(("episode_duration_s", 0.2),), reflex="uniform"),
    )
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        evaluate(config, tmp_path / "eval", workers=1, progress=False, log=lambda m: None)
    mismatches = [w for w in caught if issubclass(w.category, TwinMismatchWarning)]
    assert len(mismatches) == 1  # the policy, not the PID
    # trained on twin 1's default reflex, stretch; evaluated here on uniform
    assert "'student_exo' was trained on [reflex=stretch]" in str(mismatches[0].message)


@pytest.mark.slow
def test_a_checkpoint_chosen_by_select_is_refused_on_its_selection_root(tmp_path):
    """The real path: train, `myoexo policy select` on the selection root, then `myoexo evaluate`
    of the chosen model.zip there (exit 2, nothing written) and on the evaluation root."""
    run_dir = tmp_path / "run"
    settings = [
        "--env-id", "MyoExoKneeRandom-v0", "--total-timesteps", "300", "--n-envs", "2",
        "--algorithm-kwargs", "buffer_size=2000,batch_size=32,learning_starts=100",
        "--checkpoint-every-s", "0", "--checkpoint-every-steps", "200",
        "--eval-every-steps", "0", "--episode-duration-s", "0.3",
    ]  # fmt: skip
    args = ["policy", "train", "--run-dir", str(run_dir), "--no-progress", "-v", "0"]
    assert _myoexo(*args, *settings, cwd=tmp_path).returncode == 0
    picked = _myoexo(
        "policy",
        "select",
        str(run_dir),
        "--subjects",
        "1",
        "--levels",
        "1",
        "--last",
        "1",
        cwd=tmp_path,
    )
    assert picked.returncode == 0, picked.stderr
    chosen = next(line for line in picked.stdout.splitlines() if line.startswith("chosen:"))
    model = chosen.split(":", 1)[1].strip() + "/model.zip"
    evaluation = ["evaluate", "--controllers", model, "--levels", "1", "--subjects", "1"]
    evaluation += ["--workers", "1", "--no-progress", "--episode-duration-s", "0.3"]
    refused = _myoexo(
        *evaluation, "--seed", "1", "--out", str(tmp_path / "on1"), cwd=tmp_path, debug=False
    )
    assert refused.returncode == 2
    assert "was selected on the subjects of root seed 1" in refused.stderr
    assert not (tmp_path / "on1").exists()
    allowed = _myoexo(*evaluation, "--out", str(tmp_path / "on0"), cwd=tmp_path)
    assert allowed.returncode == 0, allowed.stderr
