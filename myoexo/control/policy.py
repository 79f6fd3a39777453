"""Adapters that turn learned policies into :class:`~myoexo.control.protocol.Controller`.

* :class:`SB3Controller`: any stable-baselines3 model (or anything with SB3's
  ``predict(obs, deterministic=...) -> (action, state)``), e.g. ``SAC.load("model.zip")``.
* :class:`CallableController`: any ``callable(obs) -> action`` (a torch module wrapper, an
  ONNX session wrapper, a hand-written law).
* :class:`ConstantController`: one command held for the whole episode (the rest and
  strap-lag measurements).
* :func:`as_controller`: picks the right one.
* :class:`GentleController`: a policy trained over the gentleness range (the env's
  ``gentleness=``) at one weight, which it appends to the observation.

All of them act on the observation alone (the sensor record is not read; they declare no
sensors) and return a float32 array of shape ``(1,)`` clipped to the action bounds [-1, 1];
a NaN / non-finite action raises ``ValueError`` naming the controller.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from myoexo.control.protocol import Controller
from myoexo.envs.sensors import Measurements

#: Bounds of the normalized exo command.
ACTION_LOW, ACTION_HIGH = -1.0, 1.0


def _to_action(raw: Any, who: str) -> np.ndarray:
    a = np.asarray(raw, dtype=np.float32).reshape(-1)
    if a.size != 1:
        raise ValueError(f"{who} returned an action of shape {np.shape(raw)}; expected (1,)")
    if not np.isfinite(a).all():
        raise ValueError(f"{who} returned a non-finite action {a.tolist()}")
    return np.clip(a, ACTION_LOW, ACTION_HIGH)


class CallableController:
    """Wrap ``fn(obs) -> action`` (stateless) as a controller.

    Args:
        fn: Maps the observation vector to an action (any array-like of size 1).
        name: Label used in error messages and tables.
    """

    def __init__(self, fn: Callable[[np.ndarray], Any], name: str | None = None) -> None:
        if not callable(fn):
            raise ValueError(f"CallableController needs a callable, got {type(fn).__name__}")
        self.fn = fn
        self.name: str = name or str(getattr(fn, "__name__", type(fn).__name__))

    def reset(self, seed: int | None = None) -> None:
        """Stateless: nothing to clear."""
        del seed

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """``fn(obs)``, clipped to [-1, 1]."""
        del measurements
        return _to_action(self.fn(obs), self.name)


class ConstantController:
    """Hold one exo command for the whole episode.

    Args:
        command: The normalized command, in [-1, 1].

    Raises:
        ValueError: If *command* is not a finite number in [-1, 1].
    """

    def __init__(self, command: float) -> None:
        value = float(command)
        if not (ACTION_LOW <= value <= ACTION_HIGH):
            raise ValueError(
                f"ConstantController command = {command!r} is outside [{ACTION_LOW:g}, "
                f"{ACTION_HIGH:g}]"
            )
        self.command = value
        self.name = f"constant {value:g}"
        self._action = np.array([value], dtype=np.float32)

    def reset(self, seed: int | None = None) -> None:
        """Stateless: nothing to clear."""
        del seed

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """The command (a fresh array)."""
        del obs, measurements
        return self._action.copy()


class SB3Controller:
    """Wrap a stable-baselines3 model (``SAC``, ``PPO``, ``TD3`` ... or its ``.policy``).

    Args:
        model: Object with ``predict(obs, deterministic=...) -> (action, state)``.
        deterministic: Use the mean action (evaluation) rather than a sample.
        name: Label used in error messages and tables.
        obs_normalizer: SB3 ``VecNormalize`` statistics applied to each observation.
        obs_preset: Observation preset of the model's env (``make_env(..., obs_preset=)``).
    """

    def __init__(
        self,
        model: Any,
        deterministic: bool = True,
        name: str | None = None,
        obs_normalizer: Any = None,
        obs_preset: str = "full",
    ) -> None:
        if not callable(getattr(model, "predict", None)):
            raise ValueError(f"{type(model).__name__} has no predict(obs, deterministic=...)")
        self.model = model
        self.deterministic = deterministic
        self.name = name or type(model).__name__
        #: SB3 ``VecNormalize`` statistics the model was trained with (``None``: raw obs).
        self.obs_normalizer = obs_normalizer
        #: Observation preset of the env the model was trained on.
        self.obs_preset = obs_preset

    def reset(self, seed: int | None = None) -> None:
        """Seed the model's RNG for stochastic evaluation (no effect when deterministic)."""
        if seed is not None and not self.deterministic:
            set_seed = getattr(self.model, "set_random_seed", None)
            if callable(set_seed):
                set_seed(int(seed))

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """``model.predict(obs)``, clipped to [-1, 1]."""
        del measurements
        if self.obs_normalizer is not None:
            obs = self.obs_normalizer.normalize_obs(obs)
        action, _ = self.model.predict(obs, deterministic=self.deterministic)
        return _to_action(action, self.name)


class GentleController:
    """A policy trained over the gentleness range, run at one weight: the trade-off between
    speed (0) and interaction torque (1) a clinician sets for a patient.

    The env it was trained on appended the weight to the observation
    (:class:`~myoexo.envs.knee_exo.MyoExoKneeEnv`'s ``gentleness=``); this wrapper does the
    same for the env it runs on, which needs no weight of its own.

    Args:
        controller: The policy (any controller acting on the observation with the weight
            appended).
        gentleness: The weight, in :data:`~myoexo.envs.config.GENTLENESS_RANGE`.

    Raises:
        ValueError: *gentleness* is outside the range.
    """

    def __init__(self, controller: Controller, gentleness: float) -> None:
        from myoexo.envs.config import check_gentleness

        self.controller = controller
        self.gentleness = check_gentleness(gentleness)
        self._weight = np.float32(self.gentleness)
        self.sensors: frozenset[str] = frozenset(getattr(controller, "sensors", frozenset()))

    def reset(self, seed: int | None = None) -> None:
        """Reset the policy."""
        self.controller.reset(seed)

    def act(self, obs: np.ndarray, measurements: Measurements) -> np.ndarray:
        """The policy's command on *obs* with the weight appended."""
        return self.controller.act(np.append(obs, self._weight), measurements)

    def __repr__(self) -> str:
        return f"GentleController({self.controller!r}, gentleness={self.gentleness:g})"


def as_controller(obj: Any, name: str | None = None) -> Controller:
    """Return ``obj`` as a controller: itself if it already is one, an SB3-style model
    through :class:`SB3Controller`, a plain callable through :class:`CallableController`."""
    if isinstance(obj, Controller):
        return obj
    if callable(getattr(obj, "predict", None)):
        return SB3Controller(obj, name=name)
    if callable(obj):
        return CallableController(obj, name=name)
    raise ValueError(
        f"cannot use {type(obj).__name__} as a controller: expected an object with "
        "reset(seed) and act(obs, measurements), an SB3 model with predict(), or a "
        "callable(obs)"
    )
