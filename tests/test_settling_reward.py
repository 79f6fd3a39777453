"""The hindsight settling reward of a training run (``settling_penalty``,
``myoexo.training.callbacks.SettlingRewardCallback``)."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from myoexo.evaluation.metrics import settling_time
from myoexo.runtime.fields import FieldError
from myoexo.training import get_preset
from myoexo.training.callbacks import SettlingRewardCallback
from myoexo.training.train import build_model, make_vec_env


def test_settling_steps_count_the_control_steps_before_the_paper_settling_time():
    t = 0.01 * np.arange(1, 201)
    errors = 78.0 * np.exp(-t / 0.2) + 5.0  # settles at 0.2 ln(50) ~ 0.78 s
    steps = SettlingRewardCallback(1.0).settling_steps(list(t), list(errors))
    ts = settling_time(t, errors, y_final=float(np.mean(errors[t >= t[-1] - 0.1 - 1e-12])))
    assert 0.75 < ts < 0.82
    assert steps == int(np.sum(t < ts - 1e-9))
    oscillating = 5.0 + 10.0 * np.sin(40.0 * t)  # ends outside its band: never settled
    assert SettlingRewardCallback(1.0).settling_steps(list(t), list(oscillating)) == t.size


def test_the_penalty_must_be_positive_and_needs_an_off_policy_learner():
    with pytest.raises(ValueError, match="penalty = -1"):
        SettlingRewardCallback(-1.0)
    with pytest.raises(ValueError, match="nothing to relabel"):
        SettlingRewardCallback(0.0)
    with pytest.raises(FieldError, match="settling_penalty"):
        get_preset("ppo", settling_penalty=1.0)
    with pytest.raises(FieldError, match="torque_until_settling"):
        get_preset("ppo", torque_until_settling=True)


def _stored_rewards(penalty: float) -> tuple[np.ndarray, np.ndarray]:
    """Rewards and done flags stored by 120 vector steps of random actions (no update)."""
    from stable_baselines3.common.logger import configure

    preset = get_preset(
        "cpu", n_envs=2, episode_duration_s=0.3, algorithm_kwargs={"learning_starts": 10_000}
    )
    venv = make_vec_env(preset, 0)
    model = build_model(preset, venv)
    model.set_logger(configure(None, []))
    callback = SettlingRewardCallback(penalty) if penalty else None
    model.learn(240, callback=callback)
    size = model.replay_buffer.size()
    return model.replay_buffer.rewards[:size].copy(), model.replay_buffer.dones[:size].copy()


def test_each_ended_episode_is_charged_on_a_prefix_of_its_steps():
    """Against the same run without it: the stored rewards differ by -penalty on the first
    steps of each ended episode, by nothing elsewhere."""
    plain, dones = _stored_rewards(0.0)
    charged, _ = _stored_rewards(0.5)
    diff = np.round(charged.astype(np.float64) - plain, 5)  # float32 rewards
    assert set(np.unique(diff)) <= {0.0, -0.5}
    assert np.any(diff != 0.0)
    for i in range(diff.shape[1]):
        ends = np.flatnonzero(dones[:, i])
        assert ends.size >= 2
        start = 0
        for end in ends:
            episode = diff[start : end + 1, i] != 0.0
            n = int(episode.sum())
            assert episode[:n].all() and not episode[n:].any()  # a prefix
            start = end + 1
        assert not np.any(diff[start:, i])  # the running episode is not charged yet
    assert math.isfinite(float(charged.sum()))


@pytest.mark.parametrize("penalty", [0.0, 2.0])
def test_the_torque_terms_are_refunded_from_the_settling_time_on(penalty):
    """Driven as SB3's collection drives it (the callback sees each step before its
    transition is stored): an episode that settles at 0.78 s gets back ``-w_inter x inter +
    gentleness x gentle`` on each step from then on, and ``-penalty`` before; the next
    episode, not yet ended, nothing."""
    t = 0.01 * np.arange(1, 201)
    errors = 78.0 * np.exp(-t / 0.2) + 5.0
    buffer = SimpleNamespace(rewards=np.zeros((260, 1), np.float32), pos=3, buffer_size=260)
    callback = SettlingRewardCallback(penalty, torque_until_settling=True)
    env = SimpleNamespace(num_envs=1, get_attr=lambda name: [{"inter": -0.1}])
    callback.model = SimpleNamespace(replay_buffer=buffer, get_env=lambda: env)
    callback._on_training_start()
    rng = np.random.default_rng(0)
    inter, gentle = rng.uniform(0, 1, 250), rng.uniform(0, 1, 250)
    for k in range(250):  # one episode of 200 steps, then 50 of the next
        info = {"time_s": t[k % 200], "error_deg": errors[k % 200], "inter": inter[k]}
        info.update(gentle=gentle[k], gentleness=0.4)
        callback.locals = {"dones": [k == 199], "infos": [info]}
        callback._on_step()
        buffer.pos += 1
    callback._on_rollout_end()
    settled = callback.settling_steps(list(t), list(errors))
    assert 70 < settled < 85
    expected = np.zeros(260)
    expected[3 : 3 + settled] = -penalty
    rows = np.arange(3 + settled, 203)
    expected[rows] = 0.4 * gentle[rows - 3] + 0.1 * inter[rows - 3]
    np.testing.assert_allclose(buffer.rewards[:, 0], expected, atol=1e-6)
