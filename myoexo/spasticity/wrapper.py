"""A gymnasium wrapper that installs the spastic reflex on any MyoSuite env with the knee
muscles (like MyoSuite's ``CtrlStageWrapper``)."""

from __future__ import annotations

from typing import Any

import gymnasium as gym
from gymnasium.utils import RecordConstructorArgs

from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel
from myoexo.spasticity.stage import STAGE_NAME, SpasticityStage


class SpasticityWrapper(RecordConstructorArgs, gym.Wrapper):
    """Install a :class:`SpasticityStage` on a MyoSuite env (CPU; like ``CtrlStageWrapper``).

    The stage runs after MyoSuite's built-in stages (noise, fatigue, reroute), right before
    ``ctrl`` is written, unless an explicit *order* puts it earlier. The stage is
    ``env.spasticity`` (also reachable through outer wrappers with
    ``env.get_wrapper_attr("spasticity")``). The wrapper pickles as its constructor
    arguments and re-installs the stage on the rebuilt env.

    Args:
        env: A MyoSuite env whose pipeline runs muscle stages and whose model has the 11
            spastic muscles and ``knee_angle_r`` (e.g. ``myoLegWalk-v0``).
        level: Spasticity level 0..3 or ``"random"``.
        subject_noise: Draw individual subjects at reset (see :class:`SpasticityStage`).
        reflex: Reflex model, a registered name (``"stretch"``, ``"uniform"``,
            ``"persistent"``, ...) or a :class:`~myoexo.spasticity.ReflexModel` (see
            :class:`SpasticityStage`).
        order: MyoSuite stage order (``None``: after the built-in stages).

    Raises:
        TypeError: If the env does not run muscle stages.
        ValueError: If *level* is unknown or the model lacks a muscle or the knee joint.
    """

    def __init__(
        self,
        env: gym.Env,
        level: int | str = 2,
        subject_noise: bool = True,
        reflex: str | ReflexModel = DEFAULT_REFLEX,
        order: float | None = None,
    ) -> None:
        RecordConstructorArgs.__init__(
            self, level=level, subject_noise=subject_noise, reflex=reflex, order=order
        )
        gym.Wrapper.__init__(self, env)
        host: Any = env.unwrapped
        if not getattr(host, "supports_ctrl_stages", False):
            raise TypeError(
                f"SpasticityWrapper needs an env whose action pipeline runs muscle stages; "
                f"{type(host).__name__} does not."
            )
        self._kwargs = {
            "level": level,
            "subject_noise": subject_noise,
            "reflex": reflex,
            "order": order,
        }
        self.spasticity = SpasticityStage(level, subject_noise=subject_noise, reflex=reflex)
        # fail now, not at the first step
        self.spasticity.bind(host.model, getattr(host, "dt", None))
        host.add_ctrl_stage(STAGE_NAME, self.spasticity.apply, self.spasticity.reset, order=order)

    def __getstate__(self) -> dict[str, Any]:
        return {"env": self.env, "kwargs": dict(self._kwargs)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        SpasticityWrapper.__init__(self, state["env"], **state["kwargs"])
