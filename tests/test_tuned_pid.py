"""The PIDs tuned for their sensors and latency: each entry is the file its tuner wrote into
the package (data with provenance, not a literal in code), and the spec ``pid:tuned=NAME``
runs it."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from myoexo import cli
from myoexo.control import tuned
from myoexo.control import ziegler_nichols as zn
from myoexo.control.specs import parse_controller_spec, pid_config
from myoexo.control.tuned import TUNED_PIDS, tuned_pid, tuned_pids_markdown
from myoexo.model import TWIN_VERSION
from myoexo.runtime import fits

ROOT = Path(__file__).resolve().parents[1]


@pytest.mark.parametrize("name", sorted(TUNED_PIDS))
def test_each_tuned_pid_is_its_file_with_provenance(name):
    t = TUNED_PIDS[name]
    doc = json.loads((ROOT / "myoexo" / t.record).read_text())
    record, provenance = doc["result"], doc["provenance"]
    assert record["zn_gains"] == {"kp": t.gains.kp, "ki": t.gains.ki, "kd": t.gains.kd}
    assert record["ultimate_gain_per_rad"] == t.ultimate_gain_per_rad
    assert record["ultimate_period_s"] == t.ultimate_period_s
    assert record["settings"]["feedback"] == t.feedback
    assert record["settings"].get("latency_s", 0.0) == t.latency_s
    assert provenance["command"] == t.command and f"--write {name}" in t.command
    assert set(provenance) >= {"subject", "twin_version", "versions", "date"}
    # tuned on today's twin: a tuning of another twin version is not today's fair baseline
    assert t.twin_version == TWIN_VERSION


def test_tune_pid_write_records_its_provenance(tmp_path, monkeypatch, capsys):
    monkeypatch.setattr(fits, "fits_dir", lambda: tmp_path)
    argv = [
        "twin",
        "tune-pid",
        "--feedback",
        "exo",
        "--rel-tol",
        "0.3",
        "--quiet",
        "--write",
        "mine",
    ]
    assert cli.main(argv) == 0
    assert (tmp_path / "pid_tuned_mine.json").is_file()
    entry = tuned.TunedPID.from_fit("mine")
    assert entry.name == "mine" and entry.feedback == "exo"
    assert entry.command == "myoexo twin tune-pid --feedback exo --rel-tol 0.3 --write mine"
    assert entry.twin_version == TWIN_VERSION
    assert cli.main(["twin", "tune-pid", "--rel-tol", "0.3", "--quiet", "--write", "no good"]) == 2
    assert "must be a word" in capsys.readouterr().err


def test_the_latency_tuning_reruns_to_its_record():
    t = TUNED_PIDS["latency"]
    result = zn.tune(zn.ZieglerNicholsSettings(feedback=t.feedback, latency_s=t.latency_s))
    assert result.ultimate_gain == pytest.approx(t.ultimate_gain_per_rad, rel=1e-9)
    assert result.gains.kp == pytest.approx(t.gains.kp, rel=1e-9)
    # the latency lowers the ultimate gain: the loop oscillates at a quarter of the gain
    assert t.ultimate_gain_per_rad < 0.5 * TUNED_PIDS["exo"].ultimate_gain_per_rad


def test_tuned_spec_sets_gains_and_feedback_and_other_options_apply():
    config = pid_config(parse_controller_spec("pid:tuned=exo").options)
    assert config.feedback == "exo" and config.gains == TUNED_PIDS["exo"].gains
    config = pid_config(parse_controller_spec("pid:tuned=latency,kp=3,ramp_s=0.5").options)
    assert config.gains.kp == 3.0 and config.gains.ki == TUNED_PIDS["latency"].gains.ki
    assert config.ramp_s == 0.5 and config.feedback == "knee"
    with pytest.raises(ValueError, match="accepted"):
        tuned_pid("nope")
    with pytest.raises(ValueError, match="accepted"):
        parse_controller_spec("pid:tuned=nope")


def test_latency_setting_is_validated_and_markdown_lists_every_entry():
    with pytest.raises(ValueError, match="latency_s"):
        zn.ZieglerNicholsSettings(latency_s=-0.01)
    table = tuned_pids_markdown()
    for name in TUNED_PIDS:
        assert f"`pid:tuned={name}`" in table
