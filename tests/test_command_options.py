"""The options of ``myoexo twin export|calibrate|torque-readings|tune-pid|strap-lag|validate``,
``myoexo frontier``, ``myoexo report``, ``myoexo video``, ``myoexo evaluate``,
``myoexo demo`` and ``myoexo results``: each is a field of the
command's config (:mod:`myoexo.runtime.fields`), its defaults are the config's, and a bad
value is one line naming the option typed, exit status 2, before any work."""

from __future__ import annotations

import argparse
from pathlib import Path

import pytest

from myoexo.cli import ArgumentParser, main
from myoexo.control.ziegler_nichols import TuningOutput, ZieglerNicholsSettings
from myoexo.evaluation.cli import EvaluationRunOptions
from myoexo.evaluation.report import ReportConfig
from myoexo.evaluation.results import CollectOptions, GoalsOptions, TablesOptions
from myoexo.model.export import ExportConfig
from myoexo.runtime.fields import Execution, from_options
from myoexo.studies import calibrate as cal
from myoexo.studies.demo import DemoConfig
from myoexo.studies.frontier import FrontierConfig
from myoexo.studies.settling_bound import SettlingBoundSettings
from myoexo.studies.strap_lag import StrapLagOutput, StrapLagSettings
from myoexo.studies.torque_readings import TorqueReadingsConfig
from myoexo.studies.validate import ValidationConfig, ValidationOutput
from myoexo.viz.video import VideoConfig, VideoJob


def _parser(module_name: str) -> argparse.ArgumentParser:
    import importlib

    parser = ArgumentParser(prog="myoexo x")
    importlib.import_module(module_name).add_arguments(parser)
    return parser


@pytest.mark.parametrize(
    ("module", "configs"),
    [
        ("myoexo.studies.calibrate", (cal.CalibrationConfig,)),
        ("myoexo.studies.torque_readings", (TorqueReadingsConfig,)),
        ("myoexo.control.ziegler_nichols", (ZieglerNicholsSettings, TuningOutput)),
        ("myoexo.studies.strap_lag", (StrapLagSettings, StrapLagOutput)),
        ("myoexo.studies.settling_bound", (SettlingBoundSettings,)),
        ("myoexo.studies.frontier", (FrontierConfig, Execution)),
        ("myoexo.viz.video", (VideoJob, VideoConfig)),
        ("myoexo.evaluation.cli", (EvaluationRunOptions, Execution)),
        ("myoexo.studies.demo", (DemoConfig, Execution)),
        ("myoexo.studies.validate", (ValidationConfig, ValidationOutput)),
    ],
)
def test_no_option_given_is_the_configs_defaults(module, configs):
    args = _parser(module).parse_args([])
    for config in configs:
        assert from_options(config, args) == config()


def test_a_positional_argument_is_a_field_too():
    args = _parser("myoexo.model.export").parse_args(["twin.xml", "--no-exo"])
    assert from_options(ExportConfig, args, output=args.output) == ExportConfig(
        Path("twin.xml"), False
    )
    args = _parser("myoexo.evaluation.report").parse_args(["run", "--bound", "oracle"])
    config = from_options(ReportConfig, args, dir=args.dir)
    assert (str(config.dir), config.out, str(config.bound)) == ("run", None, "oracle")


def test_the_results_sub_commands_are_their_options_classes():
    parser = _parser("myoexo.evaluation.results")
    args = parser.parse_args(["collect", "eval", "set", "--update"])
    assert from_options(CollectOptions, args, eval_dir=args.eval_dir, dest=args.dest) == (
        CollectOptions(Path("eval"), Path("set"), update=True)
    )
    args = parser.parse_args(["tables", "set"])
    assert from_options(TablesOptions, args, set=args.set) == TablesOptions(Path("set"))
    argv = ["goals", "nominal", "perturbed", "--controller", "student", "--teacher", "sac"]
    args = parser.parse_args(argv)
    goals = from_options(GoalsOptions, args, nominal=args.nominal, perturbed=args.perturbed)
    assert goals == GoalsOptions(Path("nominal"), Path("perturbed"), "student", "sac")
    assert goals.device_baseline == "pid:tuned=exo"
    with pytest.raises(SystemExit):  # --controller and --teacher are required
        parser.parse_args(argv[:3])


#: A paced residual base on the command line (its durations follow).
PACED_TRAIN = ["policy", "train", "--residual-base", "pid:reference=minjerk", "--residual-pace-s"]

BAD = [
    (["twin", "calibrate", "--subjects", "1"], "--subjects = 1 must be >= 2"),
    (["twin", "calibrate", "--delay-s", "-0.1"], "--delay-s = -0.1 is outside [0, 1] s"),
    (
        ["twin", "calibrate", "--reflex", "persistent", "--level1-fraction", "2"],
        "--level1-fraction = 2.0 is outside [0, 1]",
    ),
    (["twin", "calibrate", "--reflex", "nope"], "--reflex = 'nope' has no fit; fits: stretch"),
    (["twin", "torque-readings", "--subjects", "1"], "--subjects = 1 is outside [2, 10000]"),
    (["twin", "torque-readings", "--seed", "0"], "that is the evaluation root"),
    (["twin", "tune-pid", "--latency-s", "2"], "--latency-s = 2.0 is outside [0, 1] s"),
    (
        ["twin", "tune-pid", "--target-angle-deg", "200"],
        "--target-angle-deg = 200.0 is outside [-15, 95] deg",
    ),
    (["twin", "tune-pid", "--write", "no good"], "--write = 'no good' must be a word"),
    (["twin", "tune-pid", "--level", "7"], "argument --level: invalid choice"),
    (["twin", "strap-lag", "--subjects", "0"], "--subjects = 0 is outside [1, 10000]"),
    (["twin", "settling-bound", "--seed", "0"], "that is the evaluation root"),
    (["twin", "settling-bound", "--levels", "4"], "argument --levels: invalid choice"),
    (
        ["policy", "train", "--settling-penalty", "-1"],
        "--settling-penalty = -1.0 is outside [0, 10]",
    ),
    (
        ["policy", "train", "--preset", "ppo", "--settling-penalty", "1"],
        "rewrites stored rewards; ppo keeps no replay buffer",
    ),
    (
        [*PACED_TRAIN, "0.3", "0.6"],
        "paces the base by the gentleness weight: train over the weight range",
    ),
    (["frontier", "--subjects", "0"], "--subjects = 0 must be >= 1"),
    (["frontier", "--accuracy-deg", "0"], "--accuracy-deg = 0.0 must be > 0 deg"),
    (["frontier", "--workers", "0"], "--workers = 0 must be >= 1"),
    (["evaluate", "--workers", "0"], "--workers = 0 must be >= 1"),
    (["evaluate", "--backend", "nope"], "argument --backend: invalid choice"),
    (["video", "--width-px", "8"], "--width-px = 8 must be >= 16 px"),
    (["video", "--out", "episode.avi"], "--out = 'episode.avi' is not a .mp4 or .gif file"),
    (["video", "--level", "4"], "argument --level: invalid choice"),
]


@pytest.mark.parametrize(("argv", "message"), BAD, ids=[" ".join(a) for a, _ in BAD])
def test_a_bad_value_is_one_line_naming_the_option_before_any_work(
    argv, message, tmp_path, monkeypatch, capsys
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    try:
        code = main(argv)
    except SystemExit as stop:  # argparse's own check
        code = stop.code
    assert code == 2
    (line,) = capsys.readouterr().err.splitlines()
    words = 2 if argv[0] in ("twin", "policy") else 1
    assert line.startswith(f"myoexo {' '.join(argv[:words])}: error: ")
    assert message in line, line
    assert not list(tmp_path.iterdir())  # nothing written


def test_calibrate_help_lists_each_models_options_under_its_name(capsys):
    text = _parser("myoexo.studies.calibrate").format_help()
    stretch = text[text.index("--reflex stretch, spindle:") : text.index("--reflex persistent:")]
    assert "--delay-s" in stretch and "--extensor-gain" in stretch and "--sweeps" not in stretch
    assert "--level1-fraction" in text[text.index("--reflex persistent:") :]
