"""``"spindle_tone"``: ``"spindle_tsrt"`` with a length tone on each flexor, a background
tone on every spastic muscle and a phasic scale per level.

``"spindle_tsrt"`` (:mod:`myoexo.spasticity.spindle`) holds the study's PID short at levels
2-3 with its tonic term, a steep sigmoid of each flexor's length (Table I's slope ``k``, 0.2
/ 0.1 per deg). Steep enough to hold the knee, it is steep enough to fire and release as
the knee moves a few degrees about the hold, and with the phasic term it sustains a clonus
there: the PID settles in 20-35 % of the subjects. This model adds a **broad tone**: an
excitation of each flexor that rises gently as its own fibre lengthens, read on the
muscle's equivalent seated knee angle ``theta_i`` (the spindle reading) through the
reflex's 20 ms delay, and scales the phasic term per level::

    e_i = spindle_tsrt term of muscle i, with s_v * phasic_scale
          + flexor_tone * 0.5 (1 - tanh((theta_i - tone_center_deg) / tone_width_deg))
            (the second line for the muscles that extension lengthens only)

With the default shape (centre 45 deg, half-width 30 deg) the tone's slope is at most
``flexor_tone / 60`` excitation per deg (0.006 per deg at level 3's fit): a tone that holds,
not a threshold that chatters. Reclined for the pendulum test (hip 40 deg) the hamstrings
are slack, so their equivalent seated angle is flexed and their tone falls away, as the
spindle reading has it for every term.

The **background tone** is a constant excitation of every spastic muscle, flexors and
extensors alike: the raised muscle tone of spastic legs at rest (De Groote et al. 2018, PLoS
One 13:e0205763, who needed it beside short-range stiffness and feedback gains to reproduce
spastic pendulum traces). It closes no loop; its work is the active muscles' force-velocity
damping. Without it the spastic knee is damped only as lightly as the healthy one (Kim et
al. 1996's pendulum asks that of the passive knee; Lebiedowska and Fisk 1999 found the
passive viscosity of spastic knees unchanged), except past the phasic threshold, and a
constant exo command leaves it swinging for seconds.

Each subject draws its own tones: the level's flexor and background tones times factors
``max(0, 1 + 0.1 z)`` (the 10 % of the subject draw on Table I's parameters,
:class:`ToneIndividual`), so the hold they make varies from subject to subject as the
thresholds' does.

Its per-level parameters (:class:`ToneLevel`: ``"spindle_tsrt"``'s and the three above) are
fitted by ``myoexo twin calibrate --reflex spindle_tone`` (:mod:`myoexo.studies.joint_fit`,
the same joint fit as ``"spindle_tsrt"``'s, with the flexor tone of levels 2-3 as the value
the PID's final error is bisected on) and written to the package's fit
:data:`SPINDLE_TONE_FIT`. Before that fit is written it is ``"spindle_tsrt"`` (tone 0,
phasic scale 1), trajectory for trajectory.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from myoexo.runtime.fits import fit_path, read_fit
from myoexo.spasticity.registry import (
    Memory,
    calibration_from_dict,
    check_parameter,
    individual_factors,
    register_reflex,
)
from myoexo.spasticity.spindle import (
    SPINDLE_TSRT_CALIBRATION,
    LengthTone,
    SpindleTSRTConstants,
    SpindleTSRTKernel,
    SpindleTSRTReflex,
    spindle_tsrt_excitation,
    spindle_tsrt_kernel,
)
from myoexo.spasticity.tsrt import TSRTCalibration, TSRTLevel

if TYPE_CHECKING:
    from myoexo.spasticity.sensory import SensoryRecord

__all__ = [
    "SPINDLE_TONE_CALIBRATION",
    "SPINDLE_TONE_FIT",
    "SpindleToneConstants",
    "SpindleToneReflex",
    "ToneCalibration",
    "ToneIndividual",
    "ToneLevel",
]

#: The package's fit of the ``"spindle_tone"`` reflex's per-level parameters
#: (``myoexo twin calibrate --reflex spindle_tone --write``).
SPINDLE_TONE_FIT = "reflex_spindle_tone"


@dataclass(frozen=True)
class ToneLevel(TSRTLevel):
    """The ``"spindle_tone"`` reflex's parameters at one level: ``"spindle_tsrt"``'s
    (:class:`~myoexo.spasticity.tsrt.TSRTLevel`) and two more (module docstring).

    Attributes:
        flexor_tone: Peak excitation of the flexors' length tone (-, 0-1).
        phasic_scale: Factor on the phasic (velocity) term of every muscle (-, 0-2).
        phasic_threshold_offset_deg: Where the flexors' dynamic threshold sits at rest,
            from their static one, deg (> 0: further into the motion; 0: at it, as in
            ``"spindle_tsrt"``). It lets the catch stay inside the range while the static
            threshold, a steep delayed loop, is moved out of it.
        background_tone: Constant excitation of every spastic muscle (-, 0-0.5).
    """

    flexor_tone: float = 0.0
    phasic_scale: float = 1.0
    phasic_threshold_offset_deg: float = 0.0
    background_tone: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_parameter("ToneLevel", "flexor_tone", self.flexor_tone, 0.0, 1.0, "-")
        check_parameter("ToneLevel", "phasic_scale", self.phasic_scale, 0.0, 2.0, "-")
        check_parameter(
            "ToneLevel",
            "phasic_threshold_offset_deg",
            self.phasic_threshold_offset_deg,
            -100.0,
            200.0,
            "deg",
        )
        check_parameter("ToneLevel", "background_tone", self.background_tone, 0.0, 0.5, "-")

    @classmethod
    def from_tsrt(cls, level: TSRTLevel, **changes: float) -> ToneLevel:
        """``"spindle_tsrt"``'s *level* with no tone and the full phasic term (then
        *changes*)."""
        values = {name: getattr(level, name) for name in TSRTLevel.__dataclass_fields__}
        return cls(**{**values, **changes})


@dataclass(frozen=True)
class ToneCalibration(TSRTCalibration):
    """Per-level parameters of the ``"spindle_tone"`` reflex (level -> :class:`ToneLevel`;
    the fields as :class:`~myoexo.spasticity.tsrt.TSRTCalibration`'s)."""

    def __post_init__(self) -> None:
        super().__post_init__()
        for lv, value in self.levels.items():
            if not isinstance(value, ToneLevel):
                raise ValueError(
                    f"ToneCalibration.levels[{lv}] must be a ToneLevel, got {type(value).__name__}"
                )

    def __getitem__(self, level: int) -> ToneLevel:
        value = self.levels.get(int(level), ToneLevel())
        assert isinstance(value, ToneLevel)
        return value

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> ToneCalibration:
        """The calibration :meth:`to_dict` wrote."""
        result: ToneCalibration = calibration_from_dict(cls, ToneLevel, doc)
        return result

    @classmethod
    def from_tsrt(cls, calibration: TSRTCalibration) -> ToneCalibration:
        """``"spindle_tsrt"``'s *calibration* with no tone and the full phasic term."""
        levels = {lv: ToneLevel.from_tsrt(value) for lv, value in calibration.levels.items()}
        return cls(levels=MappingProxyType(levels), note=calibration.note)


def _package_fit() -> ToneCalibration:
    """The package's ``"spindle_tone"`` calibration (before its first ``--write``:
    ``"spindle_tsrt"``'s fit with no tone and the full phasic term)."""
    if not fit_path(SPINDLE_TONE_FIT).exists():
        return ToneCalibration.from_tsrt(SPINDLE_TSRT_CALIBRATION)
    return ToneCalibration.from_dict(read_fit(SPINDLE_TONE_FIT)["result"])


#: The ``"spindle_tone"`` reflex's per-level parameters: the package's fit
#: :data:`SPINDLE_TONE_FIT` (record: ``docs/studies/calibration_spindle_tone``).
SPINDLE_TONE_CALIBRATION = _package_fit()


class ToneIndividual(NamedTuple):
    """A subject's own factors on its level's tones (:meth:`SpindleToneReflex.draw_individual`;
    ``None`` in their place: 1, the level's nominal tones)."""

    flexor_tone_factor: float
    background_tone_factor: float


class SpindleToneConstants(NamedTuple):
    """A subject's constants of the ``"spindle_tone"`` reflex: ``"spindle_tsrt"``'s (with
    the phasic gains scaled), each muscle's tone amplitude (0 for the muscles flexion
    lengthens), the flexors' dynamic-threshold offset (``None``: 0), the background tone
    and the excitation's kernel made of them all
    (:func:`~myoexo.spasticity.spindle.spindle_tsrt_kernel`)."""

    tsrt: SpindleTSRTConstants
    tone: np.ndarray
    dynamic_offset_deg: np.ndarray | None
    background_tone: float
    kernel: SpindleTSRTKernel


@dataclass(frozen=True)
class SpindleToneReflex(SpindleTSRTReflex):
    """``"spindle_tone"``: ``"spindle_tsrt"`` with a broad length tone on each flexor, a
    background tone on every spastic muscle and a phasic scale per level (module
    docstring).

    Attributes:
        delay_s: Transmission delay, s (the stretch reflex's 20 ms).
        calibration: Per-level parameters (:data:`SPINDLE_TONE_CALIBRATION`).
        geometry: As ``"spindle_tsrt"``'s.
        tone_center_deg: Equivalent seated knee angle at which the tone is half its peak,
            deg (it rises as the muscle lengthens, towards extension).
        tone_width_deg: The tone sigmoid's half-width, deg.
    """

    calibration: ToneCalibration = SPINDLE_TONE_CALIBRATION
    tone_center_deg: float = 45.0
    tone_width_deg: float = 30.0

    def __post_init__(self) -> None:
        super().__post_init__()
        check_parameter(
            "SpindleToneReflex", "tone_center_deg", self.tone_center_deg, 0.0, 120.0, "deg"
        )
        check_parameter(
            "SpindleToneReflex", "tone_width_deg", self.tone_width_deg, 1.0, 90.0, "deg"
        )

    def draw_individual(self, rng: Any, rel_std: float) -> ToneIndividual:
        """The subject's factors on its level's flexor and background tones,
        ``max(0, 1 + rel_std z)`` each (:func:`~myoexo.spasticity.registry.individual_factors`:
        *rng*'s own stream is not advanced)."""
        flexor, background = individual_factors(rng, rel_std, 2)
        return ToneIndividual(float(flexor), float(background))

    def subject_constants(
        self, level: int, subject: Any, individual: Any, control_period_s: float
    ) -> SpindleToneConstants:
        c = self.muscle_constants(level, subject)
        cal = self.calibration[level]
        own = ToneIndividual(1.0, 1.0) if individual is None else individual
        tsrt = c._replace(s_v=c.s_v * cal.phasic_scale)
        tone = np.where(c.side < 0.0, cal.flexor_tone * own.flexor_tone_factor, 0.0)
        offset = cal.phasic_threshold_offset_deg
        dynamic = None if offset == 0.0 else np.where(c.side < 0.0, offset, 0.0)
        background = cal.background_tone * own.background_tone_factor
        shape = LengthTone(tone, self.tone_center_deg, self.tone_width_deg)
        kernel = spindle_tsrt_kernel(tsrt, dynamic, shape, background)
        return SpindleToneConstants(tsrt, tone, dynamic, background, kernel)

    def excite(
        self, constants: Any, memory: Memory, record: SensoryRecord
    ) -> tuple[Sequence[float], Memory]:
        e = spindle_tsrt_excitation(constants.kernel, record.fibre_length, record.lengthening_speed)
        return e, memory  # type: ignore[return-value]


register_reflex("spindle_tone", SpindleToneReflex())
