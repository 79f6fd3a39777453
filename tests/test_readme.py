"""The README's Python code runs as written (its blocks in order, in one namespace), and its
shell examples name commands and options that exist."""

from __future__ import annotations

import re
import shlex
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
BLOCK = re.compile(r"```(?P<lang>\w+)\n(?P<code>.*?)```", re.S)


def _blocks(lang: str) -> list[str]:
    return [m["code"] for m in BLOCK.finditer(README.read_text()) if m["lang"] == lang]


def test_the_readmes_python_blocks_run():
    blocks = _blocks("python")
    assert len(blocks) >= 2
    namespace: dict = {}
    for code in blocks:
        exec(compile(code, str(README), "exec"), namespace)
    info = namespace["info"]
    assert {"knee_angle_deg", "interaction_torque_nm", "subject"} <= set(info)
    assert namespace["device_policy"].obs_preset == "exo"


COMMANDS = [ln for b in _blocks("bash") for ln in b.splitlines() if ln.startswith("myoexo ")]


@pytest.mark.parametrize("line", COMMANDS)
def test_the_readmes_myoexo_commands_parse(line, monkeypatch):
    from myoexo.cli import build_parser

    # the plug-in example is the docs' own module; --plugin's environment variable is undone
    monkeypatch.syspath_prepend(str(README.parent / "docs" / "examples"))
    monkeypatch.setenv("MYOEXO_PLUGINS", "")  # recorded, so --plugin's change is undone
    words = shlex.split(line.split("#")[0])[1:]
    words = [w.replace("<run>", "run").replace("<step>", "step") for w in words]
    build_parser().parse_args(words)
