"""Build the seated leg and the coupled human + knee-exoskeleton twin.

Both models come from MyoSuite's leg fragment through
:class:`myosuite.core.model_builder.ModelBuilder` (see :mod:`myoexo.model.leg`); the twin
adds the exo fragment (:mod:`myoexo.model.exo`) at the thigh, laid out on the knee's mean
flexion axis (:mod:`myoexo.model.geometry`), the strap weld to the shank, and a keyframe
``seated_90`` (knee at 90 deg, loop closed) for easy resets. Both models get the named
cameras of :mod:`myoexo.model.scene` and, with ``TwinParams.scene`` (default), its floor,
plinth, lights and skybox (visual only: no effect on the dynamics).
"""

from __future__ import annotations

import functools

import mujoco
import numpy as np

from myoexo.model.drive import STOP_PROTECTION_NUMERIC
from myoexo.model.exo import EXO_ACTUATOR, exo_spec, strap_to_shank
from myoexo.model.geometry import ExoGeometry, KneeAxisFit, exo_geometry, fit_knee_axis
from myoexo.model.leg import (
    KNEE_JOINT,
    PELVIS_BODY,
    build_spec_quietly,
    compile_quietly,
    leg_builder,
    standalone_spec,
)
from myoexo.model.params import TwinParams
from myoexo.model.posing import pose_twin
from myoexo.model.scene import add_cameras, add_scene

__all__ = [
    "HOME_KEY",
    "HOME_KNEE_ANGLE_DEG",
    "KNEE_ANGLE_SENSOR",
    "build_leg_model",
    "build_model",
    "knee_axis_fit",
    "twin_geometry",
]

#: Keyframe of both models: seated, knee at :data:`HOME_KNEE_ANGLE_DEG`, at rest.
HOME_KEY = "seated_90"
HOME_KNEE_ANGLE_DEG = 90.0
#: The twin's knee-angle sensor: after ``mj_step`` it holds the knee angle of the state the
#: step started from, where the step's forces were computed (:class:`~myoexo.envs.twin.Twin`
#: reads it instead of stopping before the control period's last timestep).
KNEE_ANGLE_SENSOR = "knee_angle"


def _check_bodies(spec: mujoco.MjSpec, params: TwinParams) -> None:
    names = {body.name for body in spec.bodies}
    for field in ("thigh_body", "shank_body"):
        if getattr(params, field) not in names:
            raise ValueError(
                f"TwinParams.{field} = {getattr(params, field)!r} is not a body of the leg "
                f"model; expected one of {sorted(n for n in names if n)}"
            )


def _finish(spec: mujoco.MjSpec, model: mujoco.MjModel, params: TwinParams) -> mujoco.MjModel:
    """Pose the model at the home pose (:func:`pose_twin`), add the ``seated_90`` keyframe,
    the named cameras aimed at the posed knee and (``params.scene``) the visual scene, and
    recompile."""
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=HOME_KNEE_ANGLE_DEG)
    key = spec.add_key()
    key.name = HOME_KEY
    key.qpos = data.qpos.copy()
    key.qvel = np.zeros(model.nv)
    key.act = np.zeros(model.na)
    key.ctrl = np.zeros(model.nu)
    knee_m = data.xanchor[model.joint(KNEE_JOINT).id].copy()
    add_cameras(spec, knee_m)
    if params.scene:
        pelvis_m = data.xpos[model.body(PELVIS_BODY).id].copy()
        add_scene(spec, knee_m, pelvis_m, params.cuff_radius_m)
    return compile_quietly(spec)


def build_leg_model(params: TwinParams | None = None) -> tuple[mujoco.MjModel, mujoco.MjSpec]:
    """The seated one-leg model WITHOUT the exo (the benchmark baseline).

    Args:
        params: Twin parameters (hip posture, timestep, ...); default ``TwinParams()``.

    Returns:
        ``(model, spec)``: 40 ``*_r`` muscles, pelvis fixed, hip locked, no contacts;
        the named cameras and (``params.scene``) the visual scene.

    Raises:
        ValueError: If ``params.thigh_body`` / ``shank_body`` are not bodies of the leg.
    """
    params = TwinParams() if params is None else params
    spec = build_spec_quietly(leg_builder(params))
    _check_bodies(spec, params)
    spec = standalone_spec(spec)
    model = _finish(spec, compile_quietly(spec), params)
    return model, spec


@functools.lru_cache(maxsize=8)
def knee_axis_fit(params: TwinParams) -> KneeAxisFit:
    """Least-squares mean flexion axis of the subject's knee (cached per ``params``)."""
    spec = build_spec_quietly(leg_builder(params))
    _check_bodies(spec, params)
    return fit_knee_axis(compile_quietly(spec), params)


def twin_geometry(params: TwinParams | None = None) -> ExoGeometry:
    """Exo layout (thigh frame) that :func:`build_model` uses for ``params``."""
    params = TwinParams() if params is None else params
    return exo_geometry(knee_axis_fit(params), params)


def build_model(params: TwinParams | None = None) -> tuple[mujoco.MjModel, mujoco.MjSpec]:
    """The coupled human + knee-exoskeleton twin.

    Args:
        params: Twin parameters; default ``TwinParams()`` (paper values).

    Returns:
        ``(model, spec)``. Actuators: the 40 ``*_r`` muscles, then ``exo_motor`` (last).
        Keyframe ``seated_90``: knee at 90 deg with the strap loop closed. Cameras
        :data:`~myoexo.model.scene.DEFAULT_CAMERAS`; with ``params.scene``, the floor,
        plinth, lights and skybox of :func:`~myoexo.model.scene.add_scene`.

    Raises:
        ValueError: If ``params.thigh_body`` / ``shank_body`` are not bodies of the leg.
    """
    params = TwinParams() if params is None else params
    geometry = twin_geometry(params)
    builder = (
        leg_builder(params)
        .attach_spec(exo_spec(params, geometry), name="exo_knee", parent=params.thigh_body)
        .apply_transform(strap_to_shank(params, geometry))
    )
    spec = build_spec_quietly(builder)
    spec.modelname = "myoexo_twin"
    spec = standalone_spec(spec)
    spec.add_numeric(
        name=STOP_PROTECTION_NUMERIC,
        data=[params.exo_stop_braking_fraction, params.exo_stop_contact_speed_rad_s],
    )
    spec.add_sensor(
        name=KNEE_ANGLE_SENSOR,
        type=mujoco.mjtSensor.mjSENS_JOINTPOS,
        objtype=mujoco.mjtObj.mjOBJ_JOINT,
        objname=KNEE_JOINT,
    )
    model = compile_quietly(spec)
    if model.actuator(model.nu - 1).name != EXO_ACTUATOR:
        raise RuntimeError("exo_motor must be the last actuator of the twin")
    model = _finish(spec, model, params)
    return model, spec
