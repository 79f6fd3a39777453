"""Where the documentation site lives: the one base URL that the command line's help texts
and the written reports point at (a wheel carries no ``docs/`` folder).

The site is built from the repository's ``docs/`` folder (``mkdocs.yml``); a page
``docs/<page>.md`` is served at ``<DOCS_URL>/<page>/``.
"""

from __future__ import annotations

#: Base URL of the documentation site (no trailing slash).
DOCS_URL = "https://myoexo.readthedocs.io/en/latest"


def docs_url(page: str = "", anchor: str = "") -> str:
    """URL of a page of the documentation site, optionally of one of its headings.

    Args:
        page: The page's name, the ``docs/`` file without ``.md`` (``"cluster"``,
            ``"reference"``); empty for the home page.
        anchor: The heading's id on that page (``"5-evaluation-protocol-and-the-papers-results"``),
            without ``#``.
    """
    url = f"{DOCS_URL}/{page.strip('/')}/" if page.strip("/") else f"{DOCS_URL}/"
    return f"{url}#{anchor}" if anchor else url
