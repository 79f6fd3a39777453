"""Pictures of the twin: offscreen renders from the model's named cameras with muscles coloured
by activation (:mod:`myoexo.viz.render`) and episode videos (:mod:`myoexo.viz.video`,
``myoexo video``). Pick the OpenGL backend (``MUJOCO_GL=egl``) before MuJoCo is imported."""

from myoexo.viz.render import (
    CAMERAS,
    EXO_BODY_PREFIX,
    EXO_COLOR_RGBA,
    VIEWS,
    CameraView,
    EpisodeRecording,
    ForceArrowStyle,
    TwinRenderer,
    camera_name,
    foreground_fraction,
    knee_camera,
    plot_image_strip,
    record_episode,
)

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
