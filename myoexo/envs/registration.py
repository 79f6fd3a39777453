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

import warnings
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import gymnasium as gym

from myoexo.envs.config import TaskParams
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


def make_env(env: int | str = 0, **kwargs: Any) -> gym.Env[Any, Any]:
    """Build a MyoExoKnee env through ``gymnasium.make``.

    Args:
        env: A spasticity level (0..3 or ``"random"``) or an env id (``"MyoExoKnee-v2"``,
            ``"module:EnvId"`` for an env registered by another module).
        **kwargs: Keyword arguments of :class:`~myoexo.envs.knee_exo.MyoExoKneeEnv`, flat:
            task fields (``episode_duration_s=4.0``), ``reward_weights``, ``obs_preset``,
            ``reflex``, ``robustness``, ``subject_noise``, ``render_mode``, ...
    """
    import gymnasium as gym

    register_envs()  # a no-op after ``import myoexo``; here for ``myoexo.envs`` alone

    env_name = env if isinstance(env, str) and env != RANDOM_LEVEL else env_id(env)
    return gym.make(env_name, **kwargs)
