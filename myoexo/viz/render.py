"""Offscreen pictures of the twin: the model's named cameras, muscle colours, image strips.

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

Views are the twin's named cameras (:data:`myoexo.model.scene.DEFAULT_CAMERAS`, fixed
cameras aimed at the knee: ``leg_three_quarter``, ``knee_side``, ``knee_front``,
``knee_medial``), by name or by the short names of :data:`VIEWS` (``"side"`` is
``knee_side``). A :class:`CameraView` gives a free camera around the knee instead. World
frame of the twin: x anterior (the seated subject faces +x), y to the subject's left (the
exo sits on the lateral side of the right leg, at -y), z up.

Before each frame the renderer colours every muscle by its activation
(:class:`~myoexo.model.scene.MuscleColorizer`: rest colour to red), so a reflex burst of the
spastic muscles shows. With the default ``highlight_exo=True`` the exoskeleton's geoms
(bodies ``exo_*``) are drawn in light blue; ``show_muscles=False`` hides the muscle paths;
``show_scene=False`` hides the floor, plinth and skybox (black background, as
:func:`foreground_fraction` expects); :meth:`TwinRenderer.subject_mask` tells which pixels
show the subject (leg, muscles, exo) whatever the background.

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
from myoexo.model.scene import DEFAULT_CAMERAS, SCENE_GEOM_GROUP, MuscleColorizer, MuscleColors

if TYPE_CHECKING:
    import mujoco
    from matplotlib.figure import Figure

__all__ = [
    "CAMERAS",
    "EXO_BODY_PREFIX",
    "EXO_COLOR_RGBA",
    "VIEWS",
    "CameraView",
    "EpisodeRecording",
    "ForceArrowStyle",
    "TwinRenderer",
    "camera_name",
    "foreground_fraction",
    "knee_camera",
    "plot_image_strip",
    "record_episode",
]

#: Joint the free cameras look at (the human knee).
LOOKAT_JOINT = KNEE_JOINT
#: Bodies whose name starts with this prefix belong to the exoskeleton.
EXO_BODY_PREFIX = "exo_"
#: Colour of the exo's geoms when highlighted (RGB; the alpha of each geom is kept).
EXO_COLOR_RGBA = (0.25, 0.6, 1.0, 1.0)
#: Pixels whose brightest channel exceeds this value (0-255) are foreground.
FOREGROUND_THRESHOLD = 12
#: The twin's named cameras (model cameras aimed at the knee).
CAMERAS: tuple[str, ...] = tuple(c.name for c in DEFAULT_CAMERAS)
#: Force sensor (N, cuff frame) and site of the shank cuff: the force the exo applies to
#: the shank through the cuff and strap.
CUFF_FORCE_SENSOR = "shank_cuff_force"
CUFF_FORCE_SITE = "shank_cuff_site"
#: MuJoCo's renderer draws an arrow geom over half of its ``size[2]`` (shaft to size/3,
#: head to size/2): the connector is stretched by the inverse so the tip lands where asked.
_ARROW_DRAWN_FRACTION = 0.5


@dataclasses.dataclass(frozen=True)
class ForceArrowStyle:
    """Look of the cuff force arrow.

    Attributes:
        scale_m_per_n: Arrow length per newton, m/N (0.5 mm/N: 200 N is a 10 cm arrow).
        width_m: Arrow shaft width, m.
        min_force_n: Forces below this are not drawn, N.
        rgba: Arrow colour.
    """

    scale_m_per_n: float = 5e-4
    width_m: float = 0.008
    min_force_n: float = 1.0
    rgba: tuple[float, float, float, float] = (1.0, 0.75, 0.05, 1.0)


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


#: Short view names -> the twin's named cameras.
VIEWS: Mapping[str, str] = {
    "side": "knee_side",  # lateral: the exo in front
    "front": "knee_front",  # facing the subject
    "medial": "knee_medial",  # from the other leg's side, above the plinth
    "oblique": "leg_three_quarter",  # front-lateral, above: the whole leg, exo and plinth
}


def camera_name(model: mujoco.MjModel, view: str) -> str:
    """The model camera a view name stands for (a :data:`VIEWS` name or a camera name).

    Raises:
        ValueError: Neither a view of :data:`VIEWS` nor a camera of ``model``.
    """
    import mujoco

    name = VIEWS.get(view, view)
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_CAMERA, name) < 0:
        cameras = [model.camera(i).name for i in range(model.ncam)]
        raise ValueError(
            f"unknown view {view!r}; accepted: {sorted(VIEWS)}, a camera of the model "
            f"{cameras} or a CameraView"
        )
    return name


def knee_camera(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    view: str | CameraView = "side",
    distance_m: float | None = None,
) -> mujoco.MjvCamera:
    """A free :class:`mujoco.MjvCamera` on a view of the knee (e.g. for a zoom).

    For a named view it looks along the model camera's axis, at the axis point nearest the
    knee joint, from the camera's distance to that point (``distance_m`` moves it closer or
    farther): the same picture as the model camera when ``distance_m`` is ``None``. For a
    :class:`CameraView` it looks at the knee joint itself.

    Args:
        model: A model with the joint ``knee_angle_r`` (the twin or the bare leg).
        data: Its data, after ``mj_forward`` / ``mj_kinematics`` (joint anchors and camera
            frames set).
        view: A name of :data:`VIEWS`, a camera of the model, or a :class:`CameraView`.
        distance_m: Overrides the view's distance, m.

    Raises:
        ValueError: Unknown view, bad distance, or no knee joint in the model.
    """
    import mujoco

    if distance_m is not None and not (math.isfinite(distance_m) and distance_m > 0.0):
        raise ValueError(f"distance_m = {distance_m!r} must be > 0")
    jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, LOOKAT_JOINT)
    if jid < 0:
        raise ValueError(f"the model has no joint {LOOKAT_JOINT!r} to look at")
    knee = data.xanchor[jid]
    cam = mujoco.MjvCamera()
    cam.type = mujoco.mjtCamera.mjCAMERA_FREE
    if isinstance(view, CameraView):
        cam.lookat[:] = knee
        cam.distance = view.distance_m if distance_m is None else float(distance_m)
        cam.azimuth = view.azimuth_deg
        cam.elevation = view.elevation_deg
        return cam
    cid = model.camera(camera_name(model, view)).id
    pos = data.cam_xpos[cid]
    forward = -data.cam_xmat[cid].reshape(3, 3)[:, 2]  # cameras look along their -z
    depth = max(float(np.dot(knee - pos, forward)), 1e-3)
    cam.lookat[:] = pos + depth * forward
    cam.distance = depth if distance_m is None else float(distance_m)
    cam.azimuth = math.degrees(math.atan2(forward[1], forward[0]))
    cam.elevation = math.degrees(math.asin(float(np.clip(forward[2], -1.0, 1.0))))
    return cam


def foreground_fraction(image: np.ndarray, threshold: int = FOREGROUND_THRESHOLD) -> float:
    """Fraction of pixels brighter than a black background: ~0 for an empty render.

    Meaningful for renders without the scene (``TwinRenderer(show_scene=False)``, or a
    twin built with ``TwinParams(scene=False)``); with the floor and skybox every pixel is
    bright: use :meth:`TwinRenderer.subject_mask` there.

    Args:
        image: ``(height, width, 3)`` uint8 image.
        threshold: A pixel is foreground if its brightest channel exceeds this (0-255).
    """
    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] not in (3, 4):
        raise ValueError(f"image must have shape (height, width, 3 or 4), got {image.shape}")
    return float(np.mean(image[..., :3].max(axis=2) > threshold))


class TwinRenderer:
    """Offscreen renderer of the twin's named views (wraps :class:`mujoco.Renderer`).

    Creating the OpenGL context costs about half a second: make one renderer and reuse it for
    many frames; close it (or use it as a context manager) when done. Colouring the muscles
    writes ``model.tendon_rgba`` (a visual field; the dynamics do not read it).

    Args:
        model: The twin (or any model with ``knee_angle_r``).
        width: Image width, pixels (at most ``model.vis.global_.offwidth``, 640 by default).
        height: Image height, pixels (at most ``model.vis.global_.offheight``).
        show_muscles: Draw MyoSuite's muscle paths (tendons).
        highlight_exo: Draw the exo's geoms (bodies ``exo_*``) in :data:`EXO_COLOR_RGBA`.
        show_scene: Draw the floor, plinth and skybox (``False``: black background).
        color_muscles: Colour each muscle by its activation before each frame.
        muscle_colors: Rest and active muscle colours (default MyoSuite's red blend).
        show_cuff_force: Draw the force the exo applies to the shank (sensor
            ``shank_cuff_force``) as an arrow from the shank cuff (models without it: none).
        arrow_style: Scale and colour of that arrow.

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
        show_scene: bool = True,
        color_muscles: bool = True,
        muscle_colors: MuscleColors | None = None,
        show_cuff_force: bool = False,
        arrow_style: ForceArrowStyle | None = None,
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
        self.option.geomgroup[SCENE_GEOM_GROUP] = bool(show_scene)
        self.show_scene = bool(show_scene)
        self.highlight_exo = bool(highlight_exo)
        self.colorize = MuscleColorizer(model, muscle_colors) if color_muscles else None
        self.arrow_style = ForceArrowStyle() if arrow_style is None else arrow_style
        self._cuff_force: tuple[int, int] | None = None  # (sensor address, site id)
        sensor = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SENSOR, CUFF_FORCE_SENSOR)
        site = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, CUFF_FORCE_SITE)
        if show_cuff_force and sensor >= 0 and site >= 0:
            self._cuff_force = (int(model.sensor_adr[sensor]), site)
        exo = [
            b for b in range(model.nbody) if (model.body(b).name or "").startswith(EXO_BODY_PREFIX)
        ]
        self._exo_geoms = frozenset(np.flatnonzero(np.isin(model.geom_bodyid, exo)).tolist())
        self._renderer: mujoco.Renderer | None = mujoco.Renderer(
            model, height=self.height, width=self.width
        )

    def _update_scene(
        self, data: mujoco.MjData, view: str | CameraView, distance_m: float | None
    ) -> mujoco.Renderer:
        import mujoco

        if self._renderer is None:
            raise ValueError("this TwinRenderer is closed")
        camera: str | mujoco.MjvCamera
        if isinstance(view, str) and distance_m is None:
            camera = camera_name(self.model, view)
        else:
            camera = knee_camera(self.model, data, view, distance_m)
        if self.colorize is not None:
            self.colorize(data)
        self._renderer.update_scene(data, camera=camera, scene_option=self.option)
        if not self.show_scene:
            self._renderer.scene.flags[mujoco.mjtRndFlag.mjRND_SKYBOX] = 0
        return self._renderer

    def render(
        self,
        data: mujoco.MjData,
        view: str | CameraView = "side",
        distance_m: float | None = None,
    ) -> np.ndarray:
        """Render the current state of *data* from a view of the knee.

        Args:
            data: The model's data, kinematics up to date (after ``mj_forward``/``mj_step``).
            view: A name of :data:`VIEWS`, a camera of the model, or a :class:`CameraView`.
            distance_m: Moves the view closer or farther (a free camera on the same axis,
                see :func:`knee_camera`), m.

        Returns:
            ``(height, width, 3)`` uint8 RGB image.
        """
        import mujoco

        renderer = self._update_scene(data, view, distance_m)
        if self.highlight_exo and self._exo_geoms:
            scene = renderer.scene
            for i in range(scene.ngeom):
                g = scene.geoms[i]
                if g.objtype == mujoco.mjtObj.mjOBJ_GEOM and g.objid in self._exo_geoms:
                    g.rgba[:3] = EXO_COLOR_RGBA[:3]
        if self._cuff_force is not None:
            self._add_force_arrow(renderer.scene, data, *self._cuff_force)
        return renderer.render().copy()

    def _add_force_arrow(
        self, scene: mujoco.MjvScene, data: mujoco.MjData, sensor_adr: int, site: int
    ) -> None:
        """Append an arrow for a site's force sensor (site frame -> world) to the scene."""
        import mujoco

        style = self.arrow_style
        force_n = data.site_xmat[site].reshape(3, 3) @ data.sensordata[sensor_adr : sensor_adr + 3]
        if np.linalg.norm(force_n) < style.min_force_n or scene.ngeom >= scene.maxgeom:
            return
        start = data.site_xpos[site]
        geom = scene.geoms[scene.ngeom]
        mujoco.mjv_initGeom(
            geom,
            mujoco.mjtGeom.mjGEOM_ARROW,
            np.zeros(3),
            np.zeros(3),
            np.eye(3).reshape(-1),
            np.asarray(style.rgba, dtype=np.float32),
        )
        mujoco.mjv_connector(
            geom,
            mujoco.mjtGeom.mjGEOM_ARROW,
            style.width_m,
            start,
            start + style.scale_m_per_n * force_n / _ARROW_DRAWN_FRACTION,
        )
        scene.ngeom += 1

    def subject_mask(
        self,
        data: mujoco.MjData,
        view: str | CameraView = "side",
        distance_m: float | None = None,
    ) -> np.ndarray:
        """Pixels that show the subject (bones, muscles, exo), not the scene or background.

        A segmentation render of the same view: a pixel belongs to the subject when it
        shows a geom of a body other than the world, or a muscle path.

        Returns:
            ``(height, width)`` bool mask.
        """
        import mujoco

        renderer = self._update_scene(data, view, distance_m)
        renderer.enable_segmentation_rendering()
        try:
            seg = renderer.render()
        finally:
            renderer.disable_segmentation_rendering()
        objid, objtype = seg[..., 0], seg[..., 1]
        geom = (objtype == mujoco.mjtObj.mjOBJ_GEOM) & (objid >= 0)
        body = np.zeros_like(objid)
        body[geom] = self.model.geom_bodyid[objid[geom]]
        return (geom & (body > 0)) | (objtype == mujoco.mjtObj.mjOBJ_TENDON)

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
            ``act(obs, measurements)``); wrap a policy with :func:`myoexo.control.as_controller`.
        seed: Episode seed (the subject and the start angle).
        every_s: Simulated time between two frames, s (a whole number of control steps is
            used: the nearest one, at least one).
        view: Camera view (a name of :data:`VIEWS`, a camera of the model, or a
            :class:`CameraView`).
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
