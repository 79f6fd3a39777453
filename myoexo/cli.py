"""Command-line interface: ``myoexo <command> [options]``.

Each sub-command lives in the module that owns the concept and exposes two functions,
``add_arguments(parser)`` and ``run(args) -> int``; this file only routes to them, so the
modules stay independent and importing the CLI stays cheap.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

#: sub-command -> (module implementing it, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "demo": ("myoexo.demo", "run the main job on built-in defaults and print where results are"),
    "export-model": ("myoexo.model.export", "write the human + exo twin as a standalone MJCF"),
    "plot-spasticity": ("myoexo.spasticity_plots", "draw Fig. 2b and the stretch-test curves"),
    "stretch-test": ("myoexo.stretch_test", "simulate the passive Tardieu stretch per level"),
    "evaluate": ("myoexo.evaluation.cli", "run the paper's evaluation protocol"),
    "report": ("myoexo.evaluation.report", "write figures and the Markdown report of a run"),
    "tune-pid": ("myoexo.control.ziegler_nichols", "Ziegler-Nichols tuning on the twin"),
    "train": ("myoexo.training.cli", "train SAC on MyoExoKneeRandom-v0"),
    "export-policy": ("myoexo.training.export", "export a trained policy (ONNX)"),
}


def build_parser() -> argparse.ArgumentParser:
    """Parser with one sub-parser per available command."""
    parser = argparse.ArgumentParser(
        prog="myoexo",
        description="myoexo: knee-exoskeleton digital twin with spastic reflexes on MyoSuite.",
    )
    sub = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for name, (module_name, help_text) in COMMANDS.items():
        try:
            module = importlib.import_module(module_name)
        except ModuleNotFoundError as exc:  # a command whose module is not built yet
            if exc.name and exc.name.startswith("myoexo"):
                continue
            raise
        p = sub.add_parser(name, help=help_text, description=help_text)
        module.add_arguments(p)
        p.set_defaults(_module=module)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    """Entry point of the ``myoexo`` console script."""
    args = build_parser().parse_args(argv)
    return int(args._module.run(args) or 0)


if __name__ == "__main__":
    sys.exit(main())
