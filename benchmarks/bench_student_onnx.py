"""The deployable controller (``student_exo``) exported whole to ONNX: closed-loop parity with
the numpy controller and its decision latency in ONNX Runtime (one thread).

Eight nominal episodes (levels 0-3 twice, the student driving, 6,400 steps); prints the
largest action difference, the p50 / p99 latency of both runtimes and, last, their ratio::

    python benchmarks/bench_student_onnx.py [--policy student_exo]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import myoexo
from myoexo.envs import make_env
from myoexo.policies.student import StudentController, export_student_onnx


def main() -> None:
    import onnxruntime as ort

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="student_exo", help="a shipped student")
    parser.add_argument("--episodes", type=int, default=8)
    args = parser.parse_args()
    student = myoexo.load_policy(args.policy)
    if not isinstance(student, StudentController):
        raise SystemExit(f"{args.policy!r} is not a student controller")
    with tempfile.TemporaryDirectory() as tmp:
        path = export_student_onnx(student, Path(tmp) / "student.onnx")
        opts = ort.SessionOptions()
        opts.intra_op_num_threads = opts.inter_op_num_threads = 1
        sess = ort.InferenceSession(str(path), opts, providers=["CPUExecutionProvider"])
        worst, t_onnx, t_numpy = 0.0, [], []
        for k in range(args.episodes):
            env = make_env(k % 4, obs_preset="exo")
            obs, _ = env.reset(seed=100 + k)
            student.reset()
            memory, done = None, False
            while not done:
                frame = student.frame(obs).astype(np.float32)
                if memory is None:
                    memory = student.initial_memory(frame)[None]
                t0 = time.perf_counter()
                onnx_action, memory = sess.run(None, {"frame": frame[None], "memory": memory})
                t_onnx.append(time.perf_counter() - t0)
                t0 = time.perf_counter()
                action = student.act(obs)
                t_numpy.append(time.perf_counter() - t0)
                worst = max(worst, float(np.max(np.abs(onnx_action[0] - action))))
                obs, _, term, trunc, _ = env.step(action)
                done = term or trunc
            env.close()

    def pct(t: list[float], q: float) -> float:
        return float(np.percentile(t, q) * 1e6)

    print(f"max |onnx - numpy| action: {worst:.2e} over {len(t_onnx)} closed-loop steps")
    print(f"onnx runtime: p50 {pct(t_onnx, 50):.0f} us, p99 {pct(t_onnx, 99):.0f} us")
    print(f"numpy:        p50 {pct(t_numpy, 50):.0f} us, p99 {pct(t_numpy, 99):.0f} us")
    print(f"onnx / numpy decision time (p50): {pct(t_onnx, 50) / pct(t_numpy, 50):.2f}")


if __name__ == "__main__":
    main()
