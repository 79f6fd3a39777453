"""``myoexo twin export``: write the twin (or the bare leg) as a standalone MJCF file.

The file is ``spec.to_xml()`` of :func:`~myoexo.model.build.build_model`'s spec, whose
``meshdir`` is MyoSuite's absolute mesh folder, so it loads with
``mujoco.MjModel.from_xml_path`` (and opens in MuJoCo's viewer:
``python -m mujoco.viewer --mjcf out.xml``) from any directory.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from pathlib import Path

from myoexo.runtime.fields import add_options, add_positional, check_fields, from_options, option

__all__ = ["ExportConfig", "add_arguments", "export_model", "run"]


@dataclass(frozen=True)
class ExportConfig:
    """What ``myoexo twin export`` writes (``output`` is its positional argument, the other
    fields its options)."""

    output: Path = option(doc="MJCF file to write, e.g. twin.xml", flag="", metavar="OUTPUT")
    exo: bool = option(
        True,
        "export the coupled twin; --no-exo: the seated leg without the exoskeleton (the "
        "benchmark baseline)",
    )

    def __post_init__(self) -> None:
        check_fields(self)


def export_model(path: str | Path, *, with_exo: bool = True) -> Path:
    """Build the twin (``with_exo``) or the bare seated leg and write it as MJCF.

    Args:
        path: Output ``.xml`` file; parent folders are created.
        with_exo: Export the coupled twin (default) or the leg without the exo.

    Returns:
        The written path.
    """
    from myoexo.model.build import build_leg_model, build_model
    from myoexo.model.params import TwinParams

    _, spec = (build_model if with_exo else build_leg_model)(TwinParams())
    out = Path(path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(spec.to_xml())
    return out


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin export``: :class:`ExportConfig`'s fields."""
    add_positional(parser, ExportConfig, "output")
    add_options(parser, ExportConfig)


def run(args: argparse.Namespace) -> int:
    """Write the model and check that it loads; return the process exit code."""
    import mujoco

    config = from_options(ExportConfig, args, output=args.output)
    out = export_model(config.output, with_exo=config.exo)
    model = mujoco.MjModel.from_xml_path(str(out))
    print(
        f"wrote {out} ({model.nq} qpos, {model.nu} actuators, {model.neq} equalities, "
        f"{model.nsensor} sensors, {model.nkey} keyframe)"
    )
    return 0
