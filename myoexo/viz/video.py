"""``myoexo video``: render one episode of a controller to an MP4 or GIF file.

The episode is the one every part of myoexo runs (:func:`myoexo.envs.make_env` and
:func:`myoexo.control.rollout.rollout`, seeded); frames come from one of the twin's named
cameras (:mod:`myoexo.model.scene`) through :class:`myoexo.viz.TwinRenderer`, with the
muscles coloured by activation (the spastic reflex shows in red) and a small overlay of the
time, the knee angle and the exo torque::

    myoexo video --controller pid --level 2 --out pid_l2.mp4
    myoexo video --controller sac --level 3 --camera knee_side --out sac_l3.gif \\
        --width 320 --height 240 --fps 15 --duration 3 --cuff-force

Frames are taken on simulated time (frame ``k`` at ``k / fps`` s), so the file plays in real
time at any ``--fps`` up to the control rate. MP4 needs the ``imageio-ffmpeg`` package
(``pip install myoexo[video]``); GIF needs only Pillow (GIF frames are kept in memory until
the end: use small sizes). Rendering uses MuJoCo's offscreen context: set ``MUJOCO_GL=egl``
on a machine without a display.
"""

from __future__ import annotations

import argparse
import math
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.model.scene import DEFAULT_CAMERA
from myoexo.runtime.fields import FieldError, add_options, check_fields, from_options, option
from myoexo.spasticity.levels import VALID_LEVELS

__all__ = [
    "OverlayStyle",
    "VideoConfig",
    "VideoJob",
    "VideoSummary",
    "VideoWriter",
    "add_arguments",
    "draw_overlay",
    "overlay_lines",
    "run",
    "video_format",
    "write_episode_video",
]

#: Output formats by file suffix.
VIDEO_SUFFIXES: tuple[str, ...] = (".mp4", ".gif")


@dataclass(frozen=True)
class VideoConfig:
    """What to film and how (each field is an option of ``myoexo video``; ``camera`` is a
    named camera of the twin or a view name of :data:`myoexo.viz.VIEWS`; ``cuff_force``
    draws :class:`myoexo.viz.ForceArrowStyle`'s arrow)."""

    level: int | str = option(
        2, "spasticity level of the env", choices=(*VALID_LEVELS, "random"), metavar="LEVEL"
    )
    seed: int = option(0, "episode seed (subject and start angle)", low=0)
    camera: str = option(
        DEFAULT_CAMERA,
        "named camera: leg_three_quarter, knee_side, knee_front, knee_medial (or a view: side, "
        "front, medial, oblique)",
        metavar="NAME",
    )
    fps: float = option(
        25.0,
        "frames per second of simulated time (the file plays in real time)",
        low=0.0,
        above=True,
    )
    width_px: int = option(640, "frame width", low=16, unit="px")
    height_px: int = option(480, "frame height", low=16, unit="px")
    duration_s: float | None = option(
        None,
        "simulated time to film (default: the whole episode)",
        low=0.0,
        above=True,
        unit="s",
    )
    overlay: bool = option(True, "draw the time, knee angle and exo torque over the frames")
    scene: bool = option(
        True, "film the twin in its scene (floor, plinth, lights, skybox; --no-scene: black)"
    )
    cuff_force: bool = option(
        False, "draw the force the exo applies to the shank as an arrow from the shank cuff"
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class VideoJob:
    """Whose episode ``myoexo video`` films and where it goes (options of the command)."""

    controller: str = option(
        "pid",
        "'pid[:options]', 'sac' / 'student_exo' (the shipped policies), 'oracle' or an SB3 "
        "model .zip",
        metavar="SPEC",
    )
    out: Path = option(Path("episode.mp4"), "output .mp4 or .gif file", metavar="FILE")

    def __post_init__(self) -> None:
        check_fields(self)
        if Path(self.out).suffix.lower() not in VIDEO_SUFFIXES:
            raise FieldError(
                type(self).__name__,
                "out",
                str(self.out),
                f"is not a {' or '.join(VIDEO_SUFFIXES)} file",
            )


@dataclass(frozen=True)
class OverlayStyle:
    """Look of the text overlay (top-left corner of each frame).

    Attributes:
        font_height_frac: Font size as a fraction of the frame height.
        min_font_px: Smallest font size, pixels.
        margin_px: Distance of the box from the frame's corner, pixels.
        padding_px: Space between the box's edge and the text, pixels.
        line_spacing: Line pitch as a multiple of the font size.
        box_rgba: Box colour (0-255, alpha: opacity).
        text_rgba: Text colour (0-255).
    """

    font_height_frac: float = 0.04
    min_font_px: int = 9
    margin_px: int = 6
    padding_px: int = 5
    line_spacing: float = 1.25
    box_rgba: tuple[int, int, int, int] = (0, 0, 0, 150)
    text_rgba: tuple[int, int, int, int] = (255, 255, 255, 255)


@dataclass(frozen=True)
class VideoSummary:
    """What :func:`write_episode_video` wrote.

    Attributes:
        path: The video file.
        n_frames: Frames written.
        duration_s: Simulated time filmed, s.
        render_ms_per_frame: Mean render time of a frame (scene update + draw + read), ms.
        final_knee_angle_deg: Knee angle at the last step, deg.
        controller: The controller's label.
        level: Spasticity level of the episode's subject.
        camera: Camera filmed from.
    """

    path: Path
    n_frames: int
    duration_s: float
    render_ms_per_frame: float
    final_knee_angle_deg: float
    controller: str
    level: int
    camera: str


def video_format(path: str | Path) -> str:
    """The video format of ``path`` (its lower-case suffix); ``ValueError`` if unknown."""
    suffix = Path(path).suffix.lower()
    if suffix not in VIDEO_SUFFIXES:
        raise ValueError(
            f"unknown video format {Path(path).suffix!r} of {str(path)!r}; "
            f"accepted: {', '.join(VIDEO_SUFFIXES)}"
        )
    return suffix


def overlay_lines(info: Mapping[str, Any], label: str = "") -> list[str]:
    """Text lines of the overlay from a step's ``info`` (time, knee angle, exo torque)."""
    lines = [] if not label else [label]
    lines.append(f"t {float(info['time_s']):5.2f} s")
    lines.append(
        f"knee {float(info['knee_angle_deg']):5.1f} deg "
        f"(target {float(info['target_angle_deg']):.0f})"
    )
    lines.append(f"exo {float(info['exo_torque_nm']):+6.1f} Nm")
    return lines


def draw_overlay(
    frame: np.ndarray, lines: Sequence[str], style: OverlayStyle | None = None
) -> np.ndarray:
    """The frame with ``lines`` of text in a translucent box at its top-left corner.

    Args:
        frame: ``(height, width, 3)`` uint8 RGB image (not modified).
        lines: Text lines.
        style: Font size, box and colours.

    Returns:
        A new ``(height, width, 3)`` uint8 image.
    """
    from PIL import Image, ImageDraw, ImageFont

    s = OverlayStyle() if style is None else style
    height = frame.shape[0]
    font_px = max(s.min_font_px, round(s.font_height_frac * height))
    font = ImageFont.load_default(size=font_px)
    base = Image.fromarray(np.ascontiguousarray(frame[..., :3])).convert("RGBA")
    layer = Image.new("RGBA", base.size, (0, 0, 0, 0))
    draw = ImageDraw.Draw(layer)
    pitch = round(s.line_spacing * font_px)
    text_w = max((draw.textlength(line, font=font) for line in lines), default=0.0)
    x0 = y0 = s.margin_px
    box = (
        x0,
        y0,
        x0 + 2 * s.padding_px + math.ceil(text_w),
        y0 + 2 * s.padding_px + pitch * len(lines),
    )
    draw.rectangle(box, fill=s.box_rgba)
    for i, line in enumerate(lines):
        draw.text(
            (x0 + s.padding_px, y0 + s.padding_px + i * pitch), line, font=font, fill=s.text_rgba
        )
    return np.asarray(Image.alpha_composite(base, layer).convert("RGB"))


class VideoWriter:
    """Writes RGB frames to ``.mp4`` (H.264 through imageio-ffmpeg) or ``.gif`` (Pillow).

    Use as a context manager; :meth:`append` takes ``(height, width, 3)`` uint8 frames of the
    size given at construction. MP4 frames stream to ffmpeg; GIF frames are kept until
    :meth:`close`.

    Args:
        path: Output file; its suffix picks the format. Parent folders are created.
        fps: Frames per second of the file.
        width_px: Frame width, pixels (even for MP4).
        height_px: Frame height, pixels (even for MP4).

    Raises:
        ValueError: Unknown suffix, odd MP4 size, or imageio-ffmpeg missing for MP4.
    """

    def __init__(self, path: str | Path, fps: float, width_px: int, height_px: int) -> None:
        self.path = Path(path)
        self.suffix = video_format(self.path)
        self.fps = float(fps)
        self.size = (int(width_px), int(height_px))
        self.n_frames = 0
        self._gif_frames: list[Any] = []
        self._ffmpeg: Any = None
        if self.suffix == ".mp4":
            if self.size[0] % 2 or self.size[1] % 2:
                raise ValueError(f"MP4 (yuv420p) needs an even width and height, got {self.size}")
            try:
                import imageio_ffmpeg
            except ImportError:
                raise ValueError(
                    "writing MP4 needs the imageio-ffmpeg package (pip install "
                    "'myoexo[video]'); or write a .gif"
                ) from None
            self.path.parent.mkdir(parents=True, exist_ok=True)
            self._ffmpeg = imageio_ffmpeg.write_frames(
                str(self.path),
                self.size,
                fps=self.fps,
                codec="libx264",
                pix_fmt_out="yuv420p",
                macro_block_size=2,
                ffmpeg_log_level="error",
            )
            self._ffmpeg.send(None)  # start the ffmpeg process

    def append(self, frame: np.ndarray) -> None:
        """Add one frame."""
        frame = np.ascontiguousarray(frame[..., :3], dtype=np.uint8)
        if (frame.shape[1], frame.shape[0]) != self.size:
            raise ValueError(f"frame of {frame.shape[1]}x{frame.shape[0]}, expected {self.size}")
        if self._ffmpeg is not None:
            self._ffmpeg.send(frame)
        else:
            from PIL import Image

            self._gif_frames.append(Image.fromarray(frame))
        self.n_frames += 1

    def close(self) -> None:
        """Finish the file."""
        if self._ffmpeg is not None:
            self._ffmpeg.close()
            self._ffmpeg = None
        elif self._gif_frames:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            first, *rest = self._gif_frames
            first.save(
                self.path,
                save_all=True,
                append_images=rest,
                duration=round(1000.0 / self.fps),
                loop=0,
            )
            self._gif_frames = []

    def __enter__(self) -> VideoWriter:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def write_episode_video(
    out: str | Path,
    controller: str = "pid",
    config: VideoConfig | None = None,
    style: OverlayStyle | None = None,
) -> VideoSummary:
    """Run one episode of a controller and write it as a video.

    Args:
        out: Output ``.mp4`` or ``.gif`` file.
        controller: A controller spec (:mod:`myoexo.control.specs`: ``pid[:options]``,
            ``sac``, or an SB3 ``.zip`` path).
        config: Level, seed, camera, frame rate, size, duration, overlay, scene.
        style: Look of the overlay.

    Returns:
        A :class:`VideoSummary`.

    Raises:
        ValueError: A bad controller spec, camera, size or file format.
    """
    from myoexo.control.rollout import rollout
    from myoexo.control.specs import build_controller, parse_controller_spec, spec_env_kwargs
    from myoexo.envs import make_env
    from myoexo.model.params import TwinParams
    from myoexo.viz.render import TwinRenderer, camera_name

    cfg = VideoConfig() if config is None else config
    video_format(out)  # fail before building the env
    spec = parse_controller_spec(controller)
    env = make_env(cfg.level, twin=TwinParams(scene=cfg.scene), **spec_env_kwargs(spec))
    try:
        base: Any = env.unwrapped  # a MyoExoKneeEnv
        model = base.model
        camera = camera_name(model, cfg.camera)
        # The offscreen buffer bounds the frame size: grow it on this env's own model.
        vis = model.vis.global_
        vis.offwidth = max(int(vis.offwidth), cfg.width_px)
        vis.offheight = max(int(vis.offheight), cfg.height_px)
        ctrl = build_controller(spec, env)
        frame_dt_s = 1.0 / cfg.fps
        next_frame_s = 0.0
        render_s = 0.0
        n_rendered = 0
        with (
            VideoWriter(out, cfg.fps, cfg.width_px, cfg.height_px) as writer,
            TwinRenderer(
                model,
                cfg.width_px,
                cfg.height_px,
                highlight_exo=False,
                show_scene=cfg.scene,
                show_cuff_force=cfg.cuff_force,
            ) as renderer,
        ):

            def grab(step: int, info: Mapping[str, Any]) -> None:
                nonlocal next_frame_s, render_s, n_rendered
                t_s = float(info["time_s"])
                half_step_s = 0.5 * float(base.dt)
                if t_s < next_frame_s - half_step_s:
                    return
                start = time.perf_counter()
                frame = renderer.render(base.data, camera)
                render_s += time.perf_counter() - start
                n_rendered += 1
                if cfg.overlay:
                    label = f"{spec.label}, level {int(info['level'])}"
                    frame = draw_overlay(frame, overlay_lines(info, label), style)
                # Frames on simulated time: repeat a frame if the control step is longer.
                while t_s >= next_frame_s - half_step_s:
                    writer.append(frame)
                    next_frame_s += frame_dt_s

            episode = rollout(env, ctrl, cfg.seed, until_s=cfg.duration_s, on_step=grab)
        knee = episode.signals["knee_angle_deg"]
        times = episode.signals["time_s"]
        return VideoSummary(
            path=Path(out),
            n_frames=writer.n_frames,
            duration_s=float(times[-1]),
            render_ms_per_frame=1e3 * render_s / max(n_rendered, 1),
            final_knee_angle_deg=float(knee[-1]),
            controller=spec.label,
            level=episode.level,
            camera=camera,
        )
    finally:
        env.close()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo video``: :class:`VideoJob`'s and :class:`VideoConfig`'s fields."""
    add_options(parser, VideoJob)
    add_options(parser, VideoConfig)


def run(args: argparse.Namespace) -> int:
    """Write the video and print a one-line summary; return the exit code."""
    job = from_options(VideoJob, args)
    config = from_options(VideoConfig, args)
    summary = write_episode_video(job.out, job.controller, config)
    print(
        f"wrote {summary.path}: {summary.n_frames} frames ({summary.duration_s:.2f} s at "
        f"{config.fps:g} fps, {config.width_px}x{config.height_px}, camera {summary.camera}); "
        f"{summary.controller} on level {summary.level}, seed {config.seed}: final knee "
        f"{summary.final_knee_angle_deg:.1f} deg; render {summary.render_ms_per_frame:.0f} "
        "ms/frame"
    )
    return 0
