"""Run the paper's evaluation protocol into a folder: :func:`evaluate`.

The steps of a run have names: check the settings and the controllers before anything is
written (:func:`_checked_workers`, :func:`~myoexo.evaluation.engine.resolve_controllers`),
lock the folder and record the run (``config.json``), plan the chunks and run the missing
ones on a backend (:mod:`.backends`), then write the table, or, after a graceful stop,
leave it to the run that completes the chunks.

Long runs (:mod:`myoexo.runtime.lifecycle`, ``docs/long_runs.md``): the output folder is
locked for the run (a second run into it stops with the holder's name); SIGTERM or SIGINT
stops submitting chunks, lets the chunks in flight finish and be stored, shuts the pool down
and returns without writing the table (a second signal abandons the chunks in flight: their
temporary files never count as finished chunks and the next run removes them); workers end
with the driver even when it is killed with SIGKILL.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.evaluation.backends import available_cores, check_backend, run_chunks
from myoexo.evaluation.config import EvaluationConfig, write_config
from myoexo.evaluation.engine import Chunk, plan_chunks, resolve_controllers
from myoexo.evaluation.storage import (
    TABLE_STEM,
    TRACES_DIR,
    chunk_done,
    collect_table,
    write_table,
)
from myoexo.runtime.files import remove_stale_temporaries
from myoexo.runtime.lifecycle import FolderLock, StopSignals


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


def _checked_workers(workers: int | None) -> int:
    """The worker count (default: every available core), or a ``ValueError``."""
    if workers is None:
        workers = available_cores()
    if not isinstance(workers, (int, np.integer)) or workers <= 0:
        raise ValueError(f"workers = {workers!r} must be a positive integer")
    return int(workers)


def _output_folder(out_dir: str | os.PathLike[str]) -> Path:
    """The output folder, created (``ValueError`` if the path is a file)."""
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"output path {str(out)!r} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    return out


def check_table_kept(out: Path, labels: Sequence[str], config: EvaluationConfig) -> None:
    """Raise ``ValueError`` if ``out`` holds an episode table with episodes that this run
    would drop when it rewrites the table (another controller, level or more subjects): a
    folder's table, and the report drawn from it, only ever grow."""
    path = out / f"{TABLE_STEM}.parquet"
    if not path.is_file():
        return
    import pandas as pd

    old = pd.read_parquet(path, columns=["controller", "level", "subject"])
    dropped = old[
        ~old["controller"].isin(list(labels))
        | ~old["level"].isin(list(config.levels))
        | (old["subject"] >= config.subjects)
    ]
    if not dropped.empty:
        raise ValueError(
            f"{str(out)!r} holds {len(old)} episodes ({old['controller'].nunique()} "
            f"controller(s), levels {sorted(old['level'].unique().tolist())}, "
            f"{old['subject'].nunique()} subjects) and this run would drop {len(dropped)} of "
            "them; choose another --out folder, or ask for at least what it holds"
        )


def _episodes(chunks: list[Chunk]) -> int:
    return sum(c.stop - c.start for c in chunks)


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
        myoexo.runtime.lifecycle.FolderInUseError: Another process writes into ``out_dir`` (a
            ``ValueError``; nothing is written).
        OSError: A write failed (e.g. a full disk): finished chunks stay, the failed one
            leaves no file.
    """
    from tqdm.auto import tqdm

    check_backend(backend, address)
    pool_workers = _checked_workers(workers)
    specs, skipped = resolve_controllers(
        config.controllers,
        log,
        root_seed=None if config.selection else config.root_seed,  # a selection run picks
        twin=config.twin,
    )
    labels = [s.label for s in specs]
    check_table_kept(Path(out_dir), labels, config)
    out = _output_folder(out_dir)
    with FolderLock(out, "evaluation folder"), StopSignals(enabled=graceful_stop) as stop:
        write_config(out, config, specs)
        remove_stale_temporaries(out / TRACES_DIR, "*/L*/.tmp-*")  # writes cut short by a kill
        chunks = plan_chunks(specs, config)
        todo = [c for c in chunks if not chunk_done(c.path(out))]
        total = _episodes(chunks)
        bar = tqdm(
            total=total,
            initial=total - _episodes(todo),
            unit="episode",
            desc="evaluate",
            disable=not progress,
            dynamic_ncols=True,
        )
        try:  # workers=None: every CPU of a Ray cluster
            computed = run_chunks(
                backend, todo, config, out, bar, stop, pool_workers, workers, address
            )
        finally:
            bar.close()
        stored = total  # every backend stores each chunk it finishes, or raises
        if stop.received is not None:  # a graceful stop may leave chunks undone
            stored = _episodes([c for c in chunks if chunk_done(c.path(out))])
        table = None
        if stored == total:  # else stopped: the run that completes the chunks writes it
            groups = {s.label: s.seed_group for s in specs}
            table = collect_table([c.path(out) for c in chunks], labels, groups)
            write_table(out, table)
    return EvaluationRun(
        out_dir=out,
        table=table,
        controllers=labels,
        skipped=skipped,
        computed=computed,
        stopped_by=stop.name if table is None else None,
        stored=stored,
        total=total,
    )
