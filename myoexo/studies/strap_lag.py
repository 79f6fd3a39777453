"""``myoexo twin strap-lag``: how far the human knee lags the exo encoder per unit of command.

The straps give under the motor's torque, so a knee held by spastic muscles against the motor
is more flexed than the exo's encoder says. A controller that reads only the encoder (and its
stall guard, :func:`myoexo.control.guard.exo_guard`) corrects its error by this lag. The fit:
hold each subject at constant commands until the knee rests against its muscles, then fit a
line through the origin of ``knee - encoder`` (deg) against the command over the samples at
rest; the lag is minus its slope (deg per unit command, positive).

Subjects come from a root of their own (default 3: not the evaluation root 0, nor the
selection and calibration roots 1 and 2), at levels 2-3, where the muscles hold the knee
short of the target. ``--write`` makes the fit the package's (``myoexo/assets/fits/
strap_lag.json``, with its provenance), which the encoder guard reads.
"""

from __future__ import annotations

import argparse
import shlex
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from myoexo.control.guard import STRAP_LAG_FIT
from myoexo.evaluation.config import check_fit_root, device_fit_root_option
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    check_fields,
    from_options,
    option,
    option_words,
)
from myoexo.spasticity.levels import VALID_LEVELS


@dataclass(frozen=True)
class StrapLagSettings:
    """What the fit holds the subjects at (``root_seed`` and ``subjects`` are options of
    ``myoexo twin strap-lag``; the fit records every field)."""

    root_seed: int = device_fit_root_option()
    subjects: int = option(20, "subjects per level", low=1, high=10_000)
    levels: tuple[int, ...] = option(
        (2, 3),
        "levels whose muscles hold the knee against the motor",
        choices=VALID_LEVELS,
        flag="",
    )
    commands: tuple[float, ...] = option(
        (-0.7, -0.8, -0.9, -1.0),
        "constant commands (extension negative, in [-1, 0)), each held from the start",
        low=-1.0,
        high=0.0,
        flag="",
    )
    hold_s: float = option(
        4.0, "how long each command is held", low=0.0, above=True, unit="s", flag=""
    )
    rest_window_s: float = option(
        1.0,
        "the last part of each hold whose samples at rest enter the fit",
        low=0.0,
        above=True,
        unit="s",
        flag="",
    )
    rest_speed_rad_s: float = option(
        0.01,
        "a sample is at rest if the knee moves slower than this",
        low=0.0,
        above=True,
        unit="rad/s",
        flag="",
    )

    def __post_init__(self) -> None:
        check_fields(self)
        check_fit_root(self.root_seed, "the strap-lag fit")
        if not self.commands:
            raise ValueError("commands is empty: name at least one command in [-1, 0)")
        if 0.0 in self.commands:
            raise FieldError(type(self).__name__, "commands", self.commands, "is outside [-1, 0)")
        if not self.rest_window_s < self.hold_s:
            raise ValueError(
                f"rest_window_s = {self.rest_window_s!r} must be shorter than hold_s = "
                f"{self.hold_s!r}"
            )


@dataclass(frozen=True)
class StrapLagOutput:
    """What ``myoexo twin strap-lag`` does with the fit (an option of the command)."""

    write: bool = option(
        False,
        "make the fit the package's (myoexo/assets/fits/strap_lag.json), which the encoder "
        "guard reads",
    )


@dataclass(frozen=True)
class StrapLagFit:
    """The fitted lag and how well a line through the origin explains the samples.

    Attributes:
        lag_deg_per_command: Knee minus encoder per unit of extension command (deg).
        residual_sd_deg: Standard deviation of the residuals (deg).
        max_residual_deg: Largest residual (deg).
        samples: Control steps at rest that entered the fit.
        settings: The :class:`StrapLagSettings` as a dict.
    """

    lag_deg_per_command: float
    residual_sd_deg: float
    max_residual_deg: float
    samples: int
    settings: dict[str, Any]


def fit_strap_lag(settings: StrapLagSettings, log: Any = None) -> StrapLagFit:
    """Hold every subject at every command and fit the lag (module docstring)."""
    from myoexo.control.policy import ConstantController
    from myoexo.control.rollout import rollout
    from myoexo.envs import make_env
    from myoexo.evaluation.config import subject_seed

    commands, lags = [], []
    channels = ("knee_vel_rad_s", "misalignment_deg")
    for level in settings.levels:
        env = make_env(level)
        dt = float(env.unwrapped.dt)  # type: ignore[attr-defined]
        steps = round(settings.hold_s / dt)
        window = round(settings.rest_window_s / dt)
        episode = int(env.unwrapped.episode_steps)  # type: ignore[attr-defined]
        try:
            for index in range(settings.subjects):
                seed = subject_seed(level, index, settings.root_seed)
                for command in settings.commands:
                    hold = rollout(
                        env, ConstantController(command), seed, channels, until_s=steps * dt
                    )
                    # the window's steps (signals: the reset, then one sample per step); a
                    # step that truncated the episode does not count
                    ended = hold.unstable or hold.n_steps < steps or hold.n_steps >= episode
                    last = hold.n_steps - 1 if ended else hold.n_steps
                    first = steps - window + 1
                    speed = hold.signals["knee_vel_rad_s"][first : last + 1]
                    lag = hold.signals["misalignment_deg"][first : last + 1]
                    at_rest = np.abs(speed) < settings.rest_speed_rad_s
                    commands.extend([command] * int(at_rest.sum()))
                    lags.extend(lag[at_rest].tolist())
            if log is not None:
                log(f"level {level}: {len(lags)} samples at rest so far")
        finally:
            env.close()
    if not lags:
        raise RuntimeError("no sample at rest: hold longer or accept a faster knee")
    u, y = np.asarray(commands), np.asarray(lags)
    slope = float(u @ y / (u @ u))
    residual = y - slope * u
    return StrapLagFit(
        lag_deg_per_command=-slope,
        residual_sd_deg=float(np.std(residual)),
        max_residual_deg=float(np.max(np.abs(residual))),
        samples=int(y.size),
        settings=asdict(settings),
    )


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin strap-lag``: :class:`StrapLagSettings`' and
    :class:`StrapLagOutput`'s fields."""
    add_options(parser, StrapLagSettings)
    add_options(parser, StrapLagOutput)


def run(args: argparse.Namespace) -> int:
    """``myoexo twin strap-lag``: print the fitted lag; with ``--write``, make it the package's."""
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import write_command_fit

    settings = from_options(StrapLagSettings, args)
    output = from_options(StrapLagOutput, args)
    result = fit_strap_lag(settings, log=print)
    print(
        f"strap lag: {result.lag_deg_per_command:.3f} deg per unit command "
        f"(residual sd {result.residual_sd_deg:.3f} deg, at most "
        f"{result.max_residual_deg:.3f}; {result.samples} control steps at rest, levels "
        f"{list(settings.levels)}, {settings.subjects} subjects each of root {settings.root_seed})"
    )
    if output.write:
        command = shlex.join(["myoexo", "twin", "strap-lag", *option_words(settings)])
        write_command_fit(
            STRAP_LAG_FIT, asdict(result), command, TWIN_VERSION, root_seed=settings.root_seed
        )
    return 0


__all__ = ["StrapLagFit", "StrapLagOutput", "StrapLagSettings", "fit_strap_lag"]
