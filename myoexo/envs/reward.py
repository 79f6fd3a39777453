"""The MyoExoKnee reward (docs/reference.md section 3) as a pure function of two
consecutive states: no MuJoCo, no env.

MyoSuite ``rwd_dict`` convention: penalties are magnitudes that enter with negative weights,
``dense`` is the weighted sum of the ``weighted_reward_keys``
(:data:`~myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`) minus ``gentleness x gentle``: an env
built with a gentleness weight (``gentleness=`` of the env, in [0, 1]) prices the
interaction torque's peak and its square by that weight, the trade-off between speed and
interaction torque a clinician sets per patient (0: the study's reward). Each term is
defined once, in :data:`REWARD_TERMS` (its formula, in terms of
:class:`~myoexo.envs.config.RewardParams`); the documentation site's environment page
(``docs/envs.md``) shows them as a table with their default weights.

The differences are against the previous control step; the first step of an episode
differences against the reset state (command 0, the reset's torque, knee at rest).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, NamedTuple

from myoexo.envs.config import RewardParams


class RewardTerm(NamedTuple):
    """One entry of ``rwd_dict``: its key and its formula, with ``{field}`` placeholders
    for the :class:`~myoexo.envs.config.RewardParams` fields it depends on (e = knee -
    target, rad; tau: the interaction torque; u: the clipped motor command; d: the change
    since the previous control step)."""

    key: str
    formula: str

    def describe(self, params: RewardParams | None = None) -> str:
        """The formula with *params*' values (default: ``RewardParams()``)."""
        values = dataclasses.asdict(params if params is not None else RewardParams())
        return self.formula.format(**values)


#: Every entry of ``rwd_dict`` but ``dense``, in the order :func:`reward_dict` returns them;
#: the weighted ones are the keys of :data:`~myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`.
REWARD_TERMS: tuple[RewardTerm, ...] = (
    RewardTerm("pose", "exp(-e^2 / (2 sigma^2)) - |e|, sigma = {sigma_rad:g} rad"),
    RewardTerm(
        "bonus",
        "{bonus:g} while |e| < {bonus_error_rad:g} rad and |knee vel| < {bonus_vel_rad_s:g} "
        "rad/s, else 0",
    ),
    RewardTerm(
        "inter",
        "(d tau / {torque_scale_nm:g} Nm)^2, plus (tau / {torque_scale_nm:g} Nm)^2 while "
        "tau > {torque_threshold_nm:g} Nm; tau = |strap torque on the knee| "
        "(the env's interaction_torque_nm)",
    ),
    RewardTerm(
        "gentle",
        "{gentle_peak_weight:g} x max(0, tau - peak) / {torque_scale_nm:g} Nm + "
        "{gentle_torque_weight:g} x (tau / {torque_scale_nm:g} Nm)^2; peak = the episode's "
        "largest tau before this step; enters dense as -gentleness x gentle",
    ),
    RewardTerm("vel", "|d knee vel| (rad/s)"),
    RewardTerm("act", "(d u)^2"),
    RewardTerm("sparse", "-|e|"),
    RewardTerm("solved", "|e| < {bonus_error_rad:g} rad"),
    RewardTerm("done", "False: the task has no terminal state (episodes end by truncation)"),
)


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
    gentleness: float = 0.0,
    peak_torque_nm: float = math.inf,
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
        gentleness: Weight of the ``gentle`` term in ``dense`` (0: the study's reward).
        peak_torque_nm: The episode's largest interaction torque before this step (Nm;
            the default, infinity, prices no rise).

    Returns:
        ``pose``, ``bonus``, ``inter``, ``gentle``, ``vel``, ``act``, ``sparse``,
        ``solved``, ``done`` and ``dense``.
    """
    p = params
    e = error_rad
    tau = interaction_torque_nm
    d_tau = (tau - prev_interaction_torque_nm) / p.torque_scale_nm
    inter = d_tau * d_tau
    if tau > p.torque_threshold_nm:
        inter += (tau / p.torque_scale_nm) ** 2
    abs_e = abs(e)
    scaled = tau / p.torque_scale_nm
    gentle = p.gentle_torque_weight * scaled * scaled
    if tau > peak_torque_nm:
        gentle += p.gentle_peak_weight * (tau - peak_torque_nm) / p.torque_scale_nm
    rwd: dict[str, Any] = {
        "pose": math.exp(-e * e / (2.0 * p.sigma_rad**2)) - abs_e,
        "bonus": p.bonus
        if abs_e < p.bonus_error_rad and abs(knee_vel_rad_s) < p.bonus_vel_rad_s
        else 0.0,
        "inter": inter,
        "gentle": gentle,
        "vel": abs(knee_vel_rad_s - prev_knee_vel_rad_s),
        "act": (command - prev_command) ** 2,
        "sparse": -abs_e,
        "solved": abs_e < p.bonus_error_rad,
        "done": False,
    }
    dense = 0.0
    for key, weight in weights.items():
        dense += weight * rwd[key]
    if gentleness:
        dense -= gentleness * gentle
    rwd["dense"] = dense
    return rwd


def torque_cost(rwd: Mapping[str, Any], weights: Mapping[str, float], gentleness: float) -> float:
    """What one step's interaction-torque terms took from its ``dense`` reward (a
    :func:`reward_dict` result, or a step's ``info``, which carries its terms):
    ``gentleness x gentle - w_inter x inter``, *weights* the ``weighted_reward_keys``."""
    return gentleness * rwd["gentle"] - weights.get("inter", 0.0) * rwd["inter"]
