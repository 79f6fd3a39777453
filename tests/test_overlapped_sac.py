"""``sbx_sac_overlap``: SBX's SAC whose env collects with a numpy copy of the actor while the
update call runs (``myoexo/policies/overlapped_sac.py``)."""

from __future__ import annotations

import numpy as np
import pytest

from myoexo.training import get_preset
from myoexo.training.train import build_model, make_vec_env


@pytest.fixture(scope="module", autouse=True)
def _needs_sbx():
    """The JAX learners (``myoexo[jax]``), imported when the tests run."""
    pytest.importorskip("sbx")


def _model(algorithm: str = "sbx_sac_overlap", seed: int = 0, **overrides):
    from stable_baselines3.common.logger import configure

    kwargs = dict(train_freq=4, gradient_steps=8, batch_size=32, learning_starts=40)
    preset = get_preset(
        "cpu", algorithm=algorithm, n_envs=2, algorithm_kwargs={**kwargs, **overrides}
    )
    venv = make_vec_env(preset, seed)
    model = build_model(preset.replace(seed=seed), venv)
    model.set_logger(configure(None, []))
    return model


def _layers(model):
    from myoexo.policies.actor import sbx_actor_layers

    return sbx_actor_layers(model.policy)[0]


class _ConstantNoise:
    """A stand-in generator whose 'standard normal' draws are all *value*."""

    def __init__(self, value: float) -> None:
        self.value = value

    def standard_normal(self, shape):
        return np.full(shape, self.value)


@pytest.mark.parametrize("noise", [0.0, 1.0, -2.0])
def test_the_behaviour_sampler_draws_from_the_jax_actors_distribution(noise):
    """With the noise held at a value, the numpy sampler gives tanh(mean + noise x std) of
    the JAX actor's own squashed Gaussian."""
    from myoexo.policies.actor import sbx_actor_layers
    from myoexo.policies.overlapped_sac import BehaviourSampler

    model = _model()
    rng = np.random.default_rng(3)
    obs = rng.standard_normal((6, model.observation_space.shape[0])).astype(np.float32)
    dist = model.policy.actor_state.apply_fn(model.policy.actor_state.params, obs)
    mean = np.asarray(dist.distribution.loc)
    std = np.asarray(dist.distribution.stddev())
    expected = np.tanh(mean + noise * std)
    sampler = BehaviourSampler(*sbx_actor_layers(model.policy))
    np.testing.assert_allclose(sampler.sample(obs, _ConstantNoise(noise)), expected, atol=1e-5)
    if noise == 0.0:  # the deterministic action of the JAX policy
        jax_action, _ = model.predict(obs, deterministic=True)
        np.testing.assert_allclose(sampler.sample(obs, _ConstantNoise(0.0)), jax_action, atol=1e-5)


def test_each_chunk_is_collected_with_the_actor_one_update_call_before():
    """An update call takes the behaviour actor from the parameters the previous call left,
    then changes the parameters without waiting; the losses of a call are logged at the
    next one."""
    model = _model()
    model.learn(60)  # past learning_starts: the buffer holds transitions, updates have run
    for _ in range(2):
        before = _layers(model)
        model.train(gradient_steps=8, batch_size=32)
        behaviour = model.behaviour
        assert behaviour is not None
        for (w, b), (wb, bb) in zip(
            before, [*behaviour.hidden, behaviour.mean_head, behaviour.log_std_head], strict=True
        ):
            np.testing.assert_array_equal(w, wb)
            np.testing.assert_array_equal(b, bb)
        after = _layers(model)
        assert any(not np.array_equal(w, wa) for (w, _), (wa, _) in zip(before, after, strict=True))
    logged = model.logger.name_to_value
    assert {"train/actor_loss", "train/critic_loss", "train/ent_coef"} <= set(logged)
    assert all(np.isfinite(logged[k]) for k in ("train/actor_loss", "train/critic_loss"))


def test_same_seed_same_transitions_and_parameters():
    """The chunks' behaviour parameters follow the order of the calls, not their timing:
    two runs of one seed collect the same transitions and end with the same network."""
    runs = []
    for _ in range(2):
        model = _model(seed=4)
        model.learn(120)
        size = model.replay_buffer.size()
        runs.append((model.replay_buffer.actions[:size].copy(), _layers(model)))
    np.testing.assert_array_equal(runs[0][0], runs[1][0])
    for (w0, b0), (w1, b1) in zip(runs[0][1], runs[1][1], strict=True):
        np.testing.assert_array_equal(w0, w1)
        np.testing.assert_array_equal(b0, b1)
    assert model.behaviour is not None  # the numpy actor collected past the warm-up
    assert len(np.unique(runs[0][0][20:])) > 10  # rows of 2 envs after 40 transitions


def test_a_saved_model_keeps_its_behaviour_actor_and_noise_and_loads_as_sbx_sac(tmp_path):
    from sbx import SAC

    from myoexo.policies.overlapped_sac import OverlappedSAC

    model = _model()
    model.learn(80)
    model.save(tmp_path / "model.zip")
    loaded = OverlappedSAC.load(tmp_path / "model.zip", device="cpu")
    assert loaded.behaviour is not None
    np.testing.assert_array_equal(loaded.behaviour.mean_head[0], model.behaviour.mean_head[0])
    assert loaded.behaviour_rng.bit_generator.state == model.behaviour_rng.bit_generator.state
    obs = np.zeros((1, model.observation_space.shape[0]), np.float32)
    plain = SAC.load(tmp_path / "model.zip", device="cpu")
    np.testing.assert_allclose(
        plain.predict(obs, deterministic=True)[0], model.predict(obs, deterministic=True)[0]
    )


def test_a_nested_observation_space_is_refused():
    import gymnasium as gym
    from gymnasium import spaces
    from stable_baselines3.common.env_util import make_vec_env as sb3_vec_env

    from myoexo.policies.overlapped_sac import OverlappedSAC

    class _GridEnv(gym.Env):
        observation_space = spaces.Box(-1.0, 1.0, (2, 3), np.float32)
        action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

        def reset(self, *, seed=None, options=None):
            return np.zeros((2, 3), np.float32), {}

        def step(self, action):
            return np.zeros((2, 3), np.float32), 0.0, False, False, {}

    with pytest.raises(ValueError, match="flat Box observation space"):
        OverlappedSAC("MlpPolicy", sb3_vec_env(_GridEnv, n_envs=1), device="cpu")


def test_an_update_call_is_sbx_sacs_update():
    """Given the same network, replay buffer and batches, one update call of the overlapped
    learner leaves the parameters SBX's SAC leaves."""
    import jax

    models = [_model("sbx_sac", seed=2), _model("sbx_sac_overlap", seed=2)]
    rng = np.random.default_rng(2)
    venv = models[0].get_env()
    obs = venv.reset()
    for _ in range(40):
        action = rng.uniform(-1.0, 1.0, (venv.num_envs, 1)).astype(np.float32)
        new_obs, reward, done, infos = venv.step(action)
        for model in models:
            model.replay_buffer.add(obs, new_obs, action, reward, done, infos)
        obs = new_obs
    leaves = []
    for model in models:
        model._vec_normalize_env = None  # the batches as stored: one env stepped both buffers
        np.random.seed(7)  # noqa: NPY002 - SB3's replay buffer samples from the global one
        model.train(gradient_steps=8, batch_size=32)
        leaves.append(
            jax.tree_util.tree_leaves(
                (model.policy.actor_state.params, model.policy.qf_state.params)
            )
        )
    for plain, overlapped in zip(*leaves, strict=True):
        np.testing.assert_array_equal(np.asarray(plain), np.asarray(overlapped))
