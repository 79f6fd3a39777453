"""The paper's PID on a twin's subjects: the measurement every reflex fit and check reads.

:func:`pid_outcome` runs the paper's Ziegler-Nichols PID on subjects of one level and reduces
the episodes to a :class:`PIDOutcome` (final error, overshoot, settling, peak exo torque);
:func:`bisect_final_error` fits one reflex parameter whose growth moves that final error
monotonically up. ``myoexo twin calibrate`` (:mod:`myoexo.studies.calibrate`), the joint fit of
the ``"tsrt"`` reflex (:mod:`myoexo.studies.joint_fit`) and the validation table
(:mod:`myoexo.studies.validate`) use them.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from myoexo.evaluation.config import CALIBRATION_ROOT_SEED
from myoexo.spasticity.registry import ReflexModel

__all__ = ["PIDOutcome", "bisect_final_error", "pid_outcome"]


@dataclass(frozen=True)
class PIDOutcome:
    """The PID on one level of a twin: means (and spread) over the subjects.

    Attributes:
        level: Spasticity level.
        subjects: Episodes.
        final_error_deg: Mean final error (knee - target, deg; > 0 short of the target).
        final_error_std_deg: Its standard deviation over the subjects.
        overshoot_deg: Mean overshoot past the target (deg).
        settled_fraction: Fraction of subjects whose knee settled (2 % band).
        peak_exo_torque_nm: Mean over the subjects of the peak exo torque, Nm.
        settling_time_s: Median settling time of the settled subjects, s (NaN if none).
        peak_misalignment_deg: The largest misalignment of the exo hinge from the knee over
            the subjects' episodes, deg.
    """

    level: int
    subjects: int
    final_error_deg: float
    final_error_std_deg: float
    overshoot_deg: float
    settled_fraction: float
    peak_exo_torque_nm: float = math.nan
    settling_time_s: float = math.nan
    peak_misalignment_deg: float = math.nan


def pid_outcome(
    level: int,
    reflex: ReflexModel,
    subjects: int,
    root_seed: int = CALIBRATION_ROOT_SEED,
    ramp_s: float | None = None,
) -> PIDOutcome:
    """The paper's PID on ``subjects`` subjects of ``level`` with the reflex ``reflex``
    (following a target ramped over ``ramp_s`` s, :attr:`PIDConfig.ramp_s
    <myoexo.control.pid.PIDConfig.ramp_s>`, if given)."""
    from myoexo.control import PID, PIDConfig
    from myoexo.envs import TaskParams, make_env
    from myoexo.evaluation.config import subject_seed
    from myoexo.evaluation.engine import run_episode

    env = make_env(level, reflex=reflex)
    pid = PID(PIDConfig(ramp_s=ramp_s or 0.0), dt_s=TaskParams().control_period_s)
    try:
        rows = [
            run_episode(env, pid, subject_seed(level, i, root_seed)).metrics
            for i in range(subjects)
        ]
    finally:
        env.close()
    final = np.array([m.final_error_deg for m in rows])
    overshoot = np.array([m.target_overshoot_deg for m in rows])
    settling = np.array([m.settling_time_s for m in rows])
    settled = np.isfinite(settling)
    return PIDOutcome(
        level=level,
        subjects=subjects,
        final_error_deg=float(final.mean()),
        final_error_std_deg=float(final.std(ddof=1)) if subjects > 1 else 0.0,
        overshoot_deg=float(overshoot.mean()),
        settled_fraction=float(settled.mean()),
        peak_exo_torque_nm=float(np.mean([m.peak_exo_torque_nm for m in rows])),
        settling_time_s=float(np.median(settling[settled])) if settled.any() else math.nan,
        peak_misalignment_deg=float(max(m.peak_misalignment_deg for m in rows)),
    )


def bisect_final_error(
    outcome: Callable[[float], PIDOutcome],
    bracket: tuple[float, float],
    target_final_error_deg: float,
    tol: float,
    level: int,
    name: str,
) -> tuple[float, PIDOutcome]:
    """Bisection on one reflex parameter whose growth moves the PID's mean final error
    monotonically up: ``(value, outcome)`` of the value whose final error came closest to
    the target (ties: the lower bracket end).

    Args:
        outcome: The PID's outcome at a parameter value.
        bracket: ``(low, high)`` values whose outcomes must enclose the target.
        target_final_error_deg: The mean final error sought, deg.
        tol: Stop once the bracket is this narrow.
        level: The level (for the message).
        name: The parameter's name (for the message).

    Raises:
        ValueError: The target is not bracketed.
    """
    lo, hi = bracket
    out_lo, out_hi = outcome(lo), outcome(hi)
    if not out_lo.final_error_deg <= target_final_error_deg <= out_hi.final_error_deg:
        raise ValueError(
            f"level {level}: the target final error {target_final_error_deg} deg is not "
            f"between {out_lo.final_error_deg:.2f} ({name} {lo}) and "
            f"{out_hi.final_error_deg:.2f} deg ({name} {hi})"
        )

    def miss(candidate: tuple[float, PIDOutcome]) -> float:
        return abs(candidate[1].final_error_deg - target_final_error_deg)

    best = min(((lo, out_lo), (hi, out_hi)), key=miss)
    while hi - lo > tol:
        mid = 0.5 * (lo + hi)
        out_mid = outcome(mid)
        if miss((mid, out_mid)) < miss(best):
            best = (mid, out_mid)
        if out_mid.final_error_deg < target_final_error_deg:
            lo = mid
        else:
            hi = mid
    return best
