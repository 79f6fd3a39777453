"""Result sets: the small files every results table of the docs is generated from.

A *result set* is a folder of small CSV files computed from one evaluation folder
(``myoexo results collect EVAL_DIR NAME``): ``summary.csv`` (mean, std, quantiles per
controller and level, :func:`~myoexo.evaluation.report.summarize`), ``tail_risk.csv``
(:func:`~myoexo.evaluation.risk.tail_risk`), ``reductions.csv`` (each controller against the
PID on the same subjects, with intervals, :func:`~myoexo.evaluation.report.reductions`),
``headline.csv`` (the study's levels 1-2 aggregation and the mean over every level run) and
``meta.json`` (the command that produced the evaluation, its twin, subjects and root seed,
and the package versions). Result sets are committed under ``docs/results/``.

``myoexo results tables`` renders each set's Markdown tables into ``tables.md`` beside its
files (the docs include it) and the short tables of the README and the model cards between
their markers (:data:`BLOCKS`); ``--check`` fails where a committed table differs from what
the files give, so no results table is typed by hand.

A ``myoexo seeds`` folder's checkpoints are one controller of a set, named after the folder
(:func:`~myoexo.evaluation.report.seed_groups`): its means, tails and intervals are over the
seeds and the subjects.
"""

from __future__ import annotations

import argparse
import json
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.envs.options import TwinOptions
from myoexo.evaluation.config import EVALUATION_ROOT_SEED, load_config
from myoexo.evaluation.paper import PAPER_HEADLINES, PAPER_RESULTS
from myoexo.evaluation.report import (
    HEADLINE_LEVELS,
    fmt_ci,
    fmt_num,
    headline,
    reductions,
    reference_controller,
    seed_groups,
    summarize,
)
from myoexo.evaluation.risk import FAILURE_DEG, INTERVAL_METHOD, tail_risk, verdict
from myoexo.evaluation.storage import load_table
from myoexo.runtime.files import write_json_atomic

#: Where the committed result sets live, relative to the repository root.
RESULTS_DIR = Path("docs") / "results"
#: The rendered tables of a set.
TABLES_FILE = "tables.md"


@dataclass(frozen=True)
class Block:
    """A generated results block in a file outside the result sets (the README, a model
    card): the headline table of each of *controllers* from the set *result_set*, between
    the lines :attr:`start` and :attr:`end`.

    Attributes:
        path: The file, relative to the repository root.
        result_set: The set's folder name under :data:`RESULTS_DIR`.
        controllers: Controllers (or seed groups) of the set, in order.
    """

    path: str
    result_set: str
    controllers: tuple[str, ...]

    def _marker(self, edge: str) -> str:
        return f"<!-- myoexo-results:{self.result_set}:{','.join(self.controllers)}:{edge} -->"

    @property
    def start(self) -> str:
        return self._marker("start")

    @property
    def end(self) -> str:
        return self._marker("end")


#: Every generated block outside the result sets' own ``tables.md``.
BLOCKS: tuple[Block, ...] = (
    Block("README.md", "eval_500", ("guard:sac",)),
    Block("README.md", "eval_seeds_100", ("sac_5seeds",)),
    Block("myoexo/policies/MODEL_CARD.md", "eval_500", ("sac", "guard:sac")),
    Block("myoexo/policies/MODEL_CARD.md", "eval_200_perturbed", ("guard:sac",)),
    Block("myoexo/policies/MODEL_CARD.md", "eval_seeds_100", ("sac_5seeds",)),
    Block("myoexo/policies/MODEL_CARD_student_exo.md", "eval_500", ("student_exo",)),
    Block("myoexo/policies/MODEL_CARD_student_exo.md", "eval_200_perturbed", ("student_exo",)),
    Block("myoexo/policies/MODEL_CARD_sac_exo.md", "eval_100_perturbed", ("sac_exo",)),
)

_FILES = ("summary.csv", "tail_risk.csv", "reductions.csv", "headline.csv", "meta.json")


#: A controller spec of a ``myoexo seeds`` folder's checkpoint (what ``--seeds-dir`` adds).
_SEED_CHECKPOINT = re.compile(r"(?:\w+:)?(?P<dir>.+)/seed_\d+/checkpoints/step_\d+/model\.zip")


def command_of(config: dict[str, Any]) -> str:
    """The ``myoexo evaluate`` command line of an evaluation's ``config.json``."""
    cfg = config.get("config", {})
    controllers, seeds_dirs = [], []
    for spec in map(str, cfg.get("controllers", [])):
        m = _SEED_CHECKPOINT.fullmatch(spec)
        if m is None:
            controllers.append(spec)
        elif m.group("dir") not in seeds_dirs:
            seeds_dirs.append(m.group("dir"))  # --seeds-dir added the folder's checkpoints
    parts = ["myoexo evaluate", "--controllers", *controllers]
    if seeds_dirs:
        parts += ["--seeds-dir", *seeds_dirs]
    parts += ["--levels", *map(str, cfg.get("levels", [])), "--subjects", str(cfg.get("subjects"))]
    if cfg.get("root_seed", 0) != 0:
        parts += ["--seed", str(cfg["root_seed"])]
    twin = TwinOptions.from_dict(cfg.get("twin") or {})
    for key, value in twin.task:
        parts += ["--set", f"{key}={value:g}"]
    if twin.reflex != TwinOptions().reflex:
        parts += ["--reflex", twin.reflex]
    if twin.robustness:
        parts.append("--robustness")
    return " ".join(parts)


def collect(eval_dir: str | Path, dest: str | Path) -> Path:
    """Write the result set of the evaluation folder *eval_dir* into *dest* (created).

    Raises:
        ValueError: *eval_dir* is no evaluation folder, holds no episodes, or no PID.
    """
    import pandas as pd

    config = load_config(eval_dir)
    table = seed_groups(load_table(eval_dir))
    if table.empty:
        raise ValueError(f"{str(eval_dir)!r} holds no episodes yet")
    cfg = config.get("config", {})
    if cfg.get("selection") or int(cfg.get("root_seed", 0)) != EVALUATION_ROOT_SEED:
        raise ValueError(
            f"{str(eval_dir)!r} ran on root seed {cfg.get('root_seed')}"
            f"{' as a selection run' if cfg.get('selection') else ''}: a result set holds "
            f"evaluations on the evaluation root {EVALUATION_ROOT_SEED} only (numbers on other "
            "roots are in-sample)"
        )
    labels = list(dict.fromkeys(table["controller"]))
    reference = reference_controller(labels)
    if reference is None:
        raise ValueError(f"{str(eval_dir)!r} has no PID to compare with")
    dest = Path(dest)
    dest.mkdir(parents=True, exist_ok=True)
    summarize(table).to_csv(dest / "summary.csv", index=False)
    tail_risk(table, reference).to_csv(dest / "tail_risk.csv", index=False)
    others = [c for c in labels if c != reference]
    red = [reductions(table, reference, c).assign(controller=c) for c in others]
    pd.concat(red, ignore_index=True).to_csv(dest / "reductions.csv", index=False)
    levels = sorted(int(v) for v in set(table.level))
    heads = []
    for c in others:
        for scope, scope_levels in (
            ("study", [lv for lv in HEADLINE_LEVELS if lv in levels]),
            ("all", levels),
        ):
            h = headline(table, reference, c, scope_levels)
            h["levels"] = ", ".join(map(str, scope_levels))
            heads.append({"controller": c, "scope": scope, **h})
    pd.DataFrame(heads).to_csv(dest / "headline.csv", index=False)
    meta = {
        "command": command_of(config),
        "reference": reference,
        "subjects_per_level": int(cfg.get("subjects", 0)),
        "root_seed": int(cfg.get("root_seed", 0)),
        "twin": cfg.get("twin"),
        "episodes": len(table),
        "versions": config.get("versions", {}),
    }
    write_json_atomic(dest / "meta.json", meta, indent=2)
    return dest


# ----------------------------------------------------------------------------- rendering
def _ci_of(row: Any, name: str, digits: int = 1) -> str:
    """:func:`_ci` of the columns ``name``, ``name_low`` and ``name_high`` of *row*."""
    return fmt_ci(row[name], row[f"{name}_low"], row[f"{name}_high"], digits)


def _md(headers: list[str], rows: list[list[str]]) -> str:
    lines = ["| " + " | ".join(headers) + " |", "|" + "---|" * len(headers)]
    lines += ["| " + " | ".join(row) + " |" for row in rows]
    return "\n".join(lines)


def _read(folder: Path) -> tuple[Any, Any, Any, Any, dict[str, Any]]:
    import pandas as pd

    missing = [f for f in _FILES if not (folder / f).is_file()]
    if missing:
        raise ValueError(f"{str(folder)!r} is no result set: it lacks {missing}")
    return (
        pd.read_csv(folder / "summary.csv"),
        pd.read_csv(folder / "tail_risk.csv"),
        pd.read_csv(folder / "reductions.csv"),
        pd.read_csv(folder / "headline.csv", dtype={"levels": str}),
        json.loads((folder / "meta.json").read_text()),
    )


def _judged(row: Any, name: str, target: float | None, higher: bool, digits: int = 1) -> str:
    """``value [low, high]`` and, against *target*, the verdict by the interval."""
    cell = _ci_of(row, name, digits)
    if target is None:
        return cell
    call = verdict(row[f"{name}_low"], row[f"{name}_high"], target, higher_is_better=higher)
    return f"{cell} ({'>=' if higher else '<'} {target:g}: {call})"


def headline_table(folder: str | Path, controller: str) -> str:
    """The short table of one controller against the PID (the README's): per level its mean
    absolute final error, peak and RMS reductions and settling ratio, each with its interval
    and its verdict against the study's per-level claim, and the tail."""
    summary, risk, red, _, meta = _read(Path(folder))
    ref = meta["reference"]
    s = summary.set_index(["controller", "level"])
    k = risk.set_index(["controller", "level"])
    r = red[red.controller == controller].set_index("level")
    rows = []
    for level in sorted(r.index):
        paper = PAPER_RESULTS[int(level)]
        row = r.loc[level]
        rows.append(
            [
                str(level),
                str(int(row.seeds)) if "seeds" in row else "1",
                _judged(row, "abs_final_error_deg", paper.sac_final_error_bound_deg, False, 2),
                fmt_num(s.loc[(ref, level), "final_error_deg_mean"]),
                f"{fmt_num(k.loc[(ref, level), 'worst_abs_final_error_deg'], 1)} / "
                f"{fmt_num(k.loc[(controller, level), 'worst_abs_final_error_deg'], 1)}",
                str(int(k.loc[(controller, level), "catastrophic"])),
                _judged(row, "peak_reduction_pct", paper.peak_reduction_pct, True),
                _judged(row, "rms_reduction_pct", paper.rms_reduction_pct, True),
                _judged(row, "settling_ratio", 1.0, False, 2),
                f"{row.reference_settled_pct:.0f} / {row.other_settled_pct:.0f}",
            ]
        )
    return _md(
        [
            "level",
            "seeds",
            f"{controller} abs final error (deg) [95 % CI] (paper)",
            f"{ref} final error (deg)",
            f"worst subject (deg): {ref} / {controller}",
            "catastrophic subjects",
            "peak reduction % (paper)",
            "RMS reduction % (paper)",
            f"settling time / {ref}'s (faster than the PID)",
            "settled %",
        ],
        rows,
    )


def aggregation_lines(folder: str | Path) -> list[str]:
    """One line per controller: the study's levels 1-2 aggregation with its verdicts, and
    the mean over every level run."""
    _, _, _, heads, meta = _read(Path(folder))
    paper = PAPER_HEADLINES
    lines = []
    for controller, h in heads.groupby("controller", sort=False):
        study = h[h.scope == "study"].iloc[0]
        every = h[h.scope == "all"].iloc[0]
        peak_v = verdict(study.peak_low, study.peak_high, paper.peak_reduction_pct)
        rms_v = verdict(study.rms_low, study.rms_high, paper.rms_reduction_pct)
        lines.append(
            f"`{controller}` vs `{meta['reference']}`, mean over levels {study.levels} (the "
            f"study's aggregation): peak {fmt_ci(study.peak, study.peak_low, study.peak_high)} % "
            f"(paper {paper.peak_reduction_pct} %: {peak_v}), RMS "
            f"{fmt_ci(study.rms, study.rms_low, study.rms_high)} % (paper "
            f"{paper.rms_reduction_pct} %: {rms_v}); over levels {every.levels}: peak "
            f"{fmt_ci(every.peak, every.peak_low, every.peak_high)} %, RMS "
            f"{fmt_ci(every.rms, every.rms_low, every.rms_high)} %."
        )
    return lines


def render(folder: str | Path, label: str | None = None) -> str:
    """The Markdown of a result set: provenance (*label*: how the set's folder is named in
    it, default its path), one table per controller, the study's aggregation, the tail."""
    folder = Path(folder)
    _, risk, red, _, meta = _read(folder)
    versions = ", ".join(f"{k} {v}" for k, v in sorted(meta.get("versions", {}).items()))
    parts = [
        f"<!-- generated by `myoexo results tables` from {label or folder.as_posix()}: do not "
        "edit -->",
        f"Command: `{meta['command']}` ({meta['subjects_per_level']} subjects per level, root "
        f"seed {meta['root_seed']}, {meta['episodes']} episodes; {versions}). A `myoexo "
        "seeds` folder's checkpoints are one controller named after the folder: its numbers "
        "are over the seeds and the subjects. Intervals: "
        f"{INTERVAL_METHOD}. A criterion is met when its whole interval is on the good side "
        "of the paper's number, missed when wholly on the other, a tie otherwise.",
    ]
    for controller in dict.fromkeys(red.controller):
        parts.append(f"**`{controller}`** against `{meta['reference']}` on the same subjects:")
        parts.append(headline_table(folder, controller))
    parts.append("\n".join(f"- {line}" for line in aggregation_lines(folder)))
    rows = [
        [
            str(r.controller),
            str(r.level),
            fmt_num(r.worst_abs_final_error_deg, 1),
            str(r.worst_subject),
            fmt_num(r.p95_abs_final_error_deg),
            fmt_num(r.p99_abs_final_error_deg),
            str(r.failures),
            fmt_num(r.limit_deg, 1),
            str(r.catastrophic),
            str(r.unstable),
        ]
        for r in risk.itertuples()
    ]
    parts.append(
        f"Tail of the absolute final error (beyond {FAILURE_DEG:g} deg: failures; catastrophic: "
        "beyond that or the PID's own worst, whichever is larger):"
    )
    parts.append(
        _md(
            [
                "controller",
                "level",
                "worst (deg)",
                "worst subject",
                "p95 (deg)",
                "p99 (deg)",
                f"beyond {FAILURE_DEG:g} deg",
                "limit (deg)",
                "catastrophic",
                "unstable",
            ],
            rows,
        )
    )
    return "\n\n".join(parts) + "\n"


def block_text(root: Path, block: Block) -> str:
    """The text of a generated block, its markers included."""
    folder = root / RESULTS_DIR / block.result_set
    _, _, red, _, meta = _read(folder)
    missing = [c for c in block.controllers if c not in set(red.controller)]
    if missing:
        raise ValueError(f"{block.path}: the result set {block.result_set!r} has no {missing}")
    lines = [block.start]
    aggregation = aggregation_lines(folder)
    for controller in block.controllers:
        lines += [
            f"**`{controller}`** against `{meta['reference']}` on the same subjects:",
            "",
            headline_table(folder, controller),
            "",
            *(f"- {line}" for line in aggregation if line.startswith(f"`{controller}`")),
            "",
        ]
    robust = " perturbed twins," if (meta.get("twin") or {}).get("robustness") else ""
    lines += [
        f"({meta['subjects_per_level']} evaluation subjects per level,{robust} root seed "
        f"{meta['root_seed']}; generated by `myoexo results tables` from "
        f"`{RESULTS_DIR.as_posix()}/{block.result_set}`.)",
        block.end,
    ]
    return "\n".join(lines)


def write_tables(root: Path, check: bool = False, blocks: Sequence[Block] = BLOCKS) -> list[str]:
    """Render every result set under ``root/docs/results`` and every generated block of
    *blocks*; with *check*, write nothing and return the files that differ from what they
    should hold.

    Raises:
        ValueError: A folder is no result set, a block's file lacks its markers, or its set
            or controller does not exist.
    """
    stale = []
    for folder in sorted(p for p in (root / RESULTS_DIR).iterdir() if p.is_dir()):
        text = render(folder, (RESULTS_DIR / folder.name).as_posix())
        path = folder / TABLES_FILE
        if not path.is_file() or path.read_text() != text:
            stale.append(str(path.relative_to(root)))
            if not check:
                path.write_text(text)
    for block in blocks:
        path = root / block.path
        text = path.read_text()
        if block.start not in text or block.end not in text:
            raise ValueError(f"{block.path} lacks the markers {block.start} ... {block.end}")
        head, rest = text.split(block.start, 1)
        _, tail = rest.split(block.end, 1)
        new = head + block_text(root, block) + tail
        if new != text:
            if block.path not in stale:
                stale.append(block.path)
            if not check:
                path.write_text(new)
    return stale


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo results``."""
    sub = parser.add_subparsers(dest="action", required=True, metavar="ACTION")
    c = sub.add_parser("collect", help="write the result set of an evaluation folder")
    c.add_argument("eval_dir", type=Path, help="a myoexo evaluate output folder")
    c.add_argument("name", help=f"the set's name: its folder under {RESULTS_DIR}")
    c.add_argument("--root", type=Path, default=Path("."), help="repository root (default: .)")
    t = sub.add_parser("tables", help="render every result set's tables and the front page's")
    t.add_argument("--root", type=Path, default=Path("."), help="repository root (default: .)")
    t.add_argument("--check", action="store_true", help="write nothing; exit 1 if a table is stale")


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo results``."""
    if args.action == "collect":
        dest = collect(args.eval_dir, args.root / RESULTS_DIR / args.name)
        print(f"result set: {dest}")
        return 0
    stale = write_tables(args.root, check=args.check)
    verb = "stale" if args.check else "written"
    for path in stale:
        print(f"{verb}: {path}")
    return 1 if (args.check and stale) else 0
