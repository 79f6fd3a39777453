"""Fitted values as package data: one JSON file per fit, with the provenance of the command
that wrote it.

A value the package fits to the twin (a tuned PID's gains, the straps' lag) is never pasted
into code: the command that fits it writes ``myoexo/assets/fits/<name>.json`` with ``--write``,
and the code that uses it reads that file. Each file holds::

    {"result": {...what the fit found...},
     "provenance": {"command": "myoexo ...", "twin_version": N, "versions": {...},
                    "date": "YYYY-MM-DD", ...what else the command records...}}
"""

from __future__ import annotations

import datetime
import json
from importlib import resources
from pathlib import Path
from typing import Any

from myoexo.runtime.files import package_versions, write_json_atomic

__all__ = ["fit_path", "fits_dir", "provenance", "read_fit", "write_command_fit", "write_fit"]

#: Where the fits live inside the package.
FITS_PACKAGE_DIR = ("assets", "fits")


def fits_dir() -> Path:
    """The package's folder of fitted values."""
    return Path(str(resources.files("myoexo").joinpath(*FITS_PACKAGE_DIR)))


def fit_path(name: str) -> Path:
    """The file of the fit *name*."""
    if not name.replace("_", "").isalnum():
        raise ValueError(f"fit name {name!r} must be a word (letters, digits, _)")
    return fits_dir() / f"{name}.json"


def provenance(command: str, twin_version: int, **fields: Any) -> dict[str, Any]:
    """What a fit records of how it was made: *command*, the twin version, the package
    versions, today's date (UTC) and *fields*."""
    return {
        "command": command,
        "twin_version": int(twin_version),
        **fields,
        "versions": package_versions(),
        "date": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d"),
    }


def write_fit(name: str, result: dict[str, Any], prov: dict[str, Any]) -> Path:
    """Write the fit *name* (its *result* and provenance *prov*); returns the file."""
    path = fit_path(name)
    path.parent.mkdir(parents=True, exist_ok=True)
    write_json_atomic(path, {"result": result, "provenance": prov}, indent=2)
    return path


def write_command_fit(
    name: str, result: dict[str, Any], command: str, twin_version: int, **fields: Any
) -> Path:
    """Write the fit *name* that ``command --write`` made: :func:`write_fit` with the
    :func:`provenance` of that command, *twin_version* and *fields*; prints and returns the
    file."""
    path = write_fit(name, result, provenance(f"{command} --write", twin_version, **fields))
    print(f"written: {path}")
    return path


def read_fit(name: str) -> dict[str, Any]:
    """The fit *name*: ``{"result": ..., "provenance": ...}``.

    Raises:
        FileNotFoundError: If the package holds no such fit (the message names the command
            convention that writes one).
    """
    path = fit_path(name)
    if not path.is_file():
        raise FileNotFoundError(
            f"the package has no fit {name!r} ({path}); the command that fits it writes it "
            "with --write"
        )
    doc: dict[str, Any] = json.loads(path.read_text())
    return doc
