"""The human + knee-exoskeleton digital twin, built on MyoSuite's leg model.

Public API::

    from myoexo.model import TwinParams, build_model, build_leg_model, pose_twin

    model, spec = build_model(TwinParams())      # coupled human + exo twin
    model, spec = build_leg_model(TwinParams())  # the same seated leg without the exo
    pose_twin(model, data, knee_angle_deg=90.0)  # consistent pose at a knee angle, at rest

Names: human knee ``knee_angle_r`` and exo hinge ``exo_knee`` (rad, 0 = extended,
flexion positive); coupling joints ``exo_thigh_slide``, ``exo_thigh_pin``,
``exo_shank_pin``, ``exo_shank_axial``; actuator ``exo_motor`` (last; ctrl in [-1, 1],
actuator force in Nm, positive = flexion); sensors ``exo_knee_pos``, ``exo_knee_vel``,
``exo_motor_torque``, ``{thigh,shank}_cuff_{force,torque}``; keyframe ``seated_90``.
"""

from myoexo.model.build import (
    HOME_KEY,
    HOME_KNEE_ANGLE_DEG,
    KNEE_ANGLE_SENSOR,
    build_leg_model,
    build_model,
    knee_axis_fit,
    twin_geometry,
)
from myoexo.model.exo import (
    COUPLING_JOINTS,
    CUFF_SENSORS,
    EXO_ACTUATOR,
    EXO_JOINT,
    EXO_JOINTS,
    EXO_SENSORS,
    STRAP_EQUALITY,
    strap_knee_torque,
)
from myoexo.model.leg import HIP_JOINTS, KNEE_JOINT
from myoexo.model.params import TWIN_VERSION, TwinParams, recorded_twin_version
from myoexo.model.posing import pose_twin, strap_violation

__all__ = [
    "COUPLING_JOINTS",
    "CUFF_SENSORS",
    "EXO_ACTUATOR",
    "EXO_JOINT",
    "EXO_JOINTS",
    "EXO_SENSORS",
    "HIP_JOINTS",
    "HOME_KEY",
    "HOME_KNEE_ANGLE_DEG",
    "KNEE_ANGLE_SENSOR",
    "KNEE_JOINT",
    "STRAP_EQUALITY",
    "TWIN_VERSION",
    "TwinParams",
    "build_leg_model",
    "build_model",
    "knee_axis_fit",
    "pose_twin",
    "recorded_twin_version",
    "strap_knee_torque",
    "strap_violation",
    "twin_geometry",
]
