"""The MyoExoKnee reward (docs/reference.md section 3) as a pure function of two
consecutive states: no MuJoCo, no env.

Terms (MyoSuite ``rwd_dict`` convention: penalties are magnitudes that enter with negative
weights, ``dense`` is the weighted sum of the ``weighted_reward_keys``):

* ``pose`` = exp(-e^2 / (2 sigma^2)) - |e|, e = knee - target (rad);
* ``bonus`` = ``params.bonus`` while |e| < ``bonus_error_rad`` and |knee vel| <
  ``bonus_vel_rad_s``;
* ``inter`` = (d tau / tau_scale)^2, plus (tau / tau_scale)^2 while tau >
  ``torque_threshold_nm`` (tau: the interaction torque, ``|exo| + |muscle knee torque|``);
* ``vel`` = |d knee vel|; ``act`` = (d u)^2 (u: the clipped motor command);
* ``sparse`` = -|e|, ``solved`` = |e| < ``bonus_error_rad``, ``done`` = False (the task has
  no terminal state).

The differences are against the previous control step; the first step of an episode
differences against the reset state (command 0, the reset's torque, knee at rest).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

from myoexo.envs.config import RewardParams


def reward_dict(
    error_rad: float,
    knee_vel_rad_s: float,
    interaction_torque_nm: float,
    command: float,
    prev_command: float,
    prev_knee_vel_rad_s: float,
    prev_interaction_torque_nm: float,
    params: RewardParams,
    weights: Mapping[str, float],
) -> dict[str, Any]:
    """The reward terms of one control step and their weighted sum ``"dense"``.

    Args:
        error_rad: Knee minus target flexion after the step (rad).
        knee_vel_rad_s: Knee flexion velocity after the step (rad/s).
        interaction_torque_nm: Interaction torque of the step (Nm, >= 0).
        command: The step's (clipped) motor command.
        prev_command: The previous step's command (0 after a reset).
        prev_knee_vel_rad_s: The previous step's knee velocity (the reset's after a reset).
        prev_interaction_torque_nm: The previous step's interaction torque (the reset's).
        params: Shape of the terms.
        weights: ``weighted_reward_keys``: key of the returned dict -> weight (summed in
            this order).

    Returns:
        ``pose``, ``bonus``, ``inter``, ``vel``, ``act``, ``sparse``, ``solved``, ``done``
        and ``dense``.
    """
    p = params
    e = error_rad
    tau = interaction_torque_nm
    d_tau = (tau - prev_interaction_torque_nm) / p.torque_scale_nm
    inter = d_tau * d_tau
    if tau > p.torque_threshold_nm:
        inter += (tau / p.torque_scale_nm) ** 2
    abs_e = abs(e)
    rwd: dict[str, Any] = {
        "pose": math.exp(-e * e / (2.0 * p.sigma_rad**2)) - abs_e,
        "bonus": p.bonus
        if abs_e < p.bonus_error_rad and abs(knee_vel_rad_s) < p.bonus_vel_rad_s
        else 0.0,
        "inter": inter,
        "vel": abs(knee_vel_rad_s - prev_knee_vel_rad_s),
        "act": (command - prev_command) ** 2,
        "sparse": -abs_e,
        "solved": abs_e < p.bonus_error_rad,
        "done": False,
    }
    dense = 0.0
    for key, weight in weights.items():
        dense += weight * rwd[key]
    rwd["dense"] = dense
    return rwd
