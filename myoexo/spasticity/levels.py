"""The spasticity levels of the study (Table I), the spastic muscle groups and individual
subjects.

Each Modified Ashworth level 0-3 is a :class:`SpasticityParams` (the windows of the angle and
velocity terms, their gains and one sigmoid slope, docs/reference.md section 2);
:func:`sample_subject` draws an individual subject with 10 % Gaussian variability on every
parameter.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import Any

import numpy as np

#: Spastic knee flexors (docs/reference.md section 2).
SPASTIC_FLEXORS: tuple[str, ...] = (
    "gaslat_r",
    "gasmed_r",
    "semimem_r",
    "semiten_r",
    "bflh_r",
    "bfsh_r",
)
#: Spastic knee extensors; the paper groups gracilis with them.
SPASTIC_EXTENSORS: tuple[str, ...] = ("grac_r", "vasmed_r", "vaslat_r", "vasint_r", "recfem_r")
#: The 11 muscles that receive ``SC_total``: flexors then extensors.
SPASTIC_MUSCLES: tuple[str, ...] = SPASTIC_FLEXORS + SPASTIC_EXTENSORS
#: Standard deviation of a subject's parameters, relative to the level's nominal |value|.
SUBJECT_REL_STD = 0.10

_MAX_SUBJECT_DRAWS = 100


@dataclasses.dataclass(frozen=True)
class SpasticityParams:
    """Parameters of the spastic reflex of one level or one subject (paper Table I).

    Attributes:
        theta_ext_deg: Lower (extension-side) limit of the reflex-free angle range, deg.
        theta_flex_deg: Upper (flexion-side) limit of the reflex-free angle range, deg.
        v_lower_rad_s: Lower limit of the reflex-free velocity range, rad/s.
        v_upper_rad_s: Upper limit of the reflex-free velocity range, rad/s.
        s_theta: Gain of the angle term, fraction of maximum isometric force (>= 0).
        s_v: Gain of the velocity term, fraction of maximum isometric force (>= 0).
        k: Sigmoid slope (>= 0), in 1/deg for the angle term and s/rad for the velocity term.

    Raises:
        ValueError: If a value is not finite, a gain or ``k`` is negative, or a range is
            empty (lower limit not below the upper one).
    """

    theta_ext_deg: float
    theta_flex_deg: float
    v_lower_rad_s: float
    v_upper_rad_s: float
    s_theta: float
    s_v: float
    k: float

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or isinstance(
                value, bool
            ):
                raise ValueError(
                    f"SpasticityParams.{field.name} must be a real number, got {value!r}."
                )
            if not math.isfinite(value):
                raise ValueError(f"SpasticityParams.{field.name} must be finite, got {value!r}.")
            object.__setattr__(self, field.name, float(value))
        for name in ("s_theta", "s_v", "k"):
            if getattr(self, name) < 0.0:
                raise ValueError(
                    f"SpasticityParams.{name} must be >= 0, got {getattr(self, name)!r}."
                )
        if not self.theta_ext_deg < self.theta_flex_deg:
            raise ValueError(
                "SpasticityParams needs theta_ext_deg < theta_flex_deg, got "
                f"theta_ext_deg={self.theta_ext_deg!r}, theta_flex_deg={self.theta_flex_deg!r}."
            )
        if not self.v_lower_rad_s < self.v_upper_rad_s:
            raise ValueError(
                "SpasticityParams needs v_lower_rad_s < v_upper_rad_s, got "
                f"v_lower_rad_s={self.v_lower_rad_s!r}, v_upper_rad_s={self.v_upper_rad_s!r}."
            )

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of the parameters, in the order of :meth:`as_array`."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def as_array(self) -> np.ndarray:
        """The parameters as a float64 array of shape ``(7,)`` (order of the fields)."""
        return np.array(dataclasses.astuple(self), dtype=np.float64)

    @classmethod
    def from_array(cls, values: Sequence[float] | np.ndarray) -> SpasticityParams:
        """Inverse of :meth:`as_array` (validated)."""
        values = np.asarray(values, dtype=np.float64)
        names = cls.field_names()
        if values.shape != (len(names),):
            raise ValueError(f"Expected {len(names)} values {names}, got shape {values.shape}.")
        return cls(**{n: float(v) for n, v in zip(names, values, strict=True)})


#: Table I of the paper: spasticity levels (Modified Ashworth Scale) 0..3. Level 4 is not
#: modelled (excluded by the paper as unsafe).
LEVELS: Mapping[int, SpasticityParams] = MappingProxyType(
    {
        0: SpasticityParams(-45.0, 95.0, -10.0, 10.0, s_theta=0.0, s_v=0.0, k=0.0),
        1: SpasticityParams(-35.0, 80.0, -1.0, 1.0, s_theta=0.2, s_v=0.2, k=0.5),
        2: SpasticityParams(-30.0, 75.0, -0.5, 0.5, s_theta=0.3, s_v=0.3, k=0.2),
        3: SpasticityParams(-15.0, 60.0, -0.25, 0.25, s_theta=0.3, s_v=0.5, k=0.1),
    }
)


#: The levels the twin models, in order (Table I; level 4 is left out as unsafe).
VALID_LEVELS: tuple[int, ...] = tuple(sorted(LEVELS))
#: Level setting that draws the level uniformly from :data:`VALID_LEVELS` at every reset.
RANDOM_LEVEL = "random"


def check_level_setting(level: Any) -> int | str:
    """A level (``int`` of :data:`VALID_LEVELS`) or :data:`RANDOM_LEVEL`, or a ``ValueError``."""
    if isinstance(level, str) and level == RANDOM_LEVEL:
        return RANDOM_LEVEL
    return check_level(level)


def check_level(level: Any) -> int:
    """The level as an ``int`` key of :data:`LEVELS`, or a ``ValueError``."""
    if isinstance(level, (bool, np.bool_)) or not isinstance(level, (int, np.integer)):
        raise ValueError(f"Unknown spasticity level {level!r}; expected one of {sorted(LEVELS)}.")
    if int(level) not in LEVELS:
        raise ValueError(f"Unknown spasticity level {level!r}; expected one of {sorted(LEVELS)}.")
    return int(level)


def sample_subject(
    level: int, rng: np.random.Generator, rel_std: float = SUBJECT_REL_STD
) -> SpasticityParams:
    """Draw an individual subject of a level.

    Every parameter ``p`` of the level becomes ``p + rel_std * |p| * z`` with independent
    standard normals ``z`` (7 draws from *rng*). A draw that would be invalid (a negative
    gain or an empty range: more than 7 standard deviations away with the default
    ``rel_std``) is redrawn.

    Args:
        level: Spasticity level, a key of :data:`LEVELS`.
        rng: Source of randomness (for an env: ``env.np_random``); same state, same subject.
        rel_std: Standard deviation relative to each parameter's nominal absolute value.

    Returns:
        The subject's parameters.

    Raises:
        ValueError: If *level* is unknown or *rel_std* is negative or not finite.
    """
    nominal = LEVELS[check_level(level)].as_array()
    if not (math.isfinite(rel_std) and rel_std >= 0.0):
        raise ValueError(f"rel_std must be a finite value >= 0, got {rel_std!r}.")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}.")
    std = rel_std * np.abs(nominal)
    for _ in range(_MAX_SUBJECT_DRAWS):
        try:
            return SpasticityParams.from_array(nominal + std * rng.standard_normal(nominal.size))
        except ValueError:
            continue
    raise RuntimeError(  # pragma: no cover - needs rel_std far beyond any sensible value
        f"No valid subject of level {level} in {_MAX_SUBJECT_DRAWS} draws with rel_std={rel_std}."
    )
