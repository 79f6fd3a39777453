"""Several seeds of one training configuration: trained in parallel, aggregated with their
uncertainty.

    myoexo policy seeds train runs/sbx5 --seeds 0 1 2 3 4 --algorithm sbx_sac --workers 2
    myoexo policy seeds train runs/sbx5                   # again: resumes every unfinished seed
    myoexo policy seeds aggregate runs/sbx5 --subjects 10
    myoexo policy seeds ship runs/sbx5 --name sac         # the chosen seed into the package
    myoexo policy seeds compare runs/algos/* --out results/algorithms   # several configurations

``train`` runs one ``myoexo policy train`` process per seed (``--workers`` at a time), each in its
own run folder ``DIR/seed_<N>`` with its own checkpoints, so each seed is resumable on its own
(running the same command again resumes the unfinished ones); ``DIR/seeds.json`` records the
configuration (the training config of ``myoexo policy train``'s options, read by each new
seed's ``--config``). SIGTERM / SIGINT are passed on to the running seeds, which checkpoint
and stop.

``aggregate`` selects each seed's checkpoint on the selection subjects (root seed
:data:`~myoexo.evaluation.config.SELECTION_ROOT_SEED`, as ``myoexo policy select``), then reports
per level, over seeds: the mean, the interquartile mean and a bootstrap 95 % confidence
interval (``scipy.stats.bootstrap``, percentile method, resampling seeds; per level, so the
levels are the strata) of the final error, the peak and RMS reductions against the PID and the
settling time, and the fraction of seeds whose level passes the acceptance criteria
(:func:`myoexo.evaluation.criteria.compare_with_pid`; a Wilson 95 % interval):
:func:`myoexo.evaluation.stats.summarize_seeds`. It names the seed to
ship by a rule that does not pick the luckiest one: the seed closest to the aggregate (the
smallest sum over levels and metrics of its distance to the across-seed mean, each metric
divided by its across-seed spread). Files: ``aggregate_seeds.csv`` (one row per seed and
level), ``aggregate.csv`` / ``aggregate.md`` (the summary), ``aggregate.json`` (the chosen
seed and checkpoints), ``seeds_spread.png``.

``compare`` puts several aggregated folders side by side (e.g. algorithms trained on the same
wall-clock budget, ``--max-wall-time-s ...``): per configuration, the mean over seeds of
the training wall time, env steps, env steps/s and gradient updates/s, and per level the
final error and peak reduction (mean [95 % CI]) and the share of seeds passing the criteria.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import os
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.evaluation.config import SELECTION_ROOT_SEED, check_fit_root
from myoexo.evaluation.stats import summarize_seeds
from myoexo.policies.run_files import AGGREGATE_FILE
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    add_positional,
    check_fields,
    from_options,
    option,
)
from myoexo.runtime.files import write_json_atomic, write_text_atomic
from myoexo.runtime.lifecycle import FolderLock, StopSignals, process_map, signal_exit_status
from myoexo.spasticity.levels import VALID_LEVELS
from myoexo.training import checkpoints as ck
from myoexo.training.cli import add_config_arguments
from myoexo.training.config import TrainConfig, config_from_record
from myoexo.training.select import SelectionConfig, select_with

#: Configuration file of a seeds folder.
SEEDS_FILE = "seeds.json"
#: Per-seed metrics aggregated (column of the per-seed table -> what it is).
AGGREGATED: dict[str, str] = {
    "abs_final_error_deg": "|final error| (deg)",
    "peak_reduction_pct": "peak interaction torque reduction vs PID (%)",
    "rms_reduction_pct": "RMS interaction torque reduction vs PID (%)",
    "settling_time_s": "settling time (s)",
}
#: Seconds between two looks at the running seeds.
POLL_S = 1.0


@dataclass(frozen=True)
class SeedRuns:
    """Which seeds ``myoexo policy seeds train`` trains, and how many at once."""

    seeds: tuple[int, ...] = option((0, 1, 2, 3, 4), "training seeds, a run folder each", low=0)
    workers: int = option(2, "seeds trained at once", low=1)

    def __post_init__(self) -> None:
        check_fields(self)
        if len(set(self.seeds)) != len(self.seeds):
            raise FieldError("SeedRuns", "seeds", self.seeds, "repeats a seed")


def seed_dir(out: Path, seed: int) -> Path:
    """Run folder of one seed."""
    return Path(out) / f"seed_{int(seed)}"


def train_command(out: Path, seed: int, total_timesteps: int | None = None) -> list[str]:
    """The ``myoexo policy train`` command of one seed: a new run with the folder's config
    (``--config DIR/seeds.json``) and this seed, a resume if it has a resumable checkpoint
    (with *total_timesteps*: its new step budget), or a restart if it started but stopped
    before its first one."""
    run_dir = seed_dir(out, seed)
    cmd = [sys.executable, "-m", "myoexo.cli", "policy", "train", "--no-progress"]
    if (run_dir / ck.CONFIG_FILE).is_file() and ck.resumable_checkpoints(run_dir):
        cmd += ["--resume", str(run_dir)]
        if total_timesteps is not None:
            cmd += ["--total-timesteps", str(total_timesteps)]
        return cmd
    if (run_dir / ck.CONFIG_FILE).is_file():
        return [*cmd, "--restart", str(run_dir)]  # --restart keeps the saved step budget
    return [*cmd, "--config", str(out / SEEDS_FILE), "--seed", str(seed), "--run-dir", str(run_dir)]


def _record_config(out: Path, config: TrainConfig, seeds: Sequence[int]) -> None:
    """Write (first run) or check (later runs) the folder's configuration: a later run must
    give the same config (its step budget may grow; an older ``seeds.json`` is read as its
    config, :func:`~myoexo.training.config.config_from_record`)."""
    path = out / SEEDS_FILE
    record = json.loads(path.read_text()) if path.is_file() else {}
    if record:

        def compared(c: TrainConfig) -> dict[str, Any]:
            return dataclasses.replace(c, seed=0, total_timesteps=1).to_dict()

        saved, given = compared(config_from_record(record)), compared(config)
        differ = sorted(k for k in given if given[k] != saved.get(k))
        if differ:
            raise ValueError(
                f"{str(out)!r} holds seeds of another configuration (it differs in {differ}); "
                f"choose another folder or repeat its settings (--config {path} gives them)"
            )
        seeds = [*record.get("seeds", []), *seeds]
    record = {k: v for k, v in record.items() if k not in ("preset", "set")}  # older keys
    record.update(config=config.to_dict(), seeds=sorted(set(seeds)))
    write_json_atomic(path, record)


def train_seeds(args: argparse.Namespace) -> int:
    """``myoexo policy seeds train``: every seed in its own process, ``--workers`` at a time."""
    from myoexo.training.cli import config_from_args

    out = Path(args.out)
    runs = from_options(SeedRuns, args)
    config = config_from_args(args)
    config.resolved_kwargs()  # an argument the algorithm does not take stops here
    total = config.total_timesteps if hasattr(args, "total_timesteps") else None
    out.mkdir(parents=True, exist_ok=True)
    with FolderLock(out, "seeds folder"), StopSignals() as stop:
        _record_config(out, config, runs.seeds)
        queue = list(runs.seeds)
        running: dict[int, subprocess.Popen[bytes]] = {}
        codes: dict[int, int] = {}
        t0 = time.monotonic()
        while queue or running:
            while queue and len(running) < runs.workers and stop.received is None:
                seed = queue.pop(0)
                cmd = train_command(out, seed, total)
                log = open(out / f"seed_{seed}.log", "ab")
                running[seed] = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT)
                log.close()  # the child has its own copy of the file descriptor
                print(f"[seeds] seed {seed} started: {' '.join(cmd[2:])}", flush=True)
            if stop.received is not None:
                queue.clear()
                for proc in running.values():
                    if proc.poll() is None:
                        proc.send_signal(signal.SIGTERM)  # each checkpoints and stops
            time.sleep(POLL_S)
            for seed, proc in list(running.items()):
                if proc.poll() is not None:
                    codes[seed] = int(proc.returncode)
                    del running[seed]
                    print(
                        f"[seeds] seed {seed} ended with status {proc.returncode} after "
                        f"{(time.monotonic() - t0) / 60:.1f} min (log: {out}/seed_{seed}.log)",
                        flush=True,
                    )
    if stop.received is not None:
        print(
            f"myoexo policy seeds: stopped by {stop.name}; resume with the same command", flush=True
        )
        return signal_exit_status(signal.Signals[str(stop.name)])
    failed = {s: c for s, c in codes.items() if c != 0}
    if failed:
        raise ValueError(f"seeds {sorted(failed)} failed (exit statuses {failed}); see the logs")
    return 0


# ----------------------------------------------------------------------------- aggregate
def closest_seed(per_seed: Any, metrics: Sequence[str] = tuple(AGGREGATED)) -> int:
    """The seed whose per-level *metrics* (columns of *per_seed*, beside ``seed`` and
    ``level``) lie closest to the across-seed means (each metric over its across-seed
    standard deviation): a typical seed, not the best one."""
    distance: dict[int, float] = {}
    for _, group in per_seed.groupby("level"):
        for metric in metrics:
            values = group[metric].to_numpy(dtype=float)
            finite = values[np.isfinite(values)]
            if not finite.size:
                continue  # no seed has a value here (e.g. none settled): no distance
            mean, std = float(finite.mean()), float(finite.std())
            for seed, v in zip(group.seed, values, strict=True):
                d = 0.0 if not math.isfinite(v) or std == 0 else abs(v - mean) / std
                distance[int(seed)] = distance.get(int(seed), 0.0) + d
    return min(distance, key=lambda s: (distance[s], s))


def per_seed_table(out: Path, config: SelectionConfig) -> tuple[Any, dict[int, str]]:
    """Each seed's selected checkpoint (:func:`~myoexo.training.select.select_checkpoint`
    under *config*) and its comparison with the PID, one row per seed and level (the
    evaluation root is refused: the seed shipped from this table is chosen on these
    subjects). ``config.workers`` seeds are selected at once, one process each."""
    import pandas as pd

    check_fit_root(config.root_seed, "seed selection")
    seeds = sorted(
        int(p.name.partition("_")[2])
        for p in Path(out).glob("seed_*")
        if p.is_dir() and (p / ck.CONFIG_FILE).is_file()
    )
    if not seeds:
        raise ValueError(f"{str(out)!r} holds no seed run folder (seed_<N>/config.json)")
    from myoexo.evaluation.engine import init_worker

    run_dirs = [seed_dir(out, seed) for seed in seeds]
    select = functools.partial(select_with, config=config, verbose=False)
    selected = process_map(select, run_dirs, config.workers, init_worker, (os.getpid(),))
    frames, chosen = [], {}
    for seed, (checkpoint, table) in zip(seeds, selected, strict=True):
        chosen[seed] = str(checkpoint)
        frame = table.reset_index()
        frame["seed"] = seed
        frame["checkpoint"] = checkpoint.name
        frame["abs_final_error_deg"] = frame["sac_abs_final_error_deg"]
        frame["settling_time_s"] = frame["sac_settling_time_s"]
        frames.append(frame)
        print(f"[seeds] seed {seed}: {checkpoint.name}", flush=True)
    return pd.concat(frames, ignore_index=True), chosen


#: The label of every table computed on the selection subjects.
IN_SAMPLE_NOTE = (
    "**In-sample** (the selection subjects that chose each seed's checkpoint; the intervals "
    "resample seeds only): for choosing and shipping a seed, not a result. Results: an "
    "evaluation of the shipped seed on the evaluation root."
)


def markdown_summary(summary: Any) -> str:
    """The summary as a Markdown table: mean [95 % CI] (IQM) per metric and level, labelled
    in-sample (:data:`IN_SAMPLE_NOTE`)."""
    lines = [
        IN_SAMPLE_NOTE,
        "",
        "| level | seeds | " + " | ".join(AGGREGATED.values()) + " | P(pass criteria) |",
        "|---|---|" + "---|" * (len(AGGREGATED) + 1),
    ]
    for level, row in summary.iterrows():
        cells = [
            f"{row[f'{m}_mean']:.2f} [{row[f'{m}_ci_low']:.2f}, {row[f'{m}_ci_high']:.2f}] "
            f"(IQM {row[f'{m}_iqm']:.2f})"
            for m in AGGREGATED
        ]
        cells.append(
            f"{row['p_pass']:.2f} [{row['p_pass_ci_low']:.2f}, {row['p_pass_ci_high']:.2f}]"
        )
        lines.append(f"| {level} | {int(row['seeds'])} | " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def plot_spread(per_seed: Any, summary: Any) -> Any:
    """Per-seed values (dots) with the mean and its 95 % CI (bar), per level and metric."""
    from matplotlib.figure import Figure

    from myoexo.viz.colors import LEVEL_COLORS

    fig = Figure(figsize=(3.2 * len(AGGREGATED), 3.2), layout="constrained")
    axes = fig.subplots(1, len(AGGREGATED))
    for ax, (metric, title) in zip(axes, AGGREGATED.items(), strict=True):
        for level, group in per_seed.groupby("level"):
            x = np.full(len(group), float(level)) + np.linspace(-0.12, 0.12, len(group))
            ax.scatter(x, group[metric], s=14, color=LEVEL_COLORS.get(int(level), "grey"))
            row = summary.loc[level]
            lo, hi = row[f"{metric}_ci_low"], row[f"{metric}_ci_high"]
            ax.errorbar(
                float(level) + 0.3,
                row[f"{metric}_mean"],
                yerr=[[row[f"{metric}_mean"] - lo], [hi - row[f"{metric}_mean"]]],
                fmt="s",
                color="black",
                capsize=3,
                ms=4,
            )
        ax.set_xticks(sorted(per_seed.level.unique()))
        ax.set_xlabel("spasticity level")
        ax.set_title(title, fontsize=8)
        ax.grid(alpha=0.3)
    fig.suptitle("Per-seed spread (dots) and mean with its 95 % bootstrap CI", fontsize=9)
    return fig


def aggregate_seeds(args: argparse.Namespace) -> int:
    """``myoexo policy seeds aggregate``."""
    out = Path(args.out)
    config = from_options(SelectionConfig, args, levels=VALID_LEVELS)
    per_seed, chosen = per_seed_table(out, config)
    summary = summarize_seeds(per_seed, AGGREGATED)
    ship = closest_seed(per_seed)
    per_seed.to_csv(out / "aggregate_seeds.csv", index=False)
    summary.to_csv(out / "aggregate.csv")
    text = markdown_summary(summary)
    write_text_atomic(out / "aggregate.md", text)
    write_json_atomic(
        out / AGGREGATE_FILE,
        {
            "training_seeds": sorted(chosen),
            "selected_checkpoints": {str(k): v for k, v in chosen.items()},
            "selection_root_seed": SELECTION_ROOT_SEED,
            "selection_subjects_per_level": config.subjects,
            "perturbed_selection_subjects_per_level": config.perturbed_subjects,
            "perturbed_selection_levels": list(config.perturbed_levels),
            "ship_rule": "the seed closest to the across-seed means (closest_seed)",
            "ship_seed": ship,
            "ship_checkpoint": chosen[ship],
        },
    )
    plot_spread(per_seed, summary).savefig(out / "seeds_spread.png", dpi=130)
    print(text)
    print(f"ship by the closest-to-aggregate rule: seed {ship} ({chosen[ship]})")
    print(f"wrote {out}/aggregate.csv, aggregate.md, aggregate_seeds.csv, seeds_spread.png")
    return 0


def ship_seed(
    out: Path,
    stem: Path | None = None,
    name: str | None = None,
    gentleness_record: Path | None = None,
) -> Any:
    """Export the seed the aggregate chose (``aggregate.json``) as a numpy actor whose
    metadata records ``training_seeds``, ``ship_seed``, the ship rule and the selection root,
    to ``stem`` and/or into the package as ``name`` (:func:`myoexo.load_policy`). Seeds
    trained over the gentleness range take their default weight from *gentleness_record*
    (a ``myoexo policy gentleness`` record, as ``myoexo policy export --gentleness-record``)."""
    from myoexo.policies import save_actor, shipped_path
    from myoexo.training.export import load_checkpoint_actor, record_default_gentleness

    path = Path(out) / AGGREGATE_FILE
    if not path.is_file():
        raise ValueError(f"{str(path)!r} does not exist: run `myoexo policy seeds aggregate` first")
    chosen = json.loads(path.read_text())
    actor = load_checkpoint_actor(
        Path(chosen["ship_checkpoint"]), selection_root_seed=chosen["selection_root_seed"]
    )
    for key in ("training_seeds", "ship_seed", "ship_rule", "selection_subjects_per_level"):
        actor.metadata[key] = chosen[key]
    if gentleness_record is not None:
        record_default_gentleness(actor, Path(gentleness_record), chosen["ship_checkpoint"])
    stems = ([Path(stem)] if stem else []) + ([shipped_path(name)] if name else [])
    for target in stems:
        npz, js = save_actor(actor, target)
        print(
            f"actor: {npz} + {js.name} (seed {chosen['ship_seed']} of {chosen['training_seeds']})"
        )
    return actor


# ----------------------------------------------------------------------------- compare
def gradient_updates(run_dir: Path, n_updates: int) -> int:
    """Gradient steps behind a checkpoint's ``n_updates``: SB3's off-policy learners count
    gradient steps; its PPO counts epochs, each ``ceil(n_steps * n_envs / batch_size)``
    minibatch updates."""
    from myoexo.policies.algorithms import get_algorithm

    config = ck.read_run_config(run_dir)
    if not get_algorithm(config.algorithm).on_policy:
        return int(n_updates)
    kwargs = config.resolved_kwargs()
    rollout = int(kwargs["n_steps"]) * config.n_envs
    return int(n_updates) * math.ceil(rollout / int(kwargs["batch_size"]))


def training_speed(out: Path) -> Any:
    """Per seed of a seeds folder: training wall time, env steps and gradient updates of its
    newest checkpoint, and their rates."""
    import pandas as pd

    rows = []
    for run_dir in sorted(Path(out).glob("seed_*")):
        last = ck.latest_checkpoint(run_dir)
        if last is None:
            continue
        state = ck.read_state(last)
        wall = float(state["wall_time_s"])
        steps = int(state["num_timesteps"])
        updates = gradient_updates(run_dir, int(state.get("n_updates") or 0))
        rows.append(
            {
                "seed": int(run_dir.name.partition("_")[2]),
                "wall_time_min": wall / 60.0,
                "env_steps": steps,
                "gradient_updates": updates,
                "env_steps_per_s": steps / max(wall, 1e-9),
                "updates_per_s": updates / max(wall, 1e-9),
            }
        )
    if not rows:
        raise ValueError(f"{str(out)!r} holds no checkpointed seed run")
    return pd.DataFrame(rows)


def configuration_label(out: Path) -> str:
    """``algorithm (preset)`` of a seeds folder, from its first seed's config."""
    first = next(iter(sorted(Path(out).glob("seed_*"))), None)
    if first is None:
        raise ValueError(f"{str(out)!r} holds no seed run folder")
    config = ck.read_run_config(first)
    return f"{config.algorithm} ({config.name})"


def compare_configurations(folders: Sequence[Path]) -> Any:
    """One row per aggregated seeds folder (:func:`aggregate_seeds` first): speed means over
    seeds, and per level the final error and peak reduction (mean and CI) and ``p_pass``."""
    import pandas as pd

    rows = []
    for out in map(Path, folders):
        path = out / "aggregate.csv"
        if not path.is_file():
            raise ValueError(
                f"{str(path)!r} does not exist: run `myoexo policy seeds aggregate {out}`"
            )
        summary = pd.read_csv(path, index_col="level")
        speed = training_speed(out)
        row: dict[str, Any] = {
            "configuration": configuration_label(out),
            "folder": str(out),
            "seeds": int(summary["seeds"].max()),
        }
        for col in ("wall_time_min", "env_steps", "env_steps_per_s", "updates_per_s"):
            row[col] = float(speed[col].mean())
        for level, lv in summary.iterrows():
            for metric in ("abs_final_error_deg", "peak_reduction_pct"):
                for stat in ("mean", "ci_low", "ci_high"):
                    row[f"L{level}_{metric}_{stat}"] = float(lv[f"{metric}_{stat}"])
            row[f"L{level}_p_pass"] = float(lv["p_pass"])
        row["p_pass_mean"] = float(summary["p_pass"].mean())
        rows.append(row)
    return pd.DataFrame(rows)


def markdown_comparison(table: Any) -> str:
    """The comparison as a Markdown table (one row per configuration)."""
    levels = sorted({int(c[1]) for c in table.columns if c[:1] == "L" and c[1].isdigit()})
    head = ["configuration", "seeds", "wall (min/seed)", "env steps", "env steps/s", "updates/s"]
    head += [f"L{lv} final error (deg)" for lv in levels]
    head += [f"L{lv} peak reduction (%)" for lv in levels]
    head += ["criteria met (share of seed-levels)"]
    lines = ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)]

    def cell(row: Any, level: int, metric: str, fmt: str) -> str:
        m, lo, hi = (row[f"L{level}_{metric}_{s}"] for s in ("mean", "ci_low", "ci_high"))
        return f"{m:{fmt}} [{lo:{fmt}}, {hi:{fmt}}]"

    for _, row in table.iterrows():
        cells = [
            row["configuration"],
            str(int(row["seeds"])),
            f"{row['wall_time_min']:.1f}",
            f"{row['env_steps']:,.0f}",
            f"{row['env_steps_per_s']:.0f}",
            f"{row['updates_per_s']:.0f}",
        ]
        cells += [cell(row, lv, "abs_final_error_deg", ".2f") for lv in levels]
        cells += [cell(row, lv, "peak_reduction_pct", ".1f") for lv in levels]
        cells.append(f"{row['p_pass_mean']:.2f}")
        lines.append("| " + " | ".join(cells) + " |")
    return "\n".join(lines) + "\n"


def compare_seeds(args: argparse.Namespace) -> int:
    """``myoexo policy seeds compare``."""
    table = compare_configurations(args.folders)
    text = markdown_comparison(table)
    if args.out:
        stem = Path(args.out)
        stem.parent.mkdir(parents=True, exist_ok=True)
        table.to_csv(stem.with_suffix(".csv"), index=False)
        write_text_atomic(stem.with_suffix(".md"), text)
        print(f"wrote {stem.with_suffix('.csv')} and {stem.with_suffix('.md')}")
    print(text)
    return 0


# ----------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class SeedsFolder:
    """The seeds folder a ``myoexo policy seeds`` sub-command works on."""

    out: Path = option(
        Path(), "folder of the seeds (one run folder seed_<N> each)", flag="", folder=True
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SeedsShip:
    """Where ``myoexo policy seeds ship`` writes the aggregate's chosen seed (one or both)."""

    to: Path | None = option(None, "write STEM.npz + STEM.json", metavar="STEM")
    name: str | None = option(None, "write it into the package as NAME (e.g. sac)", metavar="NAME")
    gentleness_record: Path | None = option(
        None,
        "a `myoexo policy gentleness` record (gentleness.json or its folder): its default "
        "weight becomes the shipped policy's (seeds trained with --gentleness random)",
        metavar="FILE",
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class SeedsCompare:
    """The aggregated seeds folders ``myoexo policy seeds compare`` puts side by side."""

    folders: tuple[Path, ...] = option(
        (), "folders aggregated by `seeds aggregate`", flag="", metavar="FOLDERS"
    )
    out: str | None = option(None, "write STEM.csv and STEM.md", metavar="STEM")

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo policy seeds``."""
    sub = parser.add_subparsers(dest="action", required=True)
    tr = sub.add_parser(
        "train",
        help="train (or resume) several seeds of one configuration",
        description="The options of `myoexo policy train` (without --seed) give the one "
        "configuration; --total-timesteps on a later run is every seed's new step budget.",
    )
    add_positional(tr, SeedsFolder, "out", metavar="out")
    add_options(tr, SeedRuns)
    add_config_arguments(tr, seed=False)
    ag = sub.add_parser("aggregate", help="select each seed's checkpoint and aggregate them")
    add_positional(
        ag, SeedsFolder, "out", metavar="out", help="folder written by `myoexo policy seeds train`"
    )
    add_options(ag, SelectionConfig, exclude=("levels", "root_seed"))
    sh = sub.add_parser("ship", help="export the aggregate's chosen seed as a numpy actor")
    add_positional(
        sh, SeedsFolder, "out", metavar="out", help="an aggregated `myoexo policy seeds` folder"
    )
    add_options(sh, SeedsShip)
    co = sub.add_parser("compare", help="aggregated seeds folders side by side (speed, criteria)")
    add_positional(co, SeedsCompare, "folders", nargs="+", type=Path, metavar="folders")
    add_options(co, SeedsCompare)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo policy seeds train|aggregate|ship|compare``."""
    if args.action == "train":
        return train_seeds(args)
    if args.action == "aggregate":
        from_options(SelectionConfig, args, levels=VALID_LEVELS)  # checks the options
    if args.action == "compare":
        return compare_seeds(args)
    if args.action == "ship":
        where = from_options(SeedsShip, args)
        if not (where.to or where.name):
            raise ValueError("myoexo policy seeds ship: give --to STEM and/or --name NAME")
        ship_seed(Path(args.out), where.to, where.name, where.gentleness_record)
        return 0
    return aggregate_seeds(args)
