"""Setpoint reference shapes: how a controller's setpoint moves from where the knee starts to
the target.

One home for the shapes the controllers use (the ramped PID's setpoint,
:class:`~myoexo.control.pid.PIDConfig`'s ``reference``; the impedance controller's
reference, :mod:`myoexo.control.impedance`) and for the minimum-jerk polynomial the clinical
exam drives along (:func:`myoexo.clinical.mas.minimum_jerk`):

``"linear"``
    A constant-speed ramp: ``s = u``, speed ``span / duration`` (a jump in speed at both
    ends).
``"minjerk"``
    The minimum-jerk move (Flash and Hogan, *J. Neurosci.* 5(7), 1985): ``s = 10 u^3 - 15
    u^4 + 6 u^5``, the smooth, bell-shaped speed profile of a human reaching movement; speed
    and acceleration are zero at both ends, the peak speed is 1.875 times the mean, at
    mid-move.

Here ``u = elapsed / duration`` clipped to [0, 1] (held at the start before, at the target
after) and ``s`` the fraction of the span covered. The angles can be in any unit; the
velocity is in that unit per second.
"""

from __future__ import annotations

from typing import NamedTuple, TypeVar

import numpy as np

#: The accepted reference shapes (see the module docstring).
REFERENCE_SHAPES: tuple[str, ...] = ("linear", "minjerk")

_Value = TypeVar("_Value", float, np.ndarray)


class ReferencePoint(NamedTuple):
    """The reference at one instant: its angle and its velocity (the angle's unit per
    second)."""

    angle: float
    velocity: float


def minimum_jerk_position(u: _Value) -> _Value:
    """Fraction of the span covered at normalized time *u* in [0, 1] (a float or an array):
    ``s = 10 u^3 - 15 u^4 + 6 u^5`` (0 at ``u = 0``, 1 at ``u = 1``)."""
    return u**3 * (10.0 - 15.0 * u + 6.0 * u**2)


def minimum_jerk_rate(u: _Value) -> _Value:
    """``ds/du = 30 u^2 (1 - u)^2`` of :func:`minimum_jerk_position` (zero at both ends, 1.875
    at ``u = 1/2``); divide by the duration for ``ds/dt``."""
    return 30.0 * u**2 * (1.0 - u) ** 2


def check_reference_shape(shape: str, owner: str = "reference") -> str:
    """*shape* if it is one of :data:`REFERENCE_SHAPES`.

    Raises:
        ValueError: It is not (the message names *owner*).
    """
    if shape not in REFERENCE_SHAPES:
        raise ValueError(f"{owner} = {shape!r}; accepted: {REFERENCE_SHAPES}")
    return shape


def reference_point(
    shape: str, start: float, target: float, elapsed_s: float, duration_s: float
) -> ReferencePoint:
    """The reference of *shape* from *start* to *target* over *duration_s* seconds, at
    *elapsed_s* seconds after it began: held at *start* before (``elapsed_s`` < 0), at
    *target* from ``duration_s`` on. A zero duration is a step (the target, at rest).

    Raises:
        ValueError: An unknown *shape* or a negative *duration_s*.
    """
    check_reference_shape(shape)
    if not duration_s >= 0.0:
        raise ValueError(f"duration_s = {duration_s!r} must be >= 0 s")
    if duration_s == 0.0:
        return ReferencePoint(target, 0.0)
    span = target - start
    moving = 0.0 <= elapsed_s < duration_s
    u = max(0.0, min(1.0, elapsed_s / duration_s))
    if shape == "linear":
        return ReferencePoint(start + u * span, span / duration_s if moving else 0.0)
    s = minimum_jerk_position(u)
    return ReferencePoint(start + s * span, span * minimum_jerk_rate(u) / duration_s)
