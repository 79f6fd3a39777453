"""Train stable-baselines3 SAC on a myoexo env, with checkpoints that a killed run resumes from.

    from myoexo.training import get_preset, train, resume

    result = train(get_preset("cpu"), "runs/cpu_seed0", seed=0)
    result = resume("runs/cpu_seed0")          # after an interruption: same run, same counter

A run is one folder (layout in :mod:`myoexo.training.checkpoints`). ``train`` writes its
``config.json`` (preset, seed, env, observation keys, package versions) before the first
step; ``resume`` rebuilds everything from that file and the newest resumable checkpoint
(model, optimizer states, entropy coefficient, replay buffer, observation statistics, step
counter) and continues with SB3's ``reset_num_timesteps=False``, so logs, checkpoints and
the total step budget continue where they stopped. The resumed envs are seeded with
``seed + num_timesteps``: a resumed run is deterministic, though not bit-identical to an
uninterrupted one (the envs' RNG streams restart).
"""

from __future__ import annotations

import json
import platform
import sys
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.io import package_versions, write_json_atomic
from myoexo.training import checkpoints as ck
from myoexo.training.presets import SACPreset, preset_from_dict


@dataclass(frozen=True)
class TrainResult:
    """Outcome of :func:`train` / :func:`resume`.

    Attributes:
        run_dir: Run folder.
        checkpoint: Last resumable checkpoint written.
        num_timesteps: Env transitions of the run so far (all sessions).
        wall_time_s: Training wall time of the run so far (all sessions).
        session_env_steps_per_s: Transitions per second in this session.
    """

    run_dir: Path
    checkpoint: Path
    num_timesteps: int
    wall_time_s: float
    session_env_steps_per_s: float


def is_myoexo_env(env_id: str) -> bool:
    """Whether ``env_id`` is one of the MyoExoKnee envs (the paper's evaluation applies)."""
    return env_id.split(":")[-1].startswith("MyoExoKnee")


def make_env_fn(
    env_id: str,
    rank: int,
    episode_duration_s: float | None = None,
    reward_weights: tuple[tuple[str, float], ...] = (),
) -> Callable[[], Any]:
    """Factory of env ``rank`` of a vector env: ``gymnasium.make`` + ``Monitor``
    (picklable, so it also works with ``SubprocVecEnv``)."""
    return _EnvFactory(env_id, rank, episode_duration_s, tuple(reward_weights))


@dataclass(frozen=True)
class _EnvFactory:
    env_id: str
    rank: int
    episode_duration_s: float | None
    reward_weights: tuple[tuple[str, float], ...] = ()

    def __call__(self) -> Any:
        import gymnasium as gym
        from stable_baselines3.common.monitor import Monitor

        if is_myoexo_env(self.env_id):
            from myoexo.envs import make_env

            env = make_env(
                self.env_id,
                episode_duration_s=self.episode_duration_s,
                reward_weights=dict(self.reward_weights),
            )
        elif self.episode_duration_s is not None or self.reward_weights:
            raise ValueError(
                "episode_duration_s and reward_weights apply to the MyoExoKnee envs only, "
                f"not {self.env_id!r}"
            )
        else:
            env = gym.make(self.env_id)
        return Monitor(env)


def make_vec_env(preset: SACPreset, seed: int) -> Any:
    """The training envs: ``n_envs`` copies in a Dummy/SubprocVecEnv, seeded ``seed + i``,
    wrapped in ``VecNormalize`` (observations only) if the preset says so."""
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecNormalize

    fns = [
        make_env_fn(preset.env_id, i, preset.episode_duration_s, preset.reward_weights)
        for i in range(preset.n_envs)
    ]
    venv: Any = DummyVecEnv(fns) if preset.vec_env == "dummy" else SubprocVecEnv(fns)
    venv.seed(seed)
    if preset.normalize_obs:
        venv = VecNormalize(
            venv, norm_obs=True, norm_reward=False, clip_obs=preset.clip_obs, gamma=preset.gamma
        )
    return venv


def build_sac(preset: SACPreset, venv: Any, seed: int) -> Any:
    """An untrained SB3 SAC with the preset's networks and hyper-parameters."""
    from stable_baselines3 import SAC
    from torch import nn

    activation = {"gelu": nn.GELU, "relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU}
    return SAC(
        "MlpPolicy",
        venv,
        learning_rate=preset.learning_rate,
        buffer_size=preset.buffer_size,
        learning_starts=preset.learning_starts,
        batch_size=preset.batch_size,
        tau=preset.tau,
        gamma=preset.gamma,
        train_freq=(preset.train_freq, "step"),
        gradient_steps=preset.gradient_steps,
        ent_coef=preset.ent_coef,
        policy_kwargs={
            "net_arch": {"pi": list(preset.net_arch_pi), "qf": list(preset.net_arch_qf)},
            "activation_fn": activation[preset.activation],
        },
        seed=seed,
        device="cpu",
        verbose=0,
    )


def _make_logger(run_dir: Path, session: int, verbose: int) -> Any:
    from stable_baselines3.common.logger import CSVOutputFormat, Logger, make_output_format

    formats = [
        CSVOutputFormat(str(run_dir / f"progress_{session:02d}.csv")),
        make_output_format("tensorboard", str(run_dir / ck.TB_DIR)),
    ]
    if verbose >= 2:
        formats.append(make_output_format("stdout", str(run_dir)))
    return Logger(str(run_dir), formats)


def _sessions(run_dir: Path) -> list[dict[str, Any]]:
    path = run_dir / ck.SESSIONS_FILE
    if not path.is_file():
        return []
    return [json.loads(line) for line in path.read_text().splitlines() if line.strip()]


def _learn(
    model: Any,
    preset: SACPreset,
    run_dir: Path,
    total_timesteps: int,
    wall_time_offset_s: float,
    progress_bar: bool,
    verbose: int,
    extra_callbacks: Sequence[Any] = (),
) -> TrainResult:
    """Run (or continue) ``model.learn`` up to ``total_timesteps`` with the run's callbacks
    (and ``extra_callbacks`` after them)."""
    import torch
    from stable_baselines3.common.callbacks import CallbackList

    from myoexo.training.callbacks import (
        PaperMetricsEvalCallback,
        PeriodicCheckpointCallback,
        RewardTermsCallback,
        SmallEvalSpec,
    )

    torch.set_num_threads(preset.torch_threads)
    session = len(_sessions(run_dir))
    model.set_logger(_make_logger(run_dir, session, verbose))
    evaluator = None
    if preset.eval_every_steps > 0 and is_myoexo_env(preset.env_id):
        spec = SmallEvalSpec(
            levels=preset.eval_levels,
            subjects=preset.eval_subjects,
            episode_duration_s=preset.episode_duration_s,
        )
        evaluator = PaperMetricsEvalCallback(run_dir, preset.eval_every_steps, spec, verbose)
    checkpointer = PeriodicCheckpointCallback(
        run_dir,
        every_s=preset.checkpoint_every_s,
        every_steps=preset.checkpoint_every_steps,
        wall_time_offset_s=wall_time_offset_s,
        evaluator=evaluator,
        verbose=verbose,
    )
    callbacks = [
        RewardTermsCallback(),
        *([evaluator] if evaluator else []),
        checkpointer,
        *extra_callbacks,
    ]
    start_step = int(model.num_timesteps)
    remaining = max(int(total_timesteps) - start_step, 0)
    record = {
        "session": session,
        "start_step": start_step,
        "target_step": int(total_timesteps),
        "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "argv": sys.argv,
    }
    t0 = time.monotonic()
    if remaining > 0:
        model.learn(
            total_timesteps=remaining,
            callback=CallbackList(callbacks),
            reset_num_timesteps=start_step == 0,
            progress_bar=progress_bar,
            log_interval=max(1, preset.n_envs),
        )
    elapsed = time.monotonic() - t0
    last = ck.latest_checkpoint(run_dir, with_replay=True)
    if last is None:  # nothing left to do and never checkpointed
        last = checkpointer.save(with_replay=True)
    steps = int(model.num_timesteps)
    record.update(
        end_step=steps,
        wall_time_s=round(elapsed, 3),
        ended_utc=time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    )
    with open(run_dir / ck.SESSIONS_FILE, "a") as f:
        f.write(json.dumps(record) + "\n")
    return TrainResult(
        run_dir=run_dir,
        checkpoint=last,
        num_timesteps=steps,
        wall_time_s=wall_time_offset_s + elapsed,
        session_env_steps_per_s=(steps - start_step) / max(elapsed, 1e-9),
    )


def train(
    preset: SACPreset,
    run_dir: str | Path,
    seed: int = 0,
    progress_bar: bool = False,
    verbose: int = 1,
    callbacks: Sequence[Any] = (),
) -> TrainResult:
    """Train a new SAC run in ``run_dir`` (created; must not already hold a run).

    Args:
        preset: Hyper-parameters (:func:`~myoexo.training.presets.get_preset`).
        run_dir: Output folder.
        seed: Seed of the learner (torch, numpy) and of the envs (``seed + i``).
        progress_bar: Show SB3's tqdm/rich progress bar.
        verbose: 0 silent, 1 one line per checkpoint/evaluation, 2 also SB3's log tables.
        callbacks: More SB3 callbacks, called after the run's own (one returning ``False``
            stops the session early, with a final resumable checkpoint).
    """
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise ValueError(f"seed = {seed!r} must be an integer >= 0")
    run_dir = Path(run_dir)
    if (run_dir / ck.CONFIG_FILE).exists():
        raise ValueError(
            f"{str(run_dir)!r} already holds a run; continue it with resume() / "
            "`myoexo train --resume DIR`, or choose another folder"
        )
    run_dir.mkdir(parents=True, exist_ok=True)
    venv = make_vec_env(preset, seed)
    try:
        obs_keys = venv.get_attr("obs_keys", [0])[0]
    except AttributeError:
        obs_keys = None
    config = {
        "preset": preset.to_dict(),
        "seed": seed,
        "env_id": preset.env_id,
        "obs_dim": int(venv.observation_space.shape[0]),
        "obs_keys": list(obs_keys) if obs_keys is not None else None,
        "updates_per_transition": preset.updates_per_transition,
        "versions": package_versions(),
        "platform": platform.platform(),
        "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
    }
    write_json_atomic(run_dir / ck.CONFIG_FILE, config)
    model = build_sac(preset, venv, seed)
    try:
        return _learn(
            model,
            preset,
            run_dir,
            preset.total_timesteps,
            0.0,
            progress_bar,
            verbose,
            callbacks,
        )
    finally:
        venv.close()


def resume(
    run_dir: str | Path,
    total_timesteps: int | None = None,
    progress_bar: bool = False,
    verbose: int = 1,
    callbacks: Sequence[Any] = (),
) -> TrainResult:
    """Continue the run in ``run_dir`` from its newest resumable checkpoint.

    Args:
        run_dir: A folder written by :func:`train`.
        total_timesteps: New total step budget of the run (default: the preset's).
        progress_bar: Show SB3's progress bar.
        verbose: As in :func:`train`.
        callbacks: As in :func:`train`.
    """
    from stable_baselines3 import SAC
    from stable_baselines3.common.vec_env import VecNormalize

    run_dir = Path(run_dir)
    config = ck.read_config(run_dir)
    preset = preset_from_dict(config["preset"])
    seed = int(config["seed"])
    last = ck.latest_checkpoint(run_dir, with_replay=True)
    if last is None:
        raise ValueError(f"{str(run_dir)!r} has no resumable checkpoint yet; start it again")
    state = ck.read_state(last)
    step = int(state["num_timesteps"])
    venv = make_vec_env(preset, seed + step)
    if preset.normalize_obs:
        venv = VecNormalize.load(str(last / ck.VECNORM_FILE), venv.venv)
        venv.training = True
    model = SAC.load(last / ck.MODEL_FILE, env=venv, device="cpu")
    model.load_replay_buffer(last / ck.REPLAY_FILE)
    model.set_random_seed(seed + step)
    if verbose and model.replay_buffer is not None:
        print(
            f"[resume] {run_dir} from {last.name}: {step} steps, "
            f"{model.replay_buffer.size() * model.n_envs} transitions in the replay buffer",
            flush=True,
        )
    total = preset.total_timesteps if total_timesteps is None else int(total_timesteps)
    try:
        return _learn(
            model,
            preset,
            run_dir,
            total,
            float(state["wall_time_s"]),
            progress_bar,
            verbose,
            callbacks,
        )
    finally:
        venv.close()
