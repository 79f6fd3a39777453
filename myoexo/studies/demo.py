"""``myoexo demo`` (what ``make demo`` runs): the shipped controllers against the paper's PID.

The paper's evaluation protocol (:func:`myoexo.evaluation.evaluate`), small: the paper's PID
(``pid``), the same PID with its setpoint ramped over 1 s (``pid:ramp_s=1``), the impedance
controller at its defaults (``impedance``: a spring-damper on a 1 s minimum-jerk reference,
:mod:`myoexo.control.impedance`), the PID tracking a 0.6-s minimum-jerk reference
(``pid:reference=minjerk,ramp_s=0.6``), the learned correction on it (``residual``, trained on
twin version 3, at its default gentleness weight), the full-state learned policy ``sac``
(trained on an earlier twin) alone and with its
stall guard (``guard:sac``, :mod:`myoexo.control.guard`), and the deployable
``student_exo`` (the exoskeleton's own sensors with memory) alone and with its guard
(``guard:student_exo``), and the deployable students of ``residual`` distilled on the current
twin (``student_fine``, and ``student_knee`` with its fine-positioning layer, each at its
default gentleness weight), on
:data:`DEMO_SUBJECTS` subjects per spasticity level 0-3 (the protocol: 1000). Subject *i* of
a level is the same simulated person for every controller.

Prints one table (per level and controller: mean absolute final error, settled episodes,
settling time, peak interaction torque and its change from the paper's PID, RMS interaction
torque to settling) and ends with a paragraph of what the run found, computed from that
table (:func:`findings`), and the ``myoexo evaluate`` command of the full protocol. 220
episodes: well under a minute on 2 cores (the 200 of the ten controllers before
``student_knee`` took 23.9 s, ``make demo`` on a fresh clone). The episodes stay in the
output folder (default ``results/demo``; re-running reuses them); ``--report`` also writes
the figures and the Markdown report (:func:`~myoexo.evaluation.report.write_report`).

The achievable bound (the oracle MPC, spec ``oracle``) is not part of the demo: about 65 s of
a core per episode; ``myoexo evaluate --controllers oracle`` runs it.
"""

from __future__ import annotations

import argparse
import math
import re
import signal
import sys
import textwrap
import time
import warnings
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.envs.options import add_twin_arguments, twin_from_args
from myoexo.runtime.fields import Execution, add_options, check_fields, from_options, option

#: Subjects per spasticity level.
DEMO_SUBJECTS = 5
#: Controller specs of the demo (the paper's PID first: the reference).
DEMO_CONTROLLERS = (
    "pid",
    "pid:ramp_s=1",
    "pid:reference=minjerk,ramp_s=0.6",
    "impedance",
    "residual",
    "sac",
    "guard:sac",
    "student_exo",
    "guard:student_exo",
    "student_fine",
    "student_knee",
)
DEMO_OUT = Path("results") / "demo"
#: Band above the reference PID's mean absolute final error (deg) within which a controller
#: counts as tracking as well as the PID (the torque comparison of :func:`findings`).
TRACKING_BAND_DEG = 1.0
#: Width of the printed paragraph (characters).
TEXT_WIDTH = 92


@dataclass(frozen=True)
class DemoConfig:
    """What ``myoexo demo`` runs and where it writes (each field is an option of the
    command; the twin's options and :class:`~myoexo.runtime.fields.Execution`'s are its other
    options)."""

    subjects: int = option(DEMO_SUBJECTS, "subjects per level (the protocol: 1000)", low=1)
    controllers: tuple[str, ...] = option(
        DEMO_CONTROLLERS,
        "controller specs as for 'myoexo evaluate'; the paper's PID 'pid' (else the first PID) "
        "is the reference",
        metavar="SPEC",
    )
    out: Path = option(
        DEMO_OUT, "output folder; a second run reuses its episodes", folder=True, metavar="DIR"
    )
    report: bool = option(
        False,
        "write the figures and the Markdown report of the run into --out (adds about 15 s; "
        "'myoexo report DIR' writes them later)",
    )

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo demo``: :class:`DemoConfig`'s fields, the twin's options and
    :class:`~myoexo.runtime.fields.Execution`'s."""
    add_options(parser, DemoConfig)
    add_twin_arguments(parser)
    add_options(parser.add_argument_group("how to run"), Execution)


# ----------------------------------------------------------------------------- the table
def _deg(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.2f}"


def _nm(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.1f}"


def _s(value: float) -> str:
    return "n/a" if not math.isfinite(value) else f"{value:.2f}"


def _pct(value: float) -> str:
    return "-" if not math.isfinite(value) else f"{value:+.0f}"


def demo_rows(table: Any, controllers: Sequence[str]) -> Any:
    """Per level and controller (in the order of *controllers*, labels), from an episode
    table: ``n``, ``settled`` (episodes that settle), and the means ``abs_final_error_deg``,
    ``settling_time_s`` (settled episodes), ``peak_torque_nm``, ``rms_torque_nm``, and
    ``peak_vs_reference_pct`` (the peak's change from the reference PID's mean, in %; NaN for
    the reference itself or without one)."""
    from myoexo.evaluation.report import reference_controller
    from myoexo.evaluation.stats import summarize_episodes

    summary = summarize_episodes(table)
    abs_error_deg = table.groupby(["controller", "level"]).abs_final_error_deg.mean()
    summary["abs_final_error_deg"] = [
        float(abs_error_deg.loc[(c, lv)])
        for c, lv in zip(summary.controller, summary.level, strict=True)
    ]
    summary["settled"] = summary.n - summary.not_settled
    summary = summary.rename(
        columns={
            "settling_time_s_mean": "settling_time_s",
            "peak_interaction_torque_nm_mean": "peak_torque_nm",
            "rms_interaction_torque_nm_mean": "rms_torque_nm",
        }
    )
    order = {c: i for i, c in enumerate(controllers)}
    summary["_order"] = [order.get(c, len(order)) for c in summary.controller]
    rows = summary.sort_values(["level", "_order"], kind="stable").reset_index(drop=True)
    reference = reference_controller(list(dict.fromkeys(rows.controller)))
    ref_peak_nm = rows[rows.controller == reference].set_index("level").peak_torque_nm
    rows["peak_vs_reference_pct"] = [
        100.0 * (peak / ref_peak_nm[lv] - 1.0)
        if c != reference and lv in ref_peak_nm.index and ref_peak_nm[lv] > 0
        else math.nan
        for c, lv, peak in zip(rows.controller, rows.level, rows.peak_torque_nm, strict=True)
    ]
    columns = [
        "level",
        "controller",
        "n",
        "settled",
        "abs_final_error_deg",
        "settling_time_s",
        "peak_torque_nm",
        "peak_vs_reference_pct",
        "rms_torque_nm",
    ]
    return rows[columns]


def format_rows(rows: Any, reference: str | None) -> str:
    """The table of :func:`demo_rows` as text, one block per level."""
    width = max(10, *(len(c) for c in rows.controller))
    vs = f"vs {reference}" if reference else "vs PID"
    vs_width = max(7, len(vs))
    head = (
        f"{'level':>5}  {'controller':<{width}}  {'|final error|':>13}  {'settled':>7}  "
        f"{'settling':>8}  {'peak torque':>11}  {vs:>{vs_width}}  {'RMS torque':>10}"
    )
    units = (
        f"{'':>5}  {'':<{width}}  {'(deg)':>13}  {'':>7}  {'(s)':>8}  {'(Nm)':>11}  "
        f"{'(%)':>{vs_width}}  {'(Nm)':>10}"
    )
    lines = [head, units]
    level = None
    for r in rows.itertuples():
        if level is not None and r.level != level:
            lines.append("")
        level = r.level
        lines.append(
            f"{r.level:>5}  {r.controller:<{width}}  {_deg(r.abs_final_error_deg):>13}  "
            f"{f'{r.settled}/{r.n}':>7}  {_s(r.settling_time_s):>8}  "
            f"{_nm(r.peak_torque_nm):>11}  {_pct(r.peak_vs_reference_pct):>{vs_width}}  "
            f"{_nm(r.rms_torque_nm):>10}"
        )
    return "\n".join(lines)


# ----------------------------------------------------------------------------- the findings
def _and(items: Sequence[str]) -> str:
    items = list(items)
    if len(items) <= 1:
        return "".join(items)
    return f"{', '.join(items[:-1])} and {items[-1]}"


def _levels(levels: Sequence[int]) -> str:
    return f"level{'s' if len(levels) > 1 else ''} {_and([str(lv) for lv in levels])}"


def _best(
    rows: Any,
    column: str,
    fmt: Callable[[float], str],
    unit: str,
    reference: str | None,
    eligible: Callable[[Any], bool] = lambda r: True,
) -> str | None:
    """Who has the smallest *column* among the *eligible* rows at each level (ties at the
    printed precision listed together), grouped by winners, with the *reference*'s values
    where it is not a winner: ``"pid:ramp_s=1 at levels 0 and 1 (63.9 and 76.2 Nm vs pid's
    100.6 and 101.0)"``; ``None`` where no level has an eligible finite value."""
    groups: dict[tuple[str, ...], list[tuple[int, str, str | None]]] = {}
    for level in sorted(set(int(v) for v in rows.level)):
        at = rows[rows.level == level]
        ok = [r for r in at.itertuples() if eligible(r) and math.isfinite(getattr(r, column))]
        if not ok:
            continue
        best = min(float(fmt(getattr(r, column))) for r in ok)
        winners = tuple(r.controller for r in ok if float(fmt(getattr(r, column))) == best)
        ref = at[at.controller == reference]
        ref_text = (
            fmt(float(ref[column].iloc[0]))
            if reference is not None and reference not in winners and len(ref)
            else None
        )
        groups.setdefault(winners, []).append((level, fmt(best), ref_text))
    if not groups:
        return None
    parts = []
    for winners, found in groups.items():
        levels = [lv for lv, _, _ in found]
        values = f"{_and([v for _, v, _ in found])} {unit}"
        refs = [r for _, _, r in found]
        if all(r is not None for r in refs):
            values += f" vs {reference}'s {_and([str(r) for r in refs])}"
        elif any(r is not None for r in refs):
            values += ", " + ", ".join(
                f"{reference}'s {r} at level {lv}" for lv, _, r in found if r is not None
            )
        parts.append(f"{_and(winners)} at {_levels(levels)} ({values})")
    return "; ".join(parts)


def findings(
    rows: Any,
    reference: str | None,
    learned: Sequence[str],
    subjects: int,
    other_twin: Sequence[str] = (),
) -> str:
    """A paragraph of what the table of :func:`demo_rows` shows, from its numbers as printed:
    per level, which controller ended closest to the target (mean absolute final error);
    which had the lowest mean peak interaction torque among those within
    :data:`TRACKING_BAND_DEG` of the *reference* PID's error; which of the *learned*
    controllers ended closest (and whether some of them, *other_twin*, were trained on another
    twin); and the caveat of *subjects* subjects per level."""
    sentences = []
    these = f"these {subjects} subjects" if subjects != 1 else "this 1 subject"
    per_level = f"On {these} per level, the"
    tracking = _best(rows, "abs_final_error_deg", _deg, "deg", reference)
    if tracking:
        sentences.append(f"{per_level} smallest mean |final error| went to {tracking}.")
    if reference is not None:
        ref_error_deg = rows[rows.controller == reference].set_index("level").abs_final_error_deg

        def tracks(r: Any) -> bool:
            return r.level in ref_error_deg.index and (
                r.abs_final_error_deg <= ref_error_deg[r.level] + TRACKING_BAND_DEG
            )

        torque = _best(rows, "peak_torque_nm", _nm, "Nm", reference, tracks)
        if torque:
            sentences.append(
                "The lowest mean peak interaction torque among the controllers within "
                f"{TRACKING_BAND_DEG:g} deg of {reference}'s |final error| went to {torque}."
            )
    else:
        torque = _best(rows, "peak_torque_nm", _nm, "Nm", None)
        if torque:
            sentences.append(f"The lowest mean peak interaction torque went to {torque}.")
    learned = [c for c in learned if c in set(rows.controller)]
    if learned and len(learned) < len(set(rows.controller)):
        closest = _best(
            rows, "abs_final_error_deg", _deg, "deg", reference, lambda r: r.controller in learned
        )
        if closest:
            trained = (
                " (trained on another twin, see the note)"
                if any(c in other_twin for c in learned)
                else ""
            )
            sentences.append(
                f"The smallest |final error| of a learned controller{trained} went to {closest}."
            )
    sentences.append(
        f"Means of {subjects} subject{'s' if subjects != 1 else ''} without intervals show a "
        "direction, not a result; for the full protocol (1000 subjects per level, 95 % "
        "intervals in its report), run:"
    )
    return textwrap.fill(" ".join(sentences), TEXT_WIDTH, break_on_hyphens=False)


# ----------------------------------------------------------------------------- the run
_MISMATCH = re.compile(r"^myoexo evaluate: warning: controller '(?P<spec>[^']+)' was (?P<what>.+)$")


def _notes(messages: Sequence[str]) -> tuple[list[str], list[str]]:
    """The evaluation's messages for the demo's output (the controllers trained on another
    twin in one line per difference) and the specs of those controllers."""
    lines: list[str] = []
    by_what: dict[str, list[str]] = {}
    for message in messages:
        found = _MISMATCH.match(message)
        if found:
            by_what.setdefault(found["what"], []).append(found["spec"])
        else:
            lines.append(message.replace("myoexo evaluate:", "myoexo demo:", 1))
    for what, specs in by_what.items():
        lines.append(f"note: {_and(specs)} {'was' if len(specs) == 1 else 'were'} {what}")
    return lines, [s for specs in by_what.values() for s in specs]


def run(args: argparse.Namespace) -> int:
    """Run the demo: evaluate, print the table and the findings, write the report; 0 on
    success (a bad option is a ``ValueError``: one line, exit status 2)."""
    from myoexo.control.specs import CLASSICAL_KINDS, parse_controller_spec
    from myoexo.evaluation import EvaluationConfig, available_cores, evaluate
    from myoexo.evaluation.engine import TwinMismatchWarning
    from myoexo.evaluation.report import reference_controller, write_report

    demo = from_options(DemoConfig, args)
    execution = from_options(Execution, args)
    workers = execution.workers or available_cores()
    specs = [parse_controller_spec(text) for text in demo.controllers]
    config = EvaluationConfig(
        controllers=demo.controllers, subjects=demo.subjects, twin=twin_from_args(args)
    )
    levels = f"{min(config.levels)}-{max(config.levels)}"
    print(
        f"myoexo demo: {len(specs)} controllers ({' '.join(demo.controllers)}) x "
        f"{demo.subjects} subjects x levels {levels} on {workers} worker(s) -> {demo.out}"
    )
    t0 = time.perf_counter()
    messages: list[str] = []
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", TwinMismatchWarning)  # logged, shown once below
        result = evaluate(
            config, demo.out, workers=workers, progress=execution.progress, log=messages.append
        )
    if result.stopped_by is not None:
        from myoexo.runtime.lifecycle import signal_exit_status

        print(
            f"myoexo demo: stopped by {result.stopped_by}: {result.stored} of {result.total} "
            f"episodes stored in {result.out_dir}; run the same command again to continue",
            file=sys.stderr,
        )
        return signal_exit_status(signal.Signals[result.stopped_by])
    elapsed_s = time.perf_counter() - t0
    print(
        f"{len(result.table)} episodes ({result.computed} computed now) in {elapsed_s:.0f} s: "
        f"{result.out_dir / 'episodes.csv'}"
    )
    if demo.report:
        report = write_report(result.out_dir)
        print(f"figures and the Markdown report: {report}")
    else:
        print(f"figures and the Markdown report: myoexo report {result.out_dir}")

    notes, other_twin = _notes(messages)
    ran = set(result.table.controller)
    labels = [s.label for s in specs if s.label in ran]
    reference = reference_controller(labels)
    rows = demo_rows(result.table, labels)
    learned = [s.label for s in specs if s.kind not in CLASSICAL_KINDS and s.label in ran]
    print()
    for line in notes:
        print(line)
    if notes:
        print()
    print(format_rows(rows, reference))
    print()
    print(findings(rows, reference, learned, demo.subjects, other_twin))
    command = f"  myoexo evaluate --controllers {' '.join(demo.controllers)} --report"
    if result.computed:
        full_h = elapsed_s / result.computed * 1000 * len(config.levels) * len(labels) / 3600
        command += f"   # ~{full_h:.1f} h at this run's pace"
    print(command)
    return 0
