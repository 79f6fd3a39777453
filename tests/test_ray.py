"""Ray: the evaluation's Ray backend gives the process pool's table bit for bit, a killed
driver leaves no process of its local cluster behind (and a joined cluster drops its tasks),
and ``myoexo policy sweep`` runs Ray Tune over training runs, ranks them on the acceptance criteria
and resumes after its driver is killed.

Every cluster here is local and has 2 CPUs; the tests that start several clusters or train
are marked slow.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pandas as pd
import pytest

from myoexo.cli import main as cli_main
from myoexo.envs.options import TwinOptions
from myoexo.evaluation import EvaluationConfig, evaluate

CPUS = 2
#: A tiny protocol: 2 levels x 3 subjects of the PID, one subject per chunk.
TINY = EvaluationConfig(
    controllers=("pid",),
    levels=(0, 3),
    subjects=3,
    twin=TwinOptions().replace(episode_duration_s=0.5),
    chunk_size=1,
)
#: Seconds a killed driver's processes get to disappear.
ORPHAN_TIMEOUT_S = 5.0
#: Seconds allowed for a run to reach the state where it is killed.
START_TIMEOUT_S = 120.0
#: A protocol long enough to be killed half-way (80 PID episodes of 0.5 s).
LONG_ARGS = ["--controllers", "pid", "--levels", "0", "3", "--subjects", "40"]
LONG_ARGS += ["--episode-duration-s", "0.5", "--chunk-size", "1", "--no-progress"]
ON_PROC = Path("/proc/self/stat").exists()
ON_LINUX = pytest.mark.skipif(not ON_PROC, reason="needs /proc")


# ----------------------------------------------------------------------------- helpers
def _stat(pid: int) -> tuple[str, int, str] | None:
    """``(state, ppid, start time)`` of a process, ``None`` if gone."""
    try:
        fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    except (OSError, IndexError):
        return None
    return fields[0], int(fields[1]), fields[19]


def descendants(root: int) -> dict[int, str]:
    """PID -> start time of every process whose parent chain includes ``root``."""
    parents = {}
    for path in Path("/proc").glob("[0-9]*"):
        stat = _stat(int(path.name))
        if stat is not None:
            parents[int(path.name)] = (stat[1], stat[2])
    found: dict[int, str] = {}
    for pid, (_, start) in parents.items():
        p, seen = pid, set()
        while p in parents and p not in seen:
            seen.add(p)
            p = parents[p][0]
            if p == root:
                found[pid] = start
                break
    return found


def alive(processes: dict[int, str]) -> list[int]:
    """Those of ``processes`` still running (a zombie or a reused PID does not count)."""
    out = []
    for pid, start in processes.items():
        stat = _stat(pid)
        if stat is not None and stat[0] != "Z" and stat[2] == start:
            out.append(pid)
    return out


def wait_gone(processes: dict[int, str], timeout_s: float = ORPHAN_TIMEOUT_S) -> list[int]:
    deadline = time.monotonic() + timeout_s
    while alive(processes) and time.monotonic() < deadline:
        time.sleep(0.1)
    return alive(processes)


def names(pids) -> list[str]:
    out = []
    for pid in pids:
        try:
            out.append(Path(f"/proc/{pid}/comm").read_text().strip())
        except OSError:
            out.append("?")
    return sorted(out)


def kill_all(processes: dict[int, str]) -> None:
    for pid in alive(processes):
        os.kill(pid, signal.SIGKILL)


def cli(*args: str) -> list[str]:
    return [sys.executable, "-m", "myoexo.cli", *args]


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)


def wait_for(condition, proc: subprocess.Popen, what: str) -> None:
    deadline = time.monotonic() + START_TIMEOUT_S
    while not condition():
        assert proc.poll() is None, f"the driver ended before {what}"
        assert time.monotonic() < deadline, f"no {what} after {START_TIMEOUT_S} s"
        time.sleep(0.05)


# ----------------------------------------------------------------------------- optional
def test_importing_myoexo_does_not_import_ray():
    code = (
        "import sys, myoexo, myoexo.evaluation, myoexo.training, myoexo.runtime.ray_cluster\n"
        "import myoexo.evaluation.ray_backend, myoexo.studies, myoexo.studies.sweep.cli\n"
        "from myoexo.cli import build_parser\n"
        "build_parser()\n"
        "assert 'ray' not in sys.modules, 'ray imported'\n"
    )
    subprocess.run([sys.executable, "-c", code], check=True)


def test_ray_missing_is_a_one_line_error_and_writes_nothing(tmp_path, capsys, monkeypatch):
    monkeypatch.setitem(sys.modules, "ray", None)  # `import ray` now raises ImportError
    out = tmp_path / "out"
    args = ["evaluate", "--backend", "ray", "--controllers", "pid", "--subjects", "1"]
    assert cli_main([*args, "--out", str(out), "--no-progress"]) == 2
    err = capsys.readouterr().err.strip()
    assert "--backend ray needs Ray" in err and "pip install 'myoexo[ray]'" in err
    assert len(err.splitlines()) == 1 and not out.exists()
    sweep_file = tmp_path / "s.yaml"
    sweep_file.write_text("preset: cpu\n")
    assert cli_main(["policy", "sweep", str(sweep_file), "--out", str(out)]) == 2
    assert "myoexo policy sweep needs Ray" in capsys.readouterr().err
    assert not out.exists()


def test_address_needs_the_ray_backend(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["evaluate", "--address", "auto", "--controllers", "pid", "--subjects", "1"]
    assert cli_main([*args, "--out", str(out), "--no-progress"]) == 2
    assert "needs --backend ray" in capsys.readouterr().err
    assert not out.exists()


# ----------------------------------------------------------------------------- evaluate
def test_tables_are_bit_identical_across_backends_and_workers(tmp_path):
    """Process pool with 1 and 2 workers, and Ray on the local 2-CPU cluster that
    ``evaluate`` starts (as ``myoexo evaluate --backend ray`` does) and ends with it."""
    runs = {
        "process-1": evaluate(TINY, tmp_path / "p1", workers=1, progress=False),
        "process-2": evaluate(TINY, tmp_path / "p2", workers=2, progress=False),
    }
    before = set(descendants(os.getpid()))  # e.g. multiprocessing's resource tracker
    runs["ray-2"] = evaluate(TINY, tmp_path / "ray", workers=CPUS, progress=False, backend="ray")
    started = {p: t for p, t in descendants(os.getpid()).items() if p not in before}
    assert runs["ray-2"].computed == 6
    tables = {k: pd.read_parquet(r.out_dir / "episodes.parquet") for k, r in runs.items()}
    assert len(tables["process-1"]) == 6
    for key in ("process-2", "ray-2"):
        pd.testing.assert_frame_equal(tables[key], tables["process-1"], check_exact=True)
    # one folder, two backends: chunks computed by Ray resume under the process pool
    for chunk in sorted((tmp_path / "ray").glob("traces/*/L3/*.npz")):
        chunk.unlink()
    resumed = evaluate(TINY, tmp_path / "ray", workers=1, progress=False)
    assert resumed.computed == 3
    pd.testing.assert_frame_equal(resumed.table, tables["process-1"], check_exact=True)
    assert not wait_gone(started), names(alive(started))  # the cluster ended with the run


@pytest.mark.slow
def test_a_task_error_is_raised_as_the_tasks_own():
    from myoexo.evaluation.ray_backend import _get
    from myoexo.runtime.ray_cluster import ray_session

    def fails():
        raise ValueError("bad chunk")

    with ray_session(CPUS) as r:
        with pytest.raises(ValueError, match="bad chunk"):
            _get(r, r.remote(fails).remote())


# ----------------------------------------------------------------------------- orphans
@ON_LINUX
@pytest.mark.slow
@pytest.mark.parametrize("sig", ["SIGKILL", "SIGTERM", "SIGINT"])
def test_a_killed_driver_leaves_no_process_of_its_cluster(tmp_path, sig):
    """The driver starts its own 2-CPU cluster (no address); killed while its tasks run,
    none of its processes outlives it by more than a few seconds."""
    out = tmp_path / "out"
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    cmd = cli("evaluate", "--backend", "ray", "--workers", str(CPUS), *LONG_ARGS, "--out", str(out))
    # the driver as a terminal starts it: SIGINT at its default even when this test runs in a
    # background job, whose children inherit an ignored SIGINT (and keep it ignored, by design)
    proc = subprocess.Popen(
        cmd,
        env=env,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        preexec_fn=_default_sigint,
    )
    seen: dict[int, str] = {}
    try:
        # note the cluster's processes while the driver lives (they are re-parented when it
        # dies); then wait for the first stored chunk: the tasks are running
        def tasks_running() -> bool:
            seen.update(descendants(proc.pid))
            return bool(list(out.glob("traces/*/L*/*.npz")))

        wait_for(tasks_running, proc, "stored chunk")
        seen.update(descendants(proc.pid))
        assert {"raylet", "gcs_server"} <= set(names(seen)), names(seen)
        os.kill(proc.pid, getattr(signal, sig))
        proc.wait(timeout=START_TIMEOUT_S)
        left = wait_gone(seen)
        assert not left, f"still running after {ORPHAN_TIMEOUT_S} s: {names(left)}"
        assert not (out / "episodes.parquet").exists()
    finally:
        if proc.poll() is None:
            proc.kill()
        kill_all(seen)


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


@ON_LINUX
@pytest.mark.slow
def test_a_joined_cluster_drops_the_tasks_of_a_killed_driver(tmp_path):
    """``ray start --head`` (its own process here), a driver joining it with ``--address``,
    SIGKILLed while its tasks run: Ray ends the driver's tasks; the cluster lives on."""
    port = _free_port()
    temp_dir = tempfile.mkdtemp(prefix="ray", dir="/tmp")  # short: Ray's socket paths
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    env["RAY_AUTH_MODE"] = "disabled"  # a throw-away cluster on localhost
    start = "from ray.scripts.scripts import main; main()"
    head_cmd = [sys.executable, "-c", start, "start", "--head", "--block", "--port", str(port)]
    head_cmd += ["--num-cpus", str(CPUS), "--include-dashboard=false", "--temp-dir", temp_dir]
    head = subprocess.Popen(head_cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    out = tmp_path / "out"
    address = f"127.0.0.1:{port}"
    cmd = cli("evaluate", "--backend", "ray", "--address", address, *LONG_ARGS, "--out", str(out))
    driver = None
    try:
        deadline = time.monotonic() + START_TIMEOUT_S
        while not (Path(temp_dir) / "ray_current_cluster").exists():
            assert head.poll() is None and time.monotonic() < deadline, "no head node"
            time.sleep(0.1)
        driver = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        wait_for(lambda: bool(list(out.glob("traces/*/L*/*.npz"))), driver, "stored chunk")

        def chunk_workers() -> dict[int, str]:
            return {
                pid: t for pid, t in descendants(head.pid).items() if "_chunk_task" in _cmd(pid)
            }

        running: dict[int, str] = {}

        def tasks_running() -> bool:  # a snapshot: a worker between two tasks shows none
            running.clear()
            running.update(chunk_workers())
            return bool(running)

        wait_for(tasks_running, driver, "task of the driver on the cluster")
        os.kill(driver.pid, signal.SIGKILL)
        driver.wait()
        assert not wait_gone(running), "the killed driver's tasks still run"
        # a task the driver had started just before its death is ended too, a moment later
        deadline = time.monotonic() + ORPHAN_TIMEOUT_S
        while chunk_workers() and time.monotonic() < deadline:
            time.sleep(0.1)
        assert not chunk_workers(), f"the killed driver's tasks still run: {chunk_workers()}"
        assert head.poll() is None  # the cluster itself lives on
    finally:
        if driver is not None and driver.poll() is None:
            driver.kill()
        ours = descendants(head.pid)
        head.send_signal(signal.SIGTERM)  # `ray start --block` stops the processes it started
        try:
            head.wait(timeout=30)
        finally:
            kill_all(ours)
            shutil.rmtree(temp_dir, ignore_errors=True)


def _cmd(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
    except OSError:
        return ""


# ----------------------------------------------------------------------------- sweep
#: Two seeds of a tiny training run: 0.5-s episodes, 400 steps, an evaluation (1 subject at
#: levels 0 and 3) every 200 steps, a resumable checkpoint every 200.
SWEEP_YAML = """\
name: tiny
preset: cpu
seeds: [0, 1]
set:
  episode_duration_s: 0.5
  total_timesteps: 400
  n_envs: 2
  algorithm_kwargs: {buffer_size: 2000, batch_size: 32, learning_starts: 100}
  checkpoint_every_s: 0
  checkpoint_every_steps: 200
  eval_every_steps: 200
  eval_subjects: 1
  eval_levels: [0, 3]
max_concurrent_trials: 2
"""


def test_sweep_file_is_checked_before_ray_starts(tmp_path):
    from myoexo.studies.sweep.spec import build_config, read_sweep_file

    good = tmp_path / "good.toml"
    text = (
        'preset = "cpu"\nseeds = [0, 1]\n[set]\neval_every_steps = 1000\n'
        "total_timesteps = 4000\n[set.algorithm_kwargs]\ntrain_freq = 2\n"
        "[search]\nn_envs = [1, 2]\n[search.algorithm_kwargs]\n"
        "learning_rate = {loguniform = [1e-3, 1e-4]}\nbatch_size = [64, 128]\n"
        "[reward_weights]\ninter = [-0.5, -1.0]\nact = -0.25\n"
    )
    good.write_text(text)
    with pytest.raises(ValueError, match="loguniform bounds"):
        read_sweep_file(good)  # low > high
    good.write_text(text.replace("[1e-3, 1e-4]", '["1e-4", 1e-3]'))  # text, as YAML reads 1e-4
    spec = read_sweep_file(good)
    assert spec.name == "good" and spec.seeds == (0, 1)
    search = {"n_envs": 2, "algorithm_kwargs": {"batch_size": 64}}
    config = build_config("cpu", spec.fixed, search, {"inter": -0.5, "act": -0.25}, seed=1)
    kw = config.algorithm_kwargs
    assert (config.n_envs, config.seed, kw["batch_size"], kw["train_freq"]) == (2, 1, 64, 2)
    assert kw["learning_rate"] == 3e-4  # the preset's, where the trial searches nothing
    assert dict(config.twin.reward_weights) == {"inter": -0.5, "act": -0.25}
    bad = {
        "preset: gpu\n": "preset",
        "search:\n  batchsize: [1, 2]\n": "unknown training field",
        "search:\n  batch_size: [1, 2]\n": "belong under algorithm_kwargs",
        "search:\n  n_envs: 2\n": "a list of values",
        "search:\n  algorithm_kwargs: {batch_size: 64}\n": "a list of values",
        "set:\n  algorithm: ppo\n": "not an argument of ppo",
        "set:\n  algorithm_kwargs: {learning_rate: 2}\n": "learning_rate",
        "num_samples: 0\n": "num_samples = 0 must be >= 1",
        "reward_weights:\n  nope: [1.0]\n": "reward_weights has unknown keys",
        "set:\n  eval_every_steps: 0\n": "eval_every_steps > 0",
        "scheduler: hyperband\n": "scheduler",
        "algorithm: ppo\n": "unknown key",
        "search:\n  algorithm_kwargs:\n    learning_rate: {uniform: [0.1]}\n": "takes 2 arguments",
    }
    for text, message in bad.items():
        path = tmp_path / "bad.yaml"
        path.write_text(text)
        with pytest.raises(ValueError, match=message):
            read_sweep_file(path)


def test_eval_rows_survive_a_cut_line_and_a_repeated_step(tmp_path):
    from myoexo.evaluation.criteria import CRITERIA_METRICS
    from myoexo.studies.sweep.table import evaluation_metrics, read_eval_rows

    header = ["step", "level", *CRITERIA_METRICS, "unstable", "peak_vs_pid_pct", "score"]

    def row(step, level, peak):
        return [step, level, 0.5, 0.5, 1.0, 2.0, peak, 0.0, 0.0, 0.0]

    lines = [header, row(200, 0, 5.0), row(200, 3, 5.0), row(400, 0, 4.0)]
    text = "\n".join(",".join(map(str, r)) for r in lines)
    text += "\n400,3,0.5"  # cut by a kill, then the resumed session re-evaluates step 400
    text += "\n" + "\n".join(",".join(map(str, r)) for r in (row(400, 0, 3.0), row(400, 3, 3.0)))
    (tmp_path / "eval.csv").write_text(text + "\n")
    pid = {lv: dict.fromkeys(CRITERIA_METRICS, 10.0) for lv in ("0", "3")}
    (tmp_path / "eval_pid.json").write_text(json.dumps(pid))
    rows = read_eval_rows(tmp_path)
    assert sorted(rows) == [(200, 0), (200, 3), (400, 0), (400, 3)]
    assert rows[(400, 0)]["peak_interaction_torque_nm"] == 3.0  # the newest row of a step
    metrics = evaluation_metrics(tmp_path, (0, 3))
    assert [m["step"] for m in metrics] == [200, 400]
    assert metrics[1]["mean_peak_reduction_pct"] == pytest.approx(70.0)
    assert metrics[1]["passes"] and metrics[1]["shortfall"] == 0.0


@ON_LINUX
@pytest.mark.slow
def test_sweep_resumes_after_its_driver_is_killed(tmp_path):
    """Run a 2-trial sweep, SIGKILL the driver once a trial has evaluated, check that no
    process of its cluster survives, run the same command again: the table ranks both
    trials, each trained to the end, the interrupted runs continued from a checkpoint."""
    sweep_file = tmp_path / "tiny.yaml"
    sweep_file.write_text(SWEEP_YAML)
    out = tmp_path / "sweeps"
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    cmd = cli(
        "policy", "sweep", str(sweep_file), "--out", str(out), "--num-cpus", str(CPUS), "-v", "0"
    )
    sweep_dir = out / "tiny"
    proc = subprocess.Popen(cmd, env=env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
    seen: dict[int, str] = {}
    try:

        def evaluated() -> bool:
            seen.update(descendants(proc.pid))
            return bool(list(sweep_dir.glob("runs/*/eval.csv"))) and bool(
                list(sweep_dir.glob("tune/experiment_state*.json"))
            )

        wait_for(evaluated, proc, "trial evaluation")
        seen.update(descendants(proc.pid))
        os.kill(proc.pid, signal.SIGKILL)
        proc.wait()
        left = wait_gone(seen)
        assert not left, f"still running: {names(left)}"
    finally:
        if proc.poll() is None:
            proc.kill()
        kill_all(seen)
    assert not (sweep_dir / "results.parquet").exists()
    steps_at_kill = {
        run.name: max(
            (int(c.name.split("_")[1]) for c in run.glob("checkpoints/step_*")), default=0
        )
        for run in sweep_dir.glob("runs/*")
    }
    assert steps_at_kill and min(steps_at_kill.values()) < 400

    done = subprocess.run(cmd, env=env, capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "[sweep] continued tiny: 2 trials" in done.stdout
    table = pd.read_parquet(sweep_dir / "results.parquet")
    assert len(table) == 2 and sorted(table.seed) == [0, 1]
    assert table["rank"].tolist() == [1, 2] and set(table.status) == {"done"}
    assert (table.steps == 400).all() and (table.evaluations == 2).all()
    assert table.shortfall.tolist() == sorted(table.shortfall)
    for _, row in table.iterrows():
        run = sweep_dir / row.run_dir
        sessions = [json.loads(s) for s in (run / "sessions.jsonl").read_text().splitlines()]
        assert sessions[-1]["end_step"] == 400
        if 0 < steps_at_kill[row.trial] < 400:  # continued from its checkpoint
            assert sessions[0]["start_step"] == steps_at_kill[row.trial]
    md = (sweep_dir / "results.md").read_text()
    assert all(t in md for t in table.trial)
