"""``"tsrt"``: the tonic-stretch-reflex-threshold reading of the spastic reflex.

In the tonic stretch reflex threshold (TSRT) account of spasticity (Levin and Feldman 1994;
Calota and Levin 2009) a muscle's stretch reflex fires once its length passes a threshold
``lambda``, and stretching it faster lowers that threshold (``lambda - mu v``): the catch of
a fast stretch comes earlier in the range than the tone of a slow one, and spasticity is a
threshold moved inside the joint's range. Read on the knee angle (the length proxy of each
group; flexion positive, deg; velocity rad/s, flexion positive)::

    flexors (stretched by extension, v < 0):
        theta_f*(v) = theta_f + mu_f max(0, -v)                  (the dynamic threshold)
        e_flex = g_flex [ s_theta below(theta; theta_f, k)                      (tonic)
                        + s_v below(v; v_lower, k_v) below(theta; theta_f*(v), k) ]  (phasic)
    extensors (stretched by flexion, v > 0):
        theta_e*(v) = theta_e - mu_e max(0, v)
        e_ext  = g_ext  [ s_theta above(theta; theta_e, k)
                        + s_v above(v; v_upper, k_v) above(theta; theta_e*(v), k) ]

with ``below``/``above`` eq. 2's sigmoid (:mod:`myoexo.spasticity.coefficients`). What each
symbol is read from:

* ``s_theta``, ``s_v``, ``k`` (the angle slope, 1/deg), ``v_lower``, ``v_upper``: the
  subject's Table I values (10 % spread per subject), as in ``"stretch"``.
* ``theta_f = theta_ext + flexor_threshold_shift_deg`` and ``theta_e = theta_flex +
  extensor_threshold_shift_deg``: Table I's windows moved by a fitted shift per level (the
  static threshold the tone starts at; per subject it carries Table I's spread).
* ``mu_f = dynamic_shift_deg / |v_lower|``, ``mu_e = dynamic_shift_deg / v_upper``: how far
  one window-width of stretch speed moves the threshold into the range. Table I's narrower
  velocity windows at the higher levels (1 / 0.5 / 0.25 rad/s) make the same shift per
  window-width a larger shift per rad/s: the velocity dependence grows with the level as the
  Tardieu scale has it, from Table I's own numbers.
* ``k_v`` = ``velocity_slope_per_rad_s``: the velocity term's slope. The study prints one
  slope ``k`` for both terms (0.5 / 0.2 / 0.1), which per rad/s leaves the velocity term
  nearly flat over the speeds the clinic tests (0 to 3 rad/s); the study's text names two
  slopes (``k_ang``, ``k_vel``), so the velocity slope is a reading, fitted here
  (:data:`TSRT_CALIBRATION`, ``myoexo twin calibrate --reflex tsrt``).
* ``g_flex``, ``g_ext``: a gain per group and level.

The tonic term is Table I's angle term beyond the static threshold (the tone at rest); the
phasic term is Table I's velocity term, let through only past the dynamic threshold. Unlike
``"stretch"`` (whose flexors' velocity term fires at any angle, so a fast stretch "catches"
as soon as it starts), a fast stretch here catches where its dynamic threshold is crossed,
and a relaxed limb inside the static thresholds rests without tone. No memory; a 20 ms
transmission delay (:data:`~myoexo.spasticity.delay.STRETCH_DELAY_S`).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple

from myoexo.runtime.fits import read_fit
from myoexo.spasticity.coefficients import as_tensor, tensor_getter
from myoexo.spasticity.delay import STRETCH_DELAY_S
from myoexo.spasticity.registry import (
    MemorylessGroupReflex,
    calibration_from_dict,
    calibration_to_dict,
    check_parameter,
)

if TYPE_CHECKING:  # torch is imported lazily
    import torch


__all__ = [
    "TSRT_CALIBRATION",
    "TSRTCalibration",
    "TSRTConstants",
    "TSRTLevel",
    "TSRTReflex",
    "tsrt_constants",
    "tsrt_excitations",
    "tsrt_excitations_torch",
    "tsrt_terms",
]


@dataclass(frozen=True)
class TSRTLevel:
    """The ``"tsrt"`` reflex's parameters at one level (module docstring).

    Attributes:
        flexor_threshold_shift_deg: Added to Table I's ``theta_ext`` for the flexors' static
            threshold, deg (> 0 moves it into the motion).
        extensor_threshold_shift_deg: Added to Table I's ``theta_flex`` for the extensors'
            static threshold, deg (> 0 moves it out of the resting range).
        dynamic_shift_deg: Threshold shift per velocity-window width of stretch speed, deg
            (``mu = dynamic_shift_deg / |window|``, in deg per rad/s).
        velocity_slope_per_rad_s: Slope ``k_v`` of the velocity term, 1/(rad/s).
        flexor_gain: Gain of the flexors' excitation (-).
        extensor_gain: Gain of the extensors' excitation (-).
    """

    flexor_threshold_shift_deg: float = 0.0
    extensor_threshold_shift_deg: float = 0.0
    dynamic_shift_deg: float = 0.0
    velocity_slope_per_rad_s: float = 10.0
    flexor_gain: float = 1.0
    extensor_gain: float = 1.0

    def __post_init__(self) -> None:
        for name, low, high, unit in (
            ("flexor_threshold_shift_deg", -50.0, 150.0, "deg"),
            ("extensor_threshold_shift_deg", -100.0, 100.0, "deg"),
            ("dynamic_shift_deg", 0.0, 60.0, "deg"),
            ("velocity_slope_per_rad_s", 0.0, 100.0, "1/(rad/s)"),
            ("flexor_gain", 0.0, 20.0, "-"),
            ("extensor_gain", 0.0, 20.0, "-"),
        ):
            check_parameter("TSRTLevel", name, getattr(self, name), low, high, unit)


def _default_levels() -> Mapping[int, TSRTLevel]:
    return MappingProxyType({lv: TSRTLevel() for lv in range(4)})


@dataclass(frozen=True)
class TSRTCalibration:
    """Per-level parameters of the ``"tsrt"`` reflex (level -> :class:`TSRTLevel`).

    Attributes:
        levels: Parameters of each level; a level not listed uses :class:`TSRTLevel`'s
            defaults (Table I's thresholds, no dynamic shift).
        note: Provenance: the command and the numbers the fit gave.
        root_seed: Root seed of the subjects the values were fitted on (``None``: not
            fitted).
    """

    levels: Mapping[int, TSRTLevel] = field(default_factory=_default_levels)
    note: str = ""
    root_seed: int | None = None

    def __post_init__(self) -> None:
        levels = {int(lv): value for lv, value in dict(self.levels).items()}
        for lv, value in levels.items():
            if lv not in range(4):
                raise ValueError(f"TSRTCalibration.levels has level {lv!r}; levels are 0-3")
            if not isinstance(value, TSRTLevel):
                raise ValueError(
                    f"TSRTCalibration.levels[{lv}] must be a TSRTLevel, got {type(value).__name__}"
                )
        object.__setattr__(self, "levels", MappingProxyType(levels))

    def __getitem__(self, level: int) -> TSRTLevel:
        return self.levels.get(int(level), TSRTLevel())

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: ``{"levels": {"1": {...}, ...}, "note": ..., "root_seed": ...}``."""
        return calibration_to_dict(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> TSRTCalibration:
        """The calibration :meth:`to_dict` wrote."""
        result: TSRTCalibration = calibration_from_dict(cls, TSRTLevel, doc)
        return result


#: The package's fit of the ``"tsrt"`` reflex (:mod:`myoexo.runtime.fits`), written by
#: ``myoexo twin calibrate --reflex tsrt --write`` (:mod:`myoexo.studies.joint_fit`).
TSRT_FIT = "reflex_tsrt"

#: The ``"tsrt"`` reflex's per-level parameters, fitted jointly to the study's PID table and
#: the clinical rows of the validation table on the calibration root, on twin version 1
#: (``myoexo twin calibrate --reflex tsrt``, :mod:`myoexo.studies.joint_fit`; the record and its
#: check: ``docs/studies/calibration_tsrt``): the package's fit :data:`TSRT_FIT`, with its
#: provenance.
TSRT_CALIBRATION = TSRTCalibration.from_dict(read_fit(TSRT_FIT)["result"])


class TSRTConstants(NamedTuple):
    """A subject's constants of the ``"tsrt"`` reflex (halved slopes; gains multiplied in)."""

    half_k: Any
    half_k_v: Any
    flex_theta_deg: Any
    ext_theta_deg: Any
    flex_mu_deg_s_rad: Any
    ext_mu_deg_s_rad: Any
    v_lower_rad_s: Any
    v_upper_rad_s: Any
    flex_s_theta: Any
    flex_s_v: Any
    ext_s_theta: Any
    ext_s_v: Any


def tsrt_constants(p: Any, cal: Any, get: Any = getattr) -> TSRTConstants:
    """:class:`TSRTConstants` of subject *p* with the level's :class:`TSRTLevel` *cal* (read
    with *get*: ``getattr``, or :func:`~myoexo.spasticity.coefficients.tensor_getter` for
    the torch twin)."""
    dyn = get(cal, "dynamic_shift_deg")
    g_f, g_e = get(cal, "flexor_gain"), get(cal, "extensor_gain")
    v_lower, v_upper = get(p, "v_lower_rad_s"), get(p, "v_upper_rad_s")
    return TSRTConstants(
        half_k=0.5 * get(p, "k"),
        half_k_v=0.5 * get(cal, "velocity_slope_per_rad_s"),
        flex_theta_deg=get(p, "theta_ext_deg") + get(cal, "flexor_threshold_shift_deg"),
        ext_theta_deg=get(p, "theta_flex_deg") + get(cal, "extensor_threshold_shift_deg"),
        flex_mu_deg_s_rad=dyn / abs(v_lower),
        ext_mu_deg_s_rad=dyn / abs(v_upper),
        v_lower_rad_s=v_lower,
        v_upper_rad_s=v_upper,
        flex_s_theta=g_f * get(p, "s_theta"),
        flex_s_v=g_f * get(p, "s_v"),
        ext_s_theta=g_e * get(p, "s_theta"),
        ext_s_v=g_e * get(p, "s_v"),
    )


def tsrt_terms(theta_deg: Any, vel_rad_s: Any, c: TSRTConstants, tanh: Any) -> tuple[Any, Any]:
    """``(e_flex, e_ext)`` of the ``"tsrt"`` reflex (module docstring) in any array library
    (``tanh``: ``math.tanh``, ``np.tanh`` or ``torch.tanh``; ``abs`` is Python's, which
    every one of them takes)."""
    extending = 0.5 * (abs(vel_rad_s) - vel_rad_s)  # max(0, -v)
    flexing = 0.5 * (abs(vel_rad_s) + vel_rad_s)  # max(0, v)
    hk = c.half_k
    flex_static = 1.0 - tanh(hk * (theta_deg - c.flex_theta_deg))
    flex_dynamic = 1.0 - tanh(hk * (theta_deg - c.flex_theta_deg - c.flex_mu_deg_s_rad * extending))
    ext_static = 1.0 + tanh(hk * (theta_deg - c.ext_theta_deg))
    ext_dynamic = 1.0 + tanh(hk * (theta_deg - c.ext_theta_deg + c.ext_mu_deg_s_rad * flexing))
    flex_vel = 0.5 * (1.0 - tanh(c.half_k_v * (vel_rad_s - c.v_lower_rad_s)))
    ext_vel = 0.5 * (1.0 + tanh(c.half_k_v * (vel_rad_s - c.v_upper_rad_s)))
    flex = 0.5 * (c.flex_s_theta * flex_static + c.flex_s_v * flex_vel * flex_dynamic)
    ext = 0.5 * (c.ext_s_theta * ext_static + c.ext_s_v * ext_vel * ext_dynamic)
    return flex, ext


def tsrt_excitations(
    theta_deg: Any, vel_rad_s: Any, params: Any, level: TSRTLevel | None = None
) -> tuple[Any, Any]:
    """The ``"tsrt"`` reflex's ``(e_flex, e_ext)`` at knee states (numpy, broadcast).

    Args:
        theta_deg: Knee angle(s), deg, flexion positive.
        vel_rad_s: Knee velocity(ies), rad/s, flexion positive.
        params: A :class:`~myoexo.spasticity.SpasticityParams` (level or subject).
        level: The level's :class:`TSRTLevel` (default: its defaults).
    """
    import numpy as np

    c = tsrt_constants(params, level or TSRTLevel())
    theta = np.asarray(theta_deg, dtype=np.float64)
    vel = np.asarray(vel_rad_s, dtype=np.float64)
    return tsrt_terms(theta, vel, c, np.tanh)


def tsrt_excitations_torch(
    theta_deg: Any,
    vel_rad_s: Any,
    params: Mapping[str, Any],
    level: Mapping[str, Any] | TSRTLevel | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Torch twin of :func:`tsrt_excitations`, differentiable in the inputs, in every subject
    parameter (a mapping from :class:`~myoexo.spasticity.SpasticityParams` field names to
    tensors or floats) and in every :class:`TSRTLevel` parameter given as a tensor."""
    import torch

    x = as_tensor(theta_deg)
    v = as_tensor(vel_rad_s)
    c = tsrt_constants(params, level if level is not None else TSRTLevel(), tensor_getter(x))
    return tsrt_terms(x, v, c, torch.tanh)


@dataclass(frozen=True)
class TSRTReflex(MemorylessGroupReflex):
    """``"tsrt"``: each muscle group's stretch reflex fires past a threshold that stretch
    velocity moves into the range (module docstring).

    Attributes:
        delay_s: Transmission delay, s (:data:`~myoexo.spasticity.delay.STRETCH_DELAY_S`).
        calibration: Per-level parameters (:data:`TSRT_CALIBRATION`).
    """

    delay_s: float = STRETCH_DELAY_S
    calibration: TSRTCalibration = TSRT_CALIBRATION

    def constants(self, subject: Any, level_parameters: Any) -> TSRTConstants:
        return tsrt_constants(subject, level_parameters)

    def terms(self, theta_deg: Any, vel_rad_s: Any, constants: Any, tanh: Any) -> tuple[Any, Any]:
        return tsrt_terms(theta_deg, vel_rad_s, constants, tanh)

    def terms_torch(
        self, theta_deg: Any, vel_rad_s: Any, subject: Mapping[str, Any], level_parameters: Any
    ) -> tuple[torch.Tensor, torch.Tensor]:
        return tsrt_excitations_torch(theta_deg, vel_rad_s, subject, level_parameters)
