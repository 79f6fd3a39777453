"""``"spindle"``: the stretch reflex read on each muscle's own fibre length and speed.

Muscle spindles sense their own muscle's fibre length and lengthening speed, not the knee
angle. A biarticular hamstring is longer with the hip flexed than with it extended at the
same knee angle: seated (hip 90 deg) a knee extension stretches it into its reflex range,
reclined for the pendulum test (hip 40 deg) the same knee angle leaves it slack. A reflex
read on the knee angle cannot tell the two apart; this one can.

Each spastic muscle ``i`` maps its own normalised fibre length ``L_i`` and lengthening speed
``s_i`` (:class:`~myoexo.spasticity.SensoryRecord`) onto the knee angle and velocity that
would stretch it that far **in the seated posture of the study** (:class:`SpindleGeometry`:
the least-squares line of ``L_i`` over the knee's 0-90 deg, seated; ``dL_i/dtheta`` in
optimal lengths per rad)::

    theta_i = theta_ref + (L_i - L_ref,i) / (dL_i/dtheta)      (deg)
    v_i     = s_i / (dL_i/dtheta)                              (rad/s)

and answers with the ``"stretch"`` reflex's term of the side that stretches it (the flexor
term for a muscle that extension lengthens, ``dL_i/dtheta < 0``, the extensor term for one
that flexion lengthens), with the same Table I windows, calibration form and 20 ms delay::

    e_i = g_flex [ s_theta below(theta_i; theta_ext + shift) + s_v below(v_i; v_lower) ]
          (muscles extension lengthens)
    e_i = g_ext  [ s_theta above(theta_i; theta_flex)        + s_v above(v_i; v_upper) ]
          (muscles flexion lengthens)

So in the seated task it is the ``"stretch"`` reflex, muscle by muscle (each threshold a
fibre length, the tonic-stretch-reflex-threshold form of Levin and Feldman 1994 on the
muscle's own state); in any other posture each muscle answers the stretch it actually has.
The gracilis, which the paper groups with the extensors, is lengthened by extension and
answers as a flexor here. The per-level parameters (gains, the flexors' threshold shift) are
fitted by ``myoexo twin calibrate --reflex spindle`` to the study's PID table like
``"stretch"``'s, and written with the geometry to the package's fit :data:`SPINDLE_FIT`.

No memory, no torch twin (the gradient fits do not take it).

``"spindle_tsrt"`` (:class:`SpindleTSRTReflex`) reads the ``"tsrt"`` reflex
(:mod:`myoexo.spasticity.tsrt`) the same way: each muscle's static and dynamic thresholds are
fibre lengths, its dynamic threshold falls as its own lengthening speed rises (Levin and
Feldman 1994), and its excitation is the ``"tsrt"`` term of the side that stretches it at
its equivalent seated knee angle and velocity::

    e_i = tsrt flexor term (theta_i, v_i)     (muscles extension lengthens)
    e_i = tsrt extensor term (theta_i, v_i)   (muscles flexion lengthens)

Its per-level parameters (:class:`~myoexo.spasticity.tsrt.TSRTCalibration`) are fitted by
``myoexo twin calibrate --reflex spindle_tsrt`` (:mod:`myoexo.studies.joint_fit`, starting
from ``"tsrt"``'s knee-angle fit) and written to the package's fit
:data:`SPINDLE_TSRT_FIT`; the geometry is ``"spindle"``'s (:data:`SPINDLE_GEOMETRY`).
"""

from __future__ import annotations

import functools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, NamedTuple

import numpy as np

from myoexo.runtime.fits import fit_path, read_fit
from myoexo.spasticity.levels import SPASTIC_MUSCLES
from myoexo.spasticity.reflex import (
    StretchCalibration,
    StretchConstants,
    StretchReflex,
    stretch_constants,
)
from myoexo.spasticity.registry import Memory, ReflexModel, register_reflex
from myoexo.spasticity.tsrt import (
    TSRT_CALIBRATION,
    TSRTCalibration,
    TSRTConstants,
    TSRTReflex,
    tsrt_constants,
)

if TYPE_CHECKING:
    from myoexo.model import TwinParams
    from myoexo.spasticity.sensory import SensoryRecord

__all__ = [
    "SPINDLE_FIT",
    "SPINDLE_TSRT_CALIBRATION",
    "SPINDLE_TSRT_FIT",
    "LengthTone",
    "SpindleConstants",
    "SpindleGeometry",
    "SpindleReflex",
    "SpindleTSRTConstants",
    "SpindleTSRTKernel",
    "SpindleTSRTReflex",
    "spindle_constants",
    "spindle_geometry",
    "spindle_tsrt_constants",
    "spindle_tsrt_excitation",
    "spindle_tsrt_kernel",
]

#: The package's fit of the ``"spindle"`` reflex: its geometry and its per-level parameters
#: (``myoexo twin calibrate --reflex spindle --write``).
SPINDLE_FIT = "reflex_spindle"
#: The package's fit of the ``"spindle_tsrt"`` reflex's per-level parameters
#: (``myoexo twin calibrate --reflex spindle_tsrt --write``).
SPINDLE_TSRT_FIT = "reflex_spindle_tsrt"

#: Knee angles (deg) over which each muscle's fibre length is fitted by a line, seated.
_GEOMETRY_KNEE_DEG = tuple(float(v) for v in range(0, 95, 5))


@dataclass(frozen=True)
class SpindleGeometry:
    """Each spastic muscle's fibre length against the knee angle in the seated posture.

    Attributes:
        muscles: The muscles, in the stage's order (flexors, then extensors).
        reference_knee_deg: The knee angle the lines are taken about, deg.
        reference_length: Each muscle's normalised fibre length there (``L / L_opt``).
        slope_per_rad: ``dL/dtheta`` of each muscle, optimal lengths per rad of knee
            flexion (< 0: knee extension lengthens it).
        hip_flexion_deg: The hip posture the lines were measured in.
        rms_error: Each line's RMS error over the fitted range, optimal lengths.
    """

    muscles: tuple[str, ...]
    reference_knee_deg: float
    reference_length: tuple[float, ...]
    slope_per_rad: tuple[float, ...]
    hip_flexion_deg: float
    rms_error: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        n = len(self.muscles)
        if len(self.reference_length) != n or len(self.slope_per_rad) != n:
            raise ValueError(
                f"SpindleGeometry needs one reference length and one slope per muscle "
                f"({n}), got {len(self.reference_length)} and {len(self.slope_per_rad)}"
            )
        bad = [m for m, s in zip(self.muscles, self.slope_per_rad, strict=True) if s == 0.0]
        if bad:
            raise ValueError(f"SpindleGeometry: muscles {bad} do not change length with the knee")

    def equivalent_knee_deg(self, fibre_length: np.ndarray) -> np.ndarray:
        """The knee angle (deg) that would stretch each muscle to *fibre_length* seated."""
        slope = np.asarray(self.slope_per_rad)
        return self.reference_knee_deg + np.degrees(
            (np.asarray(fibre_length) - np.asarray(self.reference_length)) / slope
        )

    def equivalent_knee_velocity_rad_s(self, lengthening_speed: np.ndarray) -> np.ndarray:
        """The knee velocity (rad/s) that would lengthen each muscle at *lengthening_speed*."""
        return np.asarray(lengthening_speed) / np.asarray(self.slope_per_rad)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready."""
        return {
            "muscles": list(self.muscles),
            "reference_knee_deg": self.reference_knee_deg,
            "reference_length": list(self.reference_length),
            "slope_per_rad": list(self.slope_per_rad),
            "hip_flexion_deg": self.hip_flexion_deg,
            "rms_error": list(self.rms_error),
        }

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> SpindleGeometry:
        """The geometry :meth:`to_dict` wrote."""
        return cls(
            muscles=tuple(doc["muscles"]),
            reference_knee_deg=float(doc["reference_knee_deg"]),
            reference_length=tuple(float(v) for v in doc["reference_length"]),
            slope_per_rad=tuple(float(v) for v in doc["slope_per_rad"]),
            hip_flexion_deg=float(doc["hip_flexion_deg"]),
            rms_error=tuple(float(v) for v in doc.get("rms_error", ())),
        )


def spindle_geometry(
    params: TwinParams | None = None, muscles: Sequence[str] = SPASTIC_MUSCLES
) -> SpindleGeometry:
    """Measure :class:`SpindleGeometry` on the twin *params* (default: the seated twin):
    each muscle's normalised fibre length at knee angles 0-90 deg, a line through them."""
    import mujoco

    from myoexo.model import TwinParams, build_model, pose_twin
    from myoexo.spasticity.sensory import MuscleSensors

    params = params or TwinParams(scene=False)
    model, _ = build_model(params)
    data = mujoco.MjData(model)
    ids = np.array([model.actuator(name).id for name in muscles])
    sensors = MuscleSensors(model, ids, len(muscles))
    knee = np.array(_GEOMETRY_KNEE_DEG)
    lengths = np.empty((len(knee), len(muscles)))
    for row, knee_deg in enumerate(knee):
        pose_twin(model, data, knee_angle_deg=float(knee_deg))
        mujoco.mj_forward(model, data)
        lengths[row] = sensors.read(data, float(knee_deg), 0.0).fibre_length
    reference_deg = float(knee.mean())
    x = np.radians(knee - reference_deg)
    design = np.column_stack([np.ones_like(x), x])
    coef, *_ = np.linalg.lstsq(design, lengths, rcond=None)
    rms = np.sqrt(np.mean((design @ coef - lengths) ** 2, axis=0))
    return SpindleGeometry(
        muscles=tuple(muscles),
        reference_knee_deg=reference_deg,
        reference_length=tuple(float(v) for v in coef[0]),
        slope_per_rad=tuple(float(v) for v in coef[1]),
        hip_flexion_deg=float(params.hip_flexion_deg),
        rms_error=tuple(float(v) for v in rms),
    )


def _package_fit() -> tuple[SpindleGeometry | None, StretchCalibration]:
    """The package's geometry and calibration (``None`` and an empty calibration before the
    first ``--write``)."""
    if not fit_path(SPINDLE_FIT).exists():
        return None, StretchCalibration(note="not fitted")
    result = read_fit(SPINDLE_FIT)["result"]
    return (
        SpindleGeometry.from_dict(result["geometry"]),
        StretchCalibration.from_dict(result["calibration"]),
    )


#: The package's fit (:data:`SPINDLE_FIT`): the seated geometry and the per-level parameters.
SPINDLE_GEOMETRY, SPINDLE_CALIBRATION = _package_fit()


class SpindleConstants(NamedTuple):
    """A subject's constants of the ``"spindle"`` reflex, folded into one affine map per term.

    With ``s_i = -1`` for a muscle that extension lengthens (the flexor term's ``below``) and
    ``+1`` for one that flexion lengthens (the extensor term's ``above``), each term is
    ``weight_i (1 + tanh(x_i))`` with ``x_i = slope_i * sensed_i + offset_i``: the first
    half of each array is the angle term on the fibre length, the second the velocity term on
    the lengthening speed. ``ones``: ones of the arrays' size (adding an array of ones costs
    numpy less than adding the scalar 1)."""

    slope: np.ndarray
    offset: np.ndarray
    weight: np.ndarray
    n_muscles: int
    ones: np.ndarray


def spindle_constants(stretch: StretchConstants, geometry: SpindleGeometry) -> SpindleConstants:
    """Fold the stretch reflex's constants and the geometry into :class:`SpindleConstants`."""
    slope = np.asarray(geometry.slope_per_rad, dtype=np.float64)
    lengthened_by_extension = slope < 0.0
    sign = np.where(lengthened_by_extension, -1.0, 1.0)
    deg_per_length = np.degrees(1.0 / slope)
    # theta_i = theta_ref + (L_i - L_ref_i) deg_per_length_i, v_i = speed_i / slope_i
    theta_offset = (
        geometry.reference_knee_deg - np.asarray(geometry.reference_length) * deg_per_length
    )
    theta_threshold = np.where(
        lengthened_by_extension, stretch.flex_theta_deg, stretch.theta_flex_deg
    )
    vel_threshold = np.where(lengthened_by_extension, stretch.v_lower_rad_s, stretch.v_upper_rad_s)
    hk = stretch.half_k
    return SpindleConstants(
        slope=np.concatenate([hk * sign * deg_per_length, hk * sign / slope]),
        offset=np.concatenate(
            [hk * sign * (theta_offset - theta_threshold), -hk * sign * vel_threshold]
        ),
        weight=0.5
        * np.concatenate(
            [
                np.where(lengthened_by_extension, stretch.flex_s_theta, stretch.ext_s_theta),
                np.where(lengthened_by_extension, stretch.flex_s_v, stretch.ext_s_v),
            ]
        ),
        n_muscles=len(slope),
        ones=np.ones(2 * len(slope)),
    )


@dataclass(frozen=True)
class SpindleReflex(StretchReflex):
    """``"spindle"``: each spastic muscle answers the stretch of its own fibres (module
    docstring).

    Attributes:
        delay_s: Transmission delay, s (the stretch reflex's 20 ms).
        calibration: Per-level gains and flexor threshold shift (:data:`SPINDLE_CALIBRATION`).
        geometry: The muscles' fibre length against the knee angle, seated
            (:data:`SPINDLE_GEOMETRY`; measured with :func:`spindle_geometry` when the
            package has no fit yet).
    """

    calibration: StretchCalibration = SPINDLE_CALIBRATION
    geometry: SpindleGeometry | None = field(default=SPINDLE_GEOMETRY, compare=True)

    def subject_constants(
        self, level: int, subject: Any, individual: Any, control_period_s: float
    ) -> SpindleConstants:
        geometry = self.geometry or _measured_geometry()
        return spindle_constants(stretch_constants(subject, self.calibration[level]), geometry)

    def excite(
        self, constants: Any, memory: Memory, record: SensoryRecord
    ) -> tuple[Sequence[float], Memory]:
        c: SpindleConstants = constants
        x = np.concatenate((record.fibre_length, record.lengthening_speed))
        x *= c.slope
        x += c.offset
        np.tanh(x, out=x)
        x += c.ones
        x *= c.weight
        n = c.n_muscles
        return x[:n] + x[n:], memory

    # on the muscles' own state only: the group step and its torch twin refuse
    step = ReflexModel.step
    step_torch = ReflexModel.step_torch


class SpindleTSRTConstants(NamedTuple):
    """A subject's constants of the ``"spindle_tsrt"`` reflex, one entry per muscle (the
    ``"tsrt"`` constants of the side that stretches it: ``side`` -1 for a muscle that
    extension lengthens, whose flexor term it takes, +1 for the others).

    Each muscle's equivalent seated knee state is ``theta_i = length_i * deg_per_length_i +
    theta_offset_deg_i`` and ``v_i = speed_i * inv_slope_i``; its stretch speed is ``max(0,
    side_i v_i)``. ``half_k``, ``half_k_v``: the slopes; ``threshold_deg``: the static
    threshold; ``mu_deg_s_rad``: the dynamic threshold's shift per rad/s of stretch;
    ``v_threshold_rad_s``: the velocity window's edge; ``s_theta``, ``s_v``: the gains."""

    deg_per_length: np.ndarray
    theta_offset_deg: np.ndarray
    inv_slope: np.ndarray
    side: np.ndarray
    half_k: float
    half_k_v: float
    threshold_deg: np.ndarray
    mu_deg_s_rad: np.ndarray
    v_threshold_rad_s: np.ndarray
    s_theta: np.ndarray
    s_v: np.ndarray


def spindle_tsrt_constants(tsrt: TSRTConstants, geometry: SpindleGeometry) -> SpindleTSRTConstants:
    """Each muscle's :class:`SpindleTSRTConstants` from the ``"tsrt"`` constants and the
    geometry."""
    slope = np.asarray(geometry.slope_per_rad, dtype=np.float64)
    deg_per_length = np.degrees(1.0 / slope)
    flexor = slope < 0.0  # lengthened by extension: the flexor term

    def side(flex_value: float, ext_value: float) -> np.ndarray:
        return np.where(flexor, float(flex_value), float(ext_value))

    return SpindleTSRTConstants(
        deg_per_length=deg_per_length,
        theta_offset_deg=geometry.reference_knee_deg
        - np.asarray(geometry.reference_length) * deg_per_length,
        inv_slope=1.0 / slope,
        side=np.where(flexor, -1.0, 1.0),
        half_k=float(tsrt.half_k),
        half_k_v=float(tsrt.half_k_v),
        threshold_deg=side(tsrt.flex_theta_deg, tsrt.ext_theta_deg),
        mu_deg_s_rad=side(tsrt.flex_mu_deg_s_rad, tsrt.ext_mu_deg_s_rad),
        v_threshold_rad_s=side(tsrt.v_lower_rad_s, tsrt.v_upper_rad_s),
        s_theta=side(tsrt.flex_s_theta, tsrt.ext_s_theta),
        s_v=side(tsrt.flex_s_v, tsrt.ext_s_v),
    )


class SpindleTSRTKernel(NamedTuple):
    """A subject's ``"spindle_tsrt"``-family excitation as a few array operations per step
    (:func:`spindle_tsrt_kernel`; evaluated by :func:`spindle_tsrt_excitation`).

    With ``x = [L, s, 1]`` (fibre lengths, lengthening speeds, one), ``y = weights @ x``
    holds five rows of ``n`` entries: the static, gate, length-tone and dynamic arguments of
    the tanh terms and each muscle's signed speed ``side v``. The stretch speed ``max(0,
    side v)`` times ``speed_gain`` joins the dynamic argument; with ``t = tanh`` of the first
    four rows, the excitation is ``base + mix @ t + phasic * t_gate * t_dynamic``.
    """

    weights: np.ndarray
    speed_gain: np.ndarray
    mix: np.ndarray
    base: np.ndarray
    phasic: np.ndarray
    n_muscles: int


class LengthTone(NamedTuple):
    """A tone on each muscle's own length (:func:`spindle_tsrt_kernel`): its amplitude per
    muscle, and the equivalent seated knee angle (deg) and half-width (deg) of its sigmoid."""

    amplitude: np.ndarray
    center_deg: float
    width_deg: float


#: The constant input of a kernel's affine map (``x = [L, s, 1]``).
_ONE = np.ones(1)

#: One row of a kernel's affine map: its (length, speed, constant) coefficients, each a
#: per-muscle array or a scalar.
_Row = tuple[np.ndarray | float, np.ndarray | float, np.ndarray | float]


def spindle_tsrt_kernel(
    c: SpindleTSRTConstants,
    dynamic_offset_deg: np.ndarray | None = None,
    length_tone: LengthTone | None = None,
    background_tone: float = 0.0,
) -> SpindleTSRTKernel:
    """The kernel of each muscle's excitation at its equivalent seated knee angle
    ``theta_i = L_i deg_per_length_i + theta_offset_deg_i`` and velocity ``v_i = s_i
    inv_slope_i`` (module docstring)::

        e_i = 0.5 [ s_theta (1 + side tanh(half_k beyond))
                    + s_v gate dynamic ]
              + amplitude_i 0.5 (1 - tanh((theta_i - center_deg) / width_deg))
              + background_tone
        beyond  = theta_i - threshold_deg
        dynamic = 1 + side tanh(half_k (beyond - dynamic_offset_deg
                                        + side mu_deg_s_rad max(0, side v_i)))
        gate    = 0.5 (1 + side tanh(half_k_v (v_i - v_threshold_rad_s)))

    expanded (``side**2 = 1``) into the affine map, the tanh and the one product of
    :class:`SpindleTSRTKernel`. *dynamic_offset_deg*: each muscle's dynamic threshold apart
    from its static one (``None``: 0); *length_tone*: the tone on each muscle's length
    (``None``: none); *background_tone*: a constant excitation of every muscle."""
    a = np.asarray(c.deg_per_length, dtype=np.float64)
    n = len(a)
    b = np.asarray(c.theta_offset_deg, dtype=np.float64)
    inv_slope = np.asarray(c.inv_slope, dtype=np.float64)
    side = np.asarray(c.side, dtype=np.float64)
    hk, hkv = float(c.half_k), float(c.half_k_v)
    beyond_offset = b - c.threshold_deg
    offset = np.zeros(n) if dynamic_offset_deg is None else np.asarray(dynamic_offset_deg)
    tone_row: _Row
    if length_tone is None:  # no tone: its tanh argument and weight are 0
        tone, tone_row = np.zeros(n), (0.0, 0.0, 0.0)
    else:
        tone = np.asarray(length_tone.amplitude, dtype=np.float64)
        width = length_tone.width_deg
        tone_row = (a / width, 0.0, (b - length_tone.center_deg) / width)
    s_theta = np.asarray(c.s_theta, dtype=np.float64)
    s_v = np.asarray(c.s_v, dtype=np.float64)
    # rows of y = weights @ [L, s, 1]: (length coefficient, speed coefficient, constant)
    rows: tuple[_Row, ...] = (
        (hk * a, 0.0, hk * beyond_offset),  # static argument
        (0.0, hkv * inv_slope, -hkv * c.v_threshold_rad_s),  # gate argument
        tone_row,  # tone argument
        (hk * a, 0.0, hk * (beyond_offset - offset)),  # dynamic argument, before the speed
        (0.0, side * inv_slope, 0.0),  # side v: the stretch speed before its max(0, .)
    )
    weights = np.zeros((5 * n, 2 * n + 1))
    diagonal = np.arange(n)
    for r, (length, speed, constant) in enumerate(rows):
        weights[r * n + diagonal, diagonal] = length
        weights[r * n + diagonal, n + diagonal] = speed
        weights[r * n : (r + 1) * n, 2 * n] = constant
    mix = np.zeros((n, 4 * n))
    for r, coefficient in enumerate(
        (0.5 * s_theta * side, 0.25 * s_v * side, -0.5 * tone, 0.25 * s_v * side)
    ):
        mix[diagonal, r * n + diagonal] = coefficient
    return SpindleTSRTKernel(
        weights=weights,
        speed_gain=hk * side * np.asarray(c.mu_deg_s_rad, dtype=np.float64),
        mix=mix,
        base=0.5 * s_theta + 0.25 * s_v + 0.5 * tone + float(background_tone),
        phasic=0.25 * s_v,
        n_muscles=n,
    )


def spindle_tsrt_excitation(
    kernel: SpindleTSRTKernel, fibre_length: np.ndarray, lengthening_speed: np.ndarray
) -> np.ndarray:
    """Each muscle's excitation (:func:`spindle_tsrt_kernel`) at its normalised fibre length
    and lengthening speed: two small matrix products, one tanh, a handful of array
    operations."""
    n = kernel.n_muscles
    y = kernel.weights @ np.concatenate((fibre_length, lengthening_speed, _ONE))
    stretch = y[4 * n :]
    np.maximum(stretch, 0.0, out=stretch)
    stretch *= kernel.speed_gain
    dynamic = y[3 * n : 4 * n]
    dynamic += stretch
    t = np.tanh(y[: 4 * n])
    e: np.ndarray = kernel.mix @ t
    e += kernel.base
    product = t[n : 2 * n] * t[3 * n :]
    product *= kernel.phasic
    e += product
    return e


def _package_tsrt_fit() -> TSRTCalibration:
    """The package's ``"spindle_tsrt"`` calibration (before its first ``--write``: the
    ``"tsrt"`` knee-angle fit its own fit starts from)."""
    if not fit_path(SPINDLE_TSRT_FIT).exists():
        return TSRT_CALIBRATION
    return TSRTCalibration.from_dict(read_fit(SPINDLE_TSRT_FIT)["result"])


#: The ``"spindle_tsrt"`` reflex's per-level parameters: the package's fit
#: :data:`SPINDLE_TSRT_FIT` (record: ``docs/studies/calibration_spindle_tsrt``).
SPINDLE_TSRT_CALIBRATION = _package_tsrt_fit()


@dataclass(frozen=True)
class SpindleTSRTReflex(TSRTReflex):
    """``"spindle_tsrt"``: the tonic-stretch-reflex-threshold reflex on each muscle's own
    fibre length and lengthening speed (module docstring).

    Attributes:
        delay_s: Transmission delay, s (the stretch reflex's 20 ms).
        calibration: Per-level parameters (:data:`SPINDLE_TSRT_CALIBRATION`).
        geometry: The muscles' fibre length against the knee angle, seated
            (:data:`SPINDLE_GEOMETRY`; measured with :func:`spindle_geometry` when the
            package has no fit yet).
    """

    calibration: TSRTCalibration = SPINDLE_TSRT_CALIBRATION
    geometry: SpindleGeometry | None = field(default=SPINDLE_GEOMETRY, compare=True)

    def subject_constants(
        self, level: int, subject: Any, individual: Any, control_period_s: float
    ) -> Any:
        return spindle_tsrt_kernel(self.muscle_constants(level, subject))

    def muscle_constants(self, level: int, subject: Any) -> SpindleTSRTConstants:
        """Each muscle's :class:`SpindleTSRTConstants` of a subject at *level*."""
        geometry = self.geometry or _measured_geometry()
        return spindle_tsrt_constants(tsrt_constants(subject, self.calibration[level]), geometry)

    def excite(
        self, constants: Any, memory: Memory, record: SensoryRecord
    ) -> tuple[Sequence[float], Memory]:
        e = spindle_tsrt_excitation(constants, record.fibre_length, record.lengthening_speed)
        return e, memory  # type: ignore[return-value]

    # on the muscles' own state only: the group step and its torch twin refuse
    step = ReflexModel.step
    step_torch = ReflexModel.step_torch


@functools.cache
def _measured_geometry() -> SpindleGeometry:
    """The default twin's geometry, measured once per process (before the package's fit)."""
    return spindle_geometry()


register_reflex("spindle", SpindleReflex())
register_reflex("spindle_tsrt", SpindleTSRTReflex())
