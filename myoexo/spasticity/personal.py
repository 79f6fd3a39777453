"""A personal twin: one person's fitted reflex and passive knee, and the fit's uncertainty.

``myoexo twin fit-subject`` fits a person's reflex record
(:class:`~myoexo.spasticity.SpasticityParams`) and two scales of the twin's passive knee
(:class:`~myoexo.model.passive_knee.PassiveKneeScaler`) to their clinical recordings and
writes a report (JSON). :func:`load_subject` reads that report into a
:class:`PersonalSubject`, which an env runs in place of the population's subjects::

    env = gymnasium.make("MyoExoKnee-v2", subject="subject.json")

**The point fit or draws.** :meth:`PersonalSubject.point` is the fitted person.
:meth:`PersonalSubject.draw` draws a person from the fit's uncertainty, so that a controller
comparison carries it: in the fit's normalised coordinates (each parameter's position in its
bounds, log-scaled where the fit searched on a log scale), a normal around the fit whose
covariance is the one the report's intervals come from, ``Sigma = 2 rise f H^-1`` (``H``
the finite-difference Hessian of the time-series objective, ``f`` its value at the fit,
``rise`` the relative rise that bounds an interval). Each eigen-direction's variance is
capped at 1/12, the variance of a uniform draw over the whole bounds, which is also the
variance a flat direction (``H`` not positive there: the recordings do not constrain it)
gets; a draw is clipped to the bounds. The intervals are a tolerance of the objective, not a
likelihood (the fit's own documentation: on synthetic subjects the truth fell outside
several), so the draws say how far the recordings leave the person open, not a coverage
probability. A report without a Hessian (a diagonal-only fit) draws each parameter alone
from its conditional half-width.

A personal subject belongs to the level whose reflex calibration its fit used
(:attr:`PersonalSubject.level`) and to the reflex model it was fitted with.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.spasticity.levels import VALID_LEVELS, SpasticityParams

__all__ = [
    "PASSIVE_SCALES",
    "PersonalSubject",
    "from_unit",
    "load_subject",
    "to_unit",
]

#: The passive knee's scales a personal subject carries, at their twin values.
PASSIVE_SCALES: Mapping[str, float] = {"stiffness_scale": 1.0, "damping_scale": 1.0}
#: The variance of a uniform draw over a parameter's whole bounds (normalised): the cap of
#: a draw's variance in any direction.
_UNIFORM_VARIANCE = 1.0 / 12.0


def to_unit(value: float, low: float, high: float, log: bool = False) -> float:
    """*value*'s position in [0, 1] inside ``[low, high]`` (clipped; log-scaled if *log*)."""
    value = min(max(float(value), low), high)
    if log:
        return math.log(value / low) / math.log(high / low)
    return (value - low) / (high - low)


def from_unit(u: float, low: float, high: float, log: bool = False) -> float:
    """The value at position *u* in [0, 1] inside ``[low, high]`` (clipped)."""
    u = min(max(float(u), 0.0), 1.0)
    if log:
        return low * (high / low) ** u
    return low + u * (high - low)


@dataclasses.dataclass(frozen=True)
class PersonalSubject:
    """One person's twin (module docstring).

    Attributes:
        level: The level whose reflex calibration the fit used.
        reflex: The reflex model it was fitted with.
        values: Every fitted value by name: the :class:`SpasticityParams` fields and the
            passive knee's ``stiffness_scale`` and ``damping_scale``.
        names: The parameters the fit moved (the others have no uncertainty).
        bounds: ``(low, high, log)`` of each name of *names*.
        covariance: Covariance of a draw in the normalised coordinates of *names*
            (``None``: no uncertainty, the point fit only).
        source: Where it was read from (a path, or a description).
    """

    level: int
    reflex: str
    values: Mapping[str, float]
    names: tuple[str, ...] = ()
    bounds: tuple[tuple[float, float, bool], ...] = ()
    covariance: Any = dataclasses.field(default=None, compare=False, repr=False)
    source: str = ""

    def __post_init__(self) -> None:
        if self.level not in VALID_LEVELS:
            raise ValueError(f"level = {self.level!r}; accepted: {VALID_LEVELS}")
        fields = {f.name for f in dataclasses.fields(SpasticityParams)}
        missing = sorted((fields | set(PASSIVE_SCALES)) - set(self.values))
        if missing:
            raise ValueError(f"values lack {missing}")
        object.__setattr__(self, "values", {k: float(v) for k, v in self.values.items()})
        SpasticityParams(**{k: self.values[k] for k in fields})  # a valid reflex record
        for name in PASSIVE_SCALES:
            v = self.values[name]
            if not (math.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} = {v!r} must be a finite number > 0")
        if len(self.bounds) != len(self.names):
            raise ValueError(f"{len(self.names)} names but {len(self.bounds)} bounds")
        if self.covariance is not None:
            cov = np.asarray(self.covariance, dtype=float)
            n = len(self.names)
            if cov.shape != (n, n) or not np.all(np.isfinite(cov)):
                raise ValueError(f"covariance must be a finite {n} x {n} matrix")
            object.__setattr__(self, "covariance", cov)

    @classmethod
    def of(
        cls,
        level: int,
        subject: SpasticityParams,
        *,
        reflex: str,
        stiffness_scale: float = 1.0,
        damping_scale: float = 1.0,
        source: str = "",
    ) -> PersonalSubject:
        """A subject known exactly (no uncertainty): e.g. a synthetic subject's truth."""
        values = {**dataclasses.asdict(subject), "stiffness_scale": stiffness_scale,
                  "damping_scale": damping_scale}  # fmt: skip
        return cls(level, reflex, values, source=source)

    @property
    def subject(self) -> SpasticityParams:
        """The fitted reflex record."""
        return _spasticity(self.values)

    @property
    def has_uncertainty(self) -> bool:
        """Whether :meth:`draw` varies anything."""
        return self.covariance is not None and bool(self.names)

    def point(self) -> tuple[SpasticityParams, float, float]:
        """The fitted person: reflex record, stiffness scale, damping scale."""
        v = self.values
        return self.subject, v["stiffness_scale"], v["damping_scale"]

    def draw(self, rng: np.random.Generator) -> tuple[SpasticityParams, float, float]:
        """A person drawn from the fit's uncertainty (module docstring) with *rng*; the point
        fit where there is none (no draw is taken from *rng* then)."""
        if not self.has_uncertainty:
            return self.point()
        centre = np.array(
            [to_unit(self.values[n], lo, hi, lg) for n, (lo, hi, lg) in zip(
                self.names, self.bounds, strict=True)]
        )  # fmt: skip
        u = rng.multivariate_normal(centre, self.covariance, method="eigh")
        values = dict(self.values)
        for n, (lo, hi, lg), x in zip(self.names, self.bounds, u, strict=True):
            values[n] = from_unit(float(x), lo, hi, lg)
        try:
            subject = _spasticity(values)
        except ValueError:  # an empty window: keep the fit's record
            subject = self.subject
        return subject, values["stiffness_scale"], values["damping_scale"]

    def describe(self) -> str:
        """One line: the source, the level and what varies."""
        what = f"{len(self.names)} parameters drawn" if self.has_uncertainty else "point fit"
        return f"personal subject {self.source or '(in memory)'}, level {self.level}, {what}"


def _spasticity(values: Mapping[str, float]) -> SpasticityParams:
    return SpasticityParams(
        **{f.name: values[f.name] for f in dataclasses.fields(SpasticityParams)}
    )


def _covariance(rows: Sequence[Mapping[str, Any]], unc: Mapping[str, Any]) -> np.ndarray:
    """The draw covariance of the report's fitted parameters (module docstring)."""
    n = len(rows)
    budget = 2.0 * float(unc["rise"]) * float(unc["objective_at_center"])
    matrix = unc.get("hessian_normalised")
    if matrix is not None and len(matrix) == n and budget > 0.0:
        hess = np.array([[np.nan if v is None else v for v in row] for row in matrix], float)
        if np.all(np.isfinite(hess)):
            lam, vec = np.linalg.eigh(0.5 * (hess + hess.T))
            floor = 1e-9 * max(float(np.abs(lam).max()), 1e-300)
            var = np.where(lam > floor, budget / np.where(lam > floor, lam, 1.0), np.inf)
            var = np.minimum(var, _UNIFORM_VARIANCE)
            return (vec * var) @ vec.T
    # diagonal only: each parameter alone, from its conditional half-width
    half = [r.get("half_width_conditional_normalised") for r in rows]
    return np.diag(
        [_UNIFORM_VARIANCE if h is None else min(float(h) ** 2, _UNIFORM_VARIANCE) for h in half]
    )


def load_subject(path: str | Path) -> PersonalSubject:
    """Read ``myoexo twin fit-subject``'s report (JSON) as a :class:`PersonalSubject`.

    Raises:
        ValueError: One line naming the file and what is wrong with it (missing, not JSON,
            not a fit-subject report, a value out of range).
    """
    p = Path(path)
    try:
        report = json.loads(p.read_text())
    except FileNotFoundError:
        raise ValueError(f"{p}: no such file (a report of myoexo twin fit-subject)") from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ValueError(f"{p}: not a JSON report of myoexo twin fit-subject ({e})") from None
    try:
        passive = report["passive_knee"]
        values = {
            **{k: float(v) for k, v in report["subject"].items()},
            "stiffness_scale": float(passive["stiffness_scale"]),
            "damping_scale": float(passive["damping_scale"]),
        }
        fitted = list(report.get("fitted_parameters", []))
        by_name = {r["name"]: r for r in report.get("parameters", [])}
        rows = [by_name[n] for n in fitted]
        bounds = tuple(
            (float(r["bounds"][0]), float(r["bounds"][1]), bool(r.get("log_scale", False)))
            for r in rows
        )
        unc = report.get("uncertainty")
        covariance = None if unc is None or not rows else _covariance(rows, unc)
        return PersonalSubject(
            level=int(report["level"]),
            reflex=str(report["reflex"]),
            values=values,
            names=tuple(fitted),
            bounds=bounds,
            covariance=covariance,
            source=str(p),
        )
    except (KeyError, TypeError, IndexError) as e:
        raise ValueError(
            f"{p}: not a report of myoexo twin fit-subject (missing or malformed {e})"
        ) from None
    except ValueError as e:
        raise ValueError(f"{p}: {e}") from None
