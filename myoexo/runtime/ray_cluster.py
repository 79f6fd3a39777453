"""Ray for the distributed commands (``myoexo evaluate --backend ray``, ``myoexo policy sweep``).

Ray is an optional extra (``pip install 'myoexo[ray]'``); nothing in myoexo imports it
until one of these commands runs, and :func:`require_ray` turns its absence into a one-line
error.

:func:`ray_session` connects a command to Ray in one of three ways:

* an address (``--address HOST:6379``, ``--address auto``, or the ``RAY_ADDRESS``
  environment variable): join that cluster. The driver only submits work; when it exits or
  dies, Ray cancels its tasks and actors on the cluster, which keeps running.
* no address: start a local cluster of ``num_cpus`` CPUs owned by this driver. Ray ties its
  core processes (GCS, raylet, workers) to the driver, but after a ``SIGKILL`` of the driver
  its two agent processes (dashboard and runtime-env agents) outlive it for about a minute
  (their last message to the dead GCS waits for Ray's reconnection timeout). So on Linux the
  driver also starts a small watchdog (:func:`_watch`, a standard-library script in its own
  session, so that a Ctrl-C does not reach it first) holding the read end of a pipe: when
  the driver exits, however it exits, the pipe closes and the watchdog ends every process of
  that cluster (:func:`cluster_processes`: the processes that inherited the cluster's token
  in their environment, :data:`OWNER_ENV`, and their descendants).
* Ray already initialized in this process (a notebook, a test, a benchmark): use it as is
  and leave it running.
"""

from __future__ import annotations

import contextlib
import logging
import os
import select
import signal
import subprocess
import sys
import time
import uuid
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

#: Environment variable that marks the processes of a local cluster started by a driver; its
#: value is a token unique to that cluster.
OWNER_ENV = "MYOEXO_RAY_CLUSTER"

#: Object store of a local cluster: the tasks return a few numbers and write their results
#: to files, while Ray's default reserves 30 % of the machine's memory.
LOCAL_OBJECT_STORE_BYTES = 256 * 2**20

#: Seconds the watchdog waits for the killed processes to go.
WATCHDOG_TIMEOUT_S = 2.0

#: Polling period of the watchdog while it waits for processes to exit.
WATCHDOG_POLL_S = 0.05

#: Period of the watchdog's census of the cluster's processes while the driver lives.
WATCHDOG_SCAN_S = 0.5

#: How to install the extra, for error messages.
INSTALL_HINT = "pip install 'myoexo[ray]'"


def require_ray(what: str = "this command") -> ModuleType:
    """The ``ray`` module, or ``ValueError`` (a one-line user error) if it is not installed.

    Args:
        what: What needs Ray, for the message (e.g. ``"--backend ray"``).
    """
    try:
        import ray
    except ImportError:
        raise ValueError(f"{what} needs Ray, which is not installed: {INSTALL_HINT}") from None
    return ray


def resolve_address(address: str | None) -> str | None:
    """The cluster to join: ``address``, else ``$RAY_ADDRESS``, else ``None`` (start a
    local cluster)."""
    return address or os.environ.get("RAY_ADDRESS") or None


@contextlib.contextmanager
def ray_session(
    num_cpus: int | None = None, address: str | None = None, what: str = "this command"
) -> Iterator[ModuleType]:
    """Ray connected for the duration of the ``with`` block (see the module docstring).

    Args:
        num_cpus: CPUs of a local cluster (default: Ray's count of this machine's cores);
            ignored when joining a cluster (its nodes declare their CPUs).
        address: Cluster to join (:func:`resolve_address`); ``None`` and no
            ``RAY_ADDRESS``: start a local cluster that dies with this process.
        what: What needs Ray, for the message if it is missing.

    Yields:
        The ``ray`` module, initialized.
    """
    ray = require_ray(what)
    if ray.is_initialized():
        yield ray
        return
    target = resolve_address(address)
    if target is not None:
        try:
            ray.init(address=target, logging_level=logging.WARNING)
        except ConnectionError as exc:
            cause = f" ({_first_line(exc.__cause__)})" if exc.__cause__ is not None else ""
            raise ValueError(f"cannot join the Ray cluster at {target!r}: {exc}{cause}") from exc
        try:
            yield ray
        finally:
            ray.shutdown()
        return
    watchdog, token = _start_watchdog()
    try:
        previous = os.environ.get(OWNER_ENV)
        os.environ[OWNER_ENV] = token  # inherited by every process of the cluster
        try:
            ray.init(
                address="local",  # a new cluster, even if `ray start` runs on this machine
                num_cpus=num_cpus,
                num_gpus=0,
                include_dashboard=False,
                object_store_memory=LOCAL_OBJECT_STORE_BYTES,
                logging_level=logging.WARNING,
            )
        finally:
            if previous is None:
                os.environ.pop(OWNER_ENV, None)
            else:
                os.environ[OWNER_ENV] = previous
        try:
            yield ray
        finally:
            ray.shutdown()
    finally:
        _stop_watchdog(watchdog)


def _first_line(exc: BaseException) -> str:
    text = str(exc).strip()
    return text.splitlines()[0] if text else type(exc).__name__


def _start_watchdog() -> tuple[subprocess.Popen[bytes] | None, str]:
    """The watchdog of a new local cluster (Linux; elsewhere Ray's own fate-sharing only)
    and the cluster's token."""
    token = f"{os.getpid()}-{uuid.uuid4().hex}"
    if not sys.platform.startswith("linux"):
        return None, token
    proc = subprocess.Popen(
        # run as a script in isolated mode: the standard library only, no package import
        [sys.executable, "-I", str(Path(__file__).resolve()), token],
        stdin=subprocess.PIPE,
        start_new_session=True,  # a Ctrl-C in the terminal must not stop it first
        env={k: v for k, v in os.environ.items() if k != OWNER_ENV},
    )
    return proc, token


def _stop_watchdog(proc: subprocess.Popen[bytes] | None) -> None:
    """Close the pipe (the watchdog then ends what is left of the cluster) and reap it."""
    if proc is None:
        return
    if proc.stdin is not None:
        proc.stdin.close()
    with contextlib.suppress(subprocess.TimeoutExpired):
        proc.wait(timeout=WATCHDOG_TIMEOUT_S + 1.0)


def _read_stat(proc_dir: Path) -> tuple[str, int, str] | None:
    """``(state, parent pid, start time)`` of a process from ``/proc/<pid>/stat``."""
    try:
        fields = (proc_dir / "stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    # fields 3, 4 and 22 of proc(5): state, ppid, starttime (the name may hold spaces)
    return fields[0], int(fields[1]), fields[19]


def cluster_processes(token: str, proc_root: Path = Path("/proc")) -> dict[int, str]:
    """The live processes of cluster ``token`` (Linux): those whose environment holds
    ``OWNER_ENV=token`` and all their descendants (Ray's agents rewrite their process title,
    which hides their environment, but they are children of the marked raylet).

    Returns:
        PID -> start time (clock ticks after boot), which tells a reused PID apart.
    """
    entry = f"{OWNER_ENV}={token}".encode()
    me = os.getpid()
    stats: dict[int, tuple[str, int, str]] = {}
    marked: list[int] = []
    for path in proc_root.glob("[0-9]*"):
        pid = int(path.name)
        stat = _read_stat(path)
        if pid == me or stat is None or stat[0] == "Z":  # a zombie is already dead
            continue
        stats[pid] = stat
        try:
            if entry in (path / "environ").read_bytes().split(b"\0"):
                marked.append(pid)
        except OSError:  # gone, or not ours
            continue
    children: dict[int, list[int]] = {}
    for pid, (_, ppid, _) in stats.items():
        children.setdefault(ppid, []).append(pid)
    found: dict[int, str] = {}
    stack = list(marked)
    while stack:
        pid = stack.pop()
        if pid not in found:
            found[pid] = stats[pid][2]
            stack.extend(children.get(pid, ()))
    return found


def _still_there(pid: int, start_time: str, proc_root: Path = Path("/proc")) -> bool:
    stat = _read_stat(proc_root / str(pid))
    return stat is not None and stat[0] != "Z" and stat[2] == start_time


def end_processes(processes: dict[int, str], timeout_s: float = WATCHDOG_TIMEOUT_S) -> None:
    """SIGKILL the processes (PID -> start time) still running and wait up to ``timeout_s``
    for them to go. Their driver is gone, so nothing of theirs is worth a graceful end (the
    files myoexo writes are written atomically)."""

    def left() -> list[int]:
        return [pid for pid, t in processes.items() if _still_there(pid, t)]

    for pid in left():
        with contextlib.suppress(OSError):
            os.kill(pid, signal.SIGKILL)
    deadline = time.monotonic() + timeout_s
    while left() and time.monotonic() < deadline:
        time.sleep(WATCHDOG_POLL_S)


def _watch(token: str) -> None:
    """Watchdog: note the cluster's processes every :data:`WATCHDOG_SCAN_S` until the
    driver's end (end of file on stdin), then end them all."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    seen: dict[int, str] = {}
    fd = sys.stdin.fileno()
    while True:
        seen.update(cluster_processes(token))
        ready, _, _ = select.select([fd], [], [], WATCHDOG_SCAN_S)
        if ready and not os.read(fd, 1 << 12):
            break
    seen.update(cluster_processes(token))
    end_processes(seen)


if __name__ == "__main__" and sys.platform.startswith("linux"):
    _watch(sys.argv[1])
