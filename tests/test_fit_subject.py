"""``myoexo twin fit-subject`` (:mod:`myoexo.studies.fit_subject`): the replay of a recording
on the twin, a fit that lowers the objective and reports what it found, a stopped fit that
continues from its partial state, and a bad recording refused in one line."""

from __future__ import annotations

import dataclasses
import hashlib
import json

import numpy as np
import pytest

from myoexo.clinical.recording import Recording, SensorNoise, record_from_twin, write_recording
from myoexo.clinical.tardieu import TardieuParams
from myoexo.spasticity import DEFAULT_REFLEX
from myoexo.studies import fit_subject as fs

SEED = 7
QUIET = SensorNoise(0.0, 0.0, 0.0)


@pytest.fixture(scope="module")
def recordings(tmp_path_factory):
    """A fast stretch and a slow one (1 rad/s, to keep the tests short) of subject 7 of
    level 2, with the sensors' noise."""
    folder = tmp_path_factory.mktemp("recordings")
    fast = write_recording(record_from_twin("stretch-fast", 2, SEED), folder / "fast.csv")
    slow_params = TardieuParams(slow_rad_s=1.0)
    slow = record_from_twin("stretch-slow", 2, SEED, params=slow_params)
    return fast, write_recording(slow, folder / "slow.csv")


def _settings(tmp_path, **changes):
    base = {"out": tmp_path / "subject.json", "progress": False, "uncertainty": "diagonal"}
    return fs.FitSettings(**{**base, **changes})


def test_the_parameters_and_their_bounds():
    assert {p.name for p in fs.PARAMETERS} == {
        *(f.name for f in dataclasses.fields(fs.SpasticityParams)),
        "stiffness_scale",
        "damping_scale",
    }
    for p in fs.PARAMETERS:
        assert p.unit and p.meaning and p.informed_by
        for u in (0.0, 0.3, 1.0):
            assert p.normalise(p.value(u)) == pytest.approx(u)
    for level in (1, 2, 3):  # the levels' nominal subjects lie inside the bounds
        nominal = fs.LEVELS[level]
        for f in dataclasses.fields(nominal):
            p = fs._BY_NAME[f.name]
            assert p.low < getattr(nominal, f.name) < p.high


def test_the_settings_refuse_what_cma_es_cannot_do(tmp_path):
    with pytest.raises(ValueError, match="whole generations"):
        _settings(tmp_path, budget=5, popsize=10)
    with pytest.raises(ValueError, match="parameters"):
        _settings(tmp_path, parameters=("k", "nope"))
    with pytest.raises(ValueError, match="empty"):
        _settings(tmp_path, parameters=())


def test_the_level_comes_from_the_recordings_or_the_option():
    def target(recording):
        return fs.Target(fs.Path("x.csv"), recording, recording.test, recording.test)

    mas = target(Recording("mas", {"mas_grade": "2"}))
    assert fs._level_of([mas], None) == 2 and fs._level_of([mas], 3) == 3
    with pytest.raises(ValueError, match="give --level"):
        fs._level_of([target(Recording("mas", {"mas_grade": "1+"}))], None)
    synthetic = target(Recording("mas", {"mas_grade": "2", "synthetic_level": "3"}))
    assert fs._level_of([synthetic, mas], None) == 3


def test_the_passive_knee_scales_are_the_twins_springs_and_damping():
    import mujoco

    from myoexo.clinical.common import twin_model
    from myoexo.model import TwinParams, pose_twin
    from myoexo.model.leg import KNEE_JOINT

    base = twin_model()
    scaled = fs.scale_passive_knee(base, 2.0, 3.0)
    overridden = twin_model(
        TwinParams(knee_damping_nm_s_rad=3.0 * TwinParams().knee_damping_nm_s_rad)
    )
    np.testing.assert_allclose(scaled.dof_damping, overridden.dof_damping)
    dof = int(base.joint(KNEE_JOINT).dofadr[0])
    for knee_deg in (10.0, 45.0, 100.0):  # both one-sided springs and the joint's
        springs = []
        for model in (base, scaled):
            data = mujoco.MjData(model)
            pose_twin(model, data, knee_angle_deg=knee_deg)
            mujoco.mj_forward(model, data)
            springs.append(data.qfrc_spring[dof])
        assert springs[1] == pytest.approx(2.0 * springs[0])
    assert base.dof_damping[dof] == TwinParams().knee_damping_nm_s_rad  # the twin untouched


def test_the_twin_replays_a_noise_free_recording_exactly(tmp_path):
    paths = [
        write_recording(record_from_twin("stretch-fast", 3, SEED, noise=QUIET), tmp_path / "f.csv"),
        write_recording(record_from_twin("pendulum", 3, SEED, noise=QUIET), tmp_path / "p.csv"),
    ]
    targets = fs.read_targets(paths)
    objective = fs.SubjectObjective(targets, 3, DEFAULT_REFLEX, _settings(tmp_path))
    truth = fs._truth(targets)
    assert truth is not None
    evaluation = objective(truth)
    assert [t["test"] for t in evaluation.traces] == ["stretch-fast", "pendulum-seated"]
    for trace in evaluation.traces:  # the recording's 4 decimals
        assert trace["angle_rms_deg"] < 1e-3
        assert trace.get("torque_rms_nm", 0.0) < 1e-3
    assert objective(objective.start()).objective > 1.0  # the nominal subject is not it


def test_a_fit_lowers_the_objective_and_reports_what_it_found(recordings, tmp_path):
    names = ("theta_flex_deg", "s_theta", "s_v")
    settings = _settings(
        tmp_path, budget=12, popsize=4, sigma0=0.01, parameters=names, uncertainty="hessian"
    )
    report = fs.fit_subject(recordings, settings)
    assert report["objective"]["fitted"] < report["objective"]["start"]
    assert json.loads(settings.out.read_text()) == json.loads(json.dumps(report))
    assert not fs.partial_path(settings.out).exists()
    assert report["level"] == 2 and report["reflex"] == DEFAULT_REFLEX
    assert set(report["subject"]) == {f.name for f in dataclasses.fields(fs.SpasticityParams)}
    rows = {r["name"]: r for r in report["parameters"]}
    assert list(rows) == list(names)
    for r in rows.values():
        assert r["bounds"][0] <= r["interval"][0] <= r["fitted"] <= r["interval"][1]
        assert isinstance(r["identifiable"], bool) and "truth" in r
    assert report["not_identifiable"] == [n for n, r in rows.items() if not r["identifiable"]]
    assert report["uncertainty"]["evaluations"] == 2 * 3**2 + 1
    assert "Hessian" in report["uncertainty"]["method"]
    traces = {t["test"]: t for t in report["traces"]}
    assert set(traces) == {"stretch-fast", "stretch-slow"}
    for speed, t in traces.items():
        assert t["angle_rms_deg"] >= 0.0 and t["torque_rms_nm"] >= 0.0
        assert t["van_der_krogt_2016_rms_deg"] == fs.VAN_DER_KROGT_2016_RMS_DEG[speed[8:]]
    prov = report["provenance"]
    assert [r["sha256"] for r in prov["recordings"]] == [
        hashlib.sha256(p.read_bytes()).hexdigest() for p in recordings
    ]
    assert prov["command"].startswith("myoexo twin fit-subject ")
    assert "--budget 12" in prov["command"] and prov["seed"] == 1 and prov["budget"] == 12
    assert {"cma", "mujoco", "myoexo"} <= set(prov["versions"])
    assert report["optimiser"]["evaluations"] == 12 and report["optimiser"]["generations"] == 3
    assert "identifiable" in fs.format_report(report)


class _StopAfter:
    """``received`` turns true at its *n*-th reading plus one."""

    def __init__(self, n: int) -> None:
        self.n, self.readings = n, 0

    @property
    def received(self) -> bool:
        self.readings += 1
        return self.readings > self.n


def test_a_stopped_fit_continues_from_its_partial_state(recordings, tmp_path, monkeypatch):
    fast = recordings[:1]
    names = ("v_lower_rad_s", "s_v")
    settings = _settings(tmp_path, budget=12, popsize=4, parameters=names)
    # one generation: 3 readings between its evaluations and 1 after it; the 5th stops
    with pytest.raises(fs.FitStopped) as stopped:
        fs.fit_subject(fast, settings, stop=_StopAfter(4))
    part = fs.partial_path(settings.out)
    assert stopped.value.evaluations == 4 and part.is_file() and not settings.out.exists()
    with pytest.raises(ValueError, match="remove it to start over"):
        fs.fit_subject(fast, dataclasses.replace(settings, seed=2))
    said: list[str] = []
    # CMA-ES to its end, then a stop in the Hessian's evaluations (after the second)
    calls = []
    call = fs.SubjectObjective.__call__

    def counted(self, values, single_values=True):
        calls.append(single_values)
        return call(self, values, single_values)

    class StopInHessian:
        @property
        def received(self) -> bool:
            return calls.count(False) >= 2

    monkeypatch.setattr(fs.SubjectObjective, "__call__", counted)
    with pytest.raises(fs.FitStopped) as stopped:
        fs.fit_subject(fast, settings, stop=StopInHessian(), log=said.append)
    assert stopped.value.evaluations == 12 and part.is_file() and not settings.out.exists()
    monkeypatch.setattr(fs.SubjectObjective, "__call__", call)
    report = fs.fit_subject(fast, settings, log=said.append)
    assert "4 evaluations done" in said[0] and "12 evaluations done" in said[1]
    assert not part.exists()
    optimiser = report["optimiser"]
    assert optimiser["resumed_at_evaluations"] == [4, 12]
    assert optimiser["evaluations"] == 12 and optimiser["generations"] == 3
    assert [n for n, _ in optimiser["best_by_generation"]] == [4, 8, 12]
    once = fs.fit_subject(fast, dataclasses.replace(settings, out=tmp_path / "once.json"))
    assert once["optimiser"]["resumed_at_evaluations"] == []
    for key in ("subject", "objective", "parameters"):  # as if it had never stopped
        assert once[key] == report[key]
    assert once["uncertainty"] == report["uncertainty"]


def test_a_bad_recording_exits_2_with_one_line_and_writes_nothing(recordings, tmp_path, capsys):
    from myoexo.cli import main

    bad = tmp_path / "bad.csv"
    bad.write_text("# test: stretch\n# speed: fast\n# sampling_hz: 100\ntime_s,knee_angle_deg\n")
    before = sorted(tmp_path.iterdir())
    out = tmp_path / "subject.json"
    assert main(["twin", "fit-subject", str(recordings[0]), str(bad), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1
    assert err.startswith(f"myoexo twin fit-subject: error: {bad}: too few samples")
    assert sorted(tmp_path.iterdir()) == before
