"""The straps stay physical: the strap torque within the bound the motor, the leg and the
strap's own dynamics allow (myoexo.model.strap_bound), under every controller family the
evaluation offers and under bang-bang commands; the misalignment reported and bounded."""

from __future__ import annotations

import itertools
import math
import warnings

import numpy as np
import pytest

from myoexo.control.rollout import rollout
from myoexo.control.specs import build_controller, parse_controller_spec, spec_env_kwargs
from myoexo.envs import make_env
from myoexo.evaluation.metrics import episode_metrics
from myoexo.model import TwinParams, build_model
from myoexo.model.strap_bound import (
    kelvin_voigt_impact_peak,
    kelvin_voigt_step_peak,
    strap_bound,
)

CHANNELS = (
    "time_s",
    "knee_angle_deg",
    "knee_vel_rad_s",
    "exo_angle_deg",
    "misalignment_deg",
    "target_angle_deg",
    "command",
    "exo_torque_nm",
    "interaction_torque_nm",
)


class BangBang:
    """Full motor command, reversed every *period_steps* control steps (10 ms each)."""

    def __init__(self, period_steps: int) -> None:
        self.period_steps = period_steps
        self._n = 0

    def reset(self, seed: int | None = None) -> None:
        self._n = 0

    def act(self, obs, measurements):
        self._n += 1
        sign = 1.0 if (self._n // self.period_steps) % 2 else -1.0
        return np.array([sign], dtype=np.float32)


@pytest.fixture(scope="module")
def bound():
    model, _ = build_model(TwinParams(scene=False))
    return strap_bound(model)


def test_the_bound_is_built_from_the_twins_own_parts(bound):
    assert bound.motor_limit_nm == TwinParams().motor_limit_nm
    # the lower exo is a small fraction of the shank's inertia; the leg's muscles are strong
    assert 0.01 < bound.exo_inertia_kg_m2 < 0.1
    assert 0.2 < bound.knee_inertia_kg_m2 < 1.0
    assert 0.02 < bound.exo_share < 0.2
    assert 150.0 < bound.human_torque_nm < 1000.0
    assert 0.0 < bound.exo_weight_nm < 5.0
    # the pins' damping keeps the strap from ringing: damping ratio near 1, small overshoot
    assert 0.7 < bound.damping_ratio < 1.5
    assert 1.0 < bound.step_overshoot < 1.25
    assert bound.motor_limit_nm < bound.torque_nm < 1.6 * bound.motor_limit_nm
    assert bound.misalignment_deg == 15.0


def test_kelvin_voigt_overshoot_falls_with_damping():
    peaks = [kelvin_voigt_step_peak(z) for z in (0.0, 0.1, 0.5, 1.0, 3.0)]
    assert peaks[0] == pytest.approx(2.0, abs=0.01)  # an undamped spring doubles a step
    assert all(a > b for a, b in itertools.pairwise(peaks))
    assert peaks[-1] > 1.0  # the damper itself passes force on
    with pytest.raises(ValueError, match="damping_ratio"):
        kelvin_voigt_step_peak(-1.0)
    # an impact on an undamped spring peaks at v sqrt(k m); a stiff damper at contact, 2 zeta
    assert kelvin_voigt_impact_peak(0.0) == pytest.approx(1.0, abs=1e-3)
    assert kelvin_voigt_impact_peak(0.3) < 1.0
    assert kelvin_voigt_impact_peak(2.0) == pytest.approx(4.0, rel=1e-6)


def test_the_old_undamped_pins_had_a_bound_far_above_the_motor():
    """With the pins' former 1 Nm s/rad the strap rang: its own bound was twice the motor's."""
    model, _ = build_model(TwinParams.of_version(1, scene=False))
    assert strap_bound(model).torque_nm > 250.0


def _episodes(controller, level: int, seeds, **env_kwargs):
    """The signals of one episode per seed, on one build of the twin (each reset by its
    seed)."""
    env = make_env(level, **env_kwargs)
    try:
        return [rollout(env, controller, seed, channels=CHANNELS).signals for seed in seeds]
    finally:
        env.close()


def _episode(controller, level: int, seed: int, **env_kwargs):
    return _episodes(controller, level, (seed,), **env_kwargs)[0]


@pytest.mark.parametrize(
    "spec",
    ["pid", "pid:tuned=exo", "pid:tuned=latency", "pid:ramp_s=1", "guard:sac", "bang:1"],
)
@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_strap_torque_stays_within_the_bound(bound, spec, level):
    """Every controller family of ``myoexo evaluate``, the encoder-feedback PIDs that drove
    the strap to 900 Nm before the pins were damped among them, and a bang-bang command at
    100 Hz."""
    parsed = None if spec.startswith("bang:") else parse_controller_spec(spec)
    env = make_env(level, **({} if parsed is None else spec_env_kwargs(parsed)))
    try:  # the controller is built for the env it then runs on (one build of the twin)
        if parsed is None:
            controller = BangBang(int(spec.split(":")[1]))
        else:
            controller = build_controller(parsed, env)
        s = rollout(env, controller, 5, channels=CHANNELS).signals
    finally:
        env.close()
    assert np.max(s["interaction_torque_nm"]) <= bound.torque_nm
    # the misalignment the env reports is the knee's angle less the exo hinge's
    np.testing.assert_allclose(s["misalignment_deg"], s["knee_angle_deg"] - s["exo_angle_deg"])
    assert np.max(np.abs(s["misalignment_deg"])) <= bound.misalignment_deg


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_bang_bang_at_10_hz_and_1_hz_stays_within_the_bound(bound, level):
    """Reversing the full command every 0.1 s (or every 1 s) swings the free shank at up to
    ~20 rad/s. The drive's end-stop protection brakes before the flexion stop, so the strap
    never has to stop the shank's momentum against a rigid stop: the strap torque stays within
    the bound at every sample, the stops included."""
    for period_steps in (10, 100):
        for s in _episodes(BangBang(period_steps), level, seeds=(0, 2)):
            assert np.max(s["interaction_torque_nm"]) <= bound.torque_nm
            assert np.max(np.abs(s["misalignment_deg"])) <= bound.misalignment_deg


def test_without_the_drive_protection_the_10_hz_bang_bang_breaks_the_bound(bound):
    """Twin 3's drive (no protection): the same command slams the shank into the flexion stop
    and the strap passes more than the bound (the impact the protection exists for)."""
    env = make_env(0, twin=TwinParams.of_version(3))
    try:
        s = rollout(env, BangBang(10), 0, channels=CHANNELS).signals
    finally:
        env.close()
    assert np.max(s["interaction_torque_nm"]) > bound.torque_nm


def test_peak_misalignment_is_an_episode_metric():
    s = _episode(BangBang(1), 0, seed=0)
    m = episode_metrics(s)
    assert m.peak_misalignment_deg == pytest.approx(np.max(np.abs(s["misalignment_deg"])))
    without = episode_metrics({k: v for k, v in s.items() if k != "exo_angle_deg"})
    assert math.isnan(without.peak_misalignment_deg)


def test_the_twin_page_states_the_bound_the_code_derives(bound):
    from pathlib import Path

    text = (Path(__file__).resolve().parents[1] / "docs" / "twin.md").read_text()
    assert f"{bound.torque_nm:.1f} Nm" in text
    assert f"{bound.misalignment_deg:g} deg" in text


def test_an_earlier_twin_version_is_rebuilt_from_its_fields():
    from myoexo.model.params import EARLIER_TWINS, TWIN_VERSION

    assert TwinParams.of_version(TWIN_VERSION) == TwinParams()
    old = TwinParams.of_version(1, scene=False)
    assert old.pin_damping_nm_s_rad == EARLIER_TWINS[1]["pin_damping_nm_s_rad"]
    assert old.scene is False
    model, _ = build_model(old)
    dof = model.joint("exo_shank_pin").dofadr[0]
    assert model.dof_damping[dof] == 1.0 and model.dof_armature[dof] == 0.001
    with pytest.raises(ValueError, match="twin version 0 is unknown"):
        TwinParams.of_version(0)


def test_a_policy_of_an_earlier_twin_is_evaluated_with_a_warning():
    """The shipped policies record no twin version: they were trained on version 1."""
    from myoexo.envs.options import TwinOptions
    from myoexo.evaluation.engine import TwinMismatchWarning, resolve_controllers

    with pytest.warns(TwinMismatchWarning, match="trained on twin version 1"):
        resolve_controllers(["sac"], log=lambda _: None, twin=TwinOptions())


def test_a_policy_of_another_twin_is_evaluated_with_a_warning():
    from myoexo.envs.options import TwinOptions
    from myoexo.evaluation.engine import TwinMismatchWarning, resolve_controllers

    # student_fine: distilled on today's default twin, evaluated with the "spindle" reflex
    spindle = TwinOptions().replace(reflex="spindle")
    with pytest.warns(TwinMismatchWarning, match=r"evaluated on \[reflex=spindle\]"):
        resolve_controllers(["student_fine"], log=lambda _: None, twin=spindle)
    # the shipped residual was trained on today's default twin: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error", TwinMismatchWarning)
        resolve_controllers(["residual"], log=lambda _: None, twin=TwinOptions())
