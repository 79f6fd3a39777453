"""The ``myoexo`` command line: every command registered, a user's mistake reported as one
line with exit status 2, a bug (or ``--debug``) with its traceback."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from myoexo import cli
from myoexo.cli import COMMANDS, build_parser, main

USER_MISTAKES = [
    (["train", "--resume", "/nonexistent"], "not a training run folder"),
    (["export-policy", "/nonexistent", "--onnx", "x.onnx"], "holds no checkpoint"),
    (["stretch-test", "--level", "9"], "levels must be among"),
    (["train", "--resume", "/nonexistent", "--set", "n_envs=2"], "drop --set/--run-dir"),
    # a command that stops with SystemExit("export-policy: ...") gets the same format
    (["export-policy", "/nonexistent"], "nothing to do"),
    (["sweep", "/nonexistent.yaml"], "does not exist"),
    (["evaluate", "--backend", "process", "--address", "auto"], "needs --backend ray"),
]


def _subparsers(parser):
    (action,) = [a for a in parser._actions if a.dest == "command"]
    return action.choices


def test_every_command_is_registered():
    assert set(_subparsers(build_parser())) == set(COMMANDS)


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
    assert lines[0].startswith(f"myoexo {argv[0]}: error: ")
    assert message in lines[0]
    assert "Traceback" not in err + out
    assert not list(tmp_path.iterdir())


def test_the_console_script_exits_2_without_traceback():
    proc = subprocess.run(
        [sys.executable, "-m", "myoexo.cli", "stretch-test", "--level", "9"],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, "MYOEXO_DEBUG": ""},
    )
    assert proc.returncode == 2
    (line,) = proc.stderr.splitlines()
    assert line.startswith("myoexo stretch-test: error: ") and "levels must be among" in line
    assert "Traceback" not in proc.stdout + proc.stderr


def test_debug_shows_the_traceback_of_user_errors(monkeypatch):
    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    with pytest.raises(ValueError, match="levels must be among"):
        main(["--debug", "stretch-test", "--level", "9"])
    monkeypatch.setenv("MYOEXO_DEBUG", "1")
    with pytest.raises(ValueError, match="not a training run folder"):
        main(["train", "--resume", "/nonexistent"])


@pytest.mark.parametrize("exc", [KeyError("x"), RuntimeError("bug"), TypeError("bug")])
def test_bugs_keep_their_traceback(monkeypatch, exc):
    import myoexo.clinical.stretch

    def broken(args):
        raise exc

    monkeypatch.delenv("MYOEXO_DEBUG", raising=False)
    monkeypatch.setattr(myoexo.clinical.stretch, "run", broken)
    with pytest.raises(type(exc)):
        main(["stretch-test"])


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
    assert main(["stretch-test"]) == 2
    assert capsys.readouterr().err == "myoexo stretch-test: error: first line second line\n"
