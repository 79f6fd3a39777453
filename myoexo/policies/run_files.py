"""Where a trained policy lies in a training run folder: the names that the layers below
training read a model file by (a checkpoint's model file and the observation statistics beside
it, the run's settings two folders up)::

    <run>/config.json                            CONFIG_FILE
    <run>/checkpoints/step_<n>/model.zip         CHECKPOINTS_DIR, MODEL_FILE
    <run>/checkpoints/step_<n>/vecnormalize.pkl  VECNORM_FILE
    <run>/checkpoints/step_<n>/state.json        STATE_FILE (with the twin it was trained on)
    <seeds>/aggregate.json                       AGGREGATE_FILE (a ``myoexo policy seeds`` folder's
                                                 selected checkpoint per seed)

The run folder's layout is :mod:`myoexo.training.checkpoints`'s (it writes these files and
re-exports these names); they are defined here so that :mod:`myoexo.control.specs` reads a
model file without importing training.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

__all__ = [
    "AGGREGATE_FILE",
    "CHECKPOINTS_DIR",
    "CONFIG_FILE",
    "MODEL_FILE",
    "STATE_FILE",
    "VECNORM_FILE",
    "read_state",
]

#: The run's settings (preset, seed, env, observation keys, package versions).
CONFIG_FILE = "config.json"
#: The folder of the run's checkpoints, one folder each.
CHECKPOINTS_DIR = "checkpoints"
#: A checkpoint's SB3 model.
MODEL_FILE = "model.zip"
#: A checkpoint's observation normalization statistics (SB3 ``VecNormalize``).
VECNORM_FILE = "vecnormalize.pkl"
#: A checkpoint's state: step counter, wall time, score, and what rebuilds the policy's env
#: from the checkpoint alone (``twin``: :meth:`~myoexo.envs.options.TwinOptions.to_dict`;
#: ``env_id``; ``algorithm``).
STATE_FILE = "state.json"
#: A ``myoexo policy seeds`` folder's selection: each seed's chosen checkpoint folder
#: (``selected_checkpoints``), the seed to ship and the selection root.
AGGREGATE_FILE = "aggregate.json"


def read_state(checkpoint: Path | str) -> dict[str, Any]:
    """The ``state.json`` of a checkpoint folder (``OSError`` / ``ValueError`` if it has
    none or it is unreadable)."""
    return dict(json.loads((Path(checkpoint) / STATE_FILE).read_text()))
