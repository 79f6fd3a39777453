"""Simulated (Modified) Tardieu test of the knee flexors on the twin.

The exo extends the relaxed knee from 90 deg of flexion toward full extension (stretching the
hamstrings and gastrocnemii) once slowly (V1, 0.2 rad/s) and once fast (V3, 3 rad/s), with
the stiff PD of :mod:`myoexo.clinical.stretch` on a trapezoidal-velocity ramp. As in the
clinic (Tardieu; Boyd and Graham 1999) the test reports, per level:

``r1_deg`` (R1, the angle of catch at V3)
    The knee angle (deg of flexion, i.e. the popliteal angle of the seated test) at which the
    fast stretch's resisting torque first exceeds the slow stretch's at the same angle by
    ``catch_threshold_nm``. The excess over the slow stretch is the velocity-dependent part
    of the resistance, the part Lance's (1980) definition of spasticity names; a threshold on
    the torque itself would also fire on the passive end-range stiffness, and the largest
    d torque / d angle picks that end-range rise too (it is steepest where the hamstrings'
    passive force-length curve is). No catch: ``catch`` is False and R1 is set to R2 (the
    clinical convention: no dynamic component).
``r2_deg`` (R2, the passive range at V1)
    The knee angle from which on the slow stretch's resisting torque stays at or above
    ``end_feel_torque_nm`` to the end of the motion (the examiner's end-feel: the last rise
    through the threshold, so that a mid-range bump of tone the limb then passes, as the
    uniform reflex gives at level 3, is not taken for the end of the range); if the torque
    ends below it, the most extended angle the slow stretch reached (``r2_reached`` False).
``r2_minus_r1_deg``
    R2 - R1 measured along the stretch, ``r1_deg - r2_deg`` for this extension: the range the
    limb gains when moved slowly, the dynamic (spastic) component; 0 without a catch.
``fast_slow_peak_ratio``
    Peak resisting torque of the fast stretch over that of the slow one (both over the
    motion).

The resisting torque analysed is the leg's own torque at the knee along the stretch, its
muscles' and its passive knee's (``leg_resisting_nm``: positive = resists the extension), not
the exo's torque. At 3 rad/s
the exo torque also carries the shank's inertia and the PD's ringing after the 50 ms
acceleration (about +-15 Nm at level 0, whose muscles give the same torque at both speeds),
which a threshold would read as catches; the passive knee (and MuJoCo's passive muscle
force) has no velocity term, so at level 0 the leg's torques of the two speeds agree within
1 Nm. A device would
estimate the same quantity by subtracting a model of the limb's inertia and weight. The exo
torques are reported too (``*_exo_nm``). The analysis uses the motion only (not the holds).

Both speeds run on the seated twin (hip at 90 deg). The stretch is commanded to
``end_deg`` = 10 deg: the seated hamstrings (the popliteal-angle posture) and the PD's lag
stop the knee at 16-22 deg (16 deg at level 0, up to 22 deg at level 3 with the stretch
reflex), as far as the posture allows without saturating the 100 Nm motor.

CLI::

    myoexo clinic tardieu [--levels 0 1 2 3] [--reflex NAME] [--end-deg 10]
                   [--slow-rad-s 0.2] [--fast-rad-s 3.0] [--subject-seed N] [--out DIR]

Every field of :class:`TardieuParams` is an option of its own name (``--catch-threshold-nm``,
...), and so is every field of :class:`~myoexo.clinical.common.ExamOptions`.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.clinical.common import (
    ExamOptions,
    add_exam_arguments,
    interp_on_angle,
    levels_option,
    normalise_levels,
    print_table,
    resolve_twin,
)
from myoexo.clinical.stretch import (
    MOVING_PHASES,
    StretchTestParams,
    check_two_speeds,
    simulate_two_speeds,
)
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
    "TardieuParams",
    "TardieuResult",
    "add_arguments",
    "analyse_tardieu",
    "plot_tardieu",
    "run",
    "run_tardieu",
]


@dataclasses.dataclass(frozen=True)
class TardieuParams:
    """Parameters of the simulated Tardieu test (defaults: the seated clinical test; each
    field is an option of ``myoexo clinic tardieu``).

    Attributes:
        start_deg: Knee flexion at the start, deg (90: the seated rest).
        end_deg: Commanded knee flexion at the end, deg (10: past where the seated
            hamstrings stop the knee, about 16 deg at level 0; see the module docstring).
        slow_rad_s: V1, the slow stretch speed, rad/s (0.2 rad/s = 11 deg/s: slower than
            the limb falling under gravity, as V1 asks).
        fast_rad_s: V3, the fast stretch speed, rad/s (3 rad/s = 172 deg/s, "as fast as
            possible" for an examiner's hand).
        catch_threshold_nm: Excess of the fast over the slow resisting torque that marks the
            catch (R1), Nm: 10 Nm, ten times the < 1 Nm the two speeds differ by at level 0
            (no reflex) and a tenth of the motor's 100 Nm.
        end_feel_torque_nm: Resisting torque of the slow stretch that marks the end of the
            passive range (R2), Nm: 25 Nm, the passive knee's torque near the seated end of
            range (Riener and Edrich's moment at hip 90 deg reaches 25 Nm at about 12 deg
            of flexion; docs/reference.md section 6).
        levels: Spasticity levels to test.
        accel_time_s: Time to reach (and leave) each stretch speed, s.
        hold_s: Time held at the start before the stretch (tone and activations settle), s.
        end_hold_s: Time held at the end after the stretch, s.
    """

    start_deg: float = option(90.0, "knee flexion at the start", low=0.0, high=120.0, unit="deg")
    end_deg: float = option(
        10.0, "commanded knee flexion at the end", low=0.0, high=120.0, unit="deg"
    )
    slow_rad_s: float = option(
        0.2, "V1, the slow stretch's speed", low=0.0, above=True, unit="rad/s", metavar="RAD_S"
    )
    fast_rad_s: float = option(
        3.0, "V3, the fast stretch's speed", low=0.0, above=True, unit="rad/s", metavar="RAD_S"
    )
    catch_threshold_nm: float = option(
        10.0, "excess of the fast over the slow resisting torque that marks the catch (R1)",
        low=0.0, above=True, unit="Nm",
    )  # fmt: skip
    end_feel_torque_nm: float = option(
        25.0, "resisting torque of the slow stretch that marks the end of the range (R2)",
        low=0.0, above=True, unit="Nm",
    )  # fmt: skip
    levels: tuple[int, ...] = levels_option()
    accel_time_s: float = option(
        0.05, "time to reach (and to leave) each stretch speed", low=0.0, unit="s"
    )
    hold_s: float = option(0.5, "time held at the start before each stretch", low=0.0, unit="s")
    end_hold_s: float = option(0.2, "time held at the end after each stretch", low=0.0, unit="s")

    def __post_init__(self) -> None:
        check_fields(self)
        normalise_levels(self)
        check_two_speeds(self)

    def stretch(self, vel_rad_s: float) -> StretchTestParams:
        """The stretch-test parameters of one of the two stretches."""
        return StretchTestParams(
            start_deg=self.start_deg,
            end_deg=self.end_deg,
            velocities_rad_s=(vel_rad_s,),
            levels=self.levels,
            accel_time_s=self.accel_time_s,
            hold_s=self.hold_s,
            end_hold_s=self.end_hold_s,
        )


@dataclasses.dataclass(frozen=True)
class TardieuResult:
    """Outcome of :func:`run_tardieu`.

    Attributes:
        summary: One row per level (see :meth:`table`).
        traces: One row per control step of every stretch: ``level, speed ("slow"/"fast"),
            vel_rad_s`` and the stretch-test columns (:class:`myoexo.clinical.stretch
            .StretchTestResult`) plus ``leg_resisting_nm`` (the leg's own torque, muscles
            and passive knee, against the extension).
        params: The test parameters.
        reflex: Name of the reflex model.
    """

    summary: pd.DataFrame
    traces: pd.DataFrame
    params: TardieuParams
    reflex: str

    def table(self) -> pd.DataFrame:
        """Per level: ``r1_deg``, ``catch``, ``r2_deg``, ``r2_reached``, ``r2_minus_r1_deg``,
        ``slow_peak_nm``, ``fast_peak_nm``, ``fast_slow_peak_ratio`` (muscle resisting
        torque over the motion), ``slow_peak_exo_nm``, ``fast_peak_exo_nm`` (exo torque
        along the motion, constant-speed phase), ``fast_mean_vel_rad_s`` (the knee's mean
        speed in the fast stretch's constant phase) and ``reflex``."""
        return self.summary.copy()


def _moving(trace: pd.DataFrame) -> pd.DataFrame:
    return trace[trace["phase"].isin(MOVING_PHASES)]


def analyse_tardieu(
    slow: pd.DataFrame, fast: pd.DataFrame, params: TardieuParams
) -> dict[str, Any]:
    """R1, R2, their difference and the peak ratio of one level (definitions: module
    docstring) from its slow and fast stretch traces (with ``leg_resisting_nm``)."""
    slow_m, fast_m = _moving(slow), _moving(fast)
    slow_res = slow_m["leg_resisting_nm"].to_numpy()
    slow_deg = slow_m["knee_deg"].to_numpy()
    fast_res = fast_m["leg_resisting_nm"].to_numpy()
    fast_deg = fast_m["knee_deg"].to_numpy()

    # the end-feel: from R2 on, the resistance stays at or above the threshold to the end of
    # the motion (a mid-range bump of tone that the slow stretch passes is no end of range)
    below = np.flatnonzero(slow_res < params.end_feel_torque_nm)
    r2_reached = bool(slow_res[-1] >= params.end_feel_torque_nm)
    if r2_reached:
        r2 = float(slow_deg[below[-1] + 1 if below.size else 0])
    else:
        r2 = float(slow_deg.min())

    excess = fast_res - interp_on_angle(slow_deg, slow_res, fast_deg)  # NaN off the slow range
    catches = np.flatnonzero(excess >= params.catch_threshold_nm)
    catch = catches.size > 0
    r1 = float(fast_deg[catches[0]]) if catch else r2
    slow_peak = float(slow_res.max())
    fast_peak = float(fast_res.max())
    constant = fast["phase"] == "constant"
    slow_constant = slow["phase"] == "constant"
    return {
        "r1_deg": r1,
        "catch": catch,
        "r2_deg": r2,
        "r2_reached": r2_reached,
        "r2_minus_r1_deg": r1 - r2,  # along the extension: the range gained by going slowly
        "slow_peak_nm": slow_peak,
        "fast_peak_nm": fast_peak,
        "fast_slow_peak_ratio": fast_peak / slow_peak if slow_peak > 0 else math.nan,
        "slow_peak_exo_nm": float(slow.loc[slow_constant, "resisting_torque_nm"].max()),
        "fast_peak_exo_nm": float(fast.loc[constant, "resisting_torque_nm"].max()),
        "fast_mean_vel_rad_s": float(-fast.loc[constant, "knee_vel_rad_s"].mean()),
    }


def run_tardieu(
    params: TardieuParams = TardieuParams(),
    *,
    reflex: str | ReflexModel = DEFAULT_REFLEX,
    subjects: Mapping[int, SpasticityParams] | None = None,
    model: mujoco.MjModel | None = None,
    pose: PoseFn | None = None,
) -> TardieuResult:
    """Run the Tardieu test (a slow and a fast extension stretch) at every level of *params*.

    Args:
        params: Test parameters.
        reflex: Reflex model, a registered name (``"stretch"``, ``"uniform"``,
            ``"persistent"``, ...) or a :class:`~myoexo.spasticity.ReflexModel`.
        subjects: Individual reflex parameters per level (default: the nominal Table I
            subjects; :func:`~myoexo.clinical.common.draw_subjects` draws some).
        model: The twin (default: the seated twin, ``TwinParams()``).
        pose: Its posing function (default ``myoexo.model.pose_twin``).

    Returns:
        The per-level table and the traces (:class:`TardieuResult`).

    Raises:
        ValueError: If the reflex is unknown.
    """
    import pandas as pd

    label = reflex_label(reflex)
    model, pose = resolve_twin(model, pose)
    rows, traces = [], []
    for level in params.levels:
        subject = None if subjects is None else subjects.get(level)
        runs = simulate_two_speeds(params, model, level, pose=pose, subject=subject, reflex=reflex)
        for speed, (vel, trace) in runs.items():
            traces.append(trace.assign(level=level, speed=speed, vel_rad_s=vel))
        slow, fast = runs["slow"][1], runs["fast"][1]
        rows.append({"level": level, **analyse_tardieu(slow, fast, params)})
    summary = pd.DataFrame(rows).assign(reflex=label)
    traces_df = pd.concat(traces, ignore_index=True)
    front = ["level", "speed", "vel_rad_s"]
    traces_df = traces_df[front + [c for c in traces_df.columns if c not in front]]
    return TardieuResult(summary, traces_df, params, label)


# ----------------------------------------------------------------------------- figure
def plot_tardieu(result: TardieuResult) -> Figure:
    """Muscle resisting torque vs knee angle at both speeds, one panel per level, with R1
    (the catch, on the fast curve) and R2 (the end-feel, on the slow curve) marked."""
    from matplotlib.figure import Figure

    from myoexo.viz.colors import LEVEL_COLORS

    p = result.params
    summary = result.summary.set_index("level")
    levels = list(summary.index)
    fig = Figure(figsize=(3.6 * len(levels), 3.8), constrained_layout=True)
    axes = np.atleast_1d(fig.subplots(1, len(levels), sharey=True))
    tr = result.traces[result.traces["phase"].isin(MOVING_PHASES)]
    for ax, level in zip(axes, levels, strict=True):
        color = LEVEL_COLORS[level]
        row = summary.loc[level]
        for speed, style, vel in (("slow", "--", p.slow_rad_s), ("fast", "-", p.fast_rad_s)):
            sel = tr[(tr["level"] == level) & (tr["speed"] == speed)]
            ax.plot(
                sel["knee_deg"], sel["leg_resisting_nm"], style, color=color,
                label=f"{speed} {vel:g} rad/s",
            )  # fmt: skip
        ax.axhline(p.end_feel_torque_nm, color="0.6", lw=0.8, ls=":")
        ax.axvline(row["r2_deg"], color="0.3", lw=1.0, ls="--")
        ax.annotate("R2", (row["r2_deg"], 0.97), xycoords=("data", "axes fraction"), ha="right")
        if row["catch"]:
            ax.axvline(row["r1_deg"], color=color, lw=1.2)
            ax.annotate("R1", (row["r1_deg"], 0.9), xycoords=("data", "axes fraction"))
        ax.set_title(
            f"level {level}: R2-R1 {row['r2_minus_r1_deg']:.0f} deg, "
            f"ratio {row['fast_slow_peak_ratio']:.2f}",
            fontsize=9,
        )
        ax.set_xlabel("knee flexion (deg)")
        ax.invert_xaxis()  # the extension runs left to right
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("leg torque against the extension (Nm)")
    axes[0].legend(fontsize=8, loc="upper left")
    fig.suptitle(
        f"Simulated Tardieu test ({result.reflex} reflex): knee {p.start_deg:g} → "
        f"{p.end_deg:g} deg; R1: fast exceeds slow by {p.catch_threshold_nm:g} Nm, "
        f"R2: slow reaches {p.end_feel_torque_nm:g} Nm"
    )
    return fig


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo clinic tardieu``: :class:`TardieuParams`' fields, ``--reflex`` and
    :class:`~myoexo.clinical.common.ExamOptions`' fields."""
    add_exam_arguments(parser, TardieuParams)


def run(args: argparse.Namespace) -> int:
    """Run the test, print the per-level table, optionally write CSVs and the figure."""
    params = from_options(TardieuParams, args)
    options = from_options(ExamOptions, args, reflex=args.reflex)
    result = run_tardieu(params, reflex=options.reflex, subjects=options.subjects(params.levels))
    print_table(result.table())
    options.write("tardieu", result.table(), result.traces, lambda: plot_tardieu(result))
    return 0
