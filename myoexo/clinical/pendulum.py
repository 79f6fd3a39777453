"""Simulated Wartenberg pendulum test of the knee on the twin.

The exo holds the relaxed knee extended (a PD at ``start_deg`` for ``hold_s``: tone and
activations settle), then its motor command drops to 0 and the shank swings freely under
gravity for ``swing_s``. The exo stays strapped on, unpowered: its mass, its hinge damping and
range stops (-15 to 95 deg) and the soft coupling of its straps all stay in the swing, as
they would for a patient tested wearing it. The reflex (:class:`~myoexo.spasticity
.SpasticityStage`) acts throughout.

Outcome measures per level (knee flexion positive, deg):

``release_deg``, ``rest_deg``
    The knee angle at release, and the final resting angle (mean over the last
    ``rest_window_s`` of the swing).
``first_swing_deg``
    First-swing excursion: from the release angle to the first flexion peak (the first
    reversal of the knee velocity; the largest angle if the knee creeps to rest without one).
``relaxation_index``
    Bajd and Vodovnik's (1984) ``R = A1 / A0``: ``A1`` the amplitude of the first swing
    measured from the start angle (``first_swing_deg``), ``A0`` the start angle minus the
    final resting angle (here ``rest_deg - release_deg``, flexion positive). A healthy,
    relaxed leg overshoots its rest on the first swing: ``R`` about 1.6 and above; spastic
    extensors brake the swing: ``R`` below (an overdamped leg that creeps to rest gives
    1). ``relaxation_index_norm`` is their normalised ``R / 1.6`` (>= 1: normal). Kim, Chon,
    Park and Choi 1996 measured it in 50 healthy adults lying supine
    (:data:`HEALTHY_RELAXATION_INDEX_SUPINE`): the twin's supine, device-free posture
    (:data:`SUPINE`, ``--device freed``) is the one to compare with.
``peak_velocity_deg_s``
    The largest flexion velocity of the knee during the first swing. White et al. (2007)
    measured about 293 deg/s in typically developing children and 202 deg/s in children with
    cerebral palsy.
``time_to_peak_velocity_s``
    From the release to that velocity. White et al. (2007): 0.34 s in typically developing
    children, 0.22 s in children with cerebral palsy.
``second_peak_velocity_deg_s``
    The largest flexion velocity of the second swing (after the first return towards
    extension, up to the second flexion peak); NaN if the leg swings back once or not at
    all. Kim et al. (1996): 3.076 +- 0.551 rad/s in healthy adults.
``n_oscillations``
    Flexion peaks of the swing (velocity reversals from flexion to extension) that rise more
    than ``min_oscillation_deg`` above the resting angle.

Posture. The twin sits with the hip locked at 90 deg (docs/reference.md section 1), where the
seated hamstrings limit extension (the knee cannot be held much straighter than about 25 deg
at level 0 without a large hold torque). Clinics run the test semi-reclined, the thigh on the
table, the hip at about 30-60 deg. :data:`RECLINED` does that: the twin is built with
``TwinParams(hip_flexion_deg=40)`` and gravity is turned by the 50 deg the trunk reclines
(about the lateral axis), so the thigh is horizontal again (within 0.1 deg) while the
hamstrings are slack. With the exo worn, its 95 deg stop caps the first swing near 100 deg
of knee flexion (the straps give a few degrees): level 0 gives ``R`` = 1.40 seated and 1.43
reclined on twin 3. With the exo's stop moved out of the way (``--device freed``,
``twin=TwinParams(exo_knee_range_deg=(-15, 130))``) the healthy leg gives 1.77 seated and
1.70 reclined, the latter within Kim et al.'s 1.678 +- 0.090 (``TwinParams.of_version(2)``,
whose passive knee is its muscles' passive fibres, gives 1.57 and 1.38).

CLI::

    myoexo clinic pendulum [--levels 0 1 2 3] [--reflex NAME]
                    [--posture seated|reclined|supine] [--start-deg D] [--swing-s 10]
                    [--device worn|freed] [--subject-seed N] [--out DIR]

``--posture`` picks the preset (:data:`POSTURES`); every field of :class:`PendulumParams` but
``drive`` is an option of its own name that changes it (``--hip-flexion-deg``, ...), and so is
every field of :class:`PendulumSetup` and :class:`~myoexo.clinical.common.ExamOptions`.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Mapping
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.clinical.common import (
    DriveParams,
    ExamOptions,
    control_substeps,
    levels_option,
    normalise_levels,
    print_table,
    simulate_drive,
    twin_model,
)
from myoexo.model.exo import EXO_JOINT
from myoexo.runtime.fields import add_options, check_fields, from_options, option, option_fields
from myoexo.spasticity.levels import SpasticityParams
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel, add_reflex_argument, reflex_label

if TYPE_CHECKING:
    import mujoco
    import pandas as pd
    from matplotlib.figure import Figure

    from myoexo.model import TwinParams

__all__ = [
    "DEVICES",
    "FREED_EXO_RANGE_DEG",
    "HEALTHY_FIRST_SWING_VELOCITY_SUPINE_RAD_S",
    "HEALTHY_RELAXATION_INDEX",
    "HEALTHY_RELAXATION_INDEX_SUPINE",
    "PEAK_VELOCITY_CP_DEG_S",
    "PEAK_VELOCITY_TD_DEG_S",
    "POSTURES",
    "RECLINED",
    "SEATED",
    "PendulumParams",
    "PendulumResult",
    "PendulumSetup",
    "add_arguments",
    "analyse_swing",
    "plot_pendulum",
    "published_values",
    "reclined_gravity",
    "run",
    "run_pendulum",
]

#: Relaxation index ``A1 / A0`` of a healthy, relaxed knee: about 1.6 and above (Bajd and
#: Vodovnik 1984); below it, spastic.
HEALTHY_RELAXATION_INDEX = 1.6
#: Relaxation index of healthy adults in the pendulum test, mean and SD (Kim, Chon, Park and
#: Choi 1996, J Korean Acad Rehabil Med 20(3); n = 50, supine, no device): compare with
#: :data:`SUPINE` without the device.
HEALTHY_RELAXATION_INDEX_SUPINE = (1.678, 0.090)
#: Angular velocity of the first swing of the same healthy adults, mean and SD, rad/s (Kim
#: et al. 1996: 3.873 +- 0.622 rad/s, 222 +- 36 deg/s).
HEALTHY_FIRST_SWING_VELOCITY_SUPINE_RAD_S = (3.873, 0.622)
#: Peak knee velocity of the first swing in typically developing children, deg/s
#: (White et al. 2007).
PEAK_VELOCITY_TD_DEG_S = 293.0
#: The same in children with cerebral palsy, deg/s (White et al. 2007).
PEAK_VELOCITY_CP_DEG_S = 202.0
#: Standard gravity, m/s^2 (MuJoCo's default ``opt.gravity``).
_GRAVITY_M_S2 = 9.81
#: Hip flexion at which the thigh of the upright-pelvis twin is horizontal, deg.
_THIGH_HORIZONTAL_HIP_DEG = 90.0


#: The hold's PD: the clinic releases the leg from the held angle (full extension, reclined),
#: so the hold is stiffer than the stretch tests' drive (400 Nm/rad, 5 Nm s/rad), whose lag
#: against level 3's tone left the reclined knee 8 deg short of full extension; at 1500 Nm/rad
#: the knee is released within 2.5 deg of the held angle at every level (hold torque at most
#: 65 Nm, spindle reflex, nominal subjects).
HOLD_DRIVE = DriveParams(kp_nm_per_rad=1500.0, kd_nm_s_per_rad=10.0)


@dataclasses.dataclass(frozen=True)
class PendulumParams:
    """Parameters of the simulated pendulum test (defaults: the seated twin; each field but
    ``drive`` is an option of ``myoexo clinic pendulum``, on top of ``--posture``).

    Attributes:
        start_deg: Knee flexion the exo holds before the release, deg (20 seated: the
            seated hamstrings resist further extension; the PD's lag leaves the knee a few
            degrees more flexed, measured as ``release_deg``).
        hip_flexion_deg: Hip flexion of the twin, deg (90 seated; less: the trunk reclines
            by ``90 - hip_flexion_deg`` and gravity turns with it, the thigh stays horizontal).
        hold_s: Time the exo holds the knee before the release, s.
        swing_s: Free swing after the release, s (10 s: every level comes to rest).
        rest_window_s: The last part of the swing whose mean is the resting angle, s.
        min_oscillation_deg: A flexion peak counts as an oscillation when it rises more than
            this above the resting angle, deg (1 deg: above what a goniometer resolves).
        stop_margin_deg: The exo's flexion stop counts as hit when the exo angle comes this
            close to it, deg.
        levels: Spasticity levels to test.
        drive: The hold PD's gains and the control period (:data:`HOLD_DRIVE`).
    """

    start_deg: float = option(
        20.0,
        "knee flexion the exo holds before the release (default: the posture's, 20 seated, "
        "0 reclined)",
        low=0.0,
        high=90.0,
        unit="deg",
    )
    hip_flexion_deg: float = option(
        _THIGH_HORIZONTAL_HIP_DEG,
        "hip flexion of the twin; below 90 the trunk reclines, the thigh stays horizontal "
        "(default: the posture's, 90 seated, 40 reclined)",
        low=0.0,
        high=90.0,
        unit="deg",
    )
    hold_s: float = option(
        1.0, "time the exo holds the knee before the release", low=0.0, above=True, unit="s"
    )
    swing_s: float = option(10.0, "free swing after the release", low=0.0, above=True, unit="s")
    rest_window_s: float = option(
        1.0, "last part of the swing whose mean is the resting angle",
        low=0.0, above=True, unit="s",
    )  # fmt: skip
    min_oscillation_deg: float = option(
        1.0, "rise of a flexion peak above the resting angle that counts as an oscillation",
        low=0.0, above=True, unit="deg",
    )  # fmt: skip
    stop_margin_deg: float = option(
        1.0, "the exo's flexion stop counts as hit this close to it",
        low=0.0, above=True, unit="deg",
    )  # fmt: skip
    levels: tuple[int, ...] = levels_option()
    drive: DriveParams = dataclasses.field(default_factory=lambda: HOLD_DRIVE)

    def __post_init__(self) -> None:
        check_fields(self)
        normalise_levels(self)
        if self.rest_window_s >= self.swing_s:
            raise ValueError(
                f"PendulumParams.rest_window_s = {self.rest_window_s!r} must be shorter than "
                f"swing_s = {self.swing_s!r}"
            )

    @property
    def recline_deg(self) -> float:
        """How far the trunk reclines from upright, deg (0 seated)."""
        return _THIGH_HORIZONTAL_HIP_DEG - self.hip_flexion_deg


#: The seated test on the twin as built (hip at 90 deg).
SEATED = PendulumParams()
#: The clinic's semi-reclined test: hip at 40 deg, trunk reclined 50 deg, thigh horizontal,
#: released from full extension (the slack hamstrings allow it).
RECLINED = PendulumParams(start_deg=0.0, hip_flexion_deg=40.0)
#: Kim et al.'s (1996) supine test: hip extended (0 deg), trunk lying flat, thigh horizontal
#: on the table, released from full extension: the posture of the healthy reference values
#: (:data:`HEALTHY_RELAXATION_INDEX_SUPINE`, :data:`HEALTHY_FIRST_SWING_VELOCITY_SUPINE_RAD_S`).
SUPINE = PendulumParams(start_deg=0.0, hip_flexion_deg=0.0)
#: Named postures of the CLI.
POSTURES: Mapping[str, PendulumParams] = MappingProxyType(
    {"seated": SEATED, "reclined": RECLINED, "supine": SUPINE}
)
#: The exo's knee range with its flexion stop out of the way (``--device freed``): the exo's
#: mass and straps stay, its motor is off during the swing, its stop is past the swing:
#: as close to the clinic's test without the device as the strapped twin gets.
FREED_EXO_RANGE_DEG = (-15.0, 130.0)
#: ``--device`` choices: the exo as worn, or with its range freed.
DEVICES: tuple[str, ...] = ("worn", "freed")


def reclined_gravity(recline_deg: float) -> np.ndarray:
    """Gravity in the twin's world frame (x forward, z up) for a trunk reclined by
    *recline_deg*: the body turned backward about the lateral axis is gravity turned
    forward, ``g (-sin r, 0, -cos r)``."""
    r = math.radians(recline_deg)
    return _GRAVITY_M_S2 * np.array([-math.sin(r), 0.0, -math.cos(r)])


@dataclasses.dataclass(frozen=True)
class PendulumResult:
    """Outcome of :func:`run_pendulum`.

    Attributes:
        summary: One row per level (see :meth:`table`).
        traces: One row per control step: ``level, time_s`` (0 at the release, negative
            while held), ``phase`` ("hold"/"swing"), ``knee_deg, knee_vel_deg_s, exo_deg,
            exo_torque_nm, leg_torque_nm, sc_total``.
        params: The test parameters.
        reflex: Name of the reflex model.
    """

    summary: pd.DataFrame
    traces: pd.DataFrame
    params: PendulumParams
    reflex: str

    def table(self) -> pd.DataFrame:
        """Per level: ``release_deg, rest_deg, first_peak_deg, first_swing_deg, a0_deg,
        relaxation_index, relaxation_index_norm, peak_velocity_deg_s,
        time_to_peak_velocity_s, second_peak_velocity_deg_s, n_oscillations,
        hold_torque_nm`` (exo torque holding the knee at release, flexion positive),
        ``exo_stop_hit`` and ``reflex``, ``hip_flexion_deg``."""
        return self.summary.copy()


def published_values() -> pd.DataFrame:
    """The published reference values the pendulum test is compared with."""
    import pandas as pd

    return pd.DataFrame(
        [
            {
                "measure": "relaxation_index",
                "value": HEALTHY_RELAXATION_INDEX,
                "group": "healthy adults: about this and above; spastic: below",
                "source": "Bajd and Vodovnik 1984",
            },
            {
                "measure": "relaxation_index",
                "value": HEALTHY_RELAXATION_INDEX_SUPINE[0],
                "group": "healthy adults (n = 50, supine), SD "
                f"{HEALTHY_RELAXATION_INDEX_SUPINE[1]}",
                "source": "Kim, Chon, Park and Choi 1996",
            },
            {
                "measure": "peak_velocity_deg_s",
                "value": PEAK_VELOCITY_TD_DEG_S,
                "group": "typically developing children",
                "source": "White et al. 2007",
            },
            {
                "measure": "peak_velocity_deg_s",
                "value": PEAK_VELOCITY_CP_DEG_S,
                "group": "children with cerebral palsy",
                "source": "White et al. 2007",
            },
        ]
    )


def _flexion_peaks(vel: np.ndarray) -> np.ndarray:
    """Indices where the knee velocity turns from flexion (> 0) to extension (<= 0)."""
    return np.flatnonzero((vel[:-1] > 0.0) & (vel[1:] <= 0.0)) + 1


def analyse_swing(
    knee_deg: np.ndarray, knee_vel_deg_s: np.ndarray, dt_s: float, params: PendulumParams
) -> dict[str, Any]:
    """The outcome measures (module docstring) of one free swing sampled every *dt_s*
    from the release on."""
    release = float(knee_deg[0])
    n_rest = max(1, round(params.rest_window_s / dt_s))
    rest = float(np.mean(knee_deg[-n_rest:]))
    peaks = _flexion_peaks(knee_vel_deg_s)
    first = int(peaks[0]) if peaks.size else int(np.argmax(knee_deg))
    first_swing = float(knee_deg[first]) - release
    a0 = rest - release
    ri = first_swing / a0 if a0 > params.min_oscillation_deg else math.nan
    oscillations = int(np.sum(knee_deg[peaks] - rest > params.min_oscillation_deg))
    peak_at = int(np.argmax(knee_vel_deg_s[: first + 1]))
    # the second swing: from the first return's turn (extension to flexion) to the next peak
    turns = np.flatnonzero((knee_vel_deg_s[first:-1] <= 0.0) & (knee_vel_deg_s[first + 1 :] > 0.0))
    second = math.nan
    if turns.size and peaks.size > 1:
        start = first + int(turns[0]) + 1
        second = float(np.max(knee_vel_deg_s[start : int(peaks[1]) + 1]))
    return {
        "release_deg": release,
        "rest_deg": rest,
        "first_peak_deg": float(knee_deg[first]),
        "first_swing_deg": first_swing,
        "a0_deg": a0,
        "relaxation_index": ri,
        "relaxation_index_norm": ri / HEALTHY_RELAXATION_INDEX,
        "peak_velocity_deg_s": float(knee_vel_deg_s[peak_at]),
        "time_to_peak_velocity_s": peak_at * dt_s,
        "second_peak_velocity_deg_s": second,
        "n_oscillations": oscillations,
    }


def run_pendulum(
    params: PendulumParams = SEATED,
    *,
    reflex: str | ReflexModel = DEFAULT_REFLEX,
    subjects: Mapping[int, SpasticityParams] | None = None,
    twin: TwinParams | None = None,
) -> PendulumResult:
    """Run the pendulum test at every level of *params*.

    Args:
        params: Test parameters (:data:`SEATED`, :data:`RECLINED` or your own).
        reflex: Reflex model, a registered name (``"stretch"``, ``"uniform"``,
            ``"persistent"``, ...) or a :class:`~myoexo.spasticity.ReflexModel`.
        subjects: Individual reflex parameters per level (default: nominal Table I).
        twin: Twin parameters (default ``TwinParams()``); their hip flexion is replaced by
            ``params.hip_flexion_deg``.

    Returns:
        The per-level table and the traces (:class:`PendulumResult`).

    Raises:
        ValueError: If the reflex is unknown.
    """
    import pandas as pd

    from myoexo.model import TwinParams, pose_twin

    label = reflex_label(reflex)
    # no scene: the test is never rendered, and the plinth, placed under the thigh of the
    # upright pelvis, has no room below the knee once the hip extends
    twin = dataclasses.replace(
        twin or TwinParams(), hip_flexion_deg=params.hip_flexion_deg, scene=False
    )
    model: mujoco.MjModel = twin_model(twin)
    model.opt.gravity[:] = reclined_gravity(params.recline_deg)
    exo = model.joint(EXO_JOINT)
    exo_stop_deg = math.degrees(float(model.jnt_range[exo.id, 1]))
    _, dt = control_substeps(params.drive, model)
    n_hold = round(params.hold_s / dt)
    n_swing = round(params.swing_s / dt)
    ref_deg = np.full(n_hold + n_swing, params.start_deg)
    powered = np.arange(n_hold + n_swing) < n_hold
    rows, traces = [], []
    for level in params.levels:
        subject = None if subjects is None else subjects.get(level)
        times, col = simulate_drive(
            model,
            level,
            ref_deg,
            np.zeros_like(ref_deg),
            pose=pose_twin,
            start_deg=params.start_deg,
            powered=powered,
            drive=params.drive,
            reflex=reflex,
            subject=subject,
        )
        knee_vel_deg_s = np.degrees(col["knee_vel_rad_s"])
        row = analyse_swing(col["knee_deg"][n_hold:], knee_vel_deg_s[n_hold:], dt, params)
        row["hold_torque_nm"] = float(col["exo_torque_nm"][n_hold - 1]) if n_hold else 0.0
        row["exo_stop_hit"] = bool(
            col["exo_deg"][n_hold:].max() >= exo_stop_deg - params.stop_margin_deg
        )
        rows.append({"level": level, **row})
        traces.append(
            pd.DataFrame(
                {
                    "level": level,
                    "time_s": times - n_hold * dt,
                    "phase": np.where(powered, "hold", "swing"),
                    "knee_deg": col["knee_deg"],
                    "knee_vel_deg_s": knee_vel_deg_s,
                    "exo_deg": col["exo_deg"],
                    "exo_torque_nm": col["exo_torque_nm"],
                    "leg_torque_nm": col["leg_torque_nm"],
                    "sc_total": col["sc_total"],
                }
            )
        )
    summary = pd.DataFrame(rows).assign(reflex=label, hip_flexion_deg=params.hip_flexion_deg)
    return PendulumResult(summary, pd.concat(traces, ignore_index=True), params, label)


# ----------------------------------------------------------------------------- figure
def plot_pendulum(result: PendulumResult) -> Figure:
    """Knee angle vs time after the release per level, and the relaxation index and the
    peak velocity per level next to the published values."""
    from matplotlib.figure import Figure

    from myoexo.viz.colors import LEVEL_COLORS

    fig = Figure(figsize=(13, 3.8), constrained_layout=True)
    ax_t, ax_r, ax_v = fig.subplots(1, 3, gridspec_kw={"width_ratios": [2.2, 1, 1]})
    summary = result.summary.set_index("level")
    swing = result.traces[result.traces["phase"] == "swing"]
    for level, row in summary.iterrows():
        sel = swing[swing["level"] == level]
        color = LEVEL_COLORS[int(level)]  # type: ignore[call-overload]
        ax_t.plot(sel["time_s"], sel["knee_deg"], color=color, label=f"level {level}")
        ax_t.axhline(row["rest_deg"], color=color, lw=0.7, ls=":")
    ax_t.set(xlabel="time after release (s)", ylabel="knee flexion (deg)")
    ax_t.invert_yaxis()  # extension up, as the shank rises
    ax_t.legend(fontsize=8)
    ax_t.grid(alpha=0.3)
    colors = [LEVEL_COLORS[int(lv)] for lv in summary.index]
    ax_r.bar(summary.index, summary["relaxation_index"], color=colors, edgecolor="black")
    ax_r.axhline(HEALTHY_RELAXATION_INDEX, color="green", ls="--", label="healthy ≥ 1.6 (Bajd)")
    ax_r.axhline(1.0, color="0.5", lw=0.8)
    ax_r.set(xlabel="spasticity level", ylabel="relaxation index A1/A0")
    ax_r.legend(fontsize=8, loc="lower left")
    ax_v.bar(summary.index, summary["peak_velocity_deg_s"], color=colors, edgecolor="black")
    ax_v.axhline(PEAK_VELOCITY_TD_DEG_S, color="green", ls="--", label="TD children (White)")
    ax_v.axhline(PEAK_VELOCITY_CP_DEG_S, color="red", ls="--", label="CP children (White)")
    ax_v.set(xlabel="spasticity level", ylabel="peak first-swing velocity (deg/s)")
    ax_v.legend(fontsize=8, loc="lower left")
    for ax in (ax_r, ax_v):
        ax.set_xticks(list(summary.index))
        ax.grid(alpha=0.3, axis="y")
    p = result.params
    posture = "seated" if p.recline_deg == 0 else f"reclined {p.recline_deg:g} deg"
    fig.suptitle(
        f"Simulated pendulum test ({result.reflex} reflex, hip {p.hip_flexion_deg:g} deg, "
        f"{posture}; exo worn, unpowered)"
    )
    return fig


# ----------------------------------------------------------------------------- CLI
@dataclasses.dataclass(frozen=True)
class PendulumSetup:
    """The posture and the device of ``myoexo clinic pendulum`` (each field an option)."""

    posture: str = option(
        "seated",
        "the preset test, which the options below change (seated: hip 90 deg, the twin as "
        "built; reclined: hip 40 deg, thigh horizontal, as in clinics; supine: hip 0 deg, "
        "lying flat, as Kim et al. 1996 tested healthy adults)",
        choices=sorted(POSTURES),
    )
    device: str = option(
        "worn",
        "the exo (worn: as built, its 95 deg stop caps the first swing; freed: its range freed "
        "and its motor off, the clinic's test without the device)",
        choices=DEVICES,
    )

    def __post_init__(self) -> None:
        check_fields(self)

    def params(self, **changes: Any) -> PendulumParams:
        """The posture's :class:`PendulumParams` (:data:`POSTURES`) with *changes*."""
        return dataclasses.replace(POSTURES[self.posture], **changes)

    def twin(self) -> TwinParams | None:
        """The twin of the device (``None``: the default twin, the exo as built)."""
        if self.device == "worn":
            return None
        from myoexo.model import TwinParams

        return TwinParams(exo_knee_range_deg=FREED_EXO_RANGE_DEG)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo clinic pendulum``: :class:`PendulumSetup`'s fields, the fields of
    :class:`PendulumParams` (each given one changes the posture's preset), ``--reflex`` and
    :class:`~myoexo.clinical.common.ExamOptions`' fields."""
    add_options(parser, PendulumSetup)
    add_options(parser, PendulumParams, given_only=True)
    add_reflex_argument(parser, default=DEFAULT_REFLEX)
    add_options(parser, ExamOptions)


def run(args: argparse.Namespace) -> int:
    """Run the test, print the per-level table and the published values, optionally write
    CSVs and the figure."""
    setup = from_options(PendulumSetup, args)
    given = {  # the options given (add_options(given_only=True) leaves the others unset)
        f.name: getattr(args, f.name)
        for f in option_fields(PendulumParams)
        if hasattr(args, f.name)
    }
    params = setup.params(**{k: tuple(v) if isinstance(v, list) else v for k, v in given.items()})
    options = from_options(ExamOptions, args, reflex=args.reflex)
    result = run_pendulum(
        params, reflex=options.reflex, subjects=options.subjects(params.levels), twin=setup.twin()
    )
    print_table(result.table())
    print("published:")
    print(published_values().to_string(index=False))
    options.write("pendulum", result.table(), result.traces, lambda: plot_pendulum(result))
    return 0
