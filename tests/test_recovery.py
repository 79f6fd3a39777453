"""``myoexo twin recovery`` (:mod:`myoexo.studies.recovery`): simulated people recorded,
fitted and predicted; a stopped run continues from the rows it left; the tables come from
the rows."""

from __future__ import annotations

import json

import pandas as pd
import pytest

from myoexo.evaluation.config import SUBJECT_ROOTS
from myoexo.studies import recovery as rc


@pytest.fixture(scope="module")
def run(tmp_path_factory):
    """Two subjects (levels 0 and 1), short fits, the paper's PID predicted."""
    settings = rc.RecoverySettings(
        out=tmp_path_factory.mktemp("recovery"), subjects=2, budget=10, level0_budget=10,
        controllers=("pid",),
    )  # fmt: skip
    rows = rc.run_recovery(settings)
    return settings, rows, rc.summarise(rows, settings)


def test_the_recovery_root_is_its_own():
    assert list(SUBJECT_ROOTS.values()).count(rc.RecoverySettings().root_seed) == 1
    assert SUBJECT_ROOTS["recovery"] == rc.RecoverySettings().root_seed
    with pytest.raises(ValueError, match="evaluation root"):
        rc.RecoverySettings(root_seed=0)
    with pytest.raises(ValueError, match="subjects"):
        rc.RecoverySettings(subjects=0)


def test_each_subject_is_recorded_fitted_and_predicted(run):
    settings, rows, _ = run
    by_level = {r["level"]: r for r in rows}
    assert set(by_level) == {0, 1}
    folder = settings.out / "subjects" / "s000"
    assert {p.name for p in folder.glob("*.csv")} == {f"{t}.csv" for t in rc.RECORDED_TESTS}
    report = json.loads((folder / "subject.json").read_text())
    # level 0: the reflex is off, only the passive knee is fitted
    assert report["fitted_parameters"] == ["stiffness_scale", "damping_scale"]
    one = by_level[1]
    for name in ("theta_flex_deg", "s_v", "k", "stiffness_scale"):
        assert one[f"{name}_error"] == pytest.approx(one[f"{name}_fit"] - one[f"{name}_truth"])
    assert one["stiffness_scale_truth"] == 1.0  # recorded on the twin's own knee
    for key in ("final_error_deg", "peak_torque_nm"):
        assert one[f"pid_{key}_truth"] >= 0.0 and one[f"pid_{key}_fit"] >= 0.0
    assert one["stretch-slow_angle_rms_deg"] > 0.0


def test_the_tables_come_from_the_rows(run):
    settings, _, summary = run
    subjects = pd.read_csv(settings.out / "subjects.csv")
    assert len(subjects) == 2
    miss = (subjects["pid_final_error_deg_fit"] - subjects["pid_final_error_deg_truth"]).abs()
    peak = (
        subjects["pid_peak_torque_nm_fit"] - subjects["pid_peak_torque_nm_truth"]
    ).abs() / subjects["pid_peak_torque_nm_truth"]
    both = ((miss <= 1.5) & (peak <= 0.10)).mean()
    assert summary["prediction_target"]["both_within_fraction"] == pytest.approx(both)
    assert summary["prediction_target"]["met"] == (both >= 0.9)
    predictions = pd.read_csv(settings.out / "predictions.csv")
    row = predictions[(predictions.controller == "pid") & (predictions.level == "all")].iloc[0]
    assert row["final_error_miss_deg_max"] == pytest.approx(miss.max())
    params = pd.read_csv(settings.out / "parameters.csv")
    assert set(params[params.level == "0"].parameter) == {"stiffness_scale", "damping_scale"}
    page = (settings.out / "recovery.md").read_text()
    assert "Prediction target" in page
    assert ("**met**" in page) == summary["prediction_target"]["met"]
    command = summary["provenance"]["command"]
    assert command.startswith("myoexo twin recovery ") and " --subjects 2 " in command


def test_the_persons_pid_is_compared_with_the_papers_on_the_true_twin(run):
    settings, _, summary = run
    personal = json.loads((settings.out / "subjects" / "s001" / "personal.json").read_text())
    assert personal["generic_spec"] == "pid"
    for who in ("personal", "tuned_on_truth"):
        tuned = personal[f"{who}_tuner_failed"] == ""
        assert personal[f"{who}_spec"].startswith("pid:kp=") == tuned
        assert personal[f"{who}_peak_torque_nm"] > 0.0
    # the generic PID on the true twin is the prediction's run on the truth
    row = json.loads((settings.out / "subjects" / "s001" / "row.json").read_text())
    assert personal["generic_final_error_deg"] == pytest.approx(row["pid_final_error_deg_truth"])
    table = pd.read_csv(settings.out / "personalisation.csv")
    one = table[(table.level == "all") & (table.pid == "personal")]
    one = one[one.metric == "peak_torque_nm"].iloc[0]
    assert one["difference"] == pytest.approx(one["personal"] - one["generic"])
    assert summary["personalisation_subjects"] == 2
    assert "Personalisation" in (settings.out / "recovery.md").read_text()


def test_a_stopped_run_continues_from_its_rows(run, monkeypatch):
    settings, rows, _ = run

    def refit(*args, **kwargs):
        raise AssertionError("a subject with a row was fitted again")

    monkeypatch.setattr("myoexo.studies.fit_subject.fit_subject", refit)
    monkeypatch.setattr("myoexo.control.ziegler_nichols.tune", refit)
    again = rc.run_recovery(settings)
    assert sorted(r["index"] for r in again) == sorted(r["index"] for r in rows)


def test_the_command_summarises_only_and_refuses_an_empty_folder(run, tmp_path, capsys):
    from myoexo.cli import main

    settings, _, _ = run
    argv = ["twin", "recovery", "--out", str(settings.out), "--subjects", "2",
            "--controllers", "pid", "--summarise-only"]  # fmt: skip
    assert main(argv) == 0
    assert "Parameter recovery" in capsys.readouterr().out
    empty = ["twin", "recovery", "--out", str(tmp_path / "none"), "--summarise-only"]
    assert main(empty) == 2
    assert "no subject rows" in capsys.readouterr().err
