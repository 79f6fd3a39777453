"""The stall guard (``guard:SPEC``): silent unless the knee stalls far from the target, then
integral action toward it, within the motor's range."""

from __future__ import annotations

import json

import numpy as np
import pytest

from myoexo.control.guard import StallGuard, StallGuardConfig, exo_strap_lag_deg_per_command
from myoexo.control.policy import as_controller
from myoexo.control.specs import build_controller, parse_controller_spec
from myoexo.envs.sensors import KNEE_ANGLE_SENSOR, KneeAngleMeasurements, Measurements


def _info(knee_deg: float, target_deg: float = 7.0, exo_deg: float | None = None):
    """A sensor record with the knee angle sensor (the encoder at the knee unless given)."""
    exo = knee_deg if exo_deg is None else exo_deg
    return KneeAngleMeasurements(0.0, target_deg, exo, 0.0, 0.0, knee_deg, 0.0)


def _frozen(command: float = -0.1):
    return as_controller(lambda obs: np.array([command], dtype=np.float32), name="frozen")


def test_silent_while_the_error_is_small_or_early():
    guard = StallGuard(_frozen(), StallGuardConfig(engage_error_deg=17.0, engage_after_s=2.0))
    guard.reset()
    obs = np.zeros(3, dtype=np.float32)
    for step in range(400):  # 4 s: a large error before 2 s, a small one after
        knee = 80.0 if step < 200 else 20.0
        assert guard.act(obs, _info(knee))[0] == pytest.approx(-0.1)
    assert guard.engaged_at_s is None


def test_engages_on_a_stall_and_pushes_toward_the_target_within_the_motor_range():
    guard = StallGuard(_frozen(), StallGuardConfig(engage_after_s=2.0, ki_per_rad_s=4.0))
    guard.reset()
    obs = np.zeros(3, dtype=np.float32)
    commands = [float(guard.act(obs, _info(70.0))[0]) for _ in range(400)]
    assert guard.engaged_at_s == pytest.approx(2.0)
    assert commands[199] == pytest.approx(-0.1)  # untouched before it engages
    # knee 63 deg above the target: extension grows (negative), by ki * error * dt per step
    step = -4.0 * np.radians(63.0) * 0.01
    assert commands[201] - commands[200] == pytest.approx(step, rel=1e-4)
    assert min(commands) >= -1.0 and commands[-1] == pytest.approx(-1.0)
    # conditional integration: the term stopped growing at saturation (at most one step
    # past it), so it unwinds within a few steps once the knee passes the target
    back = [float(guard.act(obs, _info(0.0))[0]) for _ in range(20)]  # 7 deg past it
    assert back[-1] > -1.0 and back[-1] > back[-2]
    guard.reset()
    assert guard.engaged_at_s is None and guard.integral == 0.0


def test_guard_spec_wraps_any_controller_and_rejects_nonsense():
    spec = parse_controller_spec("guard:pid:ramp_s=1")
    assert spec.guard and spec.kind == "pid" and spec.label == "guard:pid:ramp_s=1"
    assert spec.options == {"ramp_s": 1.0}
    with pytest.raises(ValueError, match="needs the controller"):
        parse_controller_spec("guard:")
    with pytest.raises(ValueError, match="guarded"):
        parse_controller_spec("guard:guard:pid")
    with pytest.raises(ValueError, match="engage_error_deg"):
        StallGuardConfig(engage_error_deg=-1.0)

    class _Env:
        class unwrapped:
            dt = 0.01

    controller = build_controller(spec, _Env())
    assert isinstance(controller, StallGuard)
    assert controller.config.control_period_s == 0.01


@pytest.mark.slow
def test_guard_frees_a_stalled_subject_of_the_shipped_policy_and_leaves_others_alone():
    """Closed loop on the twin: on a subject where the shipped policy stays far from the
    target the guard brings the knee within the PID's usual error; on a subject where it
    does not stall the trajectory is the policy's own, step for step (checked against the
    policy alone on the first few such subjects: one code path, the same on each)."""
    import gymnasium as gym

    import myoexo
    from myoexo.control.rollout import rollout
    from myoexo.evaluation.config import subject_seed

    policy = myoexo.load_policy("sac")
    env = gym.make("MyoExoKnee-v2")
    try:
        finals, silent = {}, []
        for idx in range(40):
            seed = subject_seed(2, idx, 0)
            guarded_ctrl = StallGuard(as_controller(policy))
            guarded = rollout(env, guarded_ctrl, seed, channels=("error_deg",)).signals
            finals[idx] = abs(float(guarded["error_deg"][-1]))
            if guarded_ctrl.engaged_at_s is None and len(silent) < 8:
                raw = rollout(env, as_controller(policy), seed, channels=("error_deg",))
                np.testing.assert_array_equal(raw.signals["error_deg"], guarded["error_deg"])
                silent.append(idx)
    finally:
        env.close()
    assert silent, "the guard engaged on every subject: nothing left to compare"
    assert all(g <= 20.0 for g in finals.values()), finals


def test_a_device_controller_gets_a_guard_on_the_encoder():
    guard = StallGuard(_frozen(), StallGuardConfig(feedback="exo", engage_after_s=0.0))
    guard.reset()
    obs = np.zeros(3, dtype=np.float32)
    assert guard.sensors == frozenset()  # the encoder is the device's own
    # the knee is far, the encoder is near: an encoder guard stays silent
    assert guard.act(obs, _info(70.0, exo_deg=10.0))[0] == pytest.approx(-0.1)
    assert guard.engaged_at_s is None
    device_only = Measurements(0.0, 7.0, 60.0, 0.0, 0.0)  # the encoder is what it reads
    assert guard.act(obs, device_only)[0] < -0.1 and guard.engaged_at_s is not None
    with pytest.raises(ValueError, match="feedback"):
        StallGuardConfig(feedback="hip")

    class _Env:
        class unwrapped:
            dt = 0.01

    pid_guard = build_controller(parse_controller_spec("guard:pid:feedback=exo"), _Env())
    assert pid_guard.config.feedback == "exo"
    assert pid_guard.config.strap_lag_deg_per_command == exo_strap_lag_deg_per_command()
    assert build_controller(parse_controller_spec("guard:pid"), _Env()).config.feedback == "knee"


def test_an_encoder_guard_adds_the_strap_lag_of_its_last_command():
    """The knee lags the encoder by lag * command: pushing at -0.8 with the encoder 12 deg
    short, the knee is about 18 deg short, which is beyond the 17 deg the guard waits for."""
    lag = 7.5
    config = StallGuardConfig(feedback="exo", engage_after_s=0.0, strap_lag_deg_per_command=lag)
    guard = StallGuard(_frozen(-0.8), config)
    guard.reset()
    obs = np.zeros(3, dtype=np.float32)
    info = _info(25.0, exo_deg=19.0)
    assert guard.act(obs, info)[0] == pytest.approx(-0.8)  # no command yet: no lag
    assert guard.engaged_at_s is None
    out = guard.act(obs, info)  # 12 + 7.5 * 0.8 = 18 deg
    assert guard.engaged_at_s is not None
    assert out[0] - (-0.8) == pytest.approx(-4.0 * np.radians(18.0) * 0.01, rel=1e-4)
    plain = StallGuard(_frozen(-0.8), StallGuardConfig(feedback="exo", engage_after_s=0.0))
    plain.reset()
    for _ in range(3):
        plain.act(obs, info)
    assert plain.engaged_at_s is None  # the raw encoder error (12 deg) keeps it silent
    with pytest.raises(ValueError, match="strap_lag_deg_per_command"):
        StallGuardConfig(feedback="exo", strap_lag_deg_per_command=-1.0)
    with pytest.raises(ValueError, match="needs feedback='exo'"):
        StallGuardConfig(strap_lag_deg_per_command=7.5)  # the knee guard reads the knee


@pytest.mark.parametrize(("level", "command"), [(2, -0.8), (3, -0.5)])
def test_the_strap_lag_is_the_twins(level, command):
    """Held at a constant command until the knee rests against the spastic muscles, the
    twin's knee is more flexed than its encoder by the lag the encoder guard assumes."""
    import gymnasium as gym

    import myoexo  # noqa: F401  (registers the ids)
    from myoexo.evaluation.config import subject_seed

    env = gym.make(f"MyoExoKnee-v{level}")
    try:
        env.reset(seed=subject_seed(level, 5, 7))
        for _ in range(600):  # 6 s: the lightly damped knee settles
            _, _, _, _, info = env.step(np.array([command], dtype=np.float32))
    finally:
        env.close()
    assert abs(info["knee_vel_rad_s"]) < 0.01
    lag_deg = info["knee_angle_deg"] - info["exo_angle_deg"]
    assert lag_deg == pytest.approx(-exo_strap_lag_deg_per_command() * command, abs=0.6)


def test_a_guarded_policy_runs_on_its_policys_observation():
    """evaluate_controller(StallGuard(student)) builds the env the student reads."""
    from myoexo.control.specs import controller_env_kwargs, load_shipped_policy

    student = load_shipped_policy("student_exo")
    assert controller_env_kwargs(StallGuard(student)) == controller_env_kwargs(student)
    assert controller_env_kwargs(StallGuard(student))["obs_preset"] == "exo"


def test_the_strap_lag_is_fitted_data_with_provenance(tmp_path, monkeypatch, capsys):
    """``myoexo twin strap-lag --write`` writes the fit the encoder guard reads; without the
    file the guard names the command that writes it."""
    from myoexo import cli
    from myoexo.control.guard import STRAP_LAG_FIT, exo_guard
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime import fits

    shipped = fits.read_fit(STRAP_LAG_FIT)
    assert shipped["provenance"]["twin_version"] == TWIN_VERSION
    # the command that wrote it, as it was spelled then (earlier names point to today's)
    assert shipped["provenance"]["command"].split()[:1] == ["myoexo"]
    assert "strap-lag --seed 3" in shipped["provenance"]["command"]
    assert exo_guard().strap_lag_deg_per_command == shipped["result"]["lag_deg_per_command"]

    monkeypatch.setattr(fits, "fits_dir", lambda: tmp_path)
    with pytest.raises(FileNotFoundError, match="--write"):
        exo_guard()
    assert cli.main(["twin", "strap-lag", "--subjects", "1", "--write"]) == 0
    doc = json.loads((tmp_path / f"{STRAP_LAG_FIT}.json").read_text())
    assert doc["provenance"]["root_seed"] == 3
    assert 4.0 < doc["result"]["lag_deg_per_command"] < 10.0  # the straps' give, deg
    assert exo_guard().strap_lag_deg_per_command == doc["result"]["lag_deg_per_command"]
    assert (
        cli.main(["twin", "strap-lag", "--seed", "0", "--subjects", "1"]) == 2
    )  # the evaluation root
    assert "evaluation root" in capsys.readouterr().err


def test_a_knee_guard_declares_the_knee_sensor_and_keeps_it_from_its_controller():
    """The knee guard reads the knee angle sensor it declares; the controller it wraps,
    which declares none, gets the exoskeleton's sensors only."""
    seen = []

    class _Spy:
        def reset(self, seed=None):
            pass

        def act(self, obs, measurements):
            seen.append(measurements)
            return np.array([-0.1], dtype=np.float32)

    guard = StallGuard(_Spy(), StallGuardConfig(engage_after_s=0.0))
    assert guard.sensors == {KNEE_ANGLE_SENSOR}
    guard.reset()
    assert guard.act(np.zeros(3, np.float32), _info(70.0, exo_deg=60.0))[0] < -0.1
    assert type(seen[0]) is Measurements and not hasattr(seen[0], "knee_angle_deg")
    assert seen[0].exo_angle_deg == 60.0 and seen[0].setpoint_deg == 7.0
    with pytest.raises(ValueError, match="knee angle sensor"):
        guard.act(np.zeros(3, np.float32), seen[0])  # no knee reading: it cannot guess one
