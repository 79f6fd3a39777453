"""Task and reward parameters of the MyoExoKnee environments (docs/reference.md section 3).

Everything the task needs is a frozen dataclass with the paper's values (or, where the paper
is silent, the project's documented choice) as defaults. The env constructor takes them as
keyword arguments, so ``gymnasium.make("MyoExoKnee-v1", task=TaskParams(target_angle_deg=10))``
changes the task without touching code.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

#: Weighted reward terms and their default weights (MyoSuite ``weighted_reward_keys``
#: convention: the dense reward is the weighted sum of these keys of ``rwd_dict``; penalties
#: are returned as positive magnitudes and enter with negative weights). The terms
#: themselves: :data:`myoexo.envs.reward.REWARD_TERMS`.
DEFAULT_REWARD_WEIGHTS: dict[str, float] = {
    "pose": 1.0,
    "bonus": 1.0,
    "inter": -1.0,
    "vel": -0.05,
    "act": -0.5,
}


@dataclass(frozen=True)
class TaskParams:
    """The knee-extension task.

    Attributes:
        start_angle_deg: Initial human knee flexion (paper: 90 deg).
        start_angle_noise_deg: Half-width of the uniform, seeded perturbation of the start angle.
        target_angle_deg: Target knee flexion (paper: 7 deg, i.e. 83 deg of extension).
        episode_duration_s: Simulated time per episode (paper's plots: 8 s).
        control_period_s: Time between two actions. 10 ms (100 Hz): the PID at the paper's
            gains (Kp = 7 /rad -> 700 Nm/rad on a shank of ~0.4 kg m^2, ~7 Hz closed loop)
            is stable and well resolved, MyoSuite's muscle activation (10-40 ms) is
            resolved, and an episode is 800 decisions, short enough for SAC credit
            assignment. Must be a whole multiple of the physics timestep.
    """

    start_angle_deg: float = 90.0
    start_angle_noise_deg: float = 2.0
    target_angle_deg: float = 7.0
    episode_duration_s: float = 8.0
    control_period_s: float = 0.01

    def __post_init__(self) -> None:
        _check_range("start_angle_deg", self.start_angle_deg, -15.0, 95.0)
        _check_range("start_angle_noise_deg", self.start_angle_noise_deg, 0.0, 10.0)
        _check_range("target_angle_deg", self.target_angle_deg, -15.0, 95.0)
        _check_range("episode_duration_s", self.episode_duration_s, 1e-3, 3600.0)
        _check_range("control_period_s", self.control_period_s, 1e-4, 0.1)

    @property
    def episode_steps(self) -> int:
        """Number of control steps per episode."""
        return round(self.episode_duration_s / self.control_period_s)


@dataclass(frozen=True)
class RewardParams:
    """Shape of the paper's four reward terms (docs/reference.md section 3).

    Attributes:
        sigma_rad: Width of the pose kernel exp(-e^2 / (2 sigma^2)). The paper gives no value;
            0.1 rad (5.7 deg) makes the kernel informative over the last ~20 deg of the motion
            while the -|e| term keeps a gradient over the whole 83 deg.
        bonus: Bonus per step while the knee is held at the target.
        bonus_error_rad: Error bound of the bonus (paper: 0.05 rad).
        bonus_vel_rad_s: Knee-speed bound of the bonus (paper: 0.05 rad/s).
        torque_threshold_nm: Interaction torque above which the quadratic penalty starts
            (paper: 75 Nm).
        torque_scale_nm: Normalization of the interaction-torque terms (the motor limit).
        weights: ``weighted_reward_keys``: reward key -> weight.
    """

    sigma_rad: float = 0.1
    bonus: float = 0.01
    bonus_error_rad: float = 0.05
    bonus_vel_rad_s: float = 0.05
    torque_threshold_nm: float = 75.0
    torque_scale_nm: float = 100.0
    weights: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_REWARD_WEIGHTS))

    def __post_init__(self) -> None:
        _check_range("sigma_rad", self.sigma_rad, 1e-6, math.pi)
        _check_range("bonus_error_rad", self.bonus_error_rad, 0.0, math.pi)
        _check_range("bonus_vel_rad_s", self.bonus_vel_rad_s, 0.0, 100.0)
        _check_range("torque_threshold_nm", self.torque_threshold_nm, 0.0, 1e4)
        _check_range("torque_scale_nm", self.torque_scale_nm, 1e-6, 1e4)
        unknown = set(self.weights) - set(DEFAULT_REWARD_WEIGHTS)
        if unknown:
            raise ValueError(
                f"RewardParams.weights has unknown keys {sorted(unknown)}; "
                f"accepted keys: {sorted(DEFAULT_REWARD_WEIGHTS)}"
            )


def _check_range(name: str, value: float, low: float, high: float) -> None:
    if not (math.isfinite(value) and low <= value <= high):
        raise ValueError(f"{name} = {value!r} is outside the accepted range [{low}, {high}]")
