"""SBX's SAC with the env collecting while the learner updates: ``sbx_sac_overlap``.

An off-policy learner alternates two phases: collect ``train_freq`` vector steps with the
current actor, then run ``gradient_steps`` updates on the replay buffer. In SBX both phases
share one JAX device, whose executions run in order, so the actor's forward pass of every
collected step waits behind the update in flight, and each phase waits for the other.

:class:`OverlappedSAC` lets them run at the same time on two cores:

* the update is dispatched and not waited for (its losses are read, and logged, at the next
  call, when they are done), and the next call samples its batches before it waits for it;
* the env is driven by a numpy copy of the actor (:class:`BehaviourSampler`), taken when
  an update call starts from the parameters the previous call left: the actions of a chunk
  come from the actor one training call before the newest, as in an asynchronous
  actor-learner.

Everything else is SBX's SAC: networks, losses, replay sampling, target updates and
entropy tuning, saved and loaded as an SBX SAC model (``sbx_sac:model.zip`` loads it). The
run is as reproducible as SBX's: the behaviour parameters of every chunk are fixed by the
order of the calls, not by their timing, and its noise comes from a numpy generator seeded
by the run's seed and saved with the model. Only flat ``Box`` observations are supported.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from sbx import SAC
from sbx.common.type_aliases import ReplayBufferSamplesNp

from myoexo.policies.actor import ACTIVATIONS, sbx_actor_layers

#: ``log_std`` clip of SBX's squashed-Gaussian actor.
LOG_STD_RANGE = (-20.0, 2.0)


def update_learning_rates(model: Any) -> None:
    """Set an SBX SAC model's actor and critic learning rates for its progress, as SBX's
    ``SAC.train`` does before its updates."""
    model._update_learning_rate(
        model.policy.actor_state.opt_state,
        learning_rate=model.lr_schedule(model._current_progress_remaining),
        name="learning_rate_actor",
    )
    model._update_learning_rate(
        model.policy.qf_state.opt_state,
        learning_rate=model.initial_qf_learning_rate
        or model.lr_schedule(model._current_progress_remaining),
        name="learning_rate_critic",
    )


def sample_batches(model: Any, gradient_steps: int, batch_size: int) -> ReplayBufferSamplesNp:
    """``gradient_steps`` batches of an SBX SAC model's replay buffer in one draw, as numpy
    arrays in the order its jitted update slices them (SBX's ``SAC.train`` sampling; flat
    ``Box`` observations)."""
    n = batch_size * gradient_steps
    data = model.replay_buffer.sample(n, env=model._vec_normalize_env)
    if isinstance(data.observations, dict):
        raise ValueError("only flat (Box) observations are supported")
    discounts = (
        np.full((n,), model.gamma, dtype=np.float32)
        if data.discounts is None
        else data.discounts.numpy().flatten()
    )
    return ReplayBufferSamplesNp(
        data.observations.numpy(),
        data.actions.numpy(),
        data.next_observations.numpy(),
        data.dones.numpy().flatten(),
        data.rewards.numpy().flatten(),
        discounts,
    )


class BehaviourSampler:
    """The stochastic actor of an SBX SAC policy in numpy: ``tanh(mean + std * noise)``.

    Args:
        layers: ``[(W, b), ...]``, ``W`` of shape (out, in): the hidden layers, then the
            mean head, then the log-std head (:func:`~myoexo.policies.actor.sbx_actor_layers`).
        activation: Hidden activation (a key of :data:`~myoexo.policies.actor.ACTIVATIONS`).
    """

    def __init__(self, layers: list[tuple[np.ndarray, np.ndarray]], activation: str) -> None:
        if len(layers) < 2:
            raise ValueError(f"{len(layers)} layers: need the mean and the log-std heads")
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation = {activation!r}; accepted: {sorted(ACTIVATIONS)}")
        self.hidden = layers[:-2]
        self.mean_head, self.log_std_head = layers[-2], layers[-1]
        self.activation = activation

    def sample(self, obs: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """One action per row of *obs* (observations as the policy sees them), in [-1, 1],
        its Gaussian noise drawn from *rng*."""
        act = ACTIVATIONS[self.activation]
        h = np.asarray(obs, dtype=np.float32)
        for w, b in self.hidden:
            h = act(h @ w.T + b)
        mean = h @ self.mean_head[0].T + self.mean_head[1]
        log_std = np.clip(h @ self.log_std_head[0].T + self.log_std_head[1], *LOG_STD_RANGE)
        noise = rng.standard_normal(mean.shape)
        return np.tanh(mean + np.exp(log_std) * noise).astype(np.float32)


class OverlappedSAC(SAC):
    """SBX's SAC whose env collects while the previous update call runs (module docstring).

    Takes SBX SAC's arguments. Saved models are SBX SAC models with two more attributes:
    ``behaviour`` (the :class:`BehaviourSampler` of the next chunk, ``None`` before the
    first update) and ``behaviour_rng`` (the generator of its noise, the run's one stream).
    """

    def _setup_model(self) -> None:
        super()._setup_model()
        if len(self.observation_space.shape or ()) != 1:
            raise ValueError(
                f"{type(self).__name__} needs a flat Box observation space, got "
                f"{self.observation_space}"
            )
        if not hasattr(self, "behaviour_rng"):  # a loaded model keeps its saved ones
            self.behaviour: BehaviourSampler | None = None
            self.behaviour_rng = np.random.default_rng(self.seed)
        self._pending_losses: tuple[Any, ...] | None = None

    def _excluded_save_params(self) -> list[str]:
        return [*super()._excluded_save_params(), "_pending_losses"]

    def _sample_action(
        self, learning_starts: int, action_noise: Any = None, n_envs: int = 1
    ) -> tuple[np.ndarray, np.ndarray]:
        """SB3's exploration action, from the numpy behaviour actor once one is taken."""
        if self.num_timesteps < learning_starts or self.behaviour is None:
            return super()._sample_action(learning_starts, action_noise, n_envs)
        assert isinstance(self._last_obs, np.ndarray), "a flat Box observation"
        scaled = self.behaviour.sample(self._last_obs, self.behaviour_rng)
        if action_noise is not None:
            scaled = np.clip(scaled + action_noise(), -1.0, 1.0)
        return self.policy.unscale_action(scaled), scaled

    def train(self, gradient_steps: int, batch_size: int) -> None:
        """Sample the call's batches (while the previous call may still run), take the
        behaviour actor from the previous call's parameters (waiting for them), log that
        call's losses, then dispatch ``gradient_steps`` updates without waiting."""
        batch = sample_batches(self, gradient_steps, batch_size)  # while the last call runs
        self.behaviour = BehaviourSampler(*sbx_actor_layers(self.policy))
        self._record_losses()
        update_learning_rates(self)
        self._maybe_reset_params()
        (
            self.policy.qf_state,
            self.policy.actor_state,
            self.ent_coef_state,
            self.key,
            self._pending_losses,
        ) = self._train(
            self.tau,
            self.target_entropy,
            gradient_steps,
            batch,
            self.policy_delay,
            (self._n_updates + 1) % self.policy_delay,
            self.policy.qf_state,
            self.policy.actor_state,
            self.ent_coef_state,
            self.key,
        )
        self._n_updates += gradient_steps
        self.logger.record("train/n_updates", self._n_updates, exclude="tensorboard")

    def _record_losses(self) -> None:
        """Log the losses of the last dispatched update call (waits for it)."""
        if self._pending_losses is None:
            return
        names = ("actor_loss", "critic_loss", "ent_coef_loss", "ent_coef")
        for name, value in zip(names, self._pending_losses, strict=True):
            self.logger.record(f"train/{name}", float(value))
        self._pending_losses = None
