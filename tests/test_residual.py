"""Residual learning on a classical controller: the training wrapper and the run-time
controller give the same commands, a zero correction is the base controller itself, the
correction is bounded, and a trained run's record brings its base back at evaluation."""

from __future__ import annotations

import numpy as np
import pytest

from myoexo.control import read_sensors, specs
from myoexo.control.policy import CallableController, GentleController
from myoexo.control.residual import (
    PacedBase,
    ResidualConfig,
    ResidualController,
    ResidualWrapper,
    paced_duration_s,
    residual_command,
)
from myoexo.control.specs import (
    build_controller,
    paced_base_spec,
    parse_controller_spec,
    residual_base,
    with_residual_base,
)
from myoexo.envs import make_env
from myoexo.policies import load_policy
from myoexo.runtime.fields import FieldError
from myoexo.spasticity import DEFAULT_REFLEX
from myoexo.training import get_preset

BASE = "pid:reference=minjerk,ramp_s=0.6"


def _base(env):
    return build_controller(parse_controller_spec(BASE), env)


def _knee_trace(env, act, steps=120, seed=4):
    obs, info = env.reset(seed=seed)
    knees = []
    for _ in range(steps):
        obs, _, _, _, info = env.step(act(obs, info))
        knees.append(info["knee_angle_deg"])
    return np.array(knees)


def test_zero_correction_is_the_base_controller():
    """The wrapper with a zero action runs the base PID's trajectory exactly."""
    env = make_env(2)
    pid = _base(env)
    pid.reset(4)
    plain = _knee_trace(env, lambda obs, info: pid.act(obs, read_sensors(info, pid.sensors)))
    wrapped_env = ResidualWrapper(make_env(2), _base(env), scale=0.5)
    zero = np.zeros(1, np.float32)
    wrapped = _knee_trace(wrapped_env, lambda obs, info: zero)
    np.testing.assert_array_equal(plain, wrapped)


def test_wrapper_observes_the_base_command_and_bounds_the_correction():
    env = ResidualWrapper(make_env(1, gentleness="random"), _base(make_env(1)), scale=0.3)
    inner = env.env.observation_space.shape[0]
    assert env.observation_space.shape == (inner + 1,)
    obs, _ = env.reset(seed=0)
    assert obs.shape == env.observation_space.shape and obs.dtype == np.float32
    for _ in range(40):
        base_u = float(obs[-1])
        obs, _, _, _, info = env.step(np.ones(1, np.float32))
        assert info["base_command"] == pytest.approx(base_u)
        assert info["command"] == pytest.approx(min(1.0, base_u + 0.3), abs=1e-6)


def test_controller_and_wrapper_give_the_same_commands():
    """A policy run through ResidualController commands what the wrapper trained it on: same
    knee trace for a policy that reads the appended base command."""

    def policy(obs):  # halves the base command, from the last observation entry
        return np.array([-0.5 * obs[-1] / 0.4], np.float32).clip(-1, 1)

    env = make_env(1)
    controller = ResidualController(CallableController(policy), _base(env), 0.4)
    controller.reset(7)
    run = _knee_trace(env, lambda o, i: controller.act(o, read_sensors(i, controller.sensors)))
    wrapped_env = ResidualWrapper(make_env(1), _base(env), 0.4)
    trained = _knee_trace(wrapped_env, lambda o, i: policy(o))
    np.testing.assert_allclose(run, trained, atol=1e-9)


def test_metadata_record_wraps_the_policy_with_its_base():
    env = make_env(0)
    zero = CallableController(lambda obs: np.zeros(1))
    assert with_residual_base(zero, ResidualConfig.from_metadata({}), env) is zero
    record = {"residual": {"base": BASE, "scale": 0.5}}
    wrapped = with_residual_base(zero, ResidualConfig.from_metadata(record), env)
    assert isinstance(wrapped, ResidualController) and wrapped.scale == 0.5
    assert wrapped.sensors == _base(env).sensors  # the base's knee angle sensor
    gentle = GentleController(wrapped, 0.25)  # the weight before the base command
    gentle.reset(0)
    obs, info = env.reset(seed=0)
    seen = []
    wrapped.controller = CallableController(lambda o: seen.append(o.copy()) or np.zeros(1))
    gentle.act(obs, read_sensors(info, gentle.sensors))
    assert seen[0].shape == (obs.size + 2,) and seen[0][-2] == np.float32(0.25)


def test_the_penalty_prices_the_correction_and_leaves_the_trajectory():
    """With a penalty, the same actions give the same trajectory and a reward lower by
    ``penalty x a^2`` at every step (reported in ``info``)."""
    actions = np.random.default_rng(3).uniform(-1, 1, size=(60, 1)).astype(np.float32)
    runs = []
    for penalty in (0.0, 2.0):
        env = ResidualWrapper(make_env(1), _base(make_env(1)), 0.5, penalty=penalty)
        env.reset(seed=5)
        steps = [env.step(a) for a in actions]
        runs.append(steps)
    for a, plain, priced in zip(actions, *runs, strict=True):
        np.testing.assert_array_equal(plain[0], priced[0])
        assert priced[4]["residual_penalty"] == pytest.approx(2.0 * float(a[0]) ** 2)
        assert plain[1] - priced[1] == pytest.approx(2.0 * float(a[0]) ** 2)
        assert plain[4]["residual_penalty"] == 0.0


def test_residual_command_and_config_bounds():
    assert residual_command(0.9, 1.0, 0.5) == 1.0
    assert residual_command(-0.2, -0.5, 0.4) == pytest.approx(-0.4)
    with pytest.raises(ValueError, match="scale"):
        ResidualConfig(base=BASE, scale=0.0)
    assert ResidualConfig.from_metadata({"residual": {"base": BASE, "scale": 0.5}}) == (
        ResidualConfig(BASE, 0.5)
    )
    assert ResidualConfig.from_metadata({"twin": {}}) is None
    with pytest.raises(ValueError, match=r"penalty = -1.0 is outside \[0, 100\]"):
        ResidualConfig(base=BASE, penalty=-1.0)
    priced = ResidualConfig(BASE, 0.5, penalty=0.5)
    assert ResidualConfig.from_metadata({"residual": priced.to_dict()}) == priced
    assert "penalty" not in ResidualConfig(BASE, 0.5).to_dict()  # older records unchanged


PACED = ResidualConfig("pid:reference=minjerk", 0.5, pace_s=(0.3, 0.6))


def test_a_paced_base_runs_the_base_at_the_duration_of_the_episodes_weight():
    """At weight w the paced base is the PID on a ``0.3 + 0.3 w``-s reference: its commands
    equal that PID's, episode after episode, each at its own drawn weight."""
    env = make_env(1, gentleness="random")
    paced = residual_base(PACED, env)
    assert isinstance(paced, PacedBase) and paced.sensors == _base(env).sensors
    durations = []
    for seed in (0, 1):
        obs, info = env.reset(seed=seed)
        weight = float(obs[-1])
        plain = build_controller(
            parse_controller_spec(f"pid:reference=minjerk,ramp_s={0.3 + 0.3 * weight!r}"), env
        )
        paced.reset(seed)
        plain.reset(seed)
        for _ in range(60):
            measured = read_sensors(info, paced.sensors)
            u = paced.act(obs, measured)
            np.testing.assert_array_equal(u, plain.act(obs, measured))
            obs, _, _, _, info = env.step(u)
        durations.append(paced.duration_s)
        assert paced.duration_s == pytest.approx(0.3 + 0.3 * weight)
    assert durations[0] != durations[1]


def test_a_paced_base_follows_the_weight_through_the_wrapper_and_the_controller():
    """The paced base reads the weight where the training wrapper and the run-time
    controller both put it: the same knee trace at a fixed weight."""

    def policy(obs):
        return np.array([0.2 * obs[-1]], np.float32)

    env = make_env(2, gentleness=0.8)
    wrapped = ResidualWrapper(env, residual_base(PACED, env), 0.5)
    trained = _knee_trace(wrapped, lambda o, i: policy(o))
    assert wrapped.base.duration_s == pytest.approx(0.3 + 0.3 * 0.8)
    plain = make_env(2)
    controller = GentleController(
        ResidualController(CallableController(policy), residual_base(PACED, plain), 0.5), 0.8
    )
    controller.reset(4)
    run = _knee_trace(plain, lambda o, i: controller.act(o, read_sensors(i, controller.sensors)))
    np.testing.assert_array_equal(run, trained)


def test_pace_bounds_and_records():
    assert paced_duration_s((0.3, 0.6), 0.5) == pytest.approx(0.45)
    with pytest.raises(ValueError, match=r"got 1.5; accepted range \[0, 1\]"):
        paced_duration_s((0.3, 0.6), 1.5)
    with pytest.raises(ValueError, match=r"two durations .* in \[0.05, 10\] s"):
        ResidualConfig("pid:reference=minjerk", pace_s=(0.3, 20.0))
    with pytest.raises(ValueError, match="sets ramp_s"):
        paced_base_spec(BASE)
    with pytest.raises(ValueError, match="a classical controller spec"):
        paced_base_spec("oracle")
    impedance, option = paced_base_spec("impedance")
    assert (impedance.kind, option) == ("impedance", "duration_s")
    pid, option = paced_base_spec(PACED.base)
    assert (pid.options, option) == ({"reference": "minjerk"}, "ramp_s")
    assert ResidualConfig.from_metadata({"residual": PACED.to_dict()}) == PACED
    assert "pace_s" not in ResidualConfig(BASE).to_dict()  # older records unchanged


def test_a_paced_base_needs_a_kind_with_a_reference_duration(monkeypatch):
    monkeypatch.setattr(specs, "PACE_OPTIONS", {"pid": "ramp_s"})
    with pytest.raises(ValueError, match=r"reference duration of \['pid'\]; got base 'impedance'"):
        paced_base_spec("impedance")


def test_train_config_paces_the_base_only_over_the_weight_range():
    twin = get_preset("cpu").twin
    random = twin.replace(gentleness="random")
    config = get_preset(
        "cpu", residual_base="pid:reference=minjerk", residual_pace_s=(0.3, 0.6), twin=random
    )
    assert config.residual == PACED
    with pytest.raises(FieldError, match="train over the weight range"):
        get_preset("cpu", residual_base="pid:reference=minjerk", residual_pace_s=(0.3, 0.6))
    with pytest.raises(FieldError, match="no residual_base"):
        get_preset("cpu", residual_pace_s=(0.3, 0.6), twin=random)
    with pytest.raises(FieldError, match="sets ramp_s"):
        get_preset("cpu", residual_base=BASE, residual_pace_s=(0.3, 0.6), twin=random)


@pytest.mark.parametrize(
    ("base", "match"),
    [("sac", "shipped"), ("guard:pid", "guarded"), ("pid:kq=3", "unknown PID option")],
)
def test_train_config_refuses_a_base_that_is_not_classical(base, match):
    with pytest.raises(FieldError, match=match):
        get_preset("cpu", residual_base=base)


def test_train_config_refuses_a_penalty_without_a_base():
    with pytest.raises(FieldError, match="no residual_base"):
        get_preset("cpu", residual_penalty=0.5)
    config = get_preset("cpu", residual_base=BASE, residual_penalty=0.5)
    assert config.residual == ResidualConfig(BASE, 0.5, penalty=0.5)


def test_train_config_records_the_residual():
    config = get_preset("cpu", residual_base=BASE, residual_scale=0.25)
    assert config.residual == ResidualConfig(BASE, 0.25)
    assert get_preset("cpu").residual is None
    assert config.to_dict()["residual_base"] == BASE


@pytest.mark.slow
def test_a_residual_run_records_its_base_and_evaluates_with_it(tmp_path):
    """A short residual run: its checkpoint records the base; the checkpoint's controller
    and the evaluation spec of its model file both run the policy on top of that base."""
    from myoexo.training import checkpoints as ck
    from myoexo.training import train
    from myoexo.training.export import load_checkpoint_controller

    config = get_preset(
        "cpu",
        env_id="MyoExoKneeRandom-v0",
        episode_duration_s=0.5,
        total_timesteps=300,
        n_envs=2,
        checkpoint_every_s=0.0,
        checkpoint_every_steps=300,
        eval_every_steps=300,
        eval_subjects=1,
        eval_levels=(1,),
        gentleness="random",
        residual_base=BASE,
        residual_scale=0.5,
        algorithm_kwargs={"buffer_size": 2_000, "batch_size": 32, "learning_starts": 100},
    )
    run_dir = tmp_path / "res"
    train(config, run_dir, verbose=0)
    checkpoint = ck.list_checkpoints(run_dir)[-1]
    assert ck.read_state(checkpoint)["residual"] == {"base": BASE, "scale": 0.5}
    with pytest.raises(ValueError, match="gentleness range: give the weight"):
        load_checkpoint_controller(checkpoint)  # trained over the weights: one must be given
    controller = load_checkpoint_controller(checkpoint, gentleness=0.5)
    assert isinstance(controller, GentleController) and controller.gentleness == 0.5
    assert isinstance(controller.controller, ResidualController)
    env = make_env(1, episode_duration_s=0.5)
    spec = parse_controller_spec(f"{checkpoint / ck.MODEL_FILE}@0.5")
    built = build_controller(spec, env)
    assert isinstance(built, GentleController)
    assert isinstance(built.controller, ResidualController)
    obs, info = env.reset(seed=1)
    built.reset(1)
    action = built.act(obs, read_sensors(info, built.sensors))
    assert action.shape == (1,) and np.isfinite(action).all()
    # the checkpoint's controller at the same weight gives the spec's command (its numpy
    # actor against the model file's network: equal to float32 rounding)
    controller.reset(1)
    command = controller.act(obs, read_sensors(info, built.sensors))
    np.testing.assert_allclose(command, action, rtol=1e-5, atol=1e-6)


# ---------------------------------------------------------------------------- shipped
def test_the_shipped_residual_policy_is_refused_without_the_env_it_runs_on():
    import myoexo

    with pytest.raises(ValueError, match=r"pid:reference=minjerk,ramp_s=0\.6.*load_policy"):
        myoexo.load_policy("residual")


def test_the_shipped_residual_policy_records_how_it_was_chosen():
    from myoexo.model import TWIN_VERSION

    actor = load_policy("residual")
    meta = actor.metadata
    assert meta["residual"] == {"base": "pid:reference=minjerk,ramp_s=0.6", "scale": 0.5}
    assert meta["ship_seed"] in meta["training_seeds"] and len(meta["training_seeds"]) == 5
    assert "closest_seed" in meta["ship_rule"]
    # the default weight is the gentleness study's, recorded with it (selection root)
    record = meta["gentleness_record"]
    assert meta["default_gentleness"] == record["default_gentleness"]
    assert record["root_seed"] == 1 and record["subjects"] > 0
    # trained on today's default twin
    assert meta["twin_version"] == TWIN_VERSION
    assert meta["twin"]["reflex"] == DEFAULT_REFLEX
    assert meta["selection_root_seed"] == 1
    assert actor.check_reference() < 1e-5


def test_the_shipped_residual_policy_runs_on_its_base_at_its_weight():
    import myoexo

    env = make_env(1)
    try:
        controller = myoexo.load_policy("residual", env)
        gentle = myoexo.load_policy("residual@0.5", env)
    finally:
        env.close()
    default = load_policy("residual").metadata["default_gentleness"]
    assert isinstance(controller, GentleController) and controller.gentleness == default
    assert isinstance(gentle, GentleController) and gentle.gentleness == 0.5
    inner = controller.controller
    assert isinstance(inner, ResidualController) and inner.scale == 0.5
    assert inner.base.config.reference == "minjerk" and inner.base.config.ramp_s == 0.6


@pytest.mark.parametrize("level", [0, 1])
def test_the_shipped_residual_policy_reaches_the_target_at_levels_0_and_1(level):
    """Its card: within 1 deg at levels 0-1 (0.01-0.02 deg over 1000 subjects); two subjects
    (env seeds 3 and 4), full 8-s episodes from 90 deg."""
    import myoexo
    from myoexo.control.rollout import rollout

    env = make_env(level)
    try:
        controller = myoexo.load_policy("residual", env)
        for seed in (3, 4):
            episode = rollout(env, controller, seed=seed)
            assert not episode.unstable
            error_deg = episode.signals["error_deg"]
            assert abs(error_deg[0]) > 75.0
            assert abs(error_deg[-1]) < 1.0, (level, seed, error_deg[-1])
    finally:
        env.close()
