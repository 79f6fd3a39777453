"""myoexo: knee-exoskeleton digital twin with spastic reflexes on MyoSuite.

Importing the package registers the gymnasium / MyoSuite env ids ``MyoExoKnee-v0`` ..
``MyoExoKnee-v3`` (Modified Ashworth level 0..3) and ``MyoExoKneeRandom-v0`` (level drawn at
every reset)::

    import gymnasium as gym
    import myoexo

    env = gym.make("MyoExoKnee-v2")
"""

from __future__ import annotations

from myoexo.envs.registration import ENV_LEVELS, register_envs

__version__ = "0.1.0"
__all__ = ["ENV_LEVELS", "__version__", "load_policy", "register_envs"]

register_envs()


def load_policy(*args, **kwargs):
    """A SAC policy shipped with the package by name: ``"sac"`` (full state, default) or
    ``"sac_exo"`` (the exoskeleton's own sensors); see :func:`myoexo.policies.load_policy`
    and the model cards in ``myoexo/policies/``."""
    from myoexo.policies import load_policy as _load

    return _load(*args, **kwargs)
