"""Figures of the clinical tests: the stretch-test torque curves, and ``myoexo plot-spasticity``
(the paper's Fig. 2b, :mod:`myoexo.spasticity.plots`, with them).

CLI::

    myoexo plot-spasticity --out DIR [--subjects 200] [--seed 0] [--no-stretch]

writes ``DIR/fig2b_spasticity.png`` (the angle term ``sc_a`` vs knee angle and the velocity
term ``sc_v`` vs knee velocity per level: Table I curve and the 5-95 % band of sampled
subjects) and ``DIR/stretch_test.png`` (resisting torque of the simulated Tardieu test vs
knee angle per level and speed, and the peak torques).
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import TYPE_CHECKING

from myoexo.spasticity.plots import plot_sc_curves
from myoexo.viz.colors import LEVEL_COLORS

if TYPE_CHECKING:
    from matplotlib.figure import Figure

    from myoexo.clinical.stretch import StretchTestResult

__all__ = ["LEVEL_COLORS", "add_arguments", "plot_sc_curves", "plot_stretch_test", "run"]


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


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo plot-spasticity``."""
    parser.add_argument("--out", type=Path, required=True, help="output folder for the PNGs")
    parser.add_argument("--subjects", type=int, default=200, help="subjects per level in the band")
    parser.add_argument("--seed", type=int, default=0, help="seed of the subject draws")
    parser.add_argument(
        "--no-stretch", action="store_true", help="skip the stretch-test simulation and figure"
    )
    parser.add_argument("--dpi", type=int, default=150, help="resolution of the PNGs")


def run(args: argparse.Namespace) -> int:
    """Write the figures to ``args.out``."""
    args.out.mkdir(parents=True, exist_ok=True)
    fig = plot_sc_curves(n_subjects=args.subjects, seed=args.seed)
    path = args.out / "fig2b_spasticity.png"
    fig.savefig(path, dpi=args.dpi)
    print(f"wrote {path}")
    if not args.no_stretch:
        from myoexo.clinical.stretch import run_stretch_test

        result = run_stretch_test(progress=True)
        fig = plot_stretch_test(result)
        path = args.out / "stretch_test.png"
        fig.savefig(path, dpi=args.dpi)
        result.summary.to_csv(args.out / "stretch_summary.csv", index=False)
        print(f"wrote {path} and {args.out / 'stretch_summary.csv'}")
    return 0
