"""Task and reward parameters of the MyoExoKnee environments (docs/reference.md section 3).

Everything the task needs is a frozen dataclass with the paper's values (or, where the paper
is silent, the project's documented choice) as defaults. The env constructor takes them as
keyword arguments, one per field, so ``gymnasium.make("MyoExoKnee-v1", target_angle_deg=10)``
changes the task without touching code.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

from myoexo.runtime.fields import check_fields, option

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

    start_angle_deg: float = option(90.0, "initial knee flexion", low=-15.0, high=95.0, unit="deg")
    start_angle_noise_deg: float = option(
        2.0, "half-width of the seeded perturbation of the start angle", low=0.0, high=10.0,
        unit="deg",
    )  # fmt: skip
    target_angle_deg: float = option(7.0, "target knee flexion", low=-15.0, high=95.0, unit="deg")
    episode_duration_s: float = option(
        8.0, "simulated seconds per episode", low=1e-3, high=3600.0, unit="s"
    )
    control_period_s: float = option(0.01, "time between two actions", low=1e-4, high=0.1, unit="s")

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def episode_steps(self) -> int:
        """Number of control steps per episode."""
        return round(self.episode_duration_s / self.control_period_s)


#: Names of the :class:`TaskParams` fields: each is an env keyword argument of its own name.
TASK_FIELDS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(TaskParams))


#: The gentleness weight's range (the env's ``gentleness=``): 0 prices speed alone (the
#: study's reward), 1 prices the interaction torque's peak and square in full.
GENTLENESS_RANGE: tuple[float, float] = (0.0, 1.0)


def check_gentleness(value: object) -> float:
    """A gentleness weight as a float in :data:`GENTLENESS_RANGE`.

    Raises:
        ValueError: *value* is no number in the range (the message names it and the range).
    """
    low, high = GENTLENESS_RANGE
    try:
        weight = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        weight = math.nan
    if not (low <= weight <= high) or isinstance(value, bool):
        raise ValueError(
            f"gentleness = {value!r} is outside [{low:g}, {high:g}] (or 'random': drawn per reset)"
        )
    return weight


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
        gentle_peak_weight: The ``gentle`` term's price of the episode's peak interaction
            torque: each step that raises the running peak costs this times the rise over
            ``torque_scale_nm``, so an episode pays ``gentle_peak_weight x peak / scale``
            in all. 400 makes the peak of a fast extension (about 100 Nm) cost about what
            1.2 s of the 83 deg move costs in the ``pose`` term, so the gentleness range
            spans the study's fast policy (weight 0) to moves slower than a 3-s ramp
            (weight 1).
        gentle_torque_weight: The ``gentle`` term's price per step of the squared
            interaction torque over ``torque_scale_nm`` (the RMS measure).
        weights: ``weighted_reward_keys``: reward key -> weight.
    """

    sigma_rad: float = option(0.1, "width of the pose kernel", low=1e-6, high=math.pi, unit="rad")
    bonus: float = 0.01
    bonus_error_rad: float = option(0.05, "error bound of the bonus", low=0.0, high=math.pi)
    bonus_vel_rad_s: float = option(0.05, "knee-speed bound of the bonus", low=0.0, high=100.0)
    torque_threshold_nm: float = option(
        75.0, "interaction torque where the quadratic penalty starts", low=0.0, high=1e4
    )
    torque_scale_nm: float = option(
        100.0, "normalization of the interaction-torque terms", low=1e-6, high=1e4
    )
    gentle_peak_weight: float = option(
        400.0,
        "gentleness cost of each rise of the episode's peak interaction torque, per torque "
        "scale (the rises sum to the peak / torque scale)",
        low=0.0,
        high=1e6,
    )
    gentle_torque_weight: float = option(
        0.1, "gentleness cost per step of (interaction torque / torque scale)^2", low=0.0, high=1e6
    )
    weights: dict[str, float] = field(default_factory=lambda: dict(DEFAULT_REWARD_WEIGHTS))

    def __post_init__(self) -> None:
        check_fields(self)
        unknown = set(self.weights) - set(DEFAULT_REWARD_WEIGHTS)
        if unknown:
            raise ValueError(
                f"RewardParams.weights has unknown keys {sorted(unknown)}; "
                f"accepted keys: {sorted(DEFAULT_REWARD_WEIGHTS)}"
            )
