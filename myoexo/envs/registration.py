"""Env ids of myoexo, registered with gymnasium and MyoSuite's registry on ``import myoexo``.

``gymnasium.make("MyoExoKnee-v2")`` (after ``import myoexo``), ``gymnasium.make(
"myoexo:MyoExoKnee-v2")`` (imports the package itself) and
``myosuite.core.registry.make_env("MyoExoKnee-v2")`` all build the same env.
"""

from __future__ import annotations

import warnings

from myoexo.envs.config import TaskParams

ENTRY_POINT = "myoexo.envs.knee_exo:MyoExoKneeEnv"

#: env id -> spasticity level (``"random"``: uniform over 0..3 at every reset).
ENV_LEVELS: dict[str, int | str] = {
    "MyoExoKnee-v0": 0,
    "MyoExoKnee-v1": 1,
    "MyoExoKnee-v2": 2,
    "MyoExoKnee-v3": 3,
    "MyoExoKneeRandom-v0": "random",
}

#: Default episode length in control steps (8 s at 100 Hz). An env built with another
#: ``TaskParams`` truncates itself at its own length; pass ``max_episode_steps`` to
#: ``gymnasium.make`` as well if it is longer than this.
MAX_EPISODE_STEPS = TaskParams().episode_steps


def register_envs() -> None:
    """Register every id (idempotent). Instability is reported by the env itself as a
    truncation with ``info["unstable"]``, so MyoSuite's termination wrapper is not added."""
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
            wrap_mj_instability_termination=False,
            kwargs={"spasticity_level": level},
        )
