"""A personal twin (:mod:`myoexo.spasticity.personal`): the report of ``myoexo twin
fit-subject`` read back, its uncertainty drawn, and the person run by the env, the twin
options and ``myoexo evaluate``."""

from __future__ import annotations

import dataclasses
import json

import gymnasium as gym
import numpy as np
import pytest

from myoexo.clinical.recording import SensorNoise, record_from_twin, write_recording
from myoexo.clinical.tardieu import TardieuParams
from myoexo.envs.options import TwinOptions
from myoexo.evaluation import EvaluationConfig
from myoexo.model.passive_knee import PassiveKneeScaler
from myoexo.spasticity import DEFAULT_REFLEX, SpasticityParams
from myoexo.spasticity.levels import LEVELS
from myoexo.spasticity.personal import PersonalSubject, from_unit, load_subject, to_unit
from myoexo.studies import fit_subject as fs

NAMES = ("s_v", "stiffness_scale", "damping_scale")


@pytest.fixture(scope="module")
def report_path(tmp_path_factory):
    """A short fit of three parameters (the full Hessian) to two stretches of subject 7 of
    level 2 (the slow one at 1 rad/s, to keep it short)."""
    folder = tmp_path_factory.mktemp("personal")
    noise = SensorNoise(0.0, 0.0, 0.0)
    fast = write_recording(record_from_twin("stretch-fast", 2, 7, noise=noise), folder / "f.csv")
    slow = record_from_twin("stretch-slow", 2, 7, noise=noise, params=TardieuParams(slow_rad_s=1))
    recordings = [fast, write_recording(slow, folder / "s.csv")]
    settings = fs.FitSettings(
        out=folder / "subject.json", budget=8, popsize=4, sigma0=0.05, parameters=NAMES,
        progress=False,
    )  # fmt: skip
    fs.fit_subject(recordings, settings)
    return settings.out


def test_the_report_reads_back_as_the_fitted_person(report_path):
    report = json.loads(report_path.read_text())
    person = load_subject(report_path)
    assert person.level == 2 and person.reflex == DEFAULT_REFLEX and person.names == NAMES
    subject, stiffness, damping = person.point()
    assert dataclasses.asdict(subject) == pytest.approx(report["subject"])
    assert stiffness == pytest.approx(report["passive_knee"]["stiffness_scale"])
    assert damping == pytest.approx(report["passive_knee"]["damping_scale"])
    cov = person.covariance
    assert cov.shape == (3, 3) and np.allclose(cov, cov.T)
    assert np.linalg.eigvalsh(cov).min() >= -1e-12  # a covariance
    assert np.linalg.eigvalsh(cov).max() <= 1 / 12 + 1e-12  # no wider than the bounds


def test_draws_vary_the_fitted_parameters_inside_their_bounds(report_path):
    person = load_subject(report_path)
    draws = [person.draw(np.random.default_rng(s)) for s in range(200)]
    again = person.draw(np.random.default_rng(5))
    assert again == draws[5]  # same generator state, same person
    s_v = np.array([d[0].s_v for d in draws])
    stiffness = np.array([d[1] for d in draws])
    assert s_v.std() > 0 and stiffness.std() > 0
    assert s_v.min() >= 0.0 and s_v.max() <= 1.0 and stiffness.min() >= 0.5
    # a parameter the fit did not move is the fit's in every draw
    assert {d[0].theta_flex_deg for d in draws} == {person.values["theta_flex_deg"]}


def test_a_subject_known_exactly_draws_nothing():
    truth = PersonalSubject.of(2, LEVELS[2], reflex=DEFAULT_REFLEX, stiffness_scale=1.5)
    rng = np.random.default_rng(0)
    state = rng.bit_generator.state
    assert truth.draw(rng) == (LEVELS[2], 1.5, 1.0)
    assert rng.bit_generator.state == state and not truth.has_uncertainty


def test_bad_reports_are_refused_in_one_line_naming_the_file(tmp_path, report_path):
    with pytest.raises(ValueError, match=r"nope\.json: no such file"):
        load_subject(tmp_path / "nope.json")
    (tmp_path / "text.json").write_text("not json")
    with pytest.raises(ValueError, match=r"text\.json: not a JSON report"):
        load_subject(tmp_path / "text.json")
    (tmp_path / "other.json").write_text(json.dumps({"level": 2}))
    with pytest.raises(ValueError, match=r"other\.json: not a report of myoexo twin fit-subj"):
        load_subject(tmp_path / "other.json")
    report = json.loads(report_path.read_text())
    report["passive_knee"]["damping_scale"] = -1.0
    (tmp_path / "neg.json").write_text(json.dumps(report))
    with pytest.raises(ValueError, match=r"neg\.json: damping_scale = -1.0 must be"):
        load_subject(tmp_path / "neg.json")


def test_the_unit_coordinates_round_trip():
    for lo, hi, log in ((0.0, 1.0, False), (-50.0, 0.0, False), (0.25, 10.0, True)):
        for u in (0.0, 0.4, 1.0):
            assert to_unit(from_unit(u, lo, hi, log), lo, hi, log) == pytest.approx(u)
    assert from_unit(1.7, 0.0, 2.0) == 2.0  # clipped


def test_the_scaler_writes_nominal_times_scale_without_accumulating():
    env = gym.make("MyoExoKnee-v2").unwrapped
    m = env.model
    scaler = PassiveKneeScaler(m)
    knee = m.joint("knee_angle_r")
    damping, stiffness = float(m.dof_damping[knee.dofadr[0]]), m.jnt_stiffnesspoly[knee.id].copy()
    scaler.apply(2.0, 3.0)
    scaler.apply(2.0, 3.0)
    assert m.dof_damping[knee.dofadr[0]] == pytest.approx(3.0 * damping)
    assert m.jnt_stiffnesspoly[knee.id] == pytest.approx(2.0 * stiffness)
    with pytest.raises(ValueError, match=r"stiffness_scale = 0\.0"):
        scaler.apply(0.0, 1.0)


def _first_steps(env, seed, n=20):
    env.reset(seed=seed)
    return np.array([env.step(np.array([0.5], np.float32))[0] for _ in range(n)])


def test_the_env_runs_the_person_and_draws_from_the_fit(report_path):
    person = load_subject(report_path)
    env = gym.make("MyoExoKnee-v2", subject=str(report_path))
    _, info = env.reset(seed=3)
    subject, stiffness, damping = person.point()
    assert info["subject"] == pytest.approx(
        {**dataclasses.asdict(subject), "stiffness_scale": stiffness, "damping_scale": damping}
    )
    u = env.unwrapped
    nominal = gym.make("MyoExoKnee-v2").unwrapped
    dof = u.model.joint("knee_angle_r").dofadr[0]
    assert u.model.dof_damping[dof] == pytest.approx(damping * nominal.model.dof_damping[dof])
    assert u.spasticity.subject == subject
    # the point fit does not change with the seed; draws do, and repeat with it
    assert env.reset(seed=4)[1]["subject"] == info["subject"]
    drawn = gym.make("MyoExoKnee-v2", subject=str(report_path), subject_noise=True)
    a, b = drawn.reset(seed=1)[1]["subject"], drawn.reset(seed=2)[1]["subject"]
    assert a != b and drawn.reset(seed=1)[1]["subject"] == a
    np.testing.assert_array_equal(_first_steps(drawn, 1), _first_steps(drawn, 1))
    assert not np.array_equal(_first_steps(drawn, 1), _first_steps(drawn, 2))


def test_the_env_refuses_another_level_or_reflex(report_path):
    with pytest.raises(ValueError, match=r"level 2's reflex calibration.*MyoExoKnee-v2"):
        gym.make("MyoExoKnee-v3", subject=str(report_path))
    with pytest.raises(ValueError, match=f"fitted with the '{DEFAULT_REFLEX}' reflex"):
        gym.make("MyoExoKnee-v2", subject=str(report_path), reflex="stretch")


def test_twin_options_and_the_evaluation_carry_the_person(report_path, tmp_path):
    options = TwinOptions(subject=str(report_path))
    assert options.env_kwargs() == {"subject": str(report_path), "subject_noise": True}
    record = options.to_dict()
    assert len(record["subject_sha256"]) == 64
    assert TwinOptions.from_dict(record) == options
    assert options.dynamics().subject == str(report_path)
    assert EvaluationConfig(twin=options).levels == (2,)  # the fit's level
    with pytest.raises(ValueError, match="level-2 twin"):
        EvaluationConfig(twin=options, levels=(3,))
    with pytest.raises(ValueError, match=r"nope\.json: no such file"):
        TwinOptions(subject=str(tmp_path / "nope.json"))


def test_evaluate_compares_controllers_on_draws_of_the_person(report_path, tmp_path, capsys):
    import pandas as pd

    from myoexo.cli import main

    out = tmp_path / "eval"
    argv = ["evaluate", "--subject", str(report_path), "--subjects", "2", "--controllers",
            "pid", "pid:ramp_s=1", "--out", str(out), "--workers", "1"]  # fmt: skip
    assert main(argv) == 0
    episodes = pd.read_parquet(out / "episodes.parquet")
    assert set(episodes["level"]) == {2} and len(episodes) == 4
    by = episodes.set_index(["controller", "subject"])["subject_stiffness_scale"]
    assert by["pid"].tolist() == by["pid:ramp_s=1"].tolist()  # the same draws for each
    assert by["pid"].nunique() == 2
    bad = ["evaluate", "--subject", str(tmp_path / "nope.json"), "--out", str(tmp_path / "x")]
    assert main(bad) == 2
    assert "nope.json: no such file" in capsys.readouterr().err
    assert not (tmp_path / "x").exists()


def test_spasticity_params_of_the_report_are_a_valid_record(report_path):
    assert isinstance(load_subject(report_path).subject, SpasticityParams)
