"""Impedance controller: a virtual spring-damper pulling the knee along a minimum-jerk
reference (the exoskeleton field's "compliant controller").

The exo behaves as a spring of stiffness ``K`` and a damper ``D`` attached to a moving
reference ``r(t)``: at every step

    torque = K (r - angle) + D (dr/dt - velocity),    command = torque / motor torque,

clipped at ``output_limit`` (the command in [-1, 1], ``u * 100 Nm``, positive = flexion: the
sign convention of :mod:`myoexo.control.pid`, ``r - angle`` negative while the knee is still
flexed above the reference, an extending torque). The reference is the minimum-jerk move
(:mod:`myoexo.control.reference`, Flash and Hogan 1985) from the angle measured at the first
step to the target over ``duration_s`` seconds of the controller's own clock (the time since
the command began; no episode clock), then the target. Angles and velocities are those of
the feedback sensor: the human knee's angle sensor (``feedback="knee"``, declared, as the
paper's PID) or the exo encoder (``"exo"``, the device's own).

There is no integral term: the knee settles where the spring balances what resists it (the
limb's weight, the spastic muscles), ``resisting torque / K`` short of the target. That is
the price of compliance, and what a learned controller must beat on both torque and error.

Defaults: the paper's PID read as a spring-damper (:class:`ImpedanceConfig`): ``K = Kp x
100 Nm = 700 Nm/rad`` and ``D = Kd x 100 Nm = 5 Nm s/rad`` (Kp = 7 /rad and Kd = 0.05 s/rad
act on the normalized command, 1 = the 100 Nm motor), a 1 s move (the MAS exam's "about one
second" through the range, :mod:`myoexo.clinical.mas`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from myoexo.control.pid import FEEDBACK_SENSORS, feedback_angle_deg, feedback_velocity_deg_s
from myoexo.control.reference import reference_point
from myoexo.envs.sensors import Measurements
from myoexo.runtime.fields import check_fields, option

#: The motor's peak torque (Nm) the normalized command is a fraction of: the paper's 100 Nm
#: (:attr:`myoexo.model.params.TwinParams.motor_limit_nm`).
MOTOR_TORQUE_NM = 100.0
#: The shape of the impedance controller's reference.
REFERENCE_SHAPE = "minjerk"


@dataclass(frozen=True)
class ImpedanceConfig:
    """The impedance controller's settings (defaults: the paper's PID as a spring-damper).

    Attributes:
        stiffness_nm_per_rad: The virtual spring ``K`` (Nm/rad); default the paper's Kp = 7
            per rad times the 100 Nm motor.
        damping_nm_s_per_rad: The virtual damper ``D`` (Nm s/rad); default the paper's Kd =
            0.05 s/rad times the 100 Nm motor.
        duration_s: Duration of the minimum-jerk reference from the first measured angle to
            the target (0: a step to the target).
        feedback: ``"knee"`` (the human knee's angle sensor, declared) or ``"exo"`` (the exo
            encoder), as :attr:`~myoexo.control.pid.PIDConfig.feedback`.
        output_limit: Saturation of the command (1 = the motor's full torque).
        motor_torque_nm: The torque of a command of 1 (Nm): the motor's peak torque.
    """

    stiffness_nm_per_rad: float = option(
        700.0,
        "virtual spring stiffness K (the paper's Kp = 7 x 100 Nm)",
        low=0.0,
        above=True,
        unit="Nm/rad",
    )
    damping_nm_s_per_rad: float = option(
        5.0, "virtual damping D (the paper's Kd = 0.05 x 100 Nm)", low=0.0, unit="Nm s/rad"
    )
    duration_s: float = option(
        1.0,
        "duration of the minimum-jerk reference to the target",
        low=0.0,
        high=60.0,
        unit="s",
    )
    feedback: str = option("knee", "the angle the spring acts on", choices=tuple(FEEDBACK_SENSORS))
    output_limit: float = option(
        1.0, "saturation of the command (x the motor torque)", low=0.0, above=True, high=1.0
    )
    motor_torque_nm: float = option(
        MOTOR_TORQUE_NM, "the torque of a command of 1", low=0.0, above=True, unit="Nm"
    )

    def __post_init__(self) -> None:
        check_fields(self)


class ImpedanceController:
    """Spring-damper on a minimum-jerk reference (module docstring); fits
    :class:`~myoexo.control.protocol.Controller`.

    Args:
        config: Stiffness, damping, reference duration, feedback (:class:`ImpedanceConfig`).
        dt_s: Sample time (s): the env's control period ``env.unwrapped.dt`` (the
            controller's clock advances by it at every step).

    Example:
        >>> imp = ImpedanceController.from_env(env)
        >>> imp.reset()
        >>> obs, info = env.reset(seed=0)
        >>> obs, *_, info = env.step(imp.act(obs, read_sensors(info, imp.sensors)))
    """

    def __init__(self, config: ImpedanceConfig | None = None, dt_s: float = 0.01) -> None:
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s = {dt_s!r} must be a positive sample time in seconds")
        self.config = config if config is not None else ImpedanceConfig()
        self.dt_s = float(dt_s)
        self.reset()

    @classmethod
    def from_env(cls, env: Any, config: ImpedanceConfig | None = None) -> ImpedanceController:
        """Controller sampled at the env's control period (``env.unwrapped.dt``)."""
        return cls(config=config, dt_s=float(env.unwrapped.dt))

    def reset(self, seed: int | None = None) -> None:
        """Restart the clock and forget the start angle (``seed`` is unused)."""
        del seed
        self._start_rad: float | None = None
        self._steps = 0
        #: The last output's terms: ``reference_deg``, ``spring_nm``, ``damper_nm``,
        #: ``torque_nm`` (before the clip).
        self.last_terms: dict[str, float] = {}

    @property
    def sensors(self) -> frozenset[str]:
        """The sensors it declares: the knee angle sensor with ``feedback="knee"``, none
        (the exo encoder is the device's own) with ``"exo"``."""
        return FEEDBACK_SENSORS[self.config.feedback]

    def update(self, target_rad: float, angle_rad: float, velocity_rad_s: float) -> float:
        """One sample: the clipped command from the target and the feedback's angle and
        velocity (rad, rad/s); the first sample's angle starts the reference."""
        cfg = self.config
        if self._start_rad is None:
            self._start_rad = angle_rad
        elapsed_s = self._steps * self.dt_s
        self._steps += 1
        ref = reference_point(
            REFERENCE_SHAPE, self._start_rad, target_rad, elapsed_s, cfg.duration_s
        )
        spring = cfg.stiffness_nm_per_rad * (ref.angle - angle_rad)
        damper = cfg.damping_nm_s_per_rad * (ref.velocity - velocity_rad_s)
        torque = spring + damper
        self.last_terms = {
            "reference_deg": math.degrees(ref.angle),
            "spring_nm": spring,
            "damper_nm": damper,
            "torque_nm": torque,
        }
        lim = cfg.output_limit
        return min(lim, max(-lim, torque / cfg.motor_torque_nm))

    def act(self, obs: np.ndarray, measurements: Measurements) -> np.ndarray:
        """Command from the record's setpoint and feedback angle and velocity (deg, deg/s)."""
        del obs
        feedback = self.config.feedback
        u = self.update(
            math.radians(measurements.setpoint_deg),
            math.radians(feedback_angle_deg(measurements, feedback)),
            math.radians(feedback_velocity_deg_s(measurements, feedback)),
        )
        return np.array([u], dtype=np.float32)

    def __repr__(self) -> str:
        c = self.config
        return (
            f"ImpedanceController(stiffness_nm_per_rad={c.stiffness_nm_per_rad}, "
            f"damping_nm_s_per_rad={c.damping_nm_s_per_rad}, duration_s={c.duration_s}, "
            f"feedback={c.feedback!r}, output_limit={c.output_limit}, "
            f"motor_torque_nm={c.motor_torque_nm}, dt_s={self.dt_s})"
        )
