"""Put the twin (or the bare leg) at a knee angle, consistent with all its constraints.

:func:`pose_twin` sets ``qpos`` so that

* every locked joint (a joint equality with no second joint, e.g. the hip lock) sits at
  its locked value;
* the human knee is at the requested angle with Rajagopal's dependent knee and patella
  coordinates on their coupling polynomials;
* the exo joints close the strap loop: a few Gauss-Newton iterations bring the shank
  strap weld's violation to its least-squares minimum, with the coupling joints'
  springs as a small regulariser that picks the least-strained configuration among the
  exo's redundant ones;

then zeroes ``qvel`` and calls ``mj_forward``. Everything else is at ``model.qpos0``.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from myoexo.model.exo import EXO_JOINT, EXO_JOINTS, STRAP_SITES
from myoexo.model.kinematics import coupled_joint_values
from myoexo.model.leg import KNEE_JOINT

__all__ = ["pose_twin", "strap_violation"]

#: Length (m) that converts strap rotation error (rad) into a comparable distance.
_ROT_LENGTH_M = 0.1
#: Nominal strap stiffness (N/m) that weighs the coupling springs' energy against the
#: strap violation when the loop is closed.
_STRAP_STIFFNESS_N_M = 1e7
#: Levenberg-Marquardt damping (m^2) and per-iteration step bound (rad or m).
_LM_DAMPING = 1e-5
_MAX_STEP = 0.05
_MAX_ITERATIONS = 100


def _rotation_vector(mat: np.ndarray) -> np.ndarray:
    """Rotation vector (axis * angle, rad) of a 3x3 rotation matrix."""
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat.reshape(-1))
    vel = np.zeros(3)
    mujoco.mju_quat2Vel(vel, quat, 1.0)
    return vel


def strap_violation(model: mujoco.MjModel, data: mujoco.MjData) -> tuple[float, float]:
    """Current violation of the shank strap weld (after ``mj_kinematics``).

    Returns:
        ``(distance_m, angle_rad)`` between the cuff's and the tibia's strap sites.
    """
    s1, s2 = (model.site(name).id for name in STRAP_SITES)
    dist = float(np.linalg.norm(data.site_xpos[s1] - data.site_xpos[s2]))
    rel = data.site_xmat[s2].reshape(3, 3).T @ data.site_xmat[s1].reshape(3, 3)
    return dist, float(np.linalg.norm(_rotation_vector(rel)))


def _strap_residual(data: mujoco.MjData, s1: int, s2: int) -> np.ndarray:
    pos = data.site_xpos[s1] - data.site_xpos[s2]
    rel = data.site_xmat[s1].reshape(3, 3) @ data.site_xmat[s2].reshape(3, 3).T
    return np.concatenate([pos, _ROT_LENGTH_M * _rotation_vector(rel)])


def _close_exo_loop(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    """Solve the exo joints so that the strap weld is (least-squares) satisfied.

    Minimises ``|r(q)|^2 + sum_i (k_i / k_strap) q_i^2`` over the exo joints ``q`` by
    damped Gauss-Newton with backtracking, where ``r`` is the strap weld residual
    (position, and rotation times :data:`_ROT_LENGTH_M`) and ``k_i`` the joints' spring
    stiffnesses: the least-strained closure of the loop.
    """
    s1, s2 = (model.site(name).id for name in STRAP_SITES)
    joints = [model.joint(name).id for name in EXO_JOINTS]
    qadr = np.array([model.jnt_qposadr[j] for j in joints])
    dadr = np.array([model.jnt_dofadr[j] for j in joints])
    lo, hi = model.jnt_range[joints, 0], model.jnt_range[joints, 1]
    reg = model.jnt_stiffness[joints] / _STRAP_STIFFNESS_N_M
    jacp1, jacr1 = np.zeros((3, model.nv)), np.zeros((3, model.nv))
    jacp2, jacr2 = np.zeros((3, model.nv)), np.zeros((3, model.nv))

    def objective() -> tuple[float, np.ndarray]:
        mujoco.mj_kinematics(model, data)
        res = _strap_residual(data, s1, s2)
        q = data.qpos[qadr]
        return float(res @ res + np.sum(reg * q * q)), res

    cost, res = objective()
    for _ in range(_MAX_ITERATIONS):
        mujoco.mj_comPos(model, data)
        mujoco.mj_jacSite(model, data, jacp1, jacr1, s1)
        mujoco.mj_jacSite(model, data, jacp2, jacr2, s2)
        jac = np.vstack([jacp1 - jacp2, _ROT_LENGTH_M * (jacr1 - jacr2)])[:, dadr]
        q = data.qpos[qadr].copy()
        lhs = jac.T @ jac + np.diag(reg) + _LM_DAMPING * np.eye(len(joints))
        step = np.linalg.solve(lhs, -(jac.T @ res) - reg * q)
        step *= min(1.0, _MAX_STEP / max(float(np.max(np.abs(step))), 1e-300))
        scale = 1.0
        while scale > 1e-4:
            data.qpos[qadr] = np.clip(q + scale * step, lo, hi)
            new_cost, new_res = objective()
            if new_cost <= cost:
                break
            scale *= 0.5
        else:  # no descent: converged (or stuck at a limit)
            data.qpos[qadr] = q
            mujoco.mj_kinematics(model, data)
            break
        converged = cost - new_cost < 1e-16
        cost, res = new_cost, new_res
        if converged:
            break


def pose_twin(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    knee_angle_deg: float = 90.0,
) -> None:
    """Pose the twin (or the bare leg) with the human knee at ``knee_angle_deg``.

    Args:
        model: Twin from :func:`~myoexo.model.build.build_model` or leg from
            :func:`~myoexo.model.build.build_leg_model`.
        data: Its data; ``qpos``/``qvel`` are overwritten, then ``mj_forward`` runs.
        knee_angle_deg: Human knee flexion (deg; 0 = full extension, flexion positive),
            within the model's ``knee_angle_r`` range.

    Raises:
        ValueError: If ``knee_angle_deg`` is outside the human knee's joint range.
    """
    knee = model.joint(KNEE_JOINT).id
    lo, hi = np.degrees(model.jnt_range[knee])
    if not lo <= knee_angle_deg <= hi:
        raise ValueError(
            f"knee_angle_deg must be within the knee range [{lo:.1f}, {hi:.1f}] deg, "
            f"got {knee_angle_deg!r}"
        )
    data.qpos[:] = model.qpos0
    # Locked joints (joint equalities without a second joint): q = c0.
    for eq in range(model.neq):
        if model.eq_type[eq] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj2id[eq] < 0:
            data.qpos[model.jnt_qposadr[model.eq_obj1id[eq]]] = model.eq_data[eq, 0]
    angle = math.radians(knee_angle_deg)
    for adr, value in coupled_joint_values(model, KNEE_JOINT, angle).items():
        data.qpos[adr] = value
    if mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, EXO_JOINT) >= 0:
        data.qpos[model.joint(EXO_JOINT).qposadr[0]] = angle
        _close_exo_loop(model, data)
    data.qvel[:] = 0.0
    mujoco.mj_forward(model, data)
