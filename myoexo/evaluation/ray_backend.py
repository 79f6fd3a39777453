"""The Ray backend of the evaluation engine: the chunks of a run as Ray tasks.

    myoexo evaluate --backend ray --workers 2                 # a local cluster of 2 CPUs
    myoexo evaluate --backend ray --address auto              # the cluster of `ray start`

Each chunk still left (:func:`~myoexo.evaluation.engine.plan_chunks`) becomes one task of one
CPU running :func:`~myoexo.evaluation.engine.run_chunk` single-threaded, which stores the
chunk atomically in the output folder exactly as the process pool does; so the same folder
resumes under either backend, and the table is identical whatever the backend and the
number of workers (an episode depends only on its controller, level, subject and root seed).
On a cluster the output folder must be on a filesystem every node sees at the same path
(``docs/cluster.md``).

How the driver connects and what happens to its cluster when it dies:
:mod:`myoexo.runtime.ray_cluster`. Importing this module does not import Ray.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

from myoexo.evaluation.engine import Chunk, init_worker, run_chunk

if TYPE_CHECKING:
    from myoexo.evaluation.config import EvaluationConfig

#: Backends of :func:`myoexo.evaluation.runner.evaluate`.
BACKENDS: tuple[str, ...] = ("process", "ray")

#: Seconds between two looks at the finished tasks (the driver's signal handlers and
#: Ctrl-C run in between).
POLL_S = 0.5

#: CPUs per chunk: one env and one controller, single-threaded.
CPUS_PER_CHUNK = 1


def check_backend(backend: str, address: str | None) -> None:
    """Refuse an unknown backend, an address without Ray, or Ray not installed
    (``ValueError``, before anything is written)."""
    if backend not in BACKENDS:
        raise ValueError(f"unknown backend {backend!r}; accepted: {BACKENDS}")
    if backend != "ray" and address:
        raise ValueError(f"--address {address!r} needs --backend ray")
    if backend == "ray":
        from myoexo.runtime.ray_cluster import require_ray

        require_ray("--backend ray")


def _chunk_task(chunk: Chunk, config: EvaluationConfig, out_dir: str) -> tuple[Chunk, int]:
    """Body of a Ray task: one thread, then the engine's own chunk runner."""
    init_worker()
    return run_chunk(chunk, config, out_dir)


def run_chunks(
    todo: Sequence[Chunk],
    config: EvaluationConfig,
    out: Path,
    bar: Any,
    workers: int | None = None,
    address: str | None = None,
    stop: Any = None,
) -> int:
    """Run the chunks ``todo`` as Ray tasks; returns the episodes computed.

    Args:
        todo: Chunks still missing from ``out``.
        config: The run.
        out: Output folder (resolved to an absolute path for the workers).
        bar: tqdm bar, advanced as tasks finish.
        workers: CPUs of a local cluster; on a joined cluster, the most chunks in flight at
            once (``None``: every CPU of the cluster).
        address: Cluster to join (:func:`myoexo.runtime.ray_cluster.resolve_address`).
        stop: A :class:`~myoexo.runtime.lifecycle.StopSignals`: once it has received a signal, no
            chunk is submitted any more and the running ones are finished and stored.

    Raises:
        Exception: The first error of a task, as the task raised it (the others are
            cancelled).
    """
    if not todo:
        return 0
    from myoexo.runtime.ray_cluster import ray_session

    with ray_session(workers, address, "--backend ray") as ray:
        task = ray.remote(num_cpus=CPUS_PER_CHUNK)(_chunk_task)
        config_ref = ray.put(config)
        out_dir = str(Path(out).resolve())
        queue = list(todo)
        limit = len(queue) if workers is None else int(workers)
        pending: list[Any] = []
        computed = 0
        try:
            while queue or pending:
                if stop is not None and stop.received is not None:
                    queue.clear()  # a graceful stop: finish the tasks in flight only
                while queue and len(pending) < limit:
                    pending.append(task.remote(queue.pop(0), config_ref, out_dir))
                done, pending = ray.wait(pending, num_returns=1, timeout=POLL_S)
                for ref in done:
                    _, n = _get(ray, ref)
                    computed += n
                    bar.update(n)
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
    return computed


def _get(ray: Any, ref: Any) -> Any:
    """``ray.get`` raising the task's own exception (e.g. a ``ValueError`` stays one)."""
    try:
        return ray.get(ref)
    except ray.exceptions.RayTaskError as exc:
        cause = getattr(exc, "cause", None)
        if isinstance(cause, Exception):
            raise cause from exc
        raise
