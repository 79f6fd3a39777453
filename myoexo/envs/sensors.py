"""What a controller's sensors give it: the frozen records :class:`Measurements` and
:class:`KneeAngleMeasurements`.

The env's ``info`` holds the twin's whole state, the true human knee angle among it. A
controller reads none of it: its ``act(obs, measurements)`` receives the observation vector
and one record, made by :func:`read_sensors` from the env's ``info`` for the sensors the
controller declares (its ``sensors`` attribute, :func:`myoexo.control.protocol.declared_sensors`).

* The exoskeleton's own sensors are in every record (:class:`Measurements`): the device's
  clock, the setpoint, the exo joint encoder (angle and velocity) and the motor torque
  estimate.
* A knee angle sensor (:data:`KNEE_ANGLE_SENSOR`: a goniometer on the human leg, not part of
  the device) is in the record only of a controller that declares it: the paper's PID closes
  its loop on it. That controller receives a :class:`KneeAngleMeasurements`; every other one
  a plain :class:`Measurements`, which has no knee field at all.

Sensor readings are what the env's sensor model reports (``info["measured_*"]``): the twin's
state on the nominal twin, noisy and 10 ms late on a perturbed one
(:mod:`myoexo.envs.robustness`). The clock and the setpoint are exact. No record holds the
true state that the metrics score.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass
from typing import Any

#: The knee angle sensor: a goniometer on the human knee (angle and its velocity), what the
#: paper's PID reads. Only a controller that declares it gets its readings.
KNEE_ANGLE_SENSOR = "knee_angle"
#: The sensors a controller may declare beyond the exoskeleton's own (which every record
#: holds).
OPTIONAL_SENSORS: frozenset[str] = frozenset({KNEE_ANGLE_SENSOR})


@dataclass(frozen=True, slots=True)
class Measurements:
    """What the exoskeleton's own sensors report at one control step.

    Attributes:
        time_s: The device's clock: time since the episode began (s).
        setpoint_deg: The target knee flexion (deg).
        exo_angle_deg: The exo joint encoder's angle (deg, flexion positive).
        exo_velocity_deg_s: The encoder's angular velocity (deg/s).
        exo_torque_nm: The motor torque estimate (Nm, flexion positive).
    """

    time_s: float
    setpoint_deg: float
    exo_angle_deg: float
    exo_velocity_deg_s: float
    exo_torque_nm: float


@dataclass(frozen=True, slots=True)
class KneeAngleMeasurements(Measurements):
    """The exoskeleton's sensors and the declared knee angle sensor (:data:`KNEE_ANGLE_SENSOR`).

    Attributes:
        knee_angle_deg: The knee angle sensor's reading (deg, 0 = full extension).
        knee_velocity_deg_s: Its angular velocity (deg/s).
    """

    knee_angle_deg: float
    knee_velocity_deg_s: float


def device_measurements(measurements: Measurements) -> Measurements:
    """The exoskeleton's own sensors of a record (a plain :class:`Measurements`): what a
    controller that declares no other sensor may receive."""
    m = measurements
    return Measurements(
        m.time_s, m.setpoint_deg, m.exo_angle_deg, m.exo_velocity_deg_s, m.exo_torque_nm
    )


def check_sensors(sensors: Collection[str]) -> frozenset[str]:
    """*sensors* as a frozenset.

    Raises:
        ValueError: A sensor is not one of :data:`OPTIONAL_SENSORS`.
    """
    out = frozenset(sensors)
    unknown = out - OPTIONAL_SENSORS
    if unknown:
        raise ValueError(
            f"unknown sensors {sorted(unknown)}; a controller may declare "
            f"{sorted(OPTIONAL_SENSORS)}"
        )
    return out


def read_sensors(info: Mapping[str, Any], sensors: Collection[str] = frozenset()) -> Measurements:
    """The record of *sensors* (and the exoskeleton's own) from a MyoExoKnee env's ``info``
    (``env.reset`` or ``env.step``): a :class:`KneeAngleMeasurements` if *sensors* holds
    :data:`KNEE_ANGLE_SENSOR`, else a :class:`Measurements`.

    Raises:
        ValueError: An unknown sensor, or ``info`` lacks a reading.
    """
    try:
        device = (
            float(info["time_s"]),
            float(info["target_angle_deg"]),
            float(info["measured_exo_angle_deg"]),
            float(info["measured_exo_velocity_deg_s"]),
            float(info["measured_exo_torque_nm"]),
        )
        if KNEE_ANGLE_SENSOR in check_sensors(sensors):
            return KneeAngleMeasurements(
                *device,
                float(info["measured_knee_angle_deg"]),
                float(info["measured_knee_velocity_deg_s"]),
            )
    except KeyError as exc:
        raise ValueError(
            f"read_sensors needs info[{exc.args[0]!r}] (a MyoExoKnee env's info); got keys "
            f"{sorted(info)}"
        ) from None
    return Measurements(*device)
