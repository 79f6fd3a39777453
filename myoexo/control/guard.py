"""A stated safety layer for learned controllers: integral action once the knee stalls far
from the target (``guard:SPEC``, e.g. ``myoexo evaluate --controllers guard:sac``).

Why it exists. The full-state SAC policy reads the spastic muscles' activations and forces.
It has learned to ease off while they are high, which spares the interaction torque during
a catch. On a subject whose reflex stays active at rest (a threshold near the start angle),
easing off is a fixed point of the closed loop: the muscles hold the knee, the policy keeps
its command small because they do, and the knee stays 50-70 deg from the target for the
whole episode, where the paper's PID, whose integrator keeps pushing, ends within its usual
error. Replacing the muscle observations of such a state by their training means turns the
policy's command from about -0.16 to about -0.7 (the diagnosis is in the model card). A
policy has no integral action unless it learned one; this layer adds one, only where the
policy has stalled.

What it does. :class:`StallGuard` wraps any controller. It does nothing until, after
``engage_after_s``, the measured knee error exceeds ``engage_error_deg``; from then on, for
the rest of the episode, it adds an integral term to the controller's command,
``I += -ki * error * dt`` (error in rad, knee minus target; a negative command extends),
with conditional integration (the term stops growing while the summed command is saturated
in the same direction) and the sum clipped to the motor's range. It reads the knee as the
PID does (``info["measured_knee_angle_deg"]``, noisy and late on a perturbed twin, else
``info["knee_angle_deg"]``), so it needs what the wrapped full-state policy already needs; a
controller that reads only the exoskeleton's sensors gets a guard on the exo encoder
(``feedback="exo"``), the one angle it has. A
controller that never stalls beyond ``engage_error_deg`` is unchanged, command for command.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from myoexo.control.pid import FEEDBACK_KEYS, sensed_angle_deg
from myoexo.control.protocol import Controller


@dataclass(frozen=True)
class StallGuardConfig:
    """When the guard engages and how hard it pushes.

    Attributes:
        engage_error_deg: |knee - target| (deg) beyond which it engages: above the paper's
            PID's worst subject on the nominal twin at any level (15.6 deg at level 3), so
            it never acts where the PID itself stops short, below the 20 deg that counts as
            a catastrophic subject.
        engage_after_s: It may engage only after this time in the episode (s): the
            extension of 83 deg takes the paper's PID 1-2 s.
        ki_per_rad_s: Integral gain (command per rad per s): from a 60 deg stall the term
            reaches the motor's full torque in about 0.25 s.
        control_period_s: The controller's step (s).
        feedback: The angle it reads: ``"knee"`` (the human knee, as a full-state policy
            reads it) or ``"exo"`` (the exo encoder, all a device controller has; the knee
            error is then estimated by the encoder's).
    """

    engage_error_deg: float = 17.0
    engage_after_s: float = 2.0
    ki_per_rad_s: float = 4.0
    control_period_s: float = 0.01
    feedback: str = "knee"

    def __post_init__(self) -> None:
        if self.feedback not in FEEDBACK_KEYS:
            raise ValueError(f"feedback = {self.feedback!r}; accepted: {sorted(FEEDBACK_KEYS)}")
        for name, low, high in (
            ("engage_error_deg", 0.0, 180.0),
            ("engage_after_s", 0.0, 1e4),
            ("ki_per_rad_s", 0.0, 1e4),
            ("control_period_s", 1e-4, 1.0),
        ):
            value = float(getattr(self, name))
            if not (math.isfinite(value) and low <= value <= high):
                raise ValueError(
                    f"{name} = {value!r} is outside the accepted range [{low}, {high}]"
                )


class StallIntegrator:
    """The guard's integral action on its own, fed the error each control step: what
    :class:`StallGuard` adds to a controller, and what a labelling expert adds to its labels
    (:class:`myoexo.studies.distill.Expert`, on the true knee error).

    Attributes:
        engaged_at_s: Episode time (s) the guard engaged, ``None`` while it has not.
        integral: The integral term (command units) of the last step.
    """

    def __init__(self, config: StallGuardConfig | None = None) -> None:
        self.config = config or StallGuardConfig()
        self.engaged_at_s: float | None = None
        self.integral = 0.0
        self._steps = 0

    def reset(self, seed: int | None = None) -> None:
        """Disengage (an episode starts)."""
        self.engaged_at_s = None
        self.integral = 0.0
        self._steps = 0

    def correct(self, u: np.ndarray, error_rad: float) -> np.ndarray:
        """Command *u* of this control step plus the integral term once engaged, given the
        knee error (knee minus target, rad); advances the guard's clock by one step."""
        u = np.asarray(u, dtype=np.float32).reshape(1)
        c = self.config
        t_s = self._steps * c.control_period_s
        self._steps += 1
        if self.engaged_at_s is None:
            if t_s < c.engage_after_s or abs(math.degrees(error_rad)) <= c.engage_error_deg:
                return u
            self.engaged_at_s = t_s
        step = -c.ki_per_rad_s * error_rad * c.control_period_s
        total = float(u[0]) + self.integral
        if not ((total >= 1.0 and step > 0.0) or (total <= -1.0 and step < 0.0)):
            self.integral += step
        return np.array([np.clip(float(u[0]) + self.integral, -1.0, 1.0)], dtype=np.float32)


class StallGuard(StallIntegrator):
    """*controller* with the stall guard on top (see the module docstring): its
    :class:`StallIntegrator` fed the error of the angle it reads from ``info``."""

    def __init__(self, controller: Controller, config: StallGuardConfig | None = None) -> None:
        super().__init__(config)
        self.controller = controller

    def reset(self, seed: int | None = None) -> None:
        """Reset the wrapped controller and disengage."""
        self.controller.reset(seed)
        super().reset(seed)

    def act(self, obs: np.ndarray, info: Mapping[str, Any]) -> np.ndarray:
        """The wrapped controller's command, plus the integral term once engaged."""
        u = self.controller.act(obs, info)
        try:
            angle_deg = sensed_angle_deg(info, self.config.feedback)
            error_rad = math.radians(angle_deg - float(info["target_angle_deg"]))
        except KeyError as exc:
            raise ValueError(
                f"StallGuard.act needs info[{exc.args[0]!r}] (the MyoExoKnee info dict)"
            ) from None
        return self.correct(u, error_rad)

    def __repr__(self) -> str:
        return f"StallGuard({self.controller!r}, {self.config})"
