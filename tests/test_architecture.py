"""The package's layout where import-linter does not look: the contract of pyproject.toml
(``lint-imports``, run by ``make test``: the folders as floors, no import cycle between the
modules or folders of a package) kept in step with docs/architecture.md's table, every
folder in that table, no cycle through a package's own ``__init__.py``, few loose modules at
the top, and the public names kept where users find them."""

from __future__ import annotations

import importlib
import re
import sys
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "myoexo"
ARCHITECTURE = PACKAGE.parent / "docs" / "architecture.md"
PYPROJECT = PACKAGE.parent / "pyproject.toml"


def package_folders(root: Path = PACKAGE) -> set[str]:
    """The first-level folders (``name/``) and loose modules (``name.py``) of a package."""
    folders = {f"{p.parent.name}/" for p in root.glob("*/__init__.py")}
    return folders | {p.name for p in root.glob("*.py") if p.name != "__init__.py"}


def floors(text: str) -> list[str]:
    """The folders of the table of docs/architecture.md, top floor first: the first cell of
    each row, ``name/`` for a folder, ``name.py`` for a loose module, in backticks."""
    rows = re.findall(r"^\|\s*`([A-Za-z_][A-Za-z0-9_]*(?:/|\.py))`\s*\|", text, re.MULTILINE)
    return [row.removesuffix("/").removesuffix(".py") for row in rows] if rows else []


def _importlinter_settings() -> dict:
    """``[tool.importlinter]`` of pyproject.toml (tomli, import-linter's own reader, before
    Python 3.11)."""
    toml = importlib.import_module("tomllib" if sys.version_info >= (3, 11) else "tomli")
    return toml.loads(PYPROJECT.read_text())["tool"]["importlinter"]


def _contract(kind: str) -> dict:
    (contract,) = [c for c in _importlinter_settings()["contracts"] if c["type"] == kind]
    return contract


def test_the_import_contract_is_the_table_of_docs_architecture():
    """``lint-imports`` checks the layers of pyproject.toml; they are the table's floors, in
    its order, over the whole package."""
    layers = _contract("layers")
    assert layers["containers"] == ["myoexo"] and layers.get("exhaustive") is True
    assert layers["layers"] == floors(ARCHITECTURE.read_text())
    assert _contract("acyclic_siblings")["ancestors"] == ["myoexo"]
    assert not _importlinter_settings().get("exclude_type_checking_imports", False)


def cycles_through_own_package(graph) -> list[str]:
    """The imports ``module -> package`` (``from pkg.sub import name`` in ``pkg/sub/x.py``)
    whose package imports the module back, directly or not: a cycle through the package's
    ``__init__.py``, which import-linter's ``acyclic_siblings`` does not see (it looks at
    the imports between the children of a package, not at the package's own file)."""
    return [
        f"{module} -> {package}"
        for module in sorted(graph.modules)
        for package in sorted(graph.find_modules_directly_imported_by(module))
        if module.startswith(f"{package}.")
        and graph.chain_exists(importer=package, imported=module)
    ]


def test_cycles_through_a_package_init_are_found(tmp_path, monkeypatch):
    grimp = pytest.importorskip("grimp")
    pkg = tmp_path / "cyclepkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("from cyclepkg.sub.x import X\n")
    (pkg / "sub" / "x.py").write_text("X = 1\n\ndef f():\n    from cyclepkg.sub import X\n")
    (pkg / "sub" / "y.py").write_text("from cyclepkg.sub import X\n")  # no way back: fine
    monkeypatch.syspath_prepend(str(tmp_path))
    graph = grimp.build_graph("cyclepkg", cache_dir=None)
    assert cycles_through_own_package(graph) == ["cyclepkg.sub.x -> cyclepkg.sub"]


def test_no_import_cycle_through_a_package_init():
    grimp = pytest.importorskip("grimp")
    found = cycles_through_own_package(grimp.build_graph("myoexo", cache_dir=None))
    assert not found, f"import cycles through a package's __init__.py: {found}"


def test_every_folder_is_on_a_floor():
    listed = floors(ARCHITECTURE.read_text())
    on_disk = {f.removesuffix("/").removesuffix(".py") for f in package_folders()}
    missing, gone = sorted(on_disk - set(listed)), sorted(set(listed) - on_disk)
    assert not missing, f"folders missing from docs/architecture.md: {missing}"
    assert not gone, f"docs/architecture.md lists folders that are gone: {gone}"
    assert listed[:2] == ["cli", "studies"], listed


def test_few_loose_modules_at_the_package_top():
    loose = sorted(p.name for p in PACKAGE.glob("*.py") if p.name != "__init__.py")
    assert len(loose) <= 3, loose


@pytest.mark.parametrize(
    "module, names",
    [
        ("myoexo", ["make_env", "load_policy", "ENV_LEVELS"]),
        (
            "myoexo.spasticity",
            [
                "LEVELS",
                "VALID_LEVELS",
                "SpasticityParams",
                "SpasticityStage",
                "SpasticityWrapper",
                "sample_subject",
                "sc_total",
                "sc_total_torch",
                "ReflexModel",
                "register_reflex",
                "get_reflex",
                "CALIBRATION",
                "group_excitations_torch",
            ],
        ),
        ("myoexo.control", ["PID", "Controller", "build_controller"]),
        ("myoexo.viz", ["TwinRenderer", "record_episode"]),
    ],
)
def test_public_names_stay_where_users_find_them(module, names):
    mod = importlib.import_module(module)
    missing = [n for n in names if not hasattr(mod, n)]
    assert not missing


def test_every_cli_command_module_imports_and_routes():
    from myoexo.cli import COMMANDS

    for command, (module, _) in COMMANDS.items():
        mod = importlib.import_module(module)
        assert callable(mod.add_arguments) and callable(mod.run), command
