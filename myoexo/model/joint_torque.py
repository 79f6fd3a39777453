"""Actuator torque along a joint whose motion drags coupled joints with it.

Rajagopal's knee moves the tibia's translations/rotations and the patella as polynomial
functions of the flexion angle (MuJoCo joint equalities ``q_j = poly_j(theta)``). The quadriceps
pull on the patella, so ``qfrc_actuator`` at ``knee_angle_r`` alone misstates their knee
torque (by a factor of ~2 for vastus intermedius at 90 deg). By virtual work the torque
along the coupled motion is ``qfrc[theta] + sum_j qfrc[q_j] * dpoly_j/dtheta``.
"""

from __future__ import annotations

from typing import ClassVar

import mujoco
import numpy as np


def joint_inertia(model: mujoco.MjModel, data: mujoco.MjData, joint: str) -> float:
    """The diagonal entry of the joint space inertia matrix at *joint*'s dof (kg m^2 for a
    hinge): the inertia the joint moves on its own at *data*'s pose (``mj_forward`` done)."""
    dense = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, dense)
    dof = int(model.jnt_dofadr[model.joint(joint).id])
    return float(dense[dof, dof])


class CoupledJointTorque:
    """Generalized actuator force along a joint and every joint tied to it by a polynomial
    joint equality (``eq_obj2id`` = that joint).

    Args:
        model: The compiled model.
        joint: Name of the independent joint (e.g. ``"knee_angle_r"``).

    Raises:
        ValueError: If the model has no such hinge/slide joint.
    """

    def __init__(self, model: mujoco.MjModel, joint: str) -> None:
        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, joint)
        if jid < 0:
            raise ValueError(f"joint {joint!r} is not in the model")
        self.joint = joint
        self._qadr = int(model.jnt_qposadr[jid])
        self._dadr = int(model.jnt_dofadr[jid])
        eqs = [
            eq
            for eq in range(model.neq)
            if model.eq_type[eq] == mujoco.mjtEq.mjEQ_JOINT and model.eq_obj2id[eq] == jid
        ]
        self.dependent_dofs = np.array(
            [model.jnt_dofadr[model.eq_obj1id[eq]] for eq in eqs], dtype=np.intp
        )
        coef = np.array([model.eq_data[eq, 1:5] for eq in eqs]).reshape(len(eqs), 4)
        # d/dx (c1 x + c2 x^2 + c3 x^3 + c4 x^4) = c1 + 2 c2 x + 3 c3 x^2 + 4 c4 x^3
        self._dcoef = coef * np.arange(1, 5)
        # torque = [qfrc[theta], qfrc[q_j]...] @ _power_coef @ [1, x, x^2, x^3]
        self._dofs = np.concatenate([[self._dadr], self.dependent_dofs]).astype(np.intp)
        self._power_coef = np.vstack([[1.0, 0.0, 0.0, 0.0], self._dcoef])

    def transmission(self, data: mujoco.MjData) -> np.ndarray:
        """``d q_j / d theta`` of every dependent joint at the current angle."""
        x = float(data.qpos[self._qadr])
        return self._dcoef @ np.array([1.0, x, x * x, x * x * x])

    def torque_at(self, theta: float, qfrc: np.ndarray) -> float:
        """Torque (Nm) of the generalized force ``qfrc`` along the joint at joint value *theta*.

        ``qfrc[theta] + sum_j qfrc[q_j] * dpoly_j/dtheta(theta)``, regrouped by powers of
        *theta*: ``s = [qfrc[theta], qfrc[q_j]...] @ W`` (one small product) and then
        ``s0 + s1 theta + s2 theta^2 + s3 theta^3`` on python floats. Cheaper than two numpy
        products, which matters in an env step; equal to ``qfrc[theta] + qfrc[q_j] @
        transmission`` up to rounding.
        """
        return self.torque_of_dofs(theta, qfrc[self._dofs])

    @property
    def dofs(self) -> np.ndarray:
        """The joint's DOF and its dependent DOFs, in the order :meth:`torque_of_dofs` takes."""
        return self._dofs

    def torque_of_dofs(self, theta: float, qfrc_dofs: np.ndarray) -> float:
        """:meth:`torque_at` from the generalized force's entries at :attr:`dofs` only."""
        s0, s1, s2, s3 = qfrc_dofs.dot(self._power_coef).tolist()
        x = theta
        return s0 + x * (s1 + x * (s2 + x * s3))

    def from_generalized(self, data: mujoco.MjData, qfrc: np.ndarray) -> float:
        """Torque (Nm, positive along the joint) of a generalized force vector ``qfrc``."""
        return self.torque_at(float(data.qpos[self._qadr]), qfrc)

    def __call__(self, data: mujoco.MjData) -> float:
        """Actuator torque along the joint from the last computed ``qfrc_actuator`` (Nm)."""
        return self.from_generalized(data, data.qfrc_actuator)


class EqualityJointTorque:
    """Torque an equality constraint (e.g. the weld of a strap) transmits along a coupled
    joint: its constraint force ``J_eq^T f_eq`` (``efc_J``, ``efc_force`` of its rows)
    projected by :class:`CoupledJointTorque`'s virtual work.

    MuJoCo orders the constraint rows with the equalities first, by equality id (a joint
    equality one row, a connect three, a weld six), so the equality's rows are a fixed slice
    while every equality is active; :meth:`__call__` checks that (``data.ne``, the equality
    rows, is the rows of all equalities; in a model with an equality of another type: the
    slice's first row is this equality's) and falls back to a search when it does not hold.

    Args:
        model: The compiled model (dense constraint Jacobian: ``mj_isSparse`` false).
        equality: Name of the equality.
        joint: The coupled joint the torque is taken along.

    Raises:
        ValueError: If the model has no such equality, or its Jacobian is sparse.
    """

    _ROWS: ClassVar[dict[int, int]] = {
        int(mujoco.mjtEq.mjEQ_CONNECT): 3,
        int(mujoco.mjtEq.mjEQ_WELD): 6,
        int(mujoco.mjtEq.mjEQ_JOINT): 1,
        int(mujoco.mjtEq.mjEQ_TENDON): 1,
    }

    def __init__(self, model: mujoco.MjModel, equality: str, joint: CoupledJointTorque) -> None:
        eid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, equality)
        if eid < 0:
            raise ValueError(f"equality {equality!r} is not in the model")
        if mujoco.mj_isSparse(model):
            raise ValueError("EqualityJointTorque needs a dense constraint Jacobian")
        self.equality_id = int(eid)
        self.joint = joint
        self._nv = int(model.nv)
        self._rows = self._ROWS.get(int(model.eq_type[eid]), 0)
        if self._rows == 0:
            raise ValueError(f"equality {equality!r} has an unsupported type")
        self._start = sum(self._ROWS.get(int(model.eq_type[e]), 0) for e in range(eid))
        eq_rows = [self._ROWS.get(int(model.eq_type[e]), 0) for e in range(model.neq)]
        # the equality rows of a step with every equality active (None: an equality type of
        # unknown row count, so the slice's first row is checked instead)
        self._all_rows: int | None = sum(eq_rows) if all(eq_rows) else None
        self._stop = self._start + self._rows
        self._dofs = joint.dofs
        # the Jacobian entries of the fixed rows at the joint's DOFs, as indices into the
        # flat ``efc_J`` (row-major ``nefc x nv``), DOF by DOF: one 1-D index, whose
        # ``reshape(dofs, rows).T`` is the column-major block a 2-D index gives (the same
        # layout, so the same BLAS kernel sums it in the same order)
        rows = np.arange(self._start, self._stop, dtype=np.intp)
        self._jac_index = (self._dofs[:, None] + rows * self._nv).ravel()
        self._jac_shape = (len(self._dofs), self._rows)
        # a plain int: comparing a numpy value with MuJoCo's enum costs ~9 us per call
        self._equality_type = int(mujoco.mjtConstraint.mjCNSTR_EQUALITY)

    def rows(self, data: mujoco.MjData) -> slice:
        """The equality's constraint rows in *data* (an empty slice if it is inactive)."""
        if self._at_fixed_rows(data):
            return slice(self._start, self._stop)
        n = data.nefc
        found = np.flatnonzero(
            (data.efc_type[:n] == self._equality_type) & (data.efc_id[:n] == self.equality_id)
        )
        return slice(int(found[0]), int(found[-1]) + 1) if found.size else slice(0, 0)

    def _at_fixed_rows(self, data: mujoco.MjData) -> bool:
        """Whether the equality's rows in *data* are the fixed slice ``[start, stop)``."""
        if self._all_rows is not None:
            return data.ne == self._all_rows
        start = self._start
        return (
            self._stop <= data.nefc
            and data.efc_id.item(start) == self.equality_id
            and data.efc_type.item(start) == self._equality_type
        )

    def __call__(self, data: mujoco.MjData, theta: float) -> float:
        """Torque (Nm, positive along the joint) the equality applies along the joint, from
        *data*'s last computed constraint forces, at joint value *theta* (the angle those
        forces were computed at)."""
        if self._at_fixed_rows(data):
            jac = data.efc_J[self._jac_index].reshape(self._jac_shape).T
            force = data.efc_force[self._start : self._stop]
        else:
            rows = self.rows(data)
            if rows.stop == rows.start:
                return 0.0
            jac = data.efc_J.reshape(-1, self._nv)[rows, self._dofs]
            force = data.efc_force[rows]
        return self.joint.torque_of_dofs(theta, force.dot(jac))
