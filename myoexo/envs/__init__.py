"""Gymnasium environments of myoexo (registered on ``import myoexo``).

``make_env(level, ...)`` builds one (:func:`~myoexo.envs.registration.make_env`). The env
(:mod:`~myoexo.envs.knee_exo`) keeps its observation keys and layout in
:mod:`~myoexo.envs.observation`, its reward in :mod:`~myoexo.envs.reward` and the perturbed
twin in :mod:`~myoexo.envs.robustness`.
"""

from myoexo.envs.config import DEFAULT_REWARD_WEIGHTS, RewardParams, TaskParams
from myoexo.envs.registration import ENV_LEVELS, RANDOM_ENV_ID, env_id, make_env, register_envs
from myoexo.runtime.lazy import lazy_exports

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


# the env class imports MyoSuite's env base: loaded when first read
__getattr__, __dir__ = lazy_exports(
    __name__,
    {"MyoExoKneeEnv": "knee_exo", "DEFAULT_OBS_KEYS": "observation", "OBS_PRESETS": "observation"},
)
