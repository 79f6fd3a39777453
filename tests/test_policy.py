"""The shipped SAC policy (``myoexo.load_policy("sac")``) and the numpy actor
they are made of."""

from __future__ import annotations

import itertools
import socket

import numpy as np
import pytest

from myoexo.model import TwinParams
from myoexo.policies import (
    SHIPPED_POLICIES,
    MLPActor,
    load_actor,
    load_policy,
    save_actor,
    shipped_path,
)


@pytest.fixture
def no_network(monkeypatch):
    """Any attempt to open a socket fails."""

    def refuse(*args, **kwargs):
        raise OSError("network access is disabled in this test")

    monkeypatch.setattr(socket, "socket", refuse)
    monkeypatch.setattr(socket, "create_connection", refuse)


def _fixed_obs(policy: MLPActor) -> np.ndarray:
    rng = np.random.default_rng(123)
    z = rng.standard_normal((5, policy.obs_dim))
    return (policy.obs_mean + np.sqrt(policy.obs_var) * z).astype(np.float32)


# ---------------------------------------------------------------------------- shipped
#: The shipped SAC actors (``student_exo`` wraps an actor in a memory: tests/test_distill.py).
SAC_POLICIES = sorted(n for n in SHIPPED_POLICIES if n.startswith("sac"))


@pytest.mark.parametrize("name", SAC_POLICIES)
def test_shipped_policy_loads_offline_and_is_small(no_network, name):
    policy = load_policy(name)
    assert isinstance(policy, MLPActor)
    assert policy.action_dim == 1 and policy.activation == "gelu"
    assert [w.shape[0] for w, _ in policy.weights[:-1]] == [64, 64]  # the paper's actor
    npz = shipped_path(name).with_suffix(".npz")
    assert npz.stat().st_size < 100_000
    keys = ("env_id", "preset", "seed", "num_timesteps", "obs_keys", "obs_preset")
    for key in (*keys, "selection_root_seed", "reward_weights"):
        assert policy.metadata.get(key) is not None, key
    assert policy.obs_preset == "full"
    from myoexo.policies.algorithms import get_algorithm

    assert get_algorithm(policy.metadata["algorithm"]).class_name == "SAC"  # torch or JAX


def test_shipped_policy_actions_are_stable(no_network):
    a, b = load_policy(), load_policy()
    obs = _fixed_obs(a)
    first = a(obs)
    np.testing.assert_array_equal(first, a(obs))  # same object, repeated calls
    np.testing.assert_array_equal(first, b(obs))  # a fresh load
    assert a.check_reference() < 1e-5  # equal to the SB3 policy's actions at export time
    assert first.shape == (5, 1) and np.all(np.abs(first) <= 1.0)
    action, state = a.predict(obs[0], deterministic=True)
    assert action.shape == (1,) and state is None
    np.testing.assert_array_equal(action, first[0])


@pytest.mark.parametrize("name", SAC_POLICIES)
def test_shipped_policy_fits_the_env(name):
    import gymnasium as gym

    import myoexo

    policy = myoexo.load_policy(name)
    env = gym.make(policy.metadata["env_id"], obs_preset=policy.obs_preset)
    try:
        assert env.observation_space.shape == (policy.obs_dim,)
        assert list(env.unwrapped.obs_keys) == policy.metadata["obs_keys"]
    finally:
        env.close()


@pytest.mark.slow
@pytest.mark.parametrize(("name", "tolerance_deg"), [("sac", 3.0)])
def test_shipped_policy_extends_the_knee_at_level_1(name, tolerance_deg):
    """One full 8-s episode: each shipped policy brings the knee from 90 deg near 7 deg"""
    import gymnasium as gym

    import myoexo

    policy = myoexo.load_policy(name)
    env = gym.make("MyoExoKnee-v1", obs_preset=policy.obs_preset)
    obs, info = env.reset(seed=11)
    start_error = info["error_deg"]
    done = False
    while not done:
        obs, _, terminated, truncated, info = env.step(policy(obs))
        done = terminated or truncated
    env.close()
    assert start_error > 75.0
    assert not info["unstable"]
    assert abs(info["error_deg"]) < tolerance_deg


def test_shipped_policy_rejects_bad_input():
    policy = load_policy()
    with pytest.raises(ValueError, match="observation of shape"):
        policy(np.zeros(policy.obs_dim + 1))
    with pytest.raises(ValueError, match="deterministic"):
        policy.predict(np.zeros(policy.obs_dim), deterministic=False)
    with pytest.raises(FileNotFoundError, match="accepted"):
        load_policy("no_such_policy")


# ---------------------------------------------------------------------------- the actor
def _random_actor(rng, obs_dim=6, hidden=(8, 8), activation="gelu", norm=True) -> MLPActor:
    sizes = [obs_dim, *hidden, 1]
    weights = [
        (rng.standard_normal((o, i)), rng.standard_normal(o)) for i, o in itertools.pairwise(sizes)
    ]
    stats = {"obs_mean": rng.standard_normal(obs_dim), "obs_var": rng.uniform(0.1, 4, obs_dim)}
    return MLPActor(weights, activation, **(stats if norm else {}), clip_obs=2.0)


@pytest.mark.parametrize("activation", ["gelu", "relu", "tanh", "elu"])
@pytest.mark.parametrize("norm", [True, False])
def test_numpy_actor_equals_its_torch_module(activation, norm):
    import torch

    rng = np.random.default_rng(0)
    actor = _random_actor(rng, activation=activation, norm=norm)
    obs = rng.normal(0, 5, (32, actor.obs_dim))  # beyond the clip: exercises it
    with torch.no_grad():
        expected = actor.to_torch()(torch.as_tensor(obs, dtype=torch.float32)).numpy()
    np.testing.assert_allclose(actor(obs), expected, atol=2e-5)


def test_actor_normalization_clips_like_vecnormalize():
    rng = np.random.default_rng(1)
    actor = _random_actor(rng)
    obs = actor.obs_mean + 100.0 * np.sqrt(actor.obs_var)  # 100 std away
    np.testing.assert_allclose(actor.normalize(obs), 2.0, rtol=1e-6)


def test_actor_file_round_trip(tmp_path):
    rng = np.random.default_rng(2)
    actor = _random_actor(rng)
    actor.metadata["reference"] = {
        "observations": rng.standard_normal((3, actor.obs_dim)).tolist(),
        "actions": [],
    }
    actor.metadata["reference"]["actions"] = actor(
        np.asarray(actor.metadata["reference"]["observations"])
    ).tolist()
    save_actor(actor, tmp_path / "x")
    back = load_actor(tmp_path / "x.npz")
    obs = rng.standard_normal((4, actor.obs_dim))
    np.testing.assert_allclose(back(obs), actor(obs), atol=1e-5)  # float32 weights on disk
    assert back.check_reference() < 1e-5
    # an edited weight file no longer matches its reference actions
    with np.load(tmp_path / "x.npz") as data:
        arrays = {k: data[k] for k in data.files}
    arrays["layer0.bias"] = arrays["layer0.bias"] + 1.0
    np.savez(tmp_path / "x.npz", **arrays)
    with pytest.raises(ValueError, match="differs from its reference"):
        load_actor(tmp_path / "x").check_reference()


def test_actor_rejects_inconsistent_weights():
    rng = np.random.default_rng(3)
    with pytest.raises(ValueError, match="do not match"):
        MLPActor([(rng.standard_normal((4, 3)), rng.standard_normal(5))])
    with pytest.raises(ValueError, match="input width"):
        MLPActor([(np.ones((4, 3)), np.ones(4)), (np.ones((1, 5)), np.ones(1))])
    with pytest.raises(ValueError, match="activation"):
        MLPActor([(np.ones((1, 3)), np.ones(1))], activation="swish")
    with pytest.raises(ValueError, match="obs_mean"):
        MLPActor([(np.ones((1, 3)), np.ones(1))], obs_mean=np.zeros(3))


def test_the_shipped_sac_records_its_seeds_and_the_ship_rule():
    """The full-state policy is one of several seeds, shipped by a rule that does not pick
    the luckiest (``myoexo policy seeds ship``); its metadata says which and why."""
    policy = load_policy("sac")
    seeds = policy.metadata["training_seeds"]
    assert len(seeds) >= 5 and policy.metadata["ship_seed"] in seeds
    assert "closest" in policy.metadata["ship_rule"]
    assert policy.selection_root_seed == 1


#: What each shipped policy's model card claims on every evaluation subject it was tested on:
#: the levels where its mean final error is below 1 deg (the study's bound). `sac` (seed 2
#: of the five-seed set) misses it at level 1 on the evaluation root (its card's table);
#: `student_exo` meets it at levels 0-1.
ACCURATE_LEVELS = {"sac": (0,), "student_exo": (0, 1)}

#: The twin the shipped policies were trained on: twin version 1 (their metadata records no
#: version). On version 2 they end 1.3 (sac) and 4.6 deg (student_exo) short at level 0 on
#: these subjects; they are retrained on it by the controller work.
TRAINED_TWIN = {"twin": TwinParams.of_version(1)}


@pytest.fixture(scope="module")
def pid_tables():
    """``(level, reflex) -> table`` of the paper's PID on three evaluation subjects of the
    twin the shipped policies were trained on, each evaluated once for the module (the
    policies that record the same twin share it)."""
    from myoexo.control import PID
    from myoexo.envs import TaskParams
    from myoexo.evaluation import evaluate_controller

    tables: dict = {}

    def table(level, reflex):
        key = (level, repr(reflex))
        if key not in tables:
            pid = PID(dt_s=TaskParams().control_period_s)
            twin = {**TRAINED_TWIN, "reflex": reflex}
            tables[key], _ = evaluate_controller(pid, level, 3, 0, label="pid", env_kwargs=twin)
        return tables[key]

    return table


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(ACCURATE_LEVELS))
def test_the_shipped_policies_headline_criteria_against_the_pid_on_a_few_subjects(name, pid_tables):
    """Three evaluation subjects per level, full 8-s episodes, the paper's PID on the same
    subjects: the documented headline of each policy, not a tolerance fitted to one run.
    Each reaches the target (< 1 deg) where its card says it does, neither ends beyond the
    failure bound of 20 deg on any of these subjects, and both hold a lower peak interaction
    torque than the PID at every level: on the twin they were trained on."""
    from myoexo.evaluation import evaluate_controller
    from myoexo.spasticity import StretchCalibration, StretchReflex

    policy = load_policy(name)
    # the twin it was trained on: version 1 and the stretch reflex with its recorded calibration
    recorded = policy.metadata["twin"]["reflex_parameters"]
    assert policy.metadata["twin"]["reflex"] == "stretch"
    reflex = StretchReflex(
        delay_s=recorded["delay_s"],
        calibration=StretchCalibration.from_dict(recorded["calibration"]),
    )
    trained = {**TRAINED_TWIN, "reflex": reflex}
    for level in range(4):
        mine, _ = evaluate_controller(policy, level, 3, 0, label=name, env_kwargs=trained)
        base = pid_tables(level, reflex)
        assert (mine["abs_final_error_deg"] < 20.0).all(), (level, mine["abs_final_error_deg"])
        if level in ACCURATE_LEVELS[name]:
            assert mine["abs_final_error_deg"].mean() < 1.0, level
        assert (
            mine["peak_interaction_torque_nm"].mean() < base["peak_interaction_torque_nm"].mean()
        ), level
