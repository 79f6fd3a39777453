"""``myoexo train``: train SAC on MyoExoKneeRandom-v0, or resume an interrupted run.

Examples::

    myoexo train --preset cpu --seed 0 --run-dir runs/cpu_seed0
    myoexo train --preset cpu --set total_timesteps=500000 --set n_envs=2
    myoexo train --resume runs/cpu_seed0                 # continues the step counter
    myoexo train --restart runs/cpu_seed0                # a start that never checkpointed
    tensorboard --logdir runs/cpu_seed0/tb

SIGTERM or Ctrl-C (SIGINT) ends training after the current step with a resumable checkpoint
and one line on stderr (``myoexo train: stopped by SIGTERM at step N; checkpoint step_...;
resume with: myoexo train --resume DIR``); the exit status is then 128 + the signal number
(143 for SIGTERM, 130 for SIGINT). A run folder in use by another process, or ``--resume``
on a folder without a checkpoint, is a one-line error with exit status 2. See
``docs/long_runs.md``.
"""

from __future__ import annotations

import argparse
import dataclasses
import signal
import sys
import time
from pathlib import Path

from myoexo.training.presets import PRESETS, apply_overrides, get_preset


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo train``."""
    parser.add_argument(
        "--preset", choices=sorted(PRESETS), default="cpu", help="hyper-parameters (default: cpu)"
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of learner and envs (default 0)")
    parser.add_argument(
        "--run-dir", help="output folder (default: runs/sac_<preset>_seed<seed>_<timestamp>)"
    )
    parser.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="FIELD=VALUE",
        help="override a preset field (--set n_envs=2) or a twin option by its own name "
        "(--set reflex=persistent, --set robustness=true, --set episode_duration_s=4, "
        "--set reward_weights=inter:-0.5, --set obs_preset=exo); repeatable",
    )
    parser.add_argument(
        "--total-timesteps", type=int, help="step budget (new run: a preset override)"
    )
    parser.add_argument(
        "--resume", metavar="DIR", help="continue the run in DIR from its newest checkpoint"
    )
    parser.add_argument(
        "--restart",
        metavar="DIR",
        help="start the run in DIR again from step 0 with its saved settings (for a run that "
        "ended before its first checkpoint; its logs are deleted)",
    )
    parser.add_argument(
        "--no-progress", action="store_true", help="no progress bar (for logs / background runs)"
    )
    parser.add_argument(
        "-v", "--verbose", type=int, default=1, help="0 quiet, 1 checkpoints/evals, 2 SB3 tables"
    )


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo train``: 0 when the step budget is reached, 128 + the signal number when
    stopped by SIGINT / SIGTERM (a checkpoint is written)."""
    from myoexo.runtime.lifecycle import signal_exit_status
    from myoexo.training.train import restart, resume, train

    progress = not args.no_progress
    if args.resume and args.restart:
        raise ValueError("--resume and --restart exclude each other")
    if args.resume or args.restart:
        option = "--resume" if args.resume else "--restart"
        if args.set or args.run_dir:
            raise ValueError(f"{option} takes the run's saved settings; drop --set/--run-dir")
        if args.resume:
            run_dir = Path(args.resume)
            result = resume(run_dir, args.total_timesteps, progress, args.verbose)
        else:
            if args.total_timesteps is not None:
                raise ValueError("--restart takes the run's saved settings; drop --total-timesteps")
            run_dir = Path(args.restart)
            result = restart(run_dir, progress, args.verbose)
    else:
        preset = apply_overrides(get_preset(args.preset), args.set)
        if args.total_timesteps is not None:
            preset = dataclasses.replace(preset, total_timesteps=args.total_timesteps)
        stamp = time.strftime("%Y%m%d-%H%M%S")
        run_dir = Path(args.run_dir or f"runs/sac_{preset.name}_seed{args.seed}_{stamp}")
        print(
            f"[train] preset {preset.name}, seed {args.seed}, {preset.twin.describe()} -> "
            f"{run_dir}",
            flush=True,
        )
        result = train(preset, run_dir, args.seed, progress, args.verbose)
    if result.stopped_by is not None:
        print(
            f"myoexo train: stopped by {result.stopped_by} at step {result.num_timesteps}; "
            f"checkpoint {result.checkpoint.name}; resume with: myoexo train --resume {run_dir}",
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
