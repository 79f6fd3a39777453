"""``myoexo policy train``: train a learner on MyoExoKneeRandom-v0, or resume an interrupted run.

Examples::

    myoexo policy train --preset cpu --seed 0 --run-dir runs/cpu_seed0
    myoexo policy train --preset cpu --total-timesteps 500000 --n-envs 2 \\
        --algorithm sbx_sac --algorithm-kwargs train_freq=16,gradient_steps=64 \\
        --reward-weights inter:-0.1 --reflex persistent
    myoexo policy train --config runs/cpu_seed0/config.json --seed 1   # its settings, seed 1
    myoexo policy train --resume runs/cpu_seed0                 # continues the step counter
    myoexo policy train --restart runs/cpu_seed0                # a start that never checkpointed
    tensorboard --logdir runs/cpu_seed0/tb

Every field of the training config (:class:`~myoexo.training.config.TrainConfig`) is an
option of its own name (``--total-timesteps``), the algorithm's arguments one mapping
(``--algorithm-kwargs NAME=VALUE,...``, merged into the preset's), the twin's options their
own (``--reflex``, ``--episode-duration-s``, ``--obs-preset``, ``--reward-weights``); an
option not given keeps the preset's value. The earlier ``--set NAME=VALUE`` is refused with
the option that replaces it.

SIGTERM or Ctrl-C (SIGINT) ends training after the current step with a resumable checkpoint
and one line on stderr (``myoexo policy train: stopped by SIGTERM at step N; checkpoint
step_...; resume with: myoexo policy train --resume DIR``); the exit status is then 128 + the
signal number (143 for SIGTERM, 130 for SIGINT). A run folder in use by another process, or
``--resume`` on a folder without a checkpoint, is a one-line error with exit status 2. See
``docs/long_runs.md``.
"""

from __future__ import annotations

import argparse
import signal
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.envs.options import TwinOptions, add_twin_arguments, twin_from_args
from myoexo.runtime.fields import (
    add_options,
    check_fields,
    flag_of,
    from_options,
    option,
    option_fields,
    parse_assignments,
)
from myoexo.training.config import PRESETS, TrainConfig, get_preset, read_config_file

#: The preset of a command that names none.
DEFAULT_PRESET = "cpu"


def new_spelling(item: str) -> str:
    """The option that replaces an earlier ``--set NAME=VALUE`` item."""
    ((name, value),) = parse_assignments([item], "--set item").items()
    fields = {f.name: f for f in option_fields(TrainConfig)}
    if name in fields:
        flag = flag_of(fields[name])
    elif TwinOptions.is_option(name):
        flag = "--" + name.replace("_", "-")
    else:
        return f"--algorithm-kwargs {name}={value}"
    if value.lower() in ("true", "false"):  # a switch
        return flag if value.lower() == "true" else f"--no-{flag[2:]}"
    if name in ("net_arch_pi", "net_arch_qf", "eval_levels", "obs_keys"):  # several values
        value = " ".join(v for v in value.replace("-", ",").split(",") if v)
    return f"{flag} {value}"


class _RemovedSet(argparse.Action):
    """``--set NAME=VALUE``: gone; one line names the option that replaces it."""

    def __call__(self, parser: Any, namespace: Any, values: Any, option_string: Any = None):
        parser.error(
            f"--set is gone, every setting is an option of its own: --set {values} is now "
            f"{new_spelling(str(values))}"
        )


@dataclass(frozen=True)
class TrainBase:
    """What a training config starts from: a named preset or a saved config (one of the
    two; neither: :data:`DEFAULT_PRESET`)."""

    preset: str | None = option(
        None,
        f"the named config the options change (default: {DEFAULT_PRESET})",
        choices=sorted(PRESETS),
    )
    config: str | None = option(
        None,
        "start from a saved config instead: a run's config.json or a seeds folder's seeds.json",
        metavar="FILE",
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TrainRun:
    """Where ``myoexo policy train`` writes its run (or which run it continues) and how
    much it tells."""

    run_dir: Path | None = option(
        None,
        "output folder (default: runs/<algorithm>_<preset>_seed<seed>_<timestamp>)",
        folder=True,
    )
    resume: str | None = option(
        None,
        "continue the run in DIR from its newest checkpoint (with --total-timesteps: a "
        "new step budget)",
        metavar="DIR",
    )
    restart: str | None = option(
        None,
        "start the run in DIR again from step 0 with its saved settings (for a run that "
        "ended before its first checkpoint; its logs are deleted)",
        metavar="DIR",
    )
    progress: bool = option(True, "show a progress bar (--no-progress: for logs / background runs)")
    verbose: int = option(1, "0 quiet, 1 checkpoints/evals, 2 SB3 tables", low=0, short="v")

    def __post_init__(self) -> None:
        check_fields(self)


def add_config_arguments(parser: argparse.ArgumentParser, *, seed: bool = True) -> None:
    """The options of a training config: ``--preset`` or ``--config`` (the base,
    :class:`TrainBase`), one option per :class:`~myoexo.training.config.TrainConfig` field
    (without *seed*: not ``--seed``), the twin's options; ``--set`` (gone) says what
    replaced it."""
    add_options(parser.add_mutually_exclusive_group(), TrainBase)
    cpu = PRESETS[DEFAULT_PRESET]
    defaults = {f.name: getattr(cpu, f.name) for f in option_fields(TrainConfig)}
    defaults["algorithm_kwargs"] = ",".join(f"{k}={v}" for k, v in cpu.algorithm_kwargs.items())
    group = parser.add_argument_group(
        "training config",
        f"each option not given keeps the preset's value (shown: {DEFAULT_PRESET}'s)",
    )
    add_options(
        group, TrainConfig, given_only=True, defaults=defaults, exclude=() if seed else ("seed",)
    )
    add_twin_arguments(parser, observation=True)
    parser.add_argument("--set", action=_RemovedSet, metavar="NAME=VALUE", help=argparse.SUPPRESS)


def given_config_options(args: argparse.Namespace) -> list[str]:
    """The config options *args* holds (given on the command line), as typed."""
    given = [flag_of(f) for f in option_fields(TrainConfig) if hasattr(args, f.name)]
    given += [f"--{k}" for k in ("preset", "config") if getattr(args, k, None)]
    if twin_from_args(args) != TwinOptions():
        given.append("a twin option")
    return given


def config_from_args(args: argparse.Namespace) -> TrainConfig:
    """The config of the command line: ``--preset`` (or ``--config``) with every option
    given applied (``algorithm_kwargs`` merged into the base's, the twin's options on top of
    the base's twin)."""
    if getattr(args, "config", None):
        base = read_config_file(args.config)
    else:
        base = get_preset(getattr(args, "preset", None) or DEFAULT_PRESET)
    given = {
        f.name: getattr(args, f.name) for f in option_fields(TrainConfig) if hasattr(args, f.name)
    }
    twin = twin_from_args(args, base=base.twin)
    if twin != base.twin:  # one change: the options are checked against the twin they run on
        given["twin"] = twin
    return base.replace(**given) if given else base


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo policy train``."""
    add_options(parser, TrainRun)
    add_config_arguments(parser)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo policy train``: 0 when the step budget is reached, 128 + the signal number
    when stopped by SIGINT / SIGTERM (a checkpoint is written)."""
    from myoexo.runtime.lifecycle import signal_exit_status
    from myoexo.training.train import restart, resume, train

    options = from_options(TrainRun, args)
    progress = options.progress
    if args.resume and args.restart:
        raise ValueError("--resume and --restart exclude each other")
    if args.resume or args.restart:
        which = "--resume" if args.resume else "--restart"
        given = [
            g for g in given_config_options(args) if not (args.resume and g == "--total-timesteps")
        ]
        if args.run_dir:
            given.append("--run-dir")
        if given:
            raise ValueError(f"{which} takes the run's saved settings; drop {', '.join(given)}")
        if args.resume:
            run_dir = Path(args.resume)
            result = resume(
                run_dir, getattr(args, "total_timesteps", None), progress, options.verbose
            )
        else:
            run_dir = Path(args.restart)
            result = restart(run_dir, progress, options.verbose)
    else:
        config = config_from_args(args)
        config.resolved_kwargs()  # an argument its algorithm does not take stops here
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(
            args.run_dir or f"runs/{config.algorithm}_{config.name}_seed{config.seed}_{stamp}"
        )
        nominal = config.nominal_envs
        share = f" ({nominal} of {config.n_envs} envs nominal)" if nominal else ""
        print(
            f"[train] {config.algorithm} ({config.name}), seed {config.seed}, "
            f"{config.twin.describe()}{share} -> {run_dir}",
            flush=True,
        )
        result = train(config, run_dir, progress, options.verbose)
    if result.stopped_by is not None:
        print(
            f"myoexo policy train: stopped by {result.stopped_by} at step "
            f"{result.num_timesteps}; checkpoint {result.checkpoint.name}; resume with: "
            f"myoexo policy train --resume {run_dir}",
            file=sys.stderr,
            flush=True,
        )
        return signal_exit_status(signal.Signals[result.stopped_by])
    print(
        f"[train] {result.num_timesteps} steps, {result.wall_time_s / 60:.1f} min in total, "
        f"{result.session_env_steps_per_s:.0f} steps/s this session; last checkpoint "
        f"{result.checkpoint}"
    )
    return 0
