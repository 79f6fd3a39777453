"""Rajagopal's coupled knee: the dependent knee coordinates as functions of flexion.

MyoSuite's Rajagopal knee has one independent coordinate, ``knee_angle_r``, and
dependent ones (tibial translations ``knee_angle_translation{1,2}_r``, rotations
``knee_angle_rotation{2,3}_r`` and the patella's ``knee_angle_beta_*_r``) tied to it by
joint equalities ``q_dep = polyval(polycoef, q_knee)``. This module evaluates those
polynomials from the compiled model, so posing and the exo placement use exactly the
model's own coupling.
"""

from __future__ import annotations

import mujoco
import numpy as np

__all__ = ["coupled_joint_values", "relative_pose"]


def coupled_joint_values(model: mujoco.MjModel, joint: str, value_rad: float) -> dict[int, float]:
    """Values of every joint coupled to ``joint`` by a polynomial joint equality.

    Args:
        model: Compiled model.
        joint: Independent joint name (e.g. ``"knee_angle_r"``).
        value_rad: Its value (rad, or m for a slide joint).

    Returns:
        ``{qpos address: value}`` for ``joint`` itself and every dependent joint
        ``q = c0 + c1 x + c2 x^2 + c3 x^3 + c4 x^4`` with ``x = value_rad``.
    """
    jid = model.joint(joint).id
    values = {int(model.jnt_qposadr[jid]): float(value_rad)}
    for eq in range(model.neq):
        if model.eq_type[eq] != mujoco.mjtEq.mjEQ_JOINT or model.eq_obj2id[eq] != jid:
            continue
        c = model.eq_data[eq, :5]
        x = float(value_rad)
        q = c[0] + c[1] * x + c[2] * x**2 + c[3] * x**3 + c[4] * x**4
        values[int(model.jnt_qposadr[model.eq_obj1id[eq]])] = float(q)
    return values


def relative_pose(
    data: mujoco.MjData, parent_body: int, child_body: int
) -> tuple[np.ndarray, np.ndarray]:
    """Pose of ``child_body`` in ``parent_body``'s frame (after ``mj_kinematics``).

    Returns:
        ``(R, p)``: rotation matrix (3x3) and position (m) of the child in the parent frame.
    """
    r_parent = data.xmat[parent_body].reshape(3, 3)
    r_child = data.xmat[child_body].reshape(3, 3)
    rot = r_parent.T @ r_child
    pos = r_parent.T @ (data.xpos[child_body] - data.xpos[parent_body])
    return rot, pos
