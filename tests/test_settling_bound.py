"""``myoexo twin settling-bound``: the brake-pulse command, the per-subject search and its
summary."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from myoexo.studies.settling_bound import (
    PUSH_COMMAND,
    BrakePulse,
    SettlingBoundSettings,
    search_subject,
    summary,
)


def _commands(controller: BrakePulse, steps: int) -> list[float]:
    controller.reset(0)
    obs = np.zeros(1, np.float32)
    return [float(controller.act(obs)[0]) for _ in range(steps)]


def test_the_pulse_interrupts_a_push_that_rises_over_its_rise_time():
    u = _commands(BrakePulse(0.03, 0.05, 0.02, 0.5, dt=0.01), 9)
    assert u[:3] == pytest.approx([-1 / 3, -2 / 3, -1.0])
    assert u[3:5] == [-1.0, -1.0]
    assert u[5:7] == [0.5, 0.5]  # the pulse: steps 5-6
    assert u[7:] == [-1.0, -1.0]
    assert _commands(BrakePulse(0.0, 0.0, 0.0, PUSH_COMMAND, dt=0.01), 4) == [-1.0] * 4
    with pytest.raises(ValueError, match="outside"):
        BrakePulse(0.0, 0.1, 0.1, 1.5, dt=0.01)


def test_the_candidates_hold_the_constant_push_first_and_once_per_rise():
    settings = SettlingBoundSettings(
        rise_s=(0.0, 0.1), brake_start_s=(0.1, 0.2), brake_duration_s=(0.02,), brake_command=(0.0,)
    )
    candidates = settings.candidates()
    assert candidates[0] == (0.0, 0.0, 0.0, PUSH_COMMAND)
    assert len(candidates) == 2 * (1 + 2)  # per rise: no pulse, two pulses
    assert len(set(candidates)) == len(candidates)


def test_the_evaluation_root_is_refused():
    with pytest.raises(ValueError, match="evaluation root"):
        SettlingBoundSettings(root_seed=0)


def test_a_subject_search_keeps_the_soonest_qualifying_commands():
    settings = SettlingBoundSettings(
        subjects=1,
        levels=(2,),
        rise_s=(0.1,),
        brake_start_s=(0.15, 0.3),
        brake_duration_s=(0.02,),
        brake_command=(0.0,),
        workers=1,
    )
    row = search_subject(settings, 2, 0)
    assert row["candidates"] == len(settings.candidates()) == 6
    tol = settings.error_tolerance_deg
    # the constant push ends where the PID does: the muscles' hold at the motor's limit
    assert row["push_abs_final_error_deg"] == pytest.approx(row["pid_abs_final_error_deg"], abs=tol)
    # the push qualifies, so the fastest settles no later than it
    assert row["fastest_settling_time_s"] <= row["push_settling_time_s"]
    assert row["fastest_abs_final_error_deg"] <= row["pid_abs_final_error_deg"] + tol
    if math.isfinite(row["gentler_settling_time_s"]):
        assert row["gentler_peak_interaction_torque_nm"] <= row["pid_peak_interaction_torque_nm"]
        assert row["gentler_rms_interaction_torque_nm"] <= row["pid_rms_interaction_torque_nm"]
        assert row["gentler_settling_time_s"] >= row["fastest_settling_time_s"]
    table = summary(pd.DataFrame([row]))
    assert list(table.command) == ["pid", "push", "fastest", "gentler"]
    fastest = table[table.command == "fastest"].iloc[0]
    assert fastest.pid_settling_time_s == pytest.approx(row["pid_settling_time_s"])
    assert fastest.sooner_than_pid == int(
        row["fastest_settling_time_s"] < row["pid_settling_time_s"]
    )
