"""The twin's surroundings, named cameras and muscle colours (visual only).

Everything here changes what a renderer draws, never the dynamics:

* :func:`add_scene` (when ``TwinParams.scene`` is on) adds, like MuJoCo Menagerie's
  ``scene.xml``, a floor, a plinth (seat) under the pelvis and thigh, a headlight setting,
  two directional lights, a neutral gradient skybox and a matching haze. The floor and the
  plinth are geoms of the world body with ``contype = conaffinity = 0`` and density 0 in
  geom group :data:`SCENE_GEOM_GROUP` (hide that group to hide them).
* :func:`add_cameras` (always) adds the fixed world cameras of :data:`DEFAULT_CAMERAS`,
  aimed at the knee of the seated pose (the thigh is locked, so the knee stays in frame):
  ``mujoco.Renderer.update_scene(data, camera="knee_side")``, ``examine_env -c knee_side``,
  the MuJoCo viewer's camera list and the envs' ``render()`` all use them.
* :class:`MuscleColorizer` blends each muscle's tendon colour from a rest colour to red
  with its activation (MyoSuite's convention, ``c = act ** 0.25``), so a reflex burst of the
  spastic muscles shows on the picture. Call it before each render.

World frame of the twin: x anterior (the seated subject faces +x), y to the subject's left
(the exo sits on the lateral side of the right leg, at -y), z up; the floor is at z = 0.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

__all__ = [
    "DEFAULT_CAMERA",
    "DEFAULT_CAMERAS",
    "SCENE_GEOM_GROUP",
    "CameraPlacement",
    "DirectionalLight",
    "MuscleColorizer",
    "MuscleColors",
    "SceneParams",
    "add_cameras",
    "add_scene",
    "camera_frame",
]

#: Geom group of the scene's geoms (floor, plinth); visible by default in every viewer.
SCENE_GEOM_GROUP = 2

RGB = tuple[float, float, float]
RGBA = tuple[float, float, float, float]


@dataclass(frozen=True)
class CameraPlacement:
    """A fixed camera aimed at a point near the knee of the seated pose.

    Attributes:
        name: Camera name in the model.
        azimuth_deg: Viewing direction's azimuth (MuJoCo's convention), deg: 0 looks along
            +x, 90 along +y (from the lateral side of the right leg), 180 along -x (from in
            front of the subject), -90 along -y (from the medial side).
        elevation_deg: Viewing direction's elevation, deg (negative: looking down).
        distance_m: Distance from the aim point, m.
        lookat_offset_m: Aim point minus the knee joint's position, world frame (m).
        fovy_deg: Vertical field of view, deg.
    """

    name: str
    azimuth_deg: float
    elevation_deg: float
    distance_m: float
    lookat_offset_m: tuple[float, float, float] = (0.0, 0.0, 0.0)
    fovy_deg: float = 45.0

    def __post_init__(self) -> None:
        if not self.name:
            raise ValueError("CameraPlacement.name must be a non-empty camera name")
        if not -90.0 < self.elevation_deg < 90.0:
            raise ValueError(
                f"CameraPlacement.elevation_deg = {self.elevation_deg!r} must be in (-90, 90)"
            )
        if not (math.isfinite(self.distance_m) and self.distance_m > 0.0):
            raise ValueError(f"CameraPlacement.distance_m = {self.distance_m!r} must be > 0")
        if not 0.0 < self.fovy_deg < 180.0:
            raise ValueError(f"CameraPlacement.fovy_deg = {self.fovy_deg!r} must be in (0, 180)")

    def forward(self) -> np.ndarray:
        """Unit viewing direction (world frame)."""
        az, el = math.radians(self.azimuth_deg), math.radians(self.elevation_deg)
        return np.array([math.cos(el) * math.cos(az), math.cos(el) * math.sin(az), math.sin(el)])


#: Cameras of the twin, aimed near the knee; each frames the leg and the exo from the knee
#: at 90 deg flexion (the foot near the floor) to full extension (the foot forward).
DEFAULT_CAMERAS: tuple[CameraPlacement, ...] = (
    CameraPlacement("leg_three_quarter", 135.0, -20.0, 1.1, (0.14, 0.0, -0.12)),
    CameraPlacement("knee_side", 90.0, -10.0, 1.2, (0.02, 0.0, -0.16)),
    CameraPlacement("knee_front", 180.0, -15.0, 1.0, (0.0, 0.0, -0.15)),
    CameraPlacement("knee_medial", -90.0, -30.0, 1.2, (0.02, 0.0, -0.16)),
)
#: Camera of ``env.render()``, of the MuJoCo viewer at start-up and of ``myoexo video``.
DEFAULT_CAMERA = DEFAULT_CAMERAS[0].name


@dataclass(frozen=True)
class DirectionalLight:
    """A directional light of the scene.

    Attributes:
        name: Light name.
        direction: Direction the light shines in (world frame; normalised by MuJoCo).
        diffuse: Diffuse colour (RGB, 0..1).
        specular: Specular colour (RGB, 0..1).
        cast_shadow: Whether the light casts shadows (on the floor and plinth). Off by
            default: a shadow pass about triples the render time under software OpenGL
            (Mesa llvmpipe: ~0.4 s instead of ~0.14 s per 640x480 frame).
    """

    name: str
    direction: tuple[float, float, float]
    diffuse: RGB = (0.6, 0.6, 0.6)
    specular: RGB = (0.1, 0.1, 0.1)
    cast_shadow: bool = False


@dataclass(frozen=True)
class SceneParams:
    """Appearance and layout of the twin's surroundings (visual only).

    Attributes:
        floor_half_size_m: Half extent of the floor plane in x and y (m).
        floor_rgb: The floor's two checker colours (RGB).
        floor_tile_m: Size of one checker tile (m).
        floor_reflectance: Floor reflectance (0: matte; > 0 draws a mirror image).
        seat_gap_m: Gap between the plinth's top and the bottom of the thigh cuff (m);
            the plinth top sits at knee height minus the cuff radius minus this gap.
        seat_setback_m: Distance from the knee joint back to the plinth's front edge (m),
            so the shank and the shank cuff hang free.
        seat_depth_m: Plinth depth along x (m).
        seat_width_m: Plinth width along y (m), centred on the pelvis.
        cushion_thickness_m: Thickness of the plinth's cushion (m).
        cushion_rgba: Cushion colour.
        base_rgba: Colour of the plinth's base.
        skybox_rgb: Gradient skybox colours (top, bottom).
        haze_rgba: Haze colour where the floor meets the sky.
        headlight_ambient: Headlight ambient colour (RGB).
        headlight_diffuse: Headlight diffuse colour (RGB).
        headlight_specular: Headlight specular colour (RGB).
        lights: Directional lights (a key light from above and behind, a fill light
            from the front and the exo's side).
    """

    floor_half_size_m: float = 2.0
    floor_rgb: tuple[RGB, RGB] = ((0.62, 0.62, 0.60), (0.55, 0.55, 0.53))
    floor_tile_m: float = 0.25
    floor_reflectance: float = 0.0

    seat_gap_m: float = 0.01
    seat_setback_m: float = 0.08
    seat_depth_m: float = 0.6
    seat_width_m: float = 0.55
    cushion_thickness_m: float = 0.06
    cushion_rgba: RGBA = (0.30, 0.27, 0.25, 1.0)
    base_rgba: RGBA = (0.82, 0.82, 0.80, 1.0)

    skybox_rgb: tuple[RGB, RGB] = ((0.93, 0.93, 0.93), (0.62, 0.63, 0.65))
    haze_rgba: RGBA = (0.75, 0.76, 0.78, 1.0)
    headlight_ambient: RGB = (0.35, 0.35, 0.35)
    headlight_diffuse: RGB = (0.45, 0.45, 0.45)
    headlight_specular: RGB = (0.05, 0.05, 0.05)
    lights: tuple[DirectionalLight, ...] = field(
        default=(
            DirectionalLight("key_light", (-0.4, 0.3, -1.0), (0.55, 0.55, 0.55)),
            DirectionalLight("fill_light", (0.5, -0.6, -0.4), (0.25, 0.25, 0.27)),
        )
    )

    def __post_init__(self) -> None:
        positive = (
            "floor_half_size_m",
            "floor_tile_m",
            "seat_depth_m",
            "seat_width_m",
            "cushion_thickness_m",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"SceneParams.{name} must be > 0, got {value!r}")
        for name in ("seat_gap_m", "seat_setback_m", "floor_reflectance"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"SceneParams.{name} must be >= 0, got {value!r}")


def camera_frame(placement: CameraPlacement, knee_m: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World position and orientation (quaternion w, x, y, z) of a placed camera.

    The camera looks along :meth:`CameraPlacement.forward` at ``knee_m + lookat_offset_m``
    from ``distance_m`` away, with the image's vertical along the world's z.
    """
    forward = placement.forward()
    target = np.asarray(knee_m, dtype=float) + np.asarray(placement.lookat_offset_m)
    pos = target - placement.distance_m * forward
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    # MuJoCo cameras look along their -z axis, x to the right, y up.
    rot = np.column_stack([right, up, -forward])
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, rot.reshape(-1))
    return pos, quat


def add_cameras(
    spec: mujoco.MjSpec,
    knee_m: np.ndarray,
    cameras: tuple[CameraPlacement, ...] = DEFAULT_CAMERAS,
    default: str = DEFAULT_CAMERA,
) -> None:
    """Add fixed world cameras aimed at the knee, and make ``default`` the viewer's camera.

    Args:
        spec: The twin's (or the leg's) spec, edited in place.
        knee_m: World position of the knee joint in the seated pose (m).
        cameras: Placements of the cameras.
        default: Camera the MuJoCo viewer starts with (``visual/global/cameraid``).

    Raises:
        ValueError: ``default`` is not one of ``cameras``, or a camera name is taken.
    """
    names = [c.name for c in cameras]
    if default not in names:
        raise ValueError(f"default camera {default!r} is not one of {names}")
    taken = {c.name for c in spec.cameras}
    clash = taken.intersection(names)
    if clash:
        raise ValueError(f"the model already has cameras named {sorted(clash)}")
    first_id = len(spec.worldbody.cameras)  # world cameras come first in the model
    for placement in cameras:
        pos, quat = camera_frame(placement, knee_m)
        cam = spec.worldbody.add_camera()
        cam.name = placement.name
        cam.pos = pos
        cam.quat = quat
        cam.fovy = placement.fovy_deg
    spec.visual.global_.cameraid = first_id + names.index(default)


def _add_box(
    spec: mujoco.MjSpec, name: str, lo: np.ndarray, hi: np.ndarray, rgba: RGBA
) -> mujoco.MjsGeom:
    """A visual-only box spanning ``lo``..``hi`` (world frame, m) on the world body."""
    geom = spec.worldbody.add_geom()
    geom.name = name
    geom.type = mujoco.mjtGeom.mjGEOM_BOX
    geom.pos = 0.5 * (lo + hi)
    geom.size = 0.5 * (hi - lo)
    geom.rgba = np.asarray(rgba, dtype=float)
    _visual_only(geom)
    return geom


def _visual_only(geom: mujoco.MjsGeom) -> None:
    geom.contype = 0
    geom.conaffinity = 0
    geom.density = 0.0
    geom.group = SCENE_GEOM_GROUP


def add_scene(
    spec: mujoco.MjSpec,
    knee_m: np.ndarray,
    pelvis_m: np.ndarray,
    cuff_radius_m: float,
    scene: SceneParams | None = None,
) -> None:
    """Add the floor, the plinth, the lights and the skybox (visual only).

    Args:
        spec: The twin's (or the leg's) spec, edited in place.
        knee_m: World position of the knee joint in the seated pose (m).
        pelvis_m: World position of the pelvis (m); the plinth is centred on it in y.
        cuff_radius_m: Radius of the thigh cuff (m); the plinth's top clears it.
        scene: Appearance and layout; default ``SceneParams()``.

    Raises:
        ValueError: The plinth would not fit between the floor and the thigh.
    """
    p = SceneParams() if scene is None else scene
    knee = np.asarray(knee_m, dtype=float)
    pelvis = np.asarray(pelvis_m, dtype=float)

    sky = spec.add_texture()
    sky.name = "scene_skybox"
    sky.type = mujoco.mjtTexture.mjTEXTURE_SKYBOX
    sky.builtin = mujoco.mjtBuiltin.mjBUILTIN_GRADIENT
    sky.rgb1, sky.rgb2 = (np.asarray(c, dtype=float) for c in p.skybox_rgb)
    sky.width, sky.height = 512, 3072

    tiles = spec.add_texture()
    tiles.name = "scene_floor"
    tiles.type = mujoco.mjtTexture.mjTEXTURE_2D
    tiles.builtin = mujoco.mjtBuiltin.mjBUILTIN_CHECKER
    tiles.rgb1, tiles.rgb2 = (np.asarray(c, dtype=float) for c in p.floor_rgb)
    tiles.width, tiles.height = 300, 300
    material = spec.add_material()
    material.name = "scene_floor"
    textures = list(material.textures)
    textures[mujoco.mjtTextureRole.mjTEXROLE_RGB] = tiles.name
    material.textures = textures
    material.texuniform = True
    # texuniform: one texture repeat per 1/texrepeat m; a checker texture holds 2x2 tiles.
    material.texrepeat = np.full(2, 1.0 / (2.0 * p.floor_tile_m))
    material.reflectance = p.floor_reflectance

    floor = spec.worldbody.add_geom()
    floor.name = "floor"
    floor.type = mujoco.mjtGeom.mjGEOM_PLANE
    floor.size = np.array([p.floor_half_size_m, p.floor_half_size_m, 0.05])
    floor.material = material.name
    _visual_only(floor)

    top_z = knee[2] - cuff_radius_m - p.seat_gap_m
    cushion_z = top_z - p.cushion_thickness_m
    if cushion_z <= 0.0:
        raise ValueError(
            f"no room for the plinth: its top would be {top_z:.3f} m above the floor "
            f"(cushion {p.cushion_thickness_m} m); raise TwinParams.hip_height_m"
        )
    front_x = knee[0] - p.seat_setback_m
    back_x = front_x - p.seat_depth_m
    half_w = 0.5 * p.seat_width_m
    _add_box(
        spec,
        "seat_cushion",
        np.array([back_x, pelvis[1] - half_w, cushion_z]),
        np.array([front_x, pelvis[1] + half_w, top_z]),
        p.cushion_rgba,
    )
    _add_box(
        spec,
        "seat_base",
        np.array([back_x, pelvis[1] - half_w, 0.0]),
        np.array([front_x, pelvis[1] + half_w, cushion_z]),
        p.base_rgba,
    )

    head = spec.visual.headlight
    head.ambient = np.asarray(p.headlight_ambient, dtype=float)
    head.diffuse = np.asarray(p.headlight_diffuse, dtype=float)
    head.specular = np.asarray(p.headlight_specular, dtype=float)
    spec.visual.rgba.haze = np.asarray(p.haze_rgba, dtype=float)
    for light_params in p.lights:
        light = spec.worldbody.add_light()
        light.name = light_params.name
        light.type = mujoco.mjtLightType.mjLIGHT_DIRECTIONAL
        light.dir = np.asarray(light_params.direction, dtype=float)
        light.pos = knee + np.array([0.0, 0.0, 1.5])
        light.diffuse = np.asarray(light_params.diffuse, dtype=float)
        light.specular = np.asarray(light_params.specular, dtype=float)
        light.castshadow = light_params.cast_shadow


@dataclass(frozen=True)
class MuscleColors:
    """Muscle colour by activation (MyoSuite's convention).

    ``rgba = c * active_rgba + (1 - c) * rest_rgba`` with ``c = activation ** exponent``;
    the small exponent makes low activations (a reflex starting) visible.

    Attributes:
        rest_rgba: Colour of a muscle at zero activation.
        active_rgba: Colour at full activation (MyoSuite's red).
        exponent: Exponent of the activation in the blend weight (MyoSuite: 0.25).
    """

    rest_rgba: RGBA = (0.30, 0.25, 0.25, 1.0)
    active_rgba: RGBA = (0.95, 0.30, 0.30, 1.0)
    exponent: float = 0.25

    def __post_init__(self) -> None:
        if not (math.isfinite(self.exponent) and self.exponent > 0.0):
            raise ValueError(f"MuscleColors.exponent must be > 0, got {self.exponent!r}")


class MuscleColorizer:
    """Sets ``model.tendon_rgba`` of every muscle from its activation in ``data.act``.

    Resolves the muscles (actuators with muscle dynamics acting on a tendon) once; calling
    the object with a ``data`` updates the model's tendon colours (a visual field: the
    dynamics do not read it). Renderers copy the colours when they update their scene.

    Args:
        model: The twin (or any model with muscle actuators on tendons).
        colors: Rest and active colours.
    """

    def __init__(self, model: mujoco.MjModel, colors: MuscleColors | None = None) -> None:
        self.model = model
        self.colors = MuscleColors() if colors is None else colors
        muscle = (
            (model.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE)
            & (model.actuator_trntype == mujoco.mjtTrn.mjTRN_TENDON)
            & (model.actuator_actadr >= 0)
        )
        ids = np.flatnonzero(muscle)
        self.tendon_ids = model.actuator_trnid[ids, 0].astype(np.intp)
        self.act_adr = (model.actuator_actadr[ids] + model.actuator_actnum[ids] - 1).astype(np.intp)
        self._rest = np.asarray(self.colors.rest_rgba, dtype=float)
        self._span = np.asarray(self.colors.active_rgba, dtype=float) - self._rest

    def blend(self, activation: np.ndarray) -> np.ndarray:
        """``(n, 4)`` colours for activations ``activation`` (clipped to [0, 1])."""
        c = np.clip(np.asarray(activation, dtype=float), 0.0, 1.0) ** self.colors.exponent
        return self._rest + c[:, None] * self._span

    def __call__(self, data: mujoco.MjData) -> None:
        """Colour the muscles by their current activation."""
        self.model.tendon_rgba[self.tendon_ids] = self.blend(data.act[self.act_adr])
