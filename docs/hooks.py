"""mkdocs hooks of the documentation site (``hooks:`` in mkdocs.yml): what the site shows of
the code is generated from the code at build time, never typed twice.

* The API reference: one page per public module of the package, found by walking
  ``myoexo/`` (a module moved between folders, added or removed needs no edit here), under
  ``api/``, with its navigation (the ``API reference`` entry of mkdocs.yml's nav is
  replaced by the tree) and an index page (each module's first docstring line).
* The shipped policies' model cards (``myoexo/policies/MODEL_CARD*.md``) as pages under
  ``model_cards/``, with their nav entry.
* Markers ``<!-- myoexo:NAME -->`` in a page are replaced by a generated block:

  ``observation-table``
      :data:`myoexo.envs.observation.OBS_KEY_DOCS` with each key's size and vector scale
      read from a built twin, and the presets that hold it;
  ``reward-table``
      :data:`myoexo.envs.reward.REWARD_TERMS` with their default weights
      (:data:`myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`);
  ``env-table``
      the registered env ids and their spasticity levels;
  ``tuned-pid-table``
      :data:`myoexo.control.tuned.TUNED_PIDS` beside the paper's gains;
  ``cli-reference``
      every command of :func:`myoexo.cli.build_parser` (sub-commands of commands
      included): its ``--help`` (usage, description, options).
  ``recording-format``
      the clinical recording format's tables (tests, columns, metadata keys) of
      :mod:`myoexo.clinical.recording`.

A marker the hooks do not know fails the build.
"""

from __future__ import annotations

import argparse
import ast
import os
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from mkdocs.config.defaults import MkDocsConfig
from mkdocs.exceptions import PluginError
from mkdocs.structure.files import File, Files
from mkdocs.structure.pages import Page

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "myoexo"
API = "api"
#: The nav entry (title) that the API tree replaces.
API_NAV_TITLE = "API reference"
MARKER = re.compile(r"<!--\s*myoexo:(?P<name>[a-z-]+)\s*-->")
#: Width of the generated ``--help`` texts.
HELP_WIDTH = 96


# -- the package's public modules ---------------------------------------------------------
def public_modules(package: Path = PACKAGE) -> list[str]:
    """Dotted names of the package's public modules and packages, packages first in each
    folder (no name part starting with ``_`` but ``__init__``; no ``__main__``)."""
    names = []
    for path in package.rglob("*.py"):
        parts = list(path.relative_to(package.parent).with_suffix("").parts)
        if parts[-1] == "__init__":
            parts = parts[:-1]
        elif parts[-1].startswith("_"):
            continue
        if any(p.startswith("_") for p in parts):
            continue
        names.append(".".join(parts))
    return sorted(names, key=_tree_order)


def _tree_order(name: str) -> list[tuple[bool, str]]:
    """Sort key: depth first, in each folder its packages before its modules."""
    parts = name.split(".")
    return [(not _is_package(".".join(parts[: i + 1])), p) for i, p in enumerate(parts)]


def _is_package(name: str) -> bool:
    return (PACKAGE.parent / name.replace(".", "/") / "__init__.py").is_file()


def _source(name: str) -> Path:
    base = PACKAGE.parent / name.replace(".", "/")
    return base / "__init__.py" if _is_package(name) else base.with_suffix(".py")


def _summary(name: str) -> str:
    """First sentence-line of the module's docstring, roles reduced to their text."""
    doc = ast.get_docstring(ast.parse(_source(name).read_text())) or ""
    first = " ".join(doc.split("\n\n", 1)[0].split())
    first = re.sub(r":[a-z]+:`~?([^`]+)`", r"\1", first).replace("``", "`")
    return first.replace("|", "\\|")


def api_page(name: str) -> str:
    """The generated page of a module: ``api/myoexo/envs/observation.md``, a package's
    ``.../index.md``."""
    path = f"{API}/{name.replace('.', '/')}"
    return f"{path}/index.md" if _is_package(name) else f"{path}.md"


def _link(target: str, page: str) -> str:
    """Relative link from the generated *page* to the generated *target* page."""
    return os.path.relpath(target, os.path.dirname(page)).replace(os.sep, "/")


def _defined_here(name: str) -> list[str]:
    """Public functions and classes defined in the module's own file (not imported), and its
    constants documented by a ``#:`` comment."""
    source = _source(name).read_text()
    lines = source.splitlines()
    names = []
    for node in ast.parse(source).body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.append(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)) and node.lineno >= 2:
            targets = node.targets if isinstance(node, ast.Assign) else [node.target]
            documented = lines[node.lineno - 2].strip().startswith("#:")
            names += [t.id for t in targets if isinstance(t, ast.Name) and documented]
    return [n for n in names if not n.startswith("_")]


def _api_markdown(name: str) -> str:
    # the module's own heading is the page's title (level 1), so that its identifier is
    # registered for cross-references; a package page shows its docstring, what its
    # __init__ defines itself (its re-exports are documented where they are defined) and
    # its modules
    lines = [f"::: {name}"]
    if _is_package(name):
        page = api_page(name)
        children = [m for m in public_modules() if m.rpartition(".")[0] == name]
        own = _defined_here(name)
        members = "[" + ", ".join(own) + "]" if own else "false"
        lines += ["    options:", f"      members: {members}", ""]
        if children:
            lines += ["## Modules", "", "| module | what it holds |", "|---|---|"]
            lines += [f"| [`{c}`]({_link(api_page(c), page)}) | {_summary(c)} |" for c in children]
    return "\n".join(lines) + "\n"


def _api_index() -> str:
    lines = [
        "# API reference",
        "",
        "Generated from the docstrings of every public module of the package at each build "
        "of the site; the tree follows the package's folders.",
        "",
        "| module | what it holds |",
        "|---|---|",
    ]
    index = f"{API}/index.md"
    lines += [f"| [`{m}`]({_link(api_page(m), index)}) | {_summary(m)} |" for m in public_modules()]
    return "\n".join(lines) + "\n"


def _api_nav(modules: list[str]) -> list[Any]:
    """Nested nav of the API pages: the overview is the section's own page (mkdocs.yml's
    ``navigation.indexes``); a package is a section whose own page is its ``index.md`` and
    whose entries are its modules (by their last name) and sub-packages. The root package's
    modules (``myoexo.cli``) are listed by their full name beside the root package's page,
    before its sub-packages."""

    def children_of(parent: str) -> list[Any]:
        entries: list[Any] = []
        for m in modules:
            if m.rpartition(".")[0] != parent:
                continue
            if _is_package(m):
                entries.append({m: [api_page(m), *children_of(m)]})
            else:
                entries.append({m.rpartition(".")[2]: api_page(m)})
        return entries

    top = modules[0]
    own = [{m: api_page(m)} for m in modules if m.rpartition(".")[0] == top and not _is_package(m)]
    packages = [e for e in children_of(top) if not isinstance(next(iter(e.values())), str)]
    return [f"{API}/index.md", {top: api_page(top)}, *own, *packages]


# -- generated blocks ---------------------------------------------------------------------
def _cell(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _table(header: list[str], rows: list[list[object]]) -> str:
    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(_cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def _scale_text(scales: Any) -> str:
    values = [float(v) for v in scales]
    if len(set(values)) == 1:
        return f"{values[0]:g}"
    return "per entry: " + ", ".join(f"{v:.3g}" for v in values)


def observation_table() -> str:
    from myoexo.envs.config import TaskParams
    from myoexo.envs.observation import OBS_KEY_DOCS, OBS_PRESETS, RAW_KEYS, ObsLayout
    from myoexo.model import build_model

    task = TaskParams()
    model, _ = build_model()
    layout = ObsLayout.of(model, RAW_KEYS, 0.0, task.episode_duration_s)
    rows: list[list[object]] = []
    for doc in OBS_KEY_DOCS:
        size = layout.slices[doc.key].stop - layout.slices[doc.key].start
        scale = layout.vec_scale[layout.slices[doc.key]]
        presets = ", ".join(n for n, keys in OBS_PRESETS.items() if doc.key in keys) or "-"
        rows.append([f"`{doc.key}`", size, doc.meaning, doc.unit, _scale_text(scale), presets])
    sizes = {
        name: sum(layout.slices[k].stop - layout.slices[k].start for k in keys)
        for name, keys in OBS_PRESETS.items()
    }
    total = "; ".join(f"`{name}`: {n} floats" for name, n in sizes.items())
    header = ["key", "size", "meaning", "unit", "scale in the vector", "presets"]
    return _table(header, rows) + f"\n\nVector sizes of the presets: {total}."


def reward_table() -> str:
    from myoexo.envs.config import DEFAULT_REWARD_WEIGHTS
    from myoexo.envs.reward import REWARD_TERMS

    rows: list[list[object]] = []
    for term in REWARD_TERMS:
        weight = DEFAULT_REWARD_WEIGHTS.get(term.key)
        rows.append(
            [
                f"`{term.key}`",
                term.describe(),
                f"{weight:g}" if weight is not None else "not weighted (`rwd_dict` only)",
            ]
        )
    return _table(["key", "term", "default weight"], rows)


def env_table() -> str:
    from myoexo.envs.registration import ENV_LEVELS, MAX_EPISODE_STEPS
    from myoexo.spasticity.levels import RANDOM_LEVEL

    rows: list[list[object]] = []
    for env_id, level in ENV_LEVELS.items():
        shown = "uniform over 0-3, drawn at every reset" if level == RANDOM_LEVEL else level
        rows.append([f"`{env_id}`", shown, "a new random subject at every reset"])
    table = _table(["id", "spasticity level (Modified Ashworth)", "subject"], rows)
    return table + f"\n\nEvery id's episode: {MAX_EPISODE_STEPS} control steps by default."


def _subcommands(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            return dict(action.choices)
    return {}


def cli_reference() -> str:
    from myoexo.cli import build_parser

    saved = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = str(HELP_WIDTH)
    try:
        parser = build_parser()
        lines = ["## `myoexo`", "", "```text", parser.format_help().rstrip(), "```", ""]

        def add(prefix: str, sub: argparse.ArgumentParser, level: int) -> None:
            lines.extend([f"{'#' * level} `{prefix}`", ""])
            lines.extend(["```text", sub.format_help().rstrip(), "```", ""])
            for name, child in _subcommands(sub).items():
                add(f"{prefix} {name}", child, level + 1)

        for name, sub in _subcommands(parser).items():
            add(f"myoexo {name}", sub, 2)
    finally:
        if saved is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = saved
    return "\n".join(lines)


def tuned_pid_table() -> str:
    """The PIDs tuned for their sensors and latency (:mod:`myoexo.control.tuned`)."""
    from myoexo.control.tuned import tuned_pids_markdown

    return tuned_pids_markdown()


def recording_format() -> str:
    """The clinical recording format's tables (:mod:`myoexo.clinical.recording`)."""
    from myoexo.clinical.recording import format_markdown

    return format_markdown()


GENERATORS: dict[str, Callable[[], str]] = {
    "tuned-pid-table": tuned_pid_table,
    "observation-table": observation_table,
    "reward-table": reward_table,
    "env-table": env_table,
    "cli-reference": cli_reference,
    "recording-format": recording_format,
}


# -- the model cards ---------------------------------------------------------------------
def model_cards() -> dict[str, Path]:
    """Page (``model_cards/<policy>.md``) -> the shipped model card it shows
    (``myoexo/policies/MODEL_CARD.md`` is ``sac``'s, ``MODEL_CARD_<name>.md`` ``<name>``'s)."""
    cards = {}
    for path in sorted((PACKAGE / "policies").glob("MODEL_CARD*.md")):
        name = path.stem.removeprefix("MODEL_CARD").lstrip("_") or "sac"
        cards[f"model_cards/{name}.md"] = path
    return cards


def _model_cards_nav() -> list[Any]:
    return [{page.removeprefix("model_cards/")[:-3]: page} for page in model_cards()]


# -- mkdocs events ------------------------------------------------------------------------
#: nav entries (by title, at any depth) that the hooks fill in.
GENERATED_NAV: dict[str, Callable[[], list[Any]]] = {
    API_NAV_TITLE: lambda: _api_nav(public_modules()),
    "Model cards": _model_cards_nav,
}


def _fill_nav(nav: list[Any], found: set[str]) -> None:
    for i, entry in enumerate(nav):
        if not isinstance(entry, dict):
            continue
        for title, value in entry.items():
            if title in GENERATED_NAV:
                nav[i] = {title: GENERATED_NAV[title]()}
                found.add(title)
            elif isinstance(value, list):
                _fill_nav(value, found)


def on_config(config: MkDocsConfig) -> MkDocsConfig:
    found: set[str] = set()
    _fill_nav(config.nav or [], found)
    missing = set(GENERATED_NAV) - found
    if missing:
        raise PluginError(f"mkdocs.yml's nav has no entries {sorted(missing)} to fill in")
    return config


def on_files(files: Files, config: MkDocsConfig) -> Files:
    files.append(File.generated(config, f"{API}/index.md", content=_api_index()))
    for name in public_modules():
        files.append(File.generated(config, api_page(name), content=_api_markdown(name)))
    for page, card in model_cards().items():
        files.append(File.generated(config, page, content=card.read_text()))
    return files


def on_page_markdown(markdown: str, page: Page, config: MkDocsConfig, files: Files) -> str:
    def replace(match: re.Match[str]) -> str:
        name = match["name"]
        if name not in GENERATORS:
            raise PluginError(f"{page.file.src_uri}: unknown marker <!-- myoexo:{name} -->")
        return GENERATORS[name]()

    return MARKER.sub(replace, markdown)
