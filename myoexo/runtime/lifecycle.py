"""Long runs: one writer per folder, a graceful stop on SIGTERM / SIGINT, and worker
processes that end with their parent.

* :class:`FolderLock`: an OS-level exclusive lock (``fcntl.flock``) on ``<folder>/.myoexo.lock``
  held while an evaluation or a training writes into the folder. The kernel releases it when
  the holder's process ends, however it ends (kill -9 included), so there is no stale lock
  to clean up. The file records the holder (pid, host, start time, command); a second run
  into the same folder stops at once with :class:`FolderInUseError`, a ``ValueError`` (the
  CLI prints it as one line, exit status 2). The file itself stays (deleting it would let
  two processes lock two different files of the same name).
* :class:`StopSignals`: while active, the first SIGINT or SIGTERM is only recorded; the run
  polls :attr:`StopSignals.received`, stops at the next safe point and saves what it has.
  After that first signal the previous handlers are back, so a second signal acts as it
  would without myoexo (``KeyboardInterrupt`` for SIGINT, termination for SIGTERM): an
  impatient user is never stuck. A signal that the process ignores (``SIG_IGN``, e.g.
  SIGINT in a background job of a script) stays ignored.
* :func:`die_with_parent`: called in a worker process, makes it end when the process that
  started it ends, even by kill -9 (Linux: ``prctl(PR_SET_PDEATHSIG, SIGKILL)``; every
  platform: a daemon thread that polls ``os.getppid()``).
* :func:`process_map`: ``map`` over a few spawned worker processes, in order.

Exit statuses of a run stopped by a signal follow the shell's convention, 128 + the signal
number (:func:`signal_exit_status`): 130 for SIGINT, 143 for SIGTERM.
"""

from __future__ import annotations

import contextlib
import ctypes
import json
import os
import shlex
import signal
import socket
import sys
import threading
import time
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import FrameType, TracebackType
from typing import Any

try:  # POSIX
    import fcntl
except ImportError:  # pragma: no cover - Windows: no folder locks (documented)
    fcntl = None  # type: ignore[assignment]

#: Name of the lock file in a folder being written.
LOCK_FILE = ".myoexo.lock"

#: Signals that stop a run gracefully.
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM)

#: Exit status of a process ended by a signal: this base + the signal number (shell rule).
SIGNAL_EXIT_BASE = 128

#: Seconds between two checks of the parent pid by a worker's watchdog thread.
PARENT_POLL_S = 0.5

#: Exit status of a worker that found its parent gone.
ORPHAN_EXIT_STATUS = 1

#: ``PR_SET_PDEATHSIG`` of ``<linux/prctl.h>``: the signal a process gets when its parent dies.
_PR_SET_PDEATHSIG = 1


# ----------------------------------------------------------------------------- folder lock
class FolderInUseError(ValueError):
    """Another process writes into the folder (a user error: one line, exit status 2)."""


@dataclass(frozen=True)
class LockHolder:
    """Who holds a folder's lock, as recorded in its lock file."""

    pid: int | None
    host: str
    started_utc: str
    command: str

    def describe(self) -> str:
        """``pid 123 on host h since 2024-01-01T00:00:00Z (myoexo evaluate ...)``."""
        pid = f"pid {self.pid}" if self.pid is not None else "an unknown process"
        return f"{pid} on host {self.host} since {self.started_utc} ({self.command})"


def read_lock_holder(folder: str | os.PathLike[str]) -> LockHolder | None:
    """The holder recorded in ``folder``'s lock file (``None``: none recorded or unreadable).

    The record is informative only: whether the lock is held is the kernel's business.
    """
    try:
        data = json.loads((Path(folder) / LOCK_FILE).read_text())
        return LockHolder(
            pid=int(data["pid"]) if data.get("pid") is not None else None,
            host=str(data.get("host", "?")),
            started_utc=str(data.get("started_utc", "?")),
            command=str(data.get("command", "?")),
        )
    except (OSError, ValueError, KeyError, TypeError):
        return None


def _current_command() -> str:
    argv = list(sys.argv)
    if argv and argv[0].endswith(("myoexo/cli.py", "myoexo/__main__.py")):
        argv[0] = "myoexo"
    return shlex.join(argv) if argv else "python"


class FolderLock:
    """Exclusive lock of a folder for one writing process (a context manager).

    Args:
        folder: The folder (must exist).
        what: What the folder is, for the error message (``"evaluation folder"`` ...).
        command: Recorded as the holder's command (default: this process's ``sys.argv``).

    Raises:
        FolderInUseError: On :meth:`acquire`, if another process holds the lock; the message
            names it.
    """

    #: Folders locked by this process (a second lock of one of them would fail on itself).
    _held: set[Path] = set()  # noqa: RUF012 - shared by design

    def __init__(
        self,
        folder: str | os.PathLike[str],
        what: str = "folder",
        command: str | None = None,
    ) -> None:
        self.folder = Path(folder)
        self.what = what
        self.command = command if command is not None else _current_command()
        self._fd: int | None = None

    @property
    def path(self) -> Path:
        """The lock file."""
        return self.folder / LOCK_FILE

    def acquire(self) -> None:
        """Take the lock, or raise :class:`FolderInUseError` at once (never waits)."""
        key = self.folder.resolve()
        if key in FolderLock._held:
            raise FolderInUseError(
                f"{self.what} {str(self.folder)!r} is already being written by this process"
            )
        if fcntl is None:  # pragma: no cover - no flock on this platform
            FolderLock._held.add(key)
            return
        fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o644)
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            os.close(fd)
            holder = read_lock_holder(self.folder)
            who = holder.describe() if holder else "another process (not recorded yet)"
            raise FolderInUseError(
                f"{self.what} {str(self.folder)!r} is in use by {who}; wait for that run to "
                "end or stop it, or choose another folder"
            ) from None
        self._fd = fd
        FolderLock._held.add(key)
        record = {
            "pid": os.getpid(),
            "host": socket.gethostname(),
            "started_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            "command": self.command,
        }
        with contextlib.suppress(OSError):  # e.g. a full disk: the lock itself holds
            os.ftruncate(fd, 0)
            os.pwrite(fd, (json.dumps(record) + "\n").encode(), 0)

    def release(self) -> None:
        """Release the lock (the file stays, emptied)."""
        FolderLock._held.discard(self.folder.resolve())
        if self._fd is None:
            return
        fd, self._fd = self._fd, None
        with contextlib.suppress(OSError):
            os.ftruncate(fd, 0)
        os.close(fd)  # closing the descriptor releases the flock

    def __enter__(self) -> FolderLock:
        self.acquire()
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.release()


# ----------------------------------------------------------------------------- signals
def signal_exit_status(signum: int) -> int:
    """Exit status of a run stopped by ``signum``: 128 + its number (130 SIGINT, 143 SIGTERM)."""
    return SIGNAL_EXIT_BASE + int(signum)


class StopSignals:
    """Record the first SIGINT / SIGTERM instead of dying (a context manager).

    Handlers can only be installed from the main thread; elsewhere this does nothing and
    the signals keep their usual effect. See the module docstring for the second signal.

    Args:
        signals: The signals handled.
        enabled: ``False``: install nothing (the caller opted out).
    """

    def __init__(
        self, signals: Iterable[signal.Signals] = STOP_SIGNALS, enabled: bool = True
    ) -> None:
        self.signals = tuple(signals)
        self.enabled = enabled
        self.received: int | None = None
        self._previous: dict[signal.Signals, Any] = {}

    @property
    def name(self) -> str | None:
        """Name of the signal received (``"SIGTERM"``), or ``None``."""
        return signal.Signals(self.received).name if self.received is not None else None

    def _handle(self, signum: int, frame: FrameType | None) -> None:
        if self.received is None:
            self.received = signum
        self._restore()  # a second signal acts as usual

    def _restore(self) -> None:
        for sig, previous in self._previous.items():
            with contextlib.suppress(ValueError, TypeError):
                signal.signal(sig, previous if previous is not None else signal.SIG_DFL)
        self._previous.clear()

    def __enter__(self) -> StopSignals:
        if not self.enabled or threading.current_thread() is not threading.main_thread():
            return self
        for sig in self.signals:
            previous = signal.getsignal(sig)
            if previous == signal.SIG_IGN:
                continue  # an ignored signal stays ignored
            self._previous[sig] = previous
            signal.signal(sig, self._handle)
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self._restore()


def ignore_signals(signals: Iterable[signal.Signals] = (signal.SIGINT,)) -> None:
    """In a worker process: leave these signals to the parent, which stops its workers itself
    (a Ctrl-C reaches every process of the terminal's foreground group).

    The evaluation's pool workers ignore SIGINT only: the pool stops a broken worker with
    SIGTERM. The training's env workers (``SubprocVecEnv``) ignore both: they end when their
    parent closes (or loses) the pipe to them.
    """
    for sig in signals:
        signal.signal(sig, signal.SIG_IGN)


# ----------------------------------------------------------------------------- orphans
def _set_parent_death_signal() -> bool:
    """Linux: have the kernel send SIGKILL to this process when its parent ends."""
    if not sys.platform.startswith("linux"):
        return False
    try:
        libc = ctypes.CDLL(None, use_errno=True)  # the running process: libc included
        return int(libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)) == 0
    except (OSError, AttributeError):
        return False


def _watch_parent(parent_pid: int, poll_s: float) -> None:
    while True:
        if os.getppid() != parent_pid:
            os._exit(ORPHAN_EXIT_STATUS)
        time.sleep(poll_s)


def die_with_parent(parent_pid: int, poll_s: float = PARENT_POLL_S) -> None:
    """End this process when its parent ``parent_pid`` ends (call it in a worker).

    Two mechanisms: on Linux, ``prctl(PR_SET_PDEATHSIG, SIGKILL)`` (immediate; the kernel
    sends it when the thread that started the worker ends, so start workers from a thread
    that outlives them, as the evaluation engine does from its main thread); everywhere, a
    daemon thread that checks every ``poll_s`` whether ``os.getppid()`` still is
    ``parent_pid`` and calls ``os._exit`` if not. A worker whose parent is already gone
    exits at once. A chunk being written when it ends leaves only a temporary file, removed
    by the next run.
    """
    _set_parent_death_signal()
    if os.getppid() != parent_pid:  # the parent died before the death signal was armed
        os._exit(ORPHAN_EXIT_STATUS)
    watchdog = threading.Thread(
        target=_watch_parent, args=(parent_pid, poll_s), name="myoexo-parent-watch", daemon=True
    )
    watchdog.start()


def process_map(
    fn: Callable[[Any], Any],
    items: Sequence[Any],
    workers: int,
    initializer: Callable[..., None] | None = None,
    initargs: tuple[Any, ...] = (),
) -> Iterator[Any]:
    """``fn`` of each of *items*, in their order, each as it is ready: on up to *workers*
    spawned processes (each started with ``initializer(*initargs)``), or in this process
    when one would do (one worker, or one item). *fn* and the items must pickle."""
    n = min(workers, len(items))
    if n <= 1:
        yield from map(fn, items)
        return
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor

    context = mp.get_context("spawn")
    with ProcessPoolExecutor(
        n, mp_context=context, initializer=initializer, initargs=initargs
    ) as pool:
        yield from pool.map(fn, items)
