"""A reflex model of one's own: a purely velocity-dependent stretch reflex.

Each muscle group fires with the speed at which it is stretched, above a threshold: knee
extension (``v < 0``) stretches the flexors, flexion the extensors. There is no angle term
and no memory. Importing this module registers it as ``"velocity_example"``; the command
line imports it with ``myoexo --plugin velocity_reflex ...`` (the module on ``PYTHONPATH``)
or ``MYOEXO_PLUGINS=velocity_reflex``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, NamedTuple

from myoexo.spasticity import ReflexModel, register_reflex


class VelocityConstants(NamedTuple):
    gain: float  # this subject's gain, fraction of the excitation range
    half_slope_s_per_rad: float
    threshold_rad_s: float


@dataclass(frozen=True)
class VelocityReflex(ReflexModel):
    """Excitation ``g sigmoid(slope (stretch speed - threshold))`` of the stretched group.

    Attributes:
        delay_s: Transmission delay, s.
        gains: Gain ``g`` per level 0..3 (fraction of the excitation range).
        threshold_rad_s: Stretch speed at which the reflex is half on, rad/s.
        slope_s_per_rad: Steepness of the sigmoid, s/rad.
    """

    delay_s: float = 0.03
    gains: tuple[float, float, float, float] = (0.0, 0.15, 0.3, 0.45)
    threshold_rad_s: float = 1.0
    slope_s_per_rad: float = 4.0

    def __post_init__(self) -> None:
        super().__post_init__()  # checks delay_s
        if len(self.gains) != 4 or not all(0.0 <= g <= 1.0 for g in self.gains):
            raise ValueError(f"gains = {self.gains!r}: four values in [0, 1], levels 0-3")

    def subject_constants(self, level, subject, individual, control_period_s):
        # scale the gain with the subject's velocity gain s_v relative to its level's
        from myoexo.spasticity import LEVELS

        nominal = LEVELS[level].s_v
        scale = subject.s_v / nominal if nominal > 0 else 1.0
        return VelocityConstants(
            self.gains[level] * scale, 0.5 * self.slope_s_per_rad, self.threshold_rad_s
        )

    @staticmethod
    def _terms(c: Any, vel_rad_s: Any, tanh: Any) -> tuple[Any, Any]:
        flex = (
            c.gain * 0.5 * (1.0 + tanh(c.half_slope_s_per_rad * (-vel_rad_s - c.threshold_rad_s)))
        )
        ext = c.gain * 0.5 * (1.0 + tanh(c.half_slope_s_per_rad * (vel_rad_s - c.threshold_rad_s)))
        return flex, ext

    def step(self, constants, memory, theta_deg, vel_rad_s):
        flex, ext = self._terms(constants, vel_rad_s, math.tanh)
        return flex, ext, memory

    def step_torch(
        self, level, subject, memory, theta_deg, vel_rad_s, control_period_s, individual=None
    ):
        import torch

        from myoexo.spasticity import LEVELS

        nominal = LEVELS[level].s_v
        s_v = subject["s_v"] if not hasattr(subject, "s_v") else subject.s_v
        scale = s_v / nominal if nominal > 0 else 1.0
        c = VelocityConstants(
            self.gains[level] * scale, 0.5 * self.slope_s_per_rad, self.threshold_rad_s
        )
        flex, ext = self._terms(c, torch.as_tensor(vel_rad_s), torch.tanh)
        return flex, ext, tuple(memory)


register_reflex("velocity_example", VelocityReflex())
