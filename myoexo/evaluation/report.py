"""``myoexo report DIR``: figures and a Markdown report of an evaluation folder.

Writes, into ``DIR`` (or ``--out``):

* ``figures/fig3_<controller>.png`` (per-level traces of each controller),
  ``figures/fig4_comparison.png``, ``figures/fig5_rms_vs_settling.png``,
  ``figures/fig6_peak_torque.png`` (:mod:`myoexo.evaluation.figures`);
* ``summary.csv``: per controller and level, mean / std / median / IQR of the metrics;
* ``report.md``: the summary table, the comparison with the paper's numbers
  (docs/reference.md section 5, :mod:`myoexo.evaluation.paper`), the reductions of every
  other controller against the PID per level (in % of the PID's mean, and the paired
  per-subject difference in Nm), the run's configuration and the package versions.

Reductions follow the paper: ``100 (mean_PID - mean_other) / mean_PID`` for the peak
interaction torque and its RMS up to the settling time; the paired difference uses the same
subjects (subject ``i`` of a level is the same person for every controller).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.specs import controller_slug
from myoexo.envs.options import TwinOptions
from myoexo.evaluation.config import load_config
from myoexo.evaluation.paper import PAPER_HEADLINES, PAPER_RESULTS
from myoexo.evaluation.storage import load_table, load_traces
from myoexo.runtime.docs import docs_url

#: Metrics summarized per controller and level (column -> label in the report).
SUMMARY_METRICS: dict[str, str] = {
    "final_error_deg": "final error (deg)",
    "target_overshoot_deg": "overshoot past target (deg)",
    "settling_time_s": "settling time (s)",
    "rms_interaction_torque_nm": "RMS torque to settling (Nm)",
    "peak_interaction_torque_nm": "peak torque (Nm)",
    "command_rms": "command RMS (-)",
    "command_total_variation": "command total variation (-)",
}


def summarize(table: Any) -> Any:
    """Per (controller, level): count, unstable episodes, and mean / std / median / q25 /
    q75 of every metric of :data:`SUMMARY_METRICS` (NaN settling times ignored)."""
    import pandas as pd

    rows = []
    for (label, level), episodes in table.groupby(["controller", "level"], sort=False):
        row: dict[str, Any] = {
            "controller": label,
            "level": int(level),
            "n": len(episodes),
            "unstable": int(episodes["unstable"].sum()),
            "not_settled": int(episodes["settling_time_s"].isna().sum()),
        }
        for col in SUMMARY_METRICS:
            values = episodes[col].to_numpy(dtype=float)
            values = values[np.isfinite(values)]
            stats = (
                (
                    values.mean(),
                    values.std(ddof=1) if values.size > 1 else 0.0,
                    *np.percentile(values, [50, 25, 75]),
                )
                if values.size
                else (math.nan,) * 5
            )
            for name, value in zip(("mean", "std", "median", "q25", "q75"), stats, strict=True):
                row[f"{col}_{name}"] = float(value)
        rows.append(row)
    return pd.DataFrame(rows)


def reference_controller(labels: Sequence[str]) -> str | None:
    """The PID the others are compared with: ``pid`` if present, else the first PID-like."""
    if "pid" in labels:
        return "pid"
    return next((c for c in labels if c.lower().startswith("pid")), None)


def reductions(table: Any, reference: str, other: str) -> Any:
    """Per level: reduction of ``other`` vs ``reference`` for the RMS to settling and the
    peak interaction torque, in % of the reference's mean, and the paired difference
    (reference - other, same subjects) as mean and std in Nm."""
    import pandas as pd

    rows = []
    cols = {"rms": "rms_interaction_torque_nm", "peak": "peak_interaction_torque_nm"}
    ref = table[table.controller == reference].set_index(["level", "subject"])
    oth = table[table.controller == other].set_index(["level", "subject"])
    for level in sorted(set(ref.index.get_level_values(0)) & set(oth.index.get_level_values(0))):
        ref_level, other_level = ref.loc[level], oth.loc[level]
        common = ref_level.index.intersection(other_level.index)
        row: dict[str, Any] = {"level": int(level), "n_paired": len(common)}
        for key, col in cols.items():
            mean_ref, mean_other = ref_level[col].mean(), other_level[col].mean()
            diff = (ref_level.loc[common, col] - other_level.loc[common, col]).to_numpy(dtype=float)
            row[f"{key}_reduction_pct"] = (
                100.0 * (mean_ref - mean_other) / mean_ref if mean_ref else math.nan
            )
            row[f"{key}_paired_diff_nm_mean"] = float(diff.mean()) if diff.size else math.nan
            row[f"{key}_paired_diff_nm_std"] = (
                float(diff.std(ddof=1)) if diff.size > 1 else math.nan
            )
        rows.append(row)
    return pd.DataFrame(rows)


# ----------------------------------------------------------------------------- markdown
def _fmt(x: Any, digits: int = 2) -> str:
    if x is None:
        return "-"
    if isinstance(x, str):
        return x
    if not math.isfinite(float(x)):
        return "n/a"
    return f"{float(x):.{digits}f}"


def _pm(mean: float, std: float, digits: int = 2) -> str:
    if not math.isfinite(mean):
        return "n/a"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def _md_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A Markdown table (pandas ``to_markdown``) of pre-formatted cells."""
    import pandas as pd

    frame = pd.DataFrame([[str(cell) for cell in row] for row in rows], columns=list(headers))
    return str(frame.to_markdown(index=False, disable_numparse=True))


def _summary_section(summary: Any) -> str:
    headers = ["controller", "level", "n", *SUMMARY_METRICS.values(), "unstable", "not settled"]
    rows = []
    for _, stats in summary.iterrows():
        cells = [stats.controller, stats.level, stats.n]
        for col in SUMMARY_METRICS:
            digits = 3 if col.startswith("command") else 2
            cells.append(_pm(stats[f"{col}_mean"], stats[f"{col}_std"], digits))
        cells += [stats.unstable, stats.not_settled]
        rows.append(cells)
    return _md_table(headers, rows)


def _paper_section(summary: Any, red: dict[str, Any], reference: str | None) -> str:
    """Measured numbers next to the paper's, level by level."""
    by_key = summary.set_index(["controller", "level"])
    levels = sorted(set(summary.level))
    parts = []
    if reference is not None:
        rows = []
        for lv in levels:
            if (reference, lv) not in by_key.index:
                continue
            ours, paper = by_key.loc[(reference, lv)], PAPER_RESULTS[lv]
            rows.append(
                [
                    lv,
                    _pm(ours.final_error_deg_mean, ours.final_error_deg_std),
                    _pm(ours.target_overshoot_deg_mean, ours.target_overshoot_deg_std),
                    paper.pid_final_error_text,
                    _pm(ours.settling_time_s_mean, ours.settling_time_s_std),
                    _pm(
                        ours.peak_interaction_torque_nm_mean,
                        ours.peak_interaction_torque_nm_std,
                        1,
                    ),
                ]
            )
        parts.append(
            f"**PID baseline (`{reference}`)** - final error = knee - target over the last "
            "0.1 s (positive: short of the target); overshoot = how far the knee went past "
            "the target.\n\n"
            + _md_table(
                [
                    "level",
                    "final error (deg), ours",
                    "overshoot past target (deg), ours",
                    "paper: PID final error",
                    "settling time (s), ours",
                    "peak torque (Nm), ours",
                ],
                rows,
            )
        )
    for other, rdf in red.items():
        red_by_level = rdf.set_index("level")
        rows = []
        for lv in levels:
            if (other, lv) not in by_key.index:
                continue
            ours, paper = by_key.loc[(other, lv)], PAPER_RESULTS[lv]
            has = lv in red_by_level.index
            rms = red_by_level.loc[lv, "rms_reduction_pct"] if has else math.nan
            peak = red_by_level.loc[lv, "peak_reduction_pct"] if has else math.nan
            rows.append(
                [
                    lv,
                    _pm(ours.settling_time_s_mean, ours.settling_time_s_std),
                    _fmt(paper.sac_settling_time_s),
                    _pm(ours.final_error_deg_mean, ours.final_error_deg_std),
                    paper.sac_final_error_text,
                    _fmt(rms, 1),
                    _fmt(paper.rms_reduction_pct, 1),
                    _fmt(peak, 1),
                    _fmt(paper.peak_reduction_pct, 1),
                ]
            )
        parts.append(
            f"**`{other}` vs the paper's SAC** (reductions against `{reference}`, in % of its "
            "mean; positive = lower torque than the PID)\n\n"
            + _md_table(
                [
                    "level",
                    "settling (s), ours",
                    "paper",
                    "final error (deg), ours",
                    "paper",
                    "RMS reduction %, ours",
                    "paper",
                    "peak reduction %, ours",
                    "paper",
                ],
                rows,
            )
        )
    return "\n\n".join(parts)


def _reduction_section(red: dict[str, Any], reference: str) -> str:
    parts = []
    headlines = PAPER_HEADLINES
    for other, rdf in red.items():
        rows = [
            [
                int(red.level),
                int(red.n_paired),
                _fmt(red.rms_reduction_pct, 1),
                _pm(red.rms_paired_diff_nm_mean, red.rms_paired_diff_nm_std),
                _fmt(red.peak_reduction_pct, 1),
                _pm(red.peak_paired_diff_nm_mean, red.peak_paired_diff_nm_std),
            ]
            for red in rdf.itertuples()
        ]
        mean_peak = float(rdf.peak_reduction_pct.mean())
        mean_rms = float(rdf.rms_reduction_pct.mean())
        level_nm = rdf.peak_paired_diff_nm_mean.to_numpy(dtype=float)
        parts.append(
            f"**`{other}` vs `{reference}`** (paired: same subjects)\n\n"
            + _md_table(
                [
                    "level",
                    "pairs",
                    "RMS reduction %",
                    "RMS paired diff (Nm)",
                    "peak reduction %",
                    "peak paired diff (Nm)",
                ],
                rows,
            )
            + f"\n\nMean over levels: peak torque {_fmt(mean_peak, 1)} % "
            f"(paper {headlines.peak_reduction_pct} %), "
            f"{_pm(level_nm.mean(), level_nm.std(ddof=1) if level_nm.size > 1 else 0.0, 1)} Nm "
            f"across levels (paper {headlines.peak_reduction_nm} ± "
            f"{headlines.peak_reduction_std_nm} Nm); "
            f"RMS to settling {_fmt(mean_rms, 1)} % (paper {headlines.rms_reduction_pct} %)."
        )
    return "\n\n".join(parts)


def write_figures(out_dir: Path, fig_dir: Path, table: Any) -> list[Path]:
    """Draw Fig. 3-6 equivalents as PNG; returns the files written."""
    from myoexo.evaluation import figures

    fig_dir.mkdir(parents=True, exist_ok=True)
    labels = list(dict.fromkeys(table["controller"]))
    levels = sorted(set(int(v) for v in table["level"]))
    written = []

    def save(fig: Any, name: str) -> None:
        path = fig_dir / name
        fig.savefig(path, dpi=120)
        written.append(path)

    traces = {c: {lv: load_traces(out_dir, c, lv) for lv in levels} for c in labels}
    for label in labels:
        save(figures.plot_level_traces(traces[label], label), f"fig3_{controller_slug(label)}.png")
    save(figures.plot_controller_comparison(traces), "fig4_comparison.png")
    del traces
    save(figures.plot_rms_vs_settling(table), "fig5_rms_vs_settling.png")
    save(figures.plot_peak_boxplots(table), "fig6_peak_torque.png")
    return written


def write_report(
    out_dir: str | Path, report_dir: str | Path | None = None, bound_dir: str | Path | None = None
) -> Path:
    """Write figures, ``summary.csv`` and ``report.md`` for an evaluation folder.

    Args:
        out_dir: Folder written by :func:`myoexo.evaluation.evaluate`.
        report_dir: Where to write (default: ``out_dir``).
        bound_dir: An evaluation folder of the oracle (same root seed and twin) on some of
            the subjects: the report adds each controller's distance to it
            (:mod:`myoexo.evaluation.bound`). An oracle in ``out_dir`` itself is used too.

    Returns:
        Path of ``report.md``.

    Raises:
        ValueError: ``out_dir`` is not an evaluation folder.
    """
    out = Path(out_dir)
    config = load_config(out)
    table = load_table(out)
    if table.empty:
        raise ValueError(f"{str(out)!r} holds no episodes yet")
    dest = Path(report_dir) if report_dir is not None else out
    dest.mkdir(parents=True, exist_ok=True)
    fig_dir = dest / "figures"
    pngs = write_figures(out, fig_dir, table)

    summary = summarize(table)
    summary.to_csv(dest / "summary.csv", index=False)
    labels = list(dict.fromkeys(table["controller"]))
    reference = reference_controller(labels)
    red = {}
    if reference is not None:
        red = {c: reductions(table, reference, c) for c in labels if c != reference}

    cfg = config.get("config", {})
    n_per = table.groupby(["controller", "level"]).size()
    lines = [
        "# myoexo evaluation report",
        "",
        f"Evaluation folder: `{out.resolve()}`. {len(table)} episodes: controllers "
        f"{', '.join(f'`{c}`' for c in labels)}; levels {sorted(set(table.level))}; "
        f"{n_per.min()}-{n_per.max()} subjects per controller and level (paper: 1000). "
        "Subject *i* of a level is the same simulated person for every controller.",
        "",
        f"Metric definitions: [the evaluation protocol]({docs_url('evaluation')}), "
        "`myoexo.evaluation.metrics` (settling time in the 2 % band "
        "of the step, RMS of the interaction torque up to the settling time, peak "
        "interaction torque over the episode). Values are mean ± std over subjects.",
        "",
        "## Summary",
        "",
        _summary_section(summary),
        "",
        "## Next to the paper",
        "",
        "The study's numbers and how this project reads them: [the reference, section 5]("
        f"{docs_url('reference', '5-evaluation-protocol-and-the-papers-results')}).",
        "",
        _paper_section(summary, red, reference),
        "",
    ]
    if red and reference is not None:
        lines += [
            "## Reductions against the PID, per level",
            "",
            _reduction_section(red, reference),
            "",
        ]
    lines += _bound_section(table, out, bound_dir)
    lines += ["## Figures", ""]
    for png in pngs:
        rel = png.relative_to(dest)
        lines += [f"![{png.stem}]({rel.as_posix()})", ""]
    lines += [
        "## Configuration",
        "",
        "```json",
        json.dumps({k: config.get(k) for k in ("config", "controllers", "seed_rule")}, indent=2),
        "```",
        "",
        "## Versions",
        "",
        _md_table(["package", "version"], sorted(config.get("versions", {}).items())),
        "",
    ]
    try:
        twin = TwinOptions.from_dict(cfg.get("twin") or {})
    except ValueError:  # a plug-in reflex model this process has not imported
        twin = TwinOptions(task=tuple((cfg.get("twin") or {}).get("task", {}).items()))
        lines.insert(3, f"**Twin:** {json.dumps(cfg.get('twin'))}\n")
    if twin.episode_duration_s not in (None, 8.0):
        lines.insert(
            3, f"**Note:** episodes of {twin.episode_duration_s:g} s, not the paper's 8 s."
        )
    if twin.dynamics() != TwinOptions():
        lines.insert(3, f"**Twin:** {twin.dynamics().describe()} (not the default twin).\n")
    path = dest / "report.md"
    path.write_text("\n".join(lines))
    return path


def _bound_section(table: Any, out: Path, bound_dir: str | Path | None) -> list[str]:
    """The "distance to the achievable bound" section (empty without an oracle)."""
    import pandas as pd

    from myoexo.evaluation.bound import bound_label, bound_markdown

    both = table
    if bound_dir is not None:
        bound_cfg = load_config(Path(bound_dir)).get("run_key")
        if bound_cfg != load_config(out).get("run_key"):
            raise ValueError(
                f"{bound_dir} was run with other settings ({bound_cfg}) than {out}: "
                "its subjects are not the same persons"
            )
        both = pd.concat([table, load_table(Path(bound_dir))], ignore_index=True)
    if bound_label(both["controller"].unique()) is None:
        return []
    return [
        "## Distance to the achievable bound",
        "",
        "The oracle (`myoexo/control/oracle.py`) sees the true state and plans on a copy of "
        "the twin with the same 100 Nm motor; on the subjects it ran, each controller's mean "
        "absolute final error minus the oracle's, and the torque each one used.",
        "",
        bound_markdown(both),
        "",
    ]


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo report``."""
    parser.add_argument("dir", type=Path, help="evaluation folder (myoexo evaluate --out)")
    parser.add_argument(
        "--out", type=Path, default=None, help="where to write (default: the folder itself)"
    )
    parser.add_argument(
        "--bound",
        type=Path,
        default=None,
        metavar="DIR",
        help="evaluation folder of the oracle on some of the same subjects: adds each "
        "controller's distance to the achievable bound",
    )


def run(args: argparse.Namespace) -> int:
    """``myoexo report DIR``: 0 on success, 2 if DIR is not an evaluation folder."""
    try:
        path = write_report(args.dir, args.out, bound_dir=args.bound)
    except ValueError as exc:
        print(f"myoexo report: error: {exc}", file=sys.stderr)
        return 2
    print(f"report: {path}")
    return 0
