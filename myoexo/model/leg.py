"""The seated one-leg human model, cut from MyoSuite's leg model with ``mujoco.MjSpec``.

MyoSuite's ``"leg"`` fragment (``myo_sim``'s composed ``myolegs``: pelvis fixed to its
root, both legs, 80 muscles, Rajagopal's coupled knees) is loaded through
:class:`myosuite.core.model_builder.ModelBuilder`; :func:`seat_subject` then

* removes the left leg with its muscles, tendons, equalities, sensors and the pelvis
  wrapping geoms / sites only the left muscles use;
* turns the root so the subject faces +x (z up) at ``hip_height_m`` (the pelvis has no
  joint: it is fixed to the world, a seated subject);
* locks the right hip at ``hip_flexion_deg`` (adduction, rotation 0) with joint
  equalities, so the thigh is horizontal and the shank hangs under gravity;
* keeps the knee (with Rajagopal's coupled translations/rotations and the patella
  equalities), ankle, subtalar and mtp joints free;
* gives the knee its passive moment and damping (``TwinParams.passive_knee``,
  :mod:`myoexo.model.passive_knee`);
* disables all contacts (and drops the foot touch sensors): a single seated leg without
  floor has nothing to touch, and the broad phase then costs nothing.

Nothing in MyoSuite's XML files is edited; all changes are made on the spec.
"""

from __future__ import annotations

import contextlib
import math
import warnings
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import mujoco
import numpy as np

from myoexo.model.params import TwinParams
from myoexo.model.passive_knee import install_passive_knee

if TYPE_CHECKING:
    from myosuite.core.model_builder import ModelBuilder

__all__ = [
    "HIP_JOINTS",
    "KNEE_JOINT",
    "LEG_FRAGMENT",
    "PELVIS_BODY",
    "build_spec_quietly",
    "compile_quietly",
    "hip_lock_name",
    "leg_builder",
    "seat_subject",
    "standalone_spec",
]

#: MyoSuite fragment name of the leg model (resolved by ``ModelBuilder``).
LEG_FRAGMENT = "leg"
#: Human knee flexion joint (radians, 0 = full extension, flexion positive).
KNEE_JOINT = "knee_angle_r"
#: The pelvis body (fixed to the world: the seated subject's root).
PELVIS_BODY = "pelvis"
#: Right-hip joints locked by joint equalities.
HIP_JOINTS: tuple[str, ...] = ("hip_flexion_r", "hip_adduction_r", "hip_rotation_r")
#: Root rotation that turns MyoSuite's pelvis (facing -y) to face +x: 90 deg about z.
_ROOT_QUAT = (math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4))


def hip_lock_name(joint: str) -> str:
    """Name of the joint equality that locks ``joint``."""
    return f"{joint}_lock"


def _is_left(name: str) -> bool:
    return name.endswith("_l") or "_l_" in name or name.startswith(("l_", "foot_touch_l"))


def _remove_left_leg(spec: mujoco.MjSpec) -> None:
    """Delete the left leg and everything that refers to it (order matters)."""
    for actuator in [a for a in spec.actuators if _is_left(a.name)]:
        spec.delete(actuator)
    for tendon in [t for t in spec.tendons if _is_left(t.name)]:
        spec.delete(tendon)
    for eq in [e for e in spec.equalities if _is_left(e.name)]:
        spec.delete(eq)
    # Left sensors, and the foot touch sensors: with contacts off they would read 0.
    for sensor in [
        s for s in spec.sensors if _is_left(s.name) or s.type == mujoco.mjtSensor.mjSENS_TOUCH
    ]:
        spec.delete(sensor)
    spec.delete(spec.body("femur_l"))
    pelvis = spec.body(PELVIS_BODY)
    for site in [s for s in pelvis.sites if _is_left(s.name)]:
        spec.delete(site)
    # Left wrapping surfaces only (the "pelvis_l" mesh is the left hemipelvis: kept).
    for geom in [g for g in pelvis.geoms if _is_left(g.name) and "wrap" in g.name]:
        spec.delete(geom)


def _lock_hip(spec: mujoco.MjSpec, params: TwinParams) -> None:
    """Hold the right hip at the seated posture with stiff joint equalities."""
    targets_deg = (params.hip_flexion_deg, params.hip_adduction_deg, params.hip_rotation_deg)
    for joint, target_deg in zip(HIP_JOINTS, targets_deg, strict=True):
        eq = spec.add_equality()
        eq.name = hip_lock_name(joint)
        eq.type = mujoco.mjtEq.mjEQ_JOINT
        eq.objtype = mujoco.mjtObj.mjOBJ_JOINT
        eq.name1 = joint
        data = np.zeros(len(eq.data))
        data[0] = math.radians(target_deg)  # polycoef: q = c0 (no second joint)
        eq.data = data
        eq.solref = np.asarray(params.hip_lock_solref, dtype=float)
        eq.solimp = np.asarray(params.hip_lock_solimp, dtype=float)


def seat_subject(params: TwinParams) -> Callable[[mujoco.MjSpec], mujoco.MjSpec]:
    """Return a ``ModelBuilder`` transform that makes the seated right-leg subject.

    Args:
        params: Twin parameters (hip posture and lock, hip height, timestep).

    Returns:
        A function ``spec -> spec`` that edits the spec in place and returns it.
    """

    def transform(spec: mujoco.MjSpec) -> mujoco.MjSpec:
        _remove_left_leg(spec)
        root = spec.body("myolegs_root")
        root.pos = np.array([0.0, 0.0, params.hip_height_m])
        root.quat = np.array(_ROOT_QUAT)
        _lock_hip(spec, params)
        if params.passive_knee == "riener_edrich":
            install_passive_knee(
                spec,
                knee_joint=KNEE_JOINT,
                hip_deg=params.hip_flexion_deg,
                damping_nm_s_rad=params.knee_damping_nm_s_rad,
            )
        else:
            spec.joint(KNEE_JOINT).damping = np.array([params.knee_damping_nm_s_rad, 0.0, 0.0])
        for geom in spec.geoms:
            geom.contype = 0
            geom.conaffinity = 0
        spec.option.timestep = params.timestep_s
        spec.modelname = "myoexo_seated_leg"
        return spec

    return transform


def leg_builder(params: TwinParams) -> ModelBuilder:
    """Return a MyoSuite ``ModelBuilder`` recipe for the seated leg (no exo).

    Args:
        params: Twin parameters.

    Returns:
        ``myosuite.core.model_builder.ModelBuilder`` with the leg fragment and the
        :func:`seat_subject` transform recorded; further fragments/transforms may be added.
    """
    from myosuite.core.model_builder import ModelBuilder

    return (
        ModelBuilder()
        .attach_fragment(LEG_FRAGMENT)
        .apply_transform(seat_subject(params))
        .set_timestep(params.timestep_s)
    )


_EMPTY_PREFIX_WARNING = "Attaching a spec with an empty prefix"


@contextlib.contextmanager
def _quiet_empty_prefix() -> Iterator[None]:
    """Swallow MuJoCo's empty-prefix attach warning, at the Python level and at the C level
    (where it is printed to stderr and ``MUJOCO_LOG.TXT``); other MuJoCo warnings are
    re-issued as Python ``RuntimeWarning``s while the block runs."""
    previous = mujoco.get_mju_user_warning()

    def handler(message: str) -> None:
        if _EMPTY_PREFIX_WARNING not in message:
            warnings.warn(f"MuJoCo: {message}", RuntimeWarning, stacklevel=2)

    mujoco.set_mju_user_warning(handler)
    try:
        with warnings.catch_warnings():
            warnings.filterwarnings("ignore", message=_EMPTY_PREFIX_WARNING)
            yield
    finally:
        mujoco.set_mju_user_warning(previous)


def build_spec_quietly(builder: ModelBuilder) -> mujoco.MjSpec:
    """Compose ``builder``'s spec, silencing MuJoCo's empty-prefix attach warning.

    ``ModelBuilder`` attaches fragments with an empty name prefix (names stay as in
    MyoSuite: ``knee_angle_r``, ...); MuJoCo warns that such specs may not round-trip
    through XML. The twin's export is checked to round-trip (``tests/test_model.py``).
    """
    with _quiet_empty_prefix():
        return builder.build_spec()


def standalone_spec(spec: mujoco.MjSpec) -> mujoco.MjSpec:
    """Re-create ``spec`` from its own XML: a self-contained spec with no attachments.

    The copy has an absolute ``meshdir`` (MyoSuite's mesh folder), so its XML loads from
    anywhere, drops meshes no geom uses (the removed left leg's), and compiles without
    MuJoCo's empty-prefix attach warning. Building it costs one XML round trip (~50 ms).
    """
    used = {geom.meshname for geom in spec.geoms if geom.meshname}
    for mesh in [m for m in spec.meshes if m.name not in used]:
        spec.delete(mesh)
    spec.meshdir = str(_myo_sim_models_dir())
    with _quiet_empty_prefix():
        xml = spec.to_xml()
    return mujoco.MjSpec.from_string(xml)


def _myo_sim_models_dir() -> Path:
    """MyoSuite's model folder (``myo_sim/models``), where the leg's ``meshes/`` live."""
    import myo_sim

    return Path(myo_sim.__file__).resolve().parent / "models"


def compile_quietly(spec: mujoco.MjSpec) -> mujoco.MjModel:
    """``spec.compile()`` without the (expected) empty-prefix attach warning."""
    with _quiet_empty_prefix():
        return spec.compile()
