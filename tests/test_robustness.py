"""The perturbed twin (``robustness=``): draws, restoration, sensor noise and latency."""

from __future__ import annotations

import math

import numpy as np
import pytest

from myoexo.control import PID
from myoexo.envs import make_env
from myoexo.envs.robustness import RobustnessParams


def _model_arrays(env):
    m = env.unwrapped.model
    return [
        m.jnt_stiffness.copy(),
        m.dof_damping.copy(),
        m.dof_frictionloss.copy(),
        m.body_mass.copy(),
        m.body_inertia.copy(),
        m.actuator_gainprm[:, 0].copy(),
        m.eq_solref.copy(),
    ]


def test_same_seed_same_twin_and_subject_as_nominal():
    env = make_env(2, robustness=True)
    nominal = make_env(2)
    _, info_a = env.reset(seed=3)
    obs_a = env.step(np.array([-0.5], np.float32))[0]
    _, info_b = env.reset(seed=3)
    obs_b = env.step(np.array([-0.5], np.float32))[0]
    np.testing.assert_array_equal(obs_a, obs_b)
    assert info_a["twin_draw"] == info_b["twin_draw"]
    _, info_n = nominal.reset(seed=3)
    assert info_a["subject"] == info_n["subject"]  # the perturbation has its own stream
    _, info_c = env.reset(seed=4)
    assert info_c["twin_draw"] != info_a["twin_draw"]


def test_draws_stay_in_their_ranges_and_never_accumulate():
    env = make_env(1, robustness=True)
    before = _model_arrays(env)
    p = RobustnessParams()
    for seed in range(12):
        _, info = env.reset(seed=seed)
        d = info["twin_draw"]
        assert (
            p.strap_stiffness_scale[0] <= d["strap_stiffness_scale"] <= p.strap_stiffness_scale[1]
        )
        assert p.strap_damping_scale[0] <= d["strap_damping_scale"] <= p.strap_damping_scale[1]
        assert abs(d["slide_friction_scale"] - 1) <= p.slide_friction_rel
        assert abs(d["motor_gain_scale"] - 1) <= p.motor_gain_rel
        assert abs(d["mass_scale_mean"] - 1) <= p.mass_rel
    # a collapsed range brings back the nominal model exactly
    nominal = make_env(1, robustness=RobustnessParams.nominal())
    nominal.reset(seed=5)
    for a, b in zip(_model_arrays(nominal), before, strict=True):
        np.testing.assert_array_equal(a, b)
    # and the perturbed env's arrays differ from the nominal ones, by the drawn factors
    _, info = env.reset(seed=7)
    m = env.unwrapped.model
    motor = m.actuator("exo_motor").id
    assert m.actuator_gainprm[motor, 0] == pytest.approx(
        before[5][motor] * info["twin_draw"]["motor_gain_scale"]
    )


def test_latency_delays_the_measurement_by_one_control_step():
    params = RobustnessParams(noise_std=())  # latency only
    env = make_env(2, robustness=params)
    _, info = env.reset(seed=1)
    true_deg, measured_deg = [info["knee_angle_deg"]], [info["measured_knee_angle_deg"]]
    for _ in range(20):
        _, _, _, _, info = env.step(np.array([-1.0], np.float32))
        true_deg.append(info["knee_angle_deg"])
        measured_deg.append(info["measured_knee_angle_deg"])
    np.testing.assert_allclose(measured_deg[2:], true_deg[1:-1], atol=1e-12)
    assert measured_deg[1] == pytest.approx(true_deg[0])


def test_noise_has_its_documented_spread_and_the_pid_reads_it():
    std_deg = 0.5
    params = RobustnessParams(latency_s=0.0, noise_std=(("knee_angle_rad", math.radians(std_deg)),))
    env = make_env(0, robustness=params)
    env.reset(seed=0)
    diffs = []
    for _ in range(400):
        _, _, _, _, info = env.step(np.array([0.0], np.float32))
        diffs.append(info["measured_knee_angle_deg"] - info["knee_angle_deg"])
    assert np.std(diffs) == pytest.approx(std_deg, rel=0.15)
    assert abs(np.mean(diffs)) < 0.1
    # the PID acts on the measured angle: its knee angle sensor's reading, not the true one
    from myoexo.envs.sensors import read_sensors

    pid = PID.from_env(env)
    record = read_sensors(info, pid.sensors)
    assert record.knee_angle_deg == info["measured_knee_angle_deg"] != info["knee_angle_deg"]
    pid.reset()
    near = {**info, "target_angle_deg": 7.0, "knee_angle_deg": 7.0}
    u_measured = pid.act(None, read_sensors({**near, "measured_knee_angle_deg": 9.0}, pid.sensors))
    pid.reset()
    u_true = pid.act(None, read_sensors({**near, "measured_knee_angle_deg": 7.0}, pid.sensors))
    assert u_true[0] == 0.0 and u_measured[0] < -0.1


def test_bad_settings_raise():
    with pytest.raises(ValueError, match="strap_stiffness_scale"):
        RobustnessParams(strap_stiffness_scale=(0.0, 2.0))
    with pytest.raises(ValueError, match="mass_rel"):
        RobustnessParams(mass_rel=1.5)
    with pytest.raises(ValueError, match="whole number of control periods"):
        make_env(0, robustness=RobustnessParams(latency_s=0.015))
    with pytest.raises(ValueError, match="unknown key"):
        make_env(0, robustness=RobustnessParams(noise_std=(("nope", 1.0),)))
    with pytest.raises(ValueError, match="robustness"):
        make_env(0, robustness="yes")


def test_perturbed_evaluation_is_paired_reproducible_and_kept_apart(tmp_path):
    from myoexo.envs.options import TwinOptions
    from myoexo.evaluation import EvaluationConfig, evaluate

    def run(name, perturbed):
        config = EvaluationConfig(
            controllers=("pid",),
            levels=(2,),
            subjects=2,
            twin=TwinOptions().replace(episode_duration_s=0.5, robustness=perturbed),
        )
        return evaluate(config, tmp_path / name, workers=1, progress=False).table

    a, b, nominal = run("a", True), run("b", True), run("nominal", False)
    pd_cols = ["subject_k", "subject_theta_flex_deg"] if "subject_k" in a else ["seed"]
    assert (a[pd_cols].values == nominal[pd_cols].values).all()  # the same subjects
    assert (a.peak_interaction_torque_nm.values == b.peak_interaction_torque_nm.values).all()
    assert (a.peak_interaction_torque_nm.values != nominal.peak_interaction_torque_nm.values).any()
    # a folder of the nominal twin is never extended with perturbed episodes
    with pytest.raises(ValueError, match="other settings"):
        run("nominal", True)
