"""The one table of learning algorithms: their names, where their classes live and which
extra installs them.

A name is accepted in any case (``"sac"``, ``"SAC"``); a controller spec
``"sbx_sac:model.zip"`` and a training config's ``algorithm = "sbx_sac"``
(:class:`~myoexo.training.config.TrainConfig`) both read this table. The table holds the
learners that trained the shipped policies and the documented comparisons: SB3's SAC and PPO,
SBX's SAC, TQC and CrossQ, and ``sbx_sac_overlap``: SBX's SAC with the env collecting while
the updates run (:mod:`myoexo.policies.overlapped_sac`).

The ``sbx_*`` learners are SBX's (stable-baselines3 in JAX, the ``jax`` extra): the same API,
checkpoints and exports, with jitted updates. JAX on a small machine starts more threads than
it has cores unless told otherwise, so :meth:`Algorithm.load_class` sets
:data:`JAX_CPU_FLAGS` (one intra-op thread per learner, no Eigen thread pool) before JAX is
first imported, unless ``XLA_FLAGS`` is already set: two learners on two cores then do not
oversubscribe them.
"""

from __future__ import annotations

import importlib
import os
import sys
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

#: ``XLA_FLAGS`` for a JAX learner on a CPU core of its own.
JAX_CPU_FLAGS = "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"


@dataclass(frozen=True)
class Algorithm:
    """One learning algorithm.

    Attributes:
        name: Lower-case alias (``"sac"``): a training config's ``algorithm`` and a
            controller-spec prefix.
        class_name: Class name in its package (``"SAC"``).
        package: Module that defines the class.
        extra: The myoexo extra that installs ``package`` (``None``: a core dependency).
        framework: ``"torch"`` (stable-baselines3) or ``"jax"`` (SBX).
        on_policy: Learns from fresh rollouts (no replay buffer; PPO).
    """

    name: str
    class_name: str
    package: str = "stable_baselines3"
    extra: str | None = None
    framework: str = "torch"
    on_policy: bool = False

    def load_class(self) -> Any:
        """The algorithm's class; ``ValueError`` naming the extra to install if absent."""
        if self.framework == "jax" and "jax" not in sys.modules:
            os.environ.setdefault("XLA_FLAGS", JAX_CPU_FLAGS)
        try:
            return getattr(importlib.import_module(self.package), self.class_name)
        except ImportError:
            hint = f" (pip install 'myoexo[{self.extra}]')" if self.extra else ""
            raise ValueError(f"{self.class_name} needs {self.package}{hint}") from None


#: Every algorithm myoexo knows, by alias.
ALGORITHMS: MappingProxyType[str, Algorithm] = MappingProxyType(
    {
        a.name: a
        for a in (
            Algorithm("sac", "SAC"),
            Algorithm("ppo", "PPO", on_policy=True),
            Algorithm("sbx_sac", "SAC", "sbx", "jax", framework="jax"),
            Algorithm(
                "sbx_sac_overlap",
                "OverlappedSAC",
                "myoexo.policies.overlapped_sac",
                "jax",
                framework="jax",
            ),
            Algorithm("sbx_tqc", "TQC", "sbx", "jax", framework="jax"),
            Algorithm("sbx_crossq", "CrossQ", "sbx", "jax", framework="jax"),
        )
    }
)


def get_algorithm(name: str) -> Algorithm:
    """The :class:`Algorithm` of an alias (any case).

    Raises:
        ValueError: Unknown name; the message lists the accepted names.
    """
    key = str(name).lower()
    if key not in ALGORITHMS:
        raise ValueError(f"algorithm = {name!r}; accepted: {sorted(ALGORITHMS)}")
    return ALGORITHMS[key]


def algorithm_class(name: str) -> Any:
    """The class of an algorithm (alias or class name); ``ValueError`` naming the extra to
    install if its package is missing."""
    return get_algorithm(name).load_class()


def load_sb3_model(path: str, algorithm: str = "sac") -> Any:
    """Load a stable-baselines3 model file on the CPU; ``ValueError`` if it is unreadable."""
    cls = algorithm_class(algorithm)
    try:
        return cls.load(path, device="cpu")
    except Exception as exc:  # zip, pickle and torch errors all mean "not a usable model"
        raise ValueError(
            f"cannot load {path!r} as a stable-baselines3 {algorithm} model "
            f"({type(exc).__name__}: {exc})"
        ) from exc
