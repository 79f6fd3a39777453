"""The controller protocol every controller of myoexo fits.

A controller is anything with ``reset(seed)`` (start of an episode) and ``act(obs,
measurements)`` (one control decision). ``obs`` is the env's observation vector (what a
learned policy reads) and ``measurements`` the frozen record of what the controller's sensors
report at that step (:class:`~myoexo.envs.sensors.Measurements`: the device's clock, the
setpoint, the exo encoder's angle and velocity, the motor torque), made from the env's
``info`` by :func:`~myoexo.envs.sensors.read_sensors`. A controller never receives ``info``:
the true state of the twin (the human knee angle that is scored, the muscles) is in no record.

A controller that needs a sensor beyond the exoskeleton's own declares it in its ``sensors``
attribute (a frozenset of :data:`~myoexo.envs.sensors.OPTIONAL_SENSORS`; none without one):
the paper's PID on the human knee declares the knee angle sensor and receives a
:class:`~myoexo.envs.sensors.KneeAngleMeasurements`. The one controller with privileged
access, :class:`~myoexo.control.oracle.OracleMPC`, reads the true state from the env it was
built on, not from its record.

``act`` returns the normalized exo command, an array of shape ``(1,)`` in [-1, 1] (``u * 100
Nm``, positive = flexion). One step of an episode, as :func:`~myoexo.control.rollout.rollout`
runs it::

    obs, info = env.reset(seed=0)
    controller.reset(seed=0)
    action = controller.act(obs, read_sensors(info, declared_sensors(controller)))
"""

from __future__ import annotations

from typing import Any, Protocol, runtime_checkable

import numpy as np

from myoexo.envs.sensors import Measurements, check_sensors


def declared_sensors(controller: Any) -> frozenset[str]:
    """The sensors *controller* declares beyond the exoskeleton's own (its ``sensors``
    attribute; none if it has none).

    Raises:
        ValueError: It declares a sensor that is not one of
            :data:`~myoexo.envs.sensors.OPTIONAL_SENSORS`.
    """
    return check_sensors(getattr(controller, "sensors", ()))


@runtime_checkable
class Controller(Protocol):
    """Structural type of a controller (PID, SB3 policy, any ``callable(obs) -> action``)."""

    def reset(self, seed: int | None = None) -> None:
        """Clear the internal state at the start of an episode (``seed`` for stochastic
        controllers; deterministic ones ignore it)."""
        ...

    def act(self, obs: np.ndarray, measurements: Measurements) -> np.ndarray:
        """Return the normalized exo command, shape ``(1,)``, float32, in [-1, 1], from the
        observation and the record of the controller's sensors."""
        ...
