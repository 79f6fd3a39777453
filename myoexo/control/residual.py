"""Residual learning on a classical controller: a policy that corrects a PID instead of
replacing it.

The exo command is the classical controller's plus a learned correction::

    u = clip(u_base + scale x a, -1, 1)

where ``u_base`` is the base controller's command at this step (any classical controller
spec, e.g. the PID on a 0.6-s minimum-jerk reference, ``pid:reference=minjerk,ramp_s=0.6``)
and ``a`` in [-1, 1] the policy's action. The policy observes the env's observation (with
the gentleness weight last, for a policy trained over the gentleness range) followed by
``u_base``, so it knows what it corrects. An untrained policy (``a`` = 0) is the base
controller itself: learning starts from a controller that already settles every subject,
and the correction is bounded by ``scale`` (Johannink et al., "Residual reinforcement
learning for robot control", ICRA 2019; Silver et al., "Residual policy learning", 2018).
In training, a ``penalty`` prices the correction itself: the wrapper's reward is the env's
minus ``penalty x a^2``, so the policy departs from its base only where that pays on the
task's own terms (0: the env's reward unchanged).

A **paced base** (``pace_s = (fast, slow)``, for a policy trained over the gentleness range)
moves its reference in ``fast + w (slow - fast)`` seconds at gentleness weight ``w``: the
base PID's ``ramp_s`` or the impedance controller's ``duration_s``
(:data:`~myoexo.control.specs.PACE_OPTIONS`), set at each episode's first step from the
weight, the observation's last entry (:class:`PacedBase`). The weight then sets the move's
pace, which the classical families show to be the first lever between settling time and
interaction torque, and the policy corrects a base that is already as fast or as gentle as
asked.

Two halves of one definition, used in training and at run time:

* :class:`ResidualWrapper`: the training env (a gymnasium wrapper around a MyoExoKnee env);
* :class:`ResidualController`: the same law as a :class:`~myoexo.control.protocol.Controller`
  around the trained policy, built by :func:`~myoexo.control.specs.build_controller` from the
  ``residual`` record a policy's metadata carries (:class:`ResidualConfig`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from myoexo.control.protocol import Controller, declared_sensors
from myoexo.envs.sensors import Measurements, read_sensors

#: Key of the residual record in a policy's metadata (checkpoint state, exported actor).
RESIDUAL_KEY = "residual"

#: Accepted reach of the correction, ``(low, high]`` as a fraction of the 100 Nm motor.
RESIDUAL_SCALE_RANGE: tuple[float, float] = (0.0, 2.0)

#: Accepted weight of the training penalty on the squared correction, ``[low, high]``.
RESIDUAL_PENALTY_RANGE: tuple[float, float] = (0.0, 100.0)

#: Accepted reference durations of a paced base, s, ``[low, high]`` (both ends of the pace).
PACE_RANGE_S: tuple[float, float] = (0.05, 10.0)


def check_residual_scale(scale: float) -> float:
    """*scale* as a float in :data:`RESIDUAL_SCALE_RANGE` (``low`` excluded).

    Raises:
        ValueError: It is not (the message names the value and the range).
    """
    low, high = RESIDUAL_SCALE_RANGE
    if not (math.isfinite(scale) and low < scale <= high):
        raise ValueError(f"residual scale = {scale!r} is outside ({low:g}, {high:g}]")
    return float(scale)


def check_residual_penalty(penalty: float) -> float:
    """*penalty* as a float in :data:`RESIDUAL_PENALTY_RANGE`.

    Raises:
        ValueError: It is not (the message names the value and the range).
    """
    low, high = RESIDUAL_PENALTY_RANGE
    if not (math.isfinite(penalty) and low <= penalty <= high):
        raise ValueError(f"residual penalty = {penalty!r} is outside [{low:g}, {high:g}]")
    return float(penalty)


def check_pace(pace_s: Any) -> tuple[float, float]:
    """*pace_s* as ``(fast, slow)`` floats, each in :data:`PACE_RANGE_S`.

    Raises:
        ValueError: It is not two such durations (the message names the value and the range).
    """
    low, high = PACE_RANGE_S
    values = tuple(float(v) for v in pace_s)
    if len(values) != 2 or not all(math.isfinite(v) and low <= v <= high for v in values):
        raise ValueError(
            f"residual pace_s = {tuple(pace_s)!r} must be two durations (at weights 0 and 1) "
            f"in [{low:g}, {high:g}] s"
        )
    return values[0], values[1]


def paced_duration_s(pace_s: tuple[float, float], weight: float) -> float:
    """The base's reference duration at gentleness weight *weight*: ``fast + weight (slow -
    fast)``, s.

    Raises:
        ValueError: *weight* is outside [0, 1].
    """
    if not (math.isfinite(weight) and 0.0 <= weight <= 1.0):
        raise ValueError(
            f"a paced base reads the gentleness weight from the observation's last entry, "
            f"got {weight!r}; accepted range [0, 1] (a policy trained over the weight range)"
        )
    fast, slow = pace_s
    return fast + weight * (slow - fast)


@dataclass(frozen=True)
class ResidualConfig:
    """A residual policy's base controller and the reach of its correction.

    Attributes:
        base: The classical controller spec the policy corrects (``pid[:options]`` or
            ``impedance[:options]``, :mod:`myoexo.control.specs`).
        scale: Largest correction, as a fraction of the motor's 100 Nm (the policy's action
            ``a`` in [-1, 1] adds ``scale x a``), in (0, 2].
        penalty: Training only: weight of ``a^2`` subtracted from the reward, in [0, 100]
            (recorded with the policy as its provenance; the run-time law ignores it).
        pace_s: ``(fast, slow)``: the base's reference duration at gentleness weights 0 and
            1, s (a paced base, :class:`PacedBase`; the base spec leaves that option out,
            :func:`~myoexo.control.specs.paced_base_spec`); ``None``: the base spec's own.
    """

    base: str
    scale: float = 0.5
    penalty: float = 0.0
    pace_s: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if not isinstance(self.base, str) or not self.base.strip():
            raise ValueError(f"ResidualConfig.base = {self.base!r} must name a controller spec")
        check_residual_scale(self.scale)
        check_residual_penalty(self.penalty)
        if self.pace_s is not None:
            object.__setattr__(self, "pace_s", check_pace(self.pace_s))

    def to_dict(self) -> dict[str, Any]:
        """The metadata record (:data:`RESIDUAL_KEY`; ``penalty`` and ``pace_s`` only when
        set)."""
        record: dict[str, Any] = {"base": self.base, "scale": self.scale}
        if self.penalty:
            record["penalty"] = self.penalty
        if self.pace_s is not None:
            record["pace_s"] = list(self.pace_s)
        return record

    @classmethod
    def from_metadata(cls, metadata: Mapping[str, Any] | None) -> ResidualConfig | None:
        """The record a policy's metadata carries under :data:`RESIDUAL_KEY` (``None``: a
        policy that commands the exo on its own)."""
        record = (metadata or {}).get(RESIDUAL_KEY)
        if not record:
            return None
        pace = record.get("pace_s")
        return cls(
            base=str(record["base"]),
            scale=float(record["scale"]),
            penalty=float(record.get("penalty", 0.0)),
            pace_s=None if pace is None else tuple(pace),
        )


def residual_command(base_command: float, action: float, scale: float) -> float:
    """The exo command: ``clip(base_command + scale x action, -1, 1)``."""
    return min(1.0, max(-1.0, base_command + scale * action))


def _base_command(base: Controller, obs: np.ndarray, measurements: Measurements) -> float:
    return float(np.asarray(base.act(obs, measurements), dtype=np.float64).reshape(-1)[0])


class PacedBase:
    """A base controller whose reference duration follows the gentleness weight: at each
    episode's first step it builds ``build(paced_duration_s(pace_s, w))``, ``w`` the
    observation's last entry (a policy trained over the weight range observes it last), and
    then runs it for the episode.

    Args:
        build: The base controller at a reference duration (s).
        pace_s: ``(fast, slow)`` durations at weights 0 and 1 (:attr:`ResidualConfig.pace_s`).
    """

    def __init__(self, build: Callable[[float], Controller], pace_s: tuple[float, float]):
        self._build = build
        self.pace_s = check_pace(pace_s)
        #: The sensors the base declares (those of its fast end: the pace changes no sensor).
        self.sensors: frozenset[str] = declared_sensors(build(self.pace_s[0]))
        self._seed: int | None = None
        self._base: Controller | None = None
        #: The reference duration of the episode in progress, s (``None`` before its first
        #: step).
        self.duration_s: float | None = None

    def reset(self, seed: int | None = None) -> None:
        """Forget the episode's base: the next step builds one at its weight."""
        self._seed = seed
        self._base = None
        self.duration_s = None

    def act(self, obs: np.ndarray, measurements: Measurements) -> np.ndarray:
        """The command of the episode's base (built at the first step from ``obs[-1]``)."""
        base = self._base
        if base is None:
            self.duration_s = paced_duration_s(self.pace_s, float(obs[-1]))
            base = self._base = self._build(self.duration_s)
            base.reset(self._seed)
        return base.act(obs, measurements)

    def __repr__(self) -> str:
        return f"PacedBase(pace_s={self.pace_s}, duration_s={self.duration_s})"


class ResidualWrapper(gym.Wrapper, gym.utils.RecordConstructorArgs):
    """A MyoExoKnee env whose action is a correction of *base*'s command.

    The observation gains one last entry, the base controller's command for this step; the
    action ``a`` in [-1, 1] becomes the exo command ``clip(u_base + scale x a, -1, 1)``. The
    base controller reads its sensors from the env's ``info`` (:func:`read_sensors`), as
    :func:`~myoexo.control.rollout.rollout` gives them, and is reset with the env. The
    reward is the env's minus ``penalty x a^2``. ``info["base_command"]`` is the base's
    command of the step just taken, ``info["residual_penalty"]`` the ``penalty x a^2`` the
    step's reward paid.

    Args:
        env: The env.
        base: A classical controller (reset with every episode).
        scale: Reach of the correction (:attr:`ResidualConfig.scale`).
        penalty: Weight of the squared correction in the reward
            (:attr:`ResidualConfig.penalty`).
    """

    def __init__(self, env: gym.Env, base: Controller, scale: float, penalty: float = 0.0) -> None:
        gym.utils.RecordConstructorArgs.__init__(self, base=base, scale=scale, penalty=penalty)
        gym.Wrapper.__init__(self, env)
        self.base = base
        self.scale = check_residual_scale(scale)
        self.penalty = check_residual_penalty(penalty)
        self._sensors = declared_sensors(base)
        space = env.observation_space
        if not isinstance(space, gym.spaces.Box) or len(space.shape) != 1:
            raise ValueError(f"ResidualWrapper needs a flat Box observation, got {space}")
        low = np.append(space.low, -1.0).astype(np.float32)
        high = np.append(space.high, 1.0).astype(np.float32)
        self.observation_space = gym.spaces.Box(low=low, high=high, dtype=np.float32)
        self._base_u = 0.0

    def _observe(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        self._base_u = _base_command(self.base, obs, read_sensors(info, self._sensors))
        return np.append(obs, self._base_u).astype(np.float32)

    def reset(self, **kwargs: Any) -> tuple[np.ndarray, dict[str, Any]]:
        obs, info = self.env.reset(**kwargs)
        self.base.reset(kwargs.get("seed"))
        return self._observe(obs, info), info

    def step(self, action: Any) -> tuple[np.ndarray, Any, bool, bool, dict[str, Any]]:
        a = float(np.asarray(action, dtype=np.float64).reshape(-1)[0])
        base_u = self._base_u
        u = np.array([residual_command(base_u, a, self.scale)], dtype=np.float32)
        obs, reward, terminated, truncated, info = self.env.step(u)
        info["base_command"] = base_u
        paid = self.penalty * a * a
        info["residual_penalty"] = paid
        return self._observe(obs, info), float(reward) - paid, terminated, truncated, info


class ResidualController:
    """A trained residual policy with its base controller: a
    :class:`~myoexo.control.protocol.Controller` that commands
    ``clip(u_base + scale x a, -1, 1)``, ``a`` the policy's action on the observation with
    ``u_base`` appended (what :class:`ResidualWrapper` trained it on).

    Args:
        controller: The policy (a controller acting on the observation + base command).
        base: The base controller (the spec its metadata names, built on the same env).
        scale: Reach of the correction.
    """

    def __init__(self, controller: Controller, base: Controller, scale: float) -> None:
        self.controller = controller
        self.base = base
        self.scale = check_residual_scale(scale)
        #: The sensors the base declares (the policy reads the observation only).
        self.sensors: frozenset[str] = declared_sensors(base) | declared_sensors(controller)

    @property
    def metadata(self) -> Any:
        """The policy's metadata (its provenance and ``residual`` record)."""
        return getattr(self.controller, "metadata", None)

    def reset(self, seed: int | None = None) -> None:
        """Reset the base and the policy."""
        self.base.reset(seed)
        self.controller.reset(seed)

    def act(self, obs: np.ndarray, measurements: Measurements) -> np.ndarray:
        """The base's command plus the policy's bounded correction."""
        base_u = _base_command(self.base, obs, measurements)
        a = self.controller.act(np.append(obs, np.float32(base_u)), measurements)
        a0 = float(np.asarray(a, dtype=np.float64).reshape(-1)[0])
        return np.array([residual_command(base_u, a0, self.scale)], dtype=np.float32)

    def __repr__(self) -> str:
        return f"ResidualController({self.controller!r}, base={self.base!r}, scale={self.scale:g})"
