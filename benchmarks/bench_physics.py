"""Raw physics speed of the twin vs the same seated leg without the exo (one run).

Measures ``mj_step`` per second (one core, no rendering, no Python work per step beyond
the loop) of ``build_model`` and ``build_leg_model`` from the ``seated_90`` keyframe,
with the muscles and the exo motor driven by a fixed pseudo-random excitation pattern,
and prints the ratio; the twin without its visual scene (``TwinParams(scene=False)``: no
floor, plinth, lights or skybox) shows what the scene costs the physics (nothing, it is
visual only). Each model is timed ``--repeats`` times, alternating, and the best run
counts (the least disturbed by other processes)::

    .venv/bin/python benchmarks/bench_physics.py [--steps 5000] [--repeats 3] [--timestep-s 0.002]
"""

from __future__ import annotations

import argparse
import dataclasses
import time

import mujoco
import numpy as np

from myoexo.model import HOME_KEY, TwinParams, build_leg_model, build_model


def steps_per_second(model: mujoco.MjModel, n_steps: int, seed: int = 0) -> float:
    """``mj_step`` calls per second over ``n_steps`` from the home keyframe."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(HOME_KEY).id)
    rng = np.random.default_rng(seed)
    ctrl = rng.uniform(0.0, 0.2, size=(n_steps // 50 + 1, model.nu))
    lo, hi = model.actuator_ctrlrange[:, 0], model.actuator_ctrlrange[:, 1]
    ctrl = np.clip(ctrl, lo, hi)
    start = time.perf_counter()
    for k in range(n_steps):
        if k % 50 == 0:
            data.ctrl[:] = ctrl[k // 50]
        mujoco.mj_step(model, data)
    elapsed = time.perf_counter() - start
    if not np.isfinite(data.qpos).all():
        raise RuntimeError("simulation diverged during the benchmark")
    return n_steps / elapsed


def main() -> None:
    """Time both models and print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=5000, help="mj_step calls per run")
    parser.add_argument("--repeats", type=int, default=3, help="alternating runs per model")
    parser.add_argument(
        "--timestep-s", type=float, default=TwinParams().timestep_s, help="physics timestep (s)"
    )
    args = parser.parse_args()

    params = TwinParams(timestep_s=args.timestep_s)
    models = {
        "leg (no exo)": build_leg_model(params)[0],
        "twin (leg + exo)": build_model(params)[0],
        "twin, no scene": build_model(dataclasses.replace(params, scene=False))[0],
    }
    best = {name: 0.0 for name in models}
    for _ in range(args.repeats):
        for name, model in models.items():
            best[name] = max(best[name], steps_per_second(model, args.steps))

    print(f"timestep {params.timestep_s * 1e3:.1f} ms, {args.steps} steps x {args.repeats}")
    print(f"{'model':<18} {'nv':>4} {'neq':>4} {'mj_step/s':>11} {'x real time':>12}")
    for name, model in models.items():
        realtime = best[name] * model.opt.timestep
        print(f"{name:<18} {model.nv:>4} {model.neq:>4} {best[name]:>11,.0f} {realtime:>12.1f}")
    ratio = best["leg (no exo)"] / best["twin (leg + exo)"]
    print(f"cost ratio twin / leg (time per step): {ratio:.2f}  (aim <= 1.3)")
    scene = best["twin, no scene"] / best["twin (leg + exo)"]
    print(f"cost ratio twin with / without its visual scene: {scene:.2f}  (expect 1.00)")


if __name__ == "__main__":
    main()
