"""Simulated clinical stretch test (Tardieu / Modified Ashworth manoeuvre) on the twin.

The exo moves the relaxed, spastic knee through its range at a constant angular velocity, as a
clinician does in the Tardieu test, once slowly and once fast. A stiff PD position controller on
the exo motor makes the human knee angle track a trapezoidal-velocity ramp (the feedback is the
human knee, as the clinician imposes the limb's motion; the exo encoder is an option); the
spastic reflex (:class:`~myoexo.spasticity.SpasticityStage`) runs in the muscle-command
pipeline at every control step (10 ms, like the envs) and MuJoCo's activation dynamics turn the
excitation into muscle force. The torque the exo has to produce to keep the prescribed motion is the
*resisting torque*: it must grow with the stretch velocity and with the spasticity level.

Sign conventions: angles are flexion positive (deg), the exo torque is flexion positive (Nm),
and the resisting torque is the exo torque along the direction of motion (positive: the limb
resists and the exo pushes). The default manoeuvre is a knee extension from 90 to 20 deg,
which stretches the spastic hamstrings and gastrocnemii. It stops at 20 deg because with the hip
at 90 deg flexion the passive hamstrings limit extension (the clinical popliteal angle): near
full extension the resistance is passive tension at any speed and level, not the reflex.

The leg's own torque at the knee (its muscles' and its passive knee's springs) is reported
as well. Rajagopal's knee couples the tibial and patellar coordinates to ``knee_angle_r`` by
joint equalities, and the quadriceps act through the patella, so the torque is ``sum_j
(qfrc_actuator[j] + qfrc_spring[j]) dq_j/dtheta`` over the knee and its coupled coordinates
(virtual work along the coupling), not the entry of ``knee_angle_r`` alone.

CLI::

    myoexo clinic stretch [--levels 0 1 2 3] [--velocities-rad-s 0.2 3.0] [--out DIR]

Every field of :class:`StretchTestParams` is an option of its own name (``--start-deg``,
``--kp-nm-per-rad``, ``--feedback-joint exo_knee``, ...).
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Iterable
from pathlib import Path
from typing import TYPE_CHECKING, Protocol

import numpy as np

from myoexo.clinical.common import (
    FEEDBACK_JOINTS,
    DriveParams,
    PoseFn,
    control_substeps,
    levels_option,
    normalise_levels,
    resolve_twin,
    simulate_drive,
)
from myoexo.model.leg import KNEE_JOINT
from myoexo.runtime.fields import add_options, check_fields, from_options, option
from myoexo.spasticity.levels import LEVELS, SpasticityParams
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel

if TYPE_CHECKING:
    import mujoco
    import pandas as pd

__all__ = [
    "MOVING_PHASES",
    "PHASES",
    "StretchOutput",
    "StretchTestParams",
    "StretchTestResult",
    "add_arguments",
    "check_two_speeds",
    "reference_profile",
    "run",
    "run_stretch_test",
    "simulate_stretch",
    "simulate_two_speeds",
]

#: Phases of a stretch-test trace, in order (the categories of its ``phase`` column).
PHASES: tuple[str, ...] = ("hold", "accelerate", "constant", "decelerate", "end_hold")
#: The phases during which the knee moves.
MOVING_PHASES: tuple[str, ...] = PHASES[1:4]


@dataclasses.dataclass(frozen=True)
class StretchTestParams:
    """Parameters of the simulated stretch test (each field is an option of ``myoexo clinic
    stretch``).

    Attributes:
        start_deg: Knee angle at the start of the stretch, deg (flexion positive).
        end_deg: Knee angle at the end of the stretch, deg.
        velocities_rad_s: Stretch speeds (magnitudes), rad/s: slow and fast Tardieu velocities.
        levels: Spasticity levels to test.
        kp_nm_per_rad: Proportional gain of the exo position controller, Nm/rad (as stiff as
            the 10 ms control period and the exo's light link allow).
        kd_nm_s_per_rad: Derivative gain of the exo position controller, Nm s/rad.
        accel_time_s: Time to reach (and to leave) the stretch speed, s.
        hold_s: Time held at the start angle before the stretch (the reflex tone and the
            activations settle), s.
        end_hold_s: Time held at the end angle after the stretch, s.
        control_period_s: Control period (the stage and the PD run once per period), s.
        feedback_joint: Joint whose angle the PD controls: the human knee (default) or the
            exo hinge (``"exo_knee"``, what a real device's encoder measures).
    """

    start_deg: float = option(
        90.0, "knee flexion at the start of the stretch", low=0.0, high=120.0, unit="deg"
    )
    end_deg: float = option(
        20.0, "knee flexion at the end of the stretch", low=0.0, high=120.0, unit="deg"
    )
    velocities_rad_s: tuple[float, ...] = option(
        (0.2, 3.0), "stretch speeds", low=0.0, above=True, unit="rad/s", metavar="RAD_S"
    )
    levels: tuple[int, ...] = levels_option()
    kp_nm_per_rad: float = option(
        400.0, "proportional gain of the exo's position controller",
        low=0.0, unit="Nm/rad", metavar="GAIN",
    )  # fmt: skip
    kd_nm_s_per_rad: float = option(
        5.0, "derivative gain of the exo's position controller",
        low=0.0, unit="Nm s/rad", metavar="GAIN",
    )  # fmt: skip
    accel_time_s: float = option(
        0.05, "time to reach (and to leave) the stretch speed", low=0.0, unit="s"
    )
    hold_s: float = option(
        0.5, "time held at the start angle before the stretch", low=0.0, unit="s"
    )
    end_hold_s: float = option(
        0.2, "time held at the end angle after the stretch", low=0.0, unit="s"
    )
    control_period_s: float = option(
        0.01, "control period (the reflex stage and the PD run once per period)",
        low=0.0, above=True, unit="s",
    )  # fmt: skip
    feedback_joint: str = option(
        KNEE_JOINT, "joint whose angle the PD controls", choices=FEEDBACK_JOINTS, metavar="JOINT"
    )

    def __post_init__(self) -> None:
        check_fields(self)
        normalise_levels(self)
        if not self.velocities_rad_s:
            raise ValueError("StretchTestParams.velocities_rad_s is empty: give at least one speed")
        object.__setattr__(self, "velocities_rad_s", tuple(float(v) for v in self.velocities_rad_s))
        if self.start_deg == self.end_deg:
            raise ValueError(
                f"StretchTestParams.start_deg and end_deg must differ (both {self.start_deg!r})."
            )

    @property
    def direction(self) -> float:
        """+1 for a flexion stretch, -1 for an extension stretch."""
        return 1.0 if self.end_deg > self.start_deg else -1.0

    @property
    def drive(self) -> DriveParams:
        """The controller gains, control period and feedback joint as
        :class:`~myoexo.clinical.common.DriveParams`."""
        return DriveParams(
            kp_nm_per_rad=self.kp_nm_per_rad,
            kd_nm_s_per_rad=self.kd_nm_s_per_rad,
            control_period_s=self.control_period_s,
            feedback_joint=self.feedback_joint,
        )


@dataclasses.dataclass(frozen=True)
class StretchTestResult:
    """Outcome of :func:`run_stretch_test`.

    Attributes:
        traces: One row per control step and condition: ``level, vel_rad_s, time_s, phase,
            ref_deg, exo_deg, knee_deg, knee_vel_rad_s, sc_total, exo_torque_nm,
            resisting_torque_nm, leg_torque_nm (the leg's own torque at the human knee
            along its coupled motion, muscles and passive knee, flexion positive),
            saturated, tracking_error_deg`` (reference minus the feedback joint's angle).
        summary: One row per (level, speed): ``peak_resisting_torque_nm`` (over the
            constant-speed phase), ``mean_resisting_torque_nm`` (same phase),
            ``peak_resisting_torque_all_nm`` (whole motion, acceleration included),
            ``peak_sc_total``, ``max_tracking_error_deg``, ``mean_knee_vel_rad_s`` (constant
            phase, along the motion), ``saturated_fraction``.
        params: The parameters of the test.
    """

    traces: pd.DataFrame
    summary: pd.DataFrame
    params: StretchTestParams

    def peak_table(self) -> pd.DataFrame:
        """Peak resisting torque (Nm), levels as rows and speeds (rad/s) as columns."""
        return self.summary.pivot(
            index="level", columns="vel_rad_s", values="peak_resisting_torque_nm"
        )


def reference_profile(
    time_s: np.ndarray | float, vel_rad_s: float, params: StretchTestParams
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Trapezoidal-velocity reference of the exo knee.

    The knee is held at ``start_deg`` for ``hold_s``, accelerates to *vel_rad_s* in
    ``accel_time_s``, moves at constant speed, decelerates and stops at ``end_deg``.

    Args:
        time_s: Time(s) since the start of the test, s.
        vel_rad_s: Stretch speed (magnitude), rad/s.
        params: Test parameters.

    Returns:
        ``(angle_deg, vel_rad_s, phase)`` with the phase code 0 hold, 1 accelerate,
        2 constant speed, 3 decelerate, 4 end hold.
    """
    t = np.asarray(time_s, dtype=np.float64) - params.hold_s
    span = math.radians(abs(params.end_deg - params.start_deg))
    ta = min(params.accel_time_s, span / vel_rad_s)  # short moves never reach the speed
    v = min(vel_rad_s, span / ta) if ta > 0 else vel_rad_s
    t_move = span / v + ta  # total motion time of the trapezoid
    t_const_end = t_move - ta
    acc = v / ta if ta > 0 else 0.0
    s = np.where(
        t <= 0,
        0.0,
        np.where(
            t < ta,
            0.5 * acc * t**2,
            np.where(
                t < t_const_end,
                0.5 * acc * ta**2 + v * (t - ta),
                np.where(t < t_move, span - 0.5 * acc * (t_move - t) ** 2, span),
            ),
        ),
    )
    sdot = np.where(
        t <= 0,
        0.0,
        np.where(
            t < ta,
            acc * t,
            np.where(t < t_const_end, v, np.where(t < t_move, acc * (t_move - t), 0.0)),
        ),
    )
    phase = np.select([t <= 0, t < ta, t < t_const_end, t < t_move], [0, 1, 2, 3], default=4)
    angle = params.start_deg + params.direction * np.degrees(s)
    return angle, params.direction * sdot, phase


def _motion_duration_s(vel_rad_s: float, params: StretchTestParams) -> float:
    span = math.radians(abs(params.end_deg - params.start_deg))
    ta = min(params.accel_time_s, span / vel_rad_s)
    return params.hold_s + span / vel_rad_s + ta + params.end_hold_s


def simulate_stretch(
    model: mujoco.MjModel,
    level: int,
    vel_rad_s: float,
    params: StretchTestParams = StretchTestParams(),
    *,
    pose: PoseFn,
    subject: SpasticityParams | None = None,
    reflex: str | ReflexModel = DEFAULT_REFLEX,
) -> pd.DataFrame:
    """Simulate one stretch of the twin at one level and one speed.

    Args:
        model: The twin (human + exo); a fresh ``MjData`` is made for the run.
        level: Spasticity level; the reflex uses its nominal Table I parameters unless
            *subject* is given.
        vel_rad_s: Stretch speed (magnitude), rad/s.
        params: Test parameters.
        pose: ``pose(model, data, knee_angle_deg=...)`` that puts the twin at the start angle.
        subject: Individual reflex parameters (e.g. from
            :func:`~myoexo.spasticity.sample_subject`).
        reflex: Reflex model, a registered name (``"stretch"``, ``"uniform"``,
            ``"persistent"``, ...) or a :class:`~myoexo.spasticity.ReflexModel`.

    Returns:
        One row per control step (see :class:`StretchTestResult`); the state columns are at
        the start of the step, the torques are those applied during it.

    Raises:
        ValueError: If the level, speed or model names are invalid.
    """
    import pandas as pd

    if level not in LEVELS:
        raise ValueError(f"Unknown spasticity level {level!r}; expected one of {sorted(LEVELS)}.")
    if not (math.isfinite(vel_rad_s) and vel_rad_s > 0):
        raise ValueError(f"vel_rad_s must be a positive speed, got {vel_rad_s!r}.")
    drive = params.drive
    _, dt = control_substeps(drive, model)
    n_steps = math.ceil(_motion_duration_s(vel_rad_s, params) / dt)
    times = np.arange(n_steps) * dt
    ref_deg, ref_vel, phase = reference_profile(times, vel_rad_s, params)
    _, col = simulate_drive(
        model,
        level,
        ref_deg,
        ref_vel,
        pose=pose,
        start_deg=params.start_deg,
        drive=drive,
        reflex=reflex,
        subject=subject,
    )
    exo_torque = col["exo_torque_nm"]
    return pd.DataFrame(
        {
            "time_s": times,
            "phase": pd.Categorical.from_codes(
                phase.astype(np.int64),
                categories=pd.Index(list(PHASES)),
            ),
            "ref_deg": ref_deg,
            "exo_deg": col["exo_deg"],
            "knee_deg": col["knee_deg"],
            "knee_vel_rad_s": col["knee_vel_rad_s"],
            "sc_total": col["sc_total"],
            "exo_torque_nm": exo_torque,
            "resisting_torque_nm": params.direction * exo_torque,
            "leg_torque_nm": col["leg_torque_nm"],
            "saturated": np.abs(col["pd_torque_nm"] - exo_torque) > 1e-9,
            "tracking_error_deg": ref_deg - col["feedback_deg"],
        }
    )


class TwoSpeedTest(Protocol):
    """A clinical test made of a slow and a fast stretch (Tardieu, stretch-and-hold)."""

    @property
    def slow_rad_s(self) -> float:
        """The slow stretch's speed, rad/s."""
        ...

    @property
    def fast_rad_s(self) -> float:
        """The fast stretch's speed, rad/s."""
        ...

    @property
    def start_deg(self) -> float:
        """Knee flexion where both stretches start, deg."""
        ...

    @property
    def end_deg(self) -> float:
        """Knee flexion where both stretches end, deg."""
        ...

    def stretch(self, vel_rad_s: float) -> StretchTestParams:
        """The stretch-test parameters of the stretch at *vel_rad_s*."""
        ...


def check_two_speeds(test: TwoSpeedTest) -> None:
    """The rules every two-speed test's parameters keep (its ``__post_init__`` calls this):
    the fast stretch is faster than the slow one, and both extend the knee (``end_deg`` below
    ``start_deg``, stretching the flexors).

    Raises:
        ValueError: Naming the test's class, both fields and their values.
    """
    name = type(test).__name__
    if not test.fast_rad_s > test.slow_rad_s:
        raise ValueError(
            f"{name}.fast_rad_s = {test.fast_rad_s!r} must exceed slow_rad_s = {test.slow_rad_s!r}"
        )
    if not test.end_deg < test.start_deg:
        raise ValueError(
            f"{name}.end_deg = {test.end_deg!r} must be below start_deg = "
            f"{test.start_deg!r}: the test extends the knee (stretches the flexors)"
        )


def simulate_two_speeds(
    test: TwoSpeedTest,
    model: mujoco.MjModel,
    level: int,
    *,
    pose: PoseFn,
    subject: SpasticityParams | None = None,
    reflex: str | ReflexModel = DEFAULT_REFLEX,
) -> dict[str, tuple[float, pd.DataFrame]]:
    """The slow and the fast stretch of a two-speed test at one level (:func:`simulate_stretch`
    with ``test.stretch(speed)``): ``{"slow": (speed rad/s, trace), "fast": ...}``, each trace
    with ``leg_resisting_nm``, the leg's own torque (muscles and passive knee) against the
    motion."""
    runs = {}
    for name, vel in (("slow", test.slow_rad_s), ("fast", test.fast_rad_s)):
        stretch = test.stretch(vel)
        trace = simulate_stretch(
            model, level, vel, stretch, pose=pose, subject=subject, reflex=reflex
        )
        # flexion positive x -direction: the torque that resists the extension
        trace["leg_resisting_nm"] = -stretch.direction * trace["leg_torque_nm"]
        runs[name] = (vel, trace)
    return runs


def _summarize(trace: pd.DataFrame, params: StretchTestParams) -> dict[str, float]:
    moving = trace["phase"].isin(MOVING_PHASES)
    constant = trace["phase"] == "constant"
    if not constant.any():  # a move too short to reach its speed
        constant = moving
    res = trace["resisting_torque_nm"]
    return {
        "peak_resisting_torque_nm": float(res[constant].max()),
        "mean_resisting_torque_nm": float(res[constant].mean()),
        "peak_resisting_torque_all_nm": float(res[moving].max()),
        "peak_sc_total": float(trace["sc_total"][moving].max()),
        "max_tracking_error_deg": float(trace["tracking_error_deg"][moving].abs().max()),
        "mean_knee_vel_rad_s": float(params.direction * trace["knee_vel_rad_s"][constant].mean()),
        "saturated_fraction": float(trace["saturated"][moving].mean()),
    }


def run_stretch_test(
    params: StretchTestParams = StretchTestParams(),
    *,
    model: mujoco.MjModel | None = None,
    pose: PoseFn | None = None,
    subjects: dict[int, SpasticityParams] | None = None,
    progress: bool = False,
    reflex: str | ReflexModel = DEFAULT_REFLEX,
) -> StretchTestResult:
    """Run the stretch test for every level and speed of *params*.

    Args:
        params: Test parameters.
        model: The twin; default: ``myoexo.model.build_model(TwinParams())``.
        pose: Posing function of the twin; default ``myoexo.model.pose_twin``.
        subjects: Optional individual reflex parameters per level (default: Table I).
        progress: Show a tqdm progress bar.
        reflex: Reflex model, a registered name (``"stretch"``, ``"uniform"``,
            ``"persistent"``, ...) or a :class:`~myoexo.spasticity.ReflexModel`.

    Returns:
        Traces and summary (see :class:`StretchTestResult`).
    """
    import pandas as pd

    model, pose = resolve_twin(model, pose)
    conditions: Iterable[tuple[int, float]] = [
        (lv, v) for lv in params.levels for v in params.velocities_rad_s
    ]
    if progress:
        from tqdm.auto import tqdm

        conditions = tqdm(conditions, desc="stretch test")
    traces, rows = [], []
    for level, vel in conditions:
        subject = None if subjects is None else subjects.get(level)
        trace = simulate_stretch(
            model, level, vel, params, pose=pose, subject=subject, reflex=reflex
        )
        rows.append({"level": level, "vel_rad_s": vel, **_summarize(trace, params)})
        traces.append(trace.assign(level=level, vel_rad_s=vel))
    traces_df = pd.concat(traces, ignore_index=True)
    front = ["level", "vel_rad_s"]
    traces_df = traces_df[front + [c for c in traces_df.columns if c not in front]]
    return StretchTestResult(traces_df, pd.DataFrame(rows), params)


# ----------------------------------------------------------------------------- CLI
@dataclasses.dataclass(frozen=True)
class StretchOutput:
    """Where ``myoexo clinic stretch`` writes (its ``--out`` option)."""

    out: Path | None = option(
        None,
        "folder for stretch_summary.csv and stretch_traces.csv (default: print only)",
        folder=True,
        metavar="DIR",
    )

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo clinic stretch``: :class:`StretchTestParams`' fields and
    :class:`StretchOutput`'s."""
    add_options(parser, StretchTestParams)
    add_options(parser, StretchOutput)


def run(args: argparse.Namespace) -> int:
    """Run the stretch test, print the peak resisting torques, optionally write CSVs."""
    params = from_options(StretchTestParams, args)
    out = from_options(StretchOutput, args).out
    result = run_stretch_test(params, progress=True)
    cols = [
        "level", "vel_rad_s", "peak_resisting_torque_nm", "mean_resisting_torque_nm",
        "peak_sc_total", "max_tracking_error_deg", "saturated_fraction",
    ]  # fmt: skip
    print(result.summary[cols].to_string(index=False, float_format=lambda x: f"{x:.3f}"))
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        result.summary.to_csv(out / "stretch_summary.csv", index=False)
        result.traces.to_csv(out / "stretch_traces.csv", index=False)
        print(f"wrote {out / 'stretch_summary.csv'} and {out / 'stretch_traces.csv'}")
    return 0
