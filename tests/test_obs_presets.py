"""Observation presets: the deployable ``exo`` preset reads only what the exoskeleton measures."""

from __future__ import annotations

import numpy as np
import pytest

from myoexo.envs import make_env
from myoexo.envs.knee_exo import CUFF_OBS_KEYS, EXO_SENSOR_OBS_KEYS, OBS_PRESETS

HUMAN_KEYS = {"knee_angle_rad", "knee_vel_rad_s", "error_rad", "muscle_knee_torque_nm"}


def test_exo_preset_has_no_human_or_muscle_state():
    env = make_env(1, obs_preset="exo")
    base = env.unwrapped
    assert base.obs_preset == "exo"
    assert tuple(base.obs_keys) == EXO_SENSOR_OBS_KEYS
    assert not HUMAN_KEYS & set(base.obs_keys)
    assert not [k for k in base.obs_keys if k.startswith(("spastic_", "coupling_"))]
    assert set(CUFF_OBS_KEYS) <= set(base.obs_keys)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape == (6 + 3 * len(CUFF_OBS_KEYS),)
    # the error is still measured on the human knee
    _, _, _, _, info = env.step(np.array([-1.0], np.float32))
    assert info["error_deg"] == pytest.approx(info["knee_angle_deg"] - 7.0)


def test_exo_preset_vector_is_the_full_envs_entries():
    full, exo = make_env(2), make_env(2, obs_preset="exo")
    obs_full, _ = full.reset(seed=4)
    obs_exo, _ = exo.reset(seed=4)
    keys = list(full.unwrapped.obs_keys)
    # each exo entry appears in the full vector at its key's position
    base = full.unwrapped
    sizes = {k: np.size(v) for k, v in base._get_obs_dict(base._accessor).items()}
    start, index = 0, {}
    for k in keys:
        index[k] = (start, start + sizes[k])
        start += sizes[k]
    rebuilt = np.concatenate([obs_full[slice(*index[k])] for k in EXO_SENSOR_OBS_KEYS])
    np.testing.assert_array_equal(rebuilt, obs_exo)


def test_unknown_preset_raises():
    with pytest.raises(ValueError, match="obs_preset"):
        make_env(0, obs_preset="nope")
    assert set(OBS_PRESETS) == {"full", "exo"}
    from myoexo.training import get_preset

    with pytest.raises(ValueError, match="obs_preset"):  # the presets read the env's table
        get_preset("cpu", obs_preset="nope")
