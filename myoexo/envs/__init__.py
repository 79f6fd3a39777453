"""Gymnasium environments of myoexo (registered on ``import myoexo``)."""

from myoexo.envs.config import DEFAULT_REWARD_WEIGHTS, RewardParams, TaskParams
from myoexo.envs.registration import ENV_LEVELS, register_envs

__all__ = ["DEFAULT_REWARD_WEIGHTS", "ENV_LEVELS", "RewardParams", "TaskParams", "register_envs"]


def __getattr__(name: str):
    # The env class imports MuJoCo models and MyoSuite: load it only when asked for.
    if name in ("MyoExoKneeEnv", "DEFAULT_OBS_KEYS"):
        from myoexo.envs import knee_exo

        return getattr(knee_exo, name)
    raise AttributeError(name)
