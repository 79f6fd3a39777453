"""``myoexo demo``: one table, then a paragraph of what the run found, made of the table's
numbers; a bad option is one line with exit status 2."""

from __future__ import annotations

import re

import pandas as pd
import pytest

from myoexo.cli import main
from myoexo.studies.demo import DEMO_CONTROLLERS, findings

#: A row of the printed table: level, controller, then six cells.
ROW = re.compile(r"^\s*(\d)\s+(\S+)((?:\s+\S+){6})\s*$")


def test_the_default_demo_runs_the_shipped_controllers_against_the_papers_pid():
    assert {
        "pid",
        "pid:ramp_s=1",
        "impedance",
        "residual",
        "sac",
        "guard:sac",
        "student_exo",
        "guard:student_exo",
        "student_fine",
        "student_knee",
    } <= set(DEMO_CONTROLLERS)
    assert "oracle" not in " ".join(DEMO_CONTROLLERS)


def test_the_demo_prints_one_table_and_a_paragraph_of_its_numbers(tmp_path, capsys):
    controllers = ["pid", "pid:ramp_s=1", "impedance", "sac"]  # impedance: not learned
    argv = ["demo", "--subjects", "1", "--controllers", *controllers, "--workers", "1"]
    argv += ["--out", str(tmp_path / "demo"), "--no-progress"]
    assert main(argv) == 0
    lines = capsys.readouterr().out.splitlines()

    headers = [i for i, line in enumerate(lines) if line.split()[:2] == ["level", "controller"]]
    assert len(headers) == 1  # one table
    rows = [m for line in lines if (m := ROW.match(line))]
    assert len(rows) == 4 * len(controllers)
    assert {(int(m[1]), m[2]) for m in rows} == {(lv, c) for lv in range(4) for c in controllers}
    cells = {cell for m in rows for cell in m[3].split()}
    assert all(m[3].split()[1] == "1/1" or m[3].split()[1] == "0/1" for m in rows)

    # the output ends with the paragraph and the command of the full protocol (its duration
    # at this run's pace: every episode was computed now)
    command = f"myoexo evaluate --controllers {' '.join(controllers)} --report"
    assert re.fullmatch(
        re.escape(command) + r"   # ~\d+\.\d h at this run's pace", lines[-1].strip()
    )
    last_row = max(i for i, line in enumerate(lines) if ROW.match(line))
    paragraph = " ".join(lines[last_row + 1 : -1]).strip()
    assert paragraph.startswith("On this 1 subject per level, the")
    for claim in (
        r"smallest mean \|final error\| went to ([^\s,]+)",
        r"lowest mean peak interaction torque .*? went to ([^\s,]+)",
        r"smallest \|final error\| of a learned controller .*? went to (sac)",
    ):
        named = re.search(claim, paragraph)
        assert named and named[1] in controllers, claim
    assert "1000 subjects per level, 95 % intervals" in paragraph
    numbers = re.findall(r"\d+\.\d+", paragraph)
    assert numbers and set(numbers) <= cells  # every number it quotes is in the table


def _rows(values):
    columns = ["level", "controller", "abs_final_error_deg", "peak_torque_nm"]
    return pd.DataFrame(values, columns=columns)


def test_findings_name_the_winners_per_level_against_the_reference():
    rows = _rows(
        [
            (0, "pid", 0.001, 100.6),
            (0, "pid:ramp_s=1", 0.004, 63.9),
            (0, "sac", 6.43, 50.0),  # least torque, but 6 deg short: not a torque winner
            (1, "pid", 0.03, 101.0),
            (1, "pid:ramp_s=1", 0.02, 76.2),
            (1, "sac", 0.91, 102.6),
        ]
    )
    text = " ".join(findings(rows, "pid", ["sac"], subjects=5).split())
    # ties at the printed precision are named together; the reference's value is quoted
    assert (
        "smallest mean |final error| went to pid and pid:ramp_s=1 at level 0 (0.00 deg); "
        "pid:ramp_s=1 at level 1 (0.02 deg vs pid's 0.03)." in text
    )
    assert (
        "within 1 deg of pid's |final error| went to pid:ramp_s=1 at levels 0 and 1 "
        "(63.9 and 76.2 Nm vs pid's 100.6 and 101.0)." in text
    )
    assert (
        "learned controller went to sac at levels 0 and 1 (6.43 and 0.91 deg vs pid's 0.00 "
        "and 0.03)." in text
    )
    assert text.startswith("On these 5 subjects per level,")


@pytest.mark.parametrize(
    ("argv", "message"),
    [
        (["--subjects", "0"], "subjects"),
        (["--workers", "0"], "--workers = 0 must be >= 1"),
        (["--bound-subjects", "2"], "--bound-subjects"),
    ],
)
def test_a_bad_option_is_one_line_and_exit_status_2(argv, message, tmp_path, capsys):
    try:
        status = main(["demo", *argv, "--out", str(tmp_path / "demo")])
    except SystemExit as stop:  # argparse's own errors
        status = stop.code
    assert status == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("myoexo demo: error:") and message in line


def test_help(capsys):
    with pytest.raises(SystemExit) as stop:
        main(["demo", "--help"])
    assert stop.value.code == 0
    out = capsys.readouterr().out
    assert "--subjects" in out and "--controllers" in out and "--report" in out
