"""Layout of a training run folder and its checkpoints (save, find, read).

::

    <run>/config.json              preset, seed, env, observation keys, package versions
    <run>/sessions.jsonl           one line per training session (start/end step, wall time)
    <run>/eval.csv                 the periodic small evaluation (one row per level and step)
    <run>/eval_pid.json            the PID's metrics on the same fixed subjects (computed once)
    <run>/progress_<NN>.csv        SB3 logger output of training session NN (CSV)
    <run>/tb/                      the same as tensorboard event files
    <run>/checkpoints/step_<n>/    model.zip, vecnormalize.pkl, state.json and, for the
                                   newest ``keep_replay`` resumable checkpoints,
                                   replay_buffer.pkl (the others are policy snapshots)
    <run>/latest.json              name of the newest resumable checkpoint

A checkpoint is written into a temporary folder and renamed into place, and
``latest.json`` is replaced atomically afterwards, so a run killed at any moment resumes
from its newest complete checkpoint.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from myoexo.io import write_json_atomic

CONFIG_FILE = "config.json"
SESSIONS_FILE = "sessions.jsonl"
EVAL_FILE = "eval.csv"
EVAL_PID_FILE = "eval_pid.json"
LATEST_FILE = "latest.json"
CHECKPOINTS_DIR = "checkpoints"
TB_DIR = "tb"

MODEL_FILE = "model.zip"
REPLAY_FILE = "replay_buffer.pkl"
VECNORM_FILE = "vecnormalize.pkl"
STATE_FILE = "state.json"

_PREFIX = "step_"


def checkpoint_name(num_timesteps: int) -> str:
    """Folder name of the checkpoint at ``num_timesteps`` (sorts by step)."""
    return f"{_PREFIX}{int(num_timesteps):010d}"


def save_checkpoint(
    model: Any,
    run_dir: Path,
    state: dict[str, Any],
    with_replay: bool = True,
    keep_replay: int = 1,
) -> Path:
    """Save ``model`` (SB3 SAC), its VecNormalize statistics, ``state`` and (if
    ``with_replay``) its replay buffer.

    A checkpoint with a replay buffer is *resumable* and becomes ``latest.json``; one
    without is a policy snapshot (a few hundred kB) kept for checkpoint selection.

    Args:
        model: The SB3 model being trained.
        run_dir: Run folder.
        state: JSON-ready run state (step counter, wall time, evaluation score, ...).
        with_replay: Also save the replay buffer (hundreds of MB).
        keep_replay: Replay buffers kept (newest resumable checkpoints); older ones are
            deleted, leaving policy snapshots.

    Returns:
        The checkpoint folder.
    """
    run_dir = Path(run_dir)
    root = run_dir / CHECKPOINTS_DIR
    root.mkdir(parents=True, exist_ok=True)
    final = root / checkpoint_name(model.num_timesteps)
    tmp = Path(tempfile.mkdtemp(dir=root, prefix=".tmp_"))
    model.save(tmp / MODEL_FILE)
    vec_normalize = model.get_vec_normalize_env()
    if vec_normalize is not None:
        vec_normalize.save(str(tmp / VECNORM_FILE))
    if with_replay:
        model.save_replay_buffer(tmp / REPLAY_FILE)
    write_json_atomic(tmp / STATE_FILE, state)
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)
    if with_replay:
        write_json_atomic(run_dir / LATEST_FILE, {"checkpoint": final.name, **state})
        resumable = [p for p in list_checkpoints(run_dir) if (p / REPLAY_FILE).is_file()]
        for old in resumable[: -max(keep_replay, 1)]:
            (old / REPLAY_FILE).unlink(missing_ok=True)
    return final


def list_checkpoints(run_dir: Path) -> list[Path]:
    """Complete checkpoints of a run, oldest first."""
    root = Path(run_dir) / CHECKPOINTS_DIR
    if not root.is_dir():
        return []
    return sorted(
        p for p in root.iterdir() if p.name.startswith(_PREFIX) and (p / STATE_FILE).is_file()
    )


def latest_checkpoint(run_dir: Path, with_replay: bool = False) -> Path | None:
    """Newest complete checkpoint (with a replay buffer if ``with_replay``), or ``None``."""
    ckpts = list_checkpoints(run_dir)
    if with_replay:
        ckpts = [p for p in ckpts if (p / REPLAY_FILE).is_file()]
    return ckpts[-1] if ckpts else None


def read_state(checkpoint: Path) -> dict[str, Any]:
    """The ``state.json`` of a checkpoint."""
    return json.loads((Path(checkpoint) / STATE_FILE).read_text())


def read_config(run_dir: Path) -> dict[str, Any]:
    """The ``config.json`` of a run; ``ValueError`` if the folder holds no run."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise ValueError(f"{str(run_dir)!r} is not a training run folder (no {CONFIG_FILE})")
    return json.loads(path.read_text())


def resolve_checkpoint(path: str | os.PathLike[str], which: str = "latest") -> Path:
    """A checkpoint folder from a run folder (``which`` = ``latest``, ``best`` or a step
    number) or from a checkpoint folder itself.

    ``best``: the checkpoint taken at the evaluated step with the highest small-evaluation
    score (``eval.csv``).
    """
    p = Path(path)
    if (p / MODEL_FILE).is_file() and (p / STATE_FILE).is_file():
        return p
    ckpts = list_checkpoints(p)
    if not ckpts:
        raise ValueError(f"{str(p)!r} holds no checkpoint (expected {CHECKPOINTS_DIR}/step_*)")
    if which == "latest":
        return ckpts[-1]
    if which == "best":
        return _best_checkpoint(p, ckpts)
    try:
        step = int(which)
    except ValueError:
        raise ValueError(f"checkpoint {which!r}: expected 'latest', 'best' or a step") from None
    match = [c for c in ckpts if c.name == checkpoint_name(step)]
    if not match:
        raise ValueError(
            f"no checkpoint at step {step} in {str(p)!r}; available: {[step_of(c) for c in ckpts]}"
        )
    return match[0]


def step_of(checkpoint: Path) -> int:
    """Step counter of a checkpoint folder, from its name."""
    return int(Path(checkpoint).name[len(_PREFIX) :])


def _best_checkpoint(run_dir: Path, ckpts: list[Path]) -> Path:
    """Checkpoint of the evaluated step with the highest score in ``eval.csv``."""
    import csv

    path = run_dir / EVAL_FILE
    scores: dict[int, float] = {}
    if path.is_file():
        with open(path, newline="") as f:
            scores = {int(r["step"]): float(r["score"]) for r in csv.DictReader(f)}
    scored = [(scores[step_of(c)], c) for c in ckpts if step_of(c) in scores]
    if not scored:
        raise ValueError(f"no checkpoint of {str(run_dir)!r} was taken at an evaluated step")
    return max(scored, key=lambda sc: (sc[0], sc[1].name))[1]
