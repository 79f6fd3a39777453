"""Env step cost against raw physics on the same model (issue 4's speed target).

Prints env steps/s, raw ``mj_step``/s on the same model and state, and the ratio
``env time per step / (frame_skip x raw step time)`` (target <= 1.25; MyoSuite's own leg
walk env spends ~2.2x). Both are measured in this one run, single-threaded.

    .venv/bin/python benchmarks/bench_env.py [--steps 4000] [--env MyoExoKnee-v2]
"""

from __future__ import annotations

import argparse
import time

import gymnasium as gym
import mujoco
import numpy as np

import myoexo  # noqa: F401  (registers the ids)


def bench(env_id: str, steps: int, repeats: int = 3) -> dict[str, float]:
    env = gym.make(env_id).unwrapped  # the bare env: what a VecEnv worker steps
    fs = env.frame_skip
    rng = np.random.default_rng(0)
    actions = rng.uniform(-0.6, 0.2, size=(steps, 1)).astype(np.float32)

    best_env = best_raw = float("inf")
    for _ in range(repeats):
        env.reset(seed=0)
        t0 = time.perf_counter()
        for a in actions:
            _, _, _, trunc, _ = env.step(a)
            if trunc:
                env.reset()
        best_env = min(best_env, time.perf_counter() - t0)

        env.reset(seed=0)
        model, data = env.model, mujoco.MjData(env.model)
        data.qpos[:] = env.data.qpos
        t0 = time.perf_counter()
        for a in actions:
            data.ctrl[-1] = a[0]
            mujoco.mj_step(model, data, fs)
        best_raw = min(best_raw, time.perf_counter() - t0)
    env.close()
    return {
        "env_steps_per_s": steps / best_env,
        "raw_mj_steps_per_s": steps * fs / best_raw,
        "frame_skip": fs,
        "ratio": best_env / best_raw,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=4000)
    parser.add_argument("--env", default="MyoExoKnee-v2")
    args = parser.parse_args()
    r = bench(args.env, args.steps)
    print(f"env: {args.env}  frame_skip: {r['frame_skip']}  steps: {args.steps} (best of 3)")
    print(f"env steps/s            {r['env_steps_per_s']:10.0f}")
    print(f"raw mj_step/s          {r['raw_mj_steps_per_s']:10.0f}")
    print(f"env physics-equivalent {r['env_steps_per_s'] * r['frame_skip']:10.0f} mj_step/s")
    print(f"ratio env / (frame_skip x raw) = {r['ratio']:.3f}   (target <= 1.25)")


if __name__ == "__main__":
    main()
