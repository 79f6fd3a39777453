"""The twin as one object: its step is raw physics with the reflex's ctrl, its named
quantities are the env's, and it is the only place the package calls ``mj_step``."""

from __future__ import annotations

import math
import re
from pathlib import Path

import mujoco
import numpy as np
import pytest

import myoexo
from myoexo.envs import make_env
from myoexo.envs.twin import Twin
from myoexo.model import TwinParams, build_model, pose_twin
from myoexo.spasticity import SpasticityStage


def test_step_is_raw_physics_with_the_stage_ctrl() -> None:
    model, _ = build_model(TwinParams(scene=False))
    a, b = mujoco.MjData(model), mujoco.MjData(model)
    for data in (a, b):
        pose_twin(model, data, knee_angle_deg=60.0)
    stage_a = SpasticityStage(2, subject_noise=False, reflex="uniform")
    stage_b = SpasticityStage(2, subject_noise=False, reflex="uniform")
    twin = Twin(model, stage_a, 0.01, data=a)
    host = Twin(model, stage_b, 0.01, data=b)  # only as the stage's host for the raw loop
    for k in range(50):
        command = 0.3 * math.sin(k / 7.0)  # away from the drive's braking curve
        assert not twin.step(command)
        assert not twin.braking
        ctrl = np.zeros(model.nu)
        ctrl[twin.exo_actuator] = command
        b.ctrl[:] = stage_b.apply(host, ctrl)
        mujoco.mj_step(model, b, twin.frame_skip)
    np.testing.assert_array_equal(a.qpos, b.qpos)
    np.testing.assert_array_equal(a.qvel, b.qvel)


def test_the_force_knee_angle_is_the_knee_angle_the_last_timestep_started_from() -> None:
    """The knee-angle sensor gives, after a control period, the knee angle of the state its
    last physics timestep started from: what stepping ``frame_skip - 1`` timesteps and
    reading ``qpos`` gives, bit for bit."""
    model, _ = build_model(TwinParams(scene=False))
    a, b = mujoco.MjData(model), mujoco.MjData(model)
    for data in (a, b):
        pose_twin(model, data, knee_angle_deg=70.0)
    twin = Twin(model, SpasticityStage(3, subject_noise=False), 0.01, data=a)
    knee = model.joint("knee_angle_r").qposadr[0]
    for k in range(30):
        ctrl = twin.apply_command(-0.3 - 0.2 * math.cos(k / 5.0)).copy()
        assert not twin.advance() and not twin.braking
        b.ctrl[:] = ctrl
        mujoco.mj_step(model, b, twin.frame_skip - 1)
        before_last = b.qpos[knee]
        mujoco.mj_step(model, b)
        assert twin.force_knee_angle_rad == before_last
        assert twin.force_knee_angle_rad != a.qpos[knee]
    np.testing.assert_array_equal(a.qpos, b.qpos)


def test_named_quantities_are_the_envs() -> None:
    env = make_env(2, seed=0)
    env.reset(seed=4)
    twin = env.unwrapped.twin
    for _ in range(20):
        _, _, _, _, info = env.step(np.array([-0.6], dtype=np.float32))
    assert twin.knee_angle_deg == pytest.approx(info["knee_angle_deg"], abs=1e-9)
    assert twin.exo_angle_deg == pytest.approx(info["exo_angle_deg"], abs=1e-9)
    assert twin.misalignment_deg == pytest.approx(info["misalignment_deg"], abs=1e-9)
    assert twin.interaction_torque_nm == pytest.approx(info["interaction_torque_nm"], rel=1e-9)
    assert twin.muscle_torque_nm == pytest.approx(info["muscle_knee_torque_nm"], rel=1e-9)
    thigh, shank = twin.cuff_forces_n
    assert thigh == pytest.approx(info["thigh_cuff_force_n"], rel=1e-9)
    assert shank == pytest.approx(info["shank_cuff_force_n"], rel=1e-9)
    record = twin.sensory_record()
    assert record.knee_angle_deg == pytest.approx(twin.knee_angle_deg)
    assert len(record.fibre_length) == 11 and np.all(record.force_n >= 0.0)
    env.close()


def test_control_period_must_be_whole_timesteps() -> None:
    model, _ = build_model(TwinParams(scene=False))
    with pytest.raises(ValueError, match=r"control_period_s = 0\.0105"):
        Twin(model, SpasticityStage(0), 0.0105)


def test_only_the_twin_steps_the_physics() -> None:
    root = Path(myoexo.__file__).parent
    callers = [
        str(path.relative_to(root))
        for path in root.rglob("*.py")
        if re.search(r"mujoco\.mj_step\(", path.read_text(encoding="utf-8"))
    ]
    assert callers == ["envs/twin.py"]
