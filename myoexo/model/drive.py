"""The exo drive's end-stop protection: the drive brakes before its hinge meets a stop.

The exo hinge has hard end stops (``TwinParams.exo_knee_range_deg``). A command that swings
the strapped shank into a stop at speed makes the strap stop the shank's momentum, a torque
of about ``omega sqrt(k_strap I_knee)`` above anything the motor and the muscles pass on
(:mod:`myoexo.model.strap_bound`): a 10 Hz bang-bang command reaches the flexion stop at
13 rad/s and drives the strap to 2-3 times its bound. Exoskeleton drives therefore carry
software joint limits in their firmware that slow the joint down before the mechanical stop.
This is that firmware, as the twin's drive runs it at every physics timestep (a drive's
firmware runs far faster than the 100 Hz controllers that command it):

* it plans to stop the hinge (and the shank strapped to it) with a deceleration
  ``a_brake = braking_fraction * tau_motor / (I_exo + I_knee)``, the share
  ``braking_fraction`` of the motor's own authority over both inertias (the rest is the
  margin for the leg's own torques);
* before it applies a command for the next timestep, it predicts the limb's speed ``v1``
  and the hinge's distance ``d1`` to the stop it moves towards at the timestep's end, with that
  command's acceleration ``u tau_motor / (I_exo + I_knee)``; if it could not then stop
  within ``d1``, ``v1^2 > 2 a_brake d1 + v_contact^2``, it applies full braking (``-1`` or
  ``+1``) for the timestep instead. It reads the hinge's angle from its encoder and the
  limb's speed from the shank cuff's gyroscope (the thigh is held still, so the cuff's
  sagittal rate is the knee's flexion speed): what an impact on the stop has to stop is the
  shank's momentum, and the light hinge's own speed swings with the strap's give (a command
  reversal moves it 2-3 deg in 10 ms while the shank barely moves);
* ``v_contact`` is the speed at which the drive lets the hinge touch its stop: a controller
  may still rest the exo against a stop;
* it guards a stop only where the stop lies inside the knee's own range: the exo's flexion
  stop (95 deg) halts the strapped shank before the knee's 120 deg, while at extension the
  knee's own limit (0 deg) halts it 15 deg before the exo's stop could (the paper's PID,
  saturated at 13-15 rad/s, overshoots into the knee's limit, and a guard on the extension
  stop would brake it from 40 deg on).

The protection acts only while the drive is powered (a command in the clinical tests'
unpowered phases is not one). With ``braking_fraction`` 0 the drive has no protection
(twins 1-3). Its parameters travel with the compiled model (a MuJoCo custom numeric,
:data:`STOP_PROTECTION_NUMERIC`), so every twin built from :class:`TwinParams` carries its
drive.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from myoexo.model.exo import EXO_ACTUATOR, EXO_JOINT
from myoexo.model.joint_torque import joint_inertia
from myoexo.model.leg import KNEE_JOINT

__all__ = ["STOP_PROTECTION_NUMERIC", "StopProtection", "stop_protection"]

#: Name of the model's custom numeric holding ``(braking_fraction, contact_speed_rad_s)``.
STOP_PROTECTION_NUMERIC = "exo_stop_protection"


@dataclass(frozen=True)
class StopProtection:
    """The drive's end-stop protection of one compiled twin (module docstring).

    Attributes:
        lower_rad: The hinge's extension stop, rad (``-inf``: not guarded).
        upper_rad: The hinge's flexion stop, rad (``inf``: not guarded).
        accel_per_command_rad_s2: Hinge acceleration per unit command, ``tau_motor / (I_exo +
            I_knee)``, rad/s^2.
        brake_rad_s2: The deceleration the drive plans with, rad/s^2.
        contact_speed_rad_s: The speed at which the hinge may touch a stop, rad/s.
        timestep_s: The drive's period: the physics timestep, s.
    """

    lower_rad: float
    upper_rad: float
    accel_per_command_rad_s2: float
    brake_rad_s2: float
    contact_speed_rad_s: float
    timestep_s: float

    def __post_init__(self) -> None:
        if not self.lower_rad < self.upper_rad:
            raise ValueError(f"StopProtection needs lower_rad < upper_rad, got {self!r}")
        for name in ("accel_per_command_rad_s2", "brake_rad_s2", "timestep_s"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"StopProtection.{name} must be > 0, got {value!r}")
        if not (math.isfinite(self.contact_speed_rad_s) and self.contact_speed_rad_s >= 0.0):
            raise ValueError(
                f"StopProtection.contact_speed_rad_s must be >= 0, got {self.contact_speed_rad_s!r}"
            )

    def _overruns(
        self, distance_rad: float, speed_rad_s: float, accel_rad_s2: float, time_s: float
    ) -> bool:
        """Whether, moving towards a stop *distance_rad* away at *speed_rad_s* (> 0:
        towards it) and accelerating at *accel_rad_s2* for *time_s*, the hinge could no
        longer stop before it at the planned deceleration (or touch it gently)."""
        v1 = speed_rad_s + accel_rad_s2 * time_s
        if v1 <= self.contact_speed_rad_s:
            return False
        d1 = distance_rad - (speed_rad_s + 0.5 * accel_rad_s2 * time_s) * time_s
        return v1 * v1 > 2.0 * self.brake_rad_s2 * max(d1, 0.0) + self.contact_speed_rad_s**2

    def near(self, angle_rad: float, velocity_rad_s: float, period_s: float) -> bool:
        """Whether the drive may have to brake within the next *period_s* (*angle_rad*: the
        hinge's; *velocity_rad_s*: the limb's flexion speed): the hinge,
        accelerated at twice the motor's authority (the motor and as much again from the
        leg), could reach its braking curve. Away from it every command passes unchanged."""
        a = 2.0 * self.accel_per_command_rad_s2
        return self._overruns(
            self.upper_rad - angle_rad, velocity_rad_s, a, period_s
        ) or self._overruns(angle_rad - self.lower_rad, -velocity_rad_s, a, period_s)

    def command(self, angle_rad: float, velocity_rad_s: float, command: float) -> float:
        """The command the drive applies for the next physics timestep: *command*, or full
        braking (``-1`` towards the flexion stop, ``+1`` towards the extension stop) when
        *command* would carry the hinge at *angle_rad*, with the limb moving at
        *velocity_rad_s* (its flexion speed), past its braking curve."""
        accel = command * self.accel_per_command_rad_s2
        t = self.timestep_s
        if command > -1.0 and self._overruns(self.upper_rad - angle_rad, velocity_rad_s, accel, t):
            return -1.0
        if command < 1.0 and self._overruns(angle_rad - self.lower_rad, -velocity_rad_s, -accel, t):
            return 1.0
        return command


def stop_protection(model: mujoco.MjModel) -> StopProtection | None:
    """The drive's protection of the compiled twin *model* (``None``: the model's drive has
    none, its braking fraction is 0 or absent, or neither stop lies inside the knee's range).
    The inertias are the model's at its reference pose."""
    try:
        fraction, contact_speed = (float(v) for v in model.numeric(STOP_PROTECTION_NUMERIC).data)
    except KeyError:
        return None
    if fraction <= 0.0:
        return None
    data = mujoco.MjData(model)
    mujoco.mj_forward(model, data)
    inertia = joint_inertia(model, data, EXO_JOINT) + joint_inertia(model, data, KNEE_JOINT)
    motor = model.actuator(EXO_ACTUATOR)
    motor_nm = float(np.max(np.abs(motor.forcerange)))
    lower, upper = (float(v) for v in model.jnt_range[model.joint(EXO_JOINT).id])
    knee_lower, knee_upper = (float(v) for v in model.jnt_range[model.joint(KNEE_JOINT).id])
    # a stop beyond the knee's own limit is never what halts the strapped shank
    lower = lower if lower > knee_lower else -math.inf
    upper = upper if upper < knee_upper else math.inf
    if math.isinf(lower) and math.isinf(upper):
        return None
    accel = motor_nm / inertia
    return StopProtection(
        lower_rad=lower,
        upper_rad=upper,
        accel_per_command_rad_s2=accel,
        brake_rad_s2=fraction * accel,
        contact_speed_rad_s=contact_speed,
        timestep_s=float(model.opt.timestep),
    )
