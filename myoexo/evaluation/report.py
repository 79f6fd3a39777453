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
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.specs import controller_slug
from myoexo.envs.options import TwinOptions
from myoexo.evaluation.config import load_config
from myoexo.evaluation.criteria import verdict
from myoexo.evaluation.paper import PAPER_HEADLINES, PAPER_RESULTS
from myoexo.evaluation.stats import (
    FAILURE_DEG,
    HEADLINE_LEVELS,
    INTERVAL_METHOD,
    SUMMARY_METRICS,
    catastrophic_lines,
    headline,
    pool_seed_groups,
    reductions,
    summarize_episodes,
    tail_risk,
)
from myoexo.evaluation.storage import load_table, load_traces
from myoexo.runtime.docs import docs_url
from myoexo.runtime.fields import add_options, add_positional, check_fields, from_options, option


def reference_controller(labels: Sequence[str]) -> str | None:
    """The PID the others are compared with: ``pid`` if present, else the first PID-like."""
    if "pid" in labels:
        return "pid"
    return next((c for c in labels if c.lower().startswith("pid")), None)


# ----------------------------------------------------------------------------- markdown
def fmt_num(x: Any, digits: int = 2) -> str:
    """*x* with *digits* decimals; ``"n/a"`` if not finite, ``"-"`` for ``None``."""
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
    if not math.isfinite(std):
        return f"{mean:.{digits}f}"
    return f"{mean:.{digits}f} ± {std:.{digits}f}"


def _md_table(headers: Sequence[str], rows: Sequence[Sequence[Any]]) -> str:
    """A Markdown table (pandas ``to_markdown``) of pre-formatted cells."""
    import pandas as pd

    frame = pd.DataFrame([[str(cell) for cell in row] for row in rows], columns=list(headers))
    return str(frame.to_markdown(index=False, disable_numparse=True))


def _summary_section(summary: Any) -> str:
    """The summary table; a metric no episode has (an older table's) is left out."""
    metrics = [c for c in SUMMARY_METRICS if np.isfinite(summary[f"{c}_mean"]).any()]
    headers = ["controller", "level", "n", *(SUMMARY_METRICS[c] for c in metrics)]
    headers += ["unstable", "not settled"]
    rows = []
    for _, stats in summary.iterrows():
        cells = [stats.controller, stats.level, stats.n]
        for col in metrics:
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
                    fmt_num(paper.sac_settling_time_s),
                    _pm(ours.final_error_deg_mean, ours.final_error_deg_std),
                    paper.sac_final_error_text,
                    fmt_num(rms, 1),
                    fmt_num(paper.rms_reduction_pct, 1),
                    fmt_num(peak, 1),
                    fmt_num(paper.peak_reduction_pct, 1),
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


def fmt_ci(value: float, low: float, high: float, digits: int = 1) -> str:
    """``value [low, high]`` (*value* alone without a finite interval; ``"n/a"``)."""
    if not math.isfinite(value):
        return "n/a"
    if not (math.isfinite(low) and math.isfinite(high)):
        return fmt_num(value, digits)
    return f"{value:.{digits}f} [{low:.{digits}f}, {high:.{digits}f}]"


def _reduction_section(
    red: dict[str, Any], reference: str, headlines: dict[str, dict[str, Any]]
) -> str:
    parts = []
    paper = PAPER_HEADLINES
    for other, rdf in red.items():
        rows = [
            [
                int(r.level),
                int(r.n_paired),
                fmt_ci(r.rms_reduction_pct, r.rms_reduction_pct_low, r.rms_reduction_pct_high),
                _pm(r.rms_paired_diff_nm_mean, r.rms_paired_diff_nm_std),
                fmt_ci(r.peak_reduction_pct, r.peak_reduction_pct_low, r.peak_reduction_pct_high),
                _pm(r.peak_paired_diff_nm_mean, r.peak_paired_diff_nm_std),
                fmt_ci(r.settling_ratio, r.settling_ratio_low, r.settling_ratio_high, 2),
                f"{r.reference_settled_pct:.0f} / {r.other_settled_pct:.0f}",
            ]
            for r in rdf.itertuples()
        ]
        lines = [
            f"**`{other}` vs `{reference}`** (paired: same subjects; [95 % interval] over "
            f"{int(rdf.seeds.max())} seed(s) and the subjects: {INTERVAL_METHOD})\n\n"
            + _md_table(
                [
                    "level",
                    "pairs",
                    "RMS reduction %",
                    "RMS paired diff (Nm)",
                    "peak reduction %",
                    "peak paired diff (Nm)",
                    "settling time ratio (both settled)",
                    f"settled % ({reference} / {other})",
                ],
                rows,
            )
        ]
        study, every = headlines[other]["study"], headlines[other]["all"]
        peak_v = verdict(study["peak_low"], study["peak_high"], paper.peak_reduction_pct)
        rms_v = verdict(study["rms_low"], study["rms_high"], paper.rms_reduction_pct)
        study_text = (
            f"Mean over levels {'-'.join(map(str, study['levels']))} (the study's "
            "aggregation): peak torque "
            f"{fmt_ci(study['peak'], study['peak_low'], study['peak_high'])}"
            f" % (paper {paper.peak_reduction_pct} %: {peak_v}), RMS to settling "
            f"{fmt_ci(study['rms'], study['rms_low'], study['rms_high'])} % (paper "
            f"{paper.rms_reduction_pct} %: {rms_v})"
            if tuple(study["levels"]) == HEADLINE_LEVELS
            else f"Levels {'-'.join(map(str, HEADLINE_LEVELS))} (the study's aggregation) "
            "were not all run"
        )
        lines.append(
            f"{study_text}; over every level run ({', '.join(map(str, every['levels']))}): peak "
            f"{fmt_ci(every['peak'], every['peak_low'], every['peak_high'])} %, RMS "
            f"{fmt_ci(every['rms'], every['rms_low'], every['rms_high'])} %. A criterion is met "
            "when its whole interval is on the good side of the paper's number, missed when "
            "it is wholly on the other, a tie otherwise."
        )
        parts.append("\n\n".join(lines))
    return "\n\n".join(parts)


def _risk_section(risk: Any) -> str:
    headers = [
        "controller", "level", "n", "worst subject", "worst |final error| (deg)",
        "p95 (deg)", "p99 (deg)", f"beyond {FAILURE_DEG:g} deg", "limit (deg)",
        "catastrophic", "unstable",
    ]  # fmt: skip
    rows = [
        [
            r.controller,
            r.level,
            r.n,
            r.worst_subject,
            fmt_num(r.worst_abs_final_error_deg),
            fmt_num(r.p95_abs_final_error_deg),
            fmt_num(r.p99_abs_final_error_deg),
            r.failures,
            fmt_num(r.limit_deg, 1),
            r.catastrophic,
            r.unstable,
        ]
        for r in risk.itertuples()
    ]
    return _md_table(headers, rows)


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

    table = pool_seed_groups(table)  # a seed group's checkpoints: one controller
    summary = summarize_episodes(table)
    summary.to_csv(dest / "summary.csv", index=False)
    labels = list(dict.fromkeys(table["controller"]))
    reference = reference_controller(labels)
    red = {}
    heads: dict[str, dict[str, Any]] = {}
    if reference is not None:
        red = {c: reductions(table, reference, c) for c in labels if c != reference}
        levels_run = sorted(int(v) for v in set(table.level))
        study_levels = [lv for lv in HEADLINE_LEVELS if lv in levels_run]
        heads = {
            c: {
                "study": headline(table, reference, c, study_levels),
                "all": headline(table, reference, c, levels_run),
            }
            for c in red
        }
    risk = tail_risk(table, reference)
    risk.to_csv(dest / "tail_risk.csv", index=False)
    flagged = catastrophic_lines(risk)

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
        *(
            [
                "**Catastrophic subjects** (an episode that ends beyond "
                f"{FAILURE_DEG:g} deg from the target or beyond the reference PID's own worst "
                "on the same subjects, whichever is larger):",
                "",
                *[f"- {line}" for line in flagged],
                "",
            ]
            if flagged
            else []
        ),
        "## Summary",
        "",
        _summary_section(summary),
        "",
        "## Tail risk",
        "",
        "The tail of the absolute final error per controller and level: the worst subject, "
        f"the 95th and 99th percentiles, the episodes that end beyond {FAILURE_DEG:g} deg, "
        "the catastrophic bound (that or the reference PID's worst at the level, whichever "
        "is larger) and the episodes beyond it, and the unstable episodes (counted as the "
        "worst).",
        "",
        _risk_section(risk),
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
            _reduction_section(red, reference, heads),
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
@dataclass(frozen=True)
class ReportConfig:
    """What ``myoexo report`` writes (``dir`` is its positional argument, the other fields
    its options)."""

    dir: Path = option(doc="evaluation folder (myoexo evaluate --out)", flag="", metavar="DIR")
    out: Path | None = option(
        None, "where to write (default: the folder itself)", folder=True, metavar="DIR"
    )
    bound: Path | None = option(
        None,
        "evaluation folder of the oracle on some of the same subjects: adds each controller's "
        "distance to the achievable bound (default: none)",
        metavar="DIR",
    )

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo report``: :class:`ReportConfig`'s fields."""
    add_positional(parser, ReportConfig, "dir")
    add_options(parser, ReportConfig)


def run(args: argparse.Namespace) -> int:
    """``myoexo report DIR``: 0 on success; a DIR that is not an evaluation folder is a
    user error (one line, exit status 2)."""
    config = from_options(ReportConfig, args, dir=args.dir)
    path = write_report(config.dir, config.out, bound_dir=config.bound)
    print(f"report: {path}")
    return 0
