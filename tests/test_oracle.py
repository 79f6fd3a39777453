"""The oracle (sampling-based MPC on a copy of the twin): the achievable bound."""

from __future__ import annotations

import numpy as np
import pytest

from myoexo.control import PID
from myoexo.control.oracle import OracleConfig, OracleMPC, parse_oracle_options
from myoexo.control.specs import build_controller, parse_controller_spec
from myoexo.envs import make_env
from myoexo.evaluation import run_episode

FAST = {"samples": 4, "horizon_s": 0.06, "replan": 3, "knots": 2}


def test_planning_leaves_the_env_untouched_and_is_deterministic():
    env = make_env(2, episode_duration_s=0.3)
    oracle = OracleMPC.from_env(env, **FAST)
    env.reset(seed=2)
    oracle.reset(2)
    base = env.unwrapped
    for _ in range(5):
        env.step(np.array([-1.0], np.float32))
    qpos, qvel, t = base.data.qpos.copy(), base.data.qvel.copy(), base.data.time
    delay = base.spasticity.history_state()
    u = oracle.act(None)
    assert -1.0 <= u[0] <= 1.0 and oracle.plans == 1
    np.testing.assert_array_equal(base.data.qpos, qpos)
    np.testing.assert_array_equal(base.data.qvel, qvel)
    assert base.data.time == t and base.spasticity.history_state() == delay
    a = run_episode(env, OracleMPC.from_env(env, **FAST), seed=5)
    b = run_episode(env, OracleMPC.from_env(env, **FAST), seed=5)
    np.testing.assert_array_equal(a.signals["knee_angle_deg"], b.signals["knee_angle_deg"])


def test_oracle_extends_at_least_as_far_as_the_pid_at_level_3():
    """At level 3 the PID saturates the motor; the oracle, planning on the true twin with
    its default horizon, cannot do worse than hold the full torque either (1.5-s episodes).
    The tests' cheap planner (a 60 ms horizon) is too myopic for this: it backs off once
    and ends 0.8 deg further than the PID on this subject."""
    env = make_env(3, episode_duration_s=1.5)
    oracle = run_episode(env, OracleMPC.from_env(env), seed=1)
    pid = run_episode(env, PID.from_env(env), seed=1)
    assert oracle.metrics.abs_final_error_deg <= pid.metrics.abs_final_error_deg + 0.5
    assert oracle.metrics.peak_exo_torque_nm == pytest.approx(100.0, abs=1.0)


def test_spec_and_options():
    spec = parse_controller_spec("oracle:samples=6,horizon_s=0.1")
    assert spec.kind == "oracle" and spec.options == {"samples": 6, "horizon_s": 0.1}
    env = make_env(0, episode_duration_s=0.2)
    ctrl = build_controller(spec, env)
    assert isinstance(ctrl, OracleMPC) and ctrl.config.samples == 6
    with pytest.raises(ValueError, match="unknown oracle option"):
        parse_oracle_options("speed=3")
    with pytest.raises(ValueError, match="samples"):
        OracleConfig(samples=1)
    with pytest.raises(ValueError, match="horizon_s"):
        OracleConfig(horizon_s=-1.0)


def test_distance_to_bound_uses_the_subjects_in_common():
    import pandas as pd

    from myoexo.evaluation.bound import bound_markdown, distance_to_bound

    def rows(ctrl, level, errors, peak):
        return [
            {
                "controller": ctrl,
                "level": level,
                "subject": i,
                "abs_final_error_deg": e,
                "peak_interaction_torque_nm": peak,
                "rms_interaction_torque_nm": peak / 2,
            }
            for i, e in enumerate(errors)
        ]

    table = pd.DataFrame(
        rows("pid", 2, [6.0, 8.0, 100.0], 180.0)  # subject 2: the oracle did not run it
        + rows("oracle", 2, [5.0, 5.0], 170.0)
    )
    d = distance_to_bound(table)
    assert len(d) == 1
    row = d.iloc[0]
    assert row.controller == "pid" and row.subjects == 2
    assert row.abs_final_error_deg == pytest.approx(7.0)
    assert row.distance_deg == pytest.approx(2.0)
    assert row.bound_peak_nm == pytest.approx(170.0)
    assert "distance (deg)" in bound_markdown(table)
    with pytest.raises(ValueError, match="no oracle"):
        distance_to_bound(table[table.controller == "pid"])


# ------------------------------------------------------------------ torque-aware cost
def test_the_planner_reads_the_interaction_torque_as_the_env_reports_it():
    """The planner steps a twin of its own from the env's state with a planning copy of its
    reflex: the same commands give the env's interaction torque (within rounding)."""
    import mujoco

    from myoexo.envs.twin import Twin

    env = make_env(2, episode_duration_s=0.3)
    env.reset(seed=0)
    base = env.unwrapped
    data = mujoco.MjData(base.model)
    mujoco.mj_copyData(data, base.model, base.data)
    planner = Twin(
        base.model, base.spasticity.planning_copy(base.model, base.dt), base.dt, data=data
    )
    for k in range(20):
        command = -0.8 if k < 12 else 0.3
        _, _, _, _, info = env.step(np.array([command], np.float32))
        planner.step(command)
        assert planner.interaction_torque_nm == pytest.approx(
            info["interaction_torque_nm"], rel=1e-6
        )


def test_a_peak_penalty_lowers_the_peak_and_a_ramp_starts_the_reference_at_the_knee():
    env = make_env(2, episode_duration_s=0.4)
    plain = run_episode(env, OracleMPC.from_env(env, **FAST), seed=3)
    capped = run_episode(env, OracleMPC.from_env(env, **FAST, peak_weight=30.0), seed=3)
    assert (
        capped.metrics.peak_interaction_torque_nm < plain.metrics.peak_interaction_torque_nm - 1.0
    )
    oracle = OracleMPC.from_env(env, **FAST, ramp_s=1.0)
    env.reset(seed=3)
    oracle.reset(3)
    oracle.act(None)
    start = oracle._start_rad
    assert start == pytest.approx(env.unwrapped.twin.knee_angle_rad)
    assert oracle._reference_rad(0.0) == pytest.approx(start)
    assert oracle._reference_rad(0.5) == pytest.approx(0.5 * (start + oracle._target_rad))
    assert oracle._reference_rad(2.0) == oracle._target_rad
    for bad in ({"peak_weight": -1.0}, {"interaction_weight": float("nan")}, {"ramp_s": 100.0}):
        with pytest.raises(ValueError, match=next(iter(bad))):
            OracleConfig(**bad)


def test_frontier_oracle_specs_parse():
    from myoexo.studies.frontier import CHEAP_ORACLE, oracle_specs

    specs = oracle_specs()
    assert specs[0] == f"oracle:{CHEAP_ORACLE}"
    for text in specs:
        spec = parse_controller_spec(text)
        assert spec.kind == "oracle" and spec.options["samples"] == 8
