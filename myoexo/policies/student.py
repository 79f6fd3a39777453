"""A deployable knee-exo controller: an MLP on a short memory of the exoskeleton's own sensors.

The study's learned controllers read the human knee angle (``sac``) or an episode clock
(the retired ``sac_exo`` read ``time_frac``), neither of which a real exoskeleton has. The
:class:`StudentController` reads only what the device measures, one *frame* per control
step (:data:`FRAME_KEYS`, in the units and scales of the env's observation vector): the
exo encoder angle and velocity, the target, the last motor command, the motor torque and
the two cuffs' force and torque (:data:`FRAME_DIM` floats; each key's meaning, unit and scale:
:data:`myoexo.envs.observation.OBS_KEY_DOCS`, shown on the documentation site's
environment page, ``docs/envs.md``).

Nothing else: no human joint angle, no muscle or strap state, and no episode clock
(``time_frac`` is in the env's ``obs_preset="exo"`` vector; the controller drops it). Its
memory is part of the controller: the last ``history`` frames (``history = (n_frames - 1) *
stride + 1``); the network sees ``n_frames`` of them, ``stride`` steps apart, newest first.
``reset()`` clears the memory; the first ``act`` of an episode fills it with that first
frame. The network is a numpy :class:`~myoexo.policies.actor.MLPActor` (input
normalization, hidden layers, tanh head); inference needs no torch.

Files: ``<stem>.npz`` (weights) + ``<stem>.json`` (the actor's normalization and provenance,
with the controller's own fields under ``"student"``), written by :func:`save_student`
and read by :func:`load_student`; :func:`export_student_onnx` writes the whole controller
as ONNX with its memory as an explicit input and output.

    from myoexo.policies.student import load_student
    from myoexo.envs import make_env

    student = load_student("myoexo/policies/student_exo")
    env = make_env(1, obs_preset=student.obs_preset)         # "exo"
    obs, info = env.reset(seed=0)
    student.reset(0)
    obs, *_ , info = env.step(student.act(obs))           # its sensors are in obs
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.envs.observation import (
    CUFF_OBS_KEYS,
    DEFAULT_OBS_KEYS,
    EXO_SENSOR_OBS_KEYS,
    STATE_OBS_KEYS,
)
from myoexo.envs.sensors import Measurements
from myoexo.policies.actor import MLPActor, load_actor, save_actor

#: What one frame of the controller's memory holds (obs-vector keys, in this order): the
#: exo-sensor preset's keys without its episode clock.
FRAME_KEYS: tuple[str, ...] = tuple(k for k in EXO_SENSOR_OBS_KEYS if k != "time_frac")
#: Size of each scalar-or-cuff key in the observation vector (the cuffs' 3-D force and torque).
KEY_SIZES: dict[str, int] = {
    k: 3 if k in CUFF_OBS_KEYS else 1 for k in (*STATE_OBS_KEYS, *CUFF_OBS_KEYS, "time_frac")
}
FRAME_DIM: int = sum(KEY_SIZES[k] for k in FRAME_KEYS)
#: Observation keys a student must never read (the twin's hidden state and the clock).
FORBIDDEN_KEYS: tuple[str, ...] = (
    *(k for k in DEFAULT_OBS_KEYS if k not in FRAME_KEYS and k != "time_frac"),
    "time_frac",
)
#: The env's ``obs_preset="exo"`` keys (:data:`FRAME_KEYS` + ``time_frac``, ignored).
EXO_PRESET_KEYS: tuple[str, ...] = EXO_SENSOR_OBS_KEYS
#: Version of the ``"student"`` block of the file format.
STUDENT_FORMAT_VERSION = 1


def frame_indices(obs_keys: Sequence[str]) -> np.ndarray:
    """Indices of :data:`FRAME_KEYS`' entries in an observation vector of ``obs_keys``.

    Works for any layout in which every key before the last frame entry has a known size
    (:data:`KEY_SIZES`): the ``exo`` and the ``full`` presets.

    Raises:
        ValueError: A frame key is missing, or one of unknown size precedes a frame key.
    """
    where: dict[str, int] = {}
    offset = 0
    for key in obs_keys:
        if all(k in where for k in FRAME_KEYS):
            break
        if key in FRAME_KEYS:
            where[key] = offset
        if key not in KEY_SIZES:
            missing = [k for k in FRAME_KEYS if k not in where]
            raise ValueError(
                f"obs key {key!r} (unknown size) comes before the frame keys {missing}: "
                "give the student an observation with the frame keys first"
            )
        offset += KEY_SIZES[key]
    missing = [k for k in FRAME_KEYS if k not in where]
    if missing:
        raise ValueError(f"the observation lacks the frame keys {missing} (has {list(obs_keys)})")
    return np.concatenate(
        [np.arange(where[k], where[k] + KEY_SIZES[k]) for k in FRAME_KEYS]
    ).astype(np.intp)


def history_length(n_frames: int, stride: int) -> int:
    """Frames the memory keeps: ``(n_frames - 1) * stride + 1``."""
    return (int(n_frames) - 1) * int(stride) + 1


def stack_frames(history: np.ndarray, n_frames: int, stride: int) -> np.ndarray:
    """The network input from a memory of raw frames.

    Args:
        history: ``(..., H, FRAME_DIM)``, oldest first, newest last (``H`` = history length).

    Returns:
        ``(..., n_frames * FRAME_DIM)``: the newest frame, then the one ``stride`` steps
        before it, ... (newest first).
    """
    h = np.asarray(history)
    sel = h[..., ::-1, :][..., :: int(stride), :][..., : int(n_frames), :]
    return sel.reshape(*h.shape[:-2], int(n_frames) * h.shape[-1])


class StudentController:
    """Exo-sensor MLP controller with a memory of its last frames (a myoexo ``Controller``).

    Args:
        actor: The network, input ``n_frames * FRAME_DIM`` (normalization included).
        n_frames: Frames the network sees.
        stride: Control steps between those frames.
        obs_keys: Layout of the observation vector ``act`` receives (default: the env's
            ``obs_preset="exo"``); :meth:`bind` sets it from an env.
        metadata: Provenance (training run, teacher, dataset, ...).
        gentleness_input: The network takes the gentleness weight as its last input: the
            last entry of the observation ``act`` receives (what
            :class:`~myoexo.control.policy.GentleController` appends), not stored in the
            memory.
    """

    def __init__(
        self,
        actor: MLPActor,
        n_frames: int = 8,
        stride: int = 1,
        obs_keys: Sequence[str] = EXO_PRESET_KEYS,
        metadata: Mapping[str, Any] | None = None,
        gentleness_input: bool = False,
    ) -> None:
        if n_frames < 1 or stride < 1:
            raise ValueError(f"n_frames = {n_frames}, stride = {stride} must be >= 1")
        extra = int(bool(gentleness_input))
        if actor.obs_dim != n_frames * FRAME_DIM + extra:
            raise ValueError(
                f"actor input {actor.obs_dim} != n_frames {n_frames} x frame size {FRAME_DIM}"
                + (" + the gentleness weight" if extra else "")
            )
        self.actor = actor
        self.gentleness_input = bool(gentleness_input)
        self.n_frames = int(n_frames)
        self.stride = int(stride)
        self.history = history_length(n_frames, stride)
        self.metadata = dict(metadata or {})
        self.metadata["obs_preset"] = self.obs_preset  # what the evaluation's env reads
        self._memory: np.ndarray | None = None
        self.bind_obs_keys(obs_keys)

    #: What :func:`~myoexo.evaluation.engine.evaluate_controller` builds the env with.
    obs_preset: str = "exo"

    # ------------------------------------------------------------------ layout
    def bind_obs_keys(self, obs_keys: Sequence[str]) -> StudentController:
        """Read frames from observations laid out as ``obs_keys`` (returns ``self``)."""
        self.obs_keys = tuple(obs_keys)
        self._idx = frame_indices(self.obs_keys)
        # the vector's size when every key's size is known (exo preset): checked in act()
        known = all(k in KEY_SIZES for k in self.obs_keys)
        self._obs_size = (
            sum(KEY_SIZES[k] for k in self.obs_keys) + int(self.gentleness_input) if known else None
        )
        return self

    def bind(self, env: Any) -> StudentController:
        """Read frames from ``env``'s observation vector (its ``obs_keys``)."""
        return self.bind_obs_keys(list(env.unwrapped.obs_keys))

    @property
    def selection_root_seed(self) -> int | None:
        """Root seed of the subjects that selected this controller (evaluations on it are
        refused), as :attr:`MLPActor.selection_root_seed <myoexo.policies.actor.MLPActor>`."""
        seed = self.metadata.get("selection_root_seed")
        return None if seed is None else int(seed)

    @property
    def required_obs_keys(self) -> tuple[str, ...]:
        """The observation keys the controller reads (:data:`FRAME_KEYS`)."""
        return FRAME_KEYS

    # ------------------------------------------------------------------ memory
    def frame(self, obs: np.ndarray) -> np.ndarray:
        """This step's frame (float64, ``FRAME_DIM``) from an observation vector."""
        x = np.asarray(obs, dtype=np.float64).reshape(-1)
        if self._obs_size is not None and x.size != self._obs_size:
            weight = (
                " and the gentleness weight last (myoexo.load_policy(name, env) or a "
                "GentleController appends it)"
                if self.gentleness_input
                else ""
            )
            raise ValueError(
                f"observation of size {x.size}, but the student reads the layout "
                f"{list(self.obs_keys)}{weight} ({self._obs_size} entries): build the env with "
                f"obs_preset={self.obs_preset!r} or call bind(env)"
            )
        if x.size <= self._idx[-1]:
            raise ValueError(f"observation of size {x.size} is too short for the frame")
        return x[self._idx]

    @property
    def memory(self) -> np.ndarray | None:
        """The last ``history`` frames, oldest first (``None`` right after :meth:`reset`)."""
        return None if self._memory is None else self._memory.copy()

    def reset(self, seed: int | None = None) -> None:
        """Start of an episode: forget every frame."""
        del seed
        self._memory = None

    def push(self, frame: np.ndarray) -> np.ndarray:
        """Add a frame to the memory (the first one fills it); returns the network input."""
        f = np.asarray(frame, dtype=np.float64).reshape(FRAME_DIM)
        if self._memory is None:
            self._memory = np.repeat(f[None, :], self.history, axis=0)
        else:
            self._memory = np.roll(self._memory, -1, axis=0)
            self._memory[-1] = f
        return stack_frames(self._memory, self.n_frames, self.stride)

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """One decision: push this observation's frame, return the command ``(1,)`` float32
        in [-1, 1]. ``measurements`` is not read: the exo's sensors are in the frame (and,
        with :attr:`gentleness_input`, the weight is the observation's last entry)."""
        del measurements
        frame = self.frame(obs)
        if not np.isfinite(frame).all():
            raise ValueError(f"non-finite exo sensor reading {frame.tolist()}")
        x = self.push(frame)
        if self.gentleness_input:
            x = np.append(x, float(np.asarray(obs).reshape(-1)[-1]))
        action = self.actor(x)
        if not np.isfinite(action).all():
            raise ValueError(f"the student returned a non-finite action {action.tolist()}")
        return np.clip(action, -1.0, 1.0).astype(np.float32)

    # ------------------------------------------------------------------ torch / ONNX
    def to_torch(self) -> Any:
        """The whole controller as a torch module: ``(frame (B, FRAME_DIM), memory (B,
        history - 1, FRAME_DIM)[, gentleness (B, 1)]) -> (action (B, 1), new memory)``;
        memory oldest first; the weight with :attr:`gentleness_input`."""
        return _torch_student_class(self.gentleness_input)(
            self.actor.to_torch(), self.n_frames, self.stride
        )

    def initial_memory(self, frame: np.ndarray) -> np.ndarray:
        """Memory (``history - 1`` frames) an episode's first step sees: its frame repeated
        (the ONNX model's input at the first step, as :meth:`push` does)."""
        f = np.asarray(frame, dtype=np.float32).reshape(1, FRAME_DIM)
        return np.repeat(f, self.history - 1, axis=0)


def _torch_student_class(gentleness_input: bool = False) -> type:
    import torch
    from torch import nn

    class _TorchStudent(nn.Module):
        def __init__(self, actor: nn.Module, n_frames: int, stride: int) -> None:
            super().__init__()
            self.actor = actor
            self.n_frames = n_frames
            self.stride = stride
            history = history_length(n_frames, stride)
            # newest-first indices into the (history) frames, oldest first
            idx = [history - 1 - k * stride for k in range(n_frames)]
            self.register_buffer("select", torch.as_tensor(idx, dtype=torch.long))

        select: torch.Tensor

        def step(
            self, frame: torch.Tensor, memory: torch.Tensor, *extra: torch.Tensor
        ) -> tuple[torch.Tensor, torch.Tensor]:
            """The action from the memory with this frame (then *extra* inputs, the weight)
            and the memory for the next step."""
            full = torch.cat([memory, frame.unsqueeze(1)], dim=1)  # (B, history, F)
            x = torch.index_select(full, 1, self.select).flatten(1)
            action = torch.clamp(self.actor(torch.cat([x, *extra], dim=1)), -1.0, 1.0)
            return action, full[:, 1:, :]

        def forward(
            self, frame: torch.Tensor, memory: torch.Tensor
        ) -> tuple[torch.Tensor, torch.Tensor]:
            return self.step(frame, memory)

    class _TorchGentleStudent(_TorchStudent):
        def forward(  # type: ignore[override]
            self, frame: torch.Tensor, memory: torch.Tensor, gentleness: torch.Tensor
        ) -> tuple[torch.Tensor, torch.Tensor]:
            return self.step(frame, memory, gentleness)

    return _TorchGentleStudent if gentleness_input else _TorchStudent


def export_student_onnx(student: StudentController, path: str | Path, opset: int = 17) -> Path:
    """Write the controller as ONNX: inputs ``frame`` (batch, FRAME_DIM) float32,
    ``memory`` (batch, history - 1, FRAME_DIM) and, for a student with
    :attr:`~StudentController.gentleness_input`, ``gentleness`` (batch, 1), the weight in
    [0, 1]; outputs ``action`` (batch, 1) and ``memory_out`` (the memory for the next
    step). At an episode's first step, memory is that step's frame repeated
    (:meth:`StudentController.initial_memory`)."""
    import warnings

    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module = student.to_torch().eval()
    args: tuple[Any, ...] = (
        torch.zeros(1, FRAME_DIM),
        torch.zeros(1, student.history - 1, FRAME_DIM),
    )
    inputs = ["frame", "memory"]
    if student.gentleness_input:
        args = (*args, torch.zeros(1, 1))
        inputs.append("gentleness")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            module,
            args,
            str(path),
            input_names=inputs,
            output_names=["action", "memory_out"],
            dynamic_axes={
                **{name: {0: "batch"} for name in inputs},
                "action": {0: "batch"},
                "memory_out": {0: "batch"},
            },
            opset_version=opset,
            dynamo=False,
        )
    return path


# ---------------------------------------------------------------------------- files
def save_student(student: StudentController, path_stem: str | Path) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` (weights) and ``<stem>.json`` (normalization, the controller's
    fields under ``"student"``, provenance and reference pairs); returns the two paths."""
    actor = student.actor
    meta = dict(actor.metadata)
    meta.update(student.metadata)  # provenance: top level, as the shipped actors keep it
    meta.update(
        obs_preset=StudentController.obs_preset,
        obs_keys=list(EXO_PRESET_KEYS),
        student={
            "format_version": STUDENT_FORMAT_VERSION,
            "frame_keys": list(FRAME_KEYS),
            "frame_dim": FRAME_DIM,
            "n_frames": student.n_frames,
            "stride": student.stride,
            "history": student.history,
            "ignored_keys": ["time_frac"],
            "gentleness_input": student.gentleness_input,
        },
    )
    # the files hold float32 weights: the reference is computed with those
    weights = [(w.astype(np.float32), b.astype(np.float32)) for w, b in actor.weights]
    actor = MLPActor(
        weights,
        activation=actor.activation,
        obs_mean=actor.obs_mean,
        obs_var=actor.obs_var,
        epsilon=actor.epsilon,
        clip_obs=actor.clip_obs,
        action_low=actor.action_low,
        action_high=actor.action_high,
        metadata=meta,
    )
    if "reference" not in meta:
        rng = np.random.default_rng(0)
        mean = np.zeros(actor.obs_dim) if actor.obs_mean is None else actor.obs_mean
        std = np.ones(actor.obs_dim) if actor.obs_var is None else np.sqrt(actor.obs_var)
        x = mean + std * rng.standard_normal((8, actor.obs_dim))
        actor.metadata["reference"] = {"observations": x.tolist(), "actions": actor(x).tolist()}
    return save_actor(actor, path_stem)


def load_student(path_stem: str | Path, check: bool = True) -> StudentController:
    """Read a controller written by :func:`save_student` (``check``: replay its reference
    pairs, ``ValueError`` if the files disagree with them)."""
    return student_from_actor(load_actor(path_stem), path_stem, check)


def student_from_actor(
    actor: MLPActor, path_stem: str | Path, check: bool = True
) -> StudentController:
    """The controller around an actor read from a student file (*path_stem*, for the
    messages): :func:`load_student` without reading the files again."""
    block = actor.metadata.get("student")
    if not isinstance(block, dict) or block.get("format_version") != STUDENT_FORMAT_VERSION:
        raise ValueError(f"{path_stem}: not a student controller file (no 'student' block)")
    if list(block["frame_keys"]) != list(FRAME_KEYS):
        raise ValueError(f"{path_stem}: frame keys {block['frame_keys']} != {list(FRAME_KEYS)}")
    if check:
        actor.check_reference()
    extra = {k: v for k, v in actor.metadata.items() if k not in _NOT_PROVENANCE}
    return StudentController(
        actor,
        n_frames=int(block["n_frames"]),
        stride=int(block["stride"]),
        metadata=extra,
        gentleness_input=bool(block.get("gentleness_input", False)),
    )


_NOT_PROVENANCE = {"student", "reference", "obs_keys"}


def describe(student: StudentController) -> str:
    """One line: architecture and memory."""
    widths = [w.shape[0] for w, _ in student.actor.weights[:-1]]
    return json.dumps(
        {
            "hidden": widths,
            "activation": student.actor.activation,
            "n_frames": student.n_frames,
            "stride": student.stride,
            "frame_dim": FRAME_DIM,
        }
    )
