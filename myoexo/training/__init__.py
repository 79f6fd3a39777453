"""Training of the exoskeleton controller (docs/reference.md section 3): one training config
and its presets, resumable runs, logging, and the export of a trained actor.

    from myoexo.training import get_preset, train, resume

    train(get_preset("cpu", seed=0), "runs/cpu_seed0")   # or: myoexo policy train --preset cpu
    resume("runs/cpu_seed0")                               # or: myoexo policy train --resume DIR
    restart("runs/cpu_seed0")   # a first session that never checkpointed: --restart DIR

Modules: :mod:`~myoexo.training.config` (:class:`TrainConfig`; its presets ``paper`` =
Table II, ``cpu``, ``ppo``),
:mod:`~myoexo.training.train` (runs), :mod:`~myoexo.training.callbacks` (reward terms,
small evaluation vs the PID, checkpoints), :mod:`~myoexo.training.checkpoints` (run
layout), :mod:`~myoexo.training.export` (numpy actor, ONNX), :mod:`~myoexo.training.cli`.
Studies that drive training (``myoexo policy sweep``, ``myoexo policy distill``) are in
:mod:`myoexo.studies`.
Heavy dependencies (torch, SB3) are imported when a run starts, not on import. What a kill,
a signal, a damaged file or a full disk costs a run: ``docs/long_runs.md``.
"""

from myoexo.training.config import PRESETS, TrainConfig, get_preset
from myoexo.training.train import TrainResult, restart, resume, train

__all__ = [
    "PRESETS",
    "TrainConfig",
    "TrainResult",
    "get_preset",
    "restart",
    "resume",
    "train",
]
