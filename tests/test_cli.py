"""The ``myoexo`` command line: every command registered, a user's mistake reported as one
line with exit status 2, a bug (or ``--debug``) with its traceback."""

from __future__ import annotations

import argparse
import os
import subprocess
import sys

import pytest

from myoexo import cli
from myoexo.cli import COMMANDS, GROUPS, RENAMED, build_parser, main

USER_MISTAKES = [
    (["policy", "train", "--resume", "/nonexistent"], "not a training run folder"),
    (["policy", "export", "/nonexistent", "--onnx", "x.onnx"], "holds no checkpoint"),
    (["clinic", "stretch", "--velocities-rad-s", "-3"], "--velocities-rad-s = (-3.0,) must be > 0"),
    (["policy", "train", "--resume", "/nonexistent", "--n-envs", "2"], "drop --n-envs"),
    # a command that stops with SystemExit("export-policy: ...") gets the same format
    (["policy", "export", "/nonexistent"], "nothing to do"),
    (["policy", "sweep", "/nonexistent.yaml"], "does not exist"),
    (["evaluate", "--backend", "process", "--address", "auto"], "needs --backend ray"),
]


def _subparsers(parser):
    (action,) = [a for a in parser._actions if isinstance(a, argparse._SubParsersAction)]
    return action.choices


def test_every_command_is_registered():
    top = _subparsers(build_parser())
    for name in COMMANDS:
        group, _, leaf = name.rpartition(" ")
        assert leaf in (_subparsers(top[group]) if group else top)


@pytest.mark.parametrize("old", sorted(RENAMED))
def test_an_earlier_command_name_points_to_its_new_one(old, capsys):
    assert RENAMED[old] in COMMANDS
    assert main([old, "--anything"]) == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line == f"myoexo {old}: error: this command is now 'myoexo {RENAMED[old]}'"


@pytest.mark.parametrize(
    ("argv", "prog", "named"),
    [
        (["evaluate", "--subjcts", "3"], "myoexo evaluate", "--subjcts"),
        (["clinic", "tardieu", "--levls", "1"], "myoexo clinic tardieu", "--levls"),
        (["twin", "calibrat"], "myoexo twin", "calibrat"),
        (["policy"], "myoexo policy", "COMMAND"),
    ],
)
def test_a_command_line_mistake_is_one_line_of_the_command_it_was_given_to(
    argv, prog, named, capsys
):
    with pytest.raises(SystemExit) as stop:
        main(argv)
    assert stop.value.code == 2
    (line,) = capsys.readouterr().err.splitlines()
    assert line.startswith(f"{prog}: error: ") and named in line, line
    assert line.endswith(f"(see '{prog} --help')")


def test_a_command_whose_module_fails_to_import_is_an_error(monkeypatch):
    monkeypatch.setitem(COMMANDS, "broken", ("myoexo._no_such_module", "never built"))
    with pytest.raises(ModuleNotFoundError, match="_no_such_module"):
        build_parser()


@pytest.mark.parametrize(
    ("argv", "message"), USER_MISTAKES, ids=[" ".join(argv) for argv, _ in USER_MISTAKES]
)
def test_user_errors_are_one_line_and_exit_2(argv, message, tmp_path, monkeypatch, capsys):
    monkeypatch.chdir(tmp_path)  # nothing may be written anywhere else
    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    assert main(argv) == 2
    out, err = capsys.readouterr()
    lines = err.splitlines()
    assert len(lines) == 1, err
    command = " ".join(argv[: 2 if argv[0] in GROUPS else 1])
    assert lines[0].startswith(f"myoexo {command}: error: ")
    assert message in lines[0]
    assert "Traceback" not in err + out
    assert not list(tmp_path.iterdir())


def test_the_console_script_exits_2_without_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "myoexo.cli", "clinic", "stretch", "--velocities-rad-s", "-3"],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MYOEXO_DEBUG": ""},
    )
    assert proc.returncode == 2
    (line,) = proc.stderr.splitlines()
    assert line.startswith("myoexo clinic stretch: error: ") and "--velocities-rad-s = " in line
    assert "Traceback" not in proc.stdout + proc.stderr


def test_debug_shows_the_traceback_of_user_errors(monkeypatch):
    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    with pytest.raises(ValueError, match=r"StretchTestParams\.velocities_rad_s = \(-3\.0,\)"):
        main(["--debug", "clinic", "stretch", "--velocities-rad-s", "-3"])
    monkeypatch.setenv("MYOEXO_DEBUG", "1")
    with pytest.raises(ValueError, match="not a training run folder"):
        main(["policy", "train", "--resume", "/nonexistent"])


@pytest.mark.parametrize("exc", [KeyError("x"), RuntimeError("bug"), TypeError("bug")])
def test_bugs_keep_their_traceback(monkeypatch, exc):
    import myoexo.clinical.stretch

    def broken(args):
        raise exc

    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    monkeypatch.setattr(myoexo.clinical.stretch, "run", broken)
    with pytest.raises(type(exc)):
        main(["clinic", "stretch"])


def test_missing_shipped_policy_is_a_user_error():
    from myoexo.control.specs import PolicyUnavailableError

    assert cli.is_user_error(PolicyUnavailableError("no policy file"))
    assert cli.is_user_error(FileNotFoundError(2, "No such file or directory", "x"))
    assert not cli.is_user_error(RuntimeError("bug"))
    assert not cli.is_user_error(KeyError("bug"))


def test_a_multi_line_message_is_printed_on_one_line(monkeypatch, capsys):
    import myoexo.clinical.stretch

    def fails(args):
        raise FileNotFoundError("first line\n  second line\n")

    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    monkeypatch.setattr(myoexo.clinical.stretch, "run", fails)
    assert main(["clinic", "stretch"]) == 2
    assert capsys.readouterr().err == "myoexo clinic stretch: error: first line second line\n"


def test_an_examination_writes_its_table_traces_and_figure_with_out(tmp_path, capsys):
    import pandas as pd

    assert main(["clinic", "tardieu", "--levels", "0", "--out", str(tmp_path)]) == 0
    written = sorted(p.name for p in tmp_path.iterdir())
    assert written == ["tardieu.csv", "tardieu.png", "tardieu_traces.csv"]
    assert list(pd.read_csv(tmp_path / "tardieu.csv").level) == [0]
    assert "wrote " in capsys.readouterr().out
