"""Env ids of myoexo and the one way to build their envs.

The ids are registered with gymnasium and MyoSuite's registry on ``import myoexo``:
``gymnasium.make("MyoExoKnee-v2")`` (after ``import myoexo``), ``gymnasium.make(
"myoexo:MyoExoKnee-v2")`` (imports the package itself) and
``myosuite.core.registry.make_env("MyoExoKnee-v2")`` all build the same env.

The env truncates its episodes itself (at ``TaskParams.episode_steps``, 800 control steps
by default) and reports instability as a truncation, so neither gymnasium's ``TimeLimit``
nor MyoSuite's instability wrapper is added: an env built with another ``TaskParams`` needs
nothing more. Its ``spec.max_episode_steps`` still reports the episode length of the env's
own task (``gymnasium.make(id).spec.max_episode_steps == 800``; 400 for a 4 s task), which
the tools that read it use as their horizon (MyoSuite's ``examine_env``, rl_zoo3,
gymnasium's wrappers). An explicit ``gymnasium.make(..., max_episode_steps=n)`` still adds
gymnasium's ``TimeLimit(n)``. :func:`make_env` is the shortcut every part of myoexo uses::

    env = make_env(2, episode_duration_s=4.0, reward_weights={"inter": -0.5})
"""

from __future__ import annotations

import dataclasses
import warnings
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import gymnasium as gym

from myoexo.envs.config import DEFAULT_REWARD_WEIGHTS, TaskParams
from myoexo.spasticity.levels import RANDOM_LEVEL, VALID_LEVELS

ENTRY_POINT = "myoexo.envs.knee_exo:MyoExoKneeEnv"
#: Id of the env whose level is drawn uniformly at every reset (the paper's training).
RANDOM_ENV_ID = "MyoExoKneeRandom-v0"

#: env id -> spasticity level (``"random"``: uniform over the levels at every reset).
ENV_LEVELS: dict[str, int | str] = {
    **{f"MyoExoKnee-v{level}": level for level in VALID_LEVELS},
    RANDOM_ENV_ID: RANDOM_LEVEL,
}

#: Default episode length in control steps (8 s at 100 Hz), recorded in MyoSuite's registry
#: (gymnasium's entry has none, so that ``gymnasium.make`` adds no ``TimeLimit``; the env's
#: ``spec`` reports its own length).
MAX_EPISODE_STEPS = TaskParams().episode_steps


def register_envs() -> None:
    """Register every id (idempotent)."""
    from myosuite.core.registry import register_env

    # Gymnasium reads "-vN" as a version and warns that v0..v2 are "out of date" next to v3;
    # here the suffix is the spasticity level (the ids the study uses), not a version.
    warnings.filterwarnings(
        "ignore",
        message=r".*environment MyoExoKnee-v\d is out of date.*",
        category=DeprecationWarning,
    )
    for env_id, level in ENV_LEVELS.items():
        register_env(
            env_id,
            ENTRY_POINT,
            max_episode_steps=MAX_EPISODE_STEPS,
            time_limit=False,
            wrap_mj_instability_termination=False,
            kwargs={"spasticity_level": level},
        )


def env_id(level: int | str) -> str:
    """The id of a level's env: ``MyoExoKnee-v<level>``, or :data:`RANDOM_ENV_ID`."""
    for key, value in ENV_LEVELS.items():
        if value == level and type(value) is type(level):
            return key
    raise ValueError(
        f"unknown spasticity level {level!r}; accepted: {list(VALID_LEVELS)} or {RANDOM_LEVEL!r}"
    )


def make_env(
    env: int | str = 0,
    *,
    task: TaskParams | Mapping[str, Any] | None = None,
    episode_duration_s: float | None = None,
    reward_weights: Mapping[str, float] | None = None,
    subject_noise: bool = True,
    **kwargs: Any,
) -> gym.Env[Any, Any]:
    """Build a MyoExoKnee env through ``gymnasium.make``.

    Args:
        env: A spasticity level (0..3 or ``"random"``) or an env id (``"MyoExoKnee-v2"``,
            ``"module:EnvId"`` for an env registered by another module).
        task: Task parameters, or a mapping of their fields (default: the env's, i.e.
            :class:`TaskParams`' defaults).
        episode_duration_s: Shortcut replacing ``task.episode_duration_s`` (``None``: keep).
        reward_weights: Reward-weight overrides on top of the defaults
            (:data:`~myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`); an unknown key raises.
        subject_noise: Draw individual subjects at reset (``False``: Table I's nominal
            subject of the level, e.g. for tuning).
        **kwargs: Other keyword arguments of :class:`~myoexo.envs.knee_exo.MyoExoKneeEnv`
            (``twin``, ``obs_keys``, ``render_mode``, ...).
    """
    import gymnasium as gym

    register_envs()  # a no-op after ``import myoexo``; here for ``myoexo.envs`` alone

    env_name = env if isinstance(env, str) and env != RANDOM_LEVEL else env_id(env)
    if isinstance(task, Mapping):
        task = TaskParams(**task)
    if episode_duration_s is not None:
        task = dataclasses.replace(task or TaskParams(), episode_duration_s=episode_duration_s)
    if task is not None:
        kwargs["task"] = task
    if reward_weights:
        kwargs["weighted_reward_keys"] = {**DEFAULT_REWARD_WEIGHTS, **dict(reward_weights)}
    if not subject_noise:
        kwargs["subject_noise"] = False
    return gym.make(env_name, **kwargs)
