"""Atomic writes end with the permissions of a plain ``open()``: the process's umask, not the
owner-only mode of the temporary file ``mkstemp`` makes."""

from __future__ import annotations

import os
import stat

import numpy as np
import pandas as pd
import pytest

from myoexo.runtime.files import (
    atomic_path,
    current_umask,
    default_file_mode,
    savez_atomic,
    write_json_atomic,
    write_text_atomic,
)


@pytest.fixture
def umask():
    """Set the process's umask for one test (restored after it)."""
    saved = os.umask(0o022)
    os.umask(saved)

    def set_mask(mask: int) -> None:
        os.umask(mask)

    yield set_mask
    os.umask(saved)


def _mode(path) -> int:
    return stat.S_IMODE(os.stat(path).st_mode)


WRITERS = {
    "text": lambda p: write_text_atomic(p, "x\n"),
    "json": lambda p: write_json_atomic(p, {"a": 1}),
    "npz": lambda p: savez_atomic(p, a=np.arange(3)),
    "csv": lambda p: _with_atomic_path(p, lambda t: pd.DataFrame({"a": [1]}).to_csv(t)),
    "parquet": lambda p: _with_atomic_path(p, lambda t: pd.DataFrame({"a": [1]}).to_parquet(t)),
}


def _with_atomic_path(path, write) -> None:
    with atomic_path(path) as tmp:
        write(tmp)


@pytest.mark.parametrize("mask", [0o022, 0o002, 0o027, 0o077])
@pytest.mark.parametrize("kind", list(WRITERS))
def test_an_atomic_write_gets_the_mode_of_a_plain_open(kind, mask, umask, tmp_path):
    umask(mask)
    written = tmp_path / f"out.{kind}"
    WRITERS[kind](written)
    plain = tmp_path / "plain"
    with open(plain, "w") as f:
        f.write("x")
    assert _mode(written) == _mode(plain) == 0o666 & ~mask
    assert not list(tmp_path.glob(".tmp-*"))


def test_an_existing_file_is_replaced_with_the_current_mode(umask, tmp_path):
    path = tmp_path / "config.json"
    umask(0o077)
    write_json_atomic(path, {"a": 1})
    assert _mode(path) == 0o600
    umask(0o022)
    write_json_atomic(path, {"a": 2})
    assert _mode(path) == 0o644


def test_the_umask_is_read_without_changing_it(umask):
    umask(0o037)
    assert current_umask() == 0o037
    assert default_file_mode() == 0o640
    assert os.umask(0o037) == 0o037  # unchanged by the reads
