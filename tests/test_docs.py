"""The README and the documentation site: the README is a short overview whose every link and
image is absolute (it is also the package index's page) and lands on a page that exists;
the package's links into the site point at pages and headings that exist; the tables the
site generates from the code cover what the code defines. ``make test`` builds the site
itself with ``mkdocs build --strict``."""

from __future__ import annotations

import ast
import importlib.util
import re
from pathlib import Path

import pytest

from myoexo.envs.config import DEFAULT_REWARD_WEIGHTS, RewardParams
from myoexo.envs.observation import OBS_KEY_DOCS, RAW_KEYS
from myoexo.envs.reward import REWARD_TERMS, reward_dict
from myoexo.runtime.docs import DOCS_URL, docs_url

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
DOCS = ROOT / "docs"
IMAGES_URL = "https://raw.githubusercontent.com/myoexo/myoexo/main/"

LINK = re.compile(r"!?\[(?:[^\[\]]|\[[^\]]*\])*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _slug(heading: str) -> str:
    """The anchor mkdocs (Python-Markdown's toc) gives a heading."""
    from markdown.extensions.toc import slugify

    text = re.sub(r"\[([^\]]*)\]\([^)]*\)", r"\1", heading)
    text = text.replace("`", "").replace("*", "")
    return slugify(text.strip(), "-")


def _anchors(page: Path) -> set[str]:
    in_code = False
    anchors = set()
    for line in page.read_text().splitlines():
        if line.startswith("```"):
            in_code = not in_code
        elif not in_code and (m := re.match(r"#{1,6} (.+)", line)):
            anchors.add(_slug(m[1]))
    return anchors


def _page_of(url: str) -> tuple[Path, str]:
    """The docs/ source of a site URL, and its anchor."""
    assert url.startswith(DOCS_URL + "/"), url
    path, _, anchor = url[len(DOCS_URL) + 1 :].partition("#")
    path = path.strip("/")
    page = DOCS / f"{path}.md" if path else DOCS / "index.md"
    return page, anchor


def _check_site_url(url: str) -> None:
    page, anchor = _page_of(url)
    assert page.is_file(), f"{url}: no page {page.relative_to(ROOT)}"
    if anchor:
        assert anchor in _anchors(page), f"{url}: no heading #{anchor} on {page.name}"


def test_readme_is_a_short_overview_with_the_two_commands():
    text = README.read_text()
    assert len(text.splitlines()) <= 300
    assert "make demo" in text and "make test" in text
    assert 'pip install "myoexo @ git+https://github.com/myoexo/myoexo"' in text


def test_every_readme_link_and_image_is_absolute_and_resolves():
    links = LINK.findall(README.read_text())
    assert links
    for target in links:
        assert re.match(r"https?://", target), f"README links to a relative path: {target}"
        if target.startswith(DOCS_URL):
            _check_site_url(target)
        elif target.startswith(IMAGES_URL):
            assert (ROOT / target[len(IMAGES_URL) :]).is_file(), target


def _docs_url_calls() -> list[tuple[str, str, str]]:
    """``(file, page, anchor)`` of every ``docs_url(...)`` call with literal arguments in the
    package."""
    calls = []
    for path in (ROOT / "myoexo").rglob("*.py"):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.Call) and getattr(node.func, "id", None) == "docs_url":
                args = [a.value for a in node.args if isinstance(a, ast.Constant)]
                assert len(args) == len(node.args), f"{path}: docs_url with non-literal args"
                calls.append((str(path.relative_to(ROOT)), *[*args, "", ""][:2]))
    return calls


def test_the_package_links_only_into_pages_that_exist():
    calls = _docs_url_calls()
    assert {page for _, page, _ in calls} >= {"cluster", "reference"}
    for where, page, anchor in calls:
        url = docs_url(page, anchor)
        assert url.startswith(DOCS_URL + "/"), where
        _check_site_url(url)


def test_help_texts_and_the_report_name_no_repository_paths():
    sources = [
        ROOT / "myoexo/evaluation/cli.py",
        ROOT / "myoexo/evaluation/report.py",
        ROOT / "myoexo/evaluation/results.py",
    ]
    for path in sources:
        tree = ast.parse(path.read_text())
        docstrings = {
            id(n.body[0].value)
            for n in ast.walk(tree)
            if isinstance(n, (ast.Module, ast.FunctionDef, ast.ClassDef))
            and n.body
            and isinstance(n.body[0], ast.Expr)
        }
        for node in ast.walk(tree):
            if isinstance(node, ast.Constant) and isinstance(node.value, str):
                if id(node) not in docstrings:
                    assert "docs/" not in node.value, f"{path.name}: {node.value!r}"


def test_docs_url():
    assert docs_url() == f"{DOCS_URL}/"
    assert docs_url("cluster") == f"{DOCS_URL}/cluster/"
    assert docs_url("reference", "2-spastic-reflex") == f"{DOCS_URL}/reference/#2-spastic-reflex"


def test_the_observation_table_describes_every_key_once_in_order():
    assert tuple(d.key for d in OBS_KEY_DOCS) == RAW_KEYS
    assert all(d.meaning and d.unit for d in OBS_KEY_DOCS)


def test_the_reward_table_describes_every_term_once_in_order():
    rwd = reward_dict(0.1, 0.0, 10.0, 0.0, 0.0, 0.0, 0.0, RewardParams(), DEFAULT_REWARD_WEIGHTS)
    assert tuple(t.key for t in REWARD_TERMS) == tuple(k for k in rwd if k != "dense")
    assert set(DEFAULT_REWARD_WEIGHTS) <= {t.key for t in REWARD_TERMS}
    described = {t.key: t.describe() for t in REWARD_TERMS}
    assert "75 Nm" in described["inter"] and "{" not in "".join(described.values())
    assert "0.2 rad" in REWARD_TERMS[0].describe(RewardParams(sigma_rad=0.2))


# -- the site's generators (docs/hooks.py) ------------------------------------------------
@pytest.fixture(scope="module")
def hooks():
    pytest.importorskip("mkdocs")
    spec = importlib.util.spec_from_file_location("myoexo_docs_hooks", DOCS / "hooks.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_api_reference_has_a_page_for_every_public_module(hooks):
    modules = hooks.public_modules()
    assert len(modules) == len(set(modules))
    for path in (ROOT / "myoexo").rglob("*.py"):
        parts = path.relative_to(ROOT).with_suffix("").parts
        parts = parts[:-1] if parts[-1] == "__init__" else parts
        if not any(part.startswith("_") for part in parts):
            assert ".".join(parts) in modules, path
    assert modules[0] == "myoexo" and "myoexo.envs.observation" in modules
    pages = [hooks.api_page(m) for m in modules]
    assert len(set(pages)) == len(pages)


def test_the_generated_tables(hooks):
    obs = hooks.observation_table()
    for key in RAW_KEYS:
        assert f"| `{key}` |" in obs
    assert "`full`: 76 floats" in obs and "`exo`: 18 floats" in obs
    reward = hooks.reward_table()
    for term in REWARD_TERMS:
        assert f"| `{term.key}` |" in reward
    assert "| `inter` |" in reward and "| -1 |" in reward


def test_the_generated_cli_reference_covers_every_command(hooks):
    from myoexo.cli import COMMANDS

    text = hooks.cli_reference()
    for name in COMMANDS:
        assert f"## `myoexo {name}`" in text
        assert f"usage: myoexo {name}" in text
    assert "### `myoexo policy seeds train`" in text


def test_every_marker_in_the_pages_is_known(hooks):
    for page in DOCS.glob("*.md"):
        for name in hooks.MARKER.findall(page.read_text()):
            assert name in hooks.GENERATORS, f"{page.name}: unknown marker {name}"
