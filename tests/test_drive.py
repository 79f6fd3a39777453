"""The exo drive's end-stop protection (myoexo.model.drive): it guards the stop inside the
knee's range, brakes only when a command would carry the limb past its braking curve, leaves
every nominal trajectory untouched and replays bit for bit."""

from __future__ import annotations

import math

import numpy as np
import pytest

from myoexo.control.rollout import rollout
from myoexo.control.specs import build_controller, parse_controller_spec
from myoexo.envs import make_env
from myoexo.model import TwinParams, build_model
from myoexo.model.drive import StopProtection, stop_protection


@pytest.fixture(scope="module")
def protection() -> StopProtection:
    model, _ = build_model(TwinParams(scene=False))
    p = stop_protection(model)
    assert p is not None
    return p


def test_the_protection_is_built_from_the_twin(protection):
    params = TwinParams()
    upper_rad = math.radians(params.exo_knee_range_deg[1])
    assert protection.upper_rad == pytest.approx(upper_rad, abs=1e-5)
    # the extension stop lies beyond the knee's own limit (0 deg): not guarded
    assert protection.lower_rad == -math.inf
    # the motor over the exo's and the shank's inertia: some 200 rad/s^2
    assert 100.0 < protection.accel_per_command_rad_s2 < 400.0
    assert protection.brake_rad_s2 == pytest.approx(
        params.exo_stop_braking_fraction * protection.accel_per_command_rad_s2
    )
    assert protection.timestep_s == params.timestep_s


def test_earlier_twins_have_no_protection():
    model, _ = build_model(TwinParams.of_version(3, scene=False))
    assert stop_protection(model) is None
    model, _ = build_model(TwinParams(scene=False, exo_stop_braking_fraction=0.0))
    assert stop_protection(model) is None


def test_it_brakes_only_past_the_braking_curve(protection):
    top = protection.upper_rad
    # far from the stop, or moving away from it, every command passes
    assert protection.command(top - 1.0, 5.0, 1.0) == 1.0
    assert protection.command(top - 0.05, -5.0, 1.0) == 1.0
    assert protection.command(top - 0.05, 0.0, 0.3) == 0.3
    # fast towards the stop and close to it: full braking
    assert protection.command(top - 0.3, 12.0, 1.0) == -1.0
    assert protection.command(top - 0.3, 12.0, -0.5) == -1.0
    # at the contact speed it may touch the stop
    assert protection.command(top, 0.3, 0.0) == 0.0
    # the period check is conservative: whatever the timestep check brakes, it flags
    for angle, speed in [(top - 0.3, 12.0), (top - 0.05, 3.0), (top - 0.6, 14.0)]:
        if protection.command(angle, speed, 1.0) != 1.0:
            assert protection.near(angle, speed, 0.01)
    assert not protection.near(top - 1.2, -5.0, 0.01)


def test_bad_parameters_are_refused():
    with pytest.raises(ValueError, match="exo_stop_braking_fraction"):
        TwinParams(exo_stop_braking_fraction=1.5)
    with pytest.raises(ValueError, match="exo_stop_contact_speed_rad_s"):
        TwinParams(exo_stop_contact_speed_rad_s=-1.0)
    with pytest.raises(ValueError, match="brake_rad_s2"):
        StopProtection(-math.inf, 1.0, 200.0, 0.0, 0.5, 0.002)


@pytest.mark.parametrize("level", [0, 2])
def test_a_nominal_episode_is_that_of_the_unprotected_twin(level):
    """The paper's PID never comes near the braking curve: twin 4 and twin 3 (no protection)
    give the same trajectory, bit for bit."""
    signals = []
    for params in (TwinParams(), TwinParams.of_version(3)):
        env = make_env(level, twin=params)
        try:
            controller = build_controller(parse_controller_spec("pid"), env)
            s = rollout(env, controller, 3, channels=("knee_angle_deg", "drive_braking")).signals
        finally:
            env.close()
        signals.append(s)
    assert not np.any(signals[0]["drive_braking"])
    np.testing.assert_array_equal(signals[0]["knee_angle_deg"], signals[1]["knee_angle_deg"])


class _Slam:
    """Full flexion command: the shank swings into the flexion stop."""

    def reset(self, seed=None):
        pass

    def act(self, obs, measurements):
        return np.array([1.0], dtype=np.float32)


def test_a_slam_is_braked_reported_and_replayed_bit_for_bit():
    env = make_env(0, start_angle_deg=20.0)
    try:
        first = rollout(env, _Slam(), 0, channels=("knee_angle_deg", "drive_braking")).signals
        second = rollout(env, _Slam(), 0, channels=("knee_angle_deg", "drive_braking")).signals
    finally:
        env.close()
    assert np.any(first["drive_braking"])
    assert np.max(first["knee_angle_deg"]) < TwinParams().exo_knee_range_deg[1] + 3.0
    np.testing.assert_array_equal(first["knee_angle_deg"], second["knee_angle_deg"])
    np.testing.assert_array_equal(first["drive_braking"], second["drive_braking"])
