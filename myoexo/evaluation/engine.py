"""The evaluation engine: episodes with metrics, chunks of subjects, parallel and resumable.

Work is cut into *chunks* (one controller, one level, ``chunk_size`` consecutive subjects),
run in worker processes (``spawn``; each keeps one env per level and one controller per
spec) and stored as they finish (:mod:`.storage`). Running the same command again only
computes the missing chunks; an episode depends only on (controller, level, subject, root
seed) (:mod:`.config`), so the table is the same whatever the number of workers.

Long runs (:mod:`myoexo.lifecycle`, ``docs/long_runs.md``): the output folder is locked for
the run (a second run into it stops with the holder's name); SIGTERM or SIGINT stops
submitting chunks, lets the chunks in flight finish and be stored, shuts the pool down and
returns without writing the table (a second signal abandons the chunks in flight: their
temporary files never count as finished chunks and the next run removes them); workers end
with the driver even when it is killed with SIGKILL.
"""

from __future__ import annotations

import os
import sys
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.protocol import Controller
from myoexo.control.rollout import rollout
from myoexo.control.specs import (
    ControllerSpec,
    PolicyUnavailableError,
    build_controller,
    check_no_selection_leak,
    load_sb3_model,
    load_shipped_policy,
    parse_controller_spec,
    spec_env_kwargs,
)
from myoexo.evaluation.config import EvaluationConfig, subject_seed, write_config
from myoexo.evaluation.metrics import EpisodeMetrics, episode_metrics
from myoexo.evaluation.storage import (
    TRACE_CHANNELS,
    TRACES_DIR,
    chunk_done,
    chunk_path,
    collect_table,
    save_chunk,
    write_table,
)
from myoexo.io import remove_stale_temporaries
from myoexo.lifecycle import FolderLock, StopSignals, die_with_parent, ignore_signals

#: Signals recorded at full rate for the metrics (traces keep a subset, downsampled).
RECORDED_CHANNELS: tuple[str, ...] = (*TRACE_CHANNELS, "time_s", "target_angle_deg")

#: Chunks submitted to the pool beyond one per worker (keeps the workers fed; on a stop,
#: these finish too: a process pool cannot take back a queued call).
QUEUED_CHUNKS = 1

#: Seconds between two checks of the stop flag while waiting for chunks.
STOP_POLL_S = 0.2


# ----------------------------------------------------------------------------- episodes
@dataclass
class EpisodeResult:
    """One episode: its metrics, subject, and full-rate signals.

    Attributes:
        seed: Episode seed.
        level: Spasticity level.
        subject: The subject's spasticity parameters (``info["subject"]``).
        metrics: :class:`~myoexo.evaluation.metrics.EpisodeMetrics`.
        signals: ``info`` key -> array over the samples (reset + every step), float64.
        unstable: The physics diverged and the env truncated the episode.
        n_steps: Control steps run.
    """

    seed: int
    level: int
    subject: dict[str, float]
    metrics: EpisodeMetrics
    signals: dict[str, np.ndarray]
    unstable: bool
    n_steps: int


def run_episode(env: Any, controller: Controller, seed: int) -> EpisodeResult:
    """One episode (:func:`~myoexo.control.rollout.rollout`) and its metrics."""
    ep = rollout(env, controller, seed, channels=RECORDED_CHANNELS)
    return EpisodeResult(
        seed=ep.seed,
        level=ep.level,
        subject=ep.subject,
        metrics=episode_metrics(ep.signals),
        signals=ep.signals,
        unstable=ep.unstable,
        n_steps=ep.n_steps,
    )


def episode_row(result: EpisodeResult, controller: str, subject_index: int) -> dict[str, Any]:
    """The table row of an episode: ``controller, level, subject, seed, unstable, n_steps``,
    the subject's parameters as ``subject_<name>``, then the metrics."""
    row: dict[str, Any] = {
        "controller": controller,
        "level": result.level,
        "subject": int(subject_index),
        "seed": int(result.seed),
        "unstable": bool(result.unstable),
        "n_steps": int(result.n_steps),
    }
    row.update({f"subject_{k}": v for k, v in result.subject.items()})
    row.update(result.metrics.as_dict())
    return row


def downsample_trace(result: EpisodeResult, stride: int, n_samples: int) -> np.ndarray:
    """Traces of one episode as float32 ``(n_samples, len(TRACE_CHANNELS))``: every
    ``stride``-th sample, NaN-padded if the episode ended early."""
    out = np.full((n_samples, len(TRACE_CHANNELS)), np.nan, dtype=np.float32)
    for j, key in enumerate(TRACE_CHANNELS):
        x = result.signals[key][::stride][:n_samples]
        out[: x.size, j] = x
    return out


def evaluate_controller(
    controller: Controller,
    level: int,
    subjects: int | Sequence[int],
    root_seed: int = 0,
    episode_duration_s: float | None = None,
    label: str = "controller",
    env_kwargs: Mapping[str, Any] | None = None,
) -> tuple[Any, list[EpisodeResult]]:
    """In-process evaluation of a controller *object* (notebooks, tuning, selection).

    Args:
        controller: Any :class:`~myoexo.control.protocol.Controller`.
        level: Spasticity level.
        subjects: Number of subjects (indices ``0..n-1``) or explicit subject indices; the
            same indices give the same persons as :func:`evaluate`.
        root_seed: Root seed of :func:`~.config.subject_seed`.
        episode_duration_s: Episode length (``None``: the env's default).
        label: Value of the ``controller`` column.
        env_kwargs: More :func:`~myoexo.envs.make_env` arguments (e.g. the ``obs_preset``
            of a policy; default: the policy's own ``obs_preset`` attribute, if any).

    Returns:
        ``(table, results)``: a pandas DataFrame (one row per episode) and the
        :class:`EpisodeResult` list with the full-rate signals.
    """
    import pandas as pd

    from myoexo.envs import make_env

    indices = list(range(subjects)) if isinstance(subjects, (int, np.integer)) else list(subjects)
    kwargs = dict(env_kwargs or {})
    preset = getattr(controller, "obs_preset", None) or getattr(
        getattr(controller, "fn", None), "obs_preset", None
    )
    if isinstance(preset, str) and preset != "full":
        kwargs.setdefault("obs_preset", preset)
    env = make_env(level, episode_duration_s=episode_duration_s, **kwargs)
    try:
        results = [run_episode(env, controller, subject_seed(level, i, root_seed)) for i in indices]
    finally:
        env.close()
    rows = [episode_row(r, label, i) for r, i in zip(results, indices, strict=True)]
    return pd.DataFrame(rows), results


# ----------------------------------------------------------------------------- chunks
@dataclass(frozen=True)
class Chunk:
    """Unit of work: subjects ``start..stop-1`` of one level under one controller."""

    spec: ControllerSpec
    level: int
    start: int
    stop: int

    def path(self, out_dir: Path) -> Path:
        """Where the finished chunk is stored."""
        return chunk_path(out_dir, self.spec.label, self.level, self.start, self.stop)


def plan_chunks(specs: Sequence[ControllerSpec], config: EvaluationConfig) -> list[Chunk]:
    """All chunks of a run, ordered level, subjects, controller (a partial run stays
    paired across controllers)."""
    chunks: list[Chunk] = []
    for level in config.levels:
        for start in range(0, config.subjects, config.chunk_size):
            stop = min(start + config.chunk_size, config.subjects)
            chunks.extend(Chunk(spec, level, start, stop) for spec in specs)
    return chunks


#: Per-process caches of the workers: one env per env id, duration and env keyword arguments
#: (a policy's observation preset), one controller per spec, the env keyword arguments of
#: each spec.
_ENVS: dict[tuple[str, float | None, str, str], Any] = {}
_CONTROLLERS: dict[str, Controller] = {}
_SPEC_ENV_KWARGS: dict[str, dict[str, Any]] = {}


def _init_worker(parent_pid: int | None = None) -> None:
    """Worker start-up: one thread per process (the pool provides the parallelism), SIGINT
    left to the driver (it stops the pool itself), and an end with the driver
    (:func:`myoexo.lifecycle.die_with_parent`)."""
    ignore_signals()
    if parent_pid is not None:
        die_with_parent(parent_pid)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _close_worker_state() -> None:
    for env in _ENVS.values():
        env.close()
    _ENVS.clear()
    _CONTROLLERS.clear()
    _SPEC_ENV_KWARGS.clear()


def run_chunk(chunk: Chunk, config: EvaluationConfig, out_dir: str) -> tuple[Chunk, int]:
    """Run one chunk and store it atomically; returns ``(chunk, episodes run)``."""
    from myoexo.envs import make_env

    spec_kwargs = _SPEC_ENV_KWARGS.get(chunk.spec.text)
    if spec_kwargs is None:  # reads the policy's files: once per worker, not per chunk
        spec_kwargs = _SPEC_ENV_KWARGS[chunk.spec.text] = spec_env_kwargs(chunk.spec)
    env_kwargs = {**config.env_kwargs, **spec_kwargs}
    # the oracle plans on a copy of its env: it gets an env of its own, per level
    owner = chunk.spec.text if chunk.spec.kind == "oracle" else ""
    env_id = config.level_env_id(chunk.level)
    key = (env_id, config.episode_duration_s, repr(sorted(env_kwargs.items())), owner)
    env = _ENVS.get(key)
    if env is None:
        env = _ENVS[key] = make_env(
            env_id, episode_duration_s=config.episode_duration_s, **env_kwargs
        )
    controller_key = f"{chunk.spec.text}@{env_id}" if owner else chunk.spec.text
    controller = _CONTROLLERS.get(controller_key)
    if controller is None:
        controller = _CONTROLLERS[controller_key] = build_controller(chunk.spec, env)
    n_samples = config.trace_samples
    rows, traces = [], []
    for i in range(chunk.start, chunk.stop):
        result = run_episode(env, controller, subject_seed(chunk.level, i, config.root_seed))
        row = episode_row(result, chunk.spec.label, i)
        row["controller_spec"] = chunk.spec.text
        rows.append(row)
        traces.append(downsample_trace(result, config.trace_stride, n_samples))
    dt = float(env.unwrapped.dt)
    time_s = (np.arange(n_samples) * config.trace_stride * dt).astype(np.float32)
    save_chunk(chunk.path(Path(out_dir)), rows, np.stack(traces), time_s)
    return chunk, len(rows)


# ----------------------------------------------------------------------------- the run
@dataclass
class EvaluationRun:
    """What :func:`evaluate` produced.

    Attributes:
        out_dir: The output folder.
        table: One row per episode (also in ``episodes.parquet`` / ``.csv``).
        controllers: Labels of the controllers evaluated.
        skipped: Spec -> reason, for controllers left out (e.g. no shipped policy yet).
        computed: Episodes computed by this call (the rest came from earlier runs).
        stopped_by: Name of the signal that stopped the run (``"SIGTERM"``), else ``None``;
            a stopped run has stored its finished chunks but written no table (``table`` is
            ``None``): run it again to continue.
        stored: Episodes stored in the folder (all of them unless stopped).
        total: Episodes of the whole run.
    """

    out_dir: Path
    table: Any
    controllers: list[str]
    skipped: dict[str, str] = field(default_factory=dict)
    computed: int = 0
    stopped_by: str | None = None
    stored: int = 0
    total: int = 0


def resolve_controllers(
    specs_text: Iterable[str],
    log: Callable[[str], None] = print,
    root_seed: int | None = None,
) -> tuple[list[ControllerSpec], dict[str, str]]:
    """Parse and check every controller before anything is written.

    A model file that cannot be loaded raises ``ValueError``; ``sac`` without a shipped
    policy is skipped with a message (and reported in the second return value). With
    ``root_seed``, a policy selected on that root's subjects raises ``ValueError``
    (:func:`~myoexo.control.specs.check_no_selection_leak`).
    """
    specs: list[ControllerSpec] = []
    skipped: dict[str, str] = {}
    labels: dict[str, str] = {}
    for text in specs_text:
        spec = parse_controller_spec(text)
        if spec.kind == "sb3":
            load_sb3_model(str(spec.path), str(spec.algorithm))  # ValueError if unreadable
        elif spec.kind == "shipped":
            try:
                load_shipped_policy(spec.path or "sac")
            except PolicyUnavailableError as exc:
                skipped[text] = str(exc)
                log(f"myoexo evaluate: skipping controller {text!r}: {exc}")
                continue
        if root_seed is not None:
            check_no_selection_leak(spec, root_seed)
        if spec.slug in labels:
            raise ValueError(
                f"controllers {labels[spec.slug]!r} and {text!r} have the same label "
                f"{spec.slug!r}; rename one model file"
            )
        labels[spec.slug] = text
        specs.append(spec)
    if not specs:
        raise ValueError(f"no controller left to evaluate (skipped: {skipped})")
    return specs, skipped


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def evaluate(
    config: EvaluationConfig,
    out_dir: str | os.PathLike[str],
    workers: int | None = None,
    progress: bool = True,
    log: Callable[[str], None] = print,
    graceful_stop: bool = True,
    backend: str = "process",
    address: str | None = None,
) -> EvaluationRun:
    """Run (or continue) an evaluation and write its table.

    Args:
        config: What to run.
        out_dir: Output folder (created; a folder of the same run is continued).
        workers: Worker processes (default: all available cores); 1 runs in-process.
        progress: Show a tqdm progress bar.
        log: Where messages go.
        graceful_stop: Handle SIGINT / SIGTERM (main thread only): stop after the chunks in
            flight and return with :attr:`EvaluationRun.stopped_by` set, no table written.
        backend: ``"process"`` (a pool of worker processes on this machine) or ``"ray"``
            (Ray tasks, :mod:`.ray_backend`: ``workers`` CPUs of a local cluster, or the
            cluster at ``address``, where ``workers=None`` uses every CPU).
        address: Ray cluster to join (default: ``$RAY_ADDRESS``, else a local cluster).

    Raises:
        ValueError: Bad settings, an unreadable model file, or an output folder that holds
            a different run; nothing is written in those cases.
        myoexo.lifecycle.FolderInUseError: Another process writes into ``out_dir`` (a
            ``ValueError``; nothing is written).
        OSError: A write failed (e.g. a full disk): finished chunks stay, the failed one
            leaves no file.
    """
    from tqdm.auto import tqdm

    from myoexo.evaluation import ray_backend

    ray_backend.check_backend(backend, address)
    ray_workers = workers  # None: every CPU of a Ray cluster
    if workers is None:
        workers = available_cores()
    if not isinstance(workers, (int, np.integer)) or workers <= 0:
        raise ValueError(f"workers = {workers!r} must be a positive integer")
    specs, skipped = resolve_controllers(config.controllers, log, root_seed=config.root_seed)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"output path {str(out)!r} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    with FolderLock(out, "evaluation folder"), StopSignals(enabled=graceful_stop) as stop:
        write_config(out, config, specs)
        remove_stale_temporaries(out / TRACES_DIR, "*/L*/.tmp-*")  # writes cut short by a kill

        chunks = plan_chunks(specs, config)
        todo = [c for c in chunks if not chunk_done(c.path(out))]
        total = sum(c.stop - c.start for c in chunks)
        pending = sum(c.stop - c.start for c in todo)
        bar = tqdm(
            total=total,
            initial=total - pending,
            unit="episode",
            desc="evaluate",
            disable=not progress,
            dynamic_ncols=True,
        )
        computed = 0
        try:
            if backend == "ray":
                computed = ray_backend.run_chunks(
                    todo, config, out, bar, ray_workers, address, stop
                )
            elif workers == 1 or len(todo) <= 1:
                try:
                    for chunk in todo:
                        if stop.received is not None:
                            break
                        _, n = run_chunk(chunk, config, str(out))
                        computed += n
                        bar.update(n)
                finally:
                    _close_worker_state()
            elif todo:
                computed = _run_parallel(todo, config, out, min(workers, len(todo)), bar, stop)
        finally:
            bar.close()
        labels = [s.label for s in specs]
        if stop.received is not None:
            stored = sum(c.stop - c.start for c in chunks if chunk_done(c.path(out)))
            if stored < total:  # the table is written by the run that completes the chunks
                return EvaluationRun(
                    out_dir=out,
                    table=None,
                    controllers=labels,
                    skipped=skipped,
                    computed=computed,
                    stopped_by=stop.name,
                    stored=stored,
                    total=total,
                )
        table = collect_table([c.path(out) for c in chunks], labels)
        write_table(out, table)
    return EvaluationRun(
        out_dir=out,
        table=table,
        controllers=labels,
        skipped=skipped,
        computed=computed,
        stored=total,
        total=total,
    )


def _run_parallel(
    todo: list[Chunk],
    config: EvaluationConfig,
    out: Path,
    workers: int,
    bar: Any,
    stop: StopSignals,
) -> int:
    """Run ``todo`` on a pool of ``workers`` spawned processes; returns the episodes run.

    At most ``workers + QUEUED_CHUNKS`` chunks are in the pool at a time. Once ``stop`` has
    received a signal, no chunk is submitted any more and the ones in the pool finish (a
    worker ended by the same signal only loses its chunk). A worker's error cancels the chunks
    not started and lets the running ones finish; a second signal (``KeyboardInterrupt``)
    kills the workers at once.
    """
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    computed = 0
    ctx = mp.get_context("spawn")
    queue = deque(todo)
    running: set[Future[tuple[Chunk, int]]] = set()
    pool = ProcessPoolExecutor(
        workers, mp_context=ctx, initializer=_init_worker, initargs=(os.getpid(),)
    )
    try:
        while queue or running:
            while queue and stop.received is None and len(running) < workers + QUEUED_CHUNKS:
                running.add(pool.submit(run_chunk, queue.popleft(), config, str(out)))
            if stop.received is not None:
                queue.clear()
            done, running = wait(running, timeout=STOP_POLL_S, return_when=FIRST_COMPLETED)
            for fut in done:
                try:
                    _, n = fut.result()  # re-raises a worker's error
                except BrokenProcessPool:
                    if stop.received is None:
                        raise
                    continue  # the workers got the stop signal too: their chunks are lost
                computed += n
                bar.update(n)
    except Exception:
        for fut in running:
            fut.cancel()  # the chunks already running finish (and are stored) first
        raise
    except BaseException:  # a second signal: abandon the chunks in flight
        _end_workers(pool)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
    return computed


def _end_workers(pool: Any) -> None:
    """Kill the pool's worker processes (a second signal: their chunks in flight are
    abandoned, leaving only temporary files that the next run removes)."""
    processes = getattr(pool, "_processes", None) or {}
    for proc in list(processes.values()):
        if proc.is_alive():
            proc.kill()
