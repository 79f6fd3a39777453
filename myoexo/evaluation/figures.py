"""Figures of the evaluation, the equivalents of the paper's Fig. 3-6.

Each function takes data (the episode table, :class:`~myoexo.evaluation.storage.Traces`) and
returns a :class:`matplotlib.figure.Figure` built without pyplot (no GUI backend, no global
state); :mod:`myoexo.evaluation.report` saves them as PNG.

* :func:`plot_level_traces` (Fig. 3): one controller, knee error / command / interaction
  torque over time, mean +- std per level.
* :func:`plot_controller_comparison` (Fig. 4): the same three signals, one column per level,
  mean +- std per controller.
* :func:`plot_rms_vs_settling` (Fig. 5): mean RMS of the interaction torque up to the
  settling time against the mean settling time, per level and controller.
* :func:`plot_peak_boxplots` (Fig. 6): peak interaction torque per level and controller.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from myoexo.evaluation.storage import Traces
from myoexo.viz.colors import LEVEL_COLORS  # the paper's Fig. 5 caption: green, yellow, orange, red

#: Controller colours: the PID in black/grey as in the paper, others from this cycle.
PID_COLOR = "#222222"
OTHER_COLORS: tuple[str, ...] = ("#f0a30a", "#1f77b4", "#9467bd", "#17becf", "#8c564b")
#: Marker per controller in Fig. 5 (paper: triangles PID, circles SAC).
PID_MARKER, OTHER_MARKERS = "^", ("o", "s", "D", "v", "P")

#: The three signals of Fig. 3 and 4: trace channel -> axis label.
SIGNALS: dict[str, str] = {
    "error_deg": "knee error (deg)",
    "command": "command (-)",
    "interaction_torque_nm": "interaction torque (Nm)",
}


def _is_pid(label: str) -> bool:
    return label.lower().startswith("pid")


def controller_styles(labels: Sequence[str]) -> dict[str, tuple[str, str]]:
    """Label -> (colour, marker): PID-like labels dark with triangles, others coloured."""
    styles: dict[str, tuple[str, str]] = {}
    k = 0
    for label in labels:
        if _is_pid(label) and PID_COLOR not in {c for c, _ in styles.values()}:
            styles[label] = (PID_COLOR, PID_MARKER)
        else:
            styles[label] = (OTHER_COLORS[k % len(OTHER_COLORS)], OTHER_MARKERS[k % 5])
            k += 1
    return styles


def _figure(nrows: int, ncols: int, size: tuple[float, float], **kw: Any):
    from matplotlib.figure import Figure

    fig = Figure(figsize=size, layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False, **kw)
    return fig, axes


def _mean_std(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    with np.errstate(invalid="ignore"):
        valid = np.isfinite(x).any(axis=0)
        mean = np.full(x.shape[1], np.nan)
        std = np.full(x.shape[1], np.nan)
        mean[valid] = np.nanmean(x[:, valid], axis=0)
        std[valid] = np.nanstd(x[:, valid], axis=0)
    return mean, std


def _band(ax: Any, t: np.ndarray, x: np.ndarray, color: str, label: str) -> None:
    mean, std = _mean_std(x)
    ax.plot(t, mean, color=color, lw=1.4, label=label)
    ax.fill_between(t, mean - std, mean + std, color=color, alpha=0.2, lw=0)


def plot_level_traces(traces: Mapping[int, Traces], controller: str):
    """Fig. 3: one controller, mean +- std of error, command and interaction torque per level.

    Args:
        traces: Level -> stored traces of ``controller``.
        controller: Label for the title.
    """
    fig, axes = _figure(len(SIGNALS), 1, (7.0, 7.5), sharex=True)
    for level in sorted(traces):
        tr = traces[level]
        for ax, key in zip(axes[:, 0], SIGNALS, strict=True):
            _band(ax, tr.time_s, tr[key], LEVEL_COLORS.get(level, "grey"), f"level {level}")
    for ax, ylabel in zip(axes[:, 0], SIGNALS.values(), strict=True):
        ax.set_ylabel(ylabel)
        ax.grid(alpha=0.3)
    axes[0, 0].axhline(0.0, color="k", lw=0.6)
    axes[-1, 0].set_xlabel("time (s)")
    axes[0, 0].legend(loc="upper right", fontsize=8)
    n = max(len(tr.subjects) for tr in traces.values())
    fig.suptitle(f"{controller}: knee extension per spasticity level (mean ± std, n = {n})")
    return fig


def plot_controller_comparison(traces: Mapping[str, Mapping[int, Traces]]):
    """Fig. 4: columns = levels, rows = error / command / interaction torque, one
    mean +- std band per controller.

    Args:
        traces: Controller label -> level -> stored traces.
    """
    labels = list(traces)
    levels = sorted({lv for per in traces.values() for lv in per})
    styles = controller_styles(labels)
    fig, axes = _figure(
        len(SIGNALS), len(levels), (3.2 * len(levels), 7.0), sharex=True, sharey="row"
    )
    for j, level in enumerate(levels):
        for label in labels:
            tr = traces[label].get(level)
            if tr is None:
                continue
            for i, key in enumerate(SIGNALS):
                _band(axes[i, j], tr.time_s, tr[key], styles[label][0], label)
        axes[0, j].set_title(f"level {level}")
        axes[0, j].axhline(0.0, color="k", lw=0.6)
        axes[-1, j].set_xlabel("time (s)")
    for i, ylabel in enumerate(SIGNALS.values()):
        axes[i, 0].set_ylabel(ylabel)
    for ax in axes.ravel():
        ax.grid(alpha=0.3)
    axes[0, -1].legend(loc="upper right", fontsize=8)
    fig.suptitle("Controllers compared per spasticity level (mean ± std)")
    return fig


def plot_rms_vs_settling(table: Any):
    """Fig. 5: mean RMS of the interaction torque up to the settling time vs mean settling
    time; colour = level, marker = controller, bars = standard deviations.

    Args:
        table: The episode table (columns ``controller, level, settling_time_s,
            rms_interaction_torque_nm``).
    """
    labels = list(dict.fromkeys(table["controller"]))
    styles = controller_styles(labels)
    fig, axes = _figure(1, 1, (6.5, 4.8))
    ax = axes[0, 0]
    stats = table.groupby(["controller", "level"], sort=False).agg(
        ts=("settling_time_s", "mean"),
        ts_sd=("settling_time_s", "std"),
        rms=("rms_interaction_torque_nm", "mean"),
        rms_sd=("rms_interaction_torque_nm", "std"),
    )
    for (label, level), row in stats.iterrows():
        color, marker = LEVEL_COLORS.get(level, "grey"), styles[label][1]
        ax.errorbar(
            row.ts,
            row.rms,
            xerr=row.ts_sd,
            yerr=row.rms_sd,
            fmt=marker,
            color=color,
            ms=8,
            mec="k",
            capsize=2,
            alpha=0.9,
        )
    from matplotlib.lines import Line2D

    handles = [Line2D([], [], ls="", marker=styles[c][1], color="grey", mec="k") for c in labels]
    handles += [
        Line2D([], [], ls="", marker="s", color=LEVEL_COLORS[lv])
        for lv in sorted(set(table["level"]))
    ]
    names = labels + [f"level {lv}" for lv in sorted(set(table["level"]))]
    ax.legend(handles, names, fontsize=8, loc="best")
    ax.set_xlabel("settling time, 2 % band (s)")
    ax.set_ylabel("RMS interaction torque up to settling (Nm)")
    ax.grid(alpha=0.3)
    ax.set_title("RMS of the interaction torque vs settling time (mean ± std)")
    return fig


def plot_peak_boxplots(table: Any):
    """Fig. 6: box plots of the peak interaction torque per level, one box per controller
    (median line, IQR box, 1.5 IQR whiskers, outliers, mean as a dot).

    Args:
        table: The episode table (columns ``controller, level, peak_interaction_torque_nm``).
    """
    labels = list(dict.fromkeys(table["controller"]))
    levels = sorted(set(table["level"]))
    styles = controller_styles(labels)
    fig, axes = _figure(1, 1, (1.6 + 1.5 * len(levels) * max(1, len(labels)) * 0.6, 4.8))
    ax = axes[0, 0]
    width = 0.8 / len(labels)
    for k, label in enumerate(labels):
        data, pos = [], []
        for i, level in enumerate(levels):
            x = table.loc[(table.controller == label) & (table.level == level)]
            values = x["peak_interaction_torque_nm"].dropna().to_numpy()
            if values.size:
                data.append(values)
                pos.append(i + (k - (len(labels) - 1) / 2) * width)
        if not data:
            continue
        color = styles[label][0]
        ax.boxplot(
            data,
            positions=pos,
            widths=width * 0.9,
            patch_artist=True,
            showmeans=True,
            meanprops={"marker": "o", "markerfacecolor": "white", "markeredgecolor": "k"},
            boxprops={"facecolor": color, "alpha": 0.6},
            medianprops={"color": "k"},
            flierprops={"markersize": 3},
            manage_ticks=False,
        )
        ax.plot([], [], "s", color=color, alpha=0.6, label=label)
    ax.set_xticks(range(len(levels)), [f"level {lv}" for lv in levels])
    ax.set_ylabel("peak interaction torque (Nm)")
    ax.grid(alpha=0.3, axis="y")
    ax.legend(fontsize=8)
    ax.set_title("Peak interaction torque per spasticity level")
    return fig
