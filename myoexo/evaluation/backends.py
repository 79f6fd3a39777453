"""Where the chunks of an evaluation run: in this process, in a pool of worker processes on
this machine, or as Ray tasks (:mod:`.ray_backend`).

Every backend runs :func:`~myoexo.evaluation.engine.run_chunk` on the chunks still missing,
stores each as it finishes and returns the number of episodes it computed; a graceful stop
(a :class:`~myoexo.runtime.lifecycle.StopSignals` that has received a signal) submits no
chunk any more and lets the ones in flight finish.
"""

from __future__ import annotations

import os
from collections import deque
from pathlib import Path
from typing import Any

from myoexo.evaluation import ray_backend
from myoexo.evaluation.config import EvaluationConfig
from myoexo.evaluation.engine import Chunk, close_worker_state, init_worker, run_chunk
from myoexo.runtime.lifecycle import StopSignals

#: The backends: ``"process"`` (this machine) and ``"ray"`` (a Ray cluster).
BACKENDS: tuple[str, ...] = ray_backend.BACKENDS

#: Chunks submitted to the pool beyond one per worker (keeps the workers fed; on a stop,
#: these finish too: a process pool cannot take back a queued call).
QUEUED_CHUNKS = 1

#: Seconds between two checks of the stop flag while waiting for chunks.
STOP_POLL_S = 0.2


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


def check_backend(backend: str, address: str | None) -> None:
    """Refuse an unknown backend, an address without Ray, or Ray not installed
    (``ValueError``, before anything is written)."""
    ray_backend.check_backend(backend, address)


def run_chunks(
    backend: str,
    todo: list[Chunk],
    config: EvaluationConfig,
    out: Path,
    bar: Any,
    stop: StopSignals,
    workers: int,
    ray_workers: int | None = None,
    address: str | None = None,
) -> int:
    """Run the chunks ``todo`` on *backend*; returns the episodes computed.

    Args:
        backend: ``"process"`` or ``"ray"``.
        todo: Chunks still missing from ``out``.
        config: The run.
        out: Output folder.
        bar: tqdm bar, advanced as chunks finish.
        stop: The run's stop signals.
        workers: Worker processes of the ``"process"`` backend (1: in this process).
        ray_workers: CPUs of a local Ray cluster, or the most chunks in flight on a joined
            one (``None``: every CPU of the cluster).
        address: Ray cluster to join.
    """
    if backend == "ray":
        return ray_backend.run_chunks(todo, config, out, bar, ray_workers, address, stop)
    if workers == 1 or len(todo) <= 1:
        return run_in_process(todo, config, out, bar, stop)
    return run_process_pool(todo, config, out, min(workers, len(todo)), bar, stop)


def run_in_process(
    todo: list[Chunk], config: EvaluationConfig, out: Path, bar: Any, stop: StopSignals
) -> int:
    """Run ``todo`` one chunk after the other in this process; returns the episodes run."""
    computed = 0
    try:
        for chunk in todo:
            if stop.received is not None:
                break
            _, n = run_chunk(chunk, config, str(out))
            computed += n
            bar.update(n)
    finally:
        close_worker_state()
    return computed


def run_process_pool(
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
        workers, mp_context=ctx, initializer=init_worker, initargs=(os.getpid(),)
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
