"""Where the exo goes on the leg: the knee's mean flexion axis and the cuff frames.

Rajagopal's knee does not rotate about a fixed axis: the tibia translates a few mm and
rotates axially (~15 deg) as the knee flexes. A rigid exo hinge can only sit on one fixed
axis, so :func:`fit_knee_axis` finds the axis that best fits the tibia's motion over the
flexion range (least squares: the point ``c`` fixed in the femur frame and ``c'`` fixed in
the tibia frame minimising ``sum_k |R_k c' + p_k - c|^2``, the mean helical axis point),
and :func:`exo_geometry` lays the exo out around it. What is left of the misalignment is
taken up by the coupling joints (slide and pins) and the strap compliance.

All quantities are in the thigh body's (``femur_r``) frame at the model's reference pose
(knee extended, every joint 0), where the tibia frame is the femur frame shifted to the
knee: x anterior, y proximal, z lateral.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from myoexo.model.kinematics import coupled_joint_values, relative_pose
from myoexo.model.leg import KNEE_JOINT
from myoexo.model.params import TwinParams

__all__ = ["ExoGeometry", "KneeAxisFit", "exo_geometry", "fit_knee_axis"]

_AXIAL_JOINT = "knee_angle_rotation3_r"
_ABDUCTION_JOINT = "knee_angle_rotation2_r"


@dataclass(frozen=True)
class KneeAxisFit:
    """Least-squares fixed flexion axis of the knee (thigh frame).

    Attributes:
        point_m: A point of the axis in the knee's mid-plane (m, thigh frame).
        axis: Unit direction of the axis (the knee joint axis, flexion positive).
        rms_residual_m: RMS distance (m) the axis point fixed to the shank travels from
            the one fixed to the thigh over the fit range: how far the knee is from a
            fixed hinge.
        tibia_origin_m: Tibia origin at full extension (m, thigh frame).
        axial_axis: Unit axis of the tibia's axial rotation (tibia frame = thigh frame
            orientation at extension), through the tibia origin.
        abduction_axis: Unit axis of the tibia's coupled ab/adduction, through the tibia
            origin.
    """

    point_m: np.ndarray
    axis: np.ndarray
    rms_residual_m: float
    tibia_origin_m: np.ndarray
    axial_axis: np.ndarray
    abduction_axis: np.ndarray


@dataclass(frozen=True)
class ExoGeometry:
    """Positions (m) and axes of the exo in the thigh frame at the reference pose.

    Attributes:
        knee_axis: Unit axis of the exo hinge and the cuff pins (flexion positive).
        slide_axis: Unit axis of the thigh slider (along the femur, proximal positive).
        axial_axis: Unit axis of the shank cuff's axial pin (through the cuff centre).
        abduction_axis: Unit axis of the shank cuff's ab/adduction pin, through the tibia
            origin (``tibia_origin_m``), like the tibia's own coupled ab/adduction.
        thigh_cuff_m: Thigh cuff centre (on the femur's axis).
        thigh_pin_m: Thigh pin / slider point (lateral, at the thigh cuff).
        exo_knee_m: Exo hinge point (lateral, on the knee's mean flexion axis).
        shank_pin_m: Shank pin point (lateral, at the shank cuff).
        shank_cuff_m: Shank cuff centre (on the tibia's axial-rotation axis).
        tibia_origin_m: Tibia origin (to express the strap site in the tibia frame).
    """

    knee_axis: np.ndarray
    slide_axis: np.ndarray
    axial_axis: np.ndarray
    abduction_axis: np.ndarray
    thigh_cuff_m: np.ndarray
    thigh_pin_m: np.ndarray
    exo_knee_m: np.ndarray
    shank_pin_m: np.ndarray
    shank_cuff_m: np.ndarray
    tibia_origin_m: np.ndarray


def fit_knee_axis(
    model: mujoco.MjModel,
    params: TwinParams,
    *,
    knee_joint: str = KNEE_JOINT,
    n_samples: int = 40,
) -> KneeAxisFit:
    """Fit the knee's mean fixed flexion axis over ``params.knee_axis_fit_range_deg``.

    Args:
        model: Compiled human model containing the thigh/shank bodies and the coupled knee.
        params: Twin parameters (bodies and fit range).
        knee_joint: Independent knee flexion joint.
        n_samples: Number of knee angles sampled uniformly over the fit range.

    Returns:
        The fitted axis.
    """
    thigh = model.body(params.thigh_body).id
    shank = model.body(params.shank_body).id
    data = mujoco.MjData(model)
    lo, hi = (math.radians(v) for v in params.knee_axis_fit_range_deg)
    rows, rhs = [], []
    tibia_origin = None
    for angle in np.linspace(lo, hi, n_samples):
        data.qpos[:] = model.qpos0
        for adr, value in coupled_joint_values(model, knee_joint, float(angle)).items():
            data.qpos[adr] = value
        mujoco.mj_kinematics(model, data)
        rot, pos = relative_pose(data, thigh, shank)
        if tibia_origin is None:
            data.qpos[:] = model.qpos0
            mujoco.mj_kinematics(model, data)
            tibia_origin = relative_pose(data, thigh, shank)[1]
        # R c_shank + p = c_thigh  ->  [R, -I] [c_shank; c_thigh] = -p
        rows.append(np.hstack([rot, -np.eye(3)]))
        rhs.append(-pos)
    a_mat, b_vec = np.vstack(rows), np.concatenate(rhs)
    # Minimum-norm solution: unique up to a shift along the axis (fixed below).
    sol, *_ = np.linalg.lstsq(a_mat, b_vec, rcond=None)
    residual = a_mat @ sol - b_vec
    rms = float(np.sqrt(np.mean(np.sum(residual.reshape(-1, 3) ** 2, axis=1))))

    jid = model.joint(knee_joint).id
    axis = model.jnt_axis[jid] / np.linalg.norm(model.jnt_axis[jid])
    # Move the point along the axis to the knee's mid-plane (through the tibia origin).
    point = sol[3:] + axis * float(np.dot(tibia_origin - sol[3:], axis))
    axial = model.jnt_axis[model.joint(_AXIAL_JOINT).id]
    abduction = model.jnt_axis[model.joint(_ABDUCTION_JOINT).id]
    return KneeAxisFit(
        point_m=point,
        axis=axis,
        rms_residual_m=rms,
        tibia_origin_m=np.asarray(tibia_origin, dtype=float),
        axial_axis=axial / np.linalg.norm(axial),
        abduction_axis=abduction / np.linalg.norm(abduction),
    )


def exo_geometry(fit: KneeAxisFit, params: TwinParams) -> ExoGeometry:
    """Lay the exo out around the fitted knee axis.

    The hinge sits on the fitted axis, ``exo_lateral_offset_m`` lateral of the knee's
    mid-plane; the thigh cuff is ``thigh_cuff_distance_m`` above the axis on the femur's
    axis (hip centre to knee); the shank cuff is ``shank_cuff_distance_m`` below the knee
    on the tibia's axial-rotation axis, so the cuff's axial pin turns with the tibia, and
    the cuff's ab/adduction pin shares the tibia's coupled ab/adduction axis.

    Args:
        fit: Fitted knee axis.
        params: Twin parameters (cuff distances, lateral offset).

    Returns:
        The exo geometry in the thigh frame.
    """
    axis = fit.axis
    # The knee axis points medially for flexion-positive (right leg): lateral = -axis.
    lateral = -axis
    # Femur axis: from the knee towards the hip centre (the thigh frame origin).
    femur_dir = -fit.tibia_origin_m / np.linalg.norm(fit.tibia_origin_m)
    thigh_cuff = fit.point_m + params.thigh_cuff_distance_m * femur_dir
    # Tibia's axial-rotation axis passes through the tibia origin; go distally along it.
    distal = -fit.axial_axis if fit.axial_axis[1] > 0 else fit.axial_axis
    shank_cuff = fit.tibia_origin_m + params.shank_cuff_distance_m * distal
    offset = params.exo_lateral_offset_m * lateral

    def in_plane(point: np.ndarray) -> np.ndarray:
        # Shift a point along the knee axis into the exo's lateral plane.
        plane_point = fit.point_m + offset
        return point + axis * float(np.dot(plane_point - point, axis))

    return ExoGeometry(
        knee_axis=axis,
        slide_axis=femur_dir,
        axial_axis=-distal,
        abduction_axis=fit.abduction_axis,
        thigh_cuff_m=thigh_cuff,
        thigh_pin_m=in_plane(thigh_cuff),
        exo_knee_m=fit.point_m + offset,
        shank_pin_m=in_plane(shank_cuff),
        shank_cuff_m=shank_cuff,
        tibia_origin_m=fit.tibia_origin_m,
    )
