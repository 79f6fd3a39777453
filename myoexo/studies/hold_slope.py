"""``myoexo twin hold-slope``: how much less torque holds the knee per degree it ends short.

Where the motor stalls against the reflex, the strap carries the hold at the end of an
episode, and an episode's peak interaction torque is at least that hold
(:mod:`myoexo.evaluation.bound`). At level 3 the study lets a controller end up to 11.45 deg
short, a little further than the paper's PID ends, and a knee held further short needs less
torque. How much less bounds the peak reduction a controller that meets the accuracy claim
can reach: this command measures it.

For each subject it runs the paper's PID aimed at the target and at targets shifted further
short by each of ``offsets_deg`` (the PID holds the knee where it is aimed, or stalls short of
it), and reads each episode's **end** (the knee's final value as the final error reads it,
:func:`~myoexo.evaluation.metrics.final_value`, from the task's own target, deg) and **hold**
(the mean interaction torque over the bound's window,
:data:`~myoexo.evaluation.bound.HOLD_WINDOW_S`, Nm). A shifted run whose end lies at
least ``min_move_deg`` further short than the subject's own run at the target gives one
**secant slope**: the hold's fall per degree, ``(hold at the target - hold shifted) / (end
shifted - end at the target)``, Nm/deg. The fit keeps, per level, the steepest secant over the
subjects, the offsets and the twins (nominal and perturbed draws,
:mod:`myoexo.envs.robustness`): a controller that ends ``x`` deg further short than the PID on
average holds at most ``x`` times that much less (where no subject's secant is steeper). The
mean secant is recorded beside it.

Subjects come from a root of their own (default 3; the evaluation root 0 is refused).
``--write`` makes the fit the package's (``myoexo/assets/fits/hold_slope.json``, with its
provenance), which :func:`~myoexo.evaluation.bound.hold_bounds` reads.
"""

from __future__ import annotations

import argparse
import shlex
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from myoexo.evaluation.bound import HOLD_SLOPE_FIT, mean_over_end
from myoexo.evaluation.config import check_fit_root, device_fit_root_option
from myoexo.runtime.fields import add_options, check_fields, from_options, option, option_words
from myoexo.spasticity.levels import VALID_LEVELS


@dataclass(frozen=True)
class HoldSlopeSettings:
    """The subjects and the shifted aims (options of ``myoexo twin hold-slope``; the fit
    records every field)."""

    root_seed: int = device_fit_root_option()
    subjects: int = option(20, "subjects per level and twin", low=1, high=10_000)
    levels: tuple[int, ...] = option(
        (2, 3), "levels where the motor stalls against the reflex", choices=VALID_LEVELS
    )
    offsets_deg: tuple[float, ...] = option(
        (4.0, 6.0, 8.0, 10.0, 12.0, 15.0, 20.0, 30.0),
        "how much further short than the target the PID is aimed",
        low=0.0,
        above=True,
        unit="deg",
        flag="",
    )
    min_move_deg: float = option(
        0.5,
        "a shifted run counts where it ends at least this much further short",
        low=0.0,
        above=True,
        unit="deg",
        flag="",
    )
    perturbed: bool = option(
        True, "also measure on perturbed twins (one draw per subject)", flag=""
    )

    def __post_init__(self) -> None:
        check_fields(self)
        check_fit_root(self.root_seed, "the hold-slope fit")
        if not self.offsets_deg:
            raise ValueError("offsets_deg is empty: name at least one positive offset in deg")


@dataclass(frozen=True)
class HoldSlopeOutput:
    """What ``myoexo twin hold-slope`` does with the fit (an option of the command)."""

    write: bool = option(
        False,
        "make the fit the package's (myoexo/assets/fits/hold_slope.json), which the result "
        "sets' hold bounds read",
    )


@dataclass(frozen=True)
class HoldSlopeFit:
    """The fitted slopes per level.

    Attributes:
        levels: Level (as a string, JSON's keys) -> ``max_nm_per_deg`` (the steepest secant:
            the bound's), ``mean_nm_per_deg``, ``secants`` (how many), ``end_deg`` and
            ``hold_nm`` (the PID's mean end and hold at the target).
        settings: The :class:`HoldSlopeSettings` as a dict.
    """

    levels: dict[str, dict[str, float]]
    settings: dict[str, Any]


def _ends_and_holds(
    level: int, task_target_deg: float, aim_deg: float, settings: HoldSlopeSettings, perturbed: bool
) -> tuple[np.ndarray, np.ndarray]:
    """Each subject's end (deg short of *task_target_deg*: the knee's final value, as the
    final error reads it, :func:`~myoexo.evaluation.metrics.final_value`) and hold (Nm, the
    interaction torque's mean over the bound's window,
    :func:`~myoexo.evaluation.bound.mean_over_end`), under the paper's PID aimed at
    *aim_deg*, on the nominal or a *perturbed* twin."""
    from myoexo.control.specs import build_controller, parse_controller_spec
    from myoexo.envs import make_env
    from myoexo.evaluation.engine import evaluate_controller
    from myoexo.evaluation.metrics import final_value

    kwargs = {"target_angle_deg": aim_deg, "robustness": perturbed}
    env = make_env(level, **kwargs)
    try:
        pid = build_controller(parse_controller_spec("pid"), env)
    finally:
        env.close()
    _, episodes = evaluate_controller(
        pid, level, settings.subjects, root_seed=settings.root_seed, env_kwargs=kwargs
    )
    ends = [
        final_value(e.signals["time_s"], e.signals["knee_angle_deg"]) - task_target_deg
        for e in episodes
    ]
    holds = [
        float(mean_over_end(e.signals["time_s"], e.signals["interaction_torque_nm"]))
        for e in episodes
    ]
    return np.asarray(ends), np.asarray(holds)


def fit_hold_slope(settings: HoldSlopeSettings, log: Any = None) -> HoldSlopeFit:
    """Run the PID at the target and at every shifted aim, per level and twin, and keep the
    secant slopes (module docstring)."""
    from myoexo.envs.config import TaskParams

    target = TaskParams().target_angle_deg
    twins = (False, True) if settings.perturbed else (False,)
    levels = {}
    for level in settings.levels:
        secants, ends_0, holds_0 = [], [], []
        for perturbed in twins:
            end_0, hold_0 = _ends_and_holds(level, target, target, settings, perturbed)
            ends_0.append(end_0)
            holds_0.append(hold_0)
            for offset in settings.offsets_deg:
                end, hold = _ends_and_holds(level, target, target + offset, settings, perturbed)
                moved = end - end_0 >= settings.min_move_deg
                secants.extend(((hold_0 - hold)[moved] / (end - end_0)[moved]).tolist())
        if not secants:
            raise RuntimeError(
                f"level {level}: no shifted run ended {settings.min_move_deg} deg further "
                "short; aim further (offsets_deg)"
            )
        levels[str(level)] = {
            "max_nm_per_deg": float(np.max(secants)),
            "mean_nm_per_deg": float(np.mean(secants)),
            "secants": len(secants),
            "end_deg": float(np.concatenate(ends_0).mean()),
            "hold_nm": float(np.concatenate(holds_0).mean()),
        }
        if log is not None:
            s = levels[str(level)]
            log(
                f"level {level}: steepest {s['max_nm_per_deg']:.2f} Nm/deg, mean "
                f"{s['mean_nm_per_deg']:.2f} over {s['secants']} secants (the PID ends "
                f"{s['end_deg']:.2f} deg short holding {s['hold_nm']:.1f} Nm)"
            )
    return HoldSlopeFit(levels=levels, settings=asdict(settings))


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin hold-slope``: :class:`HoldSlopeSettings`' and
    :class:`HoldSlopeOutput`'s fields."""
    add_options(parser, HoldSlopeSettings)
    add_options(parser, HoldSlopeOutput)


def run(args: argparse.Namespace) -> int:
    """``myoexo twin hold-slope``: print the slopes; with ``--write``, make them the
    package's."""
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import write_command_fit

    settings = from_options(HoldSlopeSettings, args)
    output = from_options(HoldSlopeOutput, args)
    result = fit_hold_slope(settings, log=print)
    if output.write:
        command = shlex.join(["myoexo", "twin", "hold-slope", *option_words(settings)])
        write_command_fit(
            HOLD_SLOPE_FIT, asdict(result), command, TWIN_VERSION, root_seed=settings.root_seed
        )
    return 0


__all__ = ["HoldSlopeFit", "HoldSlopeOutput", "HoldSlopeSettings", "fit_hold_slope"]
