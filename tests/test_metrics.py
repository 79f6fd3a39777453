"""Metric functions on synthetic signals with known answers."""

from __future__ import annotations

import math

import numpy as np
import pytest

from myoexo.evaluation import metrics as M

DT = 1e-3


def first_order(tau_s: float, y0: float, yf: float, t_end: float = 10.0):
    t = np.arange(0.0, t_end + DT / 2, DT)
    return t, yf + (y0 - yf) * np.exp(-t / tau_s)


def second_order(zeta: float, wn: float, t_end: float = 20.0):
    t = np.arange(0.0, t_end + DT / 2, DT)
    wd = wn * math.sqrt(1 - zeta**2)
    y = 1 - np.exp(-zeta * wn * t) * (
        np.cos(wd * t) + zeta / math.sqrt(1 - zeta**2) * np.sin(wd * t)
    )
    return t, y


@pytest.mark.parametrize(("y0", "yf"), [(0.0, 1.0), (90.0, 7.0)])
def test_first_order_settling_and_rise_time(y0, yf):
    tau = 0.4
    t, y = first_order(tau, y0, yf)
    # |y - yf| = |step| exp(-t/tau) <= 2 % |step|  <=>  t >= tau ln 50
    assert M.settling_time(t, y, 0.02, y_final=yf) == pytest.approx(tau * math.log(50), abs=DT)
    assert M.settling_time(t, y, 0.05, y_final=yf) == pytest.approx(tau * math.log(20), abs=DT)
    # 10 % -> 90 %: tau (ln 10 - ln 10/9) = tau ln 9
    assert M.rise_time(t, y, y_final=yf) == pytest.approx(tau * math.log(9), abs=2 * DT)
    assert M.overshoot_pct(y, y_final=yf) == pytest.approx(0.0, abs=1e-9)


def test_second_order_overshoot_matches_the_formula():
    zeta = 0.3
    t, y = second_order(zeta, wn=5.0)
    expected = 100 * math.exp(-zeta * math.pi / math.sqrt(1 - zeta**2))  # 37.2 %
    assert M.overshoot_pct(y, y_final=1.0) == pytest.approx(expected, rel=1e-3)
    # settling later than the 4 / (zeta wn) rule's ballpark and finite
    ts = M.settling_time(t, y, y_final=1.0)
    assert 2.0 < ts < 4.0


def test_settling_edge_cases():
    t = np.linspace(0, 1, 11)
    assert M.settling_time(t, np.ones(11), y_initial=0.0) == 0.0  # always in band
    y = np.r_[np.zeros(10), 1.0]  # leaves the band on the last sample
    assert math.isnan(M.settling_time(t, y, y_final=0.0, y_initial=-1.0))
    y = np.r_[np.linspace(10, 0, 6), np.zeros(5)]
    y[7] = np.nan  # NaN counts as outside the band
    assert M.settling_time(t, y, y_final=0.0) == pytest.approx(t[8])
    with pytest.raises(ValueError, match="threshold"):
        M.settling_time(t, y, threshold=2.0)
    with pytest.raises(ValueError, match="differ in length"):
        M.settling_time(t[:-1], y)
    with pytest.raises(ValueError, match="empty"):
        M.rms(np.array([]))


def test_rms_peak_variation_and_smoothness_of_a_sine():
    fs, f0, amp = 100.0, 2.5, 0.5
    t = np.arange(0, 4.0, 1 / fs)  # 10 whole periods, f0 on an FFT bin, peaks on samples
    u = amp * np.sin(2 * np.pi * f0 * t)
    assert M.rms(u) == pytest.approx(amp / math.sqrt(2), rel=1e-9)
    u_closed = np.r_[u, 0.0]  # with the end point: exactly 10 periods
    assert M.total_variation(u_closed) == pytest.approx(10 * 4 * amp, rel=1e-9)
    n_bins = t.size // 2 + 1
    assert M.spectral_smoothness(u, fs) == pytest.approx(2 * amp * f0 / (n_bins * fs), rel=1e-9)
    assert M.spectral_smoothness(np.full(50, 0.3), fs) == pytest.approx(0.0, abs=1e-12)
    # a faster command with the same amplitude is less smooth
    assert M.spectral_smoothness(amp * np.sin(2 * np.pi * 10 * t), fs) > M.spectral_smoothness(
        u, fs
    )


def test_episode_metrics_on_a_synthetic_extension():
    tau = 0.5
    t, knee = first_order(tau, 90.0, 8.0, t_end=8.0)  # stays 1 deg short of the 7 deg target
    ts_expected = tau * math.log(50)
    tau_nm = np.where(t <= ts_expected, 30.0, 5.0)  # 30 Nm until settled, 5 Nm after...
    tau_nm[-100] = 60.0  # ...with a late 60 Nm spike: the peak, not in the RMS
    exo = -tau_nm
    signals = {
        "time_s": t,
        "knee_angle_deg": knee,
        "target_angle_deg": np.full_like(t, 7.0),
        "command": exo / 100.0,
        "exo_torque_nm": exo,
        "interaction_torque_nm": tau_nm,
    }
    m = M.episode_metrics(signals)
    assert m.final_error_deg == pytest.approx(1.0, abs=1e-4)
    assert m.abs_final_error_deg == pytest.approx(1.0, abs=1e-4)
    assert m.target_overshoot_deg == 0.0
    assert m.settling_time_s == pytest.approx(ts_expected, abs=2 * DT)
    assert m.rms_interaction_torque_nm == pytest.approx(30.0, rel=2e-3)
    assert m.peak_interaction_torque_nm == 60.0
    assert m.peak_exo_torque_nm == 60.0
    # overshoot past the target is measured in degrees
    signals["knee_angle_deg"] = np.minimum(knee, 7.0) - 2.5 * np.exp(-((t - 1.0) ** 2) / 0.01)
    assert M.episode_metrics(signals).target_overshoot_deg == pytest.approx(2.5, abs=0.05)
    with pytest.raises(ValueError, match="missing signals"):
        M.episode_metrics({"time_s": t})


def test_the_hold_and_the_final_value_average_the_same_end_window():
    from myoexo.evaluation.bound import mean_over_end

    t = np.round(np.arange(0.0, 8.0 + 1e-9, 0.02), 10)  # the traces' 50-Hz samples
    y = np.random.default_rng(0).normal(size=(3, t.size))
    last = t >= 7.5 - 1e-9  # 26 samples: the one exactly 0.5 s before the end included
    assert last.sum() == 26
    np.testing.assert_allclose(mean_over_end(t, y, 0.5), y[:, last].mean(axis=1))
    for row in y:
        assert float(mean_over_end(t, row, 0.5)) == pytest.approx(M.final_value(t, row, 0.5))
    assert M.final_value(t, y[0], 0.0) == y[0, -1]
    with pytest.raises(ValueError, match="window_s"):
        mean_over_end(t, y, -0.1)


def test_the_final_swing_sees_a_limit_cycle_the_final_error_misses():
    """A knee circling the target at 4 Hz: the 0.1-s final error reads the phase the episode
    ends in (+-2.1 deg for cycles half a period apart), the final swing the cycle's
    peak-to-peak amplitude."""
    t = np.arange(0.0, 8.0 + DT / 2, DT)
    settled = 7.0 + 83.0 * np.exp(-t / 0.3)
    signals = {
        "time_s": t,
        "target_angle_deg": np.full_like(t, 7.0),
        "command": np.zeros_like(t),
        "exo_torque_nm": np.zeros_like(t),
        "interaction_torque_nm": np.zeros_like(t),
    }
    ends = []
    for phase in (0.0, np.pi):
        cycle = np.where(t > 5.0, 3.0 * np.sin(2 * np.pi * 4.0 * t + phase), 0.0)
        m = M.episode_metrics({**signals, "knee_angle_deg": settled + cycle})
        assert m.final_swing_deg == pytest.approx(6.0, abs=0.01)
        ends.append(m.final_error_deg)
    assert ends[0] == pytest.approx(-ends[1], abs=1e-3) and abs(ends[0]) > 2.0
    at_rest = {**signals, "knee_angle_deg": settled}
    assert M.episode_metrics(at_rest).final_swing_deg < 1e-6
    assert M.episode_metrics(at_rest, swing_window_s=8.0).final_swing_deg == pytest.approx(
        settled.max() - settled.min()
    )
