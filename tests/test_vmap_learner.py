"""Seeds trained together (``jax.vmap`` over seeds, ``benchmarks/seed_batched_sac.py``, the
learner ``benchmarks/bench_training.py`` times): the same algorithm as each seed alone."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import numpy as np
import pytest

from myoexo.training import get_preset
from myoexo.training.train import build_model, make_vec_env

_PATH = Path(__file__).resolve().parents[1] / "benchmarks" / "seed_batched_sac.py"
_SPEC = importlib.util.spec_from_file_location("seed_batched_sac", _PATH)
assert _SPEC is not None and _SPEC.loader is not None
_MODULE = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(_MODULE)
SeedBatchedSAC, learn_seed_batched = _MODULE.SeedBatchedSAC, _MODULE.learn_seed_batched


@pytest.fixture(scope="module", autouse=True)
def _needs_sbx():
    """The JAX learners (``myoexo[jax]``); imported when the tests run, not when pytest
    collects them (the import takes seconds, in every pytest-xdist worker)."""
    pytest.importorskip("sbx")


def _models(n: int, **overrides):
    from stable_baselines3.common.logger import configure

    kwargs = dict(train_freq=4, gradient_steps=8, batch_size=32, learning_starts=0)
    preset = get_preset(
        "cpu", algorithm="sbx_sac", n_envs=2, algorithm_kwargs={**kwargs, **overrides}
    )
    out = []
    for seed in range(n):
        venv = make_vec_env(preset, seed)
        model = build_model(preset.replace(seed=seed), venv)
        model.set_logger(configure(None, []))
        rng = np.random.default_rng(seed)
        obs = venv.reset()
        for _ in range(40):
            action = rng.uniform(-1.0, 1.0, (preset.n_envs, 1)).astype(np.float32)
            new_obs, reward, done, infos = venv.step(action)
            model.replay_buffer.add(obs, new_obs, action, reward, done, infos)
            obs = new_obs
        out.append(model)
    return out


def _leaves(model):
    import jax

    return [
        np.asarray(x)
        for x in jax.tree_util.tree_leaves(
            (
                model.policy.actor_state.params,
                model.policy.qf_state.params,
                model.ent_coef_state.params,
            )
        )
    ]


def test_a_seed_in_a_batch_updates_as_it_does_alone():
    models = _models(2)
    saved = [(m.policy.qf_state, m.policy.actor_state, m.ent_coef_state, m.key) for m in models]
    np.random.seed(3)  # noqa: NPY002 (the replay buffers sample with numpy's global generator)
    models[0].train(gradient_steps=8, batch_size=32)
    alone = _leaves(models[0])
    for m, (qf, actor, ent, key) in zip(models, saved, strict=True):
        m.policy.qf_state, m.policy.actor_state, m.ent_coef_state, m.key = qf, actor, ent, key
    np.random.seed(3)  # noqa: NPY002 (model 0 samples first in the batch, so it draws the same batches)
    SeedBatchedSAC(models).train(8, 32)
    together = _leaves(models[0])
    assert len(alone) == len(together)
    for a, b in zip(alone, together, strict=True):
        np.testing.assert_allclose(a, b, atol=1e-5)
    assert models[0]._n_updates == 16 and models[1]._n_updates == 8
    # the other seed moved too, and differently (its own data and key)
    assert not all(np.allclose(a, b) for a, b in zip(_leaves(models[1]), together, strict=True))


def test_learn_collects_for_every_seed_and_trains_them_together():
    models = _models(2)
    before = [m.num_timesteps for m in models]
    learn_seed_batched(SeedBatchedSAC(models), 16)
    assert [m.num_timesteps - b for m, b in zip(models, before, strict=True)] == [16, 16]
    assert [m._n_updates for m in models] == [16, 16]  # 2 rollouts of 8 steps, 8 updates each


def test_batch_refuses_models_that_differ():
    a = _models(1)[0]
    b = _models(1, gradient_steps=4)[0]
    with pytest.raises(ValueError, match="gradient_steps"):
        SeedBatchedSAC([a, b])
    with pytest.raises(ValueError, match="at least one"):
        SeedBatchedSAC([])
