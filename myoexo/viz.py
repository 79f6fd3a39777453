"""Offscreen pictures of the twin: named camera views on the knee and episode image strips.

Rendering is headless with MuJoCo's :class:`mujoco.Renderer`. Pick the OpenGL backend
*before* MuJoCo is first imported (MuJoCo reads ``MUJOCO_GL`` once, at import)::

    import os
    os.environ.setdefault("MUJOCO_GL", "egl")      # Mesa EGL: no display needed

    import mujoco
    from myoexo.model import build_model, pose_twin
    from myoexo.viz import TwinRenderer

    model, _ = build_model()
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=90.0)
    with TwinRenderer(model) as renderer:
        image = renderer.render(data, view="side")   # (height, width, 3) uint8

Views (:data:`VIEWS`) look at the human knee joint (``knee_angle_r``) from a distance of about
1 m. World frame of the twin: x anterior (the seated subject faces +x), y to the subject's
left (the exo sits on the lateral side of the right leg, at -y), z up. With the default
``highlight_exo=True`` the exoskeleton's geoms (bodies ``exo_*``) are drawn in blue so they
stand out from MyoSuite's red muscle paths; ``show_muscles=False`` hides the muscle paths.

:func:`record_episode` runs one episode of a controller and renders a frame every
``every_s`` seconds of simulated time; :func:`plot_image_strip` lays frames out in a
matplotlib figure.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.model.leg import KNEE_JOINT

if TYPE_CHECKING:
    import mujoco
    from matplotlib.figure import Figure

__all__ = [
    "EXO_BODY_PREFIX",
    "EXO_COLOR_RGBA",
    "VIEWS",
    "CameraView",
    "EpisodeRecording",
    "TwinRenderer",
    "foreground_fraction",
    "knee_camera",
    "plot_image_strip",
    "record_episode",
]

#: Joint the cameras look at (the human knee).
LOOKAT_JOINT = KNEE_JOINT
#: Bodies whose name starts with this prefix belong to the exoskeleton.
EXO_BODY_PREFIX = "exo_"
#: Colour of the exo's geoms when highlighted (RGB; the alpha of each geom is kept).
EXO_COLOR_RGBA = (0.25, 0.6, 1.0, 1.0)
#: Pixels whose brightest channel exceeds this value (0-255) are foreground.
FOREGROUND_THRESHOLD = 12


@dataclasses.dataclass(frozen=True)
class CameraView:
    """A free camera looking at the knee.

    Attributes:
        azimuth_deg: MuJoCo azimuth, deg: 0 looks along +x, 90 along +y (from the lateral
            side of the right leg), 180 along -x (from in front of the subject).
        elevation_deg: MuJoCo elevation, deg (negative: looking down).
        distance_m: Distance from the knee, m.
    """

    azimuth_deg: float
    elevation_deg: float = -15.0
    distance_m: float = 1.0

    def __post_init__(self) -> None:
        for name in ("azimuth_deg", "elevation_deg", "distance_m"):
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"CameraView.{name} must be finite, got {getattr(self, name)!r}")
        if not -90.0 <= self.elevation_deg <= 90.0:
            raise ValueError(
                f"CameraView.elevation_deg = {self.elevation_deg!r} must be in [-90, 90]"
            )
        if self.distance_m <= 0.0:
            raise ValueError(f"CameraView.distance_m = {self.distance_m!r} must be > 0")


#: Named views of the knee.
VIEWS: Mapping[str, CameraView] = {
    "side": CameraView(azimuth_deg=90.0, elevation_deg=-10.0),  # lateral: the exo in front
    "front": CameraView(azimuth_deg=180.0, elevation_deg=-20.0),  # facing the subject
    "medial": CameraView(azimuth_deg=-90.0, elevation_deg=-10.0),  # from the other leg's side
    "oblique": CameraView(azimuth_deg=135.0, elevation_deg=-25.0),  # front-lateral, above
}


def _resolve_view(view: str | CameraView) -> CameraView:
    if isinstance(view, CameraView):
        return view
    if view not in VIEWS:
        raise ValueError(f"unknown view {view!r}; accepted: {sorted(VIEWS)} or a CameraView")
    return VIEWS[view]


def knee_camera(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    view: str | CameraView = "side",
    distance_m: float | None = None,
) -> mujoco.MjvCamera:
    """A free :class:`mujoco.MjvCamera` looking at the human knee joint.

    Args:
        model: A model with the joint ``knee_angle_r`` (the twin or the bare leg).
        data: Its data, after ``mj_forward`` / ``mj_kinematics`` (joint anchors set).
        view: A name of :data:`VIEWS` or a :class:`CameraView`.
        distance_m: Overrides the view's distance, m.

    Raises:
        ValueError: Unknown view, bad distance, or no knee joint in the model.
    """
    import mujoco

    cam_view = _resolve_view(view)
    if distance_m is not None:
        cam_view = dataclasses.replace(cam_view, distance_m=float(distance_m))
    jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, LOOKAT_JOINT)
    if jid < 0:
        raise ValueError(f"the model has no joint {LOOKAT_JOINT!r} to look at")
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    cam.lookat[:] = data.xanchor[jid]
    cam.distance = cam_view.distance_m
    cam.azimuth = cam_view.azimuth_deg
    cam.elevation = cam_view.elevation_deg
    return cam


def foreground_fraction(image: np.ndarray, threshold: int = FOREGROUND_THRESHOLD) -> float:
    """Fraction of pixels brighter than the (black) background: ~0 for an empty render.

    Args:
        image: ``(height, width, 3)`` uint8 image.
        threshold: A pixel is foreground if its brightest channel exceeds this (0-255).
    """
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ValueError(f"image must have shape (height, width, 3 or 4), got {image.shape}")
    return float(np.mean(image[..., :3].max(axis=2) > threshold))


class TwinRenderer:
    """Offscreen renderer of the twin with named knee views (wraps :class:`mujoco.Renderer`).

    Creating the OpenGL context costs about half a second: make one renderer and reuse it for
    many frames; close it (or use it as a context manager) when done.

    Args:
        model: The twin (or any model with ``knee_angle_r``).
        width: Image width, pixels (at most ``model.vis.global_.offwidth``, 640 by default).
        height: Image height, pixels (at most ``model.vis.global_.offheight``).
        show_muscles: Draw MyoSuite's muscle paths (tendons).
        highlight_exo: Draw the exo's geoms (bodies ``exo_*``) in :data:`EXO_COLOR_RGBA`.

    Raises:
        ValueError: A size out of range.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        width: int = 480,
        height: int = 360,
        show_muscles: bool = True,
        highlight_exo: bool = True,
    ) -> None:
        import mujoco

        max_w, max_h = int(model.vis.global_.offwidth), int(model.vis.global_.offheight)
        for name, value, limit in (("width", width, max_w), ("height", height, max_h)):
            if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
                raise ValueError(f"{name} must be an integer number of pixels, got {value!r}")
            if not 16 <= value <= limit:
                raise ValueError(
                    f"{name} = {value} must be in [16, {limit}] (the model's offscreen buffer; "
                    "raise model.vis.global_.offwidth / offheight for larger images)"
                )
        self.model = model
        self.width, self.height = int(width), int(height)
        self.option = mujoco.MjvOption()
        self.option.flags[mujoco.mjtVisFlag.mjVIS_TENDON] = bool(show_muscles)
        self.highlight_exo = bool(highlight_exo)
        exo = [
            b for b in range(model.nbody) if (model.body(b).name or "").startswith(EXO_BODY_PREFIX)
        ]
        self._exo_geoms = frozenset(np.flatnonzero(np.isin(model.geom_bodyid, exo)).tolist())
        self._renderer = mujoco.Renderer(model, height=self.height, width=self.width)

    def render(
        self,
        data: mujoco.MjData,
        view: str | CameraView = "side",
        distance_m: float | None = None,
    ) -> np.ndarray:
        """Render the current state of *data* from a view of the knee.

        Args:
            data: The model's data, kinematics up to date (after ``mj_forward``/``mj_step``).
            view: A name of :data:`VIEWS` or a :class:`CameraView`.
            distance_m: Overrides the view's distance, m.

        Returns:
            ``(height, width, 3)`` uint8 RGB image.
        """
        import mujoco

        if self._renderer is None:
            raise ValueError("this TwinRenderer is closed")
        cam = knee_camera(self.model, data, view, distance_m)
        self._renderer.update_scene(data, camera=cam, scene_option=self.option)
        if self.highlight_exo and self._exo_geoms:
            scene = self._renderer.scene
            for i in range(scene.ngeom):
                g = scene.geoms[i]
                if g.objtype == mujoco.mjtObj.mjOBJ_GEOM and g.objid in self._exo_geoms:
                    g.rgba[:3] = EXO_COLOR_RGBA[:3]
        return self._renderer.render().copy()

    def render_views(
        self, data: mujoco.MjData, views: Sequence[str | CameraView] = ("front", "side")
    ) -> dict[str, np.ndarray]:
        """Render several views of the same state: view name (or ``repr``) -> image."""
        return {(v if isinstance(v, str) else repr(v)): self.render(data, view=v) for v in views}

    def close(self) -> None:
        """Free the OpenGL context (the renderer cannot be used afterwards)."""
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None

    def __enter__(self) -> TwinRenderer:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


@dataclasses.dataclass
class EpisodeRecording:
    """Frames and signals of one rendered episode (:func:`record_episode`).

    Attributes:
        frame_times_s: Simulated time of each frame, s.
        frames: ``(n_frames, height, width, 3)`` uint8 images.
        signals: ``info`` key -> array over the control steps (reset included): the scalar
            entries of the env's ``info`` (``time_s``, ``knee_angle_deg``, ...).
    """

    frame_times_s: np.ndarray
    frames: np.ndarray
    signals: dict[str, np.ndarray]


def record_episode(
    env: Any,
    controller: Any,
    seed: int = 0,
    every_s: float = 0.5,
    view: str | CameraView = "side",
    width: int = 320,
    height: int = 240,
    show_muscles: bool = True,
    until_s: float | None = None,
) -> EpisodeRecording:
    """Run one episode of *controller* on a MyoExoKnee env and render a frame every *every_s*.

    Args:
        env: A MyoExoKnee env (``gymnasium.make("MyoExoKnee-v2")``), wrappers allowed.
        controller: A :class:`~myoexo.control.Controller` (``reset(seed)``,
            ``act(obs, info)``); wrap a policy with :func:`myoexo.control.as_controller`.
        seed: Episode seed (the subject and the start angle).
        every_s: Simulated time between two frames, s (a whole number of control steps is
            used: the nearest one, at least one).
        view: Camera view (a name of :data:`VIEWS` or a :class:`CameraView`).
        width: Frame width, pixels.
        height: Frame height, pixels.
        show_muscles: Draw the muscle paths.
        until_s: Stop the episode at this simulated time, s (``None``: run it to its end),
            e.g. to zoom into a fast transient with a small *every_s*.

    Returns:
        The frames (first one at reset, t = 0) and the scalar ``info`` signals.

    Raises:
        ValueError: Non-positive or non-finite *every_s* or *until_s*.
    """
    from myoexo.control.rollout import rollout

    if not (math.isfinite(every_s) and every_s > 0.0):
        raise ValueError(f"every_s = {every_s!r} must be a positive time in s")
    base = env.unwrapped
    stride = max(1, round(every_s / float(base.dt)))
    times: list[float] = []
    frames: list[np.ndarray] = []
    with TwinRenderer(base.model, width, height, show_muscles=show_muscles) as renderer:

        def grab(step: int, info: Mapping[str, Any]) -> None:
            if step % stride == 0:
                times.append(float(info["time_s"]))
                frames.append(renderer.render(base.data, view))

        episode = rollout(env, controller, seed, until_s=until_s, on_step=grab)
    return EpisodeRecording(
        frame_times_s=np.asarray(times), frames=np.stack(frames), signals=episode.signals
    )


def plot_image_strip(
    images: Sequence[np.ndarray] | np.ndarray,
    titles: Sequence[str] | None = None,
    ncols: int = 6,
    panel_width_in: float = 2.4,
) -> Figure:
    """Lay images out in rows of *ncols* panels (a pyplot-free matplotlib figure).

    Args:
        images: Images of equal shape.
        titles: One title per image (optional).
        ncols: Panels per row.
        panel_width_in: Width of a panel, inches.
    """
    from matplotlib.figure import Figure

    images = list(images)
    if not images:
        raise ValueError("no images to plot")
    if titles is not None and len(titles) != len(images):
        raise ValueError(f"{len(titles)} titles for {len(images)} images")
    if ncols < 1:
        raise ValueError(f"ncols = {ncols!r} must be >= 1")
    ncols = min(ncols, len(images))
    nrows = math.ceil(len(images) / ncols)
    h, w = images[0].shape[:2]
    panel_h = panel_width_in * h / w + (0.3 if titles is not None else 0.05)
    fig = Figure(figsize=(panel_width_in * ncols, panel_h * nrows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(nrows, ncols, squeeze=False)).ravel()
    for i, ax in enumerate(axes):
        ax.set_axis_off()
        if i < len(images):
            ax.imshow(images[i])
            if titles is not None:
                ax.set_title(titles[i], fontsize=9)
    return fig
