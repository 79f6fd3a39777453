"""Offscreen render cost of the twin per frame, with and without its visual scene.

Times :class:`myoexo.viz.TwinRenderer` (muscle colouring + ``update_scene`` + draw + read
back) from each named camera at the seated pose, with and without the scene (alternating
frame by frame), and ``env.render()`` of an ``rgb_array`` env (the default camera,
640x480); it prints the median and the best time per frame (the best is the least
disturbed by other processes)::

    MUJOCO_GL=egl .venv/bin/python benchmarks/bench_render.py [--frames 10] [--width 640]

Under software OpenGL (Mesa llvmpipe) the time is dominated by the MyoSuite meshes and the
4x multisampling; the floor, plinth and skybox add little.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import statistics
import time
from collections.abc import Callable

os.environ.setdefault("MUJOCO_GL", "egl")

import mujoco  # after choosing the OpenGL backend

from myoexo.model import TwinParams, build_model, pose_twin
from myoexo.viz import CAMERAS, TwinRenderer


def _timed_ms(fn: Callable[[], object]) -> float:
    start = time.perf_counter()
    fn()
    return 1e3 * (time.perf_counter() - start)


def env_frame_times_ms(frames: int) -> list[float]:
    """Wall times of ``env.render()`` (rgb_array, default camera, 640x480), ms."""
    from myoexo.envs import make_env

    env = make_env(2, render_mode="rgb_array")
    env.reset(seed=0)
    env.render()  # warm-up: creates the OpenGL context
    times = [_timed_ms(env.render) for _ in range(frames)]
    env.close()
    return times


def main() -> None:
    """Time every camera with and without the scene; print a table."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--frames", type=int, default=10, help="timed frames per camera")
    parser.add_argument("--width", type=int, default=640, help="frame width, pixels")
    parser.add_argument("--height", type=int, default=480, help="frame height, pixels")
    args = parser.parse_args()

    setups = []
    for scene in (True, False):
        model, _ = build_model(dataclasses.replace(TwinParams(), scene=scene))
        data = mujoco.MjData(model)
        pose_twin(model, data, knee_angle_deg=90.0)
        renderer = TwinRenderer(model, args.width, args.height, highlight_exo=False)
        setups.append((renderer, data))
    times: dict[tuple[str, bool], list[float]] = {}
    try:
        for camera in CAMERAS:
            for renderer, data in setups:
                renderer.render(data, camera)  # warm-up
            for _ in range(args.frames):
                for scene, (renderer, data) in zip((True, False), setups, strict=True):
                    frame_ms = _timed_ms(lambda r=renderer, d=data, c=camera: r.render(d, c))
                    times.setdefault((camera, scene), []).append(frame_ms)
    finally:
        for renderer, _ in setups:
            renderer.close()

    print(f"{args.width}x{args.height}, {args.frames} frames: median / best ms per frame")
    print(f"{'camera':<20} {'scene':>15} {'no scene':>15}")
    for camera in CAMERAS:
        cells = [
            f"{statistics.median(t):6.1f} / {min(t):6.1f}"
            for t in (times[camera, True], times[camera, False])
        ]
        print(f"{camera:<20} {cells[0]:>15} {cells[1]:>15}")
    env_times = env_frame_times_ms(args.frames)
    print(
        "env.render() (rgb_array, default camera, 640x480): "
        f"{statistics.median(env_times):.1f} / {min(env_times):.1f}"
    )


if __name__ == "__main__":
    main()
