"""Tests of the simulated Tardieu stretch test (myoexo.clinical.stretch) and its figures."""

from __future__ import annotations

import argparse
import math

import numpy as np
import pytest

from myoexo.clinical.stretch import StretchTestParams, reference_profile, run_stretch_test

SLOW, FAST = 0.2, 3.0


def test_reference_profile_is_a_trapezoid_from_start_to_end() -> None:
    p = StretchTestParams(start_deg=90.0, end_deg=5.0, hold_s=0.3, accel_time_s=0.05)
    dt = 1e-4
    t = np.arange(0.0, 1.5, dt)
    angle, vel, phase = reference_profile(t, FAST, p)
    assert angle[0] == 90.0 and angle[-1] == pytest.approx(5.0, abs=1e-9)
    assert np.all(angle[t < p.hold_s] == 90.0) and np.all(vel[t < p.hold_s] == 0.0)
    assert np.all(np.diff(angle) <= 0)  # an extension: monotone
    np.testing.assert_allclose(vel[phase == 2], -FAST)
    assert set(np.unique(phase)) == {0, 1, 2, 3, 4}
    # the velocity is the derivative of the angle
    np.testing.assert_allclose(np.radians(np.gradient(angle, dt)), vel, atol=FAST * 0.01)
    # motion time = span / speed + accel time
    moving = t[(phase >= 1) & (phase <= 3)]
    assert moving[-1] - moving[0] == pytest.approx(math.radians(85.0) / FAST + 0.05, abs=2 * dt)
    # a flexion stretch mirrors it
    angle_f, vel_f, _ = reference_profile(t, SLOW, StretchTestParams(start_deg=5.0, end_deg=90.0))
    assert angle_f[0] == 5.0 and np.all(np.diff(angle_f) >= 0) and vel_f.max() == SLOW


def test_params_reject_bad_values() -> None:
    with pytest.raises(ValueError, match="levels"):
        StretchTestParams(levels=(0, 4))
    with pytest.raises(ValueError, match="velocities_rad_s"):
        StretchTestParams(velocities_rad_s=(0.2, -3.0))
    with pytest.raises(ValueError, match="start_deg and end_deg must differ"):
        StretchTestParams(start_deg=30.0, end_deg=30.0)
    with pytest.raises(ValueError, match="control_period_s"):
        StretchTestParams(control_period_s=0.0)
    with pytest.raises(ValueError, match="kp_nm_per_rad"):
        StretchTestParams(kp_nm_per_rad=float("nan"))


@pytest.fixture(scope="module", params=["stretch", "uniform"])
def reflex(request) -> str:
    """Both reflex models (myoexo.spasticity.reflex): the stretch reflex (default), the uniform."""
    return request.param


@pytest.fixture(scope="module")
def result(reflex):
    """The default stretch test (levels 0-3, 0.2 and 3 rad/s) on the twin."""
    return run_stretch_test(StretchTestParams(velocities_rad_s=(SLOW, FAST)), reflex=reflex)


def test_exo_imposes_the_stretch(result) -> None:
    s = result.summary.set_index(["level", "vel_rad_s"])
    # the stiff controller imposes the speed: the human knee follows within 30 % (the
    # PD lags by resisting torque / Kp and the soft straps add their compliance: measured
    # 2.51 rad/s for 3 rad/s at level 3 with the uniform reflex, 2.26-2.37 rad/s at levels
    # 1-3 with the stretch reflex, whose flexors resist the fast stretch harder)
    np.testing.assert_allclose(
        s["mean_knee_vel_rad_s"], s.index.get_level_values("vel_rad_s"), rtol=0.3
    )
    assert (s["max_tracking_error_deg"] < 15.0).all()
    assert (s["saturated_fraction"] == 0.0).all()
    tr = result.traces
    # the reflex is off at level 0 and on at the other levels
    assert (tr.loc[tr["level"] == 0, "sc_total"] == 0.0).all()
    assert (tr.loc[tr["level"] > 0, "sc_total"] > 0.1).all()


def test_resisting_torque_rises_with_level_and_speed(result, reflex) -> None:
    peaks = result.peak_table()
    fast = peaks[FAST].to_numpy()
    if reflex == "uniform":
        assert np.all(np.diff(fast) > 1.0), peaks  # L0 < L1 < L2 < L3 at the fast speed
    else:
        # every spastic level resists the fast stretch more than level 0; the levels are
        # not ordered among themselves: Table I's velocity slope k falls with the level
        # (0.5, 0.2, 0.1 s/rad), so the flexors' velocity term is most speed-selective at
        # level 1 (measured 72 Nm at level 1 against 64 and 68 Nm at levels 2-3)
        assert np.all(fast[1:] > fast[0] + 10.0), peaks
    for level in (1, 2, 3):  # velocity-dependent resistance: the hallmark of spasticity
        assert peaks.loc[level, FAST] > peaks.loc[level, SLOW], peaks
    means = result.summary.set_index(["level", "vel_rad_s"])["mean_resisting_torque_nm"]
    for level in (1, 2, 3):
        assert means[(level, FAST)] > means[(level, SLOW)]


def test_cli_and_figures(result, tmp_path, monkeypatch) -> None:
    from myoexo.clinical import figures as spasticity_plots
    from myoexo.clinical import stretch as stretch_test

    fig = spasticity_plots.plot_stretch_test(result)
    fig.savefig(tmp_path / "stretch.png")
    assert (tmp_path / "stretch.png").stat().st_size > 10_000
    # the CLI runs the same test; reuse the result instead of simulating again
    monkeypatch.setattr(stretch_test, "run_stretch_test", lambda *a, **k: result)
    parser = argparse.ArgumentParser()
    stretch_test.add_arguments(parser)
    assert stretch_test.run(parser.parse_args(["--out", str(tmp_path)])) == 0
    assert (tmp_path / "stretch_summary.csv").exists()


def test_plot_spasticity_writes_fig2b(tmp_path) -> None:
    from myoexo.clinical import figures as spasticity_plots

    parser = argparse.ArgumentParser()
    spasticity_plots.add_arguments(parser)
    args = parser.parse_args(["--out", str(tmp_path), "--subjects", "20", "--no-stretch"])
    assert spasticity_plots.run(args) == 0
    assert (tmp_path / "fig2b_spasticity.png").stat().st_size > 10_000


def test_muscle_knee_torque_follows_the_coupled_knee() -> None:
    """The muscles' knee torque equals force . dL/dtheta along Rajagopal's coupled knee.

    The quadriceps pull on the patella, whose coordinates are tied to the knee angle by
    joint equalities, so ``qfrc_actuator`` of ``knee_angle_r`` alone misstates their torque.
    """
    import mujoco

    from myoexo.model import TwinParams, build_model, pose_twin
    from myoexo.model.joint_torque import CoupledJointTorque
    from myoexo.spasticity.levels import SPASTIC_EXTENSORS

    model, _ = build_model(TwinParams())
    data = mujoco.MjData(model)
    torque = CoupledJointTorque(model, "knee_angle_r")
    ids = np.array([model.actuator(n).id for n in SPASTIC_EXTENSORS])
    muscles = np.flatnonzero(model.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE)
    knee_dof = model.joint("knee_angle_r").dofadr[0]
    h_deg = 1e-3
    for angle in (80.0, 45.0):
        lengths = []
        for a in (angle - h_deg, angle + h_deg):
            pose_twin(model, data, knee_angle_deg=a)
            lengths.append(data.actuator_length[muscles].copy())
        dl_dtheta = (lengths[1] - lengths[0]) / math.radians(2 * h_deg)
        pose_twin(model, data, knee_angle_deg=angle)
        data.act[model.actuator_actadr[ids]] = 1.0
        mujoco.mj_forward(model, data)
        expected = float(data.actuator_force[muscles] @ dl_dtheta)  # passive ones too
        assert expected < -50.0  # the quadriceps extend the knee
        assert torque(data) == pytest.approx(expected, rel=1e-3)
        assert abs(data.qfrc_actuator[knee_dof] - expected) > 0.1 * abs(expected)
