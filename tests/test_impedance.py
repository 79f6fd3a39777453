"""The classical families a learned controller must beat: the setpoint reference shapes
(linear, minimum jerk; the PID along a minimum-jerk ramp: tests/test_control.py) and the
impedance controller (a spring-damper on a minimum-jerk reference): shapes, sign, sensors,
clipping, specs, and one short episode on the twin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from myoexo.control import (
    Controller,
    ImpedanceConfig,
    ImpedanceController,
    PIDConfig,
    parse_controller_spec,
)
from myoexo.control.reference import (
    REFERENCE_SHAPES,
    minimum_jerk_position,
    minimum_jerk_rate,
    reference_point,
)
from myoexo.control.specs import build_controller
from myoexo.envs.sensors import KNEE_ANGLE_SENSOR, KneeAngleMeasurements, Measurements

DT = 0.01


def sensed(
    knee_deg: float,
    target_deg: float = 7.0,
    *,
    knee_vel_deg_s: float = 0.0,
    exo_deg: float | None = None,
    exo_vel_deg_s: float = 0.0,
) -> KneeAngleMeasurements:
    """A sensor record with the knee angle sensor."""
    return KneeAngleMeasurements(
        time_s=0.0,
        setpoint_deg=target_deg,
        exo_angle_deg=knee_deg if exo_deg is None else exo_deg,
        exo_velocity_deg_s=exo_vel_deg_s,
        exo_torque_nm=0.0,
        knee_angle_deg=knee_deg,
        knee_velocity_deg_s=knee_vel_deg_s,
    )


class _Env:
    class unwrapped:
        dt = DT


# ----------------------------------------------------------------------------- reference
def test_minimum_jerk_reference_endpoints_velocity_and_monotone():
    start, target, duration = 90.0, 7.0, 1.5
    times = np.arange(0.0, duration + 0.5, 1e-3)
    points = [reference_point("minjerk", start, target, t, duration) for t in times]
    angle = np.array([p.angle for p in points])
    vel = np.array([p.velocity for p in points])
    assert angle[0] == start and angle[-1] == pytest.approx(target)
    assert reference_point("minjerk", start, target, duration, duration).angle == target
    assert reference_point("minjerk", start, target, -0.3, duration) == (start, 0.0)
    assert vel[0] == 0.0 and vel[-1] == 0.0  # at rest at both ends
    assert reference_point("minjerk", start, target, duration - 1e-9, duration).velocity == (
        pytest.approx(0.0, abs=1e-6)
    )
    assert np.all(np.diff(angle) <= 0.0)  # monotone towards the target
    # the velocity is the angle's derivative; the peak is 1.875 x the mean, at mid-move
    moving = times < duration
    np.testing.assert_allclose(
        np.gradient(angle, times)[moving][1:-1], vel[moving][1:-1], rtol=1e-3, atol=1e-2
    )
    peak = np.argmax(np.abs(vel))
    assert times[peak] == pytest.approx(duration / 2, abs=2e-3)
    assert abs(vel[peak]) == pytest.approx(1.875 * (start - target) / duration, rel=1e-4)
    # the polynomial and its rate on arrays, as the MAS exam uses them
    u = np.linspace(0.0, 1.0, 11)
    np.testing.assert_allclose(minimum_jerk_position(u), 10 * u**3 - 15 * u**4 + 6 * u**5)
    assert minimum_jerk_rate(0.5) == pytest.approx(1.875)


def test_linear_reference_and_bad_shapes():
    assert REFERENCE_SHAPES == ("linear", "minjerk")
    ref = reference_point("linear", 90.0, 10.0, 0.25, 1.0)
    assert ref.angle == pytest.approx(70.0) and ref.velocity == pytest.approx(-80.0)
    assert reference_point("linear", 90.0, 10.0, 2.0, 1.0) == (10.0, 0.0)
    assert reference_point("minjerk", 90.0, 10.0, 0.0, 0.0) == (10.0, 0.0)  # a step
    with pytest.raises(ValueError, match="cubic"):
        reference_point("cubic", 0.0, 1.0, 0.0, 1.0)
    with pytest.raises(ValueError, match="duration_s"):
        reference_point("linear", 0.0, 1.0, 0.0, -1.0)


def test_the_mas_exam_drives_along_the_same_polynomial():
    from myoexo.clinical.mas import MASExamParams, minimum_jerk

    p = MASExamParams(hold_s=0.2, duration_s=1.0)
    t = np.linspace(0.0, 1.4, 141)
    angle_deg, vel_rad_s, _ = minimum_jerk(t, p)
    for ti, a, v in zip(t, angle_deg, vel_rad_s, strict=True):
        ref = reference_point("minjerk", p.start_deg, p.end_deg, ti - p.hold_s, p.duration_s)
        assert a == pytest.approx(ref.angle, abs=1e-9)
        assert v == pytest.approx(math.radians(ref.velocity), abs=1e-9)


# ----------------------------------------------------------------------------- impedance
def test_impedance_defaults_are_the_papers_pid_as_a_spring_damper():
    from myoexo.model.params import TwinParams

    c = ImpedanceConfig()
    pid = PIDConfig().gains
    assert c.stiffness_nm_per_rad == pytest.approx(pid.kp * TwinParams().motor_limit_nm)
    assert c.damping_nm_s_per_rad == pytest.approx(pid.kd * TwinParams().motor_limit_nm)
    assert c.duration_s == 1.0 and c.feedback == "knee" and c.output_limit == 1.0
    assert c.motor_torque_nm == TwinParams().motor_limit_nm
    assert isinstance(ImpedanceController(), Controller)


def test_impedance_sign_terms_and_clipping():
    soft = ImpedanceConfig(stiffness_nm_per_rad=100.0, damping_nm_s_per_rad=2.0)
    imp = ImpedanceController(soft, dt_s=DT)
    # first step: the reference starts at the measured angle, at rest: nothing to do
    assert imp.act(None, sensed(90.0))[0] == 0.0
    # held 10 deg flexed above a reference that has barely moved: an extending command
    imp.reset()
    u = imp.act(None, sensed(90.0))  # starts the reference at 90 deg
    u = imp.act(None, sensed(100.0))
    assert u.shape == (1,) and u.dtype == np.float32
    ref_deg = imp.last_terms["reference_deg"]
    assert ref_deg < 90.0  # moving towards the 7 deg target
    spring = 100.0 * math.radians(ref_deg - 100.0)
    assert imp.last_terms["spring_nm"] == pytest.approx(spring)
    assert u[0] == pytest.approx(imp.last_terms["torque_nm"] / 100.0, rel=1e-6)
    assert u[0] < 0.0
    # past the target at the end of the move: a flexing command
    imp.reset()
    imp.act(None, sensed(90.0))
    for _ in range(200):
        u = imp.act(None, sensed(2.0))  # 5 deg extended beyond the 7 deg target
    assert imp.last_terms["reference_deg"] == pytest.approx(7.0)
    assert u[0] == pytest.approx(100.0 * math.radians(5.0) / 100.0, rel=1e-5)
    # the damper opposes the knee's velocity (at rest at the target: a flexing knee is braked)
    moving = imp.act(None, sensed(7.0, knee_vel_deg_s=50.0))
    assert moving[0] == pytest.approx(-2.0 * math.radians(50.0) / 100.0, rel=1e-5)
    # the default spring saturates far from the reference; output_limit clips
    clipped = ImpedanceController(ImpedanceConfig(output_limit=0.6), dt_s=DT)
    clipped.act(None, sensed(90.0))
    assert clipped.act(None, sensed(120.0))[0] == pytest.approx(-0.6)
    assert clipped.act(None, sensed(0.0, target_deg=90.0))[0] == pytest.approx(0.6)


def test_impedance_declares_the_sensors_of_its_feedback():
    knee = ImpedanceController(dt_s=DT)
    exo = ImpedanceController(ImpedanceConfig(feedback="exo"), dt_s=DT)
    assert knee.sensors == {KNEE_ANGLE_SENSOR} and exo.sensors == frozenset()
    record = sensed(50.0, exo_deg=55.0, exo_vel_deg_s=-10.0)
    for c in (knee, exo):
        c.act(None, record)  # the reference starts at the feedback's angle
    assert knee.last_terms["reference_deg"] == pytest.approx(50.0)
    assert exo.last_terms["reference_deg"] == pytest.approx(55.0)
    device_only = Measurements(0.0, 7.0, 55.0, 0.0, 0.0)  # no knee angle sensor
    assert np.isfinite(exo.act(None, device_only)[0])
    with pytest.raises(ValueError, match="knee angle sensor"):
        knee.act(None, device_only)


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"stiffness_nm_per_rad": 0.0}, "stiffness_nm_per_rad"),
        ({"stiffness_nm_per_rad": math.nan}, "stiffness_nm_per_rad"),
        ({"damping_nm_s_per_rad": -1.0}, "damping_nm_s_per_rad"),
        ({"duration_s": -0.5}, "duration_s"),
        ({"feedback": "hip"}, "feedback"),
        ({"output_limit": 1.5}, "output_limit"),
        ({"output_limit": 0.0}, "output_limit"),
        ({"motor_torque_nm": 0.0}, "motor_torque_nm"),
    ],
)
def test_bad_impedance_config_is_refused_naming_the_field(kwargs, field):
    with pytest.raises(ValueError, match=f"ImpedanceConfig.{field}"):
        ImpedanceConfig(**kwargs)


def test_impedance_spec():
    spec = parse_controller_spec("impedance")
    assert spec.kind == "impedance" and spec.label == "impedance" and spec.options == {}
    text = "impedance:k=350,d=2.5,duration_s=1.5,feedback=exo,limit=0.6"
    spec = parse_controller_spec(text)
    assert spec.kind == "impedance" and spec.label == text
    controller = build_controller(spec, _Env())
    assert isinstance(controller, ImpedanceController) and controller.dt_s == DT
    assert controller.config == ImpedanceConfig(
        stiffness_nm_per_rad=350.0,
        damping_nm_s_per_rad=2.5,
        duration_s=1.5,
        feedback="exo",
        output_limit=0.6,
    )
    assert controller.sensors == frozenset()
    guarded = build_controller(parse_controller_spec("guard:impedance:feedback=exo"), _Env())
    assert guarded.sensors == frozenset()  # the encoder guard, as for the encoder PID
    for bad, match in [
        ("impedance:stiffness=3", "unknown impedance option"),
        ("impedance:k=abc", "not a number"),
        ("impedance:k=-1", "impedance option k = -1"),
        ("impedance:feedback=hip", "feedback"),
        ("impedance:limit=2", "limit"),
    ]:
        with pytest.raises(ValueError, match=match):
            parse_controller_spec(bad)


# ----------------------------------------------------------------------------- on the twin
def test_impedance_moves_the_knee_toward_the_target_on_the_twin():
    import gymnasium as gym

    import myoexo  # noqa: F401  (registers the envs)
    from myoexo.control.rollout import rollout

    env = gym.make("MyoExoKnee-v1", episode_duration_s=2.0)
    try:
        imp = ImpedanceController.from_env(env)
        ep = rollout(env, imp, seed=0, channels=("knee_angle_deg", "target_angle_deg"))
    finally:
        env.close()
    knee = np.asarray(ep.signals["knee_angle_deg"])
    target = float(ep.signals["target_angle_deg"][0])
    start_error, final_error = abs(knee[0] - target), abs(knee[-1] - target)
    assert start_error > 60.0
    assert final_error < 0.25 * start_error  # most of the way along the move
    # no jump at the start: a minimum-jerk reference leaves the knee near rest at first
    assert abs(knee[5] - knee[0]) < abs(knee[-1] - knee[0]) / 10
