"""Fixtures shared by the test modules."""

from __future__ import annotations

import contextlib
import subprocess
import sys

import pytest


@pytest.fixture(scope="module")
def walk_env_factory():
    """MyoSuite's own leg env (both legs, 80 muscles) with the spasticity wrapper: the stage
    is not tied to our twin."""
    from myosuite.utils import gym  # a core dependency: its absence is a failure, not a skip

    from myoexo.spasticity.wrapper import SpasticityWrapper

    def make(**kwargs):
        return SpasticityWrapper(gym.make("myoLegWalk-v0"), **kwargs)

    return make


@pytest.fixture
def lock_holder():
    """``with lock_holder(folder, command) as proc:`` another process holds the folder's
    :class:`~myoexo.runtime.lifecycle.FolderLock` (recorded with *command*) until the block
    ends, when it is killed."""

    @contextlib.contextmanager
    def hold(folder, command="holder"):
        proc = subprocess.Popen(
            [
                sys.executable,
                "-c",
                "import sys, time; from myoexo.runtime.lifecycle import FolderLock; "
                "FolderLock(sys.argv[1], command=sys.argv[2]).acquire(); "
                "print('locked', flush=True); time.sleep(600)",
                str(folder),
                command,
            ],
            stdout=subprocess.PIPE,
            text=True,
        )
        try:
            assert proc.stdout is not None and proc.stdout.readline().strip() == "locked"
            yield proc
        finally:
            proc.kill()
            proc.wait()

    return hold


@pytest.fixture
def strap_torque_reference():
    """``f(model, data, theta) -> Nm``: the shank strap's torque along the knee, computed
    independently of the package's fixed-row shortcut: every constraint row of the weld
    found by search, ``J^T f`` by MuJoCo's own ``mj_mulJacTVec``, projected along the
    coupled knee at the angle *theta* (rad)."""
    import mujoco
    import numpy as np

    from myoexo.model.joint_torque import CoupledJointTorque

    def torque(model, data, theta):
        eq = model.equality("shank_strap").id
        n = data.nefc
        rows = (data.efc_type[:n] == mujoco.mjtConstraint.mjCNSTR_EQUALITY) & (
            data.efc_id[:n] == eq
        )
        assert rows.sum() == 6  # a weld
        f = np.where(rows, data.efc_force[:n], 0.0)
        qfrc = np.zeros(model.nv)
        mujoco.mj_mulJacTVec(model, data, qfrc, f)
        return CoupledJointTorque(model, "knee_angle_r").torque_at(theta, qfrc)

    return torque
