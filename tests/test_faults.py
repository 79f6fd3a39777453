"""Fault injection on long runs: kill -9 at random points, SIGTERM / SIGINT, two runs on one
folder, damaged checkpoints and chunks, a full disk, and orphaned worker processes.

What each fault may cost is in ``docs/long_runs.md``; these tests check it. The random kill
points come from a seeded generator (the seed is printed) so that a failure can be replayed.
"""

from __future__ import annotations

import errno
import importlib
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from myoexo.cli import EXIT_NO_SPACE
from myoexo.cli import main as cli_main
from myoexo.envs.options import TwinOptions
from myoexo.evaluation import EvaluationConfig, evaluate
from myoexo.evaluation.storage import chunk_done
from myoexo.runtime.lifecycle import LOCK_FILE, FolderLock, StopSignals, signal_exit_status
from myoexo.training import checkpoints as ck
from myoexo.training import get_preset, resume, train

#: Seed of the random kill points (change it to explore other points).
KILL_SEED = 20240611
#: Kills per kill -9 test.
N_KILLS = 3
#: Seconds a started command may take to reach the point where a test interrupts it.
START_TIMEOUT_S = 120.0
#: Seconds a signalled command may take to stop.
STOP_TIMEOUT_S = 60.0
#: Seconds the workers of a killed evaluation driver may take to end.
ORPHAN_TIMEOUT_S = 5.0
#: Seconds between two polls of a folder.
POLL_S = 0.02

#: The evaluation of the kill tests: 12 chunks of one half-second episode.
EVAL_ARGS = [
    "--controllers",
    "pid",
    "--levels",
    "0",
    "1",
    "--subjects",
    "6",
    "--episode-duration-s",
    "0.5",
    "--chunk-size",
    "1",
    "--workers",
    "2",
    "--no-progress",
]
EVAL_CONFIG = EvaluationConfig(
    controllers=("pid",),
    levels=(0, 1),
    subjects=6,
    twin=TwinOptions().replace(episode_duration_s=0.5),
    chunk_size=1,
)
#: A longer one (60 chunks), for the tests that interrupt a run in progress ...
LONG_EVAL_ARGS = [*EVAL_ARGS]
LONG_EVAL_ARGS[LONG_EVAL_ARGS.index("--subjects") + 1] = "30"
#: ... and one with 2-s episodes, killed by its test, that cannot end while it is checked.
ENDLESS_EVAL_ARGS = [*LONG_EVAL_ARGS]
ENDLESS_EVAL_ARGS[ENDLESS_EVAL_ARGS.index("--episode-duration-s") + 1] = "2"

#: Tiny training settings (as in tests/test_training.py): half-second episodes, a checkpoint
#: every 100 steps, no periodic evaluation.
TINY_TRAIN = {
    "episode_duration_s": 0.5,
    "n_envs": 2,
    "checkpoint_every_s": 0.0,
    "checkpoint_every_steps": 100,
    "eval_every_steps": 0,
}
TINY_KWARGS = {"buffer_size": 2_000, "batch_size": 32, "learning_starts": 100}
TINY_TRAIN_SETS = [
    *(arg for k, v in TINY_TRAIN.items() for arg in (f"--{k.replace('_', '-')}", str(v))),
    "--algorithm-kwargs",
    ",".join(f"{k}={v}" for k, v in TINY_KWARGS.items()),
]


# ----------------------------------------------------------------------------- helpers
def _default_sigint() -> None:  # pragma: no cover - runs in the child before exec
    """A child started from a background job would inherit an ignored SIGINT."""
    signal.signal(signal.SIGINT, signal.SIG_DFL)


@pytest.fixture
def spawn(tmp_path):
    """Start ``python -m myoexo.cli ARGS`` with its output in files; kill (by pid) whatever
    is still running at the end of the test."""
    started: list[subprocess.Popen] = []

    def start(args: list[str], name: str = "cmd") -> subprocess.Popen:
        out = open(tmp_path / f"{name}-{len(started)}.out", "w")
        err = open(tmp_path / f"{name}-{len(started)}.err", "w")
        proc = subprocess.Popen(
            [sys.executable, "-m", "myoexo.cli", *args],
            stdout=out,
            stderr=err,
            preexec_fn=_default_sigint,
            env={**os.environ, "MYOEXO_DEBUG": ""},
        )
        proc.out_path, proc.err_path = Path(out.name), Path(err.name)
        out.close()
        err.close()
        started.append(proc)
        return proc

    yield start
    for proc in started:
        if proc.poll() is None:
            proc.kill()
            proc.wait()


def _wait_for(condition, proc: subprocess.Popen | None = None, timeout: float = START_TIMEOUT_S):
    """Poll ``condition()`` until true; False if ``proc`` ended first."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if condition():
            return True
        if proc is not None and proc.poll() is not None:
            return bool(condition())
        time.sleep(POLL_S)
    raise AssertionError("timed out")


def _chunks(out: Path) -> list[Path]:
    return sorted(out.glob("traces/*/L*/0*.npz"))


def _temporaries(folder: Path) -> list[Path]:
    return [p for p in folder.rglob("*") if p.name.startswith((".tmp-", ".tmp_"))]


def _proc_stat(pid: int) -> tuple[str, int] | None:
    """``(state, parent pid)`` of a process from ``/proc`` (Linux), ``None`` if gone."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    state, ppid = text[text.rindex(")") + 2 :].split()[:2]  # after "pid (name) "
    return state, int(ppid)


def _alive(pid: int) -> bool:
    """Whether ``pid`` runs (a zombie, ended but not reaped yet, does not)."""
    try:
        import psutil
    except ImportError:
        stat = _proc_stat(pid)
        return stat is not None and stat[0] != "Z"
    try:
        return psutil.Process(pid).status() != psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return False


def _left_after(pids: list[int], timeout: float = ORPHAN_TIMEOUT_S) -> list[int]:
    """The processes of ``pids`` still running after up to ``timeout`` seconds; those are
    killed (by pid) so that a failing test leaves nothing behind."""
    deadline = time.monotonic() + timeout
    while any(_alive(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(POLL_S)
    left = [pid for pid in pids if _alive(pid)]
    for pid in left:
        os.kill(pid, signal.SIGKILL)
    return left


def _children(pid: int) -> list[int]:
    """Descendants of ``pid`` (psutil, else a scan of ``/proc``)."""
    try:
        import psutil
    except ImportError:
        if not Path("/proc/self/stat").exists():
            pytest.skip("needs psutil or /proc to list processes")
        parents = {}
        for entry in Path("/proc").iterdir():
            if entry.name.isdigit() and (stat := _proc_stat(int(entry.name))) is not None:
                parents[int(entry.name)] = stat[1]
        found, frontier = [], [pid]
        while frontier:
            kids = [p for p, pp in parents.items() if pp in frontier]
            found += kids
            frontier = kids
        return found
    return [c.pid for c in psutil.Process(pid).children(recursive=True)]


def _stderr_line(proc: subprocess.Popen) -> str:
    lines = [ln for ln in proc.err_path.read_text().splitlines() if ln.strip()]
    assert lines, "nothing on stderr"
    assert "Traceback" not in proc.err_path.read_text()
    return lines[-1]


@pytest.fixture(scope="module")
def eval_reference(tmp_path_factory):
    """The uninterrupted table of :data:`EVAL_CONFIG` (in-process: the table does not
    depend on the worker count)."""
    out = tmp_path_factory.mktemp("faults") / "reference"
    return evaluate(EVAL_CONFIG, out, workers=1, progress=False).table


# ----------------------------------------------------------------------------- evaluation
@pytest.mark.slow
def test_kill9_evaluation_at_random_points_then_resume_gives_the_same_table(
    eval_reference, tmp_path, spawn
):
    rng = random.Random(KILL_SEED)
    print(f"kill seed {KILL_SEED}")
    out = tmp_path / "eval"
    cmd = ["evaluate", *EVAL_ARGS, "--out", str(out)]
    landed = 0
    for _ in range(N_KILLS):
        before = len(_chunks(out))
        proc = spawn(cmd, "eval")
        wait_chunks = rng.randint(0, 3)  # 0: during the start-up
        _wait_for(lambda b=before, w=wait_chunks: len(_chunks(out)) >= b + w, proc)
        time.sleep(rng.uniform(0.0, 0.1))
        if proc.poll() is not None:
            break  # finished before the kill point
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        landed += 0 < len(_chunks(out)) < len(eval_reference)
    print(f"{landed} kills landed while chunks were being written")
    assert landed, "no kill landed while chunks were being written"
    assert not (out / "episodes.parquet").exists() or len(_chunks(out)) == len(eval_reference)
    for chunk in _chunks(out):
        assert chunk_done(chunk)  # a kill never leaves a partial chunk under its final name

    final = spawn(cmd, "eval")
    assert final.wait(timeout=START_TIMEOUT_S) == 0, final.err_path.read_text()
    pd.testing.assert_frame_equal(
        pd.read_parquet(out / "episodes.parquet"), eval_reference, check_exact=True
    )
    assert not _temporaries(out)


@pytest.mark.slow
def test_a_second_evaluation_into_a_folder_in_use_stops_and_workers_end_with_a_killed_driver(
    tmp_path, spawn, capsys
):
    out = tmp_path / "eval"
    cmd = ["evaluate", *ENDLESS_EVAL_ARGS, "--out", str(out)]
    proc = spawn(cmd, "eval")
    assert _wait_for(lambda: len(_chunks(out)) >= 1, proc), "the run ended too early"

    # a second run into the same folder stops at once, naming the holder
    assert cli_main(cmd) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("myoexo evaluate: error: evaluation folder")
    assert f"in use by pid {proc.pid} on host" in line and "myoexo evaluate" in line

    children = _children(proc.pid)  # two workers and multiprocessing's resource tracker
    assert len(children) >= 2
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    left = _left_after(children)
    assert not left, f"worker processes {left} outlived their killed driver"


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_stops_an_evaluation_cleanly_and_the_same_command_resumes(
    sig, tmp_path, spawn, capsys
):
    out = tmp_path / "eval"
    cmd = ["evaluate", *LONG_EVAL_ARGS, "--out", str(out)]
    proc = spawn(cmd, "eval")
    assert _wait_for(lambda: len(_chunks(out)) >= 1, proc), "the run ended too early"
    children = _children(proc.pid)
    t0 = time.monotonic()
    proc.send_signal(sig)
    assert proc.wait(timeout=STOP_TIMEOUT_S) == signal_exit_status(sig)
    print(f"stopped {time.monotonic() - t0:.1f} s after {sig.name}")
    line = _stderr_line(proc)
    assert line.startswith(f"myoexo evaluate: stopped by {sig.name}: ")
    assert "run the same command again to continue" in line
    assert not (out / "episodes.parquet").exists()  # no table from a partial run
    assert not _temporaries(out)  # the chunks in flight finished
    stored = _chunks(out)
    assert stored and all(chunk_done(c) for c in stored)
    assert not _left_after(children)  # the pool was shut down

    assert cli_main(cmd) == 0
    table = pd.read_parquet(out / "episodes.parquet")
    assert len(table) == 60 and not table.duplicated(["level", "subject"]).any()
    assert f"({60 - len(stored)} computed now)" in capsys.readouterr().out


def test_a_damaged_chunk_is_recomputed(eval_reference, tmp_path):
    out = tmp_path / "eval"
    config = EvaluationConfig(**{**EVAL_CONFIG.__dict__, "levels": (0,), "subjects": 2})
    evaluate(config, out, workers=1, progress=False)
    first, second = _chunks(out)
    first.write_bytes(first.read_bytes()[: first.stat().st_size // 2])  # truncated
    second.write_bytes(b"")  # emptied
    run = evaluate(config, out, workers=1, progress=False)
    assert run.computed == 2
    expected = eval_reference[eval_reference.level == 0].head(2).reset_index(drop=True)
    pd.testing.assert_frame_equal(run.table, expected, check_exact=True)


def test_a_full_disk_leaves_the_previous_files_and_no_temporary(tmp_path, monkeypatch, capsys):
    out = tmp_path / "eval"
    cmd = ["evaluate", "--controllers", "pid", "--levels", "0", "--subjects", "2"]
    cmd += ["--episode-duration-s", "0.5", "--chunk-size", "1", "--workers", "1"]
    cmd += ["--no-progress", "--out", str(out)]
    assert cli_main(cmd) == 0
    capsys.readouterr()
    first, second = _chunks(out)
    kept = first.read_bytes()
    table = (out / "episodes.parquet").read_bytes()
    second.unlink()

    def full_disk(file, *args, **kwargs):
        file.write(b"PK\x03\x04 partial")  # the start of a zip, then no space left
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(np, "savez_compressed", full_disk)
    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    assert cli_main(cmd) == EXIT_NO_SPACE
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("myoexo evaluate: error: No space left on device")
    assert "run the same command again" in line
    assert not _temporaries(out)
    assert first.read_bytes() == kept and not second.exists()
    assert (out / "episodes.parquet").read_bytes() == table

    # the table itself: the previous one stays whole
    monkeypatch.undo()

    def full_disk_table(self, path, *args, **kwargs):
        Path(path).write_bytes(b"PAR1 partial")
        raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

    monkeypatch.setattr(pd.DataFrame, "to_parquet", full_disk_table)
    assert cli_main(cmd) == EXIT_NO_SPACE
    assert (out / "episodes.parquet").read_bytes() == table and not _temporaries(out)
    monkeypatch.undo()
    assert cli_main(cmd) == 0  # space is back: the same command completes
    assert (out / "episodes.parquet").read_bytes() != b""


# ----------------------------------------------------------------------------- one writer
def test_a_folder_in_use_is_refused_with_the_holder_and_freed_by_its_death(
    tmp_path, capsys, monkeypatch, lock_holder
):
    folder = tmp_path / "busy"
    folder.mkdir()
    with lock_holder(folder, "holder for the test") as holder:
        record = json.loads((folder / LOCK_FILE).read_text())
        assert record["pid"] == holder.pid and record["command"] == "holder for the test"
        assert {"host", "started_utc"} <= set(record)
        monkeypatch.delenv("MYOEXO_DEBUG", raising=False)

        evaluation = ["evaluate", "--controllers", "pid", "--levels", "0", "--subjects", "1"]
        assert cli_main([*evaluation, "--out", str(folder), "--no-progress"]) == 2
        (line,) = capsys.readouterr().err.splitlines()
        assert line.startswith("myoexo evaluate: error: evaluation folder")
        assert f"in use by pid {holder.pid}" in line and "holder for the test" in line
        assert sorted(p.name for p in folder.iterdir()) == [LOCK_FILE]  # nothing written

        config = {"config": get_preset("cpu").to_dict(), "seed": 0}
        (folder / ck.CONFIG_FILE).write_text(json.dumps(config))
        for argv in (
            ["policy", "train", "--resume", str(folder)],
            ["policy", "train", "--run-dir", str(folder)],
        ):
            assert cli_main(argv) == 2
            (line,) = capsys.readouterr().err.splitlines()
            assert line.startswith("myoexo policy train: error: training run folder")
            assert f"in use by pid {holder.pid}" in line
    with FolderLock(folder):  # the lock died with its holder: no stale lock to clean
        assert json.loads((folder / LOCK_FILE).read_text())["pid"] == os.getpid()
    assert (folder / LOCK_FILE).read_text() == ""  # released: no holder recorded


def test_stop_signals_record_the_first_signal_and_restore_the_handlers():
    previous = signal.getsignal(signal.SIGTERM)
    with StopSignals() as stop:
        assert signal.getsignal(signal.SIGTERM) != previous
        os.kill(os.getpid(), signal.SIGTERM)
        deadline = time.monotonic() + 5.0
        while stop.received is None and time.monotonic() < deadline:
            time.sleep(POLL_S)
        assert stop.name == "SIGTERM"
        # a second signal would act as without myoexo: the previous handler is back
        assert signal.getsignal(signal.SIGTERM) == previous
    assert signal.getsignal(signal.SIGTERM) == previous
    old_int = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        with StopSignals():  # an ignored signal stays ignored
            assert signal.getsignal(signal.SIGINT) == signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, old_int)


# ----------------------------------------------------------------------------- training
def _tiny(algorithm_kwargs=None, **changes):
    kwargs = {**TINY_KWARGS, **(algorithm_kwargs or {})}
    return get_preset("cpu", **{**TINY_TRAIN, **changes}, algorithm_kwargs=kwargs)


@pytest.fixture(scope="module")
def tiny_run(tmp_path_factory):
    """A 300-step run: resumable checkpoints at 200 and 300 (the two kept), a snapshot at
    100."""
    run_dir = tmp_path_factory.mktemp("faults") / "run"
    train(_tiny(total_timesteps=300, seed=1), run_dir, verbose=0)
    return run_dir


def _sessions(run_dir: Path) -> list[dict]:
    return [json.loads(s) for s in (run_dir / ck.SESSIONS_FILE).read_text().splitlines()]


@pytest.mark.slow
@pytest.mark.parametrize(
    ("damage", "file"),
    [
        ("truncate", ck.MODEL_FILE),
        ("truncate", ck.STATE_FILE),
        ("truncate", ck.REPLAY_FILE),
        ("garble", ck.REPLAY_FILE),
    ],
)
def test_a_damaged_newest_checkpoint_falls_back_to_the_previous_one(
    tiny_run, tmp_path, damage, file
):
    run_dir = tmp_path / "run"
    shutil.copytree(tiny_run, run_dir)
    newest = run_dir / ck.CHECKPOINTS_DIR / ck.checkpoint_name(300)
    assert [c.name for c in ck.resumable_checkpoints(run_dir)] == [
        ck.checkpoint_name(200),
        newest.name,
    ]
    path = newest / file
    data = path.read_bytes()
    if damage == "truncate":
        path.write_bytes(data[: len(data) // 2])
    else:  # complete-looking but unloadable: only the load finds it
        path.write_bytes(b"\x80\x05garbage.")
    with pytest.warns(ck.DamagedCheckpointWarning, match=newest.name):
        result = resume(run_dir, total_timesteps=400, verbose=0)
    assert result.num_timesteps == 400
    assert (_sessions(run_dir)[-1]["start_step"], _sessions(run_dir)[-1]["end_step"]) == (200, 400)
    aside = list((run_dir / ck.CHECKPOINTS_DIR).glob(f"{ck.DAMAGED_PREFIX}*"))
    assert len(aside) == (damage == "truncate")  # set aside when the file check finds it
    assert ck.checkpoint_problem(ck.latest_checkpoint(run_dir, with_replay=True)) is None


@pytest.mark.slow
def test_no_intact_checkpoint_says_how_to_start_again(tiny_run, tmp_path, capsys, monkeypatch):
    run_dir = tmp_path / "run"
    shutil.copytree(tiny_run, run_dir)
    for checkpoint in ck.resumable_checkpoints(run_dir):
        (checkpoint / ck.MODEL_FILE).write_bytes(b"")
    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    with pytest.warns(ck.DamagedCheckpointWarning):
        assert cli_main(["policy", "train", "--resume", str(run_dir)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "no intact resumable checkpoint" in line
    assert f"myoexo policy train --restart {run_dir}" in line


def test_resume_without_checkpoint_is_one_line_and_restart_starts_again(
    tmp_path, capsys, monkeypatch
):
    train_module = importlib.import_module("myoexo.training.train")  # the package's
    # ``train`` attribute is the function

    run_dir = tmp_path / "run"
    real_build = train_module.build_model

    def crash(*args, **kwargs):
        raise RuntimeError("crash during the start")

    monkeypatch.setattr(train_module, "build_model", crash)
    preset = _tiny(
        total_timesteps=150, algorithm_kwargs={"learning_starts": 50}, first_checkpoint_steps=0
    )
    with pytest.raises(RuntimeError, match="crash"):
        train(preset, run_dir, verbose=0)
    monkeypatch.setattr(train_module, "build_model", real_build)
    assert (run_dir / ck.CONFIG_FILE).is_file() and not ck.list_checkpoints(run_dir)
    (run_dir / "progress_00.csv").write_text("time/total_timesteps\n")  # a failed start's log

    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    assert cli_main(["policy", "train", "--resume", str(run_dir)]) == 2
    out, err = capsys.readouterr()
    (line,) = err.splitlines()
    assert "has no resumable checkpoint yet" in line
    assert f"myoexo policy train --restart {run_dir}" in line and "Traceback" not in out + err
    # starting it again with the plain command is refused, pointing at --restart
    assert cli_main(["policy", "train", "--run-dir", str(run_dir)]) == 2
    assert "--restart" in capsys.readouterr().err

    assert cli_main(["policy", "train", "--restart", str(run_dir), "--no-progress", "-v", "0"]) == 0
    assert [c.name for c in ck.resumable_checkpoints(run_dir)] == [
        ck.checkpoint_name(100),
        ck.checkpoint_name(150),
    ]
    assert ck.read_config(run_dir)["config"]["total_timesteps"] == 150
    assert [s["start_step"] for s in _sessions(run_dir)] == [0]
    capsys.readouterr()
    assert cli_main(["policy", "train", "--restart", str(run_dir)]) == 2  # it has a checkpoint now
    assert "continue it with: myoexo policy train --resume" in capsys.readouterr().err


def test_a_full_disk_during_a_checkpoint_leaves_the_previous_one(tmp_path):
    class Model:
        """Just enough of an SB3 model for :func:`save_checkpoint`."""

        def __init__(self, num_timesteps: int, fail: bool) -> None:
            self.num_timesteps, self.fail = num_timesteps, fail

        def save(self, path):
            Path(path).write_bytes(b"model")

        def get_vec_normalize_env(self):
            return None

        def save_replay_buffer(self, path):
            Path(path).write_bytes(b"partial replay")
            if self.fail:
                raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC), str(path))

    previous = ck.save_checkpoint(Model(100, False), tmp_path, {"num_timesteps": 100})
    before = {p.name: p.read_bytes() for p in previous.iterdir()}
    latest = (tmp_path / ck.LATEST_FILE).read_bytes()
    with pytest.raises(OSError, match="No space left"):
        ck.save_checkpoint(Model(200, True), tmp_path, {"num_timesteps": 200})
    assert [c.name for c in ck.list_checkpoints(tmp_path)] == [previous.name]
    assert {p.name: p.read_bytes() for p in previous.iterdir()} == before
    assert (tmp_path / ck.LATEST_FILE).read_bytes() == latest
    assert not _temporaries(tmp_path)


def test_a_stale_temporary_and_a_cut_line_are_cleaned_on_resume(tmp_path):
    (tmp_path / ck.CHECKPOINTS_DIR / ".tmp_abc").mkdir(parents=True)
    (tmp_path / ck.CHECKPOINTS_DIR / ".tmp_abc" / ck.MODEL_FILE).write_bytes(b"half")
    (tmp_path / ".tmp-latest.json.xyz").write_text("{")
    (tmp_path / ck.SESSIONS_FILE).write_text('{"session": 0}\n{"sess')
    assert ck.clean_interrupted_writes(tmp_path) == 3
    assert not _temporaries(tmp_path)
    assert (tmp_path / ck.SESSIONS_FILE).read_text() == '{"session": 0}\n'


@pytest.mark.slow
@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_a_signal_stops_training_with_a_checkpoint_and_resume_continues(
    sig, tmp_path, spawn, capsys
):
    run_dir = tmp_path / "run"
    cmd = ["policy", "train", *TINY_TRAIN_SETS, "--total-timesteps", "100000", "--no-progress"]
    proc = spawn([*cmd, "--run-dir", str(run_dir)], "train")
    assert _wait_for(lambda: bool(ck.resumable_checkpoints(run_dir)), proc)

    assert cli_main(["policy", "train", "--resume", str(run_dir)]) == 2  # one writer per folder
    assert f"in use by pid {proc.pid}" in capsys.readouterr().err

    t0 = time.monotonic()
    proc.send_signal(sig)
    assert proc.wait(timeout=STOP_TIMEOUT_S) == signal_exit_status(sig)
    print(f"stopped {time.monotonic() - t0:.1f} s after {sig.name}")
    line = _stderr_line(proc)
    last = ck.latest_checkpoint(run_dir, with_replay=True)
    assert last is not None and ck.checkpoint_problem(last) is None
    step = ck.read_state(last)["num_timesteps"]
    assert line == (
        f"myoexo policy train: stopped by {sig.name} at step {step}; checkpoint {last.name}; "
        f"resume with: myoexo policy train --resume {run_dir}"
    )
    session = _sessions(run_dir)[-1]
    assert session["stopped_by"] == sig.name and session["end_step"] == step
    assert not _temporaries(run_dir)

    result = resume(run_dir, total_timesteps=step + 100, verbose=0)
    assert result.num_timesteps == step + 100 and result.stopped_by is None
    assert _sessions(run_dir)[-1]["start_step"] == step


@pytest.mark.slow
def test_kill9_training_at_random_points_then_resume_continues_from_the_newest_checkpoint(
    tmp_path, spawn, capsys
):
    rng = random.Random(KILL_SEED + 1)
    run_dir = tmp_path / "run"
    total = 1_000
    first = ["policy", "train", *TINY_TRAIN_SETS, "--total-timesteps", str(total), "--no-progress"]
    first += ["--run-dir", str(run_dir)]
    expected: str | None = None  # the checkpoint the next session must start from
    kills = 0
    for i in range(N_KILLS):
        before = {c.name for c in ck.list_checkpoints(run_dir)}
        proc = spawn(
            first if i == 0 else ["policy", "train", "--resume", str(run_dir), "--no-progress"]
        )
        _wait_for(lambda b=before: {c.name for c in ck.list_checkpoints(run_dir)} - b, proc)
        time.sleep(rng.uniform(0.0, 1.0))
        if proc.poll() is not None:
            break
        proc.send_signal(signal.SIGKILL)
        proc.wait()
        kills += 1
        printed = proc.out_path.read_text()
        if expected is not None:
            assert f"from {expected}: " in printed  # resumed from the newest intact one
        intact = [c for c in ck.resumable_checkpoints(run_dir) if ck.checkpoint_problem(c) is None]
        expected = intact[-1].name
        saved = [int(n) for n in re.findall(r"\[checkpoint\] step (\d+)", printed)]
        assert ck.step_of(intact[-1]) >= max(saved, default=0)  # nothing older than printed

    with capsys.disabled():
        print(f"\nkill seed {KILL_SEED + 1}: {kills} kills, the last one after {expected}")
    assert kills >= 2 and expected is not None
    capsys.readouterr()
    result = resume(run_dir, verbose=1)
    assert f"from {expected}: {ck.step_of(run_dir / ck.CHECKPOINTS_DIR / expected)} steps" in (
        capsys.readouterr().out
    )
    assert result.num_timesteps == total
    assert _sessions(run_dir)[-1]["start_step"] == ck.step_of(Path(expected))
    assert not _temporaries(run_dir)
    # the killed sessions' logs are kept: one progress file per session
    assert len(list(run_dir.glob("progress_*.csv"))) >= 2


def test_process_map_keeps_the_order_in_processes_and_in_this_one():
    from myoexo.runtime.lifecycle import process_map

    items = [-3, 2, -1, 4]
    assert list(process_map(abs, items, 1)) == [3, 2, 1, 4]  # in this process
    assert list(process_map(abs, items, 2)) == [3, 2, 1, 4]  # two spawned workers
    assert list(process_map(abs, [], 2)) == []
