"""Fixtures shared by the test modules."""

from __future__ import annotations

import pytest


@pytest.fixture(scope="module")
def walk_env_factory():
    """MyoSuite's own leg env (both legs, 80 muscles) with the spasticity wrapper: the stage
    is not tied to our twin."""
    gym = pytest.importorskip("myosuite.utils").gym
    from myoexo.spasticity.wrapper import SpasticityWrapper

    def make(**kwargs):
        return SpasticityWrapper(gym.make("myoLegWalk-v0"), **kwargs)

    return make
