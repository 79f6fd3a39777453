"""Files of an evaluation folder: finished chunks, the episode table and the traces.

::

    config.json                      the run-defining settings (:mod:`.config`)
    episodes.parquet, episodes.csv   one row per episode (:func:`~.engine.episode_row`, and
                                     the controller's ``seed_group``)
    traces/<controller>/L<level>/<first>-<stop>.npz   finished chunks (rows + traces)

A finished chunk is one compressed ``.npz`` (its table rows as JSON, its traces, their
times and channel names), written atomically, so an interrupted run loses at most the chunks
in flight. Traces are float32, every ``trace_stride``-th control step (default 2: 50 Hz),
channels :data:`TRACE_CHANNELS`: a few KB per episode, some tens of MB for the full protocol
(1000 subjects x 4 levels x 2 controllers), and never all in memory at once.
:func:`load_traces` gathers them per (controller, level).
"""

from __future__ import annotations

import json
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.specs import controller_slug
from myoexo.evaluation.stats import SEED_GROUP
from myoexo.runtime.files import atomic_path, savez_atomic

TABLE_STEM = "episodes"
TRACES_DIR = "traces"

#: Per-step signals kept for the figures (keys of the env's ``info``).
TRACE_CHANNELS: tuple[str, ...] = (
    "knee_angle_deg",
    "exo_angle_deg",
    "error_deg",
    "command",
    "exo_torque_nm",
    "muscle_knee_torque_nm",
    "interaction_torque_nm",
    "sc_total",
)


def chunk_path(out_dir: Path, label: str, level: int, start: int, stop: int) -> Path:
    """Where the chunk of subjects ``start..stop-1`` of one controller and level is stored."""
    folder = Path(out_dir) / TRACES_DIR / controller_slug(label) / f"L{int(level)}"
    return folder / f"{start:06d}-{stop:06d}.npz"


def save_chunk(
    path: Path, rows: Sequence[Mapping[str, Any]], traces: np.ndarray, time_s: np.ndarray
) -> None:
    """Store a finished chunk atomically: its table rows and traces
    ``(episodes, samples, channels)`` at ``time_s``."""
    savez_atomic(
        path,
        rows_json=np.array(json.dumps(list(rows), allow_nan=True)),
        traces=traces,
        time_s=time_s,
        channels=np.array(TRACE_CHANNELS),
    )


def chunk_done(path: Path) -> bool:
    """Whether ``path`` holds a complete chunk (a corrupt or truncated file does not)."""
    if not path.is_file():
        return False
    try:
        with np.load(path) as z:
            return {"rows_json", "traces"} <= set(z.files)
    except Exception:  # a truncated file from a crash outside the atomic write
        return False


def read_chunk(path: Path) -> tuple[list[dict[str, Any]], np.ndarray, np.ndarray]:
    """``(rows, traces, time_s)`` of a stored chunk."""
    with np.load(path) as z:
        return json.loads(str(z["rows_json"])), z["traces"], z["time_s"]


def collect_table(
    paths: Sequence[Path],
    controller_order: Sequence[str],
    seed_groups: Mapping[str, str | None] | None = None,
) -> Any:
    """The episode table of the given chunk files, sorted by controller (in
    ``controller_order``), level and subject, with the column ``seed_group``
    (:data:`~myoexo.evaluation.stats.SEED_GROUP`) beside ``controller`` (*seed_groups*: each
    controller label's group, ``None`` for none)."""
    import pandas as pd

    rows: list[dict[str, Any]] = []
    for path in paths:
        rows.extend(read_chunk(path)[0])
    table = pd.DataFrame(rows)
    if not table.empty:
        groups = dict(seed_groups or {})
        table.insert(1, SEED_GROUP, [groups.get(c) for c in table["controller"]])
        order = {label: i for i, label in enumerate(controller_order)}

        def sort_key(col: pd.Series) -> pd.Series:
            return col.map(order) if col.name == "controller" else col

        table = table.sort_values(["controller", "level", "subject"], key=sort_key)
        table = table.reset_index(drop=True)
    return table


def write_table(out_dir: str | os.PathLike[str], table: Any) -> None:
    """Write ``episodes.parquet`` and ``episodes.csv`` atomically."""
    out = Path(out_dir)
    for suffix, writer in ((".parquet", table.to_parquet), (".csv", table.to_csv)):
        with atomic_path(out / f"{TABLE_STEM}{suffix}") as tmp:
            writer(tmp, index=False)


#: The label of a seed group's member in a table without the column ``seed_group``:
#: ``<group>-seed_<N>-step_<k>`` (a seeds folder's checkpoint) or
#: ``<group>-seed_<N>-round_<r>`` (a distillation seed's copy).
_MEMBER_LABEL = re.compile(r"(?P<group>.+)-seed_\d+-(?:step|round)_\d+")


def load_table(out_dir: str | os.PathLike[str]) -> Any:
    """The episode table of an evaluation folder; a table without the column ``seed_group``
    (:data:`~myoexo.evaluation.stats.SEED_GROUP`) gets it from its members' labels."""
    import pandas as pd

    path = Path(out_dir) / f"{TABLE_STEM}.parquet"
    if not path.is_file():
        raise ValueError(f"{str(out_dir)!r} has no {path.name}: not an evaluation folder")
    table = pd.read_parquet(path)
    if SEED_GROUP not in table and "controller" in table:
        members = [_MEMBER_LABEL.fullmatch(str(c)) for c in table["controller"]]
        column = list(table.columns).index("controller") + 1
        table.insert(column, SEED_GROUP, [m.group("group") if m else None for m in members])
    return table


@dataclass
class Traces:
    """Stored traces of one (controller, level).

    Attributes:
        time_s: Sample times (s), shape ``(n_samples,)``.
        subjects: Subject indices, shape ``(n_subjects,)``.
        data: Channel (:data:`TRACE_CHANNELS`) -> float32 ``(n_subjects, n_samples)``.
    """

    time_s: np.ndarray
    subjects: np.ndarray
    data: Mapping[str, np.ndarray]

    def __getitem__(self, channel: str) -> np.ndarray:
        return self.data[channel]


def load_traces(out_dir: str | os.PathLike[str], controller: str, level: int) -> Traces:
    """Gather the stored traces of one controller label and level (every stored chunk)."""
    folder = chunk_path(Path(out_dir), controller, level, 0, 0).parent
    files = sorted(folder.glob("[0-9]*-[0-9]*.npz"))
    if not files:
        raise ValueError(f"no traces for controller {controller!r} at level {level} in {folder}")
    subjects: list[int] = []
    blocks = []
    time_s = np.zeros(0)
    for path in files:
        rows, traces, time_s = read_chunk(path)
        subjects.extend(r["subject"] for r in rows)
        blocks.append(traces)
    stacked = np.concatenate(blocks)
    # chunks of runs with another chunk size may overlap: keep each subject once, in order
    subjects_arr, first = np.unique(np.asarray(subjects), return_index=True)
    stacked = stacked[first]
    return Traces(
        time_s=time_s,
        subjects=subjects_arr,
        data={k: stacked[:, :, j] for j, k in enumerate(TRACE_CHANNELS)},
    )
