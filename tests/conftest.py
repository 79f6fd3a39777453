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
