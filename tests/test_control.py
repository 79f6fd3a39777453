"""Controllers: PID sign, terms, anti-windup, derivative modes; ZN table and oscillation
analysis; policy adapters and specs; PID and Ziegler-Nichols on the twin."""

from __future__ import annotations

import math

import numpy as np
import pytest

from myoexo.control import (
    PID,
    CallableController,
    Controller,
    PIDConfig,
    PIDGains,
    SB3Controller,
    as_controller,
    parse_controller_spec,
)
from myoexo.control import ziegler_nichols as zn
from myoexo.control.specs import pid_config
from myoexo.envs.sensors import KNEE_ANGLE_SENSOR, KneeAngleMeasurements, Measurements

DT = 0.01


def sensed(
    knee_deg: float, target_deg: float = 7.0, exo_deg: float | None = None
) -> KneeAngleMeasurements:
    """A sensor record with the knee angle sensor (knee and encoder at rest)."""
    return KneeAngleMeasurements(
        time_s=0.0,
        setpoint_deg=target_deg,
        exo_angle_deg=knee_deg if exo_deg is None else exo_deg,
        exo_velocity_deg_s=0.0,
        exo_torque_nm=0.0,
        knee_angle_deg=knee_deg,
        knee_velocity_deg_s=0.0,
    )


def test_sign_flexed_knee_gets_an_extending_command():
    pid = PID(dt_s=DT)
    u = pid.act(np.zeros(3), sensed(90.0))  # env error_deg = +83 (still flexed)
    assert u.shape == (1,) and u.dtype == np.float32
    assert u[0] == -1.0  # saturated extension torque
    pid.reset()
    assert pid.act(np.zeros(3), sensed(-10.0))[0] == 1.0  # 17 deg past the target: flex back
    pid.reset()
    small = pid.act(np.zeros(3), sensed(7.5))[0]  # 0.5 deg short: small extending command
    assert -1.0 < small < 0.0


def test_proportional_integral_and_derivative_terms_are_exact():
    e = math.radians(0.2)  # small: no saturation
    p_only = PID(PIDConfig(gains=PIDGains(kp=7.0, ki=0.0, kd=0.0)), dt_s=DT)
    assert p_only.update(e, 0.0) == pytest.approx(7.0 * e)
    i_only = PID(PIDConfig(gains=PIDGains(kp=0.0, ki=40.0, kd=0.0)), dt_s=DT)
    for _ in range(10):
        u = i_only.update(e, 0.0)
    assert u == pytest.approx(40.0 * e * 10 * DT)  # backward Euler over 10 samples
    d_only = PID(PIDConfig(gains=PIDGains(kp=0.0, ki=0.0, kd=0.05)), dt_s=DT)
    assert d_only.update(0.0, 0.0) == 0.0  # no derivative on the first sample
    assert d_only.update(0.0, 0.001) == pytest.approx(-0.05 * 0.001 / DT)  # -Kd dy/dt


def test_derivative_on_measurement_has_no_setpoint_kick():
    gains = PIDGains(kp=0.0, ki=0.0, kd=0.05)
    on_meas = PID(PIDConfig(gains=gains), dt_s=DT)
    on_err = PID(PIDConfig.textbook(gains), dt_s=DT)
    for pid in (on_meas, on_err):
        pid.update(0.0, 0.0)
    # constant setpoint: both forms agree
    assert on_meas.update(0.0, 0.001) == pytest.approx(on_err.update(0.0, 0.001))
    # setpoint step of 0.01 rad: only the textbook form kicks
    assert on_meas.update(0.01, 0.001) == pytest.approx(0.0)
    assert on_err.update(0.01, 0.001) == pytest.approx(0.05 * 0.01 / DT)


def _windup_then_reverse(config: PIDConfig) -> tuple[float, int]:
    """Saturate for 2 s against a large error, then reverse the error: integral at the
    reversal and samples until the output leaves the extension saturation."""
    pid = PID(config, dt_s=DT)
    for _ in range(200):
        pid.update(0.0, 1.0)  # e = -1 rad: extension saturation
    integral = pid.last_terms["i"]
    for k in range(1, 500):
        if pid.update(0.0, -0.01) > -1.0:  # small opposite error
            return integral, k
    return integral, 500


def test_anti_windup_clamping_and_back_calculation_vs_none():
    gains = PIDGains(kp=7.0, ki=40.0, kd=0.0)
    i_none, k_none = _windup_then_reverse(PIDConfig(gains=gains, anti_windup="none"))
    i_clamp, k_clamp = _windup_then_reverse(PIDConfig(gains=gains, anti_windup="clamping"))
    i_back, k_back = _windup_then_reverse(PIDConfig(gains=gains, anti_windup="back_calculation"))
    assert i_none == pytest.approx(-40.0 * 1.0 * 200 * DT)  # wound up to -80
    assert i_clamp == 0.0  # frozen from the first saturated sample
    assert -2.0 < i_back < 0.0  # held near the saturation limit
    assert k_clamp <= 2 and k_back <= 5
    assert k_none > 100  # windup: stays saturated long after the error reversed


def test_feedback_option_reads_the_exo_encoder():
    knee = PID(dt_s=DT, config=PIDConfig(gains=PIDGains(kp=1.0, ki=0.0, kd=0.0)))
    exo = PID(dt_s=DT, config=PIDConfig(gains=PIDGains(kp=1.0, ki=0.0, kd=0.0), feedback="exo"))
    i = sensed(10.0, exo_deg=12.0)
    assert knee.act(None, i)[0] == pytest.approx(math.radians(7 - 10), rel=1e-6)
    assert exo.act(None, i)[0] == pytest.approx(math.radians(7 - 12), rel=1e-6)
    # the knee PID declares the knee angle sensor; the encoder PID only the device's own
    assert knee.sensors == {KNEE_ANGLE_SENSOR} and exo.sensors == frozenset()
    device_only = Measurements(0.0, 7.0, 12.0, 0.0, 0.0)  # no knee angle sensor
    assert exo.act(None, device_only)[0] == pytest.approx(math.radians(7 - 12), rel=1e-6)
    with pytest.raises(ValueError, match="knee angle sensor"):
        knee.act(None, device_only)


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"anti_windup": "magic"}, "anti_windup"),
        ({"feedback": "hip"}, "feedback"),
        ({"output_limit": 0.0}, "output_limit"),
        ({"tracking_time_s": -1.0}, "tracking_time_s"),
    ],
)
def test_bad_pid_config_is_refused(kwargs, match):
    with pytest.raises(ValueError, match=match):
        PIDConfig(**kwargs)


def test_bad_gains_and_sample_time_are_refused():
    with pytest.raises(ValueError, match="kp"):
        PIDGains(kp=-1.0)
    with pytest.raises(ValueError, match="dt_s"):
        PID(dt_s=0.0)


def test_defaults_are_the_papers_gains_and_tracking_time_rule():
    cfg = PIDConfig()
    assert (cfg.gains.kp, cfg.gains.ki, cfg.gains.kd) == (7.0, 40.0, 0.05)
    assert cfg.derivative_on_measurement and cfg.anti_windup == "clamping"
    ti, td = 7.0 / 40.0, 0.05 / 7.0
    assert cfg.effective_tracking_time_s == pytest.approx(math.sqrt(ti * td))


# ----------------------------------------------------------------------------- ZN
def test_classic_table_and_papers_implied_ultimate_point():
    g = zn.classic_zn_gains(ku=10.0, tu_s=0.5)
    assert (g.kp, g.ki, g.kd) == pytest.approx((6.0, 24.0, 0.375))
    ku, tu = zn.implied_ultimate(PIDGains())
    assert ku == pytest.approx(7.0 / 0.6) and tu == pytest.approx(0.35)
    # round trip on Kp and Ki
    back = zn.classic_zn_gains(ku, tu)
    assert back.kp == pytest.approx(7.0) and back.ki == pytest.approx(40.0)
    with pytest.raises(ValueError):
        zn.classic_zn_gains(0.0, 1.0)


def test_oscillation_analysis_on_sustained_and_decaying_sines():
    t = np.arange(0, 8, 0.01)
    sustained = zn.analyze_oscillation(t, 3.0 + 2.0 * np.sin(2 * np.pi * t / 0.4), start_s=2.0)
    assert sustained.period_s == pytest.approx(0.4, rel=1e-3)
    assert sustained.amplitude_ratio == pytest.approx(1.0, abs=0.02)
    assert sustained.last_amplitude == pytest.approx(2.0, rel=0.02)
    decaying = zn.analyze_oscillation(t, np.exp(-t) * np.sin(2 * np.pi * t / 0.4), start_s=2.0)
    assert decaying.amplitude_ratio < 0.1
    flat = zn.analyze_oscillation(t, np.ones_like(t))
    assert flat.half_cycles == 0


# ----------------------------------------------------------------------------- adapters
class _FakeSB3:
    def __init__(self):
        self.calls = []

    def predict(self, obs, deterministic=True):
        self.calls.append(deterministic)
        return np.array([2.0 * float(obs[0])]), None


def test_policy_adapters_clip_validate_and_dispatch():
    ctrl = as_controller(lambda obs: -3.0)
    assert isinstance(ctrl, CallableController) and isinstance(ctrl, Controller)
    assert ctrl.act(np.zeros(2))[0] == -1.0  # clipped to the action bound
    sb3 = _FakeSB3()
    c = as_controller(sb3)
    assert isinstance(c, SB3Controller)
    assert c.act(np.array([0.2], np.float32))[0] == pytest.approx(0.4)
    assert sb3.calls == [True]  # deterministic by default
    pid = PID(dt_s=DT)
    assert as_controller(pid) is pid
    with pytest.raises(ValueError, match="non-finite"):
        as_controller(lambda obs: np.nan).act(np.zeros(1))
    with pytest.raises(ValueError, match="shape"):
        as_controller(lambda obs: [0.1, 0.2]).act(np.zeros(1))
    with pytest.raises(ValueError, match="cannot use"):
        as_controller(42)


def test_controller_specs(tmp_path):
    spec = parse_controller_spec("pid:kp=5,feedback=exo,anti_windup=back_calculation")
    cfg = pid_config(spec.options)
    assert cfg.gains.kp == 5.0 and cfg.gains.ki == 40.0 and cfg.feedback == "exo"
    assert (
        cfg.anti_windup == "back_calculation"
        and spec.slug == "pid_kp_5_feedback_exo_anti_windup_back_calculation"
    )
    tb = pid_config(parse_controller_spec("pid:textbook").options)
    assert not tb.derivative_on_measurement and tb.anti_windup == "none"
    assert parse_controller_spec("sac").kind == "shipped"
    model = tmp_path / "my_policy.zip"
    model.write_bytes(b"")
    spec = parse_controller_spec(str(model))
    assert spec.kind == "sb3" and spec.label == "my_policy" and spec.algorithm == "sac"
    assert parse_controller_spec(f"ppo:{model}").algorithm == "ppo"
    for bad, match in [
        ("pid:gain=3", "unknown PID option"),
        ("pid:kp=abc", "not a number"),
        ("pid:feedback=hip", "feedback"),
        ("lqr", "unknown controller"),
        (str(tmp_path / "missing.zip"), "does not exist"),
    ]:
        with pytest.raises(ValueError, match=match):
            parse_controller_spec(bad)


# ----------------------------------------------------------------------------- on the twin
@pytest.mark.slow
def test_ziegler_nichols_finds_an_ultimate_point_on_the_twin():
    # the procedure needs an operating point the motor can hold: 30 deg of flexion is one
    # (with the paper's 7 deg target the current twin pins the knee short of the target with
    # the command saturated, and `tune` says so instead of returning a gain)
    settings = zn.ZieglerNicholsSettings(rel_tol=0.15, target_angle_deg=30.0)
    result = zn.tune(settings)
    sustained = [t.kp for t in result.trials if t.sustained]
    decaying = [t.kp for t in result.trials if not t.sustained]
    assert decaying and sustained
    # Ku is the smallest sustained gain and every decaying trial lies below it
    assert result.ultimate_gain == min(sustained) and max(decaying) < result.ultimate_gain
    assert 0.02 < result.ultimate_period_s < 2.0
    g = result.gains
    assert g.kp == pytest.approx(0.6 * result.ultimate_gain)
    assert g.ki == pytest.approx(1.2 * result.ultimate_gain / result.ultimate_period_s)
    print("\n" + zn.format_result(result))


def test_sb3_models_see_the_observation_normalization_they_were_trained_with(tmp_path):
    """A checkpoint's vecnormalize.pkl (cpu preset) is applied before predict()."""
    import gymnasium as gym
    from stable_baselines3.common.vec_env import DummyVecEnv, VecNormalize

    from myoexo.control.policy import SB3Controller
    from myoexo.control.specs import load_obs_normalizer

    vn = VecNormalize(DummyVecEnv([lambda: gym.make("Pendulum-v1")]), norm_reward=False)
    vn.obs_rms.mean[:] = 1.0
    vn.obs_rms.var[:] = 4.0
    vn.save(str(tmp_path / "vecnormalize.pkl"))
    assert load_obs_normalizer(str(tmp_path / "elsewhere" / "model.zip")) is None

    class EchoModel:
        def predict(self, obs, deterministic=True):
            return np.asarray(obs)[:1] / 10.0, None

    normalizer = load_obs_normalizer(str(tmp_path / "model.zip"))
    ctrl = SB3Controller(EchoModel(), obs_normalizer=normalizer)
    action = ctrl.act(np.array([3.0, 3.0, 3.0], np.float32))
    assert action[0] == pytest.approx(0.1, rel=1e-3)  # (3 - 1) / sqrt(4) / 10


def test_ramped_setpoint_and_clipped_command():
    """``ramp_s`` moves the setpoint linearly from the first measured angle to the target on
    the controller's own clock; ``limit`` clips the command; both parse from a spec."""
    import math

    from myoexo.control.pid import PID, PIDConfig
    from myoexo.control.specs import parse_controller_spec, pid_config

    pid = PID(PIDConfig(ramp_s=0.5), dt_s=0.1)
    start, target = math.radians(90.0), math.radians(7.0)
    points = [pid.setpoint_rad(target, start) for _ in range(8)]
    assert points[0] == pytest.approx(start)
    assert points[5] == pytest.approx(target) and points[7] == pytest.approx(target)
    assert points[2] == pytest.approx(start + 0.4 * (target - start))
    pid.reset()
    assert pid.setpoint_rad(target, math.radians(60.0)) == pytest.approx(math.radians(60.0))
    assert PID(PIDConfig(), dt_s=0.1).setpoint_rad(target, start) == target  # the paper's step
    clipped = PID(PIDConfig(output_limit=0.6), dt_s=0.01)
    assert clipped.update(target, start) == pytest.approx(-0.6)
    spec = parse_controller_spec("pid:ramp_s=0.6,limit=0.6")
    config = pid_config(spec.options)
    assert config.ramp_s == 0.6 and config.output_limit == 0.6
    with pytest.raises(ValueError, match="ramp_s"):
        PIDConfig(ramp_s=-1.0)
    with pytest.raises(ValueError, match="output_limit"):
        PIDConfig(output_limit=1.5)


def test_pid_along_a_minimum_jerk_ramp():
    start, target, ramp = math.radians(90.0), math.radians(7.0), 1.0
    steps = round(ramp / DT) + 5
    linear = PID(PIDConfig(ramp_s=ramp), dt_s=DT)
    minjerk = PID(PIDConfig(ramp_s=ramp, reference="minjerk"), dt_s=DT)
    lin = np.array([linear.setpoint_rad(target, start) for _ in range(steps)])
    mj = np.array([minjerk.setpoint_rad(target, start) for _ in range(steps)])
    assert lin[0] == mj[0] == start
    at_ramp = round(ramp / DT)  # the setpoint of the step ramp_s after the first
    assert mj[at_ramp] == pytest.approx(target) and mj[-1] == pytest.approx(target)
    assert lin[at_ramp] == pytest.approx(target)
    # the minimum-jerk setpoint starts slower, is level with the linear one at mid-ramp
    assert mj[10] > lin[10]  # still nearer the start (flexed) after 0.1 s
    assert mj[50] == pytest.approx(lin[50])
    assert mj[90] < lin[90]  # and nearer the target near the end
    assert np.all(np.diff(mj) <= 0.0)
    # the default stays the linear ramp; the shape is in the repr and checked
    assert PIDConfig().reference == "linear"
    assert "reference='minjerk'" in repr(minjerk)
    with pytest.raises(ValueError, match="reference"):
        PIDConfig(reference="cubic")
    # the commands differ once the setpoints do
    a = PID(PIDConfig(ramp_s=ramp), dt_s=DT)
    b = PID(PIDConfig(ramp_s=ramp, reference="minjerk"), dt_s=DT)
    knee = sensed(90.0)
    ua = [a.act(None, knee)[0] for _ in range(20)]
    ub = [b.act(None, knee)[0] for _ in range(20)]
    assert ua[0] == ub[0] and ua != ub


def test_minimum_jerk_pid_spec_parses():
    spec = parse_controller_spec("pid:reference=minjerk,ramp_s=1")
    assert spec.kind == "pid" and spec.label == "pid:reference=minjerk,ramp_s=1"
    config = pid_config(spec.options)
    assert config.reference == "minjerk" and config.ramp_s == 1.0
    with pytest.raises(ValueError, match="reference"):
        parse_controller_spec("pid:reference=cubic,ramp_s=1")


def test_ramp_steps_to_the_target_where_the_knee_lags_it():
    """``step_lag_deg``: the ramp's point while the knee keeps within the lag of it, the
    target from the first step it lags further (and for the rest of the motion)."""
    start, target = math.radians(90.0), math.radians(7.0)
    config = PIDConfig(ramp_s=1.0, reference="minjerk", step_lag_deg=4.0)
    plain = PID(PIDConfig(ramp_s=1.0, reference="minjerk"), dt_s=DT)
    points = [plain.setpoint_rad(target, start) for _ in range(40)]  # the ramp from the start
    # a knee that follows the ramp within the lag: the ramp's points
    lagging = PID(config, dt_s=DT)
    knee = [start] + [p + math.radians(3.9) for p in points[1:]]
    assert [lagging.setpoint_rad(target, k) for k in knee] == points
    # a knee held at the start: the ramp leaves it behind, then the setpoint is the target
    held = PID(config, dt_s=DT)
    setpoints = [held.setpoint_rad(target, start) for _ in range(40)]
    first = setpoints.index(target)
    assert setpoints[:first] == points[:first] and set(setpoints[first:]) == {target}
    assert math.degrees(start - points[first - 1]) <= 4.0 < math.degrees(start - points[first])
    # once stepped it stays stepped, even where the knee catches up; reset starts afresh
    assert held.setpoint_rad(target, target) == target
    held.reset()
    assert held.setpoint_rad(target, start) == start
    # its checks, and the spec
    with pytest.raises(ValueError, match=r"step_lag_deg = 4.0 needs a ramp"):
        PIDConfig(step_lag_deg=4.0)
    with pytest.raises(ValueError, match=r"step_lag_deg = -1.0 is outside \(0, 180\]"):
        PIDConfig(ramp_s=1.0, step_lag_deg=-1.0)
    spec = parse_controller_spec("pid:reference=minjerk,ramp_s=0.45,step_lag_deg=4")
    assert pid_config(spec.options) == PIDConfig(ramp_s=0.45, reference="minjerk", step_lag_deg=4.0)


# ----------------------------------------------------------------------------- sensors
class _Spy:
    """Records the sensor records it is given; commands nothing."""

    def __init__(self, sensors=frozenset()):
        self.sensors = frozenset(sensors)
        self.seen: list = []

    def reset(self, seed=None):
        self.seen.clear()

    def act(self, obs, measurements):
        self.seen.append(measurements)
        return np.zeros(1, dtype=np.float32)


def test_a_controller_receives_only_the_record_of_its_sensors():
    """On a perturbed twin (noisy, late sensors) a controller that declares no sensor gets
    the exoskeleton's readings only: a record type without any knee field, no value of it the
    true knee angle. One that declares the knee angle sensor gets that sensor's (noisy, late)
    reading, never the true angle either."""
    import dataclasses

    from myoexo.control.rollout import rollout
    from myoexo.envs import make_env

    assert not any("knee" in f.name for f in dataclasses.fields(Measurements))
    env = make_env(2, episode_duration_s=0.2, robustness=True)
    infos: list[dict] = []
    try:
        for sensors in (frozenset(), {KNEE_ANGLE_SENSOR}):
            infos.clear()
            spy = _Spy(sensors)
            rollout(env, spy, seed=4, on_step=lambda _, info: infos.append(dict(info)))
            assert len(spy.seen) == len(infos) - 1 == 20
            for m, info in zip(spy.seen, infos, strict=False):
                assert dataclasses.is_dataclass(m) and not isinstance(m, dict)
                if not sensors:
                    assert type(m) is Measurements and not hasattr(m, "knee_angle_deg")
                    assert info["knee_angle_deg"] not in dataclasses.astuple(m)
                else:
                    assert type(m) is KneeAngleMeasurements
                    assert m.knee_angle_deg == info["measured_knee_angle_deg"]
                    assert m.knee_angle_deg != info["knee_angle_deg"]
                assert m.exo_angle_deg == info["measured_exo_angle_deg"]
                assert m.exo_angle_deg != info["exo_angle_deg"]
                assert m.setpoint_deg == info["target_angle_deg"] and m.time_s == info["time_s"]
                with pytest.raises(dataclasses.FrozenInstanceError):
                    m.exo_angle_deg = 0.0  # type: ignore[misc]
    finally:
        env.close()
    with pytest.raises(ValueError, match="unknown sensors"):
        rollout(make_env(0, episode_duration_s=0.05), _Spy({"hip_angle"}), seed=0)


@pytest.mark.parametrize(
    ("spec", "reads_knee"),
    [
        ("pid", True),
        ("pid:tuned=latency", True),
        ("guard:sac", True),
        ("pid:feedback=exo", False),
        ("guard:pid:feedback=exo", False),
        ("impedance", True),
        ("impedance:feedback=exo", False),
        ("student_exo", False),
        ("guard:student_exo", False),
        ("sac", False),  # its observation is the twin's full state; its record is the device's
    ],
)
def test_only_the_controllers_on_the_knee_declare_the_knee_angle_sensor(spec, reads_knee):
    from myoexo.control.protocol import declared_sensors
    from myoexo.control.specs import build_controller

    class _Env:
        class unwrapped:
            dt = 0.01

    controller = build_controller(parse_controller_spec(spec), _Env())
    assert declared_sensors(controller) == ({KNEE_ANGLE_SENSOR} if reads_knee else frozenset())


def test_constant_controller_holds_its_command_and_refuses_one_out_of_range() -> None:
    from myoexo.control import ConstantController

    hold = ConstantController(-0.4)
    hold.reset(3)
    first = hold.act(np.zeros(5))
    first[0] = 0.9  # a fresh array each step: changing one leaves the command alone
    np.testing.assert_array_equal(hold.act(np.ones(5)), np.array([-0.4], dtype=np.float32))
    assert hold.name == "constant -0.4"
    with pytest.raises(ValueError, match=r"command = 1.5 is outside \[-1, 1\]"):
        ConstantController(1.5)
    with pytest.raises(ValueError, match="nan"):
        ConstantController(float("nan"))
