"""Several seeds of one training configuration: trained in parallel, aggregated with their
uncertainty.

    myoexo seeds train runs/sbx5 --seeds 0 1 2 3 4 --set algorithm=sbx_sac --workers 2
    myoexo seeds train runs/sbx5                   # again: resumes every unfinished seed
    myoexo seeds aggregate runs/sbx5 --subjects 10
    myoexo seeds ship runs/sbx5 --name sac         # the chosen seed into the package
    myoexo seeds compare runs/algos/* --out results/algorithms   # several configurations

``train`` runs one ``myoexo train`` process per seed (``--workers`` at a time), each in its
own run folder ``DIR/seed_<N>`` with its own checkpoints, so each seed is resumable on its own
(running the same command again resumes the unfinished ones); ``DIR/seeds.json`` records the
configuration. SIGTERM / SIGINT are passed on to the running seeds, which checkpoint and stop.

``aggregate`` selects each seed's checkpoint on the selection subjects (root seed
:data:`~myoexo.evaluation.config.SELECTION_ROOT_SEED`, as ``myoexo select``), then reports
per level, over seeds: the mean, the interquartile mean and a bootstrap 95 % confidence
interval (``scipy.stats.bootstrap``, percentile method, resampling seeds; per level, so the
levels are the strata) of the final error, the peak and RMS reductions against the PID and the
settling time, and the fraction of seeds whose level passes the acceptance criteria
(:func:`myoexo.evaluation.criteria.compare`; a Wilson 95 % interval). It names the seed to
ship by a rule that does not pick the luckiest one: the seed closest to the aggregate (the
smallest sum over levels and metrics of its distance to the across-seed mean, each metric
divided by its across-seed spread). Files: ``aggregate_seeds.csv`` (one row per seed and
level), ``aggregate.csv`` / ``aggregate.md`` (the summary), ``aggregate.json`` (the chosen
seed and checkpoints), ``seeds_spread.png``.

``compare`` puts several aggregated folders side by side (e.g. algorithms trained on the same
wall-clock budget, ``--set max_wall_time_s=...``): per configuration, the mean over seeds of
the training wall time, env steps, env steps/s and gradient updates/s, and per level the
final error and peak reduction (mean [95 % CI]) and the share of seeds passing the criteria.
"""

from __future__ import annotations

import argparse
import json
import math
import signal
import subprocess
import sys
import time
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.evaluation.config import SELECTION_ROOT_SEED, check_fit_root
from myoexo.policies.run_files import AGGREGATE_FILE
from myoexo.runtime.files import write_json_atomic, write_text_atomic
from myoexo.runtime.lifecycle import FolderLock, StopSignals, signal_exit_status
from myoexo.training import checkpoints as ck

#: Configuration file of a seeds folder.
SEEDS_FILE = "seeds.json"
#: Per-seed metrics aggregated (column of the per-seed table -> what it is).
AGGREGATED: dict[str, str] = {
    "abs_final_error_deg": "|final error| (deg)",
    "peak_reduction_pct": "peak interaction torque reduction vs PID (%)",
    "rms_reduction_pct": "RMS interaction torque reduction vs PID (%)",
    "settling_time_s": "settling time (s)",
}
#: Resamples of the bootstrap.
BOOTSTRAP_RESAMPLES = 2_000
#: Seconds between two looks at the running seeds.
POLL_S = 1.0


def seed_dir(out: Path, seed: int) -> Path:
    """Run folder of one seed."""
    return Path(out) / f"seed_{int(seed)}"


def train_command(
    out: Path,
    seed: int,
    preset: str,
    overrides: Sequence[str],
    total_timesteps: int | None,
) -> list[str]:
    """The ``myoexo train`` command of one seed: a new run, a resume if it has a resumable
    checkpoint, or a restart if it started but stopped before its first one."""
    run_dir = seed_dir(out, seed)
    cmd = [sys.executable, "-m", "myoexo.cli", "train", "--no-progress"]
    if (run_dir / ck.CONFIG_FILE).is_file() and ck.resumable_checkpoints(run_dir):
        cmd += ["--resume", str(run_dir)]
    elif (run_dir / ck.CONFIG_FILE).is_file():
        return [*cmd, "--restart", str(run_dir)]  # --restart keeps the saved step budget
    else:
        cmd += ["--preset", preset, "--seed", str(seed), "--run-dir", str(run_dir)]
        for item in overrides:
            cmd += ["--set", item]
    if total_timesteps is not None:
        cmd += ["--total-timesteps", str(total_timesteps)]
    return cmd


def _record_config(out: Path, args: argparse.Namespace) -> None:
    """Write (first run) or check (later runs) the folder's configuration."""
    path = out / SEEDS_FILE
    config = {"preset": args.preset, "set": list(args.set), "seeds": sorted(set(args.seeds))}
    if path.is_file():
        saved = json.loads(path.read_text())
        if saved.get("preset") != config["preset"] or saved.get("set") != config["set"]:
            raise ValueError(
                f"{str(out)!r} holds seeds of another configuration ({saved}); choose another "
                "folder or repeat its settings"
            )
        config["seeds"] = sorted(set(saved.get("seeds", [])) | set(config["seeds"]))
    write_json_atomic(path, config)


def train_seeds(args: argparse.Namespace) -> int:
    """``myoexo seeds train``: every seed in its own process, ``--workers`` at a time."""
    out = Path(args.out)
    if any(s < 0 for s in args.seeds) or len(set(args.seeds)) != len(args.seeds):
        raise ValueError(f"--seeds {args.seeds} must be distinct integers >= 0")
    if args.workers < 1:
        raise ValueError(f"--workers = {args.workers} must be >= 1")
    out.mkdir(parents=True, exist_ok=True)
    with FolderLock(out, "seeds folder"), StopSignals() as stop:
        _record_config(out, args)
        queue = list(args.seeds)
        running: dict[int, subprocess.Popen[bytes]] = {}
        codes: dict[int, int] = {}
        t0 = time.monotonic()
        while queue or running:
            while queue and len(running) < args.workers and stop.received is None:
                seed = queue.pop(0)
                cmd = train_command(out, seed, args.preset, args.set, args.total_timesteps)
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
        print(f"myoexo seeds: stopped by {stop.name}; resume with the same command", flush=True)
        return signal_exit_status(signal.Signals[str(stop.name)])
    failed = {s: c for s, c in codes.items() if c != 0}
    if failed:
        raise ValueError(f"seeds {sorted(failed)} failed (exit statuses {failed}); see the logs")
    return 0


# ----------------------------------------------------------------------------- aggregate
def interquartile_mean(x: Any, axis: int = -1) -> Any:
    """Mean of the middle 50 % (``scipy.stats.trim_mean(x, 0.25)``), rliable's IQM."""
    from scipy.stats import trim_mean

    return trim_mean(x, 0.25, axis=axis)


def bootstrap_ci(values: Sequence[float], statistic: Any = np.mean, seed: int = 0) -> tuple:
    """95 % percentile-bootstrap interval of ``statistic`` over *values* (resampling them);
    ``(nan, nan)`` for fewer than two finite values."""
    from scipy.stats import bootstrap

    x = np.asarray([v for v in values if math.isfinite(v)], dtype=float)
    if x.size < 2 or np.all(x == x[0]):
        v = float(x[0]) if x.size else math.nan
        return (v, v) if x.size else (math.nan, math.nan)
    res = bootstrap(
        (x,),
        lambda s, axis=-1: statistic(s, axis=axis),
        n_resamples=BOOTSTRAP_RESAMPLES,
        method="percentile",
        rng=np.random.default_rng(seed),
    )
    return float(res.confidence_interval.low), float(res.confidence_interval.high)


def wilson_interval(successes: int, n: int, z: float = 1.959964) -> tuple[float, float]:
    """Wilson 95 % interval of a proportion."""
    if n == 0:
        return math.nan, math.nan
    p = successes / n
    denom = 1 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return centre - half, centre + half


def summarize(per_seed: Any) -> Any:
    """Per level: mean, IQM and bootstrap CI of every :data:`AGGREGATED` metric over seeds,
    and the fraction of seeds passing the criteria with its Wilson interval."""
    import pandas as pd

    rows = []
    for level, group in per_seed.groupby("level"):
        row: dict[str, Any] = {"level": int(level), "seeds": len(group)}
        for metric in AGGREGATED:
            values = group[metric].to_numpy(dtype=float)
            finite = values[np.isfinite(values)]
            lo, hi = bootstrap_ci(finite, seed=int(level))
            row[f"{metric}_mean"] = float(finite.mean()) if finite.size else math.nan
            row[f"{metric}_iqm"] = float(interquartile_mean(finite)) if finite.size else math.nan
            row[f"{metric}_ci_low"], row[f"{metric}_ci_high"] = lo, hi
        passed = int(group["pass"].sum())
        row["p_pass"] = passed / len(group)
        row["p_pass_ci_low"], row["p_pass_ci_high"] = wilson_interval(passed, len(group))
        rows.append(row)
    return pd.DataFrame(rows).set_index("level")


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


def per_seed_table(
    out: Path, subjects: int, last: int, top: int, root_seed: int = SELECTION_ROOT_SEED
) -> tuple[Any, dict[int, str]]:
    """Each seed's selected checkpoint (:func:`~myoexo.training.select.select_checkpoint`) and
    its comparison with the PID, one row per seed and level (the evaluation root is refused:
    the seed shipped from this table is chosen on these subjects)."""
    import pandas as pd

    root_seed = check_fit_root(root_seed, "seed selection")

    from myoexo.training.select import select_checkpoint

    seeds = sorted(
        int(p.name.partition("_")[2])
        for p in Path(out).glob("seed_*")
        if p.is_dir() and (p / ck.CONFIG_FILE).is_file()
    )
    if not seeds:
        raise ValueError(f"{str(out)!r} holds no seed run folder (seed_<N>/config.json)")
    frames, chosen = [], {}
    for seed in seeds:
        run_dir = seed_dir(out, seed)
        checkpoint, table = select_checkpoint(
            run_dir, subjects=subjects, last=last, top=top, root_seed=root_seed, verbose=False
        )
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
    """``myoexo seeds aggregate``."""
    out = Path(args.out)
    per_seed, chosen = per_seed_table(out, args.subjects, args.last, args.top)
    summary = summarize(per_seed)
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
            "selection_subjects_per_level": args.subjects,
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


def ship_seed(out: Path, stem: Path | None = None, name: str | None = None) -> Any:
    """Export the seed the aggregate chose (``aggregate.json``) as a numpy actor whose
    metadata records ``training_seeds``, ``ship_seed``, the ship rule and the selection root,
    to ``stem`` and/or into the package as ``name`` (:func:`myoexo.load_policy`)."""
    from myoexo.policies import save_actor, shipped_path
    from myoexo.training.export import load_checkpoint_actor

    path = Path(out) / AGGREGATE_FILE
    if not path.is_file():
        raise ValueError(f"{str(path)!r} does not exist: run `myoexo seeds aggregate` first")
    chosen = json.loads(path.read_text())
    actor = load_checkpoint_actor(
        Path(chosen["ship_checkpoint"]), selection_root_seed=chosen["selection_root_seed"]
    )
    for key in ("training_seeds", "ship_seed", "ship_rule", "selection_subjects_per_level"):
        actor.metadata[key] = chosen[key]
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

    preset = ck.read_config(run_dir)["preset"]
    if not get_algorithm(preset["algorithm"]).on_policy:
        return int(n_updates)
    rollout = int(preset["n_steps"]) * int(preset["n_envs"])
    return int(n_updates) * math.ceil(rollout / int(preset["batch_size"]))


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
    preset = ck.read_config(first)["preset"]
    return f"{preset['algorithm']} ({preset['name']})"


def compare_configurations(folders: Sequence[Path]) -> Any:
    """One row per aggregated seeds folder (:func:`aggregate_seeds` first): speed means over
    seeds, and per level the final error and peak reduction (mean and CI) and ``p_pass``."""
    import pandas as pd

    rows = []
    for out in map(Path, folders):
        path = out / "aggregate.csv"
        if not path.is_file():
            raise ValueError(f"{str(path)!r} does not exist: run `myoexo seeds aggregate {out}`")
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
    """``myoexo seeds compare``."""
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
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo seeds``."""
    sub = parser.add_subparsers(dest="action", required=True)
    tr = sub.add_parser("train", help="train (or resume) several seeds of one configuration")
    tr.add_argument("out", help="folder of the seeds (one run folder seed_<N> each)")
    tr.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 2, 3, 4])
    tr.add_argument("--preset", default="cpu", help="training preset (default: cpu)")
    tr.add_argument(
        "--set", action="append", default=[], metavar="FIELD=VALUE", help="preset override"
    )
    tr.add_argument("--total-timesteps", type=int, help="step budget of every seed")
    tr.add_argument("--workers", type=int, default=2, help="seeds trained at once (default 2)")
    ag = sub.add_parser("aggregate", help="select each seed's checkpoint and aggregate them")
    ag.add_argument("out", help="folder written by `myoexo seeds train`")
    ag.add_argument("--subjects", type=int, default=10, help="selection subjects per level")
    ag.add_argument("--last", type=int, default=2, help="newest checkpoints per seed")
    ag.add_argument("--top", type=int, default=4, help="best checkpoints by eval.csv per seed")
    sh = sub.add_parser("ship", help="export the aggregate's chosen seed as a numpy actor")
    sh.add_argument("out", help="an aggregated `myoexo seeds` folder")
    sh.add_argument("--to", type=Path, help="write STEM.npz + STEM.json")
    sh.add_argument("--name", help="write it into the package as NAME (e.g. sac)")
    co = sub.add_parser("compare", help="aggregated seeds folders side by side (speed, criteria)")
    co.add_argument("folders", nargs="+", type=Path, help="folders aggregated by `seeds aggregate`")
    co.add_argument("--out", help="write STEM.csv and STEM.md")


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo seeds train|aggregate|ship|compare``."""
    if args.action == "train":
        return train_seeds(args)
    if args.action == "compare":
        return compare_seeds(args)
    if args.action == "ship":
        if not (args.to or args.name):
            raise ValueError("myoexo seeds ship: give --to STEM and/or --name NAME")
        ship_seed(Path(args.out), args.to, args.name)
        return 0
    return aggregate_seeds(args)
