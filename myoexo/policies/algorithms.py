"""The one table of learning algorithms: their names, where their classes live, which extra
installs them and which ones a training preset can run.

A name is accepted in any case (``"sac"``, ``"SAC"``); a controller spec ``"td3:model.zip"``
and a preset's ``algorithm = "tqc"`` both read this table.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any


@dataclass(frozen=True)
class Algorithm:
    """One learning algorithm.

    Attributes:
        name: Lower-case alias (``"sac"``): preset values and controller-spec prefixes.
        class_name: Class name in its package (``"SAC"``).
        package: Module that defines the class.
        extra: The myoexo extra that installs ``package`` (``None``: a core dependency).
        trainable: A preset can train it (the off-policy learners with SAC's interface).
    """

    name: str
    class_name: str
    package: str = "stable_baselines3"
    extra: str | None = None
    trainable: bool = False

    def load_class(self) -> Any:
        """The algorithm's class; ``ValueError`` naming the extra to install if absent."""
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
            Algorithm("sac", "SAC", trainable=True),
            Algorithm("tqc", "TQC", "sb3_contrib", "contrib", trainable=True),
            Algorithm("crossq", "CrossQ", "sb3_contrib", "contrib", trainable=True),
            Algorithm("td3", "TD3"),
            Algorithm("ddpg", "DDPG"),
            Algorithm("ppo", "PPO"),
            Algorithm("a2c", "A2C"),
        )
    }
)

#: Aliases a training preset accepts.
TRAINABLE_ALGORITHMS: tuple[str, ...] = tuple(a.name for a in ALGORITHMS.values() if a.trainable)


def get_algorithm(name: str, trainable: bool = False) -> Algorithm:
    """The :class:`Algorithm` of an alias or class name (any case).

    Raises:
        ValueError: Unknown name (or, with ``trainable``, one a preset cannot train); the
            message lists the accepted names.
    """
    accepted = TRAINABLE_ALGORITHMS if trainable else tuple(ALGORITHMS)
    key = str(name).lower()
    if key not in accepted:
        raise ValueError(f"algorithm = {name!r}; accepted: {sorted(accepted)}")
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
