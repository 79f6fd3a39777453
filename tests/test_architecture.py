"""The package's layout: no import cycles between modules (lazy and TYPE_CHECKING imports
included), the folders as floors (no cycle between folders, every import going down the order
that docs/architecture.md's table draws, every folder in that table), few loose modules at
the top, and the public names kept where users find them."""

from __future__ import annotations

import ast
import importlib
import re
from pathlib import Path

import pytest

PACKAGE = Path(__file__).resolve().parents[1] / "myoexo"
ARCHITECTURE = PACKAGE.parent / "docs" / "architecture.md"


def _module_name(path: Path, root: Path) -> str:
    parts = list(path.relative_to(root.parent).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def import_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """Module -> the package's modules it imports, anywhere in its body. ``from a.b import
    c`` counts as importing ``a.b.c`` if that is a module, else ``a.b``; a parent package
    is not counted as imported by its children."""
    files = {_module_name(p, root): p for p in root.rglob("*.py")}
    edges: dict[str, set[str]] = {m: set() for m in files}
    for mod, path in files.items():
        package = mod if path.name == "__init__.py" else mod.rpartition(".")[0]
        for node in ast.walk(ast.parse(path.read_text())):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                base = node.module or ""
                if node.level:
                    parts = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join([*parts, *([base] if base else [])])
                targets = [
                    f"{base}.{a.name}" if f"{base}.{a.name}" in files else base for a in node.names
                ]
            for target in targets:
                while target and target not in files:
                    target = target.rpartition(".")[0]
                if target and target != mod:
                    edges[mod].add(target)
    return edges


def cycles(edges: dict[str, set[str]]) -> list[list[str]]:
    """Strongly connected components with more than one module (Tarjan, iterative)."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found: list[list[str]] = []
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, iter(sorted(edges[root])))]
        index[root] = low[root] = len(index)
        stack.append(root)
        on_stack.add(root)
        while work:
            node, children = work[-1]
            child = next(children, None)
            if child is not None:
                if child not in index:
                    index[child] = low[child] = len(index)
                    stack.append(child)
                    on_stack.add(child)
                    work.append((child, iter(sorted(edges[child]))))
                elif child in on_stack:
                    low[node] = min(low[node], index[child])
                continue
            work.pop()
            if work:
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    member = stack.pop()
                    on_stack.discard(member)
                    component.append(member)
                    if member == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return found


def _folder(module: str) -> str:
    """The first-level folder (or loose module) of a module: ``pkg.a.b`` -> ``a``; ``""`` for
    the package itself."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 else ""


def folder_edges(root: Path = PACKAGE) -> dict[tuple[str, str], list[str]]:
    """``(folder, folder it imports)`` -> the module imports behind that edge.

    A node is a first-level folder or loose module of the package. Every import of
    :func:`import_graph` counts: inside functions, under ``TYPE_CHECKING``, and the
    re-exports of a folder's ``__init__.py`` (they belong to their folder). The package's own
    ``__init__.py`` is no node: importing the package (``import pkg``, ``from pkg import
    name``) counts as importing what that file imports. Imports by name (``importlib``, as
    ``myoexo.cli`` routes its commands) are not seen.
    """
    modules = import_graph(root)
    package = root.name
    front = sorted(t for t in modules[package] if _folder(t))
    edges: dict[tuple[str, str], list[str]] = {}
    for mod, targets in sorted(modules.items()):
        src = _folder(mod)
        if not src:
            continue
        for target in sorted(targets):
            via = [target] if _folder(target) else front
            for t in via:
                if _folder(t) != src:
                    edges.setdefault((src, _folder(t)), []).append(f"{mod} -> {t}")
    return edges


def folder_graph(root: Path = PACKAGE) -> dict[str, set[str]]:
    """Folder -> the folders it imports (:func:`folder_edges`); every folder is a key."""
    nodes = {_folder(_module_name(p, root)) for p in root.rglob("*.py")} - {""}
    graph: dict[str, set[str]] = {n: set() for n in nodes}
    for src, dst in folder_edges(root):
        graph[src].add(dst)
    return graph


def package_folders(root: Path = PACKAGE) -> set[str]:
    """The first-level folders (``name/``) and loose modules (``name.py``) of a package."""
    folders = {f"{p.parent.name}/" for p in root.glob("*/__init__.py")}
    return folders | {p.name for p in root.glob("*.py") if p.name != "__init__.py"}


def floors(text: str) -> list[str]:
    """The folders of the table of docs/architecture.md, top floor first: the first cell of
    each row, ``name/`` for a folder, ``name.py`` for a loose module, in backticks."""
    rows = re.findall(r"^\|\s*`([A-Za-z_][A-Za-z0-9_]*(?:/|\.py))`\s*\|", text, re.MULTILINE)
    return [row.removesuffix("/").removesuffix(".py") for row in rows] if rows else []


def upward_imports(edges: dict[tuple[str, str], list[str]], order: list[str]) -> list[str]:
    """The imports that do not go down ``order`` (top floor first); a folder missing from
    ``order`` is an error of its own (:func:`test_every_folder_is_on_a_floor`)."""
    floor = {name: i for i, name in enumerate(order)}
    return [
        f"{src} -> {dst} ({', '.join(via[:3])})"
        for (src, dst), via in sorted(edges.items())
        if src in floor and dst in floor and floor[src] >= floor[dst]
    ]


def test_the_cycle_finder_finds_a_cycle():
    graph = {"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}
    assert cycles(graph) == [["a", "b", "c"]]
    assert cycles({"a": {"b"}, "b": set()}) == []


def test_the_graph_sees_lazy_and_relative_imports(tmp_path):
    pkg = tmp_path / "pkg"
    (pkg / "sub").mkdir(parents=True)
    (pkg / "__init__.py").write_text("")
    (pkg / "sub" / "__init__.py").write_text("")
    (pkg / "sub" / "x.py").write_text("def f():\n    from pkg.sub import y\n")
    (pkg / "sub" / "y.py").write_text("from . import x\n")
    assert cycles(import_graph(pkg)) == [["pkg.sub.x", "pkg.sub.y"]]


def _fake_package(tmp_path: Path) -> Path:
    """``pkg`` with folders ``a``, ``b``, ``c`` and a loose module ``d``: ``a.x`` imports
    ``b.y`` inside a function, ``b.w`` imports ``a.x`` under ``TYPE_CHECKING`` (a folder cycle
    that no module cycle shows), ``c.z`` imports the package (whose ``__init__.py`` imports
    ``d``), ``c``'s ``__init__.py`` re-exports ``a.x``."""
    pkg = tmp_path / "pkg"
    for folder in ("a", "b", "c"):
        (pkg / folder).mkdir(parents=True)
        (pkg / folder / "__init__.py").write_text("")
    (pkg / "__init__.py").write_text("from pkg.d import VALUE\n")
    (pkg / "d.py").write_text("VALUE = 1\n")
    (pkg / "a" / "x.py").write_text("def f():\n    from pkg.b.y import g\n")
    (pkg / "b" / "y.py").write_text("def g():\n    pass\n")
    (pkg / "b" / "w.py").write_text(
        "from typing import TYPE_CHECKING\n\nif TYPE_CHECKING:\n    from pkg.a.x import f\n"
    )
    (pkg / "c" / "__init__.py").write_text("from pkg.a import x\n")
    (pkg / "c" / "z.py").write_text("import pkg\n")
    return pkg


def test_the_folder_graph_sees_lazy_typing_package_and_init_imports(tmp_path):
    pkg = _fake_package(tmp_path)
    assert cycles(import_graph(pkg)) == []  # no module cycle ...
    graph = folder_graph(pkg)
    assert graph == {"a": {"b"}, "b": {"a"}, "c": {"a", "d"}, "d": set()}
    assert cycles(graph) == [["a", "b"]]  # ... but a folder cycle
    assert folder_edges(pkg)[("c", "d")] == ["pkg.c.z -> pkg.d"]
    assert package_folders(pkg) == {"a/", "b/", "c/", "d.py"}


def test_the_floor_check_finds_an_upward_import(tmp_path):
    edges = folder_edges(_fake_package(tmp_path))
    text = "| folder | what |\n| --- | --- |\n| `c/` | top |\n| `a/` | mid |\n| `d.py` | loose |\n"
    assert floors(text) == ["c", "a", "d"]
    assert upward_imports(edges, ["c", "a", "d"]) == []  # b is not on a floor: not judged
    assert upward_imports(edges, ["c", "b", "a", "d"]) == ["a -> b (pkg.a.x -> pkg.b.y)"]
    assert upward_imports(edges, ["a", "c", "d"]) == ["c -> a (pkg.c -> pkg.a.x)"]
    assert floors("no table here") == []


def test_no_import_cycles_in_the_package():
    found = cycles(import_graph())
    assert not found, f"import cycles: {found}"


def test_no_import_cycles_between_the_folders():
    found = cycles(folder_graph())
    edges = folder_edges()
    detail = {
        " ".join(c): [f"{a} -> {b}: {v[0]}" for (a, b), v in edges.items() if {a, b} <= set(c)]
        for c in found
    }
    assert not found, f"folder cycles: {detail}"


def test_every_import_goes_down_the_floors():
    order = floors(ARCHITECTURE.read_text())
    assert order, f"no table of folders in {ARCHITECTURE}"
    assert len(order) == len(set(order)), f"a folder on two floors: {order}"
    upward = upward_imports(folder_edges(), order)
    assert not upward, f"imports against the floors of docs/architecture.md: {upward}"


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
