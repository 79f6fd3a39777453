"""The reward's values: every term recomputed by hand from the observations of consecutive
steps of the real env, with the paper's constants written out here (not read back from the
env's parameters), and the weighted sum under the default and overridden weights."""

from __future__ import annotations

import dataclasses
import math

import gymnasium as gym
import numpy as np
import pytest

import myoexo  # noqa: F401  (registers the ids)
from myoexo.envs.config import DEFAULT_REWARD_WEIGHTS, TaskParams

SIGMA_RAD = 0.1  # width of the pose kernel (the project's documented choice)
BONUS = 0.01
BONUS_ERROR_RAD = 0.05
BONUS_VEL_RAD_S = 0.05
TORQUE_THRESHOLD_NM = 75.0
TORQUE_SCALE_NM = 100.0

TERMS = ("pose", "bonus", "inter", "vel", "act")


def approx(x: float):
    return pytest.approx(x, rel=1e-12, abs=1e-12)


def _run(env: gym.Env, actions, seed: int = 0):
    """Reset, then one step per action: the reset info and, per step, (reward, info)."""
    _, reset_info = env.reset(seed=seed)
    steps = []
    for a in actions:
        _, reward, terminated, truncated, info = env.step(np.array([a], np.float32))
        assert not (terminated or truncated)
        steps.append((reward, info))
    return reset_info, steps


def _expected_terms(actions, reset_info, steps, target_deg: float) -> list[dict[str, float]]:
    """The reward terms of each step from the definitions.

    The previous step of the first one is the reset state (command 0, the reset's torque
    and knee velocity)."""
    # the leg starts at rest: the velocity term of the first step is against 0
    assert reset_info["knee_vel_rad_s"] == 0.0
    prev_tau = reset_info["interaction_torque_nm"]
    prev_vel = reset_info["knee_vel_rad_s"]
    prev_u = 0.0
    expected = []
    for a, (_, info) in zip(actions, steps, strict=True):
        od = info["obs_dict"]
        u = min(1.0, max(-1.0, float(np.float32(a))))  # the motor driver clips the command
        assert info["command"] == u
        e = float(od["knee_angle_rad"][0]) - math.radians(target_deg)
        assert float(od["error_rad"][0]) == approx(e)
        vel = float(od["knee_vel_rad_s"][0])
        tau = float(od["interaction_torque_nm"][0])
        assert tau == approx(abs(info["cuff_knee_torque_nm"]))
        inter = ((tau - prev_tau) / TORQUE_SCALE_NM) ** 2
        if tau > TORQUE_THRESHOLD_NM:
            inter += (tau / TORQUE_SCALE_NM) ** 2
        on_target = abs(e) < BONUS_ERROR_RAD and abs(vel) < BONUS_VEL_RAD_S
        expected.append(
            {
                "pose": math.exp(-(e**2) / (2 * SIGMA_RAD**2)) - abs(e),
                "bonus": BONUS if on_target else 0.0,
                "inter": inter,
                "vel": abs(vel - prev_vel),
                "act": (u - prev_u) ** 2,
                # what the hand computation depends on, for the branch-coverage checks
                "_e": e,
                "_vel": vel,
                "_tau": tau,
            }
        )
        prev_tau, prev_vel, prev_u = tau, vel, u
    return expected


def _check_terms(steps, expected, weights: dict[str, float]) -> None:
    for i, ((reward, info), exp) in enumerate(zip(steps, expected, strict=True)):
        for key in TERMS:
            assert info["rwd_dict"][key] == approx(exp[key]), (i, key)
            assert info[key] == info["rwd_dict"][key]
        dense = sum(w * exp[k] for k, w in weights.items())
        assert reward == approx(dense), i
        assert info["rwd_dict"]["dense"] == reward


#: Extension commands of several sizes, a repeat (no command change), a clipped one and a
#: full reversal: covers both sides of the 75 Nm threshold and non-zero command changes.
ACTIONS = (0.0, -0.3, -0.3, -0.6, 0.5, -2.0, -1.0, 1.0, 0.25, 0.0)


@pytest.fixture(scope="module")
def default_run():
    env = gym.make("MyoExoKnee-v1")
    reset_info, steps = _run(env, ACTIONS, seed=4)
    env.close()
    return reset_info, steps


def test_each_term_and_the_weighted_sum_match_their_definitions(default_run):
    reset_info, steps = default_run
    expected = _expected_terms(ACTIONS, reset_info, steps, TaskParams().target_angle_deg)
    _check_terms(steps, expected, DEFAULT_REWARD_WEIGHTS)
    assert DEFAULT_REWARD_WEIGHTS == {
        "pose": 1.0,
        "bonus": 1.0,
        "inter": -1.0,
        "vel": -0.05,
        "act": -0.5,
    }
    # the run exercised both sides of the torque threshold and moved the knee
    taus = [x["_tau"] for x in expected]
    assert max(taus) > TORQUE_THRESHOLD_NM > min(taus)
    assert all(x["bonus"] == 0.0 for x in expected)  # far from the target: no bonus
    assert min(x["vel"] for x in expected) > 0.0 and max(x["act"] for x in expected) == 4.0


def test_torque_penalty_switches_on_above_75_nm():
    """Level 0: the full command puts about 90-105 Nm on the knee through the strap (the
    shank's inertia takes the rest); 0.70-0.77 put it within 10 Nm of the threshold, below
    and above."""
    env = gym.make("MyoExoKnee-v0")
    actions = (1.0, 1.0, -1.0, -0.70, -0.70, -0.77, -0.77, -0.74, -0.74, -0.72)
    reset_info, steps = _run(env, actions, seed=0)
    env.close()
    expected = _expected_terms(actions, reset_info, steps, TaskParams().target_angle_deg)
    _check_terms(steps, expected, DEFAULT_REWARD_WEIGHTS)
    taus = [x["_tau"] for x in expected]
    inters = [info["rwd_dict"]["inter"] for _, info in steps]
    # the first step's rate term is measured from the reset's torque
    tau0 = reset_info["interaction_torque_nm"]
    assert inters[0] == approx(
        ((taus[0] - tau0) / TORQUE_SCALE_NM) ** 2 + (taus[0] / TORQUE_SCALE_NM) ** 2
    )
    for (_, info), tau, inter in zip(steps[:3], taus[:3], inters[:3], strict=True):
        assert abs(info["exo_torque_nm"]) == pytest.approx(100.0, rel=1e-6)
        assert tau > TORQUE_THRESHOLD_NM
        assert inter >= (tau / TORQUE_SCALE_NM) ** 2
    # just below the threshold only the rate term counts; just above the level term adds
    below = [i for i, t in enumerate(taus) if TORQUE_THRESHOLD_NM - 10 < t < TORQUE_THRESHOLD_NM]
    above = [i for i, t in enumerate(taus) if TORQUE_THRESHOLD_NM < t < TORQUE_THRESHOLD_NM + 10]
    assert below and above
    for i in below:
        assert inters[i] == approx(((taus[i] - taus[i - 1]) / TORQUE_SCALE_NM) ** 2)
        assert inters[i] < (TORQUE_THRESHOLD_NM / TORQUE_SCALE_NM) ** 2
    for i in above:
        assert inters[i] > (TORQUE_THRESHOLD_NM / TORQUE_SCALE_NM) ** 2
    # reversing from +1 to -1 costs (d u)^2 = 4
    assert steps[2][1]["rwd_dict"]["act"] == 4.0


def test_a_new_episode_takes_the_differences_from_its_own_reset():
    """The rate terms of an episode's first step are not against the last step of the
    previous episode (command -0.6, a moving knee, a loaded joint)."""
    env = gym.make("MyoExoKnee-v1")
    _run(env, (0.0, -0.3, -0.6), seed=1)
    actions = (0.4, 0.4)
    reset_info, steps = _run(env, actions, seed=2)
    env.close()
    expected = _expected_terms(actions, reset_info, steps, TaskParams().target_angle_deg)
    _check_terms(steps, expected, DEFAULT_REWARD_WEIGHTS)
    assert steps[0][1]["rwd_dict"]["act"] == pytest.approx(0.4**2, rel=1e-6)


#: The hanging leg's passive equilibrium on the default twin, deg.
HANG_DEG = 78.6


def _still_knee_run(offset_rad: float, n: int, start_deg: float = HANG_DEG):
    """Start at the passive equilibrium of the hanging leg (78.6 deg: level 0, motor off,
    tests/test_model.py) with no perturbation, so the knee barely moves at first, and the
    target ``offset_rad`` below the start."""
    target_deg = start_deg - math.degrees(offset_rad)
    task = TaskParams(
        start_angle_deg=start_deg, target_angle_deg=target_deg, start_angle_noise_deg=0
    )
    env = gym.make("MyoExoKnee-v0", **dataclasses.asdict(task))
    actions = (0.0,) * n
    reset_info, steps = _run(env, actions, seed=0)
    env.close()
    assert reset_info["knee_angle_deg"] == pytest.approx(start_deg, abs=1e-9)
    expected = _expected_terms(actions, reset_info, steps, task.target_angle_deg)
    _check_terms(steps, expected, DEFAULT_REWARD_WEIGHTS)
    return steps, expected


def test_bonus_while_the_knee_is_held_at_the_target():
    """On the target the knee first stays still (bonus on), then drifts with a speed above
    the 0.05 rad/s bound while still within 0.05 rad of the target (bonus off through the
    velocity bound alone)."""
    steps, expected = _still_knee_run(0.0, 20, start_deg=HANG_DEG + 1.0)  # drifts as it settles
    bonus = [info["rwd_dict"]["bonus"] for _, info in steps]
    assert bonus[0] == BONUS and sum(b == BONUS for b in bonus) >= 3
    vel_gated = [
        x for x in expected if abs(x["_e"]) < BONUS_ERROR_RAD and abs(x["_vel"]) >= BONUS_VEL_RAD_S
    ]
    assert vel_gated and all(x["bonus"] == 0.0 for x in vel_gated)
    # the bonus enters the dense reward with weight 1 next to a pose term near 1
    reward0, _ = steps[0]
    assert reward0 > 1.0


@pytest.mark.parametrize(
    ("offset_rad", "bonus"),
    [(0.045, BONUS), (-0.045, BONUS), (0.055, 0.0), (-0.055, 0.0)],
)
def test_bonus_error_bound_is_005_rad(offset_rad, bonus):
    """A still knee just inside / just outside 0.05 rad of the target, on either side."""
    _, expected = _still_knee_run(offset_rad, 3)
    for x in expected:
        assert abs(x["_vel"]) < BONUS_VEL_RAD_S
        assert abs(x["_e"]) == pytest.approx(abs(offset_rad), abs=2e-3)
        assert x["bonus"] == bonus


@pytest.mark.parametrize(
    "weights",
    [
        {"pose": 2.0, "bonus": 0.0, "inter": -0.25, "vel": -1.0, "act": -3.0},
        {"pose": 1.0, "act": -10.0},  # keys left out keep their default weight
    ],
    ids=["all-keys", "subset"],
)
def test_reward_weights_override_the_weights(default_run, weights):
    env = gym.make("MyoExoKnee-v1", reward_weights=weights)
    assert env.unwrapped.rwd_keys_wt == {**DEFAULT_REWARD_WEIGHTS, **weights}
    reset_info, steps = _run(env, ACTIONS, seed=4)
    env.close()
    expected = _expected_terms(ACTIONS, reset_info, steps, TaskParams().target_angle_deg)
    _check_terms(steps, expected, {**DEFAULT_REWARD_WEIGHTS, **weights})
    # the weights change the sum only: the same seed and actions give the same terms
    _, default_steps = default_run
    for (_, info), (_, info_default) in zip(steps, default_steps, strict=True):
        for key in TERMS:
            assert info["rwd_dict"][key] == info_default["rwd_dict"][key]
    rewards = [r for r, _ in steps]
    assert rewards != [r for r, _ in default_steps]


# -- the pure function, without an env ---------------------------------------------------


def _pure(**overrides):
    from myoexo.envs.config import RewardParams
    from myoexo.envs.reward import reward_dict

    state = {
        "error_rad": 0.2,
        "knee_vel_rad_s": -0.5,
        "interaction_torque_nm": 40.0,
        "command": -0.4,
        "prev_command": -0.1,
        "prev_knee_vel_rad_s": -0.2,
        "prev_interaction_torque_nm": 30.0,
        "params": RewardParams(),
        "weights": DEFAULT_REWARD_WEIGHTS,
    }
    state.update(overrides)
    return reward_dict(**state), state


def test_pure_reward_function_terms_from_their_definitions():
    """``myoexo.envs.reward.reward_dict`` from plain floats: no model, no env."""
    rwd, s = _pure()
    e = s["error_rad"]
    assert rwd["pose"] == approx(math.exp(-(e**2) / (2 * SIGMA_RAD**2)) - abs(e))
    assert rwd["bonus"] == 0.0  # 0.2 rad from the target
    assert rwd["inter"] == approx(((40.0 - 30.0) / TORQUE_SCALE_NM) ** 2)  # below 75 Nm
    assert rwd["vel"] == approx(abs(-0.5 - -0.2))
    assert rwd["act"] == approx((-0.4 - -0.1) ** 2)
    assert rwd["sparse"] == -abs(e) and rwd["solved"] is False and rwd["done"] is False
    dense = sum(w * rwd[k] for k, w in DEFAULT_REWARD_WEIGHTS.items())
    assert rwd["dense"] == approx(dense)
    assert set(rwd) == {*TERMS, "gentle", "sparse", "solved", "done", "dense"}


@pytest.mark.parametrize(
    ("tau", "prev_tau", "expected"),
    [
        (74.0, 70.0, (4.0 / TORQUE_SCALE_NM) ** 2),  # the rate term only
        (80.0, 70.0, (10.0 / TORQUE_SCALE_NM) ** 2 + (80.0 / TORQUE_SCALE_NM) ** 2),
        (75.0, 75.0, 0.0),  # the threshold itself is not above it
    ],
)
def test_pure_reward_torque_penalty_threshold(tau, prev_tau, expected):
    rwd, _ = _pure(interaction_torque_nm=tau, prev_interaction_torque_nm=prev_tau)
    assert rwd["inter"] == approx(expected)


@pytest.mark.parametrize(
    ("error_rad", "vel", "bonus", "solved"),
    [
        (0.049, 0.049, BONUS, True),
        (-0.049, -0.049, BONUS, True),
        (0.051, 0.0, 0.0, False),
        (0.0, 0.051, 0.0, True),  # solved on the error alone; the bonus also needs stillness
    ],
)
def test_pure_reward_bonus_and_solved_bounds(error_rad, vel, bonus, solved):
    rwd, _ = _pure(error_rad=error_rad, knee_vel_rad_s=vel)
    assert rwd["bonus"] == bonus and rwd["solved"] is solved


def test_pure_reward_weights_and_params_are_arguments():
    from myoexo.envs.config import RewardParams

    weights = {"act": -10.0, "pose": 2.0}
    params = RewardParams(sigma_rad=0.3, bonus=0.5, torque_threshold_nm=10.0)
    rwd, _ = _pure(weights=weights, params=params, error_rad=0.01, knee_vel_rad_s=0.0)
    assert rwd["pose"] == approx(math.exp(-(0.01**2) / (2 * 0.3**2)) - 0.01)
    assert rwd["bonus"] == 0.5
    assert rwd["inter"] == approx((10.0 / 100.0) ** 2 + (40.0 / 100.0) ** 2)
    assert rwd["dense"] == approx(-10.0 * rwd["act"] + 2.0 * rwd["pose"])


def test_torque_cost_is_what_the_torque_terms_take_from_dense():
    """Without the ``inter`` weight and the gentleness weight, ``dense`` rises by exactly
    :func:`~myoexo.envs.reward.torque_cost` (a rising torque: the ``gentle`` peak term
    counts too)."""
    from myoexo.envs.reward import torque_cost

    weights = {**DEFAULT_REWARD_WEIGHTS, "inter": -0.1}
    rwd, _ = _pure(weights=weights, gentleness=0.6, peak_torque_nm=20.0)
    plain, _ = _pure(weights={k: w for k, w in weights.items() if k != "inter"})
    assert rwd["gentle"] > 0.0 and rwd["inter"] > 0.0
    assert plain["dense"] - rwd["dense"] == approx(torque_cost(rwd, weights, 0.6))
    assert torque_cost(rwd, {}, 0.0) == 0.0


def test_env_reward_is_the_pure_function_of_consecutive_steps(default_run):
    """The env's reward of each step equals ``reward_dict`` of the step's observations and
    the previous step's (the reset's for the first), bit for bit."""
    from myoexo.envs.config import RewardParams
    from myoexo.envs.reward import reward_dict

    reset_info, steps = default_run
    prev_u, prev_vel, prev_tau = (
        0.0,
        reset_info["knee_vel_rad_s"],
        reset_info["interaction_torque_nm"],
    )
    for reward, info in steps:
        od = info["obs_dict"]
        vel, tau = float(od["knee_vel_rad_s"][0]), float(od["interaction_torque_nm"][0])
        rwd = reward_dict(
            float(od["error_rad"][0]),
            vel,
            tau,
            info["command"],
            prev_u,
            prev_vel,
            prev_tau,
            RewardParams(),
            DEFAULT_REWARD_WEIGHTS,
        )
        assert rwd == info["rwd_dict"] and rwd["dense"] == reward
        prev_u, prev_vel, prev_tau = info["command"], vel, tau
