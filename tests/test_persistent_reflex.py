"""Tests of the ``"persistent"`` reflex model (myoexo.spasticity.reflex, its stage and the
oracle's planning copy): the after-discharge ignites at fast extension only, decays slowly,
agrees with its torch twin, is saved and restored with the stage's history, is cleared at
reset, leaves the other models' trajectories and random streams untouched, and rejects bad
parameters."""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType

import numpy as np
import pytest
import torch

from myoexo.spasticity.levels import sample_subject
from myoexo.spasticity.reflex import (
    DEFAULT_REFLEX,
    PERSISTENT,
    PersistentParams,
    PersistentReflex,
    persistent_step,
    persistent_step_torch,
)
from myoexo.spasticity.registry import get_reflex, reflex_names
from myoexo.spasticity.stage import SpasticityStage

DT = 0.01
#: Level 1's Table I velocity window, rad/s: the default ignition speed of its subjects.
WINDOW = 1.0


def _run(params: PersistentParams, vel: float, steps: int, r0: float = 0.0) -> float:
    a_rise, a_decay = params.rates(DT)
    r = r0
    for _ in range(steps):
        r = float(persistent_step(r, vel, a_rise, a_decay, params, WINDOW))
    return r


def test_presets_list_the_persistent_model_and_the_default_is_spindle_tone() -> None:
    assert "persistent" in reflex_names()
    assert DEFAULT_REFLEX == "spindle_tone"
    assert SpasticityStage().reflex_name == "spindle_tone"
    cfg = get_reflex("persistent")
    assert isinstance(cfg, PersistentReflex)
    assert cfg.after_discharge.gain(0) == 0.0
    assert (
        0.0
        < cfg.after_discharge.gain(1)
        < cfg.after_discharge.gain(2)
        <= cfg.after_discharge.gain(3)
    )


def test_after_discharge_rises_fast_at_fast_extension_and_decays_slowly() -> None:
    p = PERSISTENT
    assert (p.rise_time_s, p.decay_time_s) == (0.2, 2.0)  # onset and decay in seconds
    r = _run(p, -3.0, 80)  # 0.8 s of a 3 rad/s extension: four rise time constants
    assert r > 0.95
    held = _run(p, 0.0, 100, r0=r)  # then 1 s at rest: it decays with the 2 s constant
    gate_at_rest = 0.5 * (1.0 + math.tanh(0.5 * 8.0 / WINDOW * (0.0 - WINDOW)))
    assert held == pytest.approx(r * math.exp(-1.0 / p.decay_time_s), rel=0.05)
    assert 0.5 < held < 0.7 and gate_at_rest < 0.02
    assert _run(p, 0.0, 600, r0=r) < 0.06  # 6 s later it is nearly gone: no latch
    assert _run(p, 2.0, 100, r0=r) < r  # flexion (the flexors shorten) never ignites it


def test_the_ignition_comes_from_the_subjects_velocity_window() -> None:
    p = PERSISTENT
    for window in (1.0, 0.5, 0.25):  # Table I's windows at levels 1-3
        v_ig, slope = p.ignition(window)
        assert v_ig == window and slope == pytest.approx(8.0 / window)
    with pytest.raises(ValueError, match="window_rad_s = None"):
        p.ignition(None)
    # a smooth gate: at the threshold half on, a quarter window either side 12 % / 88 %
    gains = [float(persistent_step(0.0, -v, 1.0, 0.0, p, WINDOW)) for v in (0.75, 1.0, 1.25)]
    assert gains == pytest.approx([0.119, 0.5, 0.881], abs=2e-3)


@pytest.mark.parametrize("vel", [0.0, -0.1, -0.2, 1.0, 4.0])
def test_after_discharge_stays_low_well_below_the_ignition_speed(vel: float) -> None:
    """A slow stretch (a fifth of level 1's 1 rad/s window or less) for 5 s leaves r below
    5 % (the smooth gate is under 4 % there and the decay pulls it back)."""
    assert _run(PERSISTENT, vel, 500) < 0.05


def test_stage_adds_the_after_discharge_to_the_flexors_only_and_not_at_level_0() -> None:
    from myoexo.envs import make_env

    for level, expect_memory in ((0, False), (2, True)):
        env = make_env(level, reflex="persistent")
        env.reset(seed=3)
        base = env.unwrapped
        stage = base.spasticity
        stage.bind(base.model, base.dt)
        d = base.data
        d.qvel[stage._dof_adr] = -3.0  # a fast extension, held for the test
        ctrl = np.zeros(base.model.nu)
        for _ in range(80):  # 0.8 s: four rise time constants
            out = stage.apply(base, ctrl.copy())
        flex = out[stage.actuator_ids[: len(stage.flexors)]]
        ext = out[stage.actuator_ids[len(stage.flexors) :]]
        sc = stage.sc_now(math.degrees(d.qpos[stage._qpos_adr]), -3.0)
        if expect_memory:
            assert stage.memory[0] > 0.95
            assert stage.constants.gain > 0.0
            np.testing.assert_allclose(flex, min(1.0, sc + stage.constants.gain * stage.memory[0]))
            np.testing.assert_allclose(ext, min(1.0, sc))
        else:
            assert stage.constants.gain == 0.0
            np.testing.assert_allclose(flex, min(1.0, sc))
            np.testing.assert_allclose(ext, min(1.0, sc))
        env.close()


def test_torch_twin_agrees_and_differentiates() -> None:
    p = PERSISTENT
    a_rise, a_decay = p.rates(DT)
    r = np.linspace(0.0, 1.0, 11)[:, None]
    v = np.linspace(-4.0, 2.0, 25)[None, :]
    ref = persistent_step(r, v, a_rise, a_decay, p, WINDOW)
    got = persistent_step_torch(
        torch.as_tensor(r, dtype=torch.float64),
        torch.as_tensor(v, dtype=torch.float64),
        DT,
        p,
        WINDOW,
    )
    np.testing.assert_allclose(got.numpy(), ref, rtol=1e-12, atol=1e-14)

    v_ig, slope = p.ignition(WINDOW)
    params = {
        "ignition_velocity_rad_s": torch.tensor(v_ig, dtype=torch.float64),
        "ignition_slope_per_rad_s": torch.tensor(slope, dtype=torch.float64),
        "rise_time_s": torch.tensor(p.rise_time_s, dtype=torch.float64),
        "decay_time_s": torch.tensor(p.decay_time_s, dtype=torch.float64),
    }
    r_t = torch.tensor([0.2, 0.7], dtype=torch.float64, requires_grad=True)
    v_t = torch.tensor([-1.02, -0.95], dtype=torch.float64, requires_grad=True)
    tau = torch.tensor(p.rise_time_s, dtype=torch.float64, requires_grad=True)

    def f(r_: torch.Tensor, v_: torch.Tensor, tau_: torch.Tensor) -> torch.Tensor:
        return persistent_step_torch(r_, v_, DT, {**params, "rise_time_s": tau_})

    assert torch.autograd.gradcheck(f, (r_t, v_t, tau))
    out = f(r_t, v_t, tau).sum()
    out.backward()
    assert v_t.grad is not None and bool((v_t.grad < 0).all())  # faster extension: more r
    # the torch step rolled over a motion matches the stage's scalar update
    r_np, r_torch = 0.0, torch.tensor(0.0, dtype=torch.float64)
    for vel in [-0.5, -2.0, -3.5, -3.5, -1.0, 0.0, 0.5]:
        r_np = float(persistent_step(r_np, vel, a_rise, a_decay, p, WINDOW))
        r_torch = persistent_step_torch(
            r_torch, torch.tensor(vel, dtype=torch.float64), DT, p, WINDOW
        )
    assert float(r_torch) == pytest.approx(r_np, rel=1e-12)


def test_history_state_is_saved_and_restored_by_the_planning_copy_and_reset_clears_it() -> None:
    from myoexo.envs import make_env

    env = make_env(2, reflex="persistent")
    env.reset(seed=5)
    base = env.unwrapped
    stage = base.spasticity
    stage.bind(base.model, base.dt)
    base.data.qvel[stage._dof_adr] = -3.0
    ctrl = np.zeros(base.model.nu)
    for _ in range(20):
        stage.apply(base, ctrl.copy())
    saved = stage.history_state()
    r = stage.memory[0]
    assert 0.3 < r < 1.0 and saved[1] == (r,)

    twin = stage.planning_copy(base.model, base.dt)
    import mujoco

    from myoexo.spasticity.stage import StageHost

    host = StageHost(base.model, mujoco.MjData(base.model), base.dt)
    twin.set_history_state(saved)
    assert twin.memory[0] == r
    host.data.qvel[:] = base.data.qvel
    host.data.qpos[:] = base.data.qpos
    for _ in range(10):
        twin.apply(host, ctrl.copy())
    assert twin.memory[0] > r  # ran ahead on its own copy
    assert stage.memory[0] == r and stage.history_state() == saved  # untouched
    twin.set_history_state(saved)
    assert twin.history_state() == saved

    env.reset(seed=5)
    assert stage.memory[0] == 0.0 and stage.history_state()[1] == (0.0,)
    env.close()


def test_the_oracle_plans_on_the_after_discharge_without_touching_the_env() -> None:
    from myoexo.control.oracle import OracleMPC
    from myoexo.envs import make_env
    from myoexo.envs.sensors import read_sensors

    env = make_env(2, reflex="persistent")
    obs, info = env.reset(seed=1)
    stage = env.unwrapped.spasticity
    stage.memory = (0.6,)  # a lasting after-discharge the planner must see
    saved = stage.history_state()
    oracle = OracleMPC.from_env(env, samples=3, horizon_s=0.05)
    oracle.act(obs, read_sensors(info))
    assert stage.history_state() == saved
    env.close()


def test_reset_draws_the_gain_without_advancing_the_envs_stream() -> None:
    """The persistent model draws its gain's noise from a child of the env's generator: the
    subject and everything after it (the start angle) are those of the uniform model."""
    from myoexo.spasticity.stage import StageHost

    rng_states = {}
    subjects = {}
    gains = []
    for reflex in ("uniform", "persistent", "stretch"):
        stage = SpasticityStage(level=2, reflex=reflex)
        host = StageHost(None, None, DT, seed=11)
        stage.reset(host)
        rng_states[reflex] = host.np_random.bit_generator.state
        subjects[reflex] = stage.subject
        gains.append(getattr(stage.constants, "gain", 0.0))  # only "persistent" has one
    assert rng_states["uniform"] == rng_states["persistent"] == rng_states["stretch"]
    assert subjects["uniform"] == subjects["persistent"]
    assert subjects["persistent"] == sample_subject(2, np.random.default_rng(11))
    g = gains[1]
    assert g != PERSISTENT.gain(2) and abs(g / PERSISTENT.gain(2) - 1.0) < 0.5
    assert gains[0] == gains[2] == 0.0


def test_zero_gains_give_the_uniform_trajectory_and_other_models_have_no_memory() -> None:
    from myoexo.control import PID
    from myoexo.control.rollout import rollout
    from myoexo.envs import make_env

    zero = dataclasses.replace(
        get_reflex("persistent"),
        after_discharge=dataclasses.replace(
            PERSISTENT, gains=MappingProxyType({lv: 0.0 for lv in range(4)})
        ),
    )
    runs = {}
    for name, reflex in (("uniform", "uniform"), ("zero", zero)):
        env = make_env(3, reflex=reflex)
        ep = rollout(env, PID.from_env(env), seed=7, until_s=2.0)
        runs[name] = ep.signals["knee_angle_deg"]
        env.close()
    assert np.array_equal(runs["uniform"], runs["zero"])
    for reflex in ("stretch", "uniform"):
        env = make_env(2, reflex=reflex)
        rollout(env, PID.from_env(env), seed=7, until_s=1.0)
        assert env.unwrapped.spasticity.memory == ()  # no memory
        env.close()


def test_the_pids_fast_extension_ignites_the_after_discharge_and_it_fades() -> None:
    """Level 2: the paper's PID extends far faster than the 0.5 rad/s window and ignites the
    after-discharge; with a decay of seconds it fades while the knee is held, so the PID
    still ends at the target at 8 s (the reason the model is not fitted to the study's
    stall, docs/reference.md section 11)."""
    from myoexo.control import PID
    from myoexo.control.rollout import rollout
    from myoexo.envs import make_env
    from myoexo.studies.calibrate import pid_outcome

    env = make_env(2, reflex="persistent")
    rollout(env, PID.from_env(env), seed=7, until_s=0.6)
    ignited = env.unwrapped.spasticity.memory[0]
    rollout(env, PID.from_env(env), seed=7)
    faded = env.unwrapped.spasticity.memory[0]
    env.close()
    assert ignited > 0.5 and faded < 0.1 * ignited
    assert abs(pid_outcome(2, get_reflex("persistent"), 3).final_error_deg) < 1.0


def test_hold_test_separates_memory_from_no_memory() -> None:
    from myoexo.clinical.hold import StretchHoldParams, run_stretch_hold

    params = StretchHoldParams(levels=(0, 2), hold_s=1.5)
    stretch = run_stretch_hold(params, reflex="stretch").table().set_index("level")
    persistent = run_stretch_hold(params, reflex="persistent").table().set_index("level")
    assert abs(stretch.loc[2, "hold_excess_late_nm"]) < 1.0
    assert abs(persistent.loc[0, "hold_excess_late_nm"]) < 1.0
    assert persistent.loc[2, "hold_excess_late_nm"] > 20.0


@pytest.mark.parametrize(
    ("field", "value", "match"),
    [
        ("ignition_velocity_rad_s", -1.0, r"ignition_velocity_rad_s = -1.0 is outside \[0.01, 20"),
        ("ignition_slope_per_rad_s", 0.0, r"ignition_slope_per_rad_s = 0.0 is outside \[1.0"),
        ("rise_time_s", 0.0, r"rise_time_s = 0.0 is outside \[0.001, 10.0\] s"),
        ("decay_time_s", math.inf, r"decay_time_s = inf is outside"),
        ("decay_time_s", float("nan"), r"decay_time_s = nan is outside"),
        ("gains", {2: 1.5}, r"gains\[2\] = 1.5 is outside \[0, 1\]"),
        ("gains", {0: 0.1}, r"gains\[0\] = 0.1 must be 0"),
        ("gains", {5: 0.1}, r"gains has level 5"),
    ],
)
def test_bad_parameters_raise(field: str, value: object, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        PersistentParams(**{field: value})
