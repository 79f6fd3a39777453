"""Fixtures shared by the test modules."""

from __future__ import annotations

import contextlib
import importlib.util
import os
import shutil
import subprocess
import sys
import tempfile

import pytest

#: JAX reads its compilation cache settings from these (tests of the JAX learners build
#: several models of the same shapes: each would compile the same XLA programs again).
_JAX_CACHE_DIR = "JAX_COMPILATION_CACHE_DIR"


def pytest_configure(config):
    """One JAX compilation cache for the session, in a temporary folder removed at its end:
    every compiled program (even a quick one) is written there and read back by later
    compilations of the same program, in this process, in the pytest-xdist workers and in
    the commands the tests start (they inherit the environment). A size limit turns on
    JAX's file lock, so that the processes never read an entry half written. A cache set
    by the caller is left alone."""
    if os.environ.get(_JAX_CACHE_DIR):
        return  # the caller's, or the one the xdist controller made for its workers
    folder = tempfile.mkdtemp(prefix="myoexo-test-jax-cache-")
    config._myoexo_jax_cache = folder
    os.environ[_JAX_CACHE_DIR] = folder
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0"
    if importlib.util.find_spec("filelock") is not None:  # JAX's lock needs it
        os.environ["JAX_COMPILATION_CACHE_MAX_SIZE"] = str(2**31)


def pytest_unconfigure(config):
    folder = getattr(config, "_myoexo_jax_cache", None)
    if folder is not None:
        shutil.rmtree(folder, ignore_errors=True)
        for name in (
            _JAX_CACHE_DIR,
            "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS",
            "JAX_COMPILATION_CACHE_MAX_SIZE",
        ):
            os.environ.pop(name, None)


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
