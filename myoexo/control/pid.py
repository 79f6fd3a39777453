"""PID position controller of the paper's baseline (docs/reference.md section 4).

The controller acts on the knee position error in **radians** and outputs the normalized exo
command in [-1, 1] (``u * 100 Nm``, positive = flexion torque). With the paper's gains
(Kp = 7, Ki = 40, Kd = 0.05, Ziegler-Nichols tuned at level 1) an error of 1 rad asks for
7 x 100 Nm, so the motor saturates for errors above ~8 deg: the 83 deg extension starts
saturated and the PID only leaves saturation near the target.

Sign convention. The control error is the textbook ``e = r - y`` (setpoint minus
measurement), i.e. ``e = target - knee``: negative while the knee is still flexed above the
target, which is the *opposite* sign of the env's ``info["error_deg"]`` (``knee - target``,
positive while flexed). A positive gain on ``e`` therefore commands extension (a negative,
extending torque) while the knee is flexed, as it must.

Two standard refinements are on by default and can be switched off to get the textbook
parallel PID ``u = Kp e + Ki int(e) dt + Kd de/dt``
(:meth:`PIDConfig.textbook`):

* **Derivative on measurement** (Astrom & Hagglund, *Advanced PID Control*, ISA 2006,
  sec. 3.4): the derivative term is ``-Kd dy/dt`` instead of ``Kd de/dt``. Both are equal
  while the setpoint is constant; the former has no "derivative kick" when it changes.
* **Anti-windup** at the +-1 saturation (ibid., sec. 3.5): ``"clamping"`` (conditional
  integration: the integrator is frozen while the output is saturated and the error would
  drive it deeper into saturation) or ``"back_calculation"`` (the integrator is driven back
  by ``(u_sat - u) / Tt`` with tracking time ``Tt``; default ``Tt = sqrt(Ti Td)``, Astrom &
  Hagglund's rule, with ``Ti = Kp / Ki`` and ``Td = Kd / Kp``).

Two ways to start gently, for the torque-versus-settling trade-off (the cheap baselines of a
learned controller): a **ramped setpoint** (``ramp_s``: the setpoint moves from the angle
measured at the first step to the target over ``ramp_s`` seconds of the controller's own
clock, the time since the command began; no episode clock) and a **clipped command**
(``output_limit`` < 1: at most that fraction of the 100 Nm). The ramp's shape is
``reference`` (:mod:`myoexo.control.reference`): ``"linear"`` (constant speed, the default)
or ``"minjerk"`` (minimum jerk, ``s = 10 u^3 - 15 u^4 + 6 u^5``, Flash and Hogan 1985: it
starts and ends at rest, the bell-shaped speed of a human movement). A ramp can give way to
the step where the leg resists it (``step_lag_deg``): once the knee lags the ramp's point by
more than that angle, further from the target, the setpoint is the target for the rest of
the motion, so a ramp that is gentle where nothing resists pushes as the paper's PID does
where a spastic reflex holds the knee back.

Discretization at the env's control period ``dt``: backward-Euler integral and backward
difference derivative, no derivative filter (Kd is small); the derivative is zero on the
first step of an episode (no previous sample).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from myoexo.control.reference import REFERENCE_SHAPES, reference_point
from myoexo.envs.sensors import KNEE_ANGLE_SENSOR, KneeAngleMeasurements, Measurements

#: Accepted anti-windup schemes.
ANTI_WINDUP_SCHEMES: tuple[str, ...] = ("clamping", "back_calculation", "none")

#: Accepted feedback signals -> the sensors (beyond the exoskeleton's own) each needs: the
#: human knee's angle sensor (:data:`~myoexo.envs.sensors.KNEE_ANGLE_SENSOR`) or none (the
#: exo encoder is the device's own).
FEEDBACK_SENSORS: dict[str, frozenset[str]] = {
    "knee": frozenset({KNEE_ANGLE_SENSOR}),
    "exo": frozenset(),
}


def feedback_angle_deg(measurements: Measurements, feedback: str) -> float:
    """The *feedback* angle (deg) in a sensor record: the knee angle sensor's reading
    (``"knee"``) or the exo encoder's (``"exo"``), as the sensors report them (noisy and late
    on a perturbed twin, :mod:`myoexo.envs.robustness`).

    Raises:
        ValueError: ``"knee"`` and the record has no knee angle sensor.
    """
    if feedback == "exo":
        return measurements.exo_angle_deg
    return _knee_record(measurements).knee_angle_deg


def feedback_velocity_deg_s(measurements: Measurements, feedback: str) -> float:
    """The *feedback* angular velocity (deg/s) in a sensor record: the knee angle sensor's
    (``"knee"``) or the exo encoder's (``"exo"``), as :func:`feedback_angle_deg` reads the
    angle.

    Raises:
        ValueError: ``"knee"`` and the record has no knee angle sensor.
    """
    if feedback == "exo":
        return measurements.exo_velocity_deg_s
    return _knee_record(measurements).knee_velocity_deg_s


def _knee_record(measurements: Measurements) -> KneeAngleMeasurements:
    if not isinstance(measurements, KneeAngleMeasurements):
        raise ValueError(
            f"knee feedback needs the knee angle sensor ({KNEE_ANGLE_SENSOR!r}); the record "
            f"holds the exoskeleton's sensors only ({type(measurements).__name__})"
        )
    return measurements


@dataclass(frozen=True)
class PIDGains:
    """Parallel-form PID gains on the knee error in radians, output in the normalized command.

    Attributes:
        kp: Proportional gain (1/rad). Paper: 7.
        ki: Integral gain (1/(rad s)). Paper: 40.
        kd: Derivative gain (s/rad). Paper: 0.05.
    """

    kp: float = 7.0
    ki: float = 40.0
    kd: float = 0.05

    def __post_init__(self) -> None:
        for name in ("kp", "ki", "kd"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"PIDGains.{name} = {value!r} must be finite and >= 0")


@dataclass(frozen=True)
class PIDConfig:
    """Structure of the PID (defaults: the paper's gains, the two refinements on).

    Attributes:
        gains: The three gains.
        derivative_on_measurement: ``-Kd dy/dt`` (True) or ``Kd de/dt`` (False).
        anti_windup: One of :data:`ANTI_WINDUP_SCHEMES`.
        tracking_time_s: Back-calculation tracking time ``Tt`` (s); ``None`` = ``sqrt(Ti Td)``
            (``Ti`` alone when Kd = 0). Ignored by the other schemes.
        output_limit: Saturation of the command (the env's action bound, 1 = 100 Nm).
        feedback: ``"knee"`` (the human knee angle, read by a knee angle sensor the PID
            declares; the paper's reading) or ``"exo"`` (the exo joint encoder, what a real
            device measures; it differs from the human knee by the strap misalignment).
        ramp_s: Duration (s) of the setpoint's ramp from the first measured angle to the
            target (0: the paper's step).
        reference: Shape of that ramp, one of
            :data:`~myoexo.control.reference.REFERENCE_SHAPES`: ``"linear"`` (constant
            speed) or ``"minjerk"`` (minimum jerk: at rest at both ends). Ignored without a
            ramp.
        step_lag_deg: With a ramp: the lag (deg, the feedback angle behind the ramp's point,
            away from the target) beyond which the setpoint steps to the target for the rest
            of the motion (``None``: it follows the ramp).
    """

    gains: PIDGains = field(default_factory=PIDGains)
    derivative_on_measurement: bool = True
    anti_windup: str = "clamping"
    tracking_time_s: float | None = None
    output_limit: float = 1.0
    feedback: str = "knee"
    ramp_s: float = 0.0
    reference: str = "linear"
    step_lag_deg: float | None = None

    def __post_init__(self) -> None:
        if self.step_lag_deg is not None:
            if not (math.isfinite(self.step_lag_deg) and 0.0 < self.step_lag_deg <= 180.0):
                raise ValueError(
                    f"PIDConfig.step_lag_deg = {self.step_lag_deg!r} is outside (0, 180] deg"
                )
            if self.ramp_s <= 0.0:
                raise ValueError(
                    f"PIDConfig.step_lag_deg = {self.step_lag_deg!r} needs a ramp (ramp_s > 0)"
                )
        if not (math.isfinite(self.ramp_s) and 0.0 <= self.ramp_s <= 60.0):
            raise ValueError(f"PIDConfig.ramp_s = {self.ramp_s!r} is outside [0, 60] s")
        if self.reference not in REFERENCE_SHAPES:
            raise ValueError(
                f"PIDConfig.reference = {self.reference!r}; accepted: {REFERENCE_SHAPES}"
            )
        if self.anti_windup not in ANTI_WINDUP_SCHEMES:
            raise ValueError(
                f"PIDConfig.anti_windup = {self.anti_windup!r}; accepted: {ANTI_WINDUP_SCHEMES}"
            )
        if self.feedback not in FEEDBACK_SENSORS:
            raise ValueError(
                f"PIDConfig.feedback = {self.feedback!r}; accepted: {tuple(FEEDBACK_SENSORS)}"
            )
        if not (math.isfinite(self.output_limit) and 0.0 < self.output_limit <= 1.0):
            raise ValueError(
                f"PIDConfig.output_limit = {self.output_limit!r} is outside (0, 1] (x 100 Nm)"
            )
        if self.tracking_time_s is not None and not (
            math.isfinite(self.tracking_time_s) and self.tracking_time_s > 0.0
        ):
            raise ValueError(
                f"PIDConfig.tracking_time_s = {self.tracking_time_s!r} must be > 0 or None"
            )

    @classmethod
    def textbook(cls, gains: PIDGains | None = None, **overrides: Any) -> PIDConfig:
        """Plain parallel PID: derivative on error, no anti-windup (output still clipped)."""
        return cls(
            gains=gains or PIDGains(),
            derivative_on_measurement=False,
            anti_windup="none",
            **overrides,
        )

    def with_gains(self, kp: float, ki: float, kd: float) -> PIDConfig:
        """Copy with other gains."""
        return replace(self, gains=PIDGains(kp=kp, ki=ki, kd=kd))

    @property
    def effective_tracking_time_s(self) -> float:
        """The back-calculation tracking time actually used (s)."""
        if self.tracking_time_s is not None:
            return self.tracking_time_s
        g = self.gains
        if g.ki == 0.0 or g.kp == 0.0:
            return math.inf  # no integrator (or no scale for it): nothing to track
        ti = g.kp / g.ki
        td = g.kd / g.kp
        return math.sqrt(ti * td) if td > 0.0 else ti


class PID:
    """Discrete PID on the knee angle; fits :class:`~myoexo.control.protocol.Controller`.

    Args:
        config: Gains and structure (:class:`PIDConfig`).
        dt_s: Sample time (s): the env's control period ``env.unwrapped.dt``.

    Example:
        >>> pid = PID.from_env(env)
        >>> pid.reset()
        >>> obs, info = env.reset(seed=0)
        >>> obs, *_, info = env.step(pid.act(obs, read_sensors(info, pid.sensors)))
    """

    def __init__(self, config: PIDConfig | None = None, dt_s: float = 0.01) -> None:
        if not (math.isfinite(dt_s) and dt_s > 0.0):
            raise ValueError(f"dt_s = {dt_s!r} must be a positive sample time in seconds")
        self.config = config if config is not None else PIDConfig()
        self.dt_s = float(dt_s)
        self.reset()

    @classmethod
    def from_env(cls, env: Any, config: PIDConfig | None = None) -> PID:
        """PID sampled at the env's control period (``env.unwrapped.dt``)."""
        return cls(config=config, dt_s=float(env.unwrapped.dt))

    def reset(self, seed: int | None = None) -> None:
        """Zero the integrator and forget the previous sample (``seed`` is unused)."""
        del seed
        self._integral = 0.0  # integral term, already multiplied by Ki (command units)
        self._prev_error_rad: float | None = None
        self._prev_measurement_rad: float | None = None
        self._ramp_start_rad: float | None = None  # first measured angle (ramped setpoint)
        self._stepped = False  # the ramp gave way to the target (``step_lag_deg``)
        self._steps = 0
        #: The last output's terms (command units): ``p``, ``i``, ``d``, ``unsaturated``.
        self.last_terms: dict[str, float] = {}

    def update(self, setpoint_rad: float, measurement_rad: float) -> float:
        """One sample: error ``e = setpoint - measurement`` (rad) -> saturated command."""
        cfg, g, dt = self.config, self.config.gains, self.dt_s
        error = setpoint_rad - measurement_rad
        p = g.kp * error
        if self._prev_measurement_rad is None or self._prev_error_rad is None:
            d = 0.0
        elif cfg.derivative_on_measurement:
            d = -g.kd * (measurement_rad - self._prev_measurement_rad) / dt
        else:
            d = g.kd * (error - self._prev_error_rad) / dt
        integral = self._integral + g.ki * error * dt
        unsaturated = p + integral + d
        lim = cfg.output_limit
        u = min(lim, max(-lim, unsaturated))

        if cfg.anti_windup == "clamping" and u != unsaturated and error * unsaturated > 0.0:
            integral = self._integral  # saturated and pushing further in: freeze
        elif cfg.anti_windup == "back_calculation":
            tt = cfg.effective_tracking_time_s
            if math.isfinite(tt):
                integral += dt / tt * (u - unsaturated)
        self._integral = integral
        self._prev_error_rad = error
        self._prev_measurement_rad = measurement_rad
        self.last_terms = {"p": p, "i": integral, "d": d, "unsaturated": unsaturated}
        return u

    @property
    def sensors(self) -> frozenset[str]:
        """The sensors it declares: the knee angle sensor with ``feedback="knee"``, none
        (the exo encoder is the device's own) with ``"exo"``."""
        return FEEDBACK_SENSORS[self.config.feedback]

    def act(self, obs: np.ndarray, measurements: Measurements) -> np.ndarray:
        """Command from the record's setpoint and feedback angle (deg)."""
        del obs
        target_deg = measurements.setpoint_deg
        measured_deg = feedback_angle_deg(measurements, self.config.feedback)
        setpoint_rad = self.setpoint_rad(math.radians(target_deg), math.radians(measured_deg))
        u = self.update(setpoint_rad, math.radians(measured_deg))
        return np.array([u], dtype=np.float32)

    def setpoint_rad(self, target_rad: float, measured_rad: float) -> float:
        """The setpoint of this step: the target, or with ``ramp_s`` > 0 the point of the
        ramp (of shape ``reference``) from the first measured angle, until the measured angle
        lags it by more than ``step_lag_deg`` (the step counter advances by one)."""
        cfg = self.config
        self._steps += 1
        if cfg.ramp_s <= 0.0 or self._stepped:
            return target_rad
        start = self._ramp_start_rad
        if start is None:
            start = self._ramp_start_rad = measured_rad
        elapsed_s = (self._steps - 1) * self.dt_s
        point = reference_point(cfg.reference, start, target_rad, elapsed_s, cfg.ramp_s).angle
        lag = cfg.step_lag_deg
        if lag is not None and (measured_rad - point) * math.copysign(
            1.0, start - target_rad
        ) > math.radians(lag):
            self._stepped = True
            return target_rad
        return point

    def __repr__(self) -> str:
        g = self.config.gains
        return (
            f"PID(kp={g.kp}, ki={g.ki}, kd={g.kd}, dt_s={self.dt_s}, "
            f"feedback={self.config.feedback!r}, anti_windup={self.config.anti_windup!r}, "
            f"derivative_on_measurement={self.config.derivative_on_measurement}, "
            f"output_limit={self.config.output_limit}, ramp_s={self.config.ramp_s}, "
            f"reference={self.config.reference!r}, step_lag_deg={self.config.step_lag_deg})"
        )
