"""Configuration fields (myoexo.runtime.fields): one declaration gives the check, the option,
its help and the one-line error under the option's name."""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

import pytest

from myoexo.cli import ArgumentParser, main
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    add_positional,
    check_fields,
    convert,
    from_options,
    option,
    option_words,
    parse_assignments,
)


@dataclass(frozen=True)
class Demo:
    subjects: int = option(6, "subjects per level", low=1, high=100)
    duration_s: float = option(2.0, "episode length", low=0.0, above=True, unit="s")
    mode: str = option("fast", "how", choices=("fast", "slow"))
    levels: tuple[int, ...] = option((1, 2), "levels", low=0, high=3)
    noisy: bool = option(False, "add noise")
    out: Path | None = option(None, "where to write", folder=True)
    hidden: int = option(3, "not on the command line", flag="")
    ceiling_nm: float | None = option(5.0, "a bound (none: no bound)", low=0.0, above=True)

    def __post_init__(self) -> None:
        check_fields(self)


def _parser() -> argparse.ArgumentParser:
    parser = ArgumentParser(prog="demo")
    add_options(parser, Demo)
    return parser


def test_defaults_round_trip_through_the_command_line():
    assert from_options(Demo, _parser().parse_args([])) == Demo()


def test_each_field_is_an_option_of_its_own_name():
    args = _parser().parse_args(
        ["--subjects", "9", "--duration-s", "0.5", "--mode", "slow", "--levels", "0", "3",
         "--noisy"]
    )  # fmt: skip
    assert from_options(Demo, args) == Demo(9, 0.5, "slow", (0, 3), True)
    assert not hasattr(args, "hidden")


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"subjects": 0}, "Demo.subjects = 0 is outside [1, 100]"),
        ({"subjects": 2.5}, "Demo.subjects = 2.5 is not a whole number"),
        ({"duration_s": 0.0}, "Demo.duration_s = 0.0 must be > 0 s"),
        ({"duration_s": float("nan")}, "Demo.duration_s = nan must be > 0 s"),
        ({"mode": "medium"}, "Demo.mode = 'medium' is not one of fast, slow"),
        ({"levels": (1, 4)}, "Demo.levels = (1, 4) is outside [0, 3]"),
    ],
)
def test_a_bad_value_names_the_field_and_what_it_accepts(kwargs, message):
    with pytest.raises(FieldError) as err:
        Demo(**kwargs)
    assert str(err.value) == message
    assert isinstance(err.value, ValueError)


def test_none_is_accepted_where_the_fields_type_admits_it():
    assert Demo(ceiling_nm=None).ceiling_nm is None
    with pytest.raises(FieldError, match=r"ceiling_nm = 0\.0 must be > 0"):
        Demo(ceiling_nm=0.0)
    with pytest.raises(FieldError, match="subjects = None"):
        Demo(subjects=None)  # type: ignore[arg-type]
    for raw, value in (("none", None), ("3", 3.0)):
        args = _parser().parse_args(["--ceiling-nm", raw])
        assert from_options(Demo, args).ceiling_nm == value


def test_help_shows_each_fields_doc_and_default():
    text = " ".join(_parser().format_help().split())
    assert "--subjects SUBJECTS subjects per level (default: 6)" in text
    assert "--duration-s S episode length (default: 2 s)" in text
    assert "how: fast, slow (default: fast)" in text
    assert "--hidden" not in text


def test_an_output_folder_option_refuses_a_file_before_any_work(tmp_path, capsys):
    a_file = tmp_path / "f"
    a_file.write_text("x")
    with pytest.raises(SystemExit) as stop:
        _parser().parse_args(["--out", str(a_file / "sub")])
    assert stop.value.code == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert "is under a file" in line and line.startswith("demo: error: argument --out")


def test_a_positional_argument_is_a_field_without_an_option():
    @dataclass(frozen=True)
    class Copy:
        source: Path = option(doc="file to copy", flag="")
        times: int = option(1, "copies", low=1)

    parser = ArgumentParser(prog="copy")
    add_positional(parser, Copy, "source")
    add_options(parser, Copy)
    args = parser.parse_args(["a.txt", "--times", "2"])
    assert from_options(Copy, args, source=args.source) == Copy(Path("a.txt"), 2)
    assert "SOURCE file to copy" in " ".join(parser.format_help().split())


def test_a_short_letter_and_a_const_are_spellings_of_the_same_option():
    @dataclass(frozen=True)
    class Export:
        verbose: int = option(1, "how much it tells", low=0, short="v")
        quiet: bool = option(False, "no per-epoch lines", short="q")
        ship: str | None = option(None, "into the package as NAME", metavar="NAME", const="sac")

    parser = ArgumentParser(prog="export")
    add_options(parser, Export)
    assert from_options(Export, parser.parse_args([])) == Export(1, False, None)
    assert from_options(Export, parser.parse_args(["-v", "2", "-q", "--ship"])) == Export(
        2, True, "sac"
    )
    assert from_options(Export, parser.parse_args(["--verbose", "0", "--ship", "x"])) == Export(
        0, False, "x"
    )
    assert from_options(Export, parser.parse_args(["--no-quiet"])).quiet is False
    assert "-v VERBOSE, --verbose VERBOSE" in parser.format_help()
    with pytest.raises(ValueError, match="one letter"):
        option(1, "bad", short="vv")


def test_the_command_line_names_the_option_not_the_class(capsys):
    assert main(["twin", "validate", "--subjects", "0"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line == "myoexo twin validate: error: --subjects = 0 is outside [1, 10000]"


@pytest.mark.parametrize(
    ("raw", "tp", "value"),
    [
        ("3", int, 3),
        ("0.5", float, 0.5),
        ("none", float | None, None),
        ("yes", bool, True),
        ("0", bool, False),
        ("a,b", tuple[str, ...], ("a", "b")),
        ("1,2", tuple[int, ...], (1, 2)),
        ("inter:-0.5,act:-0.2", dict[str, float], {"inter": -0.5, "act": -0.2}),
        ("2", int | str, 2),
        ("random", int | str, "random"),
    ],
)
def test_convert_reads_text_as_the_fields_type(raw, tp, value):
    assert convert(raw, tp) == value


@pytest.mark.parametrize(("raw", "tp"), [("x", int), ("maybe", bool), ("a:b", dict[str, float])])
def test_convert_refuses_text_of_another_type(raw, tp):
    with pytest.raises(ValueError, match="field"):
        convert(raw, tp, "field")


def test_parse_assignments_is_the_one_name_value_reader():
    assert parse_assignments("kp=7, feedback=exo") == {"kp": "7", "feedback": "exo"}
    assert parse_assignments(["a=1", "b="]) == {"a": "1", "b": ""}
    with pytest.raises(ValueError, match="expected NAME=VALUE"):
        parse_assignments("kp")
    with pytest.raises(ValueError, match="given twice"):
        parse_assignments("kp=1,kp=2")


def _round_trip(settings, **fixed):
    parser = argparse.ArgumentParser()
    add_options(parser, type(settings))
    words = option_words(settings)
    return words, from_options(type(settings), parser.parse_args(words), **fixed)


def test_option_words_give_the_settings_back():
    settings = Demo(
        subjects=9,
        duration_s=0.1 + 0.2,  # not short in %g: written in full
        mode="slow",
        levels=(0, 3),
        noisy=True,
        hidden=7,  # no option: never written
        ceiling_nm=None,
    )
    words, back = _round_trip(settings, hidden=7)
    assert back == settings
    assert "--hidden" not in words and "--out" not in words  # the default is not written
    assert words[words.index("--ceiling-nm") + 1] == "none"
    assert words[words.index("--duration-s") + 1] == repr(0.1 + 0.2)
    assert option_words(Demo()) == []


def _recorded_settings():
    from myoexo.control.ziegler_nichols import ZieglerNicholsSettings
    from myoexo.policies.student import FinePositioning
    from myoexo.studies.knee_estimator import KneeEstimatorSettings
    from myoexo.studies.recovery import RecoverySettings
    from myoexo.studies.settling_bound import SettlingBoundSettings

    return [
        ZieglerNicholsSettings(feedback="exo", latency_s=0.02),
        RecoverySettings(subjects=3, personalise=False, controllers=("pid", "pid:ramp_s=1")),
        KneeEstimatorSettings(levels=(0, 1), perturbed=False, hidden=(64,), lr=3e-4),
        FinePositioning(speed_limit_deg_s=None, window_deg=1.25),
        SettlingBoundSettings(levels=(3,), subjects=4),
    ]


def test_a_commands_recorded_options_give_its_settings_back():
    """What a record's command says (``option_words``) is what the command ran with."""
    for settings in _recorded_settings():
        assert option_words(settings), settings
        assert _round_trip(settings)[1] == settings


def test_twin_words_give_the_twin_back():
    from myoexo.envs.options import TwinOptions, add_twin_arguments, twin_from_args, twin_words

    twin = TwinOptions(task=(("episode_duration_s", 4.0),), reflex="stretch", robustness=True)
    parser = argparse.ArgumentParser()
    add_twin_arguments(parser)
    words = twin_words(twin)
    assert words == ["--episode-duration-s", "4", "--reflex", "stretch", "--robustness"]
    assert twin_from_args(parser.parse_args(words)) == twin
    assert twin_words(TwinOptions()) == []
    trained = TwinOptions(gentleness="random", reward_weights=(("inter", -0.5),))
    parser = argparse.ArgumentParser()
    add_twin_arguments(parser, observation=True)
    assert twin_from_args(parser.parse_args(twin_words(trained, observation=True))) == trained
