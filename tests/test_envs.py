"""MyoExoKnee environments: API compliance, determinism, task physics, robustness."""

from __future__ import annotations

import pickle

import gymnasium as gym
import numpy as np
import pytest

import myoexo
from myoexo.envs.registration import ENV_LEVELS

ALL_IDS = list(ENV_LEVELS)


def _rollout(env: gym.Env, seed: int, n: int, action: float | None = None):
    obs, info = env.reset(seed=seed)
    obs_list, rew, infos = [obs], [], [info]
    for _ in range(n):
        a = env.action_space.sample() if action is None else np.array([action], np.float32)
        obs, r, term, trunc, info = env.step(a)
        obs_list.append(obs)
        rew.append(r)
        infos.append(info)
        if term or trunc:
            break
    return np.array(obs_list), np.array(rew), infos


@pytest.fixture(scope="module")
def env1():
    env = gym.make("MyoExoKnee-v1")
    yield env
    env.close()


@pytest.mark.parametrize("env_id", ALL_IDS)
def test_gymnasium_and_sb3_env_checkers(env_id):
    from gymnasium.utils.env_checker import check_env
    from stable_baselines3.common.env_checker import check_env as sb3_check_env

    env = gym.make(env_id)
    check_env(env.unwrapped, skip_render_check=True)
    sb3_check_env(env.unwrapped, warn=True)
    env.close()


def test_ids_reachable_through_myosuite_and_module_prefix():
    from myosuite.core.registry import make_env

    env = make_env("MyoExoKnee-v2")
    assert env.unwrapped.level == 2
    env.close()
    env = gym.make("myoexo:MyoExoKnee-v3")
    env.reset(seed=0)
    assert env.unwrapped.level == 3
    # the env truncates itself (800 steps = 8 s) and its spec says so; no TimeLimit, so
    # another TaskParams needs no matching max_episode_steps
    assert env.spec.max_episode_steps == env.unwrapped.episode_steps == 800
    assert not _has_time_limit(env)
    env.close()


def _has_time_limit(env: gym.Env) -> bool:
    while isinstance(env, gym.Wrapper):
        if isinstance(env, gym.wrappers.TimeLimit):
            return True
        env = env.env
    return False


def test_spaces_dt_and_info_keys(env1):
    env = env1.unwrapped
    assert env.action_space.shape == (1,)
    assert env.dt == pytest.approx(0.01)
    assert env.episode_steps == 800
    obs, info = env1.reset(seed=3)
    assert obs.shape == env.observation_space.shape and obs.dtype == np.float32
    # normalized scale: no entry far outside O(1) at rest
    assert np.abs(obs).max() < 10
    for key in (
        "time_s",
        "knee_angle_deg",
        "knee_vel_rad_s",
        "exo_angle_deg",
        "target_angle_deg",
        "error_deg",
        "command",
        "exo_torque_nm",
        "muscle_knee_torque_nm",
        "interaction_torque_nm",
        "thigh_cuff_force_n",
        "shank_cuff_force_n",
        "sc_total",
        "level",
        "subject",
        "unstable",
    ):
        assert key in info, key
    assert 87 <= info["knee_angle_deg"] <= 93
    assert info["level"] == 1 and set(info["subject"]) >= {"s_theta", "s_v", "k"}
    _, _, _, _, info = env1.step(np.array([0.0], np.float32))
    assert {"obs_dict", "rwd_dict", "pose", "inter", "vel", "act"} <= set(info)


def test_same_seed_bit_identical_different_seed_different_subject():
    env_a, env_b = gym.make("MyoExoKneeRandom-v0"), gym.make("MyoExoKneeRandom-v0")
    oa, ra, ia = _rollout(env_a, 11, 60)
    env_b.action_space.seed(0)
    env_a.action_space.seed(0)
    oa, ra, ia = _rollout(env_a, 11, 60)
    ob, rb, ib = _rollout(env_b, 11, 60)
    assert np.array_equal(oa, ob) and np.array_equal(ra, rb)
    assert ia[0]["subject"] == ib[0]["subject"]
    _, _, ic = _rollout(env_b, 12, 1)
    assert ic[0]["subject"] != ia[0]["subject"]


def test_pickle_roundtrip_behaves_the_same(env1):
    clone = pickle.loads(pickle.dumps(env1))
    a, ra, _ = _rollout(env1, 5, 20, action=-0.3)
    b, rb, _ = _rollout(clone, 5, 20, action=-0.3)
    np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(ra, rb)
    assert clone.unwrapped.ctrl_stages == ("spasticity",)


def test_myosuite_style_accessors(env1):
    env1.reset(seed=0)
    env = env1.unwrapped
    od = env.get_obs_dict(env.model, env.data)
    assert od["knee_angle_rad"].shape == (1,)
    rd = env.get_reward_dict(od)
    assert {"dense", "done", "sparse", "solved"} <= set(rd)
    t, vec, pdict = env.get_proprioception()
    assert vec.ndim == 1 and "exo_angle_rad" in pdict and t == pytest.approx(0.0)


def _final_angle(env_id: str, action: float, seconds: float = 3.0, seed: int = 0) -> float:
    env = gym.make(env_id)
    _, _, infos = _rollout(env, seed, int(seconds / 0.01), action=action)
    env.close()
    assert not any(i["unstable"] for i in infos)
    return infos[-1]["knee_angle_deg"]


def test_zero_action_stays_near_hanging_equilibrium():
    angle = _final_angle("MyoExoKnee-v0", 0.0)
    assert 60.0 < angle < 100.0


def test_constant_extension_reaches_target_region_and_spasticity_resists():
    a0 = _final_angle("MyoExoKnee-v0", -0.5)
    a3 = _final_angle("MyoExoKnee-v3", -0.5)
    assert a0 < 20.0  # the exo extends the passive knee to near the 7 deg target
    assert a3 > a0 + 5.0  # level 3 reflexes resist the same command


@pytest.mark.parametrize("bad", [np.array([np.nan]), np.array([np.inf]), np.zeros(2), [[0.1]]])
def test_bad_actions_raise(env1, bad):
    env1.reset(seed=0)
    with pytest.raises(ValueError, match="action"):
        env1.step(bad)


def test_out_of_range_actions_are_clipped(env1):
    env1.reset(seed=0)
    _, _, _, _, info = env1.step(np.array([5.0], np.float32))
    assert info["command"] == 1.0
    assert info["exo_torque_nm"] == pytest.approx(100.0, rel=1e-6)


def test_bad_constructor_arguments_raise():
    from myoexo.envs.config import RewardParams, TaskParams

    with pytest.raises(ValueError, match="target_angle_deg"):
        TaskParams(target_angle_deg=200.0)
    with pytest.raises(ValueError, match="weights"):
        RewardParams(weights={"nope": 1.0})
    with pytest.raises(ValueError):
        gym.make("MyoExoKnee-v0", spasticity_level=7)


def test_episode_truncates_at_8_s():
    """The default env runs the full 8 s: 800 steps, none truncated before the last."""
    env = gym.make("MyoExoKnee-v0")
    env.reset(seed=0)
    zero = np.array([0.0], np.float32)
    for step in range(1, 801):
        _, _, terminated, truncated, info = env.step(zero)
        assert not terminated
        assert truncated == (step == 800), step
    assert info["time_s"] == pytest.approx(8.0)
    assert not info["unstable"]
    env.close()


def test_custom_episode_duration_truncates_in_the_env_itself():
    """A shorter task ends at its own duration; no TimeLimit is involved."""
    env = gym.make("MyoExoKnee-v0", episode_duration_s=0.2)
    _, _, infos = _rollout(env, 0, 1000, action=0.0)
    assert len(infos) == 21 and infos[-1]["time_s"] == pytest.approx(0.2)
    # the spec reports this env's own length (20 steps), and no TimeLimit is added
    assert env.spec.max_episode_steps == env.unwrapped.spec.max_episode_steps == 20
    assert not _has_time_limit(env)


def test_vector_envs():
    from stable_baselines3.common.vec_env import SubprocVecEnv

    venv = gym.make_vec("MyoExoKnee-v1", num_envs=2, vectorization_mode="async")
    obs, _ = venv.reset(seed=[0, 1])
    obs, r, *_ = venv.step(np.zeros((2, 1), np.float32))
    assert obs.shape[0] == 2 and np.isfinite(r).all()
    venv.close()
    # worker processes start fresh: the "myoexo:" prefix imports the package there
    sb3 = SubprocVecEnv([lambda: gym.make("myoexo:MyoExoKnee-v2")] * 2)
    sb3.seed(0)
    obs = sb3.reset()
    obs, r, _, infos = sb3.step(np.zeros((2, 1), np.float32))
    assert obs.shape[0] == 2 and infos[0]["level"] == 2
    sb3.close()


def test_instability_truncates_with_a_flag_and_finite_observation(env1):
    env1.reset(seed=0)
    env1.step(np.array([0.0], np.float32))
    env1.unwrapped.data.qvel[:] = 1e11  # beyond mjMAXVAL: what a blow-up looks like
    obs, reward, terminated, truncated, info = env1.step(np.array([0.0], np.float32))
    assert truncated and not terminated
    assert info["unstable"] is True
    assert np.isfinite(obs).all() and np.isfinite(reward)


def test_step_is_raw_physics_and_forces_are_those_of_the_last_substep(strap_torque_reference):
    """The documented timing of ``step``: the state after the step is exactly
    ``mj_step(frame_skip)`` with the step's ``ctrl``; the force-like observations equal what a
    fresh ``mj_forward`` of the state at t - h (the last substep's start) gives."""
    import mujoco

    from myoexo.model.joint_torque import CoupledJointTorque

    env = gym.make("MyoExoKnee-v2")
    base = env.unwrapped
    model, fs = base.model, base.frame_skip
    env.reset(seed=4)
    for a in (-0.5, 0.2, -0.8, 0.0, -0.3):
        env.step(np.array([a], np.float32))
    replica = mujoco.MjData(model)
    mujoco.mj_copyData(replica, model, base.data)
    obs, _, _, _, info = env.step(np.array([0.4], np.float32))
    od = info["obs_dict"]

    replica.ctrl[:] = base.data.ctrl  # the step's control, spastic excitations included
    mujoco.mj_step(model, replica, fs - 1)
    mujoco.mj_forward(model, replica)  # the state at t - h, as the last substep saw it
    ids = np.array([model.actuator(n).id for n in myoexo.spasticity.SPASTIC_MUSCLES])
    f0 = np.abs(model.actuator_gainprm[ids, 2])
    lo, hi = model.actuator_lengthrange[ids].T
    span = np.maximum(hi - lo, 1e-6)
    exo = replica.qfrc_actuator[model.joint("exo_knee").dofadr[0]]
    muscle = CoupledJointTorque(model, "knee_angle_r")(replica)
    assert od["exo_torque_nm"][0] == exo == info["exo_torque_nm"]
    assert od["muscle_knee_torque_nm"][0] == muscle == info["muscle_knee_torque_nm"]
    strap = strap_torque_reference(
        model, replica, replica.qpos[model.joint("knee_angle_r").qposadr[0]]
    )
    assert od["cuff_knee_torque_nm"][0] == pytest.approx(strap, abs=1e-9)
    assert od["interaction_torque_nm"][0] == abs(od["cuff_knee_torque_nm"][0])
    assert info["torque_abs_sum_nm"] == abs(exo) + abs(muscle)
    assert info["torque_signed_sum_nm"] == exo + muscle
    for key, sensor in myoexo.envs.knee_exo.CUFF_OBS_KEYS.items():
        np.testing.assert_array_equal(od[key], replica.sensor(sensor).data)
    np.testing.assert_array_equal(od["spastic_force"], replica.actuator_force[ids] * (-1.0 / f0))
    np.testing.assert_array_equal(
        od["spastic_length"], (replica.actuator_length[ids] - lo) * (1.0 / span)
    )
    np.testing.assert_array_equal(
        od["spastic_velocity"], replica.actuator_velocity[ids] * (1.0 / span)
    )

    mujoco.mj_step(model, replica)  # the last substep: the state after the step
    for name in ("qpos", "qvel", "act"):
        np.testing.assert_array_equal(getattr(replica, name), getattr(base.data, name))
    assert replica.time == base.data.time == info["time_s"]
    knee = model.joint("knee_angle_r")
    assert od["knee_angle_rad"][0] == replica.qpos[knee.qposadr[0]]
    assert od["knee_vel_rad_s"][0] == replica.qvel[knee.dofadr[0]]
    np.testing.assert_array_equal(od["spastic_act"], replica.act[model.actuator_actadr[ids]])
    np.testing.assert_array_equal(obs, base._obs_dict_to_vec(od))
    env.close()


def test_ctrl_stages_installed_or_removed_between_steps_take_effect():
    env = gym.make("MyoExoKnee-v0")
    base = env.unwrapped
    env.reset(seed=0)
    env.step(np.array([0.0], np.float32))
    muscle = int(np.flatnonzero(base._muscle_act_ind)[0])

    def excite(_env, ctrl):
        ctrl[muscle] = 0.7
        return ctrl

    base.add_ctrl_stage("test_excite", excite)
    env.step(np.array([0.0], np.float32))
    assert base.data.ctrl[muscle] == 0.7
    base.remove_ctrl_stage("test_excite")
    env.step(np.array([0.0], np.float32))
    assert base.data.ctrl[muscle] == 0.0
    env.close()
