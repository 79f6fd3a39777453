"""myoexo: knee-exoskeleton digital twin with spastic reflexes on MyoSuite.

Importing the package registers the gymnasium / MyoSuite env ids ``MyoExoKnee-v0`` ..
``MyoExoKnee-v3`` (Modified Ashworth level 0..3) and ``MyoExoKneeRandom-v0`` (level drawn at
every reset)::

    import gymnasium as gym
    import myoexo

    env = gym.make("MyoExoKnee-v2")            # or myoexo.make_env(2, reward_weights=...)
    policy = myoexo.load_policy("sac")          # a shipped controller

The folders are floors, each importing only from those below it (``docs/architecture.md``);
bottom up: :mod:`myoexo.runtime` (files, locks, signals, clusters), :mod:`myoexo.model` (the
twin), :mod:`myoexo.spasticity` (the reflex), :mod:`myoexo.envs`, :mod:`myoexo.policies`,
:mod:`myoexo.control`, :mod:`myoexo.viz`, :mod:`myoexo.clinical`, :mod:`myoexo.evaluation`,
:mod:`myoexo.training`, :mod:`myoexo.studies` (the experiments that drive them all) and the
command line, :mod:`myoexo.cli`.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from myoexo.envs.registration import ENV_LEVELS, make_env, register_envs

if TYPE_CHECKING:
    from myoexo.policies.actor import MLPActor
    from myoexo.policies.student import StudentController

__version__ = "0.1.0"
__all__ = ["ENV_LEVELS", "__version__", "load_policy", "make_env", "register_envs"]

register_envs()


def load_policy(name: str = "sac", check: bool = True) -> MLPActor | StudentController:
    """A policy shipped with the package, by name: ``"sac"`` (the twin's full state,
    default) or ``"student_exo"`` (the exoskeleton's own sensors with memory: deployable).

    Args:
        name: A name of :data:`myoexo.policies.SHIPPED_POLICIES` (or a file stem inside
            ``myoexo/policies/``).
        check: Replay the reference (observation, action) pairs stored at export time and
            raise ``ValueError`` if the loaded actor disagrees.

    Raises:
        FileNotFoundError: No such shipped policy (the message lists the names).

    See :func:`myoexo.policies.load_policy` and the model cards in ``myoexo/policies/``.
    """
    from myoexo.policies import load_policy as _load

    return _load(name, check=check)
