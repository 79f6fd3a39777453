"""A deployable student exported whole to ONNX: closed-loop parity with the numpy controller
and its decision latency in ONNX Runtime (one thread).

Eight nominal episodes (levels 0-3 twice, the student driving, 6,400 steps); prints the
largest action difference, the p50 / p99 latency of both runtimes and, last, their ratio. A
student with a gentleness input runs at its default weight (or ``--weight``), fed to the ONNX
file as its ``gentleness`` input; one with a fine-positioning layer carries the layer's
integral from step to step through ``integral`` / ``integral_out``::

    python benchmarks/bench_student_onnx.py [--policy student_exo] [--weight W]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np

import myoexo
from myoexo.envs import make_env
from myoexo.envs.config import check_gentleness
from myoexo.policies.student import StudentController, export_student_onnx


def main() -> None:
    import onnxruntime as ort

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--policy", default="student_exo", help="a shipped student")
    parser.add_argument("--episodes", type=int, default=8)
    parser.add_argument(
        "--weight",
        type=float,
        default=None,
        help="gentleness weight of a student that takes one (default: its default weight)",
    )
    args = parser.parse_args()
    controller = myoexo.load_policy(args.policy, make_env(0, obs_preset="exo"))
    student = getattr(controller, "controller", controller)  # a gentle policy's student
    if not isinstance(student, StudentController):
        raise SystemExit(f"{args.policy!r} is not a student controller")
    weight = getattr(controller, "gentleness", None)  # the policy's default, if it takes one
    if args.weight is not None:
        if weight is None:
            raise SystemExit(f"{args.policy!r} takes no gentleness weight; drop --weight")
        weight = check_gentleness(args.weight)
    if weight is not None:
        print(f"{args.policy}: gentleness weight {weight}")
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
            integral = np.zeros((1, 1), np.float32)
            while not done:
                if student.gentleness_input:
                    obs = np.append(obs, np.float32(weight))  # what a GentleController does
                frame = student.frame(obs).astype(np.float32)
                if memory is None:
                    memory = student.initial_memory(frame)[None]
                feeds = {"frame": frame[None], "memory": memory}
                if student.gentleness_input:
                    feeds["gentleness"] = np.full((1, 1), weight, np.float32)
                if student.fine is not None:
                    feeds["integral"] = integral
                t0 = time.perf_counter()
                outputs = sess.run(None, feeds)
                t_onnx.append(time.perf_counter() - t0)
                onnx_action, memory = outputs[0], outputs[1]
                if student.fine is not None:
                    integral = outputs[2]
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
