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

from typing import TYPE_CHECKING, Any

from myoexo.envs.registration import ENV_LEVELS, make_env, register_envs

if TYPE_CHECKING:
    from myoexo.control import Controller
    from myoexo.policies.actor import MLPActor
    from myoexo.policies.student import StudentController

__version__ = "0.1.0"
__all__ = ["ENV_LEVELS", "__version__", "load_policy", "make_env", "register_envs"]

register_envs()


def load_policy(
    name: str = "sac", env: Any = None, check: bool = True
) -> MLPActor | StudentController | Controller:
    """A policy shipped with the package, by name: ``"sac"`` (the twin's full state,
    default), ``"student_exo"`` (the exoskeleton's own sensors with memory: deployable) or
    ``"residual"`` (a correction on the minimum-jerk PID, trained on the current twin, with a
    gentleness weight).

    With *env*, the controller as it runs there (what ``myoexo evaluate --controllers NAME``
    runs): a residual policy on its base controller built on *env*, a policy trained over the
    gentleness range at its default weight (``"residual@0.5"``: at 0.5). Without, the stored
    actor; a residual policy is refused there, since its actor alone is only the correction.

    Args:
        name: A name of :data:`myoexo.policies.SHIPPED_POLICIES` (or a file stem inside
            ``myoexo/policies/``); with *env*, any ``myoexo evaluate`` controller spec.
        env: The env the controller will run on (its base controller is built on it).
        check: Replay the reference (observation, action) pairs stored at export time and
            raise ``ValueError`` if the loaded actor disagrees.

    Raises:
        FileNotFoundError: No such shipped policy (the message lists the names).
        ValueError: A residual policy named without *env*.

    See :func:`myoexo.policies.load_policy` and the model cards in ``myoexo/policies/``.
    """
    if env is not None:
        from myoexo.control import build_controller, parse_controller_spec

        return build_controller(parse_controller_spec(name), env)
    from myoexo.control.residual import ResidualConfig
    from myoexo.policies import load_policy as _load

    policy = _load(name, check=check)
    residual = ResidualConfig.from_metadata(getattr(policy, "metadata", None))
    if residual is not None:
        raise ValueError(
            f"the policy {name!r} is a correction on the controller {residual.base!r}: pass the "
            f"env it runs on, myoexo.load_policy({name!r}, env), for the controller as it runs"
        )
    return policy
