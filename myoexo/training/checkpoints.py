"""Layout of a training run folder and its checkpoints (save, find, read).

::

    <run>/config.json              training config (seed included), env, observation keys,
                                   package versions
    <run>/sessions.jsonl           one line per training session (start/end step, wall time)
    <run>/eval.csv                 the periodic small evaluation (one row per level and step)
    <run>/eval_pid.json            the PID's metrics on the same fixed subjects (computed once)
    <run>/progress_<NN>.csv        SB3 logger output of training session NN (CSV)
    <run>/tb/                      the same as tensorboard event files
    <run>/checkpoints/step_<n>/    model.zip, vecnormalize.pkl, state.json and, for the
                                   newest ``keep_replay`` (2) resumable checkpoints,
                                   replay_buffer.pkl (the others are policy snapshots);
                                   an on-policy learner (PPO) has no replay buffer: its
                                   resumable checkpoints hold on_policy.json instead
    <run>/checkpoints/damaged-step_<n>-<time>/   a checkpoint found damaged, set aside
    <run>/latest.json              name of the newest resumable checkpoint
    <run>/.myoexo.lock             the lock of the process training in the folder

A checkpoint is written into a temporary folder (a unique ``.tmp_*`` name) and renamed into
place, and ``latest.json`` is replaced atomically afterwards, so a run killed at any moment
resumes from its newest complete checkpoint; a failed write (a full disk) removes its
temporary folder and leaves the previous checkpoints as they were. Resuming checks the
newest resumable checkpoint (:func:`checkpoint_problem`) and falls back to the previous one
with a :class:`DamagedCheckpointWarning` if it is damaged.
"""

from __future__ import annotations

import json
import os
import shutil
import tempfile
import time
import warnings
import zipfile
from pathlib import Path
from typing import Any

# the names that the layers below training read a model file by (control.specs) are
# defined with the policies, and are part of this layout: re-exported here
from myoexo.policies.run_files import (
    CHECKPOINTS_DIR,
    CONFIG_FILE,
    MODEL_FILE,
    STATE_FILE,
    VECNORM_FILE,
    read_state,
)
from myoexo.runtime.files import remove_stale_temporaries, write_json_atomic

SESSIONS_FILE = "sessions.jsonl"
EVAL_FILE = "eval.csv"
EVAL_PID_FILE = "eval_pid.json"
LATEST_FILE = "latest.json"
TB_DIR = "tb"

REPLAY_FILE = "replay_buffer.pkl"
#: What makes an on-policy learner's checkpoint resumable (it has no replay buffer; a resumed
#: run starts a new rollout, the one in progress when the checkpoint was written is dropped).
ON_POLICY_FILE = "on_policy.json"
#: The files that make a checkpoint resumable, one per kind of learner.
RESUME_FILES: tuple[str, ...] = (REPLAY_FILE, ON_POLICY_FILE)

_PREFIX = "step_"
_TMP_PREFIX = ".tmp_"
#: Prefix of a damaged checkpoint set aside (not listed as a checkpoint).
DAMAGED_PREFIX = "damaged-"
#: Last byte of a complete pickle (its STOP opcode): a truncated pickle usually lacks it.
_PICKLE_STOP = b"."
#: Members every SB3 ``model.zip`` holds (its parameters as JSON, the policy's weights);
#: an SBX (JAX) model keeps its weights inside ``data``.
MODEL_MEMBERS: tuple[str, ...] = ("data", "policy.pth")
JAX_MODEL_MEMBERS: tuple[str, ...] = ("data",)
#: Resumable checkpoints kept with their replay buffer unless told otherwise.
DEFAULT_KEEP_REPLAY = 2


class DamagedCheckpointWarning(UserWarning):
    """A checkpoint could not be resumed from; the run falls back to an older one."""


def checkpoint_name(num_timesteps: int) -> str:
    """Folder name of the checkpoint at ``num_timesteps`` (sorts by step)."""
    return f"{_PREFIX}{int(num_timesteps):010d}"


def save_checkpoint(
    model: Any,
    run_dir: Path,
    state: dict[str, Any],
    with_replay: bool = True,
    keep_replay: int = DEFAULT_KEEP_REPLAY,
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
    tmp = Path(tempfile.mkdtemp(dir=root, prefix=_TMP_PREFIX))
    try:
        model.save(tmp / MODEL_FILE)
        vec_normalize = model.get_vec_normalize_env()
        if vec_normalize is not None:
            vec_normalize.save(str(tmp / VECNORM_FILE))
        if with_replay and hasattr(model, "save_replay_buffer"):
            model.save_replay_buffer(tmp / REPLAY_FILE)
        elif with_replay:  # on-policy: the model and its statistics are the whole state
            write_json_atomic(tmp / ON_POLICY_FILE, {"rollout": "dropped; resume collects anew"})
        write_json_atomic(tmp / STATE_FILE, state)
    except BaseException:  # e.g. a full disk: no partial checkpoint stays behind
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    if final.exists():
        shutil.rmtree(final)
    os.replace(tmp, final)
    if with_replay:
        write_json_atomic(run_dir / LATEST_FILE, {"checkpoint": final.name, **state})
        for old in resumable_checkpoints(run_dir)[: -max(keep_replay, 1)]:
            for name in RESUME_FILES:
                (old / name).unlink(missing_ok=True)
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
    ckpts = resumable_checkpoints(run_dir) if with_replay else list_checkpoints(run_dir)
    return ckpts[-1] if ckpts else None


def is_resumable(checkpoint: Path) -> bool:
    """Whether a checkpoint holds what resuming needs (a replay buffer, or an on-policy
    learner's marker)."""
    return any((Path(checkpoint) / name).is_file() for name in RESUME_FILES)


def resumable_checkpoints(run_dir: Path) -> list[Path]:
    """Checkpoints of a run that can be resumed from (:func:`is_resumable`), oldest first."""
    return [p for p in list_checkpoints(run_dir) if is_resumable(p)]


def _pickle_problem(path: Path) -> str | None:
    if not path.is_file():
        return f"{path.name} is missing"
    size = path.stat().st_size
    if size == 0:
        return f"{path.name} is empty"
    with open(path, "rb") as f:
        f.seek(size - 1)
        if f.read(1) != _PICKLE_STOP:
            return f"{path.name} is truncated"
    return None


def _model_members(checkpoint: Path) -> tuple[str, ...]:
    """The members ``model.zip`` of *checkpoint* must hold, by its run's algorithm."""
    from myoexo.policies.algorithms import ALGORITHMS

    try:
        algorithm = read_run_config(checkpoint.parent.parent).algorithm
    except (OSError, ValueError, KeyError, TypeError):
        return MODEL_MEMBERS
    known = ALGORITHMS.get(str(algorithm).lower())
    return JAX_MODEL_MEMBERS if known is not None and known.framework == "jax" else MODEL_MEMBERS


def checkpoint_problem(checkpoint: Path, with_replay: bool = True) -> str | None:
    """Why ``checkpoint`` cannot be resumed from, or ``None`` if it looks intact.

    Checks: ``state.json`` parses and holds the step counter; ``model.zip`` is a readable
    zip (every member's CRC) with SB3's members (:data:`MODEL_MEMBERS`); the replay buffer
    (if ``with_replay``) and the normalization statistics (if present) are complete pickles
    (their last byte). Loading them is the final check
    (:func:`myoexo.training.train.resume` falls back on a failure there too).
    """
    checkpoint = Path(checkpoint)
    try:
        state = read_state(checkpoint)
        int(state["num_timesteps"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        return f"{STATE_FILE} is unreadable ({type(exc).__name__}: {exc})"
    try:
        with zipfile.ZipFile(checkpoint / MODEL_FILE) as z:
            bad = z.testzip()
            missing = sorted(set(_model_members(checkpoint)) - set(z.namelist()))
        if bad is not None:
            return f"{MODEL_FILE} member {bad} is corrupt"
        if missing:  # e.g. cut inside an embedded torch archive, read as the whole zip
            return f"{MODEL_FILE} lacks {missing}"
    except (OSError, zipfile.BadZipFile, EOFError) as exc:
        return f"{MODEL_FILE} is not a readable zip ({type(exc).__name__}: {exc})"
    if with_replay and not (checkpoint / ON_POLICY_FILE).is_file():
        problem = _pickle_problem(checkpoint / REPLAY_FILE)
        if problem:
            return problem
    if (checkpoint / VECNORM_FILE).exists():
        return _pickle_problem(checkpoint / VECNORM_FILE)
    return None


def set_aside(checkpoint: Path, reason: str) -> Path:
    """Rename a damaged checkpoint to ``damaged-<name>-<UTC time>`` (kept for inspection, no
    longer listed) and warn with ``reason``; returns its new path."""
    checkpoint = Path(checkpoint)
    stamp = time.strftime("%Y%m%dT%H%M%SZ", time.gmtime())
    aside = checkpoint.with_name(f"{DAMAGED_PREFIX}{checkpoint.name}-{stamp}")
    os.replace(checkpoint, aside)
    warnings.warn(
        f"checkpoint {checkpoint} is damaged ({reason}); set aside as {aside.name}, "
        "falling back to the previous checkpoint",
        DamagedCheckpointWarning,
        stacklevel=2,
    )
    return aside


def clean_interrupted_writes(run_dir: Path) -> int:
    """Delete what writes cut short by a kill left in a run folder (temporary checkpoint
    folders, temporary files, a partial last log line); returns how many. Call it while
    holding the folder's lock."""
    run_dir = Path(run_dir)
    n = 0
    root = run_dir / CHECKPOINTS_DIR
    if root.is_dir():
        for stale in root.glob(f"{_TMP_PREFIX}*"):
            if stale.is_dir():
                shutil.rmtree(stale, ignore_errors=True)
                n += 1
    for pattern in (".tmp-*", f"{CHECKPOINTS_DIR}/.tmp-*"):
        n += remove_stale_temporaries(run_dir, pattern)
    for name in (SESSIONS_FILE, EVAL_FILE):
        n += trim_partial_line(run_dir / name)
    return n


def clear_run_outputs(run_dir: Path) -> int:
    """Delete what a training session writes in a run folder (checkpoints, logs,
    evaluations), keeping ``config.json`` and the lock file; returns how many entries."""
    run_dir = Path(run_dir)
    n = 0
    for name in (CHECKPOINTS_DIR, TB_DIR):
        if (run_dir / name).is_dir():
            shutil.rmtree(run_dir / name)
            n += 1
    files = [run_dir / name for name in (LATEST_FILE, SESSIONS_FILE, EVAL_FILE, EVAL_PID_FILE)]
    files += [*run_dir.glob("progress_*.csv"), *run_dir.glob(".tmp-*")]
    for path in files:
        if path.is_file():
            path.unlink()
            n += 1
    return n


def trim_partial_line(path: Path) -> int:
    """Cut an unfinished last line (an append cut short by a kill) from a text file that is
    only ever appended to; returns 1 if it did."""
    if not path.is_file():
        return 0
    data = path.read_bytes()
    if not data or data.endswith(b"\n"):
        return 0
    with open(path, "r+b") as f:
        f.truncate(data.rfind(b"\n") + 1)
    return 1


def record_selection(checkpoint: Path, root_seed: int) -> None:
    """Record in a checkpoint's ``state.json`` that it was selected on the subjects of
    *root_seed* (``selection_root_seed``; atomic rewrite)."""
    state = read_state(checkpoint)
    state["selection_root_seed"] = int(root_seed)
    write_json_atomic(Path(checkpoint) / STATE_FILE, state)


def read_config(run_dir: Path) -> dict[str, Any]:
    """The ``config.json`` of a run; ``ValueError`` if the folder holds no run."""
    path = Path(run_dir) / CONFIG_FILE
    if not path.is_file():
        raise ValueError(f"{str(run_dir)!r} is not a training run folder (no {CONFIG_FILE})")
    return json.loads(path.read_text())


def read_run_config(run_dir: Path) -> Any:
    """The :class:`~myoexo.training.config.TrainConfig` of a run (its ``config.json``; one
    written before the config held ``algorithm_kwargs`` is converted,
    :func:`~myoexo.training.config.config_from_record`); ``ValueError`` if the folder holds
    no run."""
    from myoexo.training.config import config_from_record

    return config_from_record(read_config(run_dir))


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
