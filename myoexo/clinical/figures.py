"""Figures of the spasticity model and of the clinical tests: the paper's Fig. 2b (the
spasticity coefficient's angle and velocity terms per level, the Table I curve and the 5-95 %
band of sampled subjects: :func:`plot_sc_curves`), the stretch-test torque curves, and
``myoexo clinic plot``, which draws both.

CLI::

    myoexo clinic plot --out DIR [--subjects 200] [--seed 0] [--no-stretch] [--dpi 150]

writes ``DIR/fig2b_spasticity.png`` (the angle term ``sc_a`` vs knee angle and the velocity
term ``sc_v`` vs knee velocity per level: Table I curve and the 5-95 % band of sampled
subjects) and ``DIR/stretch_test.png`` (resisting torque of the simulated Tardieu test vs
knee angle per level and speed, and the peak torques).
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from myoexo.runtime.fields import add_options, check_fields, from_options, option
from myoexo.spasticity.coefficients import sc_angle, sc_velocity
from myoexo.spasticity.levels import LEVELS, sample_subject
from myoexo.viz.colors import LEVEL_COLORS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from myoexo.clinical.stretch import StretchTestResult

__all__ = [
    "LEVEL_COLORS",
    "PlotConfig",
    "add_arguments",
    "plot_sc_curves",
    "plot_stretch_test",
    "run",
    "subject_band",
]


def subject_band(
    x: np.ndarray,
    level: int,
    term: str,
    n_subjects: int,
    rng: np.random.Generator,
    quantiles: tuple[float, float] = (0.05, 0.95),
) -> tuple[np.ndarray, np.ndarray]:
    """Quantile band of one term of the coefficient over sampled subjects of a level.

    Args:
        x: Knee angles in deg (``term="angle"``) or velocities in rad/s (``"velocity"``).
        level: Spasticity level.
        term: ``"angle"`` (``sc_a``) or ``"velocity"`` (``sc_v``).
        n_subjects: Number of subjects drawn with :func:`~myoexo.spasticity.sample_subject`.
        rng: Random generator.
        quantiles: Lower and upper quantile of the band.

    Returns:
        ``(lower, upper)`` arrays with the shape of *x*.
    """
    if term not in ("angle", "velocity"):
        raise ValueError(f"term must be 'angle' or 'velocity', got {term!r}.")
    if n_subjects < 2:
        raise ValueError(f"n_subjects must be >= 2, got {n_subjects}.")
    fn = sc_angle if term == "angle" else sc_velocity
    curves = np.stack([fn(x, sample_subject(level, rng)) for _ in range(n_subjects)])
    lower, upper = np.quantile(curves, quantiles, axis=0)
    return lower, upper


def plot_sc_curves(n_subjects: int = 200, seed: int = 0) -> Figure:
    """The paper's Fig. 2b: ``sc_a`` vs knee angle and ``sc_v`` vs knee velocity per level.

    Args:
        n_subjects: Subjects per level drawn for the band (5-95 %).
        seed: Seed of the subject draws.
    """
    from matplotlib.figure import Figure  # no pyplot: works in scripts and notebooks alike

    rng = np.random.default_rng(seed)
    theta_deg = np.linspace(-60.0, 130.0, 381)
    vel_rad_s = np.linspace(-4.0, 4.0, 401)
    fig = Figure(figsize=(10, 4), constrained_layout=True)
    ax_a, ax_v = fig.subplots(1, 2)
    for level, params in LEVELS.items():
        color = LEVEL_COLORS[level]
        for ax, x, term, fn in (
            (ax_a, theta_deg, "angle", sc_angle),
            (ax_v, vel_rad_s, "velocity", sc_velocity),
        ):
            lower, upper = subject_band(x, level, term, n_subjects, rng)
            ax.fill_between(x, lower, upper, color=color, alpha=0.2, linewidth=0)
            ax.plot(x, fn(x, params), color=color, label=f"level {level}")
    ax_a.set(xlabel="knee angle θ (deg, flexion +)", ylabel="sc_a (fraction of F_max)")
    ax_a.set_title("angle term")
    ax_v.set(xlabel="knee velocity v (rad/s, flexion +)", ylabel="sc_v (fraction of F_max)")
    ax_v.set_title("velocity term")
    for ax in (ax_a, ax_v):
        ax.grid(alpha=0.3)
        ax.set_ylim(-0.02, 0.65)
    ax_a.legend(title=f"Table I; band: 5-95 % of {n_subjects} subjects", fontsize=8)
    fig.suptitle("Spasticity coefficient per level (paper Fig. 2b)")
    return fig


def plot_stretch_test(result: StretchTestResult) -> Figure:
    """Resisting torque vs knee angle per level, one panel per speed, and the peak torques."""
    from matplotlib.figure import Figure

    speeds = list(result.params.velocities_rad_s)
    fig = Figure(figsize=(4.2 * (len(speeds) + 1), 4), constrained_layout=True)
    axes = fig.subplots(1, len(speeds) + 1)
    traces = result.traces
    from myoexo.clinical.stretch import MOVING_PHASES

    moving = traces["phase"].isin(MOVING_PHASES)
    for ax, speed in zip(axes[:-1], speeds, strict=True):
        for level in result.params.levels:
            sel = moving & (traces["level"] == level) & (traces["vel_rad_s"] == speed)
            ax.plot(
                traces.loc[sel, "knee_deg"],
                traces.loc[sel, "resisting_torque_nm"],
                color=LEVEL_COLORS[level],
                label=f"level {level}",
            )
        ax.set(xlabel="knee angle (deg)", ylabel="resisting torque (Nm)")
        ax.set_title(f"stretch at {speed:g} rad/s")
        ax.grid(alpha=0.3)
        if result.params.direction < 0:
            ax.invert_xaxis()  # time runs left to right during an extension stretch
    axes[0].legend(fontsize=8)
    peaks = result.peak_table()
    width = 0.8 / len(peaks.columns)
    for j, speed_column in enumerate(peaks.columns):
        axes[-1].bar(
            peaks.index + (j - (len(peaks.columns) - 1) / 2) * width,
            peaks[speed_column],
            width=width,
            color=[LEVEL_COLORS[lv] for lv in peaks.index],
            alpha=0.45 + 0.55 * j / max(1, len(peaks.columns) - 1),
            edgecolor="black",
            label=f"{speed_column:g} rad/s",
        )
    axes[-1].set(xlabel="spasticity level", ylabel="peak resisting torque (Nm)")
    axes[-1].set_xticks(list(peaks.index))
    axes[-1].set_title("peak, constant-speed phase")
    axes[-1].grid(alpha=0.3, axis="y")
    p = result.params
    fig.suptitle(f"Simulated Tardieu stretch, knee {p.start_deg:g} → {p.end_deg:g} deg")
    return fig


@dataclasses.dataclass(frozen=True)
class PlotConfig:
    """What ``myoexo clinic plot`` draws and where (each field is an option of its own name;
    ``--out`` is required)."""

    out: Path = option(
        doc="output folder for the PNGs (required, no default)", folder=True, metavar="DIR"
    )
    subjects: int = option(200, "subjects per level in the band", low=2)
    seed: int = option(0, "seed of the subject draws", low=0)
    stretch: bool = option(True, "simulate the stretch test and draw its figure")
    dpi: int = option(150, "resolution of the PNGs", low=1)

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo clinic plot``: :class:`PlotConfig`'s fields."""
    add_options(parser, PlotConfig)
    # the field has no default: its option is required
    next(a for a in parser._actions if a.dest == "out").required = True


def run(args: argparse.Namespace) -> int:
    """Write the figures to ``--out``."""
    config = from_options(PlotConfig, args)
    config.out.mkdir(parents=True, exist_ok=True)
    fig = plot_sc_curves(n_subjects=config.subjects, seed=config.seed)
    path = config.out / "fig2b_spasticity.png"
    fig.savefig(path, dpi=config.dpi)
    print(f"wrote {path}")
    if config.stretch:
        from myoexo.clinical.stretch import run_stretch_test

        result = run_stretch_test(progress=True)
        fig = plot_stretch_test(result)
        path = config.out / "stretch_test.png"
        fig.savefig(path, dpi=config.dpi)
        result.summary.to_csv(config.out / "stretch_summary.csv", index=False)
        print(f"wrote {path} and {config.out / 'stretch_summary.csv'}")
    return 0
