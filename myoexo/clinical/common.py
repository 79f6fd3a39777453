"""Machinery shared by the clinical tests: the twin, the reflex host, an exo-driven (or
released) knee, the options every examination command shares and the output files.

The core is :func:`simulate_drive`: the relaxed twin (muscles get the spastic reflex only,
:class:`~myoexo.spasticity.SpasticityStage` in the muscle-command pipeline, at every 10 ms
control step like the envs) with the exo motor either running a stiff PD that makes the
knee follow a reference (``powered``) or commanded to zero (the exo's mass, damping, range
stops and straps stay: it is worn, switched off). :func:`myoexo.clinical.stretch.simulate_stretch`
(the Tardieu stretch and the MAS examination) and the pendulum test are built on it.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import functools
import math
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.envs.twin import Twin
from myoexo.model.exo import EXO_ACTUATOR, EXO_JOINT
from myoexo.model.leg import KNEE_JOINT
from myoexo.runtime.fields import add_options, check_fields, option
from myoexo.spasticity.levels import VALID_LEVELS, SpasticityParams, check_level, sample_subject
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel, add_reflex_argument
from myoexo.spasticity.stage import SpasticityStage

if TYPE_CHECKING:
    import mujoco
    import pandas as pd
    from matplotlib.figure import Figure

    from myoexo.model import TwinParams

__all__ = [
    "DRIVE_COLUMNS",
    "FEEDBACK_JOINTS",
    "DriveParams",
    "ExamOptions",
    "PoseFn",
    "add_exam_arguments",
    "default_twin",
    "draw_subjects",
    "interp_on_angle",
    "motor_nm_per_ctrl",
    "simulate_drive",
    "twin_model",
]

PoseFn = Callable[..., Any]
"""``pose(model, data, knee_angle_deg=...)``: put the twin at a knee angle (``pose_twin``)."""

#: Columns of :func:`simulate_drive`'s record, in order.
DRIVE_COLUMNS: tuple[str, ...] = (
    "exo_deg",
    "knee_deg",
    "knee_vel_rad_s",
    "sc_total",
    "exo_torque_nm",
    "leg_torque_nm",
    "pd_torque_nm",
    "feedback_deg",
)

#: Joints whose angle the exo's PD can control: the human knee (the clinician imposes the
#: limb's motion) or the exo hinge (what a real device's encoder measures).
FEEDBACK_JOINTS: tuple[str, ...] = (KNEE_JOINT, EXO_JOINT)


def levels_option() -> Any:
    """The ``levels`` field of a clinical test's parameters (``--levels``): spasticity levels
    of :data:`~myoexo.spasticity.VALID_LEVELS`, all by default."""
    return option(VALID_LEVELS, "spasticity levels to test", choices=VALID_LEVELS, metavar="L")


def normalise_levels(params: Any) -> None:
    """After :func:`~myoexo.runtime.fields.check_fields` (each level is valid): *params*'
    ``levels`` as a tuple of ``int`` (a list or numpy integers are accepted), or a
    ``ValueError`` if there is none."""
    if not params.levels:
        raise ValueError(
            f"{type(params).__name__}.levels is empty; accepted levels: {list(VALID_LEVELS)}"
        )
    object.__setattr__(params, "levels", tuple(int(level) for level in params.levels))


@dataclasses.dataclass(frozen=True)
class DriveParams:
    """How the exo drives the knee, and which joint it reads.

    Attributes:
        kp_nm_per_rad: Proportional gain of the exo position controller, Nm/rad (400: as
            stiff as the 10 ms control period and the exo's light link allow; the knee lags
            the reference by resisting torque / kp, plus the straps' compliance).
        kd_nm_s_per_rad: Derivative gain of the exo position controller, Nm s/rad.
        control_period_s: Control period, s (the stage and the PD run once per period, as in
            the envs: 10 ms).
        feedback_joint: Joint whose angle the PD controls: the human knee (default: the
            clinician imposes the limb's motion) or the exo hinge (``"exo_knee"``).
    """

    kp_nm_per_rad: float = option(
        400.0, "proportional gain of the exo's position controller", low=0.0, unit="Nm/rad"
    )
    kd_nm_s_per_rad: float = option(
        5.0, "derivative gain of the exo's position controller", low=0.0, unit="Nm s/rad"
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


def draw_subjects(levels: Iterable[int], seed: int) -> dict[int, SpasticityParams]:
    """One individual subject per level (10 % noise on Table I,
    :func:`~myoexo.spasticity.sample_subject`), drawn in the order of *levels* from one
    generator seeded with *seed*."""
    rng = np.random.default_rng(seed)
    return {level: sample_subject(level, rng) for level in map(check_level, levels)}


# ----------------------------------------------------------------------------- the twin
@functools.lru_cache(maxsize=4)
def _cached_twin(params: TwinParams | None) -> mujoco.MjModel:
    from myoexo.model import TwinParams, build_model

    model, _ = build_model(params if params is not None else TwinParams())
    return model


def twin_model(params: TwinParams | None = None) -> mujoco.MjModel:
    """The twin for *params* (default ``TwinParams()``): built once per parameter set, a
    private copy on every call (callers may change its options, e.g. gravity)."""
    return copy.copy(_cached_twin(params))


def default_twin(params: TwinParams | None = None) -> tuple[mujoco.MjModel, PoseFn]:
    """``(model, pose)``: the twin (:func:`twin_model`) and ``myoexo.model.pose_twin``."""
    from myoexo.model import pose_twin

    return twin_model(params), pose_twin


def resolve_twin(
    model: mujoco.MjModel | None, pose: PoseFn | None
) -> tuple[mujoco.MjModel, PoseFn]:
    """``(model, pose)`` with the default twin (:func:`default_twin`) where one is ``None``."""
    if model is not None and pose is not None:
        return model, pose
    default_model, default_pose = default_twin()
    return (default_model if model is None else model), (default_pose if pose is None else pose)


def control_substeps(drive: DriveParams, model: mujoco.MjModel) -> tuple[int, float]:
    """``(physics substeps per control period, the period they make in s)``: the drive's
    control period rounded to whole timesteps of *model* (at least one)."""
    n_sub = max(1, round(drive.control_period_s / model.opt.timestep))
    return n_sub, n_sub * model.opt.timestep


def motor_nm_per_ctrl(model: mujoco.MjModel, actuator_id: int) -> float:
    """Torque (Nm) per unit command of a torque motor (fixed gain, no bias)."""
    import mujoco

    if model.actuator_gaintype[actuator_id] != mujoco.mjtGain.mjGAIN_FIXED or (
        model.actuator_biastype[actuator_id] != mujoco.mjtBias.mjBIAS_NONE
    ):
        raise ValueError("The exo actuator must be a torque motor (fixed gain, no bias).")
    return float(model.actuator_gainprm[actuator_id, 0] * model.actuator_gear[actuator_id, 0])


def simulate_drive(
    model: mujoco.MjModel,
    level: int,
    ref_deg: np.ndarray,
    ref_vel_rad_s: np.ndarray,
    *,
    pose: PoseFn,
    start_deg: float,
    powered: np.ndarray | None = None,
    drive: DriveParams = DriveParams(),
    reflex: str | ReflexModel = DEFAULT_REFLEX,
    subject: SpasticityParams | None = None,
) -> tuple[np.ndarray, dict[str, np.ndarray]]:
    """Run the relaxed spastic twin with the exo driving (or released from) a reference.

    At every control step ``i`` (period ``drive.control_period_s``): if ``powered[i]``, the exo
    command is the PD ``kp (ref - q) + kd (ref_vel - qd)`` on the feedback joint, clipped to
    the motor's range; otherwise it is 0 (unpowered exo). The muscles get nothing but the
    reflex. The model runs ``control_period_s / timestep`` physics steps per control step.

    Args:
        model: The twin (human + exo); a fresh ``MjData`` is made for the run.
        level: Spasticity level; the reflex uses its nominal Table I parameters unless
            *subject* is given.
        ref_deg: Reference knee angle per control step, deg.
        ref_vel_rad_s: Reference knee velocity per control step, rad/s.
        pose: ``pose(model, data, knee_angle_deg=...)`` that puts the twin at *start_deg*.
        start_deg: Knee angle of the initial (static) pose, deg.
        powered: Per step, whether the PD drives the exo (default: every step).
        drive: Controller gains, control period and feedback joint.
        reflex: Reflex model (a registered name or :class:`~myoexo.spasticity.ReflexModel`).
        subject: Individual reflex parameters (default: the level's Table I values).

    Returns:
        ``(times_s, columns)``: the time of each step and one array per name of
        :data:`DRIVE_COLUMNS` (state at the start of the step, torques applied during it;
        ``pd_torque_nm`` is the unclipped PD torque, 0 while unpowered; ``leg_torque_nm``
        the leg's own torque along the coupled knee, flexion positive: its muscles' and its
        passive knee's springs, :mod:`myoexo.model.passive_knee`).

    Raises:
        ValueError: If the level, the reflex or a joint/actuator name is unknown.
    """
    import mujoco

    level = check_level(level)
    n_steps = len(ref_deg)
    powered_steps = np.ones(n_steps, dtype=bool) if powered is None else np.asarray(powered)
    if len(ref_vel_rad_s) != n_steps or len(powered_steps) != n_steps:
        raise ValueError("ref_deg, ref_vel_rad_s and powered must have one entry per step.")
    fb_j = model.joint(drive.feedback_joint)
    exo_a = model.actuator(EXO_ACTUATOR).id
    fb_q, fb_d = int(fb_j.qposadr[0]), int(fb_j.dofadr[0])
    nm_per_ctrl = motor_nm_per_ctrl(model, exo_a)
    ctrl_lo, ctrl_hi = model.actuator_ctrlrange[exo_a]
    _, dt = control_substeps(drive, model)

    data = mujoco.MjData(model)
    pose(model, data, knee_angle_deg=start_deg)
    stage = SpasticityStage(level, subject_noise=False, reflex=reflex)
    if subject is not None:
        stage.set_subject(subject)
    twin = Twin(model, stage, dt, data=data)

    ref_rad = np.radians(np.asarray(ref_deg, dtype=np.float64))
    ref_vel = np.asarray(ref_vel_rad_s, dtype=np.float64)
    rec = np.empty((n_steps, len(DRIVE_COLUMNS)))
    for i in range(n_steps):
        q, qd = data.qpos[fb_q], data.qvel[fb_d]
        if powered_steps[i]:
            torque = drive.kp_nm_per_rad * (ref_rad[i] - q) + drive.kd_nm_s_per_rad * (
                ref_vel[i] - qd
            )
            u = min(max(torque / nm_per_ctrl, ctrl_lo), ctrl_hi)
        else:
            torque, u = 0.0, 0.0
        # relaxed limb: the muscles get the reflex only
        twin.apply_command(u, powered=bool(powered_steps[i]))
        rec[i] = (  # in the order of DRIVE_COLUMNS
            twin.exo_angle_deg,
            twin.knee_angle_deg,
            twin.knee_velocity_rad_s,
            stage.last_sc_total,
            twin.applied_command * nm_per_ctrl,
            twin.leg_torque_nm,
            torque,
            math.degrees(q),
        )
        twin.advance()
    return np.arange(n_steps) * dt, {name: rec[:, j] for j, name in enumerate(DRIVE_COLUMNS)}


# ----------------------------------------------------------------------------- analysis
def interp_on_angle(angle_deg: Any, values: Any, at_deg: Any) -> np.ndarray:
    """*values* recorded at knee angles *angle_deg*, linearly interpolated at *at_deg*
    (the samples sorted by angle; NaN outside the recorded angles)."""
    angle = np.asarray(angle_deg, dtype=np.float64)
    order = np.argsort(angle, kind="stable")
    x, y = angle[order], np.asarray(values, dtype=np.float64)[order]
    return np.interp(np.asarray(at_deg, dtype=np.float64), x, y, left=np.nan, right=np.nan)


# ----------------------------------------------------------------------------- CLI
@dataclasses.dataclass(frozen=True)
class ExamOptions:
    """What an examination command (``myoexo clinic tardieu|pendulum|mas``) runs on and
    writes, besides its test parameters: each field is an option of its own name
    (``--reflex`` is :func:`~myoexo.spasticity.registry.add_reflex_argument`'s)."""

    reflex: str = option(DEFAULT_REFLEX, "reflex model of the twin", flag="")
    subject_seed: int | None = option(
        None,
        "draw one individual subject per level with this seed (default: the nominal Table I "
        "subjects)",
        low=0,
        metavar="N",
    )
    out: Path | None = option(
        None,
        "folder for the CSV tables and the PNG figure (default: print only)",
        folder=True,
        metavar="DIR",
    )
    dpi: int = option(120, "resolution of the PNG figure", low=1)

    def __post_init__(self) -> None:
        check_fields(self)

    def write(
        self, stem: str, table: pd.DataFrame, traces: pd.DataFrame, plot: Callable[[], Figure]
    ) -> list[Path]:
        """With :attr:`out`: write ``<stem>.csv`` (the table), ``<stem>_traces.csv`` and
        ``<stem>.png`` (the figure *plot* draws, at :attr:`dpi`) into it (created if
        missing), say so and return the paths; without: nothing."""
        if self.out is None:
            return []
        self.out.mkdir(parents=True, exist_ok=True)
        paths = [
            self.out / f"{stem}.csv",
            self.out / f"{stem}_traces.csv",
            self.out / f"{stem}.png",
        ]
        table.to_csv(paths[0], index=False)
        traces.to_csv(paths[1], index=False)
        plot().savefig(paths[2], dpi=self.dpi)
        print("wrote " + ", ".join(str(path) for path in paths))
        return paths

    def subjects(self, levels: Iterable[int]) -> Mapping[int, SpasticityParams] | None:
        """The individual subjects of *levels* (:func:`draw_subjects` with
        ``subject_seed``; ``None``: the nominal Table I subjects)."""
        if self.subject_seed is None:
            return None
        return draw_subjects(levels, self.subject_seed)


def add_exam_arguments(parser: argparse.ArgumentParser, params: type) -> None:
    """The options of an examination command: one per field of its test parameters
    (*params*, a dataclass declared with :func:`~myoexo.runtime.fields.option`), then
    ``--reflex`` and :class:`ExamOptions`' fields."""
    add_options(parser, params)
    add_reflex_argument(parser, default=DEFAULT_REFLEX)
    add_options(parser, ExamOptions)


def print_table(table: pd.DataFrame) -> None:
    """Print a table with 3 decimals."""
    print(table.to_string(index=False, float_format=lambda x: f"{x:.3f}"))
