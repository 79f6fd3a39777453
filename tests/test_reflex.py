"""Tests of the reflex models (myoexo.spasticity.reflex) and their stage in MyoSuite's pipeline: the
stretch reflex decomposes the paper's SC_total by muscle group, the torch twin agrees and
differentiates, the delay line delays, and the stage drives each group with its own part."""

from __future__ import annotations

import dataclasses
import functools
import pickle

import numpy as np
import pytest
import torch

from myoexo.spasticity.coefficients import sc_total
from myoexo.spasticity.delay import DelayLine
from myoexo.spasticity.levels import LEVELS, SPASTIC_EXTENSORS, SPASTIC_FLEXORS, SpasticityParams
from myoexo.spasticity.reflex import (
    CALIBRATION,
    DEFAULT_REFLEX,
    UNCALIBRATED,
    LevelCalibration,
    StretchReflex,
    UniformReflex,
    group_excitations,
    group_excitations_torch,
)
from myoexo.spasticity.registry import get_reflex, resolve_reflex

THETA = np.linspace(-20.0, 110.0, 27)
VEL = np.linspace(-4.0, 4.0, 17)


@pytest.mark.parametrize("level", [0, 1, 2, 3])
def test_uncalibrated_stretch_reflex_splits_the_papers_sc_total(level: int) -> None:
    """With unit gains and Table I's thresholds, flexor + extensor parts add up to SC_total:
    the stretch model only says which group gets which one-sided term."""
    th, v = np.meshgrid(THETA, VEL)
    flex, ext = group_excitations(th, v, LEVELS[level])
    np.testing.assert_allclose(flex + ext, sc_total(th, v, LEVELS[level]), atol=1e-12)


def test_each_group_answers_its_own_stretch() -> None:
    """Extension (low angle, negative velocity) stretches the flexors, flexion the extensors."""
    p = LEVELS[2]
    cal = CALIBRATION[2]
    f_ext_fast, e_ext_fast = group_excitations(10.0, -3.0, p, cal)  # fast extension, extended
    f_flex_fast, e_flex_fast = group_excitations(85.0, 3.0, p, cal)  # fast flexion, flexed
    half_flex = 0.5 * cal.flexor_gain * (p.s_theta + p.s_v)
    half_ext = 0.5 * cal.extensor_gain * (p.s_theta + p.s_v)
    assert f_ext_fast > half_flex and e_ext_fast < half_ext
    assert e_flex_fast > half_ext and f_flex_fast < half_flex
    # faster extension recruits the flexors more (velocity dependence, Lance 1980)
    assert group_excitations(40.0, -2.0, p, cal)[0] > group_excitations(40.0, -0.2, p, cal)[0]


def test_calibration_moves_the_flexor_threshold_into_the_motion() -> None:
    """Table I's extension-side limits lie outside the 7-90 deg motion; the calibrated
    thresholds of levels 2-3 lie inside it and fire more at the higher level's target side."""
    for level in (2, 3):
        p, c = LEVELS[level], CALIBRATION[level]
        assert p.theta_ext_deg < 0.0 < p.theta_ext_deg + c.flexor_threshold_shift_deg < 90.0
        still_near_target = group_excitations(7.0, 0.0, p, c)[0]
        assert still_near_target > group_excitations(7.0, 0.0, p, UNCALIBRATED[level])[0]


def test_torch_twin_matches_and_differentiates() -> None:
    p = LEVELS[3]
    params = {
        n: torch.tensor(v, dtype=torch.float64, requires_grad=True)
        for n, v in zip(SpasticityParams.field_names(), p.as_array(), strict=True)
    }
    shift = torch.tensor(CALIBRATION[3].flexor_threshold_shift_deg, requires_grad=True)
    cal = {
        "flexor_gain": CALIBRATION[3].flexor_gain,
        "extensor_gain": CALIBRATION[3].extensor_gain,
        "flexor_threshold_shift_deg": shift,
    }
    th = torch.tensor(THETA, dtype=torch.float64, requires_grad=True)
    v = torch.tensor(np.linspace(-3, 3, THETA.size), dtype=torch.float64)
    flex, ext = group_excitations_torch(th, v, params, cal)
    ref = group_excitations(THETA, v.numpy(), p, CALIBRATION[3])
    np.testing.assert_allclose(flex.detach().numpy(), ref[0], atol=1e-12)
    np.testing.assert_allclose(ext.detach().numpy(), ref[1], atol=1e-12)
    (flex.sum() + ext.sum()).backward()
    assert shift.grad is not None and float(shift.grad) > 0.0  # a higher threshold fires more
    assert th.grad is not None and bool(torch.isfinite(th.grad).all())
    assert params["s_theta"].grad is not None and float(params["s_theta"].grad) > 0.0


def test_delay_line_returns_the_state_delay_steps_ago() -> None:
    line = DelayLine(3)
    out = [line.push((float(i), -float(i))) for i in range(8)]
    # held at the first sample until 3 steps of history exist, then 3 steps late
    assert [o[0] for o in out] == [0.0, 0.0, 0.0, 0.0, 1.0, 2.0, 3.0, 4.0]
    assert out[-1] == (4.0, -4.0)
    line.clear()
    assert line.push((9.0, 1.0)) == (9.0, 1.0)
    assert DelayLine(0).push((5.0, 2.0)) == (5.0, 2.0)
    with pytest.raises(ValueError):
        DelayLine(-1)


def test_bad_reflex_settings_are_rejected() -> None:
    with pytest.raises(
        ValueError,
        match=r"not a registered reflex model.*persistent, spindle, spindle_tone, spindle_tsrt, "
        r"stretch",
    ):
        get_reflex("clonus")
    with pytest.raises(ValueError, match=r"outside \[0, 0.2\]"):
        StretchReflex(delay_s=0.5)
    with pytest.raises(ValueError, match="outside"):
        LevelCalibration(flexor_gain=-1.0)
    with pytest.raises(ValueError, match="registered name"):
        resolve_reflex(3)  # type: ignore[arg-type]
    assert resolve_reflex("uniform") is get_reflex("uniform")


# ------------------------------------------------------------------------------ the stage
def test_stretch_stage_drives_each_group_with_its_delayed_part(walk_env_factory) -> None:
    env = walk_env_factory(level=3, reflex="stretch")
    host = env.unwrapped
    model = host.model
    env.reset(seed=0)
    stage = env.spasticity
    assert stage.delay_steps == round(get_reflex("stretch").delay_s / host.dt)
    flex_ids = np.array([model.actuator(n).id for n in SPASTIC_FLEXORS])
    ext_ids = np.array([model.actuator(n).id for n in SPASTIC_EXTENSORS])
    others = np.setdiff1d(np.arange(model.nu), np.concatenate([flex_ids, ext_ids]))
    knee = model.joint("knee_angle_r")
    history = []
    rng = np.random.default_rng(0)
    for step in range(8):
        history.append(
            (np.degrees(host.data.qpos[knee.qposadr[0]]), host.data.qvel[knee.dofadr[0]])
        )
        delayed = history[max(0, step - stage.delay_steps)]
        flex, ext = group_excitations(*delayed, stage.subject, CALIBRATION[3])
        action = rng.uniform(0.0, 0.5, model.nu).astype(np.float32)
        env.step(action)
        ctrl = host.data.ctrl
        np.testing.assert_allclose(
            ctrl[flex_ids], np.clip(action[flex_ids] + flex, 0, 1), atol=1e-7
        )
        np.testing.assert_allclose(ctrl[ext_ids], np.clip(action[ext_ids] + ext, 0, 1), atol=1e-7)
        np.testing.assert_array_equal(ctrl[others], action[others].astype(np.float64))
        assert stage.last_sc_total == pytest.approx(flex + ext, abs=1e-12)
    env.close()


def test_envs_take_the_reflex_keyword_and_keep_it_through_pickling() -> None:
    import gymnasium as gym

    import myoexo  # noqa: F401

    default = gym.make("MyoExoKnee-v3")
    assert default.unwrapped.spasticity.reflex == get_reflex(DEFAULT_REFLEX)
    default.close()
    stretch = gym.make("MyoExoKnee-v3", reflex="stretch")
    uniform = gym.make("MyoExoKnee-v3", reflex="uniform")
    assert stretch.unwrapped.spasticity.reflex == get_reflex("stretch") == StretchReflex()
    assert uniform.unwrapped.spasticity.reflex == UniformReflex()
    assert uniform.unwrapped.spasticity.reflex_name == "uniform"
    states = []
    for env in (stretch, uniform, pickle.loads(pickle.dumps(uniform.unwrapped))):
        env.reset(seed=4)
        for _ in range(30):
            _, _, _, _, info = env.step(np.array([-0.6], np.float32))
        states.append(info["knee_angle_deg"])
    assert states[1] == states[2]  # the pickled env is the same uniform twin
    assert states[0] != states[1]  # the models differ
    custom = dataclasses.replace(get_reflex("stretch"), delay_s=0.0)
    assert gym.make("MyoExoKnee-v1", reflex=custom).unwrapped.spasticity.reflex.delay_s == 0.0


def test_delay_line_history_can_be_taken_and_restored():
    from myoexo.spasticity.delay import DelayLine

    line = DelayLine(2)
    for k in range(3):
        line.push((float(k), -float(k)))
    saved = line.state()
    ahead = [line.push((10.0 + k, 0.0)) for k in range(4)]
    line.set_state(saved)
    assert [line.push((10.0 + k, 0.0)) for k in range(4)] == ahead
    with pytest.raises(ValueError, match="does not fit"):
        DelayLine(1).set_state(saved)


def test_the_stage_installs_through_myosuite_3s_env_config() -> None:
    """MyoSuite 3's own way to add a condition to one of its envs: ``make_env`` of an
    ``EnvConfig`` whose ``features`` name the wrapper. The stage then drives the spastic
    muscles of MyoSuite's walking leg exactly as the wrapper built by hand does."""
    from myosuite.core.config import EnvConfig
    from myosuite.core.registry import make_env
    from myosuite.utils import gym

    from myoexo.spasticity.wrapper import SpasticityWrapper

    config = EnvConfig(
        "myoLegWalk-v0", features=((SpasticityWrapper, {"level": 3, "reflex": "stretch"}),)
    )
    env = make_env(config)
    by_hand = SpasticityWrapper(gym.make("myoLegWalk-v0"), level=3, reflex="stretch")
    try:
        assert isinstance(env, SpasticityWrapper) or any(
            isinstance(w, SpasticityWrapper) for w in _wrappers(env)
        )
        model = env.unwrapped.model
        ids = [model.actuator(n).id for n in (*SPASTIC_FLEXORS, *SPASTIC_EXTENSORS)]
        env.reset(seed=0)
        by_hand.reset(seed=0)
        action = np.zeros(model.nu, np.float32)
        for _ in range(5):
            env.step(action)
            by_hand.step(action)
        ctrl = env.unwrapped.data.ctrl
        np.testing.assert_array_equal(ctrl, by_hand.unwrapped.data.ctrl)
        assert ctrl[ids].max() > 0.0  # the reflex drives the spastic muscles on its own
    finally:
        env.close()
        by_hand.close()


def _wrappers(env):
    while hasattr(env, "env"):
        yield env
        env = env.env


@pytest.mark.parametrize("model", ["stretch", "spindle", "tsrt", "spindle_tsrt", "spindle_tone"])
def test_the_reflex_calibrations_are_fitted_data_with_provenance(model: str) -> None:
    """The fitted reflexes read their calibrations from the package's fits, which record how
    they were fitted, on the twin of today."""
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import read_fit
    from myoexo.spasticity.reflex import STRETCH_FIT
    from myoexo.spasticity.spindle import (
        SPINDLE_CALIBRATION,
        SPINDLE_FIT,
        SPINDLE_TSRT_CALIBRATION,
        SPINDLE_TSRT_FIT,
    )
    from myoexo.spasticity.spindle_tone import SPINDLE_TONE_CALIBRATION, SPINDLE_TONE_FIT
    from myoexo.spasticity.tsrt import TSRT_CALIBRATION, TSRT_FIT

    name, calibration = {
        "stretch": (STRETCH_FIT, CALIBRATION),
        "spindle": (SPINDLE_FIT, SPINDLE_CALIBRATION),
        "tsrt": (TSRT_FIT, TSRT_CALIBRATION),
        "spindle_tsrt": (SPINDLE_TSRT_FIT, SPINDLE_TSRT_CALIBRATION),
        "spindle_tone": (SPINDLE_TONE_FIT, SPINDLE_TONE_CALIBRATION),
    }[model]
    doc = read_fit(name)
    result = doc["result"]["calibration"] if model == "spindle" else doc["result"]
    assert type(calibration).from_dict(result) == calibration
    assert type(calibration).from_dict(calibration.to_dict()) == calibration
    assert doc["provenance"]["command"].startswith(f"{calibration.note.split(':')[0]}")
    assert doc["provenance"]["root_seed"] == calibration.root_seed == 2
    assert doc["provenance"]["twin_version"] == TWIN_VERSION


@pytest.mark.slow
def test_calibrate_write_makes_the_fit_the_packages(tmp_path, monkeypatch, capsys) -> None:
    from myoexo import cli
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime import fits
    from myoexo.spasticity.reflex import STRETCH_FIT, StretchCalibration
    from myoexo.studies import calibrate

    monkeypatch.setattr(fits, "fits_dir", lambda: tmp_path)
    # what is written, not how closely it is fitted: a 5-deg bisection (7 trials a level
    # instead of 12) ends inside the same bounds
    fit = calibrate.fit_threshold_shift
    monkeypatch.setattr(calibrate, "fit_threshold_shift", functools.partial(fit, tol_deg=5.0))
    argv = [
        "twin",
        "calibrate",
        "--subjects",
        "2",
        "--verify-subjects",
        "2",
        "--extensor-gain",
        "0.5",
    ]
    assert cli.main([*argv, "--write"]) == 0
    doc = fits.read_fit(STRETCH_FIT)
    fitted = StretchCalibration.from_dict(doc["result"])
    assert fitted.root_seed == 2 and set(fitted.levels) == {1, 2, 3}
    assert 0.0 < fitted[2].flexor_threshold_shift_deg < 150.0
    assert doc["provenance"]["twin_version"] == TWIN_VERSION
    assert doc["provenance"]["command"].endswith("--seed 2 --write")
    assert cli.main(["twin", "calibrate", "--reflex", "persistent", "--write"]) == 2
    assert "chosen, not fitted" in capsys.readouterr().err


def test_each_model_registers_its_own_fit_and_options(capsys) -> None:
    """``myoexo twin calibrate`` runs the fit registered for ``--reflex``; another model's option
    is refused with one line naming whose it is; a plug-in registers its fit the same way, its
    options the fields of a config dataclass (:mod:`myoexo.runtime.fields`)."""
    from dataclasses import dataclass

    from myoexo import cli
    from myoexo.runtime.fields import option
    from myoexo.studies import calibrate as cal

    assert set(cal.fit_names()) >= {"stretch", "spindle", "persistent", "tsrt"}
    assert cli.main(["twin", "calibrate", "--sweeps", "3"]) == 2
    assert (
        "--sweeps is an option of --reflex tsrt / spindle_tsrt / spindle_tone, not of --reflex "
        "stretch"
    ) in (capsys.readouterr().err)

    @dataclass(frozen=True)
    class MineOptions:
        rate_hz: float = option(5.0, "a plug-in's rate", low=0.0, unit="Hz")

    seen: dict = {}

    def fit_mine(config: cal.CalibrationConfig, options: MineOptions) -> int:
        seen.update(config=config, options=options)
        return 0

    mine = cal.ReflexFit("mine_example", "a plug-in's fit", fit_mine, MineOptions)
    cal.register_fit(mine)
    try:
        with pytest.raises(ValueError, match="has a fit already"):
            cal.register_fit(mine)
        argv = ["twin", "calibrate", "--reflex", "mine_example"]
        assert cli.main([*argv, "--subjects", "3"]) == 0
        assert seen["options"] == MineOptions() and seen["config"].subjects == 3
        assert cli.main([*argv, "--rate-hz", "7"]) == 0
        assert seen["options"] == MineOptions(7.0)
        assert cli.main([*argv, "--rate-hz", "-1"]) == 2
        assert "--rate-hz = -1.0 must be >= 0 Hz" in capsys.readouterr().err
        assert cli.main(["twin", "calibrate", "--rate-hz", "7"]) == 2  # stretch takes no --rate-hz
        assert "--rate-hz is an option of --reflex mine_example" in capsys.readouterr().err

        @dataclass(frozen=True)
        class Clash:
            rate_hz: int = option(5, "another rate")

        with pytest.raises(ValueError, match="differs from"):
            cal.register_fit(cal.ReflexFit("clash_example", "", fit_mine, Clash))
    finally:
        cal._FITS.pop("mine_example")
