"""Griffe extension of the documentation site: the package's docstrings are written for
Sphinx-like readers (``:class:`~myoexo.x.Y```, ``Example::`` literal blocks, reST simple
tables); this turns them into the Markdown mkdocstrings renders.

* a role ``:class:`~a.b.C``` (``:func:``, ``:meth:``, ``:mod:``, ``:data:``, ``:attr:``,
  ``:exc:``, ...) becomes an *optional* cross-reference: a link where the target is on a
  page of the site, a code span where it is not (no warning either way, so the strict build
  never fails on one). ``~`` shows the last component only; relative targets (``.runner``,
  ``ObsLayout.gather``) are resolved against the docstring's module, class and imports;
* a paragraph ending in ``::`` followed by an indented block becomes a paragraph ending in
  ``:`` and a fenced code block (roles inside it lose their markup);
* a reST simple table (``====  ====`` borders) becomes a Markdown table;
* an attribute without a docstring gets the ``#:`` comment lines right above its assignment
  (the Sphinx convention for documenting a constant).

mkdocs.yml loads it as ``docs/sphinx_roles.py:SphinxToMarkdown``.
"""

from __future__ import annotations

import html
import re
import textwrap
from typing import Any

import griffe

ROLE = re.compile(r":(?:py:)?(?P<role>[a-z]+):`(?P<body>[^`]+)`")
BORDER = re.compile(r"^(?P<indent> *)=+(?: +=+)+ *$")


def _split_title(body: str) -> tuple[str, str, bool]:
    """``"Title <target>"`` / ``"~target"`` / ``"target"`` -> (title, target, explicit)."""
    explicit = re.fullmatch(r"(?P<title>.+?)\s*<(?P<target>[^>]+)>", body)
    if explicit:
        return explicit["title"], explicit["target"].lstrip("~"), True
    target = body.lstrip("~!")
    title = target.rsplit(".", 1)[-1] if body.startswith("~") else target
    return title, target, False


class SphinxToMarkdown(griffe.Extension):
    """Rewrite every docstring of the loaded package (see the module docstring)."""

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        for obj in _walk(pkg):
            if obj.docstring is None and obj.is_attribute:
                _doc_comment(obj)
            if obj.docstring is not None:
                obj.docstring.value = self.convert(obj.docstring.value, obj)

    # -- the three conversions -----------------------------------------------------------
    def convert(self, text: str, obj: griffe.Object) -> str:
        text = _tables_to_markdown(text)
        parts = _split_literal_blocks(text)
        out = []
        for is_code, chunk in parts:
            if is_code:
                out.append(ROLE.sub(lambda m: _split_title(m["body"])[0], chunk))
            else:
                out.append(ROLE.sub(lambda m: self._reference(m, obj), chunk))
        return "".join(out)

    def _reference(self, match: re.Match[str], obj: griffe.Object) -> str:
        title, target, _ = _split_title(match["body"])
        if match["role"] in ("mod", "module") and target.startswith("."):
            title = title.lstrip(".")
        identifier = _resolve(target, obj)
        code = f"<code>{html.escape(title)}</code>"
        return f'<autoref identifier="{html.escape(identifier)}" optional>{code}</autoref>'


def _walk(obj: griffe.Object) -> Any:
    yield obj
    for member in obj.members.values():
        if member.is_alias:
            continue
        yield from _walk(member)  # type: ignore[arg-type]


def _doc_comment(attr: griffe.Object) -> None:
    """Give *attr* the ``#:`` comment lines right above its assignment as its docstring."""
    if attr.filepath is None or attr.lineno is None or isinstance(attr.filepath, list):
        return
    try:
        lines = attr.lines_collection[attr.filepath]
    except KeyError:
        return
    doc: list[str] = []
    i = attr.lineno - 2
    while i >= 0 and lines[i].strip().startswith("#:"):
        doc.insert(0, lines[i].strip()[2:].strip())
        i -= 1
    if doc:
        attr.docstring = griffe.Docstring(
            "\n".join(doc), lineno=i + 2, endlineno=attr.lineno - 1, parent=attr
        )


def _found(path: str, obj: griffe.Object) -> str | None:
    """The path of the object *path* names (an alias: of its final target), else None."""
    try:
        found = obj.modules_collection[path]
        return found.final_target.path if found.is_alias else found.path
    except (
        KeyError,
        ValueError,
        AttributeError,
        griffe.AliasResolutionError,
        griffe.CyclicAliasError,
    ):
        return None


def _resolve(target: str, obj: griffe.Object) -> str:
    """The full path of *target* as written in *obj*'s docstring (best effort)."""
    module = obj if obj.is_module else obj.module
    package = module.path if module.is_init_module else module.path.rpartition(".")[0]
    candidates: list[str] = []
    if target.startswith("."):
        up = len(target) - len(target.lstrip("."))
        base = package.split(".")
        base = base[: len(base) - (up - 1)] if up > 1 else base
        candidates.append(".".join([*base, target.lstrip(".")]))
    else:
        head, _, rest = target.partition(".")
        scopes = [o for o in (obj, obj.parent, module) if o is not None]
        for scope in scopes:
            member = scope.members.get(head) if hasattr(scope, "members") else None
            if member is not None:
                base = member.target_path if member.is_alias else member.path
                candidates.append(f"{base}.{rest}" if rest else base)
        candidates += [target, f"{module.path}.{target}", f"{package}.{target}"]
    for candidate in candidates:
        found = _found(candidate, obj)
        if found is not None:
            return found
    return candidates[0]


def _split_literal_blocks(text: str) -> list[tuple[bool, str]]:
    """[(is_code, text)]: each ``::`` paragraph's indented block as a fenced code block."""
    lines = text.split("\n")
    parts: list[tuple[bool, str]] = []
    prose: list[str] = []
    i = 0
    while i < len(lines):
        line = lines[i]
        if line.rstrip().endswith("::"):
            stripped = line.rstrip()[:-2].rstrip()
            indent = len(line) - len(line.lstrip())
            j = i + 1
            while j < len(lines) and not lines[j].strip():
                j += 1
            block_start = j
            while j < len(lines) and (
                not lines[j].strip() or len(lines[j]) - len(lines[j].lstrip()) > indent
            ):
                j += 1
            block = lines[block_start:j]
            while block and not block[-1].strip():
                block.pop()
            if block:
                if stripped:
                    prose.append(stripped + ":")
                prose.append("")
                parts.append((False, "\n".join(prose) + "\n"))
                prose = []
                pad = " " * indent
                code = textwrap.dedent("\n".join(block))
                fenced = f"{pad}```text\n" + textwrap.indent(code, pad) + f"\n{pad}```\n"
                parts.append((True, fenced))
                if j < len(lines):
                    prose.append("")
                i = j
                continue
        prose.append(line)
        i += 1
    if prose:
        parts.append((False, "\n".join(prose)))
    return parts


def _tables_to_markdown(text: str) -> str:
    """Every reST simple table of *text* as a Markdown table."""
    lines = text.split("\n")
    out: list[str] = []
    i = 0
    while i < len(lines):
        top = BORDER.match(lines[i])
        if not top:
            out.append(lines[i])
            i += 1
            continue
        border = lines[i]
        spans = [(m.start(), m.end()) for m in re.finditer(r"=+", border)]
        starts = [s for s, _ in spans]
        rows: list[list[str]] = []
        header_rows = 0
        borders = 1
        j = i + 1
        while j < len(lines) and borders < 3:
            line = lines[j]
            if BORDER.match(line):
                borders += 1
                if borders == 2:
                    header_rows = len(rows)
                j += 1
                continue
            if not line.strip():
                j += 1
                continue
            cells = [
                line[s : (starts[k + 1] if k + 1 < len(starts) else len(line))].strip()
                for k, s in enumerate(starts)
            ]
            if rows and not cells[0] and borders == 2:
                rows[-1] = [f"{a} {b}".strip() for a, b in zip(rows[-1], cells, strict=True)]
            else:
                rows.append(cells)
            j += 1
        if borders < 3 or not header_rows:
            out.append(lines[i])
            i += 1
            continue

        def row(cells: list[str]) -> str:
            return "| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |"

        indent = top["indent"]
        header = [" ".join(c).strip() for c in zip(*rows[:header_rows], strict=True)]
        table = [row(header), "|" + "---|" * len(starts)]
        table += [row(r) for r in rows[header_rows:]]
        if out and out[-1].strip():
            out.append("")
        out += [indent + t for t in table]
        if j < len(lines) and lines[j].strip():
            out.append("")
        i = j
    return "\n".join(out)
