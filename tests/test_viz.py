"""myoexo.viz: camera views, input validation, and real offscreen renders of the twin.

Rendering runs in a child process with ``MUJOCO_GL=egl``: MuJoCo picks its OpenGL backend
once, when it is first imported, so this test process (which imported MuJoCo long before)
cannot switch to EGL itself.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import textwrap

import mujoco
import numpy as np
import pytest

from myoexo.model import build_model, pose_twin
from myoexo.viz import VIEWS, CameraView, foreground_fraction, knee_camera, plot_image_strip


@pytest.fixture(scope="module")
def twin():
    model, _ = build_model()
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=90.0)
    return model, data


def test_knee_camera_looks_at_the_knee(twin) -> None:
    model, data = twin
    knee = data.xanchor[model.joint("knee_angle_r").id]
    # A named view: the model camera's axis, aimed at the axis point nearest the knee.
    cam = knee_camera(model, data, "side")
    side = model.camera(VIEWS["side"]).id
    assert np.linalg.norm(cam.lookat - knee) < 0.25
    assert cam.distance == pytest.approx(np.linalg.norm(cam.lookat - data.cam_xpos[side]))
    assert cam.azimuth == pytest.approx(90.0)
    assert knee_camera(model, data, "knee_side").azimuth == pytest.approx(90.0)
    assert knee_camera(model, data, "front", distance_m=0.7).distance == pytest.approx(0.7)
    # A free view looks at the knee itself.
    free = knee_camera(model, data, CameraView(azimuth_deg=45.0, distance_m=0.8))
    np.testing.assert_allclose(free.lookat, knee)
    assert free.distance == pytest.approx(0.8) and free.azimuth == pytest.approx(45.0)


def test_bad_views_raise(twin) -> None:
    model, data = twin
    with pytest.raises(ValueError, match="unknown view 'top'"):
        knee_camera(model, data, "top")
    with pytest.raises(ValueError, match="distance_m"):
        knee_camera(model, data, "side", distance_m=-1.0)
    with pytest.raises(ValueError, match="distance_m"):
        CameraView(azimuth_deg=0.0, distance_m=0.0)
    with pytest.raises(ValueError, match="elevation_deg"):
        CameraView(azimuth_deg=0.0, elevation_deg=120.0)


def test_foreground_fraction() -> None:
    image = np.zeros((10, 20, 3), dtype=np.uint8)
    assert foreground_fraction(image) == 0.0
    image[:5, :4] = 200
    assert foreground_fraction(image) == pytest.approx(20 / 200)
    with pytest.raises(ValueError, match="shape"):
        foreground_fraction(np.zeros((10, 20)))


def test_image_strip_layout() -> None:
    images = [np.full((30, 40, 3), i * 20, dtype=np.uint8) for i in range(7)]
    fig = plot_image_strip(images, [f"{i}" for i in range(7)], ncols=3)
    assert len(fig.axes) == 9  # 3 x 3 grid, the last two empty
    with pytest.raises(ValueError, match="3 titles for 7 images"):
        plot_image_strip(images, ["a", "b", "c"])
    with pytest.raises(ValueError, match="no images"):
        plot_image_strip([])


_RENDER_SCRIPT = textwrap.dedent(
    """
    import json
    import os
    os.environ["MUJOCO_GL"] = "egl"
    import gymnasium as gym
    import mujoco
    import numpy as np
    import myoexo
    from myoexo.control import PID
    from myoexo.model import build_model, pose_twin
    from myoexo.viz import TwinRenderer, foreground_fraction, record_episode

    model, _ = build_model()
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=90.0)
    out = {}
    images = {}
    for highlight in (True, False):
        # Without the scene the background is black, as foreground_fraction expects.
        with TwinRenderer(model, 160, 120, highlight_exo=highlight, show_scene=False) as renderer:
            image = renderer.render(data, "side")
        images[highlight] = image.astype(int)
        out[f"fg_{highlight}"] = foreground_fraction(image)
        out["shape"] = list(image.shape)
    # The highlight recolours the exo's pixels (and nothing else).
    out["recoloured"] = float(np.mean(np.abs(images[True] - images[False]).max(axis=2) > 30))
    try:
        TwinRenderer(model, width=10_000)
    except ValueError as exc:
        out["too_wide"] = str(exc)
    env = gym.make("MyoExoKnee-v0")
    rec = record_episode(env, PID(), seed=0, every_s=0.05, width=80, height=60, until_s=0.2)
    out["frame_times_s"] = rec.frame_times_s.tolist()
    out["frames_shape"] = list(rec.frames.shape)
    out["n_signal"] = int(rec.signals["knee_angle_deg"].size)
    knee = rec.signals["knee_angle_deg"]
    out["knee_moved_deg"] = float(knee[0] - knee[-1])
    print("RESULT " + json.dumps(out))
    """
)


@pytest.mark.slow
def test_offscreen_render_and_episode_frames(tmp_path) -> None:
    env = {**os.environ, "MUJOCO_GL": "egl"}
    proc = subprocess.run(
        [sys.executable, "-c", _RENDER_SCRIPT],
        capture_output=True,
        text=True,
        cwd=tmp_path,
        env=env,
        timeout=300,
    )
    lines = [ln for ln in proc.stdout.splitlines() if ln.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stderr[-3000:]
    out = json.loads(lines[-1].removeprefix("RESULT "))
    assert out["shape"] == [120, 160, 3]
    # Not a black frame: the leg and exo fill a clear share of the image.
    assert out["fg_True"] > 0.03 and out["fg_False"] > 0.03
    # The highlight recolours the exo: a small, clear share of the pixels.
    assert 0.002 < out["recoloured"] < 0.1
    assert "width = 10000 must be in [16, 640]" in out["too_wide"]
    # Frames at reset and every 50 ms up to 0.2 s; signals at every 10 ms step.
    np.testing.assert_allclose(out["frame_times_s"], [0.0, 0.05, 0.1, 0.15, 0.2], atol=1e-9)
    assert out["frames_shape"] == [5, 60, 80, 3]
    assert out["n_signal"] == 21
    assert out["knee_moved_deg"] > 10.0  # the PID extends the knee within the first 0.2 s
