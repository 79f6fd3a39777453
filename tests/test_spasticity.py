"""Tests of the spastic reflex model (myoexo.spasticity): Table I, eqs. 1-4, torch twin,
subject sampling and the MyoSuite muscle-pipeline stage."""

from __future__ import annotations

import dataclasses
import itertools
import math
import pickle

import numpy as np
import pytest
import torch

from myoexo.spasticity.coefficients import phi, sc_angle, sc_total, sc_total_torch, sc_velocity
from myoexo.spasticity.levels import (
    LEVELS,
    SPASTIC_MUSCLES,
    SUBJECT_REL_STD,
    SpasticityParams,
    sample_subject,
)
from myoexo.spasticity.stage import SpasticityStage

FIELDS = SpasticityParams.field_names()


def _phi_ref(k: float, b: float, b0: float) -> float:
    """Eq. 1 written literally (the module evaluates it through tanh)."""
    return 1.0 / (1.0 + math.exp(k * (b - b0)))


def _sc_ref(theta_deg: float, vel_rad_s: float, p: SpasticityParams) -> float:
    """Eqs. 2-4 (docs/reference.md section 2 reading), written literally."""
    sc_a = p.s_theta * (
        1.0
        - (_phi_ref(p.k, theta_deg, p.theta_flex_deg) - _phi_ref(p.k, theta_deg, p.theta_ext_deg))
    )
    sc_v = p.s_v * (
        1.0
        - (_phi_ref(p.k, vel_rad_s, p.v_upper_rad_s) - _phi_ref(p.k, vel_rad_s, p.v_lower_rad_s))
    )
    return sc_a + sc_v


# ------------------------------------------------------------------------------ Table I


def test_table_one_values() -> None:
    table = {
        0: (-45, 95, -10, 10, 0.0, 0.0, 0.0),
        1: (-35, 80, -1, 1, 0.2, 0.2, 0.5),
        2: (-30, 75, -0.5, 0.5, 0.3, 0.3, 0.2),
        3: (-15, 60, -0.25, 0.25, 0.3, 0.5, 0.1),
    }
    assert sorted(LEVELS) == [0, 1, 2, 3]  # level 4 excluded as unsafe
    for level, row in table.items():
        np.testing.assert_array_equal(LEVELS[level].as_array(), np.array(row, dtype=float))
    with pytest.raises(TypeError):
        LEVELS[4] = LEVELS[3]  # read-only table
    with pytest.raises(dataclasses.FrozenInstanceError):
        LEVELS[1].k = 1.0  # type: ignore[misc]


# ------------------------------------------------------------------------------ the model


def test_phi_is_eq_one_without_overflow() -> None:
    for k, b, b0 in [(0.5, 80.0, 80.0), (0.2, -30.0, 75.0), (0.1, 0.3, -0.25), (2.0, 3.0, 1.0)]:
        assert phi(k, b, b0) == pytest.approx(_phi_ref(k, b, b0), rel=1e-12, abs=1e-15)
    with np.errstate(all="raise"):  # no overflow warning for huge k |b - b0|
        np.testing.assert_allclose(phi(1e3, np.array([-1e3, 1e3]), 0.0), [1.0, 0.0])


def test_steep_windows_zero_inside_half_at_limits_full_outside() -> None:
    p = dataclasses.replace(LEVELS[2], k=50.0)  # large k: sharp windows
    inside_theta = np.linspace(p.theta_ext_deg + 1.0, p.theta_flex_deg - 1.0, 50)
    assert np.max(sc_angle(inside_theta, p)) < 1e-6 * p.s_theta
    # the velocity range is only 1 rad/s wide: ~0 at 0.2 rad/s (10 / k) from its limits
    assert np.max(sc_velocity(np.linspace(-0.3, 0.3, 7), p)) < 1e-4 * p.s_v
    for limit in (p.theta_ext_deg, p.theta_flex_deg):
        assert sc_angle(limit, p) == pytest.approx(p.s_theta / 2, rel=1e-9)
    for limit in (p.v_lower_rad_s, p.v_upper_rad_s):
        assert sc_velocity(limit, p) == pytest.approx(p.s_v / 2, rel=1e-9)
    for far in (-200.0, 300.0):
        assert sc_angle(far, p) == pytest.approx(p.s_theta, rel=1e-12)
    for far in (-20.0, 20.0):
        assert sc_velocity(far, p) == pytest.approx(p.s_v, rel=1e-12)
    assert sc_total(300.0, 20.0, p) == pytest.approx(p.s_theta + p.s_v, rel=1e-12)


def test_level_zero_is_identically_zero() -> None:
    theta, vel = np.meshgrid(np.linspace(-90, 180, 31), np.linspace(-20, 20, 17))
    assert np.all(sc_total(theta, vel, LEVELS[0]) == 0.0)


def test_hand_computed_points() -> None:
    # level 1 at its flexion limit and upper velocity limit:
    #   sc_a = 0.2 (1 - (1/2 - 1/(1+e^57.5))) = 0.1
    #   sc_v = 0.2 (1 - (1/2 - 1/(1+e)))      = 0.2 (0.5 + 0.26894142137) = 0.15378828427
    assert sc_angle(80.0, LEVELS[1]) == pytest.approx(0.1, abs=1e-12)
    assert sc_velocity(1.0, LEVELS[1]) == pytest.approx(0.15378828427, abs=1e-10)
    # level 3 at rest, knee extended (theta = 0, v = 0):
    #   sc_a = 0.3 (1 - (1/(1+e^-6) - 1/(1+e^1.5)))       = 0.3 * 0.18489814696 = 0.05546944409
    #   sc_v = 0.5 (1 - (1/(1+e^-0.025) - 1/(1+e^0.025))) = 0.5 * 0.98750065100 = 0.49375032550
    assert sc_total(0.0, 0.0, LEVELS[3]) == pytest.approx(0.05546944409 + 0.49375032550, abs=1e-10)
    # level 2 at 90 deg flexion moving at 3 rad/s: compare with the literal formula
    assert sc_total(90.0, 3.0, LEVELS[2]) == pytest.approx(_sc_ref(90.0, 3.0, LEVELS[2]), rel=1e-12)
    # vectorized over arrays and broadcasting
    theta = np.array([[-40.0, 0.0, 70.0, 110.0]])
    vel = np.array([[-2.0], [0.1], [4.0]])
    out = sc_total(theta, vel, LEVELS[1])
    assert out.shape == (3, 4)
    ref = np.vectorize(lambda t, v: _sc_ref(t, v, LEVELS[1]))(theta, vel)
    np.testing.assert_allclose(out, ref, rtol=1e-12)


def test_sc_grows_with_level_and_with_speed() -> None:
    theta = np.linspace(0.0, 90.0, 10)
    for v in (0.0, 3.0):
        by_level = [sc_total(theta, v, LEVELS[lvl]) for lvl in (0, 1, 2, 3)]
        for lo, hi in itertools.pairwise(by_level):
            assert np.all(hi > lo)
    for lvl in (1, 2, 3):
        assert np.all(sc_total(theta, 3.0, LEVELS[lvl]) > sc_total(theta, 0.2, LEVELS[lvl]))


# ------------------------------------------------------------------------------ torch twin


def test_numpy_and_torch_agree_in_float64() -> None:
    rng = np.random.default_rng(0)
    theta = rng.uniform(-60.0, 130.0, 500)
    vel = rng.uniform(-6.0, 6.0, 500)
    subjects = [*LEVELS.values(), *(sample_subject(lvl, rng) for lvl in (1, 2, 3))]
    for p in subjects:
        ref = sc_total(theta, vel, p)
        out = sc_total_torch(torch.from_numpy(theta), torch.from_numpy(vel), p)
        assert out.dtype == torch.float64
        np.testing.assert_allclose(out.numpy(), ref, rtol=0, atol=1e-9)
        tensors = {
            n: torch.tensor(v, dtype=torch.float64)
            for n, v in zip(FIELDS, p.as_array(), strict=True)
        }
        out2 = sc_total_torch(torch.from_numpy(theta), torch.from_numpy(vel), tensors)
        np.testing.assert_allclose(out2.numpy(), ref, rtol=0, atol=1e-9)


@pytest.mark.parametrize("level", [1, 2, 3])
def test_torch_gradients_match_finite_differences(level: int) -> None:
    names = ("theta_deg", "vel_rad_s", *FIELDS)

    def f(*xs: torch.Tensor) -> torch.Tensor:
        theta, vel, *params = xs
        return sc_total_torch(theta, vel, dict(zip(FIELDS, params, strict=True)))

    points = [(50.0, 0.3), (LEVELS[level].theta_flex_deg + 3.0, 1.5), (-20.0, -0.7)]
    for theta, vel in points:
        values = (theta, vel, *LEVELS[level].as_array())
        inputs = tuple(torch.tensor(v, dtype=torch.float64, requires_grad=True) for v in values)
        assert torch.autograd.gradcheck(f, inputs, eps=1e-6, atol=1e-8), names
    # every parameter receives a gradient (near the middle of the ranges no sigmoid saturates)
    p = LEVELS[level]
    mid_theta, mid_vel = (p.theta_ext_deg + p.theta_flex_deg) / 2 + 10.0, p.v_upper_rad_s / 2
    inputs = tuple(
        torch.tensor(v, dtype=torch.float64, requires_grad=True)
        for v in (mid_theta, mid_vel, *p.as_array())
    )
    f(*inputs).backward()
    for name, x in zip(names, inputs, strict=True):
        assert x.grad is not None and x.grad != 0.0, name


# ------------------------------------------------------------------------------ subjects


def test_subject_relative_std_is_ten_percent() -> None:
    rng = np.random.default_rng(123)
    n = 4000
    for level in (1, 2, 3):
        draws = np.stack([sample_subject(level, rng).as_array() for _ in range(n)])
        nominal = LEVELS[level].as_array()
        rel = draws / nominal - 1.0
        rel_std = rel.std(axis=0, ddof=1)
        se_std = SUBJECT_REL_STD / math.sqrt(2 * (n - 1))  # standard error of a std estimate
        np.testing.assert_allclose(rel_std, SUBJECT_REL_STD, atol=4 * se_std)
        np.testing.assert_allclose(rel.mean(axis=0), 0.0, atol=4 * SUBJECT_REL_STD / math.sqrt(n))
        # parameters are independent
        corr = np.corrcoef(rel.T) - np.eye(len(FIELDS))
        assert np.max(np.abs(corr)) < 4 / math.sqrt(n) + 0.02
    # level 0: zero gains and slope stay exactly zero
    p0 = sample_subject(0, rng)
    assert (p0.s_theta, p0.s_v, p0.k) == (0.0, 0.0, 0.0)
    assert p0.theta_ext_deg != LEVELS[0].theta_ext_deg


def test_subject_sampling_is_reproducible() -> None:
    a = sample_subject(2, np.random.default_rng(7))
    b = sample_subject(2, np.random.default_rng(7))
    c = sample_subject(2, np.random.default_rng(8))
    assert a == b
    assert a != c
    assert sample_subject(2, np.random.default_rng(7), rel_std=0.0) == LEVELS[2]


# ------------------------------------------------------------------------------ bad input


def test_bad_input_raises_clear_errors() -> None:
    with pytest.raises(ValueError, match="level 4"):
        sample_subject(4, np.random.default_rng(0))
    for bad in (4, -1, "2", 2.0, True, None):
        with pytest.raises(ValueError, match="Unknown spasticity level"):
            SpasticityStage(level=bad)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="s_theta must be >= 0"):
        dataclasses.replace(LEVELS[1], s_theta=-0.1)
    with pytest.raises(ValueError, match="s_v must be >= 0"):
        dataclasses.replace(LEVELS[1], s_v=-0.1)
    with pytest.raises(ValueError, match="k must be >= 0"):
        dataclasses.replace(LEVELS[1], k=-1.0)
    with pytest.raises(ValueError, match="theta_ext_deg < theta_flex_deg"):
        dataclasses.replace(LEVELS[1], theta_ext_deg=90.0)
    with pytest.raises(ValueError, match="v_lower_rad_s < v_upper_rad_s"):
        dataclasses.replace(LEVELS[1], v_lower_rad_s=2.0)
    with pytest.raises(ValueError, match="k must be finite"):
        dataclasses.replace(LEVELS[1], k=float("nan"))
    with pytest.raises(ValueError, match="theta_deg must be finite"):
        sc_total(float("nan"), 0.0, LEVELS[1])
    with pytest.raises(ValueError, match="vel_rad_s must be finite"):
        sc_total(np.array([10.0, 20.0]), np.array([0.0, np.inf]), LEVELS[1])
    with pytest.raises(ValueError, match="theta_deg must be finite"):
        sc_total_torch(torch.tensor([float("nan")], dtype=torch.float64), 0.0, LEVELS[1])
    with pytest.raises(ValueError, match="theta_deg must be finite"):
        SpasticityStage(level=1).sc_now(float("nan"), 0.0)
    with pytest.raises(ValueError, match="rel_std"):
        sample_subject(1, np.random.default_rng(0), rel_std=-0.1)


# ------------------------------------------------------------------------------ the stage


def test_stage_scalar_path_matches_vectorized_model() -> None:
    stage = SpasticityStage(level=3, subject_noise=False)
    rng = np.random.default_rng(1)
    for theta, vel in zip(rng.uniform(-30, 120, 50), rng.uniform(-5, 5, 50), strict=True):
        assert stage.sc_now(theta, vel) == pytest.approx(sc_total(theta, vel, LEVELS[3]), abs=1e-12)


class _Host:
    """The minimum a stage needs: model, data and a seeded np_random."""

    def __init__(self, model, data, seed: int) -> None:
        self.model, self.data = model, data
        self.np_random = np.random.default_rng(seed)


def test_stage_reset_draws_from_env_rng() -> None:
    stage = SpasticityStage(level="random")
    assert stage.level == 0  # nominal level 0 until the first reset
    host = _Host(None, None, seed=5)
    seen = []
    for _ in range(40):
        stage.reset(host)
        seen.append(stage.level)
        assert stage.subject != LEVELS[stage.level] or stage.level == 0
    assert set(seen) == {0, 1, 2, 3}
    again = SpasticityStage(level="random")
    host2 = _Host(None, None, seed=5)
    for level in seen:
        again.reset(host2)
        assert again.level == level
    fixed = SpasticityStage(level=2, subject_noise=False)
    fixed.reset(host)
    assert fixed.subject == LEVELS[2]
    fixed.set_level(1)
    fixed.reset(host)
    assert (fixed.level, fixed.subject) == (1, LEVELS[1])


def test_stage_in_simulation_raises_only_the_spastic_muscles(walk_env_factory) -> None:
    """The paper's reading ("uniform", no delay): every spastic muscle gets SC_total of the
    present knee state; no other actuator is touched."""
    env = walk_env_factory(level=3, reflex="uniform")
    host = env.unwrapped
    model = host.model
    assert host.ctrl_stages[-1] == "spasticity"
    env.reset(seed=0)
    stage = env.spasticity
    assert stage.subject != LEVELS[3]  # an individual subject was drawn at reset
    ids = np.array([model.actuator(n).id for n in SPASTIC_MUSCLES])
    others = np.setdiff1d(np.arange(model.nu), ids)
    assert len(others) == model.nu - 11
    np.testing.assert_array_equal(stage.actuator_ids, ids)
    knee = model.joint("knee_angle_r")
    rng = np.random.default_rng(0)
    for step in range(5):
        action = rng.uniform(0.0, 1.0, model.nu).astype(np.float32)
        action[ids[:3]] = 0.95  # these saturate at 1
        theta_deg = np.degrees(host.data.qpos[knee.qposadr[0]])
        vel = host.data.qvel[knee.dofadr[0]]
        expected_sc = sc_total(theta_deg, vel, stage.subject)
        env.step(action)
        assert stage.last_sc_total == pytest.approx(expected_sc, abs=1e-12), step
        assert expected_sc > 0.3
        ctrl = host.data.ctrl
        np.testing.assert_allclose(
            ctrl[ids], np.clip(action[ids].astype(np.float64) + expected_sc, 0.0, 1.0), atol=1e-12
        )
        assert np.all(ctrl[ids[:3]] == 1.0)
        np.testing.assert_array_equal(ctrl[others], action[others].astype(np.float64))
    env.close()


def test_level_zero_stage_changes_nothing(walk_env_factory) -> None:
    env = walk_env_factory(level=0)
    env.reset(seed=1)
    action = np.full(env.action_space.shape, 0.4, dtype=np.float32)
    env.step(action)
    assert env.spasticity.last_sc_total == 0.0
    np.testing.assert_allclose(env.unwrapped.data.ctrl, 0.4, atol=1e-7)
    env.close()


def test_wrapper_reproducible_and_picklable(walk_env_factory) -> None:
    a = walk_env_factory(level="random")
    b = walk_env_factory(level="random")
    a.reset(seed=11)
    b.reset(seed=11)
    assert (a.spasticity.level, a.spasticity.subject) == (b.spasticity.level, b.spasticity.subject)
    c = pickle.loads(pickle.dumps(a))
    assert c.unwrapped.ctrl_stages == ("spasticity",)
    assert c.spasticity.level_setting == "random"
    c.reset(seed=11)
    assert c.spasticity.subject == a.spasticity.subject
    for env in (a, b, c):
        env.close()


def test_stage_rejects_models_without_the_muscles() -> None:
    import mujoco

    xml = """<mujoco><worldbody><body><joint name="knee_angle_r" type="hinge"/>
    <geom size="0.1"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    with pytest.raises(ValueError, match="no actuators"):
        SpasticityStage(level=1).bind(model)
    with pytest.raises(ValueError, match="no joint 'knee_r'"):
        SpasticityStage(level=1, joint="knee_r").bind(model)
