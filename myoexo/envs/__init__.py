"""Gymnasium environments of myoexo (registered on ``import myoexo``).

``make_env(level, ...)`` builds one (:func:`~myoexo.envs.registration.make_env`).
"""

from myoexo.envs.config import DEFAULT_REWARD_WEIGHTS, RewardParams, TaskParams
from myoexo.envs.registration import ENV_LEVELS, RANDOM_ENV_ID, env_id, make_env, register_envs

__all__ = [
    "DEFAULT_REWARD_WEIGHTS",
    "ENV_LEVELS",
    "RANDOM_ENV_ID",
    "RewardParams",
    "TaskParams",
    "env_id",
    "make_env",
    "register_envs",
]


def __getattr__(name: str):
    # The env class imports MuJoCo models and MyoSuite: load it only when asked for.
    if name in ("MyoExoKneeEnv", "DEFAULT_OBS_KEYS"):
        from myoexo.envs import knee_exo

        return getattr(knee_exo, name)
    raise AttributeError(name)
