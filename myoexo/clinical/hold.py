"""Stretch-and-hold test of the knee flexors: does the resistance outlast the stretch?

The exo extends the relaxed knee from ``start_deg`` to ``end_deg`` (stretching the hamstrings
and gastrocnemii) once slowly and once fast, with the stiff PD of
:mod:`myoexo.clinical.stretch`, then *holds* it there for ``hold_s``. A reflex without memory
(``"uniform"``, ``"stretch"``) answers the present (delayed) angle and speed only: once the
knee is held, the fast and the slow stretch leave the same resistance. A reflex with an
after-discharge (``"persistent"``: motoneurons firing on for seconds after a fast stretch,
Gorassini et al. 2004, Mottram et al. 2009) keeps resisting after the fast stretch only.

Per level the test reports the leg's resisting torque (its muscles' and its passive knee's,
against the extension, Nm) in two windows of the hold, ``early`` (0.5-1 s after the stop) and
``late`` (the last 0.5 s), after each stretch, and the excess of the fast over the slow
stretch in each window::

    hold_excess_early_nm = fast_early_nm - slow_early_nm
    hold_excess_late_nm  = fast_late_nm  - slow_late_nm

(0 for a reflex without memory; > 0 while an after-discharge lasts), plus the flexors' reflex
excitation at the end of each hold (``*_end_sc``; for ``"persistent"`` ``SC_total + G r``).

On the command line, ``myoexo clinic hold --reflex persistent``: every field of
:class:`StretchHoldParams` is an option of its own name (``--hold-s``, ``--end-deg``, ...).
API::

    from myoexo.clinical.hold import run_stretch_hold
    run_stretch_hold(reflex="persistent").table()
"""

from __future__ import annotations

import argparse
import dataclasses
from collections.abc import Mapping
from typing import TYPE_CHECKING

from myoexo.clinical.common import (
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
from myoexo.runtime.fields import add_options, check_fields, from_options, option
from myoexo.spasticity.levels import SpasticityParams
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel, add_reflex_argument, reflex_label

if TYPE_CHECKING:
    import mujoco
    import pandas as pd

    from myoexo.clinical.common import PoseFn

__all__ = ["StretchHoldParams", "StretchHoldResult", "run_stretch_hold"]


@dataclasses.dataclass(frozen=True)
class StretchHoldParams:
    """Parameters of the stretch-and-hold test (each field is an option of ``myoexo clinic
    hold``).

    Attributes:
        start_deg: Knee flexion at the start, deg (90: the seated rest).
        end_deg: Knee flexion held after the stretch, deg (30: inside the range, short of the
            seated hamstrings' passive end range near 20 deg).
        slow_rad_s: The slow stretch's speed, rad/s (Tardieu V1).
        fast_rad_s: The fast stretch's speed, rad/s (Tardieu V3).
        hold_s: Time held at ``end_deg`` after the stretch, s (>= 1.5).
        levels: Spasticity levels to test.
    """

    start_deg: float = option(90.0, "knee flexion at the start", low=0.0, high=120.0, unit="deg")
    end_deg: float = option(
        30.0, "knee flexion held after the stretch", low=0.0, high=120.0, unit="deg"
    )
    slow_rad_s: float = option(
        0.2, "the slow stretch's speed", low=0.0, above=True, unit="rad/s", metavar="RAD_S"
    )
    fast_rad_s: float = option(
        3.0, "the fast stretch's speed", low=0.0, above=True, unit="rad/s", metavar="RAD_S"
    )
    hold_s: float = option(
        3.0, "time held at the end after the stretch", low=1.5, high=60.0, unit="s"
    )
    levels: tuple[int, ...] = levels_option()

    def __post_init__(self) -> None:
        check_fields(self)
        normalise_levels(self)
        check_two_speeds(self)

    def stretch(self, vel_rad_s: float) -> StretchTestParams:
        """The stretch-test parameters of one stretch and its hold."""
        return StretchTestParams(
            start_deg=self.start_deg,
            end_deg=self.end_deg,
            velocities_rad_s=(vel_rad_s,),
            levels=self.levels,
            end_hold_s=self.hold_s,
        )


@dataclasses.dataclass(frozen=True)
class StretchHoldResult:
    """Outcome of :func:`run_stretch_hold`.

    Attributes:
        summary: One row per level (see :meth:`table`).
        traces: One row per control step of every run: ``level, speed, vel_rad_s`` and the
            stretch-test columns plus ``leg_resisting_nm`` and ``hold_time_s`` (time since
            the hold began, NaN before).
        params: The test parameters.
        reflex: Name of the reflex model.
    """

    summary: pd.DataFrame
    traces: pd.DataFrame
    params: StretchHoldParams
    reflex: str

    def table(self) -> pd.DataFrame:
        """Per level: ``slow_early_nm, fast_early_nm, slow_late_nm, fast_late_nm``
        (mean muscle resisting torque in the hold's windows), ``hold_excess_early_nm``,
        ``hold_excess_late_nm`` (fast minus slow), ``slow_end_sc, fast_end_sc`` (the flexors'
        reflex excitation at the end of the hold), ``fast_peak_nm`` (the fast stretch's
        peak resisting torque during the motion) and ``reflex``."""
        return self.summary.copy()


def run_stretch_hold(
    params: StretchHoldParams = StretchHoldParams(),
    *,
    reflex: str | ReflexModel = DEFAULT_REFLEX,
    subjects: Mapping[int, SpasticityParams] | None = None,
    model: mujoco.MjModel | None = None,
    pose: PoseFn | None = None,
) -> StretchHoldResult:
    """Run the stretch-and-hold test (slow and fast, each then held) at every level.

    Args:
        params: Test parameters.
        reflex: Reflex model, a registered name or a :class:`~myoexo.spasticity.ReflexModel`.
        subjects: Individual reflex parameters per level (default: nominal Table I).
        model: The twin (default: the seated twin).
        pose: Its posing function.

    Raises:
        ValueError: If the reflex is unknown.
    """
    import numpy as np
    import pandas as pd

    label = reflex_label(reflex)
    model, pose = resolve_twin(model, pose)
    rows, traces = [], []
    for level in params.levels:
        subject = None if subjects is None else subjects.get(level)
        row: dict[str, float | int] = {"level": level}
        runs = simulate_two_speeds(params, model, level, pose=pose, subject=subject, reflex=reflex)
        for speed, (vel, trace) in runs.items():
            hold = (trace["phase"] == "end_hold").to_numpy()
            t0 = float(trace["time_s"][hold].iloc[0])
            trace["hold_time_s"] = np.where(hold, trace["time_s"] - t0, np.nan)
            ht = trace["hold_time_s"]
            early = (ht >= 0.5) & (ht < 1.0)
            late = ht >= params.hold_s - 0.5
            res = trace["leg_resisting_nm"]
            moving = trace["phase"].isin(MOVING_PHASES)
            row[f"{speed}_early_nm"] = float(res[early].mean())
            row[f"{speed}_late_nm"] = float(res[late].mean())
            row[f"{speed}_end_sc"] = float(trace["sc_total"][hold].iloc[-1])
            row[f"{speed}_peak_nm"] = float(res[moving].max())
            traces.append(trace.assign(level=level, speed=speed, vel_rad_s=vel))
        row["hold_excess_early_nm"] = float(row["fast_early_nm"]) - float(row["slow_early_nm"])
        row["hold_excess_late_nm"] = float(row["fast_late_nm"]) - float(row["slow_late_nm"])
        rows.append(row)
    order = [
        "level",
        "slow_early_nm",
        "fast_early_nm",
        "hold_excess_early_nm",
        "slow_late_nm",
        "fast_late_nm",
        "hold_excess_late_nm",
        "slow_end_sc",
        "fast_end_sc",
        "fast_peak_nm",
    ]
    summary = pd.DataFrame(rows)[order].assign(reflex=label)
    traces_df = pd.concat(traces, ignore_index=True)
    return StretchHoldResult(summary, traces_df, params, label)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo clinic hold``: :class:`StretchHoldParams`' fields and ``--reflex``."""
    add_options(parser, StretchHoldParams)
    add_reflex_argument(parser, default=DEFAULT_REFLEX)


def run(args: argparse.Namespace) -> int:
    """``myoexo clinic hold [--reflex NAME] [--levels ...] [--hold-s 3]``: the table."""
    params = from_options(StretchHoldParams, args)
    print_table(run_stretch_hold(params, reflex=args.reflex).table())
    return 0
