"""``myoexo clinic check-recording FILE...``: read clinical recordings
(:mod:`myoexo.clinical.recording`'s format) and print one line per file.

A file read prints ``FILE: <test>, <samples>, <duration>, <ranges>`` (or its single values).
A file the format refuses is named with what is wrong; if any is, the command ends with
one line, ``myoexo clinic check-recording: error: ...`` (the first refusal, and how many
there were), exit status 2. Nothing is written anywhere.
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

from myoexo.clinical.recording import read_recording
from myoexo.runtime.fields import add_positional, check_fields, option

__all__ = ["CheckOptions", "add_arguments", "check_files", "run"]


@dataclasses.dataclass(frozen=True)
class CheckOptions:
    """What ``myoexo clinic check-recording`` reads (``files`` is its positional argument)."""

    files: tuple[Path, ...] = option((), "recording files (CSV) to check", flag="", metavar="FILE")

    def __post_init__(self) -> None:
        check_fields(self)
        if not self.files:
            raise ValueError("CheckOptions.files is empty: name at least one recording")


def check_files(files: tuple[Path, ...]) -> tuple[list[str], list[str]]:
    """``(summaries, refusals)``: one line per file read, one per file refused."""
    summaries, refusals = [], []
    for path in files:
        try:
            recording = read_recording(path)
        except (ValueError, OSError) as exc:
            message = str(exc)
            if isinstance(exc, OSError):
                message = f"{path}: {exc.strerror or type(exc).__name__}"
            refusals.append(message)
            continue
        summaries.append(f"{path}: {recording.summary()}")
    return summaries, refusals


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo clinic check-recording``: the files (:class:`CheckOptions`)."""
    add_positional(parser, CheckOptions, "files", nargs="+", type=Path)


def run(args: argparse.Namespace) -> int:
    """Read every file, print its summary; a refused file ends the command with one line."""
    options = CheckOptions(files=tuple(args.files))
    summaries, refusals = check_files(options.files)
    for line in summaries:
        print(line)
    if len(refusals) == 1:
        raise ValueError(refusals[0])
    if refusals:
        raise ValueError(
            f"{len(refusals)} of {len(options.files)} files refused; first: {refusals[0]}"
        )
    return 0
