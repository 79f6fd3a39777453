"""The env's layout: observation keys and presets (observation.py), the layout of one model's
``MjData`` built once, the reward and robustness set-up in their own modules, and an env
whose state is created in ``__init__``."""

from __future__ import annotations

import subprocess
import sys

import mujoco
import numpy as np
import pytest

import myoexo  # noqa: F401  (registers the ids)
from myoexo.envs import make_env, observation
from myoexo.envs.observation import (
    CUFF_OBS_KEYS,
    DEFAULT_OBS_KEYS,
    EXO_SENSOR_OBS_KEYS,
    OBS_PRESETS,
    RAW_KEYS,
    SCALAR_KEYS,
    ObsLayout,
)


@pytest.fixture(scope="module")
def twin():
    from myoexo.model import TwinParams, build_model, pose_twin

    model, _ = build_model(TwinParams())
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=60.0)
    data.qvel[:] = np.linspace(-0.3, 0.3, model.nv)
    data.ctrl[:] = np.linspace(0.0, 1.0, model.nu)
    mujoco.mj_forward(model, data)
    return model, data


def test_observation_module_is_light():
    """``myoexo.envs.observation`` (what ``myoexo.envs.options`` reads the presets from)
    neither builds a model nor imports the env."""
    code = (
        "import sys, myoexo.envs.observation as o; "
        "assert 'myoexo.envs.knee_exo' not in sys.modules; "
        "print(sorted(o.OBS_PRESETS))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "['exo', 'full']"


def test_keys_are_written_once():
    from myoexo.envs import knee_exo

    assert len(set(RAW_KEYS)) == len(RAW_KEYS)
    assert set(DEFAULT_OBS_KEYS) == set(RAW_KEYS) - {
        "time",
        "interaction_torque_nm",
        "cuff_knee_torque_nm",
    }
    assert set(EXO_SENSOR_OBS_KEYS) <= set(DEFAULT_OBS_KEYS)
    # the raw buffer's scalars are the vector's state scalars between time and the
    # interaction torque, then time_frac
    assert SCALAR_KEYS == (
        "time",
        *observation.STATE_OBS_KEYS,
        "interaction_torque_nm",
        "cuff_knee_torque_nm",
        "time_frac",
    )
    assert DEFAULT_OBS_KEYS[: len(observation.STATE_OBS_KEYS)] == observation.STATE_OBS_KEYS
    assert OBS_PRESETS == {"full": DEFAULT_OBS_KEYS, "exo": EXO_SENSOR_OBS_KEYS}
    assert knee_exo.MyoExoKneeEnv.DEFAULT_OBS_KEYS == list(DEFAULT_OBS_KEYS)


def test_layout_gathers_each_quantity_from_its_definition(twin, strap_torque_reference):
    """One index gathers what the names say, after an ``mj_forward`` (so every entry refers
    to the current state); the muscle block normalized, everything else exact."""
    from myoexo.model.joint_torque import CoupledJointTorque
    from myoexo.spasticity.levels import SPASTIC_MUSCLES

    model, data = twin
    layout = ObsLayout.of(model, DEFAULT_OBS_KEYS, target_rad=0.12, episode_duration_s=8.0)
    raw = layout.gather(layout.views(data), command=-0.25)
    od = layout.split(raw)
    assert list(od) == list(RAW_KEYS) == list(layout.slices)
    assert sum(v.size for v in od.values()) == raw.size == layout.raw_size
    assert all(v.base is raw for v in od.values())  # views of one fresh buffer

    knee, exo = model.joint("knee_angle_r"), model.joint("exo_knee")
    muscle = CoupledJointTorque(model, "knee_angle_r")(data)
    exo_torque = data.qfrc_actuator[exo.dofadr[0]]
    strap = strap_torque_reference(model, data, data.qpos[knee.qposadr[0]])
    expected = {
        "time": data.time,
        "knee_angle_rad": data.qpos[knee.qposadr[0]],
        "knee_vel_rad_s": data.qvel[knee.dofadr[0]],
        "exo_angle_rad": data.qpos[exo.qposadr[0]],
        "exo_vel_rad_s": data.qvel[exo.dofadr[0]],
        "target_rad": 0.12,
        "error_rad": data.qpos[knee.qposadr[0]] - 0.12,
        "command": -0.25,
        "exo_torque_nm": exo_torque,
        "muscle_knee_torque_nm": muscle,
        "interaction_torque_nm": abs(strap),
        "cuff_knee_torque_nm": strap,
        "time_frac": data.time / 8.0,
    }
    for key, value in expected.items():
        # the strap torque is summed in another order here: equal to round-off
        assert od[key].shape == (1,) and od[key][0] == pytest.approx(value, rel=1e-12), key
    for key, sensor in CUFF_OBS_KEYS.items():
        np.testing.assert_array_equal(od[key], data.sensor(sensor).data)
    jq = [model.joint(n) for n in layout.coupling_joints]
    assert len(jq) >= 3
    np.testing.assert_array_equal(od["coupling_qpos"], [data.qpos[j.qposadr[0]] for j in jq])
    np.testing.assert_array_equal(od["coupling_qvel"], [data.qvel[j.dofadr[0]] for j in jq])
    ids = np.array([model.actuator(n).id for n in SPASTIC_MUSCLES])
    lo, hi = model.actuator_lengthrange[ids].T
    span = np.maximum(hi - lo, 1e-6)
    np.testing.assert_array_equal(od["spastic_act"], data.act[model.actuator_actadr[ids]])
    np.testing.assert_array_equal(
        od["spastic_force"],
        data.actuator_force[ids] * (-1.0 / np.abs(model.actuator_gainprm[ids, 2])),
    )
    np.testing.assert_array_equal(
        od["spastic_length"], (data.actuator_length[ids] - lo) * (1.0 / span)
    )
    np.testing.assert_array_equal(od["spastic_velocity"], data.actuator_velocity[ids] * (1 / span))

    # the vector: the obs_keys entries times their scales, from raw or from any dict
    vec = layout.to_vec(raw)
    assert vec.dtype == np.float32 and vec.size == sum(od[k].size for k in DEFAULT_OBS_KEYS)
    manual = np.concatenate([od[k] for k in DEFAULT_OBS_KEYS]) * layout.vec_scale
    np.testing.assert_array_equal(vec, manual.astype(np.float32))
    np.testing.assert_array_equal(layout.dict_to_vec({k: v.copy() for k, v in od.items()}), vec)
    assert layout.vec_scale[DEFAULT_OBS_KEYS.index("knee_vel_rad_s")] == 0.1


def test_layout_of_another_mjdata_and_a_preset(twin):
    model, data = twin
    layout = ObsLayout.of(model, EXO_SENSOR_OBS_KEYS, target_rad=0.0, episode_duration_s=1.0)
    other = mujoco.MjData(model)
    mujoco.mj_copyData(other, model, data)
    a = layout.gather(layout.views(data), 0.0)
    b = layout.gather(layout.views(other), 0.0)
    np.testing.assert_array_equal(a, b)
    assert layout.to_vec(a).size == 6 + 3 * len(CUFF_OBS_KEYS)


def test_unknown_keys_raise(twin):
    model, _ = twin
    with pytest.raises(ValueError, match="unknown obs_keys"):
        ObsLayout.of(model, ["knee_angle_rad", "nope"], target_rad=0.0, episode_duration_s=1.0)
    layout = ObsLayout.of(model, DEFAULT_OBS_KEYS, target_rad=0.0, episode_duration_s=1.0)
    with pytest.raises(ValueError, match="noise_std names unknown key 'nope'"):
        layout.raw_std([("nope", 1.0)])
    std = layout.raw_std([("spastic_force", 0.5), ("knee_angle_rad", 0.1)])
    assert std[layout.at["knee_angle_rad"]] == 0.1
    sl = layout.slices["spastic_force"]
    np.testing.assert_array_equal(std[sl], 0.5 * np.abs(layout.raw_gain[sl]))


def test_robustness_set_up_lives_next_to_robustness(twin):
    from myoexo.envs.robustness import (
        RobustnessParams,
        SensorModel,
        robustness_params,
        twin_perturbation,
    )

    assert robustness_params(True) == RobustnessParams()
    assert robustness_params(False) is None and robustness_params(None) is None
    with pytest.raises(ValueError, match="robustness"):
        robustness_params("yes")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="whole number of control periods"):
        SensorModel.with_latency(np.zeros(3), 0.015, 0.01)
    assert SensorModel.with_latency(np.zeros(3), 0.02, 0.01).delay_steps == 2
    model, _ = twin
    layout = ObsLayout.of(model, DEFAULT_OBS_KEYS, target_rad=0.0, episode_duration_s=1.0)
    draw = twin_perturbation(model, RobustnessParams(), layout.coupling_joints).apply(
        np.random.default_rng(0)
    )
    assert set(draw) >= {"strap_stiffness_scale", "motor_gain_scale"}


@pytest.mark.parametrize("kwargs", [{}, {"robustness": True, "obs_preset": "exo"}])
def test_env_state_is_created_in_init(kwargs):
    """No attribute appears after construction: reset and step only update the state."""
    env = make_env(2, **kwargs).unwrapped
    before = set(vars(env))
    env.reset(seed=0)
    for a in (-0.5, 0.3):
        env.step(np.array([a], np.float32))
    env.get_obs_dict(env.model, env.data)
    # (gymnasium creates the env's unseeded generator when it is first used)
    assert set(vars(env)) - {"_np_random", "_np_random_seed"} == before
    assert env.obs_layout.obs_keys == tuple(env.obs_keys)
    assert env.coupling_joints == env.obs_layout.coupling_joints
    assert env.obs_layout.knee_qadr == env.model.joint("knee_angle_r").qposadr[0]
    assert env.obs_layout.knee_dadr == env.model.joint("knee_angle_r").dofadr[0]
