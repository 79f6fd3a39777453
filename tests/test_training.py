"""Training pipeline: the training config and its presets, a short end-to-end run on the real
env with a checkpoint, a resume that continues the step counter, logging, and the export
(numpy / torch / ONNX)."""

from __future__ import annotations

import argparse
import json
import warnings

import numpy as np
import pytest

from myoexo.runtime.fields import FieldError
from myoexo.training import PRESETS, TrainConfig, get_preset, resume, train
from myoexo.training import checkpoints as ck
from myoexo.training.config import config_from_record

ENV_ID = "MyoExoKneeRandom-v0"


# ---------------------------------------------------------------------------- presets
def test_paper_preset_is_table_ii():
    p = get_preset("paper")
    assert isinstance(p, TrainConfig) and p.name == "paper" and p.algorithm == "sac"
    assert p.net_arch_pi == (64, 64) and p.net_arch_qf == (64, 64)
    assert p.activation == "gelu"
    assert p.total_timesteps == 50_000_000
    kw = p.algorithm_kwargs  # SAC's own arguments, as SB3's SAC takes them
    assert kw["buffer_size"] == 5_000_000
    assert kw["learning_rate"] == 1e-4
    assert kw["tau"] == 0.05
    assert kw["batch_size"] == 4096
    assert kw["gamma"] == 0.99
    assert p.env_id == ENV_ID


def test_cpu_preset_budget():
    p = get_preset("cpu")
    assert p.total_timesteps <= 2_000_000
    assert p.updates_per_transition() < 1.0
    assert p.torch_threads == 1
    # the paper's networks and discounting are kept
    kw = p.algorithm_kwargs
    assert (p.net_arch_pi, p.activation, kw["gamma"], kw["tau"]) == ((64, 64), "gelu", 0.99, 0.05)
    assert set(PRESETS) == {"paper", "cpu", "ppo"}
    assert get_preset("ppo").updates_per_transition() == pytest.approx(10 * 8 / 4096)


@pytest.mark.parametrize(
    ("changes", "match"),
    [
        ({"algorithm_kwargs": {"batch_size": 0}}, "batch_size"),
        ({"algorithm_kwargs": {"learning_rate": -1e-3}}, "learning_rate"),
        ({"algorithm_kwargs": {"gamma": 1.5}}, "gamma"),
        ({"algorithm_kwargs": {"buffer_size": 1.5}}, "buffer_size"),
        ({"algorithm_kwargs": {"seed": 1}}, "set by the run"),
        ({"n_envs": 1.5}, "n_envs"),
        ({"vec_env": "ray"}, "vec_env"),
        ({"activation": "swish"}, "activation"),
        ({"eval_levels": (0, 4)}, "eval_levels"),
        ({"net_arch_pi": ()}, "net_arch_pi"),
        ({"seed": -1}, "seed"),
    ],
)
def test_config_rejects_bad_values(changes, match):
    with pytest.raises(FieldError, match=match):
        get_preset("cpu", **changes)


def test_preset_lookup_errors_and_changes():
    with pytest.raises(ValueError, match="unknown preset"):
        get_preset("gpu")
    with pytest.raises(ValueError, match="unknown training field"):
        get_preset("cpu", batchsize=3)
    with pytest.raises(ValueError, match="belong to the algorithm"):
        get_preset("cpu", learning_rate=1e-3)  # an argument of the algorithm, not a field
    # text is read as the field's type (a sweep file's values)
    p = get_preset(
        "cpu",
        n_envs="2",
        normalize_obs="false",
        net_arch_pi="32,32",
        algorithm_kwargs="learning_rate=1e-3,ent_coef=auto_0.1,buffer_size=1e5",
    )
    assert (p.n_envs, p.normalize_obs, p.net_arch_pi) == (2, False, (32, 32))
    kw = p.algorithm_kwargs
    assert (kw["learning_rate"], kw["ent_coef"], kw["buffer_size"]) == (1e-3, "auto_0.1", 100_000)
    assert kw["batch_size"] == 256  # merged into the preset's
    assert "tau" not in p.replace(algorithm_kwargs={"tau": None}).algorithm_kwargs  # dropped
    assert TrainConfig.from_dict(json.loads(json.dumps(p.to_dict()))) == p


def test_an_algorithm_argument_its_class_does_not_take_is_refused():
    with pytest.raises(FieldError, match=r"tau.*not an argument of ppo"):
        get_preset("ppo", algorithm_kwargs={"tau": 0.1}).resolved_kwargs()
    with pytest.raises(FieldError, match=r"batch_size=64.*exceeds buffer_size"):
        get_preset("cpu", algorithm_kwargs={"batch_size": 64, "buffer_size": 10}).resolved_kwargs()
    resolved = get_preset("cpu").resolved_kwargs()  # the class's defaults fill the rest
    assert resolved["tau"] == 0.05 and resolved["target_entropy"] == "auto"


def test_a_run_recorded_before_algorithm_kwargs_is_read_as_its_config():
    """A config.json whose preset held every algorithm argument as a field of its own (and
    a seeds.json of a preset name and --set items) reads as the same run."""
    old = {
        "name": "cpu", "env_id": ENV_ID, "total_timesteps": 300, "n_envs": 2,
        "vec_env": "dummy", "buffer_size": 1000, "batch_size": 32, "learning_rate": 3e-4,
        "tau": 0.05, "gamma": 0.99, "train_freq": 1, "gradient_steps": 1,
        "learning_starts": 100, "net_arch_pi": [64, 64], "net_arch_qf": [64, 64],
        "activation": "gelu", "ent_coef": "auto", "normalize_obs": True, "clip_obs": 10.0,
        "algorithm": "sac", "n_steps": 256, "n_epochs": 10, "gae_lambda": 0.95,
        "clip_range": 0.2, "normalize_reward": False,
        "twin": {"task": {"episode_duration_s": 1.0}, "reward_weights": {"inter": -0.1}},
    }  # fmt: skip
    config = config_from_record({"preset": old, "seed": 3})
    assert config == get_preset(
        "cpu",
        seed=3,
        total_timesteps=300,
        n_envs=2,
        episode_duration_s=1.0,
        reward_weights="inter:-0.1",
        algorithm_kwargs={"buffer_size": 1000, "batch_size": 32, "learning_starts": 100},
    )  # SAC's arguments only: n_steps (n-step returns for SAC) was never SAC's
    ppo = config_from_record({"preset": {**old, "name": "ppo", "algorithm": "ppo"}, "seed": 0})
    assert set(ppo.algorithm_kwargs) == {
        "learning_rate", "n_steps", "batch_size", "n_epochs", "gamma", "gae_lambda",
        "clip_range", "ent_coef",
    }  # fmt: skip
    crossq = config_from_record({"preset": {**old, "algorithm": "sbx_crossq"}, "seed": 0})
    assert "tau" not in crossq.algorithm_kwargs  # CrossQ never took it
    with pytest.raises(ValueError, match="sb3-contrib"):
        config_from_record({"preset": {**old, "algorithm": "tqc"}, "seed": 0})
    seeds = config_from_record(
        {"preset": "cpu", "set": ["algorithm=sbx_sac", "n_envs=2", "reflex=persistent"]}
    )
    assert (seeds.algorithm, seeds.n_envs, seeds.twin.reflex) == ("sbx_sac", 2, "persistent")


# ---------------------------------------------------------------------------- a short run
def _tiny_preset(**changes):
    """Half-second episodes (50 steps), tiny batch, few updates: seconds, not hours."""
    base = {
        "env_id": ENV_ID,
        "episode_duration_s": 0.5,
        "total_timesteps": 400,
        "n_envs": 2,
        "checkpoint_every_s": 0.0,
        "checkpoint_every_steps": 200,
        "eval_every_steps": 200,
        "eval_subjects": 1,
        "eval_levels": (0, 3),
    }
    kwargs = {"buffer_size": 2_000, "batch_size": 32, "learning_starts": 100}
    kwargs.update(changes.pop("algorithm_kwargs", {}))
    return get_preset("cpu", **{**base, **changes}, algorithm_kwargs=kwargs)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A 400-step run, then resumed to 600 steps."""
    run_dir = tmp_path_factory.mktemp("run") / "tiny"
    first = train(_tiny_preset(seed=3), run_dir, verbose=0)
    first_ckpts = [c.name for c in ck.list_checkpoints(run_dir)]
    second = resume(run_dir, total_timesteps=600, verbose=0)
    return run_dir, first, first_ckpts, second


@pytest.mark.slow
def test_short_run_writes_resumable_checkpoints(tiny_run):
    run_dir, first, first_ckpts, _ = tiny_run
    assert first.num_timesteps == 400
    assert first_ckpts == ["step_0000000200", "step_0000000400"]
    ckpt = run_dir / ck.CHECKPOINTS_DIR / "step_0000000400"
    for name in (ck.MODEL_FILE, ck.VECNORM_FILE, ck.STATE_FILE):
        assert (ckpt / name).is_file()
    state = ck.read_state(ckpt)
    assert state["num_timesteps"] == 400
    # (400 - 100 learning starts) / 2 envs vector steps, one update each
    assert state["n_updates"] == pytest.approx(150, abs=2)
    config = ck.read_config(run_dir)
    assert config["seed"] == 3 and config["env_id"] == ENV_ID
    assert config["config"]["name"] == "cpu" and config["obs_keys"]
    assert ck.read_run_config(run_dir) == _tiny_preset(seed=3)
    assert {"torch", "stable-baselines3", "mujoco", "myosuite"} <= set(config["versions"])


@pytest.mark.slow
def test_resume_continues_the_step_counter(tiny_run):
    run_dir, first, _, second = tiny_run
    assert second.num_timesteps == 600
    # the wall time accumulates over sessions: the resumed session starts from the time
    # recorded in the checkpoint it resumed (a session's result also counts its own tail,
    # e.g. the final checkpoint write, so compare with the checkpoint, not the result)
    resumed_from = ck.read_state(run_dir / ck.CHECKPOINTS_DIR / "step_0000000400")
    assert second.wall_time_s > resumed_from["wall_time_s"] > 0.0
    assert first.wall_time_s >= resumed_from["wall_time_s"]
    latest = json.loads((run_dir / ck.LATEST_FILE).read_text())
    assert latest["checkpoint"] == "step_0000000600"
    state = ck.read_state(run_dir / ck.CHECKPOINTS_DIR / "step_0000000600")
    assert state["n_updates"] == pytest.approx(250, abs=3)  # updates continued too
    sessions = [json.loads(s) for s in (run_dir / ck.SESSIONS_FILE).read_text().splitlines()]
    assert [(s["start_step"], s["end_step"]) for s in sessions] == [(0, 400), (400, 600)]
    # only the two newest resumable checkpoints keep their (large) replay buffer
    with_replay = [c.name for c in ck.list_checkpoints(run_dir) if (c / ck.REPLAY_FILE).exists()]
    assert with_replay == ["step_0000000400", "step_0000000600"]
    # the cadence is recorded with the run
    cadence = ck.read_config(run_dir)["checkpoint_cadence"]
    assert cadence["every_steps"] == 200 and cadence["keep_resumable"] == 2


@pytest.mark.slow
def test_run_logs_reward_terms_and_small_evaluation(tiny_run):
    import pandas as pd

    run_dir, *_ = tiny_run
    progress = pd.read_csv(run_dir / "progress_00.csv")
    for term in ("pose", "inter", "vel", "act", "dense"):
        assert f"reward_terms/{term}" in progress.columns
    assert "eval/score" in progress.columns
    assert "eval/L0/peak_vs_pid_pct" in progress.columns
    assert any(p.name.startswith("events.out.tfevents") for p in (run_dir / ck.TB_DIR).iterdir())
    evals = pd.read_csv(run_dir / ck.EVAL_FILE)
    assert sorted(evals.step.unique()) == [200, 400, 600]
    assert set(evals.level) == {0, 3}
    assert np.isfinite(evals.peak_interaction_torque_nm).all()
    pid = json.loads((run_dir / ck.EVAL_PID_FILE).read_text())
    assert set(pid) == {"0", "3"} and pid["0"]["peak_interaction_torque_nm"] > 0
    # every evaluated step has a policy snapshot carrying its score; 'best' picks among them
    best = ck.resolve_checkpoint(run_dir, "best")
    assert ck.read_state(best)["eval_score"] == pytest.approx(evals.score.max())


def test_train_refuses_existing_run_and_resume_needs_a_run(tmp_path):
    (tmp_path / ck.CONFIG_FILE).write_text("{}")
    with pytest.raises(ValueError, match="already holds a run"):
        train(_tiny_preset(), tmp_path)
    with pytest.raises(ValueError, match="not a training run"):
        resume(tmp_path / "nothing")
    with pytest.raises(ValueError, match="not an argument of ppo"):
        train(_tiny_preset(algorithm="ppo"), tmp_path / "x")  # SAC's arguments
    assert not (tmp_path / "x").exists()  # refused before the folder is made


# ---------------------------------------------------------------------------- export
@pytest.mark.slow
def test_exported_actor_matches_sb3_torch_and_onnx(tiny_run, tmp_path):
    import onnxruntime as ort
    import torch
    from stable_baselines3 import SAC

    from myoexo.policies import load_actor
    from myoexo.training.export import export_onnx, load_checkpoint_actor

    run_dir, *_ = tiny_run
    ckpt = ck.resolve_checkpoint(run_dir, "latest")
    actor = load_checkpoint_actor(ckpt)
    rng = np.random.default_rng(0)
    obs = actor.obs_mean + np.sqrt(actor.obs_var) * rng.standard_normal((16, actor.obs_dim))
    obs = obs.astype(np.float32)

    # the SB3 policy behind its VecNormalize statistics
    import pickle

    with open(ckpt / ck.VECNORM_FILE, "rb") as f:
        vn = pickle.load(f)
    sb3_action, _ = SAC.load(ckpt / ck.MODEL_FILE, device="cpu").predict(
        vn.normalize_obs(obs), deterministic=True
    )
    np.testing.assert_allclose(actor(obs), sb3_action, atol=1e-5)

    with torch.no_grad():
        torch_action = actor.to_torch()(torch.as_tensor(obs)).numpy()
    onnx_path = export_onnx(actor, tmp_path / "actor.onnx")
    session = ort.InferenceSession(str(onnx_path))
    onnx_action = session.run(None, {"obs": obs})[0]
    assert onnx_action.shape == (16, 1)
    np.testing.assert_allclose(onnx_action, torch_action, atol=1e-5)
    np.testing.assert_allclose(actor(obs), torch_action, atol=1e-5)

    # the file round trip keeps the function
    from myoexo.policies import save_actor

    save_actor(actor, tmp_path / "a")
    np.testing.assert_allclose(load_actor(tmp_path / "a")(obs), actor(obs), atol=1e-6)


@pytest.mark.slow
def test_export_policy_cli(tiny_run, tmp_path):
    from myoexo.cli import main
    from myoexo.policies import load_actor

    run_dir, *_ = tiny_run
    rc = main(
        [
            "policy",
            "export",
            str(run_dir),
            "--checkpoint",
            "200",
            "--onnx",
            str(tmp_path / "p.onnx"),
            "--out",
            str(tmp_path / "p"),
            "--seed-group",
            "tiny_seeds",
        ]
    )
    assert rc == 0 and (tmp_path / "p.onnx").stat().st_size > 1000
    actor = load_actor(tmp_path / "p")
    assert actor.metadata["num_timesteps"] == 200
    from myoexo.control import parse_controller_spec

    # the group makes the actor one seed of a controller of the tables
    assert parse_controller_spec(str(tmp_path / "p.npz")).seed_group == "tiny_seeds"
    assert actor.check_reference() < 1e-5
    with pytest.raises(ValueError, match="no checkpoint at step"):
        ck.resolve_checkpoint(run_dir, "123")


def test_train_cli_arguments(tmp_path, capsys):
    from myoexo.cli import main
    from myoexo.training import cli

    parser = argparse.ArgumentParser()
    cli.add_arguments(parser)
    args = parser.parse_args(
        [
            "--preset", "paper", "--n-envs", "2", "--no-progress", "--seed", "4",
            "--algorithm-kwargs", "learning_rate=1e-3,train_freq=16", "--reflex", "persistent",
            "--reward-weights", "inter:-0.1", "--net-arch-pi", "32", "32", "--no-normalize-obs",
        ]
    )  # fmt: skip
    config = cli.config_from_args(args)
    assert config == get_preset(
        "paper",
        n_envs=2,
        seed=4,
        algorithm_kwargs={"learning_rate": 1e-3, "train_freq": 16},
        reflex="persistent",
        reward_weights={"inter": -0.1},
        net_arch_pi=(32, 32),
        normalize_obs=False,
    )
    assert cli.config_from_args(parser.parse_args([])) == get_preset("cpu")  # nothing given
    # an option checked against the twin: the twin's options apply with it
    paced = ["--residual-base", "pid:reference=minjerk", "--residual-pace-s", "0.3", "0.6"]
    config = cli.config_from_args(parser.parse_args([*paced, "--gentleness", "random"]))
    assert config.residual_pace_s == (0.3, 0.6) and config.twin.gentleness == "random"
    args = parser.parse_args(["--resume", "runs/x"])
    assert args.resume == "runs/x"
    # a saved config is a base, as a preset is
    saved = tmp_path / "config.json"
    saved.write_text(json.dumps({"config": config.to_dict()}))
    again = cli.config_from_args(parser.parse_args(["--config", str(saved), "--seed", "5"]))
    assert again == config.replace(seed=5)
    # the earlier --set is refused in one line that names the option replacing it
    for item, new in (
        ("n_envs=2", "--n-envs 2"),
        ("batch_size=64", "--algorithm-kwargs batch_size=64"),
        ("robustness=true", "--robustness"),
        ("episode_duration_s=4", "--episode-duration-s 4"),
    ):
        with pytest.raises(SystemExit) as stop:
            main(["policy", "train", "--set", item, "--run-dir", str(tmp_path / "r")])
        err = capsys.readouterr().err
        assert stop.value.code == 2
        assert len(err.strip().splitlines()) == 1 and f"is now {new}" in err
    # a bad value is reported under its option, before a folder is made
    assert main(["policy", "train", "--n-envs", "0", "--run-dir", str(tmp_path / "r")]) == 2
    assert "--n-envs = 0 must be >= 1" in capsys.readouterr().err
    args = ["policy", "train", "--algorithm-kwargs", "learning_rate=2", "--run-dir"]
    assert main([*args, str(tmp_path / "r")]) == 2
    assert "--algorithm-kwargs = 'learning_rate=2.0' is outside (0, 1]" in capsys.readouterr().err
    assert not (tmp_path / "r").exists()


def test_reward_weight_changes_reach_the_training_envs():
    from myoexo.training.train import make_env_fn

    preset = get_preset("cpu", reward_weights="inter:-0.5,act:-0.25")
    assert TrainConfig.from_dict(preset.to_dict()) == preset  # survives the run's config.json
    env = make_env_fn(ENV_ID, 0, preset.twin)()
    weights = env.unwrapped.rwd_keys_wt
    assert weights["inter"] == -0.5 and weights["act"] == -0.25 and weights["pose"] == 1.0
    env.close()
    with pytest.raises(ValueError, match="reward_weights"):
        get_preset("cpu", reward_weights=(("nope", 1.0),))


def _assert_newest_checkpoint_acts(run_dir):
    """The run's newest checkpoint, loaded as a controller, gives one command in [-1, 1]."""
    from myoexo.envs import make_env
    from myoexo.envs.sensors import read_sensors
    from myoexo.training.export import load_checkpoint_controller

    controller = load_checkpoint_controller(ck.list_checkpoints(run_dir)[-1])
    env = make_env(1, episode_duration_s=0.5)
    obs, info = env.reset(seed=0)
    action = controller.act(obs, read_sensors(info))
    assert action.shape == (1,) and abs(float(action[0])) <= 1.0
    with pytest.raises(ValueError, match="not trained with a gentleness weight"):
        load_checkpoint_controller(ck.list_checkpoints(run_dir)[-1], gentleness=0.5)


@pytest.mark.slow
@pytest.mark.parametrize("algorithm", ["sbx_sac", "sbx_sac_overlap"])
def test_jax_learner_trains_exports_and_resumes(tmp_path, algorithm):
    """SBX's SAC (JAX), plain or overlapped, goes through the same run folder, checkpoints,
    resume and export as SB3's; its numpy actor gives the JAX policy's deterministic
    actions."""
    pytest.importorskip("sbx")
    run_dir = tmp_path / "sbx"
    preset = _tiny_preset(algorithm=algorithm, eval_levels=(1,), seed=1)
    first = train(preset, run_dir, verbose=0)
    assert first.num_timesteps == 400
    second = resume(run_dir, total_timesteps=600, verbose=0)
    assert second.num_timesteps == 600
    from myoexo.training.export import _checkpoint_parts, load_checkpoint_actor

    checkpoint = ck.list_checkpoints(run_dir)[-1]
    actor = load_checkpoint_actor(checkpoint)  # stores and checks reference pairs vs JAX
    model, vn, _ = _checkpoint_parts(checkpoint)
    rng = np.random.default_rng(0)
    obs = rng.standard_normal((16, actor.obs_dim)).astype(np.float32)
    jax_action, _ = model.predict(vn.normalize_obs(obs), deterministic=True)
    np.testing.assert_allclose(actor(obs), jax_action, atol=1e-5)
    assert actor.metadata["algorithm"] == algorithm


def test_the_jax_extra_is_named_when_missing(monkeypatch):
    import builtins

    from myoexo.policies.algorithms import ALGORITHMS

    real_import = builtins.__import__

    def no_sbx(name, *args, **kwargs):
        if name == "sbx" or name.startswith("sbx."):
            raise ImportError("No module named 'sbx'")
        return real_import(name, *args, **kwargs)

    monkeypatch.setattr(builtins, "__import__", no_sbx)
    monkeypatch.delitem(__import__("sys").modules, "sbx", raising=False)
    with pytest.raises(ValueError, match=r"myoexo\[jax\]"):
        ALGORITHMS["sbx_sac"].load_class()


def test_obs_preset_and_algorithm_fields_are_validated():
    preset = get_preset("cpu", obs_preset="exo", algorithm="SBX_TQC")
    assert preset.algorithm == "sbx_tqc"
    assert TrainConfig.from_dict(preset.to_dict()) == preset
    with pytest.raises(ValueError, match="obs_preset"):
        get_preset("cpu", obs_preset="nope")
    for removed in ("a2c", "td3", "tqc", "crossq"):
        with pytest.raises(FieldError, match="algorithm"):
            get_preset("cpu", algorithm=removed)


def test_exo_preset_and_robustness_reach_the_training_envs():
    from myoexo.training.train import make_vec_env

    venv = make_vec_env(_tiny_preset(obs_preset="exo", robustness=True, n_envs=1), seed=0)
    assert venv.get_attr("obs_preset")[0] == "exo"
    assert venv.get_attr("robustness")[0] is not None  # a perturbed twin per episode
    assert venv.observation_space.shape == (18,)
    venv.close()
    plain = make_vec_env(_tiny_preset(n_envs=1), seed=0)
    assert plain.get_attr("robustness")[0] is None
    plain.close()
    assert get_preset("cpu", robustness="true").twin.robustness is True  # a twin option


def test_nominal_envs_share_the_training_envs_between_twins(tiny_run, tmp_path):
    from myoexo.training.export import load_checkpoint_actor
    from myoexo.training.train import make_vec_env

    config = _tiny_preset(robustness=True, n_envs=3, nominal_envs=1)
    venv = make_vec_env(config, seed=0)
    perturbed = [r is not None for r in venv.get_attr("robustness")]
    assert perturbed == [True, True, False]  # the last nominal_envs: the nominal twin
    venv.close()
    assert TrainConfig.from_dict(config.to_dict()) == config
    with pytest.raises(FieldError, match=r"nominal_envs.*robustness"):
        _tiny_preset(n_envs=3, nominal_envs=1)
    with pytest.raises(FieldError, match=r"nominal_envs.*below n_envs = 3"):
        _tiny_preset(robustness=True, n_envs=3, nominal_envs=3)
    # the exported policy records the share (its twin says robustness alone)
    train(_tiny_preset(robustness=True, nominal_envs=1, total_timesteps=200), tmp_path / "r")
    actor = load_checkpoint_actor(ck.resolve_checkpoint(tmp_path / "r", "latest"))
    assert actor.metadata["training_envs"] == {"n_envs": 2, "nominal_envs": 1}
    plain = load_checkpoint_actor(ck.resolve_checkpoint(tiny_run[0], "latest"), False)
    assert "training_envs" not in plain.metadata
    # it was trained on the perturbed twin and on its nominal one: evaluated on either, no
    # mismatch; on another reflex, the warning names both
    from myoexo.evaluation.engine import TwinMismatchWarning, resolve_controllers
    from myoexo.policies.actor import save_actor

    npz, _ = save_actor(actor, tmp_path / "half")
    checkpoint = ck.resolve_checkpoint(tmp_path / "r", "latest")
    assert ck.read_state(checkpoint)["training_envs"] == {"n_envs": 2, "nominal_envs": 1}
    model = f"{config.algorithm}:{checkpoint / ck.MODEL_FILE}"  # its checkpoint records it
    with warnings.catch_warnings():
        warnings.simplefilter("error", TwinMismatchWarning)
        for twin in (config.twin, config.twin.nominal()):
            resolve_controllers([str(npz), model], log=lambda _: None, twin=twin)
    other = config.twin.replace(reflex="spindle")
    with pytest.warns(TwinMismatchWarning, match=r"trained on \[.*robustness=true and .*\]"):
        resolve_controllers([str(npz)], log=lambda _: None, twin=other)


# ---------------------------------------------------------------------------- on-policy (PPO)
def test_ppo_preset_fields_are_validated():
    p = get_preset("ppo")
    assert p.algorithm == "ppo" and p.n_envs == 16 and p.normalize_reward
    assert (p.net_arch_pi, p.net_arch_qf, p.activation) == ((64, 64), (64, 64), "gelu")
    with pytest.raises(FieldError, match="ent_coef=auto"):
        get_preset("ppo", algorithm_kwargs={"ent_coef": "auto"}).resolved_kwargs()
    with pytest.raises(FieldError, match=r"batch_size=8192.*exceeds a rollout"):
        get_preset("ppo", algorithm_kwargs={"batch_size": 8192}).resolved_kwargs()
    with pytest.raises(FieldError, match="gae_lambda"):
        get_preset("ppo", algorithm_kwargs={"gae_lambda": 1.5})
    with pytest.raises(FieldError, match="max_wall_time_s"):
        get_preset("cpu", max_wall_time_s=-1.0)


def _tiny_ppo(**changes):
    base = {
        "env_id": ENV_ID,
        "episode_duration_s": 0.5,
        "total_timesteps": 256,
        "n_envs": 2,
        "checkpoint_every_s": 0.0,
        "checkpoint_every_steps": 128,
        "eval_every_steps": 128,
        "eval_subjects": 1,
        "eval_levels": (1,),
        "algorithm_kwargs": {"n_steps": 64, "batch_size": 32, "n_epochs": 2},
    }
    return get_preset("ppo", **{**base, **changes})


@pytest.mark.slow
def test_ppo_trains_checkpoints_resumes_and_acts(tmp_path):
    """SB3's PPO goes through the same run folder, small evaluation, checkpoints and resume
    as the off-policy learners; its checkpoints are resumable without a replay buffer."""
    run_dir = tmp_path / "ppo"
    first = train(_tiny_ppo(seed=2), run_dir, verbose=0)
    assert first.num_timesteps == 256
    last = ck.list_checkpoints(run_dir)[-1]
    assert (last / ck.ON_POLICY_FILE).is_file() and not (last / ck.REPLAY_FILE).exists()
    assert ck.resumable_checkpoints(run_dir)[-1] == last
    assert ck.checkpoint_problem(last) is None
    # written as the second rollout of 2 x 64 transitions ends: one update phase of 2 epochs
    assert ck.read_state(last)["n_updates"] == 2
    from myoexo.training.seeds import gradient_updates

    assert gradient_updates(run_dir, 2) == 2 * (2 * 64 // 32)
    second = resume(run_dir, total_timesteps=512, verbose=0)
    assert second.num_timesteps == 512
    # only the newest keep_resumable_checkpoints stay resumable
    assert len(ck.resumable_checkpoints(run_dir)) == 2
    _assert_newest_checkpoint_acts(run_dir)


@pytest.mark.slow
def test_the_wall_time_budget_ends_a_run_and_a_resume_keeps_it(tmp_path):
    run_dir = tmp_path / "budget"
    preset = _tiny_ppo(total_timesteps=10**7, eval_every_steps=0, max_wall_time_s=2.0)
    first = train(preset, run_dir, verbose=0)
    assert 0 < first.num_timesteps < 10**7
    assert 2.0 <= first.wall_time_s < 30.0
    sessions = [json.loads(x) for x in (run_dir / ck.SESSIONS_FILE).read_text().splitlines()]
    assert sessions[-1]["ended_by"] == "wall_time_budget" and sessions[-1]["stopped_by"] is None
    newest = ck.latest_checkpoint(run_dir, with_replay=True)
    assert float(ck.read_state(newest)["wall_time_s"]) >= 2.0
    again = resume(run_dir, verbose=0)  # the budget is spent: nothing more is trained
    assert again.num_timesteps == first.num_timesteps


@pytest.mark.slow
def test_jax_crossq_evaluates_during_training_through_its_model(tmp_path):
    """SBX's CrossQ keeps its actor's batch-renormalization state beside the layers: the
    periodic evaluation and the checkpoints act through the JAX model, not the numpy actor."""
    pytest.importorskip("sbx")
    from myoexo.control.policy import SB3Controller
    from myoexo.training.export import load_checkpoint_controller

    run_dir = tmp_path / "crossq"
    # CrossQ has no target networks: the cpu preset's tau is dropped (NAME=none on the CLI)
    preset = _tiny_preset(algorithm="sbx_crossq", eval_levels=(1,), algorithm_kwargs={"tau": None})
    train(preset, run_dir, verbose=0)
    assert len((run_dir / ck.EVAL_FILE).read_text().splitlines()) == 1 + 2
    controller = load_checkpoint_controller(ck.list_checkpoints(run_dir)[-1])
    assert isinstance(controller, SB3Controller)


def test_a_budget_stop_leaves_a_checkpoint_past_the_budget(tmp_path):
    """In the step the budget runs out (a cadence checkpoint is due in the same step), the
    checkpointer writes one resumable checkpoint that records a wall time at or past the
    budget and ends the session, so that a resume does not train on."""
    import time as _time

    from myoexo.training.callbacks import PeriodicCheckpointCallback

    def checkpointer(offset_s):
        cb = PeriodicCheckpointCallback(
            tmp_path, every_s=0.0, every_steps=128, wall_time_offset_s=offset_s, max_wall_time_s=2.0
        )
        cb.num_timesteps, cb._step_last_full = 128, 0  # the step cadence is due
        cb._t_start = _time.monotonic() - 0.01
        cb.saved = []
        cb.save = lambda with_replay=True: cb.saved.append((with_replay, cb.wall_time_s()))
        return cb

    spent = checkpointer(1.999)
    assert spent._on_step() is False and spent.budget_spent
    assert len(spent.saved) == 1 and spent.saved[0][0] and spent.saved[0][1] >= 2.0
    running = checkpointer(1.0)
    assert running._on_step() is True and not running.budget_spent
    assert len(running.saved) == 1 and running.saved[0][1] < 2.0  # the cadence checkpoint


def test_the_training_vector_env_steps_as_sb3s_and_hands_on_each_steps_own_info():
    """FreshInfoVecEnv gives DummyVecEnv's observations, rewards, dones and infos (episode
    ends, terminal observations and resets included) without its deep copy; the infos of
    two steps are distinct objects."""
    from stable_baselines3.common.vec_env import DummyVecEnv

    from myoexo.training.plumbing import FreshInfoVecEnv
    from myoexo.training.train import make_env_fn

    twin = get_preset("cpu").twin.replace(episode_duration_s=0.05)  # 5 steps per episode
    venvs = [
        cls([make_env_fn(ENV_ID, i, twin) for i in range(2)])
        for cls in (DummyVecEnv, FreshInfoVecEnv)
    ]
    for venv in venvs:
        venv.seed(3)
    first = [venv.reset() for venv in venvs]
    np.testing.assert_array_equal(first[0], first[1])
    rng = np.random.default_rng(0)
    previous = None
    ends = 0
    for _ in range(12):
        action = rng.uniform(-1, 1, (2, 1)).astype(np.float32)
        (o0, r0, d0, i0), (o1, r1, d1, i1) = (venv.step(action) for venv in venvs)
        np.testing.assert_array_equal(o0, o1)
        np.testing.assert_array_equal(r0, r1)
        np.testing.assert_array_equal(d0, d1)
        for a, b in zip(i0, i1, strict=True):
            assert a.keys() == b.keys()
            assert a["TimeLimit.truncated"] == b["TimeLimit.truncated"]
            assert a["knee_angle_deg"] == b["knee_angle_deg"]
            if "terminal_observation" in a:
                np.testing.assert_array_equal(a["terminal_observation"], b["terminal_observation"])
                assert (a["episode"]["r"], a["episode"]["l"]) == (
                    b["episode"]["r"],
                    b["episode"]["l"],
                )
        ends += int(d1.sum())
        if previous is not None:
            assert all(p is not n for p, n in zip(previous, i1, strict=True))
            assert all(
                p["obs_dict"] is not n["obs_dict"] for p, n in zip(previous, i1, strict=True)
            )
        previous = i1
    assert ends >= 4  # every env ended two episodes and was reset
    for venv in venvs:
        venv.close()


def test_the_jax_learners_replay_buffer_samples_what_sb3s_does():
    """NumpySampleReplayBuffer's samples equal ReplayBuffer's for the same draws, and the
    JAX learners get it by default."""
    pytest.importorskip("sbx")
    from gymnasium import spaces
    from stable_baselines3.common.buffers import ReplayBuffer

    from myoexo.training.plumbing import NumpySampleReplayBuffer
    from myoexo.training.train import build_model, make_vec_env

    obs_space = spaces.Box(-1.0, 1.0, (5,), np.float32)
    act_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    buffers = [
        cls(100, obs_space, act_space, n_envs=2) for cls in (ReplayBuffer, NumpySampleReplayBuffer)
    ]
    rng = np.random.default_rng(0)
    for _ in range(30):
        obs, nxt = rng.normal(size=(2, 5)), rng.normal(size=(2, 5))
        act, rew = rng.uniform(-1, 1, (2, 1)), rng.normal(size=2)
        done = rng.random(2) < 0.1
        for buf in buffers:
            buf.add(obs, nxt, act, rew, done, [{}, {}])
    samples = []
    for buf in buffers:
        np.random.seed(7)  # noqa: NPY002 (SB3 samples from numpy's global RNG)
        samples.append(buf.sample(16))
    for a, b in zip(*samples, strict=True):
        assert (a is None) == (b is None)
        if a is not None:
            np.testing.assert_array_equal(a.numpy(), b.numpy())
    preset = get_preset("cpu", algorithm="sbx_sac")
    venv = make_vec_env(preset.replace(n_envs=1), seed=0)
    model = build_model(preset, venv)
    assert isinstance(model.replay_buffer, NumpySampleReplayBuffer)
    venv.close()
