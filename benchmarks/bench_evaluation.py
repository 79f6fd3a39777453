"""Speed of the evaluation protocol (target: the full protocol in <= 20 min here).

Measures, in this one run:

1. PID episodes/s in one process, per level (``evaluate_controller``: env + PID + metrics);
2. the cost of a SAC decision (``predict`` of the shipped policy if available, else of an
   untrained SB3 SAC with the paper's 64-64 actor), per step;
3. episodes/s of ``evaluate`` (PID) on all cores (steady state, file writing included) and
   its fixed worker start-up, from two runs of different sizes;

and extrapolates the full protocol: 1000 subjects x 4 levels x 2 controllers (PID + SAC,
a SAC episode costing a PID episode plus 800 policy decisions).

With ``--backends N`` it instead compares the two backends of ``evaluate`` on one protocol,
PID at levels 0 and 3 with N subjects each, on ``--workers`` CPUs: the process pool, then
Ray on a local cluster of as many CPUs (``myoexo.runtime.ray_cluster.ray_session``). Ray's
start-up (``ray.init``) and shutdown are timed apart from the evaluation; the overhead is
Ray's evaluation wall time against the process pool's (each including its own worker
start-up: processes spawned, or tasks' first imports), then with Ray's start-up added. The
tables are checked identical. ``--repeats`` alternates the two backends and reports medians.

    .venv/bin/python benchmarks/bench_evaluation.py [--subjects 6] [--workers N]
    .venv/bin/python benchmarks/bench_evaluation.py --backends 100 --workers 2 --repeats 3
"""

from __future__ import annotations

import argparse
import tempfile
import time

import numpy as np

from myoexo.control import PID
from myoexo.control.specs import PolicyUnavailableError, load_shipped_policy
from myoexo.envs import TaskParams, make_env
from myoexo.evaluation import EvaluationConfig, available_cores, evaluate, evaluate_controller
from myoexo.spasticity.levels import VALID_LEVELS

FULL_SUBJECTS, FULL_CONTROLLERS = 1000, 2


def serial_pid(subjects: int) -> dict[int, float]:
    """Seconds per PID episode, per level, in this process."""
    out = {}
    for level in VALID_LEVELS:
        env = make_env(level)
        pid = PID.from_env(env)
        env.close()
        evaluate_controller(pid, level, 1)  # warm-up (model build, imports)
        t0 = time.perf_counter()
        evaluate_controller(pid, level, range(1, subjects + 1))
        out[level] = (time.perf_counter() - t0) / subjects
    return out


def policy_step_s(steps: int = 2000) -> tuple[float, str]:
    """Seconds per policy decision and which policy was timed."""
    from myoexo.control import declared_sensors, read_sensors
    from myoexo.control.policy import as_controller

    env = make_env(1)
    obs, info = env.reset(seed=0)
    try:
        policy, name = load_shipped_policy(), "shipped SAC policy"
    except PolicyUnavailableError:
        from stable_baselines3 import SAC

        policy = SAC("MlpPolicy", env, buffer_size=1, policy_kwargs={"net_arch": [64, 64]})
        name = "untrained SB3 SAC, 64-64 actor (no shipped policy yet)"
    ctrl = as_controller(policy)
    env.close()
    measurements = read_sensors(info, declared_sensors(ctrl))
    ctrl.act(obs, measurements)
    t0 = time.perf_counter()
    for _ in range(steps):
        ctrl.act(obs, measurements)
    return (time.perf_counter() - t0) / steps, name


def parallel_pid(subjects: int, workers: int) -> tuple[float, float]:
    """Steady-state seconds per episode and fixed start-up seconds of ``evaluate`` (PID, all
    levels) on ``workers`` processes, from two runs of different sizes (t = t0 + n c)."""
    sizes, times = [], []
    for n in (max(1, subjects // 4), subjects):
        cfg = EvaluationConfig(controllers=("pid",), subjects=n, chunk_size=max(1, n // 2))
        with tempfile.TemporaryDirectory() as tmp:
            t0 = time.perf_counter()
            run = evaluate(cfg, tmp, workers=workers, progress=False, log=lambda s: None)
            times.append(time.perf_counter() - t0)
            sizes.append(len(run.table))
    per_episode = (times[1] - times[0]) / (sizes[1] - sizes[0])
    return per_episode, times[1] - sizes[1] * per_episode


#: Levels of the backend comparison.
COMPARE_LEVELS = (0, 3)


def compare_backends(subjects: int, workers: int, repeats: int) -> None:
    """Print the process pool's and Ray's wall times on one protocol (module docstring)."""
    import pandas as pd

    from myoexo.runtime.ray_cluster import ray_session

    config = EvaluationConfig(controllers=("pid",), levels=COMPARE_LEVELS, subjects=subjects)
    quiet = {"progress": False, "log": lambda s: None}
    times: dict[str, list[float]] = {"process": [], "ray": []}
    tables = {}
    t0 = time.perf_counter()
    session = ray_session(workers)
    session.__enter__()
    startup_s = time.perf_counter() - t0
    try:
        for _ in range(repeats):
            for backend in ("process", "ray"):
                with tempfile.TemporaryDirectory() as tmp:
                    t0 = time.perf_counter()
                    run = evaluate(config, tmp, workers=workers, backend=backend, **quiet)
                    times[backend].append(time.perf_counter() - t0)
                    tables[backend] = run.table
    finally:
        t0 = time.perf_counter()
        session.__exit__(None, None, None)
        shutdown_s = time.perf_counter() - t0
    n = subjects * len(COMPARE_LEVELS)
    med = {k: float(np.median(v)) for k, v in times.items()}
    overhead = 100.0 * (med["ray"] - med["process"]) / med["process"]
    with_startup = 100.0 * (med["ray"] + startup_s - med["process"]) / med["process"]
    print(
        f"backends, PID, levels {list(COMPARE_LEVELS)} x {subjects} subjects = {n} episodes "
        f"of {config.episode_duration_s or TaskParams().episode_duration_s:g} s, chunks of "
        f"{config.chunk_size}, {workers} workers, median of {repeats}:"
    )
    for backend, values in times.items():
        runs = ", ".join(f"{v:.1f}" for v in values)
        print(f"  {backend:8s} {med[backend]:7.1f} s  ({n / med[backend]:.2f} episodes/s; {runs})")
    print(
        f"  Ray start-up (ray.init, {workers} CPUs): {startup_s:.1f} s, shutdown {shutdown_s:.1f} s"
    )
    print(f"  Ray's overhead: {overhead:+.1f} % (with its start-up: {with_startup:+.1f} %)")
    same = tables["process"].equals(tables["ray"])
    pd.testing.assert_frame_equal(tables["process"], tables["ray"], check_exact=True)
    print(f"  tables identical: {same}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--subjects", type=int, default=6, help="subjects per level timed")
    parser.add_argument(
        "--parallel-subjects", type=int, default=12, help="subjects per level, parallel run"
    )
    parser.add_argument("--workers", type=int, default=available_cores())
    parser.add_argument(
        "--backends",
        type=int,
        default=0,
        metavar="N",
        help="compare the process and Ray backends on N subjects per level (needs the ray extra)",
    )
    parser.add_argument("--repeats", type=int, default=1, help="runs per backend (--backends)")
    args = parser.parse_args()
    if args.backends > 0:
        compare_backends(args.backends, args.workers, args.repeats)
        return

    per_level = serial_pid(args.subjects)
    t_pid = float(np.mean(list(per_level.values())))
    t_step, policy_name = policy_step_s()
    steps = make_env(0).unwrapped.episode_steps
    t_sac = t_pid + steps * t_step
    par_episode_s, startup_s = parallel_pid(args.parallel_subjects, args.workers)
    speedup = t_pid / par_episode_s

    print(f"PID episode, one process ({args.subjects} subjects per level):")
    for level, t in per_level.items():
        print(f"  level {level}: {t:.3f} s/episode  ({1 / t:.2f} episodes/s)")
    print(f"policy decision ({policy_name}): {t_step * 1e6:.0f} us/step")
    print(f"SAC episode (PID episode + {steps} decisions): {t_sac:.3f} s")
    print(
        f"evaluate(), PID, {args.workers} workers: {1 / par_episode_s:.2f} episodes/s steady "
        f"(x{speedup:.2f} the single process) + {startup_s:.1f} s start-up"
    )
    n = FULL_SUBJECTS * len(VALID_LEVELS)
    serial_total = n * (t_pid + t_sac)
    parallel_total = startup_s + serial_total / speedup
    print(
        f"full protocol ({FULL_SUBJECTS} subjects x {len(VALID_LEVELS)} levels x "
        f"{FULL_CONTROLLERS} controllers = {n * FULL_CONTROLLERS} episodes): "
        f"{serial_total / 60:.1f} min in one process, ~{parallel_total / 60:.1f} min on "
        f"{args.workers} workers (target <= 20 min)"
    )


if __name__ == "__main__":
    main()
