"""A reflex model on the muscles' own state: each spastic muscle answers its own stretch.

Muscle spindles sense their muscle's fibre length and lengthening speed, not the knee angle.
Here each spastic muscle is excited by its own normalised lengthening speed (optimal fibre
lengths per second, from the :class:`~myoexo.spasticity.SensoryRecord` the stage hands over,
delayed by ``delay_s``) above a threshold, the form of van der Krogt et al. 2016 (JNER 13:64),
who drove the hamstrings' reflex with their fibre velocity. Knee extension lengthens the
hamstrings, so they fire; the quadriceps shorten and stay quiet. There is no memory, and no
torch twin (a model without one runs everywhere but in the gradient fits). Importing this
module registers it as ``"spindle_example"``.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, NamedTuple

import numpy as np

from myoexo.spasticity import ReflexModel, SensoryRecord, register_reflex


class SpindleConstants(NamedTuple):
    gain: float  # this subject's gain, fraction of the excitation range
    half_slope_s: float  # half the sigmoid's slope, s per optimal length
    threshold_per_s: float  # lengthening speed at which the reflex is half on


@dataclass(frozen=True)
class SpindleReflex(ReflexModel):
    """Excitation ``g sigmoid(slope (v_i - threshold))`` of each muscle ``i`` from its own
    normalised lengthening speed ``v_i``.

    Attributes:
        delay_s: Transmission delay, s.
        gains: Gain ``g`` per level 0..3 (fraction of the excitation range).
        threshold_per_s: Lengthening speed at which the reflex is half on, optimal lengths/s.
        slope_s: Steepness of the sigmoid, s per optimal length.
    """

    delay_s: float = 0.03
    gains: tuple[float, float, float, float] = (0.0, 0.15, 0.3, 0.45)
    threshold_per_s: float = 0.5
    slope_s: float = 8.0

    def __post_init__(self) -> None:
        super().__post_init__()  # checks delay_s
        if len(self.gains) != 4 or not all(0.0 <= g <= 1.0 for g in self.gains):
            raise ValueError(f"gains = {self.gains!r}: four values in [0, 1], levels 0-3")

    def subject_constants(self, level, subject, individual, control_period_s):
        return SpindleConstants(self.gains[level], 0.5 * self.slope_s, self.threshold_per_s)

    def excite(self, constants: Any, memory: Any, record: SensoryRecord) -> tuple[Any, Any]:
        c = constants
        z = c.half_slope_s * (record.lengthening_speed - c.threshold_per_s)
        return c.gain * 0.5 * (1.0 + np.tanh(z)), memory


register_reflex("spindle_example", SpindleReflex())
