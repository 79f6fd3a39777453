"""The episode loop: one controller on one env, from a seeded reset to the episode's end.

Everything that runs episodes (the evaluation, the Ziegler-Nichols tuner, the training's
periodic evaluation, the renderer) goes through :func:`rollout`, so an episode means the same
thing everywhere: ``env.reset(seed)`` and ``controller.reset(seed)`` with the same seed, then
``controller.act(obs, measurements)`` -> ``env.step`` until the env terminates or truncates it
(its episode length, or a physics blow-up flagged in ``info["unstable"]``). The controller
gets the observation and the record of the sensors it declares
(:func:`~myoexo.envs.sensors.read_sensors`), never ``info``.

    from myoexo.control import PID, rollout
    from myoexo.envs import make_env

    env = make_env(2)
    ep = rollout(env, PID.from_env(env), seed=0, channels=("time_s", "knee_angle_deg"))
    ep.signals["knee_angle_deg"][-1]      # final knee angle, deg
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from myoexo.control.protocol import Controller, declared_sensors
from myoexo.envs.sensors import read_sensors

#: Called at the reset (step 0) and after every step with ``(step, info)``.
StepHook = Callable[[int, Mapping[str, Any]], None]


@dataclass
class Rollout:
    """One episode.

    Attributes:
        seed: Episode seed (the env's subject and start angle; the controller's RNG).
        level: Spasticity level of the episode's subject.
        subject: The subject's reflex parameters (``info["subject"]``).
        signals: ``info`` key -> float64 array over the samples (reset + every step).
        unstable: The physics diverged and the env truncated the episode.
        n_steps: Control steps run.
    """

    seed: int
    level: int
    subject: dict[str, float]
    signals: dict[str, np.ndarray]
    unstable: bool
    n_steps: int


def scalar_info_keys(info: Mapping[str, Any]) -> list[str]:
    """Keys of ``info`` whose values are plain numbers (not flags, not arrays)."""
    return [k for k, v in info.items() if isinstance(v, (int, float)) and not isinstance(v, bool)]


def rollout(
    env: Any,
    controller: Controller,
    seed: int,
    channels: Sequence[str] | None = None,
    *,
    until_s: float | None = None,
    on_step: StepHook | None = None,
) -> Rollout:
    """Run one episode of ``controller`` on ``env`` from ``env.reset(seed=seed)``.

    Args:
        env: A MyoExoKnee env (wrappers allowed) or any env whose ``info`` has the channels
            and the sensor readings (:func:`~myoexo.envs.sensors.read_sensors`).
        controller: Any :class:`~myoexo.control.protocol.Controller`; reset with ``seed``.
        seed: Episode seed.
        channels: ``info`` keys to record (default: every scalar key of the reset's info).
        until_s: Stop at this simulated time, s (``None``: the episode's end).
        on_step: Called with ``(step, info)`` at the reset (step 0) and after every step.

    Raises:
        ValueError: ``until_s`` not a positive time; a channel missing from ``info``; the
            controller declares an unknown sensor.
    """
    if until_s is not None and not (math.isfinite(until_s) and until_s > 0.0):
        raise ValueError(f"until_s = {until_s!r} must be a positive time in s or None")
    sensors = declared_sensors(controller)
    base = env.unwrapped
    max_steps = int(getattr(base, "episode_steps", 0)) or 10_000
    obs, info = env.reset(seed=int(seed))
    controller.reset(int(seed))
    keys = list(channels) if channels is not None else scalar_info_keys(info)
    missing = [k for k in keys if k not in info]
    if missing:
        raise ValueError(f"channels {missing} are not in the env's info; it has {list(info)}")
    buf = np.full((max_steps + 1, len(keys)), np.nan)
    buf[0] = [info[k] for k in keys]
    if on_step is not None:
        on_step(0, info)
    n, unstable = 0, False
    while n < max_steps:
        action = controller.act(obs, read_sensors(info, sensors))
        obs, _, terminated, truncated, info = env.step(action)
        n += 1
        buf[n] = [info[k] for k in keys]
        unstable = unstable or bool(info.get("unstable", False))
        if on_step is not None:
            on_step(n, info)
        if terminated or truncated:
            break
        if until_s is not None and float(info["time_s"]) >= until_s - 1e-9:
            break
    return Rollout(
        seed=int(seed),
        level=int(info.get("level", getattr(base, "level", -1))),
        subject={str(k): float(v) for k, v in dict(info.get("subject", {})).items()},
        signals={k: buf[: n + 1, j] for j, k in enumerate(keys)},
        unstable=unstable,
        n_steps=n,
    )
