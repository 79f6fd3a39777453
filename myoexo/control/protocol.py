"""The controller protocol every controller of myoexo fits.

A controller is anything with ``reset(seed)`` (start of an episode) and ``act(obs, info)``
(one control decision). ``obs`` is the env's observation vector and ``info`` the dict the
env returned with it (``env.reset`` or the previous ``env.step``), so a controller may use the
normalized observation (learned policies) or the named physical quantities of ``info``
(the PID reads ``info["knee_angle_deg"]``). ``act`` returns the normalized exo command, an
array of shape ``(1,)`` in [-1, 1] (``u * 100 Nm``, positive = flexion).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, Protocol, runtime_checkable

import numpy as np


@runtime_checkable
class Controller(Protocol):
    """Structural type of a controller (PID, SB3 policy, any ``callable(obs) -> action``)."""

    def reset(self, seed: int | None = None) -> None:
        """Clear the internal state at the start of an episode (``seed`` for stochastic
        controllers; deterministic ones ignore it)."""
        ...

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        """Return the normalized exo command, shape ``(1,)``, float32, in [-1, 1]."""
        ...
