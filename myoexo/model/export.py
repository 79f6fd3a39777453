"""``myoexo export-model``: write the twin (or the bare leg) as a standalone MJCF file.

The file is ``spec.to_xml()`` of :func:`~myoexo.model.build.build_model`'s spec, whose
``meshdir`` is MyoSuite's absolute mesh folder, so it loads with
``mujoco.MjModel.from_xml_path`` (and opens in MuJoCo's viewer:
``python -m mujoco.viewer --mjcf out.xml``) from any directory.
"""

from __future__ import annotations

import argparse
from pathlib import Path

__all__ = ["add_arguments", "export_model", "run"]


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
    """Add the ``export-model`` arguments to ``parser``."""
    parser.add_argument("output", type=Path, help="MJCF file to write, e.g. twin.xml")
    parser.add_argument(
        "--no-exo",
        action="store_true",
        help="export the seated leg without the exoskeleton (the benchmark baseline)",
    )


def run(args: argparse.Namespace) -> int:
    """Write the model and check that it loads; return the process exit code."""
    import mujoco

    out = export_model(args.output, with_exo=not args.no_exo)
    model = mujoco.MjModel.from_xml_path(str(out))
    print(
        f"wrote {out} ({model.nq} qpos, {model.nu} actuators, {model.neq} equalities, "
        f"{model.nsensor} sensors, {model.nkey} keyframe)"
    )
    return 0
