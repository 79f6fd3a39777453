"""The policies shipped with myoexo (a model card each beside this file).

======================  ===========================  ===========================================
name                    files (``<stem>.npz/json``)  observation
======================  ===========================  ===========================================
``residual``            ``residual_knee_exo``        ``obs_preset="full"`` and a gentleness
                                                     weight: a correction on the minimum-jerk
                                                     PID, trained on today's default twin
                                                     (version 4, ``spindle_tone``); it runs
                                                     on its base, built on an env
                                                     (``myoexo.load_policy("residual", env)``);
                                                     ``MODEL_CARD_residual.md``
``sac``                 ``sac_knee_exo``             ``obs_preset="full"``: the twin's whole
                                                     state, muscle activations, forces and
                                                     lengths included (simulation only; trained
                                                     on twin version 1); ``MODEL_CARD.md``
``student_exo``         ``student_exo``              ``obs_preset="exo"``: only what the
                                                     exoskeleton measures (encoder, motor torque,
                                                     cuff force/torque sensors, last command,
                                                     target), a memory of the last 10 frames, no
                                                     clock: deployable; distilled from ``sac``
                                                     on twin version 1;
                                                     ``MODEL_CARD_student_exo.md``
``student_fine``        ``student_fine``             ``obs_preset="exo"`` and a gentleness
                                                     weight: the same sensors and memory,
                                                     distilled from ``residual`` on today's
                                                     default twin with a smoothness term and
                                                     a fine-positioning term, the weight its
                                                     last input (default 0.25);
                                                     ``MODEL_CARD_student_fine.md``
``student_knee``        ``student_knee``             ``obs_preset="exo"`` and a gentleness
                                                     weight: ``student_fine``'s recipe
                                                     distilled again, with a fine-positioning
                                                     layer (a second network on the same
                                                     memory estimates the knee, an integral
                                                     on its error near the target; default
                                                     weight 0.25);
                                                     ``MODEL_CARD_student_knee.md``
======================  ===========================  ===========================================

Retired (their model cards stay as the record of what they measured): ``sac_exo`` (the
exoskeleton's sensors plus an episode clock) read a clock a device does not have and ended
20-50 deg off on perturbed level-3 twins, and ``student_exo`` supersedes it;
``student_residual`` (distilled on twin version 3, without the smoothness term) had a command
rougher than the paper's PID's, and ``student_smooth`` superseded it; ``student_smooth``
(distilled with the earlier ``spindle`` reflex from the ``residual`` of twin version 3)
settled more slowly than ``student_fine`` on today's twin, which supersedes it.

    import gymnasium as gym, myoexo

    policy = myoexo.load_policy()              # "sac"; offline: two small files in this folder
    device_policy = myoexo.load_policy("student_exo")
    env = gym.make("MyoExoKnee-v1", obs_preset=device_policy.obs_preset)
    obs, info = env.reset(seed=0)
    action = policy.act(obs)                               # a myoexo Controller
    action, _ = policy.predict(obs, deterministic=True)   # SB3's signature
    action = policy(obs)                                   # or simply call it

``sac`` is the deterministic actor of a SAC run (observation normalization
included) as numpy :class:`~myoexo.policies.actor.MLPActor` (``to_torch()`` gives a torch
module); ``student_exo`` is a :class:`~myoexo.policies.student.StudentController` (its MLP
actor on a memory of sensor frames, ``reset()`` clears it). Each expects the env observation
vector of its preset (``policy.obs_preset``). :mod:`~myoexo.policies.algorithms` is the one
table of learning algorithms.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path
from typing import TYPE_CHECKING

from myoexo.policies.actor import (
    MLPActor,
    actor_from_document,
    load_actor,
    read_actor_files,
    save_actor,
)

if TYPE_CHECKING:
    from myoexo.policies.student import StudentController

#: File stem of the default shipped actor (``.npz`` weights + ``.json`` normalization and
#: provenance).
SHIPPED_POLICY = "sac_knee_exo"

#: Shipped policies: name -> file stem inside this folder.
SHIPPED_POLICIES: dict[str, str] = {
    "sac": SHIPPED_POLICY,
    "student_exo": "student_exo",
    "residual": "residual_knee_exo",
    "student_fine": "student_fine",
    "student_knee": "student_knee",
}

__all__ = [
    "SHIPPED_POLICIES",
    "SHIPPED_POLICY",
    "MLPActor",
    "load_actor",
    "load_controller",
    "load_policy",
    "save_actor",
    "shipped_path",
]


def shipped_path(name: str = SHIPPED_POLICY) -> Path:
    """Path stem (no suffix) of a policy shipped in this package, by name
    (:data:`SHIPPED_POLICIES`) or file stem."""
    return Path(str(resources.files(__name__).joinpath(SHIPPED_POLICIES.get(name, name))))


def load_policy(name: str = "sac", check: bool = True) -> MLPActor | StudentController:
    """Load a policy shipped with the package (no network, no SB3 needed).

    Args:
        name: ``"sac"`` (full-state observation), ``"student_exo"`` (the exoskeleton's own sensors
            with a memory of 10 frames, no clock: deployable; a
            :class:`~myoexo.policies.student.StudentController`), ``"residual"`` (the
            correction alone, as stored: :func:`myoexo.load_policy` with an env puts it on
            its base), or a file stem inside ``myoexo/policies/``.
        check: Replay the reference (observation, action) pairs stored at export time and
            raise ``ValueError`` if the loaded actor disagrees (corrupted or edited files).

    Raises:
        FileNotFoundError: No such shipped policy (the message lists the names).
    """
    path = shipped_path(name)
    if not path.with_suffix(".npz").is_file():
        raise FileNotFoundError(f"no shipped policy {name!r}; accepted: {sorted(SHIPPED_POLICIES)}")
    return load_controller(path, check=check)


def load_controller(path_stem: str | Path, check: bool = True) -> MLPActor | StudentController:
    """A controller from its files (``<stem>.npz`` + ``<stem>.json``): the numpy actor, or,
    for a student file, the :class:`~myoexo.policies.student.StudentController` around it.

    Args:
        path_stem: The files' path without suffix (a suffix is ignored).
        check: Replay the stored reference pairs; ``ValueError`` if the actor disagrees.
    """
    meta, arrays = read_actor_files(path_stem)
    actor = actor_from_document(meta, arrays)
    if "student" in actor.metadata:  # a controller with memory around its actor
        from myoexo.policies.student import student_from_actor

        return student_from_actor(actor, arrays, path_stem, check)
    if check:
        actor.check_reference()
    return actor
