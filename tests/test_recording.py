"""The clinical recording format (:mod:`myoexo.clinical.recording`): a recording round-trips
through its file exactly, every kind of bad file is refused with one line naming the file
and what is wrong, ``myoexo clinic check-recording`` reports a bad file in one line with exit
status 2 and writes nothing, and the synthetic recordings from the twin hold what the tests
they record show (short simulations, one level at a time)."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from myoexo.cli import main
from myoexo.clinical.common import draw_subjects
from myoexo.clinical.recording import (
    COLUMNS,
    EXAMS,
    KEYS,
    MAS_GRADES,
    MASGrading,
    Recording,
    SensorNoise,
    format_markdown,
    read_recording,
    record_from_twin,
    recording_text,
    write_recording,
)
from myoexo.spasticity import DEFAULT_REFLEX

ROOT = Path(__file__).resolve().parents[1]
STRETCH_HEAD = "# test: stretch\n# speed: fast\n# sampling_hz: 100\n"


def _pendulum(n: int = 150, **meta: str) -> Recording:
    t = np.arange(n) * 0.01
    angle = 25.0 + 40.0 * (1.0 - np.exp(-t / 0.4) * np.cos(7.0 * t))
    metadata = {"posture": "seated", "sampling_hz": "100", "side": "right", **meta}
    return Recording(
        "pendulum",
        metadata,
        {"time_s": t, "knee_angle_deg": angle, "knee_velocity_deg_s": np.gradient(angle, t)},
    )


def _stretch_text(rows: list[str], head: str = STRETCH_HEAD, columns: str = "") -> str:
    header = columns or "time_s,knee_angle_deg,torque_nm"
    return head + header + "\n" + "\n".join(rows) + "\n"


def _good_rows(n: int = 20) -> list[str]:
    return [f"{i * 0.01!r},{90.0 - 3.0 * i!r},{-2.0 * i!r}" for i in range(n)]


def _refusal(tmp_path: Path, text: str, name: str = "bad.csv") -> str:
    path = tmp_path / name
    path.write_text(text)
    with pytest.raises(ValueError) as info:
        read_recording(path)
    message = str(info.value)
    assert "\n" not in message  # one line
    assert message.startswith(f"{path}: ")  # naming the file
    return message


# ----------------------------------------------------------------------------- round trip
def test_a_recording_round_trips_exactly(tmp_path):
    recording = _pendulum(note="the patient was relaxed", subject="P-001")
    path = write_recording(recording, tmp_path / "sub" / "pendulum.csv")
    back = read_recording(path)
    assert back == recording
    for name, values in recording.columns.items():
        assert np.array_equal(back.columns[name], values)  # to the last bit
        assert back.columns[name].tobytes() == values.tobytes()
    assert dict(back.metadata) == dict(recording.metadata)
    assert recording_text(back) == path.read_text()
    assert back.samples == 150 and back.duration_s == pytest.approx(1.49)
    assert list(back.frame().columns) == ["time_s", "knee_angle_deg", "knee_velocity_deg_s"]


def test_single_value_recordings_round_trip(tmp_path):
    tardieu = Recording("tardieu", {"r1_deg": 62.5, "r2_deg": 28, "posture": "seated"})
    mas = Recording("mas", {"mas_grade": "1+", "note": "catch at 40 deg"})
    for rec in (tardieu, mas):
        path = write_recording(rec, tmp_path / f"{rec.test}.csv")
        assert read_recording(path) == rec
    assert tardieu.metadata["r1_deg"] == "62.5" and tardieu.metadata["r2_deg"] == "28"
    assert read_recording(tmp_path / "mas.csv").summary() == "mas, grade 1+"


def test_the_columns_are_read_only_and_in_the_tests_order():
    rec = Recording(
        "stretch",
        {"speed": "slow", "sampling_hz": 100},
        {"torque_nm": np.zeros(20), "knee_angle_deg": np.linspace(90, 20, 20),
         "time_s": np.arange(20) / 100},
    )  # fmt: skip
    assert list(rec.columns) == ["time_s", "knee_angle_deg", "torque_nm"]
    with pytest.raises(ValueError):
        rec.columns["torque_nm"][0] = 1.0


# ----------------------------------------------------------------------------- bad files
@pytest.mark.parametrize(
    ("text", "expected"),
    [
        # unknown / missing test
        ("# test: pendlum\n# posture: seated\n", "unknown test 'pendlum'; accepted tests: "
         "pendulum, stretch, tardieu, mas"),
        ("# posture: seated\ntime_s,knee_angle_deg\n", "no '# test: ...' line"),
        # a missing required column, named with the accepted ones
        (_stretch_text([f"{i / 100!r}" for i in range(20)], columns="time_s"),
         "missing column 'knee_angle_deg'; a stretch recording's columns: time_s, "
         "knee_angle_deg (required); torque_nm (optional)"),
        (_stretch_text(_good_rows(), columns="time_s,knee_angle_deg,emg_mv"),
         "unknown column 'emg_mv'"),
        # time not strictly increasing, naming the row
        (_stretch_text([*_good_rows(5), "0.03,75.0,-10.0", *_good_rows(20)[6:]]),
         "time_s is not strictly increasing at row 6 (line 10)"),
        # NaN / inf, naming column and row
        (_stretch_text([*_good_rows(3), "0.03,nan,-6.0", *_good_rows(20)[4:]]),
         "knee_angle_deg is nan at row 4 (line 8)"),
        (_stretch_text([*_good_rows(3), "0.03,81.0,inf", *_good_rows(20)[4:]]),
         "torque_nm is inf at row 4 (line 8)"),
        (_stretch_text([*_good_rows(3), "0.03,,-6.0", *_good_rows(20)[4:]]),
         "knee_angle_deg is empty at row 4 (line 8)"),
        (_stretch_text([*_good_rows(3), "0.03,81 deg,-6.0", *_good_rows(20)[4:]]),
         "knee_angle_deg is '81 deg', not a number at row 4 (line 8)"),
        # radians instead of degrees
        (_stretch_text([f"{i / 100!r},{1.57 - 0.06 * i!r}" for i in range(20)],
                       columns="time_s,knee_angle_deg"),
         "knee_angle_deg looks like radians"),
        # out of range
        (_stretch_text([*_good_rows(3), "0.03,181.0,-6.0", *_good_rows(20)[4:]]),
         "knee_angle_deg = 181 at row 4 (line 8) is outside [-20, 160] deg"),
        # too few samples, too short, irregular sampling
        (_stretch_text(_good_rows(4)), "too few samples: 4 rows, a stretch recording needs "
         "at least 10"),
        (_stretch_text([f"{i / 1000!r},{90.0 - i!r}" for i in range(20)],
                       head=STRETCH_HEAD.replace("100", "1000"), columns="time_s,knee_angle_deg"),
         "too short: 0.019 s, a stretch recording spans at least 0.1 s"),
        (_stretch_text([*_good_rows(10), *[r.replace(f"{i / 100!r},", f"{i / 100 + 0.01!r},", 1)
                                           for i, r in enumerate(_good_rows(20)[10:], 10)]]),
         "irregular sampling at row 11 (line 15): 0.02 s after the previous sample, "
         "sampling_hz 100 gives 0.01 s +- 10%"),
        # metadata
        ("# test: mas\n# mas_grade: 5\n", "metadata mas_grade = '5' is not one of 0, 1, 1+, "
         "2, 3, 4"),
        ("# test: mas\n# mas_grade: 1.5\n", "mas_grade = '1.5'"),
        ("# test: mas\n", "missing metadata '# mas_grade: ...'"),
        ("# test: mas\n# mas_grade: 2\n# sampling_hz: 100\n", "metadata key 'sampling_hz' is "
         "not one of a mas recording's"),
        ("# test: mas\n# mas_grade: 2\n# grade: 2\n", "unknown metadata key 'grade'"),
        ("# test: mas\n# mas_grade: 2\n# mas_grade: 3\n", "line 3: metadata 'mas_grade' "
         "given twice (first on line 2)"),
        ("# test: mas\n# mas grade 2\n", "line 2: '# mas grade 2' is not a '# key: value' "
         "line"),
        ("# test: mas\n# mas_grade: 2\ntime_s\n", "line 3: a mas recording holds no rows"),
        (STRETCH_HEAD.replace("# speed: fast\n", ""), "missing metadata '# speed: ...'"),
        (STRETCH_HEAD.replace("100", "fast"), "metadata sampling_hz = 'fast' is not a number"),
        (STRETCH_HEAD, "no header row"),
        # the Tardieu angles
        ("# test: tardieu\n# r1_deg: 20\n# r2_deg: 40\n", "r1_deg = 20 is below r2_deg = 40"),
        ("# test: tardieu\n# r1_deg: 200\n# r2_deg: 40\n", "r1_deg = '200' is not a number "
         "in [-20, 160] deg"),
        ("# test: tardieu\n# r1_deg: 1.4\n# r2_deg: 0.3\n", "look like radians"),
        ("# test: tardieu\n# r1_deg: 60\n", "missing metadata '# r2_deg: ...'"),
        # a row of the wrong width
        (_stretch_text([*_good_rows(3), "0.03,81.0", *_good_rows(20)[4:]]),
         "row 4 (line 8): 2 values under 3 columns"),
    ],
)  # fmt: skip
def test_a_bad_file_is_refused_with_one_line_naming_the_problem(tmp_path, text, expected):
    message = _refusal(tmp_path, text)
    assert expected in message


def test_radian_angles_out_of_a_pendulum_get_the_hint(tmp_path):
    rows = [f"{i / 100!r},{0.4 + 1.2 * (1 - float(np.cos(i / 10))) / 2!r}" for i in range(150)]
    text = "# test: pendulum\n# posture: seated\n# sampling_hz: 100\ntime_s,knee_angle_deg\n"
    message = _refusal(tmp_path, text + "\n".join(rows) + "\n")
    assert "radians" in message and "degrees" in message


def test_the_reader_never_fixes_a_file(tmp_path):
    good = _stretch_text(_good_rows())
    path = tmp_path / "ok.csv"
    path.write_text(good)
    read_recording(path)
    assert path.read_text() == good  # left as it was
    # a file that differs from a good one by one sample is refused, not repaired
    _refusal(tmp_path, good.replace("\n0.05,", "\n0.0500001,").replace(",75.0,", ",nan,"))


def test_a_recording_made_in_code_is_checked_too():
    with pytest.raises(ValueError, match="unknown test 'walk'"):
        Recording("walk")
    with pytest.raises(ValueError, match="time_s is not strictly increasing at row 3"):
        Recording(
            "stretch",
            {"speed": "slow", "sampling_hz": "100"},
            {"time_s": [0.0, 0.01, 0.01, *np.arange(3, 20) / 100],
             "knee_angle_deg": np.linspace(90, 20, 20)},
        )  # fmt: skip
    with pytest.raises(ValueError, match="columns differ in length"):
        Recording(
            "stretch",
            {"speed": "slow", "sampling_hz": "100"},
            {"time_s": np.arange(20) / 100, "knee_angle_deg": np.ones(19)},
        )


def test_a_missing_file_is_a_user_error(tmp_path):
    with pytest.raises(FileNotFoundError):
        read_recording(tmp_path / "none.csv")


# ----------------------------------------------------------------------------- the CLI
def test_check_recording_prints_one_line_per_file(tmp_path, capsys):
    a = write_recording(_pendulum(), tmp_path / "a.csv")
    b = write_recording(Recording("mas", {"mas_grade": "2"}), tmp_path / "b.csv")
    assert main(["clinic", "check-recording", str(a), str(b)]) == 0
    out = capsys.readouterr().out.splitlines()
    assert len(out) == 2
    assert out[0].startswith(f"{a}: pendulum, 150 samples at 100 Hz, 1.49 s, knee_angle_deg")
    assert out[1] == f"{b}: mas, grade 2"


def test_check_recording_refuses_a_bad_file_in_one_line_and_writes_nothing(tmp_path, capsys):
    good = write_recording(_pendulum(), tmp_path / "good.csv")
    bad = tmp_path / "bad.csv"
    bad.write_text("# test: mas\n# mas_grade: 5\n")
    before = sorted(p.name for p in tmp_path.iterdir())
    assert main(["clinic", "check-recording", str(good), str(bad)]) == 2
    captured = capsys.readouterr()
    (line,) = captured.err.splitlines()
    assert line.startswith(f"myoexo clinic check-recording: error: {bad}: metadata mas_grade")
    assert captured.out.splitlines()[0].startswith(f"{good}: pendulum")
    assert sorted(p.name for p in tmp_path.iterdir()) == before
    assert main(["clinic", "check-recording", str(bad), str(tmp_path / "none.csv")]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "2 of 2 files refused; first: " in line


def test_record_refuses_a_posture_the_test_has_not(tmp_path, capsys):
    out = tmp_path / "x.csv"
    argv = ["clinic", "record", "--test", "mas", "--level", "1", "--posture", "reclined"]
    assert main([*argv, "--out", str(out)]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("myoexo clinic record: error: posture 'reclined'")
    assert not out.exists()
    with pytest.raises(SystemExit) as stop:  # --test missing: argparse's one line
        main(["clinic", "record", "--level", "1", "--out", str(out)])
    assert stop.value.code == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith("myoexo clinic record: error: the following arguments are required")
    assert "--test" in line
    assert main(["clinic", "record", "--test", "mas", "--level", "1", "--out", str(out),
                 "--angle-std-deg", "-1"]) == 2  # fmt: skip
    (line,) = capsys.readouterr().err.splitlines()
    assert "--angle-std-deg = -1.0 must be >= 0 deg" in line


# ----------------------------------------------------------------------------- synthetic
def test_a_synthetic_pendulum_starts_near_extension_and_swings():
    from myoexo.clinical.pendulum import SEATED

    params = dataclasses.replace(SEATED, swing_s=2.0)
    rec = record_from_twin("pendulum", 0, 3, params=params)
    angle = rec.columns["knee_angle_deg"]
    assert rec.test == "pendulum" and rec.metadata["posture"] == "seated"
    assert rec.samples == 200 and rec.metadata["sampling_hz"] == "100"
    assert rec.columns["time_s"][0] == 0.0  # the release
    # released near extension (the seated hold, 20 deg, plus the PD's lag), then falls
    # into flexion and turns back
    assert angle[0] < params.start_deg + 15.0
    assert angle.max() - angle[0] > 40.0
    assert angle[-1] < angle.max() - 5.0
    assert rec.columns["knee_velocity_deg_s"].max() > 100.0
    # how it was made, the truth a fit is held against
    meta = rec.metadata
    assert (meta["synthetic_level"], meta["synthetic_subject_seed"]) == ("0", "3")
    assert meta["synthetic_reflex"] == DEFAULT_REFLEX and meta["device"] == "exo"
    assert rec.synthetic_subject() == draw_subjects((0,), 3)[0]
    assert meta["synthetic_noise"] == SensorNoise().text()


def test_a_fast_stretch_resists_more_at_level_3_than_at_level_0(tmp_path):
    def mid_range_resistance(level: int) -> float:
        rec = record_from_twin("stretch-fast", level, 5)
        assert rec.metadata["speed"] == "fast" and rec.metadata["speed_rad_s"] == "3"
        assert rec.synthetic_subject() == draw_subjects((level,), 5)[level]  # the truth
        angle, torque = rec.columns["knee_angle_deg"], rec.columns["torque_nm"]
        moving = (angle < 80.0) & (angle > 30.0)
        assert moving.sum() >= 5
        return float(np.mean(-torque[moving]))  # the extension's resisting torque

    level0, level3 = mid_range_resistance(0), mid_range_resistance(3)
    assert level3 > level0 + 10.0 * SensorNoise().torque_std_nm


def test_the_same_seed_gives_the_same_file_and_another_seed_another(tmp_path):
    paths = []
    for name, seed in (("a", 11), ("b", 11), ("c", 12)):
        rec = record_from_twin("stretch-fast", 2, seed)
        paths.append(write_recording(rec, tmp_path / f"{name}.csv"))
        assert read_recording(paths[-1]) == rec
    a, b, c = (p.read_bytes() for p in paths)
    assert a == b
    assert a != c


def test_the_noise_is_seeded_and_can_be_switched_off():
    quiet = SensorNoise(angle_std_deg=0.0, velocity_std_deg_s=0.0, torque_std_nm=0.0)
    clean = record_from_twin("stretch-fast", 0, None, noise=quiet)
    noisy = record_from_twin("stretch-fast", 0, None)
    diff = noisy.columns["knee_angle_deg"] - clean.columns["knee_angle_deg"]
    assert 0.3 < float(np.std(diff)) < 0.7  # 0.5 deg
    assert "synthetic_subject_seed" not in clean.metadata  # the nominal subject
    coarse = record_from_twin("stretch-fast", 0, None, noise=SensorNoise(torque_step_nm=0.5))
    assert np.allclose(coarse.columns["torque_nm"] * 2, np.round(coarse.columns["torque_nm"] * 2))


def test_synthetic_tardieu_and_mas_values(tmp_path):
    tardieu = record_from_twin("tardieu", 2, 4)
    r1, r2 = tardieu.number("r1_deg"), tardieu.number("r2_deg")
    assert r1 is not None and r2 is not None and r1 >= r2
    assert tardieu.columns == {}
    mas = record_from_twin("mas", 0, 4)
    assert mas.metadata["mas_grade"] == "0"  # level 0 is its own reference
    for rec in (tardieu, mas):
        assert read_recording(write_recording(rec, tmp_path / f"{rec.test}.csv")) == rec


def test_mas_grading_reads_the_exams_row():
    grading = MASGrading()
    row = {"reached_position": 0.9, "onset_position": float("nan"), "resisted_fraction": 0.0,
           "excess_mean_nm": 0.0}  # fmt: skip
    assert grading.grade(row) == "0"
    assert grading.grade({**row, "onset_position": 0.8, "resisted_fraction": 0.2}) == "1"
    assert grading.grade({**row, "onset_position": 0.3, "resisted_fraction": 0.4}) == "1+"
    assert grading.grade({**row, "onset_position": 0.1, "resisted_fraction": 0.9,
                          "excess_mean_nm": 20.0}) == "2"  # fmt: skip
    assert grading.grade({**row, "onset_position": 0.1, "resisted_fraction": 0.9,
                          "excess_mean_nm": 40.0}) == "3"  # fmt: skip
    assert grading.grade({**row, "reached_position": 0.3}) == "4"
    assert {grading.grade(r) for r in [row]} <= set(MAS_GRADES)


def test_record_from_twin_refuses_what_it_cannot_record():
    with pytest.raises(ValueError, match="recordable: pendulum, stretch-slow"):
        record_from_twin("stretch", 1, 0)
    with pytest.raises(ValueError, match="Unknown spasticity level 4"):
        record_from_twin("mas", 4, 0)
    with pytest.raises(ValueError, match="seated only"):
        record_from_twin("tardieu", 1, 0, posture="reclined")
    with pytest.raises(ValueError, match="must be PendulumParams"):
        from myoexo.clinical.mas import MASExamParams

        record_from_twin("pendulum", 1, 0, params=MASExamParams())


def test_record_writes_a_file_the_reader_reads(tmp_path, capsys):
    out = tmp_path / "fast.csv"
    argv = ["clinic", "record", "--test", "stretch-fast", "--level", "1", "--subject-seed", "2"]
    assert main([*argv, "--out", str(out)]) == 0
    assert capsys.readouterr().out.startswith(f"wrote {out}: stretch (fast), ")
    assert read_recording(out) == record_from_twin("stretch-fast", 1, 2)


# ----------------------------------------------------------------------------- the docs
def test_the_docs_examples_are_valid_recordings(tmp_path):
    page = (ROOT / "docs" / "recordings.md").read_text()
    blocks = re.findall(r"```text\n(# test: .*?)```", page, flags=re.S)
    assert len(blocks) == 2
    tests = []
    for i, block in enumerate(blocks):
        path = tmp_path / f"example{i}.csv"
        path.write_text(block)
        tests.append(read_recording(path).test)
    assert tests == ["tardieu", "mas"]
    example = read_recording(ROOT / "docs" / "examples" / "recording_stretch_fast.csv")
    assert example.test == "stretch" and example.metadata["synthetic_level"] == "2"
    lines = len((ROOT / "docs/examples/recording_stretch_fast.csv").read_text().splitlines())
    assert f"of its {lines} lines" in " ".join(page.split())


def test_the_generated_tables_cover_the_format():
    text = format_markdown()
    for column in COLUMNS:
        assert f"| `{column.name}` |" in text
    for key in KEYS:
        assert f"| `{key.key}` |" in text
    for exam in EXAMS:
        assert f"| `{exam.test}` |" in text
        assert set(exam.keys) <= {k.key for k in KEYS}
        assert set(exam.columns) <= {c.name for c in COLUMNS}
