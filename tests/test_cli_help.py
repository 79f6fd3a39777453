"""Every ``--help`` of the command line prints and exits 0: ``myoexo --help``, each command's
and each sub-command's (read from the parser, so a new command is covered without an edit
here), in-process and through the installed console script; ``myoexo --version``."""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
from importlib import metadata
from pathlib import Path

import pytest

import myoexo
from myoexo.cli import build_parser, main
from myoexo.runtime.docs import DOCS_URL


def _subparsers(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def _all_commands(parser: argparse.ArgumentParser, prefix: tuple[str, ...] = ()):
    """Every command path under *parser*: ``("evaluate",)``, ``("policy", "seeds", "train")``."""
    for name, sub in _subparsers(parser).items():
        yield (*prefix, name)
        yield from _all_commands(sub, (*prefix, name))


COMMAND_PATHS = list(_all_commands(build_parser()))


def _run(argv: list[str], capsys) -> tuple[int, str, str]:
    with pytest.raises(SystemExit) as stop:
        main(argv)
    out, err = capsys.readouterr()
    return stop.value.code, out, err


def _console_script() -> str:
    beside = Path(sys.executable).with_name("myoexo")
    found = str(beside) if beside.is_file() else shutil.which("myoexo")
    if found is None:
        pytest.skip("the myoexo console script is not installed")
    return found


def test_the_parser_has_the_commands_and_their_sub_commands():
    top = _subparsers(build_parser())
    assert 5 <= len(top) <= 10  # grouped by what they act on
    assert {"twin", "clinic", "policy"} <= set(top)
    assert ("policy", "seeds", "train") in COMMAND_PATHS  # a command's own sub-commands are walked


def test_top_level_help(capsys):
    code, out, err = _run(["--help"], capsys)
    assert code == 0, err
    assert out.startswith("usage: myoexo")
    for name in _subparsers(build_parser()):
        assert name in out


@pytest.mark.parametrize("path", COMMAND_PATHS, ids=[" ".join(p) for p in COMMAND_PATHS])
def test_every_command_help(path, capsys):
    code, out, err = _run([*path, "--help"], capsys)
    assert code == 0, err
    assert out.startswith(f"usage: myoexo {' '.join(path)}"), out[:200]
    assert "options:" in out or "optional arguments:" in out
    assert not err


def test_version(capsys):
    code, out, _ = _run(["--version"], capsys)
    assert code == 0
    assert out.strip() == f"myoexo {metadata.version('myoexo')}"
    assert metadata.version("myoexo") == myoexo.__version__


def test_a_literal_percent_in_a_command_help_is_printed(capsys):
    # the one-line help of `policy seeds` says "95 % CIs"; argparse %-formats help texts
    code, out, _ = _run(["policy", "--help"], capsys)
    assert code == 0
    assert "95 % CIs" in " ".join(out.split())


def test_urls_in_help_texts_are_never_broken_across_lines(capsys, monkeypatch):
    monkeypatch.setenv("COLUMNS", "60")  # narrow: a URL is longer than the help column
    code, out, _ = _run(["evaluate", "--help"], capsys)
    assert code == 0
    urls = re.findall(r"https?://\S+", out)
    assert f"{DOCS_URL}/cluster/" in [u.rstrip(").,;") for u in urls]


def test_the_console_script_prints_help_and_version(tmp_path):
    script = _console_script()
    env = {**os.environ, "MYOEXO_DEBUG": ""}
    proc = subprocess.run(
        [script, "--help"], capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith("usage: myoexo") and "evaluate" in proc.stdout
    proc = subprocess.run(
        [script, "--version"], capture_output=True, text=True, timeout=300, cwd=tmp_path, env=env
    )
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.strip() == f"myoexo {metadata.version('myoexo')}"


@pytest.mark.parametrize(
    "path", [(), *COMMAND_PATHS], ids=["myoexo", *map(" ".join, COMMAND_PATHS)]
)
def test_help_points_at_the_site_not_at_repository_files(path, capsys):
    # a wheel has no docs/ folder: help texts link to the documentation site
    code, out, _ = _run([*path, "--help"], capsys)
    assert code == 0
    assert not re.search(r"docs/\w+\.md|README", out), out
