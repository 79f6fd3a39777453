"""Simulated Modified Ashworth (MAS) examination of the knee flexors on the twin.

The examiner moves the relaxed knee through its range in about one second: here the exo
drives it from 90 deg of flexion to ``end_deg`` along a minimum-jerk profile (Flash and
Hogan 1985: the smooth, bell-shaped speed of a hand movement; peak speed 1.875 times the
mean, 2.6 rad/s for the default 80 deg in 1 s) with the stiff PD of
:mod:`myoexo.clinical.stretch`. The resisting torque is the exo's torque along the motion,
what the examiner's hand feels: the limb's weight and inertia, the passive muscles and the
reflex. The MAS grades the *increase* of that resistance over a normal limb (Bohannon and Smith
1987):

* 1: a catch and release, or minimal resistance at the end of the range;
* 1+: a catch followed by minimal resistance through less than half of the range;
* 2: more marked resistance through most of the range, the limb still easily moved;
* 3: considerable increase in tone, passive movement difficult.

So the analysis compares each level with level 0 (always simulated as the reference) at the
same knee angle: ``excess_nm`` = resisting torque minus level 0's. Per level (range position
``s`` = the fraction of the commanded range covered, 0 at the start and 1 at ``end_deg``):

``peak_torque_nm``, ``mean_torque_nm``
    The largest resisting torque of the motion, and its mean over the range (uniform in
    ``s``, from 0 to the position reached).
``onset_position``, ``onset_deg``
    Where the excess first reaches ``onset_threshold_nm`` (NaN: never): a MAS-1 catch at the
    end of the range reads near 1, resistance through most of the range near 0.
``resisted_fraction``
    The fraction of the range over which the excess is at or above the threshold: MAS 1
    small, 1+ under a half, 2 "most of the range".
``excess_mean_nm``, ``excess_peak_nm``
    Mean (over the range) and largest excess over level 0.
``reached_position``
    The range position the knee reached (the PD lags by resisting torque / Kp).

CLI::

    myoexo clinic mas [--levels 0 1 2 3] [--reflex NAME] [--end-deg 10]
                    [--duration-s 1.0] [--subject-seed N] [--out DIR]

Every field of :class:`MASExamParams` but ``drive`` is an option of its own name
(``--onset-threshold-nm``, ...), and so is every field of
:class:`~myoexo.clinical.common.ExamOptions`.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.clinical.common import (
    DriveParams,
    ExamOptions,
    add_exam_arguments,
    control_substeps,
    interp_on_angle,
    levels_option,
    normalise_levels,
    print_table,
    resolve_twin,
    simulate_drive,
)
from myoexo.control.reference import minimum_jerk_position, minimum_jerk_rate
from myoexo.runtime.fields import check_fields, from_options, option
from myoexo.spasticity.levels import SpasticityParams
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel, reflex_label

if TYPE_CHECKING:
    import mujoco
    import pandas as pd
    from matplotlib.figure import Figure

    from myoexo.clinical.common import PoseFn

__all__ = [
    "MASExamParams",
    "MASExamResult",
    "add_arguments",
    "minimum_jerk",
    "plot_mas_exam",
    "run",
    "run_mas_exam",
]

#: The healthy reference level the excess is measured against.
REFERENCE_LEVEL = 0
#: Range positions on which the means over the range are taken.
_RANGE_GRID_POINTS = 201


@dataclasses.dataclass(frozen=True)
class MASExamParams:
    """Parameters of the simulated MAS examination (defaults: the seated clinical exam; each
    field but ``drive`` is an option of ``myoexo clinic mas``).

    Attributes:
        start_deg: Knee flexion at the start, deg (90: the seated rest).
        end_deg: Commanded knee flexion at the end, deg (10, as the Tardieu test: the
            seated hamstrings stop the knee near 16-22 deg).
        duration_s: Time through the range, s ("about one second", the MAS count of one).
        hold_s: Time held at the start before the motion (tone settles), s.
        end_hold_s: Time held at the end, s.
        onset_threshold_nm: Excess over level 0 that counts as felt resistance, Nm (10 Nm,
            as the Tardieu catch; a tenth of the motor's 100 Nm).
        levels: Spasticity levels to report (level 0 is always simulated as the reference).
        drive: The exo PD's gains and the control period.
    """

    start_deg: float = option(90.0, "knee flexion at the start", low=0.0, high=120.0, unit="deg")
    end_deg: float = option(
        10.0, "commanded knee flexion at the end", low=0.0, high=120.0, unit="deg"
    )
    duration_s: float = option(1.0, "time through the range", low=0.0, above=True, unit="s")
    hold_s: float = option(0.5, "time held at the start before the motion", low=0.0, unit="s")
    end_hold_s: float = option(0.2, "time held at the end", low=0.0, unit="s")
    onset_threshold_nm: float = option(
        10.0, "excess over level 0 that counts as felt resistance",
        low=0.0, above=True, unit="Nm",
    )  # fmt: skip
    levels: tuple[int, ...] = levels_option()
    drive: DriveParams = dataclasses.field(default_factory=DriveParams)

    def __post_init__(self) -> None:
        check_fields(self)
        normalise_levels(self)
        if not self.end_deg < self.start_deg:
            raise ValueError(
                f"MASExamParams.end_deg = {self.end_deg!r} must be below start_deg = "
                f"{self.start_deg!r}: the exam extends the knee (moves the flexors)"
            )

    @property
    def span_deg(self) -> float:
        """The commanded range, deg (positive)."""
        return self.start_deg - self.end_deg


def minimum_jerk(
    time_s: np.ndarray, params: MASExamParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The exam's reference: held, a minimum-jerk move ``s = 10 u^3 - 15 u^4 + 6 u^5``
    (``u`` = time / duration; :func:`myoexo.control.reference.minimum_jerk_position`) from
    ``start_deg`` to ``end_deg``, held.

    Returns:
        ``(angle_deg, vel_rad_s, moving)``: reference angle and velocity (flexion positive)
        and whether the step is part of the motion.
    """
    u = np.clip((np.asarray(time_s, dtype=np.float64) - params.hold_s) / params.duration_s, 0, 1)
    s = minimum_jerk_position(u)
    ds_dt = minimum_jerk_rate(u) / params.duration_s
    span_rad = math.radians(params.span_deg)
    moving = (time_s >= params.hold_s) & (time_s <= params.hold_s + params.duration_s)
    return params.start_deg - params.span_deg * s, -span_rad * ds_dt, moving


@dataclasses.dataclass(frozen=True)
class MASExamResult:
    """Outcome of :func:`run_mas_exam`.

    Attributes:
        summary: One row per level (see :meth:`table`).
        traces: One row per control step of the motion: ``level, time_s, ref_deg, knee_deg,
            position`` (range position), ``knee_vel_rad_s, resisting_torque_nm,
            leg_resisting_nm, excess_nm, sc_total, tracking_error_deg``.
        params: The exam parameters.
        reflex: Name of the reflex model.
    """

    summary: pd.DataFrame
    traces: pd.DataFrame
    params: MASExamParams
    reflex: str

    def table(self) -> pd.DataFrame:
        """Per level: ``peak_torque_nm, mean_torque_nm, onset_position, onset_deg,
        resisted_fraction, excess_mean_nm, excess_peak_nm, reached_position`` (module
        docstring) and ``reflex``."""
        return self.summary.copy()


def _simulate(
    model: mujoco.MjModel,
    pose: PoseFn,
    level: int,
    params: MASExamParams,
    reflex: str | ReflexModel,
    subject: SpasticityParams | None,
) -> pd.DataFrame:
    import pandas as pd

    _, dt = control_substeps(params.drive, model)
    total_s = params.hold_s + params.duration_s + params.end_hold_s
    times = np.arange(math.ceil(total_s / dt)) * dt
    ref_deg, ref_vel, moving = minimum_jerk(times, params)
    _, col = simulate_drive(
        model,
        level,
        ref_deg,
        ref_vel,
        pose=pose,
        start_deg=params.start_deg,
        drive=params.drive,
        reflex=reflex,
        subject=subject,
    )
    trace = pd.DataFrame(
        {
            "level": level,
            "time_s": times,
            "ref_deg": ref_deg,
            "knee_deg": col["knee_deg"],
            "position": (params.start_deg - col["knee_deg"]) / params.span_deg,
            "knee_vel_rad_s": col["knee_vel_rad_s"],
            # along the extension (-1 x flexion positive): the exo pushes, the limb resists
            "resisting_torque_nm": -col["exo_torque_nm"],
            "leg_resisting_nm": col["leg_torque_nm"],
            "sc_total": col["sc_total"],
            "tracking_error_deg": ref_deg - col["feedback_deg"],
        }
    )
    return trace[moving].reset_index(drop=True)


def _range_mean(position: np.ndarray, values: np.ndarray, reached: float) -> float:
    grid = np.linspace(0.0, reached, _RANGE_GRID_POINTS)
    return float(np.nanmean(interp_on_angle(position, values, grid)))


def _analyse(trace: pd.DataFrame, params: MASExamParams) -> dict[str, Any]:
    pos = trace["position"].to_numpy()
    res = trace["resisting_torque_nm"].to_numpy()
    excess = trace["excess_nm"].to_numpy()
    reached = float(pos.max())
    felt = excess >= params.onset_threshold_nm
    onset = np.flatnonzero(felt)
    grid = np.linspace(0.0, reached, _RANGE_GRID_POINTS)
    excess_on_grid = interp_on_angle(pos, excess, grid)
    return {
        "peak_torque_nm": float(res.max()),
        "mean_torque_nm": _range_mean(pos, res, reached),
        "onset_position": float(pos[onset[0]]) if onset.size else math.nan,
        "onset_deg": float(trace["knee_deg"].iloc[onset[0]]) if onset.size else math.nan,
        "resisted_fraction": float(np.mean(excess_on_grid >= params.onset_threshold_nm)),
        "excess_mean_nm": float(np.nanmean(excess_on_grid)),
        "excess_peak_nm": float(np.nanmax(excess)),
        "reached_position": reached,
    }


def run_mas_exam(
    params: MASExamParams = MASExamParams(),
    *,
    reflex: str | ReflexModel = DEFAULT_REFLEX,
    subjects: Mapping[int, SpasticityParams] | None = None,
    model: mujoco.MjModel | None = None,
    pose: PoseFn | None = None,
) -> MASExamResult:
    """Run the MAS examination at every level of *params* (and level 0, the reference).

    Args:
        params: Exam parameters.
        reflex: Reflex model, a registered name (``"stretch"``, ``"uniform"``,
            ``"persistent"``, ...) or a :class:`~myoexo.spasticity.ReflexModel`.
        subjects: Individual reflex parameters per level (default: nominal Table I; the
            level-0 reference stays nominal unless given).
        model: The twin (default: the seated twin, ``TwinParams()``).
        pose: Its posing function (default ``myoexo.model.pose_twin``).

    Returns:
        The per-level table and the traces (:class:`MASExamResult`).

    Raises:
        ValueError: If the reflex is unknown.
    """
    import pandas as pd

    label = reflex_label(reflex)
    model, pose = resolve_twin(model, pose)
    sims = {}
    for level in dict.fromkeys((REFERENCE_LEVEL, *params.levels)):
        subject = None if subjects is None else subjects.get(level)
        sims[level] = _simulate(model, pose, level, params, reflex, subject)
    ref = sims[REFERENCE_LEVEL]
    rows, traces = [], []
    for level in params.levels:
        trace = sims[level]
        trace["excess_nm"] = trace["resisting_torque_nm"] - interp_on_angle(
            ref["knee_deg"], ref["resisting_torque_nm"], trace["knee_deg"]
        )
        rows.append({"level": level, **_analyse(trace, params)})
        traces.append(trace)
    summary = pd.DataFrame(rows).assign(reflex=label)
    return MASExamResult(summary, pd.concat(traces, ignore_index=True), params, label)


# ----------------------------------------------------------------------------- figure
def plot_mas_exam(result: MASExamResult) -> Figure:
    """Resisting torque, and its excess over level 0, vs range position per level."""
    from matplotlib.figure import Figure

    from myoexo.viz.colors import LEVEL_COLORS

    p = result.params
    fig = Figure(figsize=(11, 4), constrained_layout=True)
    ax_t, ax_x = fig.subplots(1, 2, sharex=True)
    summary = result.summary.set_index("level")
    for level, row in summary.iterrows():
        sel = result.traces[result.traces["level"] == level]
        color = LEVEL_COLORS[int(level)]  # type: ignore[call-overload]
        ax_t.plot(sel["position"], sel["resisting_torque_nm"], color=color, label=f"level {level}")
        ax_x.plot(sel["position"], sel["excess_nm"], color=color, label=f"level {level}")
        if not math.isnan(row["onset_position"]):
            ax_x.plot(row["onset_position"], p.onset_threshold_nm, "o", color=color)
    ax_x.axhline(p.onset_threshold_nm, color="0.5", ls=":", label="felt resistance")
    ax_t.set(xlabel="range position (0: 90 deg, 1: end)", ylabel="resisting torque (Nm)")
    ax_t.set_title("exo torque against the motion")
    ax_x.set(xlabel="range position (0: 90 deg, 1: end)", ylabel="excess over level 0 (Nm)")
    ax_x.set_title("increase of tone over level 0 (onset marked)")
    for ax in (ax_t, ax_x):
        ax.grid(alpha=0.3)
    ax_t.legend(fontsize=8)
    fig.suptitle(
        f"Simulated MAS examination ({result.reflex} reflex): knee {p.start_deg:g} → "
        f"{p.end_deg:g} deg in {p.duration_s:g} s (minimum jerk)"
    )
    return fig


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo clinic mas``: :class:`MASExamParams`' fields, ``--reflex`` and
    :class:`~myoexo.clinical.common.ExamOptions`' fields."""
    add_exam_arguments(parser, MASExamParams)


def run(args: argparse.Namespace) -> int:
    """Run the exam, print the per-level table, optionally write CSVs and the figure."""
    params = from_options(MASExamParams, args)
    options = from_options(ExamOptions, args, reflex=args.reflex)
    result = run_mas_exam(params, reflex=options.reflex, subjects=options.subjects(params.levels))
    print_table(result.table())
    options.write("mas_exam", result.table(), result.traces, lambda: plot_mas_exam(result))
    return 0
