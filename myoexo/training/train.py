"""Train a stable-baselines3 (or SBX) learner on a myoexo env, with checkpoints that a killed
run resumes from.

    from myoexo.training import get_preset, train, resume

    result = train(get_preset("cpu", seed=0), "runs/cpu_seed0")
    result = resume("runs/cpu_seed0")          # after an interruption: same run, same counter

A run is one folder (layout in :mod:`myoexo.training.checkpoints`). ``train`` writes its
``config.json`` (the :class:`~myoexo.training.config.TrainConfig`, env, observation keys,
package versions) before the first step; ``resume`` rebuilds everything from that file and
the newest resumable checkpoint (model, optimizer states, entropy coefficient, replay
buffer, observation statistics, step counter) and continues with SB3's
``reset_num_timesteps=False``, so logs, checkpoints and the total step budget continue where
they stopped. The resumed envs are seeded with
``seed + num_timesteps``: a resumed run is deterministic, though not bit-identical to an
uninterrupted one (the envs' RNG streams restart).

Long runs (``docs/long_runs.md``): the run folder is locked while a session trains in it (a
second ``train`` / ``resume`` into it stops with the holder's name); SIGTERM or SIGINT ends
``learn`` after the current step, writes a resumable checkpoint and returns with
:attr:`TrainResult.stopped_by` set; ``resume`` falls back to the previous checkpoint when the
newest is damaged; ``restart`` starts a folder again whose first session ended before its
first checkpoint.
"""

from __future__ import annotations

import contextlib
import json
import platform
import re
import signal
import sys
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.control.residual import ResidualConfig
from myoexo.control.specs import TRAINING_ENVS_KEY
from myoexo.envs.options import TwinOptions
from myoexo.model import TWIN_VERSION
from myoexo.policies.algorithms import algorithm_class, get_algorithm
from myoexo.runtime.files import package_versions, write_json_atomic
from myoexo.runtime.lifecycle import FolderLock, StopSignals, ignore_signals
from myoexo.training import checkpoints as ck
from myoexo.training.config import TrainConfig


@dataclass(frozen=True)
class TrainResult:
    """Outcome of :func:`train` / :func:`resume`.

    Attributes:
        run_dir: Run folder.
        checkpoint: Last resumable checkpoint written.
        num_timesteps: Env transitions of the run so far (all sessions).
        wall_time_s: Training wall time of the run so far (all sessions).
        session_env_steps_per_s: Transitions per second in this session.
        stopped_by: Name of the signal (``"SIGTERM"``, ``"SIGINT"``) that ended the session
            before its step budget, else ``None``; ``checkpoint`` is then the checkpoint
            written at the stop.
    """

    run_dir: Path
    checkpoint: Path
    num_timesteps: int
    wall_time_s: float
    session_env_steps_per_s: float
    stopped_by: str | None = None


#: How the lock error and messages name a training folder.
RUN_FOLDER = "training run folder"

#: ``progress_<NN>.csv``: the SB3 log of one session.
_PROGRESS_RE = re.compile(r"progress_(\d+)\.csv")


class NoCheckpointError(ValueError):
    """A run folder without a resumable checkpoint to continue from."""


def is_myoexo_env(env_id: str) -> bool:
    """Whether ``env_id`` is one of the MyoExoKnee envs (the paper's evaluation applies)."""
    return env_id.split(":")[-1].startswith("MyoExoKnee")


def make_env_fn(env_id: str, rank: int, twin: TwinOptions | None = None) -> Callable[[], Any]:
    """Factory of env ``rank`` of a vector env: *env_id* built with the options of *twin*
    (:meth:`TwinOptions.env_kwargs`, via :func:`~myoexo.envs.make_env`) + ``Monitor``
    (picklable, so it also works with ``SubprocVecEnv``)."""
    return _EnvFactory(env_id, rank, twin or TwinOptions())


@dataclass(frozen=True)
class _EnvFactory:
    env_id: str
    rank: int
    twin: TwinOptions
    in_worker: bool = False  # called in a SubprocVecEnv worker
    residual: ResidualConfig | None = None  # the classical controller the policy corrects

    def __call__(self) -> Any:
        from stable_baselines3.common.monitor import Monitor

        from myoexo.envs import make_env

        if self.in_worker:
            # the trainer stops its env workers itself; they end when it closes (or loses)
            # the pipe to them, so a terminal's Ctrl-C or a group's SIGTERM must not kill
            # them under a trainer that is writing its final checkpoint
            ignore_signals((signal.SIGINT, signal.SIGTERM))
        kwargs = self.twin.env_kwargs()
        try:
            env = make_env(self.env_id, **kwargs)
        except TypeError as exc:  # the id's constructor does not take an option
            raise ValueError(
                f"env {self.env_id!r} does not take the twin options "
                f"[{self.twin.describe()}] ({exc})"
            ) from exc
        if self.residual is not None:
            env = residual_env(env, self.residual)
        return Monitor(env)


def residual_env(env: Any, residual: ResidualConfig) -> Any:
    """*env* behind :class:`~myoexo.control.residual.ResidualWrapper`: its action corrects
    the command of the base controller *residual* names (built on *env*)."""
    from myoexo.control.residual import ResidualWrapper
    from myoexo.control.specs import residual_base

    return ResidualWrapper(env, residual_base(residual, env), residual.scale, residual.penalty)


def make_vec_env(config: TrainConfig, seed: int | None = None) -> Any:
    """The training envs: ``n_envs`` copies in a vector env (``"dummy"``:
    :class:`~myoexo.training.plumbing.FreshInfoVecEnv`, SB3's ``DummyVecEnv`` without its
    copy of every info; ``"subproc"``: ``SubprocVecEnv``), seeded ``seed + i`` (default: the
    config's seed), the last ``nominal_envs`` of them on the nominal twin, wrapped in
    ``VecNormalize`` (observations and/or rewards) if the config says so."""
    from stable_baselines3.common.vec_env import SubprocVecEnv, VecNormalize

    from myoexo.training.plumbing import FreshInfoVecEnv

    subproc = config.vec_env == "subproc"
    nominal = config.twin.nominal()
    first_nominal = config.n_envs - config.nominal_envs  # the last nominal_envs: nominal
    fns: list[Callable[[], Any]] = [
        _EnvFactory(
            config.env_id,
            i,
            config.twin if i < first_nominal else nominal,
            in_worker=subproc,
            residual=config.residual,
        )
        for i in range(config.n_envs)
    ]
    venv: Any = FreshInfoVecEnv(fns) if config.vec_env == "dummy" else SubprocVecEnv(fns)
    venv.seed(config.seed if seed is None else seed)
    if config.normalize_obs or config.normalize_reward:
        venv = VecNormalize(
            venv,
            norm_obs=config.normalize_obs,
            norm_reward=config.normalize_reward,
            clip_obs=config.clip_obs,
            gamma=config.resolved_kwargs()["gamma"],
        )
    return venv


def _activation(name: str, framework: str) -> Any:
    """The hidden activation *name* of a framework (GELU exact in both, as the numpy actor)."""
    if framework == "jax":
        import functools

        import flax.linen as fnn

        jax_fns = {
            "gelu": functools.partial(fnn.gelu, approximate=False),
            "relu": fnn.relu,
            "tanh": fnn.tanh,
            "elu": fnn.elu,
        }
        return jax_fns[name]
    from torch import nn

    return {"gelu": nn.GELU, "relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU}[name]


def build_model(config: TrainConfig, venv: Any) -> Any:
    """An untrained agent of the config's algorithm: its class (SB3's SAC or PPO, SBX's SAC,
    TQC or CrossQ) given ``algorithm_kwargs`` as they are, the config's networks (PPO:
    ``net_arch_qf`` is its value network) and seed, on the CPU. A JAX learner samples from a
    :class:`~myoexo.training.plumbing.NumpySampleReplayBuffer` unless ``algorithm_kwargs``
    names a ``replay_buffer_class``.

    Raises:
        FieldError: An argument the class does not take, or arguments that do not fit
            together (:meth:`~myoexo.training.config.TrainConfig.resolved_kwargs`).
    """
    algorithm = get_algorithm(config.algorithm)
    config.resolved_kwargs()  # every argument one the class takes
    critic = "vf" if algorithm.on_policy else "qf"
    kwargs = dict(config.algorithm_kwargs)
    if algorithm.framework == "jax" and not algorithm.on_policy:
        from myoexo.training.plumbing import NumpySampleReplayBuffer

        kwargs.setdefault("replay_buffer_class", NumpySampleReplayBuffer)
    return algorithm.load_class()(
        "MlpPolicy",
        venv,
        **kwargs,
        policy_kwargs={
            "net_arch": {"pi": list(config.net_arch_pi), critic: list(config.net_arch_qf)},
            "activation_fn": _activation(config.activation, algorithm.framework),
        },
        seed=config.seed,
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


def _next_session(run_dir: Path) -> int:
    """Number of the new session: after every recorded session and every progress log (a
    session killed with SIGKILL has a log but no record; its log is kept)."""
    logged = [
        int(m.group(1))
        for p in run_dir.glob("progress_*.csv")
        if (m := _PROGRESS_RE.fullmatch(p.name))
    ]
    return max(len(_sessions(run_dir)), max(logged, default=-1) + 1)


def checkpoint_cadence(config: TrainConfig, learning_starts: int = 0) -> dict[str, Any]:
    """The checkpoint cadence of a run (recorded in its ``config.json``; *learning_starts*:
    the algorithm's, 0 for an on-policy one)."""
    return {
        "every_s": config.checkpoint_every_s,
        "every_steps": config.checkpoint_every_steps,
        "first_after_learning_starts_steps": config.first_checkpoint_steps,
        "first_after_s": config.first_checkpoint_s,
        "learning_starts": int(learning_starts),
        "keep_resumable": config.keep_resumable_checkpoints,
        "rule": "a resumable checkpoint when either cadence is due (whichever comes first); "
        "the first one once learning_starts + first_after_learning_starts_steps transitions "
        "are collected or first_after_s seconds have passed; the newest keep_resumable keep "
        "their replay buffer",
    }


@dataclass(frozen=True)
class SessionOptions:
    """How a training session runs (the same for :func:`train`, :func:`resume` and
    :func:`restart`).

    Attributes:
        progress_bar: Show SB3's tqdm/rich progress bar.
        verbose: 0 silent, 1 one line per checkpoint/evaluation, 2 also SB3's log tables.
        graceful_stop: Handle SIGINT / SIGTERM during ``learn`` (main thread only): stop
            after the current step with a checkpoint (:attr:`TrainResult.stopped_by`).
        callbacks: More SB3 callbacks, called after the run's own (one returning ``False``
            stops the session early, with a final resumable checkpoint).
    """

    progress_bar: bool = False
    verbose: int = 1
    graceful_stop: bool = True
    callbacks: Sequence[Any] = ()


def _run_callbacks(
    config: TrainConfig, run_dir: Path, wall_time_offset_s: float, verbose: int, stop: StopSignals
) -> tuple[Any, Any]:
    """The run's periodic evaluator (``None`` without one) and its checkpointer."""
    from myoexo.training.callbacks import (
        PaperMetricsEvalCallback,
        PeriodicCheckpointCallback,
        SmallEvalSpec,
    )

    evaluator = None
    if config.eval_every_steps > 0 and is_myoexo_env(config.env_id):
        spec = SmallEvalSpec(
            levels=config.eval_levels,
            subjects=config.eval_subjects,
            twin=config.twin.nominal(),
            residual=config.residual,
        )
        evaluator = PaperMetricsEvalCallback(
            run_dir, config.eval_every_steps, spec, verbose, stop=stop
        )
    checkpointer = PeriodicCheckpointCallback(
        run_dir,
        every_s=config.checkpoint_every_s,
        every_steps=config.checkpoint_every_steps,
        wall_time_offset_s=wall_time_offset_s,
        evaluator=evaluator,
        keep_replay=config.keep_resumable_checkpoints,
        verbose=verbose,
        first_after_steps=config.first_checkpoint_steps,
        first_after_s=config.first_checkpoint_s,
        max_wall_time_s=config.max_wall_time_s,
        provenance={
            "twin": config.twin.to_dict(),
            "twin_version": TWIN_VERSION,
            "env_id": config.env_id,
            "algorithm": config.algorithm,
            **({"residual": config.residual.to_dict()} if config.residual else {}),
            **({TRAINING_ENVS_KEY: config.training_envs()} if config.nominal_envs else {}),
        },
    )
    return evaluator, checkpointer


def _utc_now() -> str:
    return time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime())


def _learn(
    model: Any,
    config: TrainConfig,
    run_dir: Path,
    total_timesteps: int,
    wall_time_offset_s: float,
    options: SessionOptions,
) -> TrainResult:
    """Run (or continue) ``model.learn`` up to ``total_timesteps`` with the run's callbacks
    (and ``options.callbacks`` after them); with ``options.graceful_stop``, SIGINT / SIGTERM
    end it early with a checkpoint. The session is appended to the run's sessions log."""
    import torch
    from stable_baselines3.common.callbacks import CallbackList

    from myoexo.training.callbacks import (
        RewardTermsCallback,
        SettlingRewardCallback,
        StopOnSignalCallback,
    )

    torch.set_num_threads(config.torch_threads)
    session = _next_session(run_dir)
    model.set_logger(_make_logger(run_dir, session, options.verbose))
    stop = StopSignals(enabled=options.graceful_stop)
    evaluator, checkpointer = _run_callbacks(
        config, run_dir, wall_time_offset_s, options.verbose, stop
    )
    start_step = int(model.num_timesteps)
    remaining = max(int(total_timesteps) - start_step, 0)
    budget_spent = 0 < config.max_wall_time_s <= wall_time_offset_s
    if budget_spent:
        remaining = 0  # earlier sessions spent the wall-time budget
    record: dict[str, Any] = {
        "session": session,
        "start_step": start_step,
        "target_step": int(total_timesteps),
        "started_utc": _utc_now(),
        "argv": sys.argv,
    }
    t0 = time.monotonic()
    with stop:
        if remaining > 0:
            callbacks = [
                RewardTermsCallback(),
                *(
                    [
                        SettlingRewardCallback(
                            config.settling_penalty,
                            torque_until_settling=config.torque_until_settling,
                        )
                    ]
                    if config.settling_penalty or config.torque_until_settling
                    else []
                ),
                *([evaluator] if evaluator else []),
                checkpointer,
                StopOnSignalCallback(stop),
                *options.callbacks,
            ]
            model.learn(
                total_timesteps=remaining,
                callback=CallbackList(callbacks),
                reset_num_timesteps=start_step == 0,
                progress_bar=options.progress_bar,
                log_interval=max(1, config.n_envs),
            )
        elapsed = time.monotonic() - t0
        last = _final_checkpoint(run_dir, checkpointer)
    steps = int(model.num_timesteps)
    stopped_by = stop.name if steps < int(total_timesteps) else None
    record.update(
        end_step=steps, wall_time_s=round(elapsed, 3), ended_utc=_utc_now(), stopped_by=stopped_by
    )
    if budget_spent or checkpointer.budget_spent:
        record["ended_by"] = "wall_time_budget"
    with open(run_dir / ck.SESSIONS_FILE, "a") as f:
        f.write(json.dumps(record) + "\n")
    return TrainResult(
        run_dir=run_dir,
        checkpoint=last,
        num_timesteps=steps,
        wall_time_s=wall_time_offset_s + elapsed,
        session_env_steps_per_s=(steps - start_step) / max(elapsed, 1e-9),
        stopped_by=stopped_by,
    )


def _final_checkpoint(run_dir: Path, checkpointer: Any) -> Path:
    """The session's last resumable checkpoint (one is written if the run has none)."""
    last = checkpointer.last_checkpoint
    if last is None or not ck.is_resumable(last):
        last = ck.latest_checkpoint(run_dir, with_replay=True)
    if last is None:  # nothing left to do and never checkpointed
        last = checkpointer.save(with_replay=True)
    return Path(last)


@contextlib.contextmanager
def _saved_run(run_dir: Path) -> Iterator[TrainConfig]:
    """Lock an existing run folder and yield its saved config (a folder written before the
    config held ``algorithm_kwargs`` is read as its config,
    :func:`~myoexo.training.config.config_from_record`); a folder that is not a run is
    refused before anything is written (``ValueError``)."""
    ck.read_run_config(run_dir)
    with FolderLock(run_dir, RUN_FOLDER):
        yield ck.read_run_config(run_dir)


def train(
    config: TrainConfig,
    run_dir: str | Path,
    progress_bar: bool = False,
    verbose: int = 1,
    graceful_stop: bool = True,
    callbacks: Sequence[Any] = (),
) -> TrainResult:
    """Train a new run of *config* in ``run_dir`` (created; must not already hold a run).

    Args:
        config: The run (:func:`~myoexo.training.config.get_preset`, its seed included).
        run_dir: Output folder.
        progress_bar: Show SB3's tqdm/rich progress bar.
        verbose: 0 silent, 1 one line per checkpoint/evaluation, 2 also SB3's log tables.
        graceful_stop: Handle SIGINT / SIGTERM during ``learn`` (main thread only): stop
            after the current step with a checkpoint (:attr:`TrainResult.stopped_by`).
        callbacks: More SB3 callbacks, called after the run's own (one returning ``False``
            stops the session early, with a final resumable checkpoint).

    Raises:
        ValueError: An algorithm argument its class does not take (checked before the
            folder is made), a folder that already holds a run, or a folder in use by
            another process (:class:`~myoexo.runtime.lifecycle.FolderInUseError`).
    """
    config.resolved_kwargs()
    run_dir = Path(run_dir)
    run_dir.mkdir(parents=True, exist_ok=True)
    with FolderLock(run_dir, RUN_FOLDER):
        if (run_dir / ck.CONFIG_FILE).exists():
            raise ValueError(
                f"{str(run_dir)!r} already holds a run; continue it with resume() / "
                "`myoexo policy train --resume DIR` (or, if it never wrote a checkpoint, start it "
                "again with `myoexo policy train --restart DIR`), or choose another folder"
            )
        options = SessionOptions(progress_bar, verbose, graceful_stop, tuple(callbacks))
        return _start(config, run_dir, options)


def _start(config: TrainConfig, run_dir: Path, options: SessionOptions) -> TrainResult:
    """A new run in ``run_dir`` (locked by the caller): ``config.json``, then ``learn``."""
    ck.clean_interrupted_writes(run_dir)
    resolved = config.resolved_kwargs()
    venv = make_vec_env(config)
    try:
        try:
            obs_keys = venv.get_attr("obs_keys", [0])[0]
        except AttributeError:
            obs_keys = None
        record = {
            "config": config.to_dict(),
            "seed": config.seed,
            "env_id": config.env_id,
            "obs_dim": int(venv.observation_space.shape[0]),
            "obs_keys": list(obs_keys) if obs_keys is not None else None,
            "updates_per_transition": config.updates_per_transition(resolved),
            "checkpoint_cadence": checkpoint_cadence(
                config, int(resolved.get("learning_starts", 0))
            ),
            "versions": package_versions(),
            "platform": platform.platform(),
            "created_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        }
        write_json_atomic(run_dir / ck.CONFIG_FILE, record)
        model = build_model(config, venv)
        return _learn(model, config, run_dir, config.total_timesteps, 0.0, options)
    finally:
        venv.close()


def _load_checkpoint(checkpoint: Path, config: TrainConfig) -> tuple[Any, Any]:
    """``(model, venv)`` restored from a resumable checkpoint (raises if it cannot be)."""
    from stable_baselines3.common.vec_env import VecNormalize

    step = int(ck.read_state(checkpoint)["num_timesteps"])
    seed = config.seed + step
    venv = make_vec_env(config, seed)
    try:
        if config.normalize_obs or config.normalize_reward:
            venv = VecNormalize.load(str(checkpoint / ck.VECNORM_FILE), venv.venv)
            venv.training = True
        cls = algorithm_class(config.algorithm)
        model = cls.load(checkpoint / ck.MODEL_FILE, env=venv, device="cpu")
        if (checkpoint / ck.REPLAY_FILE).is_file():  # off-policy; on-policy has none
            model.load_replay_buffer(checkpoint / ck.REPLAY_FILE)
        model.set_random_seed(seed)
    except BaseException:
        venv.close()
        raise
    return model, venv


def _restore_newest(run_dir: Path, config: TrainConfig) -> tuple[Any, Any, Path]:
    """``(model, venv, checkpoint)`` from the newest intact resumable checkpoint.

    A checkpoint that fails :func:`~myoexo.training.checkpoints.checkpoint_problem` is set
    aside; one that fails to load is skipped; both with a
    :class:`~myoexo.training.checkpoints.DamagedCheckpointWarning`.
    """
    candidates = ck.resumable_checkpoints(run_dir)
    if not candidates:
        raise NoCheckpointError(
            f"{str(run_dir)!r} has no resumable checkpoint yet (its first session ended "
            "before writing one); start it again in the same folder, with its saved "
            f"settings, with: myoexo policy train --restart {run_dir}"
        )
    failures: list[str] = []
    for checkpoint in reversed(candidates):
        problem = ck.checkpoint_problem(checkpoint)
        if problem is not None:
            ck.set_aside(checkpoint, problem)
            failures.append(f"{checkpoint.name}: {problem}")
            continue
        try:
            model, venv = _load_checkpoint(checkpoint, config)
        except Exception as exc:
            reason = f"{type(exc).__name__}: {exc}"
            warnings.warn(
                f"checkpoint {checkpoint} cannot be loaded ({reason}); falling back to the "
                "previous checkpoint",
                ck.DamagedCheckpointWarning,
                stacklevel=3,
            )
            failures.append(f"{checkpoint.name}: {reason}")
            continue
        return model, venv, checkpoint
    raise NoCheckpointError(
        f"{str(run_dir)!r} has no intact resumable checkpoint ({'; '.join(failures)}); start "
        f"it again with: myoexo policy train --restart {run_dir}"
    )


def resume(
    run_dir: str | Path,
    total_timesteps: int | None = None,
    progress_bar: bool = False,
    verbose: int = 1,
    graceful_stop: bool = True,
    callbacks: Sequence[Any] = (),
) -> TrainResult:
    """Continue the run in ``run_dir`` from its newest intact resumable checkpoint.

    Args:
        run_dir: A folder written by :func:`train`.
        total_timesteps: New total step budget of the run (default: its config's).
        progress_bar: Show SB3's progress bar.
        verbose: As in :func:`train`.
        graceful_stop: As in :func:`train`.
        callbacks: As in :func:`train`.

    Raises:
        ValueError: Not a run folder; no resumable checkpoint (:class:`NoCheckpointError`:
            use :func:`restart`); a folder in use by another process.
    """
    run_dir = Path(run_dir)
    options = SessionOptions(progress_bar, verbose, graceful_stop, tuple(callbacks))
    with _saved_run(run_dir) as config:
        ck.clean_interrupted_writes(run_dir)
        model, venv, last = _restore_newest(run_dir, config)
        try:
            state = ck.read_state(last)
            step = int(state["num_timesteps"])
            if verbose and getattr(model, "replay_buffer", None) is not None:
                print(
                    f"[resume] {run_dir} from {last.name}: {step} steps, "
                    f"{model.replay_buffer.size() * model.n_envs} transitions in the replay "
                    "buffer",
                    flush=True,
                )
            total = config.total_timesteps if total_timesteps is None else int(total_timesteps)
            return _learn(model, config, run_dir, total, float(state["wall_time_s"]), options)
        finally:
            venv.close()


def restart(
    run_dir: str | Path,
    progress_bar: bool = False,
    verbose: int = 1,
    graceful_stop: bool = True,
    callbacks: Sequence[Any] = (),
) -> TrainResult:
    """Start the run in ``run_dir`` again from step 0 with its saved settings.

    For a run whose first session ended (a crash, a kill) before its first resumable
    checkpoint: its outputs (checkpoints, logs, evaluations) are deleted, its
    ``config.json`` (its config, seed included) is kept and rewritten.

    Args:
        run_dir: A folder written by :func:`train`.
        progress_bar: As in :func:`train`.
        verbose: As in :func:`train`.
        graceful_stop: As in :func:`train`.
        callbacks: As in :func:`train`.

    Raises:
        ValueError: Not a run folder; the folder holds an intact resumable checkpoint
            (continue it with :func:`resume`); a folder in use by another process.
    """
    run_dir = Path(run_dir)
    options = SessionOptions(progress_bar, verbose, graceful_stop, tuple(callbacks))
    with _saved_run(run_dir) as config:
        intact = [c for c in ck.resumable_checkpoints(run_dir) if ck.checkpoint_problem(c) is None]
        if intact:
            raise ValueError(
                f"{str(run_dir)!r} holds the resumable checkpoint {intact[-1].name}; continue "
                f"it with: myoexo policy train --resume {run_dir}"
            )
        removed = ck.clear_run_outputs(run_dir)
        if verbose:
            print(f"[restart] {run_dir}: removed {removed} output(s) of the failed start")
        return _start(config, run_dir, options)
