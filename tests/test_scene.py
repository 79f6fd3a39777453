"""The twin's scene, named cameras, muscle colours and videos.

The scene is visual only (same sizes, bit-identical trajectory without it); each named
camera frames the leg; muscles turn red with activation; ``myoexo video`` writes a GIF
(MyoSuite's ``examine_env`` renders each ``myoexo:`` id offscreen on a named camera in
tests/test_ecosystem.py).

Renders run in child processes with ``MUJOCO_GL=egl`` (MuJoCo picks its OpenGL backend
when it is first imported, long before these tests run) and with this checkout first on
``PYTHONPATH``.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import mujoco
import numpy as np
import pytest

from myoexo.model import HOME_KEY, TwinParams, build_model, pose_twin
from myoexo.model.scene import (
    DEFAULT_CAMERA,
    DEFAULT_CAMERAS,
    SCENE_GEOM_GROUP,
    MuscleColorizer,
    MuscleColors,
)
from myoexo.viz import CAMERAS, VIEWS, knee_camera
from myoexo.viz.video import VideoWriter, draw_overlay, overlay_lines

REPO = Path(__file__).resolve().parents[1]


def _child_env() -> dict[str, str]:
    path = os.pathsep.join(p for p in (str(REPO), os.environ.get("PYTHONPATH", "")) if p)
    return {**os.environ, "MUJOCO_GL": "egl", "PYTHONPATH": path}


def _run_child(args: list[str], cwd: Path, timeout_s: float = 300) -> subprocess.CompletedProcess:
    return subprocess.run(
        args, capture_output=True, text=True, cwd=cwd, env=_child_env(), timeout=timeout_s
    )


@pytest.fixture(scope="module")
def twins():
    """The twin with and without its scene."""
    return build_model(TwinParams())[0], build_model(TwinParams(scene=False))[0]


def test_scene_changes_only_visual_elements(twins) -> None:
    with_scene, without = twins
    for size in ("nq", "nv", "nu", "na", "nbody", "njnt", "neq", "ntendon", "nsensor"):
        assert getattr(with_scene, size) == getattr(without, size), size
    assert with_scene.ngeom > without.ngeom and with_scene.nlight >= 2 > without.nlight
    assert with_scene.ncam == without.ncam == len(DEFAULT_CAMERAS)
    world = with_scene.geom_bodyid == 0
    assert world.any()
    assert not with_scene.geom_contype[world].any() and not with_scene.geom_conaffinity[world].any()
    assert (with_scene.geom_group[world] == SCENE_GEOM_GROUP).all()
    np.testing.assert_array_equal(with_scene.body_mass, without.body_mass)

    # Same trajectory, bit for bit, under the same excitation.
    rng = np.random.default_rng(0)
    ctrl = rng.uniform(0.0, 0.3, size=(4, with_scene.nu))
    qpos = []
    for model in twins:
        data = mujoco.MjData(model)
        mujoco.mj_resetDataKeyframe(model, data, model.key(HOME_KEY).id)
        for u in ctrl:
            data.ctrl[:] = u
            mujoco.mj_step(model, data, 10)
        qpos.append(data.qpos.copy())
    assert np.array_equal(qpos[0], qpos[1])


def test_named_cameras_aim_at_the_knee(twins) -> None:
    model = twins[0]
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=90.0)
    knee = data.xanchor[model.joint("knee_angle_r").id]
    assert model.vis.global_.cameraid == model.camera(DEFAULT_CAMERA).id
    assert set(VIEWS.values()) <= set(CAMERAS)
    for placement in DEFAULT_CAMERAS:
        cid = model.camera(placement.name).id
        forward = -data.cam_xmat[cid].reshape(3, 3)[:, 2]
        to_knee = knee - data.cam_xpos[cid]
        off_axis_deg = math.degrees(math.acos(np.dot(forward, to_knee) / np.linalg.norm(to_knee)))
        assert off_axis_deg < 0.5 * placement.fovy_deg / 2, placement.name  # central half
        np.testing.assert_allclose(forward, placement.forward(), atol=1e-6)
        # The free camera of the same view: same axis, aimed next to the knee.
        cam = knee_camera(model, data, placement.name)
        assert cam.azimuth == pytest.approx(placement.azimuth_deg)
        assert cam.elevation == pytest.approx(placement.elevation_deg)
        assert np.linalg.norm(cam.lookat - knee) < 0.25
        np.testing.assert_allclose(
            cam.lookat - cam.distance * forward, data.cam_xpos[cid], atol=1e-9
        )


def test_muscle_colours_follow_activation(twins) -> None:
    model = twins[0]
    data = mujoco.MjData(model)
    colors = MuscleColors()
    colorize = MuscleColorizer(model, colors)
    assert colorize.tendon_ids.size == 40  # every muscle, not the exo motor
    colorize(data)  # all at rest
    np.testing.assert_allclose(model.tendon_rgba[colorize.tendon_ids], [colors.rest_rgba] * 40)
    data.act[colorize.act_adr[0]] = 1.0
    data.act[colorize.act_adr[1]] = 0.5**4  # blend weight act ** 0.25 = 0.5
    colorize(data)
    rgba = model.tendon_rgba[colorize.tendon_ids]
    np.testing.assert_allclose(rgba[0], colors.active_rgba)
    np.testing.assert_allclose(
        rgba[1], 0.5 * (np.array(colors.rest_rgba) + np.array(colors.active_rgba))
    )
    np.testing.assert_allclose(rgba[2:], [colors.rest_rgba] * 38)


def test_overlay_and_writer_checks(tmp_path) -> None:
    info = {"time_s": 1.25, "knee_angle_deg": 45.04, "target_angle_deg": 7.0, "exo_torque_nm": -3}
    lines = overlay_lines(info, "pid, level 2")
    assert lines == ["pid, level 2", "t  1.25 s", "knee  45.0 deg (target 7)", "exo   -3.0 Nm"]
    frame = np.full((240, 320, 3), 200, dtype=np.uint8)
    out = draw_overlay(frame, lines)
    assert out.shape == frame.shape and out.dtype == np.uint8
    assert (out[8:12, 8:12] < 200).all() and (out[-5:, -5:] == 200).all()  # box top-left only
    with pytest.raises(ValueError, match=r"unknown video format '\.avi'"):
        VideoWriter(tmp_path / "x.avi", 10, 64, 48)
    with pytest.raises(ValueError, match="even width and height"):
        VideoWriter(tmp_path / "x.mp4", 10, 65, 48)


_RENDER_SCRIPT = textwrap.dedent(
    """
    import json, time
    import mujoco
    import numpy as np
    from myoexo.envs import make_env
    from myoexo.model import build_model, pose_twin
    from myoexo.viz import CAMERAS, TwinRenderer, foreground_fraction

    model, _ = build_model()
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=90.0)
    out = {"subject": {}, "centre": {}, "fg_no_scene": {}}
    with TwinRenderer(model, 160, 120) as renderer:
        for cam in CAMERAS:
            mask = renderer.subject_mask(data, cam)
            rows, cols = np.nonzero(mask)
            out["subject"][cam] = float(mask.mean())
            out["centre"][cam] = [float(cols.mean() / 160), float(rows.mean() / 120)]
        image = renderer.render(data, "knee_side")
        out["fg_scene"] = foreground_fraction(image)
        muscles = renderer.colorize
        data.act[muscles.act_adr] = 1.0  # every muscle fully active: red paths
        red = renderer.render(data, "knee_side").astype(int)
        rest = image.astype(int)
        def reddish(im):
            return float(np.mean((im[..., 0] > 180) & (im[..., 1] < 120)))
        out["red_rest"], out["red_active"] = reddish(rest), reddish(red)
    data.act[:] = 0.0
    with TwinRenderer(model, 160, 120, show_scene=False) as renderer:
        for cam in CAMERAS:
            out["fg_no_scene"][cam] = foreground_fraction(renderer.render(data, cam))
    env = make_env(1, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    out["env_frame"] = list(frame.shape)
    out["env_camera"] = env.unwrapped.render_camera
    for _ in range(3):
        env.step(np.array([-1.0]))  # the exo extends the knee: a large cuff force
    base = env.unwrapped
    frames = []
    for arrow in (True, False):
        with TwinRenderer(base.model, 160, 120, show_cuff_force=arrow) as renderer:
            frames.append(renderer.render(base.data, "knee_side").astype(int))
    out["arrow"] = float(np.mean(np.abs(frames[0] - frames[1]).max(axis=2) > 30))
    env.close()
    print("RESULT " + json.dumps(out))
    """
)


@pytest.mark.slow
def test_renders_from_every_named_camera_show_the_leg(tmp_path) -> None:
    proc = _run_child([sys.executable, "-c", _RENDER_SCRIPT], tmp_path)
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stderr[-3000:]
    out = json.loads(lines[-1].removeprefix("RESULT "))
    for cam in CAMERAS:
        assert 0.04 < out["subject"][cam] < 0.6, (cam, out["subject"])  # leg in frame
        assert all(0.25 < c < 0.75 for c in out["centre"][cam]), (cam, out["centre"])
        assert 0.04 < out["fg_no_scene"][cam] < 0.6, (cam, out["fg_no_scene"])
    assert out["fg_scene"] > 0.95  # floor and sky: no black background left
    assert out["red_active"] > out["red_rest"] + 0.01
    assert out["env_frame"] == [480, 640, 3] and out["env_camera"] == DEFAULT_CAMERA
    assert out["arrow"] > 0.002  # the cuff force arrow is drawn


@pytest.mark.slow
def test_video_command_writes_a_gif(tmp_path) -> None:
    from PIL import Image

    out = tmp_path / "episode.gif"
    args = ["--level", "0", "--out", str(out), "--width-px", "64", "--height-px", "48"]
    args += ["--fps", "20", "--duration-s", "0.1", "--camera", "knee_side", "--cuff-force"]
    proc = _run_child([sys.executable, "-m", "myoexo.cli", "video", *args], tmp_path)
    assert proc.returncode == 0, proc.stderr[-3000:]
    assert "wrote" in proc.stdout and "3 frames" in proc.stdout
    with Image.open(out) as gif:
        assert gif.size == (64, 48)
        assert gif.n_frames == 3  # t = 0, 0.05, 0.1 s
