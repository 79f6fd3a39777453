"""Several seeds' SAC updates in one compiled call: ``jax.vmap`` over seeds.

One SBX SAC update of the ``cpu`` preset multiplies matrices 64 wide over a batch of 256:
products too small to fill a core's vector units, so the update runs at about half of the
core's arithmetic limit (``benchmarks/bench_training.py``). Training several seeds of one
configuration, as every result here does (five seeds, intervals over seeds), gives the
products a seed axis for free: :class:`SeedBatchedSAC` stacks the seeds' network, optimizer
and entropy states along a leading axis and runs SBX's own compiled update loop
(``SAC._train``, ``gradient_steps`` updates in a ``fori_loop``) under ``jax.vmap``, so one
call performs ``gradient_steps`` updates of every seed. Each seed keeps its own replay
buffer, observation normalization, random key and env; only the arithmetic is shared.

The result is the same algorithm: a seed's update reads only its own slice of every array
(``tests/test_vmap_learner.py`` checks that one seed trained in a batch equals the same
seed trained alone, to float32 round-off).

:func:`learn_seed_batched` is SB3's off-policy ``learn`` loop for several models at once:
each model collects its ``train_freq`` vector steps with its current actor, then one batched
call trains them all.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


class SeedBatchedSAC:
    """Gradient updates of several SBX SAC models (one per seed) in one jitted call.

    Args:
        models: SBX ``SAC`` models of one configuration (same networks, batch size,
            ``gradient_steps``, ``tau``, ``gamma``, ``policy_delay`` and target entropy);
            their replay buffers must hold data before :meth:`train`.

    Raises:
        ValueError: No model, a model that is not SBX SAC, or models whose configurations
            differ (the message names the field).
    """

    #: Fields that must agree across the models (they are compiled into the update).
    SHARED_FIELDS = ("batch_size", "gradient_steps", "tau", "gamma", "policy_delay")

    def __init__(self, models: Sequence[Any]) -> None:
        import jax
        from sbx import SAC

        if not models:
            raise ValueError("SeedBatchedSAC needs at least one model")
        for m in models:
            if not isinstance(m, SAC):
                raise ValueError(f"SeedBatchedSAC trains SBX SAC models, got {type(m).__name__}")
        first = models[0]
        for name in self.SHARED_FIELDS:
            values = [getattr(m, name) for m in models]
            if any(v != values[0] for v in values):
                raise ValueError(f"the models' {name} differ ({values}); one batch needs one")
        entropies = [float(np.asarray(m.target_entropy)) for m in models]
        if any(e != entropies[0] for e in entropies):
            raise ValueError(f"the models' target_entropy differ ({entropies})")
        self.models = list(models)
        self._cls = type(first)
        self._tau = float(first.tau)
        self._target_entropy = np.asarray(first.target_entropy, dtype=np.float32)
        self._jax = jax
        self._compiled: dict[tuple[int, int], Any] = {}

    @property
    def n_seeds(self) -> int:
        """Models trained together."""
        return len(self.models)

    def _function(self, gradient_steps: int, offset: int) -> Any:
        key = (gradient_steps, offset)
        if key not in self._compiled:
            jax = self._jax
            cls, tau, entropy = self._cls, self._tau, self._target_entropy
            delay = int(self.models[0].policy_delay)

            def one_seed(data: Any, qf: Any, actor: Any, ent: Any, rng: Any) -> Any:
                return cls._train(
                    tau, entropy, gradient_steps, data, delay, offset, qf, actor, ent, rng
                )

            self._compiled[key] = jax.jit(jax.vmap(one_seed))
        return self._compiled[key]

    def train(self, gradient_steps: int, batch_size: int | None = None) -> None:
        """``gradient_steps`` updates of every model, in one compiled call.

        Each model samples its own batches from its own replay buffer, with its own
        normalization; its states and key are written back to it.
        """
        from sbx.common.type_aliases import ReplayBufferSamplesNp

        from myoexo.policies.overlapped_sac import sample_batches, update_learning_rates

        jax = self._jax
        batch_size = int(batch_size or self.models[0].batch_size)
        first = self.models[0]
        offset = int((first._n_updates + 1) % first.policy_delay)
        for m in self.models:
            update_learning_rates(m)
        samples = [sample_batches(m, gradient_steps, batch_size) for m in self.models]
        data = ReplayBufferSamplesNp(*(np.stack(parts) for parts in zip(*samples, strict=True)))
        qf, actor, ent, rng = (
            _stack([getattr_path(m, path) for m in self.models])
            for path in ("policy.qf_state", "policy.actor_state", "ent_coef_state", "key")
        )
        qf, actor, ent, rng, infos = self._function(gradient_steps, offset)(
            data, qf, actor, ent, rng
        )
        actor_loss, qf_loss, ent_loss, ent_value = (np.asarray(x) for x in infos)
        for i, m in enumerate(self.models):
            m.policy.qf_state = _index(qf, i)
            m.policy.actor_state = _index(actor, i)
            m.ent_coef_state = _index(ent, i)
            m.key = rng[i]
            m._n_updates += gradient_steps
            m.logger.record("train/n_updates", m._n_updates, exclude="tensorboard")
            m.logger.record("train/actor_loss", float(actor_loss[i]))
            m.logger.record("train/critic_loss", float(qf_loss[i]))
            m.logger.record("train/ent_coef_loss", float(ent_loss[i]))
            m.logger.record("train/ent_coef", float(ent_value[i]))
        jax.block_until_ready(self.models[-1].policy.actor_state.params)


def learn_seed_batched(
    batch: SeedBatchedSAC, total_timesteps: int, callbacks: Sequence[Any] | None = None
) -> None:
    """SB3's off-policy ``learn`` for every model of *batch*, with batched updates.

    Each model collects its ``train_freq`` with its own env and actor (SB3's
    ``collect_rollouts``: random actions before ``learning_starts``, replay, normalization),
    then, once every model is past ``learning_starts``, one :meth:`SeedBatchedSAC.train`
    call runs ``gradient_steps`` updates of each. Stops when every model has
    ``total_timesteps`` transitions (counted from its current ``num_timesteps``), or when
    a callback asks to.

    Args:
        batch: The models and their batched update.
        total_timesteps: Transitions per model to collect in this call.
        callbacks: One SB3 callback (or ``None``) per model.
    """
    models = batch.models
    callbacks = list(callbacks) if callbacks is not None else [None] * len(models)
    if len(callbacks) != len(models):
        raise ValueError(f"{len(callbacks)} callbacks for {len(models)} models")
    setups = [
        m._setup_learn(total_timesteps, cb, reset_num_timesteps=False, tb_log_name="run")
        for m, cb in zip(models, callbacks, strict=True)
    ]
    totals = [total for total, _ in setups]
    cbs = [cb for _, cb in setups]
    for cb in cbs:
        cb.on_training_start(locals(), globals())
    go = True
    while go and any(m.num_timesteps < t for m, t in zip(models, totals, strict=True)):
        for m, cb in zip(models, cbs, strict=True):
            rollout = m.collect_rollouts(
                m.env,
                train_freq=m.train_freq,
                action_noise=m.action_noise,
                callback=cb,
                learning_starts=m.learning_starts,
                replay_buffer=m.replay_buffer,
                log_interval=None,
            )
            go = go and rollout.continue_training
        if go and all(m.num_timesteps > m.learning_starts for m in models):
            batch.train(int(models[0].gradient_steps), int(models[0].batch_size))
    for cb in cbs:
        cb.on_training_end()


def getattr_path(obj: Any, path: str) -> Any:
    """``obj.a.b`` for ``path = "a.b"``."""
    for name in path.split("."):
        obj = getattr(obj, name)
    return obj


def _stack(trees: Sequence[Any]) -> Any:
    """The trees' leaves stacked along a new leading axis (the first tree's structure: the
    static fields, e.g. ``apply_fn`` and the optimizer, are the same for every seed)."""
    import jax
    import jax.numpy as jnp

    leaves = [jax.tree_util.tree_leaves(t) for t in trees]
    treedef = jax.tree_util.tree_structure(trees[0])
    return jax.tree_util.tree_unflatten(
        treedef, [jnp.stack(parts) for parts in zip(*leaves, strict=True)]
    )


def _index(tree: Any, i: int) -> Any:
    """Seed *i*'s slice of a stacked tree."""
    import jax

    return jax.tree_util.tree_map(lambda x: x[i], tree)
