"""``myoexo strap-lag``: how far the human knee lags the exo encoder per unit of command.

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
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from myoexo.control.guard import STRAP_LAG_FIT


@dataclass(frozen=True)
class StrapLagSettings:
    """What the fit holds the subjects at.

    Attributes:
        root_seed: Root of the subjects (not the evaluation root 0).
        subjects: Subjects per level.
        levels: Levels whose muscles hold the knee against the motor.
        commands: Constant commands (extension negative), each held from the start.
        hold_s: How long each command is held, s.
        rest_window_s: The samples of the last ``rest_window_s`` count.
        rest_speed_rad_s: ... if the knee moves slower than this.
    """

    root_seed: int = 3
    subjects: int = 20
    levels: tuple[int, ...] = (2, 3)
    commands: tuple[float, ...] = (-0.7, -0.8, -0.9, -1.0)
    hold_s: float = 4.0
    rest_window_s: float = 1.0
    rest_speed_rad_s: float = 0.01

    def __post_init__(self) -> None:
        from myoexo.evaluation.config import EVALUATION_ROOT_SEED

        if self.root_seed == EVALUATION_ROOT_SEED or self.root_seed < 0:
            raise ValueError(
                f"root_seed = {self.root_seed!r}: the fit may not see the evaluation root "
                f"{EVALUATION_ROOT_SEED}; accepted: another root >= 0"
            )
        if not 1 <= self.subjects <= 10_000:
            raise ValueError(f"subjects = {self.subjects!r} is outside [1, 10000]")
        if not self.commands or any(not -1.0 <= c < 0.0 for c in self.commands):
            raise ValueError(f"commands = {self.commands!r}: each must be in [-1, 0)")
        if not 0.0 < self.rest_window_s < self.hold_s:
            raise ValueError(
                f"rest_window_s = {self.rest_window_s!r} must be in (0, hold_s = {self.hold_s})"
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
    from myoexo.envs import make_env
    from myoexo.evaluation.config import subject_seed

    commands, lags = [], []
    for level in settings.levels:
        env = make_env(level)
        base: Any = env.unwrapped  # a MyoExoKneeEnv
        dt = float(base.dt)
        steps = round(settings.hold_s / dt)
        window = round(settings.rest_window_s / dt)
        try:
            for index in range(settings.subjects):
                seed = subject_seed(level, index, settings.root_seed)
                for command in settings.commands:
                    env.reset(seed=seed)
                    action = np.array([command], dtype=np.float32)
                    for step in range(steps):
                        _, _, _, truncated, info = env.step(action)
                        if truncated:
                            break
                        if step >= steps - window and (
                            abs(info["knee_vel_rad_s"]) < settings.rest_speed_rad_s
                        ):
                            commands.append(command)
                            lags.append(info["misalignment_deg"])
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
    """Options of ``myoexo strap-lag``."""
    d = StrapLagSettings()
    parser.add_argument("--seed", type=int, default=d.root_seed, help="root seed of the subjects")
    parser.add_argument("--subjects", type=int, default=d.subjects, help="subjects per level")
    parser.add_argument(
        "--write",
        action="store_true",
        help="make the fit the package's (myoexo/assets/fits/strap_lag.json), which the "
        "encoder guard reads",
    )


def run(args: argparse.Namespace) -> int:
    """``myoexo strap-lag``: print the fitted lag; with ``--write``, make it the package's."""
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import provenance, write_fit

    settings = StrapLagSettings(root_seed=args.seed, subjects=args.subjects)
    result = fit_strap_lag(settings, log=print)
    print(
        f"strap lag: {result.lag_deg_per_command:.3f} deg per unit command "
        f"(residual sd {result.residual_sd_deg:.3f} deg, at most "
        f"{result.max_residual_deg:.3f}; {result.samples} control steps at rest, levels "
        f"{list(settings.levels)}, {settings.subjects} subjects each of root {settings.root_seed})"
    )
    if args.write:
        command = f"myoexo strap-lag --seed {settings.root_seed} --subjects {settings.subjects}"
        path = write_fit(
            STRAP_LAG_FIT,
            asdict(result),
            provenance(f"{command} --write", TWIN_VERSION, root_seed=settings.root_seed),
        )
        print(f"written: {path}")
    return 0


__all__ = ["StrapLagFit", "StrapLagSettings", "fit_strap_lag"]
