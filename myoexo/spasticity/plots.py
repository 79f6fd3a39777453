"""The paper's Fig. 2b: the spasticity coefficient's angle and velocity terms per level, the
Table I curve and the 5-95 % band of sampled subjects."""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from myoexo.spasticity.coefficients import sc_angle, sc_velocity
from myoexo.spasticity.levels import LEVELS, sample_subject
from myoexo.viz.colors import LEVEL_COLORS

if TYPE_CHECKING:
    from matplotlib.figure import Figure


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
