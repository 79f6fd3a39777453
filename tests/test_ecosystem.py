"""The envs as the ecosystem's own clients build and run them, by id: MyoSuite's
``examine_env`` (a subprocess, as a user calls it), gymnasium's ``make`` / ``make_vec``,
stable-baselines3's ``make_vec_env`` and ``check_env``, RLlib's env runner.

What they rely on: ``spec.max_episode_steps`` is the episode length (their horizon), env
arguments are literals (``episode_duration_s=...``), and an unknown keyword
argument raises Python's own ``TypeError`` message, which their builders look for.
"""

from __future__ import annotations

import glob
import os
import re
import subprocess
import sys

import gymnasium as gym
import h5py
import numpy as np
import pytest

import myoexo  # noqa: F401  (registers the ids)
from myoexo.envs import TaskParams, make_env
from myoexo.envs.registration import ENV_LEVELS, RANDOM_ENV_ID

ALL_IDS = list(ENV_LEVELS)
UNKNOWN_KWARG = "MyoExoKneeEnv.__init__() got an unexpected keyword argument 'x'"
ZERO = np.array([0.0], np.float32)


def _time_limits(env: gym.Env) -> list[int]:
    limits = []
    while isinstance(env, gym.Wrapper):
        if isinstance(env, gym.wrappers.TimeLimit):
            limits.append(env._max_episode_steps)
        env = env.env
    return limits


def _truncations(env: gym.Env, steps: int) -> list[bool]:
    env.reset(seed=0)
    return [env.step(ZERO)[3] for _ in range(steps)]


# -- spec.max_episode_steps ----------------------------------------------------------------


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_spec_reports_the_episode_length_without_a_time_limit(env_id):
    env = gym.make(env_id)
    assert env.spec.max_episode_steps == env.unwrapped.episode_steps == 800
    assert _time_limits(env) == []  # the env truncates itself, once
    env.close()


def test_another_episode_length_reports_its_own_and_truncates_once():
    env = make_env(1, episode_duration_s=0.3)
    assert env.spec.max_episode_steps == env.unwrapped.episode_steps == 30
    assert _truncations(env, 30) == [False] * 29 + [True]
    # the same through gymnasium.make (examine_env --env_args, YAML configs)
    literal = gym.make("MyoExoKnee-v1", episode_duration_s=0.3)
    assert literal.unwrapped.task == env.unwrapped.task == TaskParams(episode_duration_s=0.3)
    assert literal.spec.max_episode_steps == 30 and _time_limits(literal) == []
    # MyoSuite's registry builds the same env
    from myosuite.core.registry import make_env as myosuite_make_env

    ms = myosuite_make_env("MyoExoKnee-v2", episode_duration_s=2.0)
    assert ms.spec.max_episode_steps == 200
    for e in (env, literal, ms):
        e.close()


def test_an_explicit_max_episode_steps_is_gymnasiums_time_limit():
    env = gym.make("MyoExoKnee-v0", max_episode_steps=7)
    assert env.spec.max_episode_steps == 7 and _time_limits(env) == [7]
    assert _truncations(env, 7) == [False] * 6 + [True]
    env.close()


def test_the_spec_changes_no_trajectory():
    """``gymnasium.make`` (spec set) and the bare class (no spec) step the same."""
    from myoexo.envs.knee_exo import MyoExoKneeEnv

    made, bare = gym.make("MyoExoKnee-v3"), MyoExoKneeEnv(spasticity_level=3)
    assert bare.spec is None
    obs = []
    for env in (made, bare):
        o, _ = env.reset(seed=3)
        run = [o]
        for a in np.linspace(-1.0, 0.5, 25, dtype=np.float32):
            run.append(env.step(np.array([a]))[0])
        obs.append(np.array(run))
    np.testing.assert_array_equal(obs[0], obs[1])
    made.close()


# -- MyoSuite's examine_env, as a user runs it ------------------------------------------------


def _examine_env(env_id: str, out_dir, *args: str) -> subprocess.CompletedProcess:
    cmd = [sys.executable, "-m", "myosuite.utils.examine_env", "-e", f"myoexo:{env_id}"]
    cmd += ["-n", "1", "-o", str(out_dir), *args]
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=600)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-4000:]
    return proc


@pytest.mark.slow
@pytest.mark.parametrize("env_id", ["MyoExoKnee-v2", RANDOM_ENV_ID])  # the ids differ in level
def test_examine_env_renders_an_episode_offscreen(env_id, tmp_path):
    """``examine_env -r offscreen``: its horizon is ``spec.max_episode_steps`` of the env
    built with ``--env_args`` (a 5-step task here, to keep the test short)."""
    proc = _examine_env(
        env_id,
        tmp_path,
        "-r",
        "offscreen",
        "-c",
        "leg_three_quarter",
        "-ea",
        "{'episode_duration_s': 0.05}",
    )
    video = tmp_path / "random_policy0.mp4"
    assert video.is_file() and video.stat().st_size > 1000, proc.stdout[-2000:]


def test_examine_env_runs_the_full_default_episode(tmp_path):
    """The default horizon is the env's 800 steps: the saved trace has the 800 steps and
    the final state."""
    _examine_env("MyoExoKnee-v1", tmp_path, "-r", "none", "-sp", "True")
    (trace,) = glob.glob(str(tmp_path / "*_trace.h5"))
    with h5py.File(trace) as f:
        assert f["Trial0/time"].shape == (801,)
        assert f["Trial0/done"][-1] and not f["Trial0/done"][:-1].any()


# -- keyword arguments ------------------------------------------------------------------------


def test_unknown_keyword_argument_raises_pythons_own_type_error():
    from myoexo.envs.knee_exo import MyoExoKneeEnv

    with pytest.raises(TypeError) as exc:
        MyoExoKneeEnv(x=1, y=2)  # type: ignore[call-arg]
    assert str(exc.value) == UNKNOWN_KWARG  # the first one, as Python says it
    # gymnasium.make adds the id and the kwargs after Python's message
    with pytest.raises(TypeError, match=re.escape(UNKNOWN_KWARG)):
        gym.make("MyoExoKnee-v1", x=1)
    with pytest.raises(TypeError, match=re.escape(UNKNOWN_KWARG)):
        make_env(1, x=1)


# -- other RL libraries' env builders ----------------------------------------------------------


def test_sb3_make_vec_env_by_id_with_env_kwargs():
    """stable-baselines3's ``make_vec_env`` tries ``render_mode="rgb_array"`` first (and
    retries without it on a ``TypeError``), wraps each env in a ``Monitor``."""
    from stable_baselines3.common.env_checker import check_env
    from stable_baselines3.common.env_util import make_vec_env

    kwargs = {"reflex": "uniform", "obs_preset": "exo", "episode_duration_s": 0.05}
    venv = make_vec_env("MyoExoKnee-v2", n_envs=2, seed=0, env_kwargs=kwargs)
    assert venv.get_attr("render_mode") == ["rgb_array"] * 2
    assert venv.observation_space.shape == (6 + 12,)
    assert [s.reflex_name for s in venv.get_attr("spasticity")] == ["uniform"] * 2
    venv.reset()
    for _ in range(5):
        _, rewards, dones, infos = venv.step(np.zeros((2, 1), np.float32))
    assert dones.all() and np.isfinite(rewards).all()
    assert [i["episode"]["l"] for i in infos] == [5, 5]
    assert all(i["TimeLimit.truncated"] for i in infos)  # a truncation, not a termination
    check_env(venv.envs[0], warn=True)
    venv.close()
    with pytest.raises(TypeError, match=re.escape(UNKNOWN_KWARG)):
        make_vec_env("MyoExoKnee-v2", n_envs=1, env_kwargs={"x": 1})


def test_gymnasium_make_vec_with_kwargs_autoresets_at_the_episode_length():
    venv = gym.make_vec(
        "MyoExoKnee-v2",
        num_envs=2,
        vectorization_mode="sync",
        episode_duration_s=0.05,
        reflex="uniform",
    )
    venv.reset(seed=[0, 1])
    zeros = np.zeros((2, 1), np.float32)
    for step in range(1, 6):
        _, rewards, terminated, truncated, info = venv.step(zeros)
        assert not terminated.any() and truncated.all() == (step == 5)
    np.testing.assert_allclose(info["time_s"], 0.05)
    _, rewards, _, truncated, info = venv.step(zeros)  # next-step autoreset
    assert (rewards == 0.0).all() and not truncated.any() and (info["time_s"] == 0.0).all()
    venv.close()


def test_rllib_env_runner_builds_the_env_by_id_with_env_config():
    pytest.importorskip("tree", reason="RLlib needs dm-tree")
    ppo = pytest.importorskip("ray.rllib.algorithms.ppo")
    from ray.rllib.env.single_agent_env_runner import SingleAgentEnvRunner

    env_config = {"reflex": "uniform", "episode_duration_s": 0.1}
    config = (
        ppo.PPOConfig()
        .environment("MyoExoKnee-v1", env_config=env_config)
        .env_runners(num_env_runners=0, num_envs_per_env_runner=2)
    )
    runner = SingleAgentEnvRunner(config=config)
    try:
        episodes = runner.sample(num_timesteps=30, random_actions=True)
        done = [e for e in episodes if e.is_done]
        assert done and all(len(e) == 10 and e.is_truncated for e in done)
        base = runner.env.unwrapped.envs[0].unwrapped
        assert base.spasticity.reflex_name == "uniform" and base.episode_steps == 10
    finally:
        runner.stop()
    bad = ppo.PPOConfig().environment("MyoExoKnee-v1", env_config={"x": 1})
    with pytest.raises(TypeError, match=re.escape(UNKNOWN_KWARG)):
        SingleAgentEnvRunner(config=bad.env_runners(num_env_runners=0))
