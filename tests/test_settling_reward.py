"""The hindsight settling reward of a training run (``settling_penalty``,
``myoexo.training.callbacks.SettlingRewardCallback``)."""

from __future__ import annotations

import math

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
    with pytest.raises(ValueError, match="penalty = 0"):
        SettlingRewardCallback(0.0)
    with pytest.raises(FieldError, match="settling_penalty"):
        get_preset("ppo", settling_penalty=1.0)


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
