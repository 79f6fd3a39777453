"""Files that survive a kill: atomic writes, and the provenance record of a run.

Every file myoexo writes for later reading (evaluation chunks and tables, run configs,
checkpoint states) goes through :func:`atomic_path`: the content is written to a temporary
file in the same folder, with a name unique to the writing process, and renamed into place.
A reader therefore sees either the old file or the complete new one, never a partial one, and
two processes writing the same file never share a temporary name. The file ends with the
permissions a plain ``open(path, "w")`` would give it (``0o666`` less the process's umask),
not the owner-only ones of the temporary.
"""

from __future__ import annotations

import argparse
import contextlib
import hashlib
import json
import os
import platform
import tempfile
import threading
from collections.abc import Iterator, Mapping
from importlib import metadata
from pathlib import Path
from typing import Any

import numpy as np

#: Packages whose versions a run records (evaluation ``config.json``, training config).
RECORDED_PACKAGES: tuple[str, ...] = (
    "myoexo",
    "myosuite",
    "mujoco",
    "gymnasium",
    "numpy",
    "stable-baselines3",
    "torch",
)


_UMASK_LOCK = threading.Lock()


def output_folder(text: str) -> Path:
    """An ``--out FOLDER`` of the command line (an argparse ``type``): a folder that exists or
    can be made, checked when the command line is read, before any work. Raises
    ``argparse.ArgumentTypeError`` (reported as one line naming the option) when the path,
    or the nearest of its parents that exists, is not a folder."""
    path = Path(text)
    existing = next((p for p in (path, *path.parents) if p.exists()), None)
    if existing is not None and not existing.is_dir():
        what = "is a file" if existing == path else f"is under a file, {str(existing)!r}"
        raise argparse.ArgumentTypeError(f"{text!r} {what}: name a folder (it is made if missing)")
    return path


def current_umask() -> int:
    """The process's file-creation mask, read without changing it where the system tells
    (Linux' ``/proc/self/status``), else set and restored at once under a lock."""
    try:
        with open("/proc/self/status") as f:
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    with _UMASK_LOCK:
        mask = os.umask(0o022)
        os.umask(mask)
    return mask


def default_file_mode() -> int:
    """Permissions of a file created by a plain ``open()`` now: ``0o666 & ~umask``."""
    return 0o666 & ~current_umask()


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike[str]) -> Iterator[Path]:
    """Yield a temporary path beside ``path``; on success rename it onto ``path``.

    The temporary name starts with ``.tmp-`` and is unique per call (``tempfile.mkstemp``),
    so concurrent writers never collide; on any exception (a full disk included) it is
    removed and ``path`` is left as it was; an ``OSError`` without a file name gets
    ``path``'s. The parent folder is created if missing. Before the rename the file gets
    :func:`default_file_mode` (``mkstemp`` creates it readable by its owner only).
    """
    final = Path(path)
    final.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp_name = tempfile.mkstemp(dir=final.parent, prefix=f".tmp-{final.name}.")
    os.close(fd)
    tmp = Path(tmp_name)
    try:
        yield tmp
        os.chmod(tmp, default_file_mode())
        os.replace(tmp, final)
    except BaseException as exc:
        tmp.unlink(missing_ok=True)
        if isinstance(exc, OSError) and exc.filename is None:
            exc.filename = str(final)  # name the file in messages (e.g. a full disk)
        raise


def write_text_atomic(path: str | os.PathLike[str], text: str) -> None:
    """Write ``text`` to ``path`` atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_study_files(folder: str | os.PathLike[str], files: Mapping[str, Any]) -> list[Path]:
    """Write a study's outputs into *folder* (created if missing), each atomically: name ->
    text (a ``str``) or table (anything with ``to_csv``, written without its index).

    Returns:
        The paths written, in the order given.
    """
    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for name, content in files.items():
        path = out / name
        if isinstance(content, str):
            write_text_atomic(path, content)
        else:
            with atomic_path(path) as tmp:
                content.to_csv(tmp, index=False)
        paths.append(path)
    return paths


def write_json_atomic(path: str | os.PathLike[str], data: Any, indent: int = 1) -> None:
    """Write ``data`` as JSON (and a final newline) to ``path`` atomically."""
    write_text_atomic(path, json.dumps(data, indent=indent) + "\n")


def savez_atomic(path: str | os.PathLike[str], **arrays: Any) -> None:
    """``numpy.savez_compressed`` to ``path`` atomically."""
    with atomic_path(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, **arrays)


def remove_stale_temporaries(folder: str | os.PathLike[str], pattern: str = "**/.tmp-*") -> int:
    """Delete temporaries left by writes cut short by a kill; returns how many."""
    n = 0
    for stale in Path(folder).glob(pattern):
        if stale.is_file():
            stale.unlink(missing_ok=True)
            n += 1
    return n


def package_versions() -> dict[str, str]:
    """Python's and :data:`RECORDED_PACKAGES`' versions (``"not installed"`` if absent)."""
    out = {"python": platform.python_version()}
    for name in RECORDED_PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


def file_sha256(path: str | os.PathLike[str]) -> str:
    """The sha256 hex digest of the file *path* (read in 1 MiB blocks): a file's identity
    in a provenance record."""
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()
