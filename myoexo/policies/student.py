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

A student may carry a *fine-positioning* layer (:class:`FinePositioner`): a second network
on the same memory that estimates how far the human knee sits from the exo's encoder (the
straps' give, which the encoder cannot see), and an integral of the target minus that
estimated knee, added to the command near the target. It is fitted after distillation on the
student's own episodes (``myoexo policy knee-estimator``) and travels in the student's files.

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
import math
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.envs.observation import (
    CUFF_OBS_KEYS,
    DEFAULT_OBS_KEYS,
    EXO_SENSOR_OBS_KEYS,
    OBS_SCALES,
    STATE_OBS_KEYS,
)
from myoexo.envs.sensors import Measurements
from myoexo.policies.actor import (
    MLPActor,
    actor_arrays,
    actor_document,
    actor_from_document,
    clip_in_place,
    read_actor_files,
    save_actor,
)
from myoexo.runtime.fields import check_fields, option

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
#: Positions of the exo encoder angle (rad) and of the target (rad) in a frame.
EXO_ANGLE_INDEX, TARGET_INDEX = FRAME_KEYS.index("exo_angle_rad"), FRAME_KEYS.index("target_rad")
EXO_VEL_INDEX = FRAME_KEYS.index("exo_vel_rad_s")
_VEL_SCALE = OBS_SCALES["exo_vel_rad_s"]
#: The knee estimator's output range, deg (its tanh head spans +-this).
KNEE_OFFSET_RANGE_DEG = 20.0


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
        before it, ... (newest first); a new array, never a view of *history*.
    """
    h = np.asarray(history)
    newest_first = np.arange(h.shape[-2] - 1, -1, -int(stride))[: int(n_frames)]
    return h[..., newest_first, :].reshape(*h.shape[:-2], int(n_frames) * h.shape[-1])


@dataclass(frozen=True)
class FinePositioning:
    """The fine-positioning layer's integral law (:class:`FinePositioner`).

    Each control step the layer computes ``e`` = target - estimated knee angle (rad); while
    ``|e|`` is below :attr:`window_deg` and the encoder's speed below
    :attr:`speed_limit_deg_s`, its integral state moves by ``gain_per_rad_s x e x
    control_period_s``, clipped to ``+-limit``; the state is added to the student's command
    (then clipped to [-1, 1]). Otherwise the state is held: a knee that swings through the
    window (a limit cycle under a device's latency) does not wind it up.

    Raises:
        ValueError: A value outside its range (the message names it and the range).
    """

    gain_per_rad_s: float = option(
        1.25, "integral gain of the fine-positioning layer", low=0.0, unit="command/(rad s)"
    )
    window_deg: float = option(
        1.5, "the integral runs only this close to the target", low=0.0, above=True, unit="deg"
    )
    limit: float = option(0.3, "largest share of the command the integral gives", low=0.0, high=1.0)
    speed_limit_deg_s: float | None = option(
        10.0,
        "the integral runs only while the exo encoder turns slower than this (none: at any "
        "speed, the law of layers written before the option)",
        low=0.0,
        above=True,
        unit="deg/s",
    )
    control_period_s: float = option(
        0.01, "time between two decisions (the env's dt)", low=0.0, above=True, unit="s", flag=""
    )

    def __post_init__(self) -> None:
        check_fields(self)

    @property
    def frame_speed_limit(self) -> float:
        """:attr:`speed_limit_deg_s` in a frame's scale (the observation vector's; ``inf``
        for none)."""
        speed = self.speed_limit_deg_s
        return math.inf if speed is None else math.radians(speed) * _VEL_SCALE


class FinePositioner:
    """A student's fine-positioning layer: a knee estimator and an integral on its error.

    The estimator reads the student's network input without the weight (its memory of
    frames, newest first) and returns the human knee angle minus the exo encoder angle, deg;
    the knee estimate is the encoder angle plus that offset.

    Args:
        estimator: The network (input ``n_frames x FRAME_DIM``, output the offset in deg).
        law: The integral law.
    """

    def __init__(self, estimator: MLPActor, law: FinePositioning | None = None) -> None:
        if estimator.action_dim != 1:
            raise ValueError(f"the knee estimator has {estimator.action_dim} outputs, not 1")
        self.estimator = estimator
        self.law = law or FinePositioning()
        self._window_rad = math.radians(self.law.window_deg)
        self._step = self.law.gain_per_rad_s * self.law.control_period_s
        self._speed_limit = self.law.frame_speed_limit
        self.integral = 0.0

    def reset(self) -> None:
        """Start of an episode: the integral is 0."""
        self.integral = 0.0

    def offset_deg(self, window: np.ndarray) -> float:
        """The estimated knee angle minus the encoder angle, deg, from one network input."""
        return float(self.estimator(window)[0])

    def step(self, window: np.ndarray, frame: np.ndarray) -> float:
        """Update the integral from this step's memory and frame; return it."""
        if not abs(frame[EXO_VEL_INDEX]) < self._speed_limit:
            return self.integral  # held while the knee moves: no estimate needed
        knee_rad = frame[EXO_ANGLE_INDEX] + math.radians(self.offset_deg(window))
        error_rad = frame[TARGET_INDEX] - knee_rad
        if abs(error_rad) < self._window_rad:
            limit = self.law.limit
            self.integral = min(max(self.integral + self._step * error_rad, -limit), limit)
        return self.integral


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
        fine: The fine-positioning layer (``None``: the network's command alone); its
            estimator reads the same memory.
    """

    def __init__(
        self,
        actor: MLPActor,
        n_frames: int = 8,
        stride: int = 1,
        obs_keys: Sequence[str] = EXO_PRESET_KEYS,
        metadata: Mapping[str, Any] | None = None,
        gentleness_input: bool = False,
        fine: FinePositioner | None = None,
    ) -> None:
        if n_frames < 1 or stride < 1:
            raise ValueError(f"n_frames = {n_frames}, stride = {stride} must be >= 1")
        extra = int(bool(gentleness_input))
        if actor.obs_dim != n_frames * FRAME_DIM + extra:
            raise ValueError(
                f"actor input {actor.obs_dim} != n_frames {n_frames} x frame size {FRAME_DIM}"
                + (" + the gentleness weight" if extra else "")
            )
        if fine is not None and fine.estimator.obs_dim != n_frames * FRAME_DIM:
            raise ValueError(
                f"knee estimator input {fine.estimator.obs_dim} != n_frames {n_frames} x "
                f"frame size {FRAME_DIM}"
            )
        self.actor = actor
        self.fine = fine
        self.gentleness_input = bool(gentleness_input)
        self.n_frames = int(n_frames)
        self.stride = int(stride)
        self.history = history_length(n_frames, stride)
        self.metadata = dict(metadata or {})
        self.metadata["obs_preset"] = self.obs_preset  # what the evaluation's env reads
        self._memory: np.ndarray | None = None
        self._window: np.ndarray | None = None
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

    def with_fine(self, fine: FinePositioner | None) -> StudentController:
        """The same network, memory layout and provenance with *fine*'s estimator and law
        as the fine-positioning layer (``None``: without one); the layer's integral is the
        new controller's own."""
        return StudentController(
            self.actor,
            n_frames=self.n_frames,
            stride=self.stride,
            obs_keys=self.obs_keys,
            metadata=self.metadata,
            gentleness_input=self.gentleness_input,
            fine=None if fine is None else FinePositioner(fine.estimator, fine.law),
        )

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

    @property
    def last_window(self) -> np.ndarray | None:
        """The network input the last :meth:`push` made of the memory (newest frame first;
        ``None`` right after :meth:`reset`); a new array at every push, never changed
        afterwards."""
        return self._window

    def reset(self, seed: int | None = None) -> None:
        """Start of an episode: forget every frame (and the fine-positioning integral)."""
        del seed
        self._memory = None
        self._window = None
        if self.fine is not None:
            self.fine.reset()

    def push(self, frame: np.ndarray) -> np.ndarray:
        """Add a frame to the memory (the first one fills it); returns the network input."""
        f = np.asarray(frame, dtype=np.float64).reshape(FRAME_DIM)
        memory = self._memory
        if memory is None:
            memory = self._memory = np.repeat(f[None, :], self.history, axis=0)
        else:  # one frame older, in place (np.roll would allocate a new memory each step)
            memory[:-1] = memory[1:]
            memory[-1] = f
        self._window = stack_frames(memory, self.n_frames, self.stride)  # a copy
        return self._window

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """One decision: push this observation's frame, return the command ``(1,)`` float32
        in [-1, 1]. ``measurements`` is not read: the exo's sensors are in the frame (and,
        with :attr:`gentleness_input`, the weight is the observation's last entry)."""
        del measurements
        frame = self.frame(obs)
        if not np.isfinite(frame).all():
            raise ValueError(f"non-finite exo sensor reading {frame.tolist()}")
        window = self.push(frame)
        x = (
            np.concatenate((window, (float(np.asarray(obs).reshape(-1)[-1]),)))
            if self.gentleness_input
            else window
        )
        action = self.actor(x)
        if not np.isfinite(action).all():
            raise ValueError(f"the student returned a non-finite action {action.tolist()}")
        if self.fine is not None:
            action = clip_in_place(action, 1.0)
            action += self.fine.step(window, frame)
        return clip_in_place(action, 1.0).astype(np.float32)

    # ------------------------------------------------------------------ torch / ONNX
    def to_torch(self) -> Any:
        """The whole controller as a torch module: ``(frame (B, FRAME_DIM), memory (B,
        history - 1, FRAME_DIM)[, gentleness (B, 1)][, integral (B, 1)]) -> (action (B, 1),
        new memory[, new integral])``; memory oldest first; the weight with
        :attr:`gentleness_input`, the integral with a fine-positioning layer (:attr:`fine`)."""
        return _torch_student_class()(
            self.actor.to_torch(),
            self.n_frames,
            self.stride,
            self.gentleness_input,
            None if self.fine is None else self.fine.estimator.to_torch(),
            None if self.fine is None else self.fine.law,
        )

    def initial_memory(self, frame: np.ndarray) -> np.ndarray:
        """Memory (``history - 1`` frames) an episode's first step sees: its frame repeated
        (the ONNX model's input at the first step, as :meth:`push` does)."""
        f = np.asarray(frame, dtype=np.float32).reshape(1, FRAME_DIM)
        return np.repeat(f, self.history - 1, axis=0)


def _torch_student_class() -> type:
    import torch
    from torch import nn

    class _TorchStudent(nn.Module):
        def __init__(
            self,
            actor: nn.Module,
            n_frames: int,
            stride: int,
            gentleness_input: bool,
            estimator: nn.Module | None,
            law: FinePositioning | None,
        ) -> None:
            super().__init__()
            self.actor = actor
            self.estimator = estimator
            self.gentleness_input = gentleness_input
            history = history_length(n_frames, stride)
            # newest-first indices into the (history) frames, oldest first
            idx = [history - 1 - k * stride for k in range(n_frames)]
            self.register_buffer("select", torch.as_tensor(idx, dtype=torch.long))
            if law is not None:
                self.window_rad = math.radians(law.window_deg)
                self.integral_step = law.gain_per_rad_s * law.control_period_s
                self.limit = law.limit
                self.speed_limit = law.frame_speed_limit

        select: torch.Tensor

        def forward(
            self, frame: torch.Tensor, memory: torch.Tensor, *extra: torch.Tensor
        ) -> tuple[torch.Tensor, ...]:
            """The action from the memory with this frame (then the weight and the integral,
            as the controller has them), the memory for the next step (and the integral)."""
            full = torch.cat([memory, frame.unsqueeze(1)], dim=1)  # (B, history, F)
            window = torch.index_select(full, 1, self.select).flatten(1)
            weight = extra[:1] if self.gentleness_input else ()
            action = torch.clamp(self.actor(torch.cat([window, *weight], dim=1)), -1.0, 1.0)
            if self.estimator is None:
                return action, full[:, 1:, :]
            integral = extra[-1]
            offset_rad = self.estimator(window) * (math.pi / 180.0)
            knee = frame[:, EXO_ANGLE_INDEX : EXO_ANGLE_INDEX + 1] + offset_rad
            error = frame[:, TARGET_INDEX : TARGET_INDEX + 1] - knee
            moved = torch.clamp(integral + self.integral_step * error, -self.limit, self.limit)
            speed = frame[:, EXO_VEL_INDEX : EXO_VEL_INDEX + 1]
            runs = (torch.abs(error) < self.window_rad) & (torch.abs(speed) < self.speed_limit)
            integral = torch.where(runs, moved, integral)
            action = torch.clamp(action + integral, -1.0, 1.0)
            return action, full[:, 1:, :], integral

    return _TorchStudent


def export_student_onnx(student: StudentController, path: str | Path, opset: int = 17) -> Path:
    """Write the controller as ONNX: inputs ``frame`` (batch, FRAME_DIM) float32,
    ``memory`` (batch, history - 1, FRAME_DIM), for a student with
    :attr:`~StudentController.gentleness_input` ``gentleness`` (batch, 1), the weight in
    [0, 1], and for one with a fine-positioning layer ``integral`` (batch, 1); outputs
    ``action`` (batch, 1), ``memory_out`` (the memory for the next step) and, with the
    layer, ``integral_out``. At an episode's first step, memory is that step's frame
    repeated (:meth:`StudentController.initial_memory`) and the integral 0."""
    import warnings

    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module = student.to_torch().eval()
    args: tuple[Any, ...] = (
        torch.zeros(1, FRAME_DIM),
        torch.zeros(1, student.history - 1, FRAME_DIM),
    )
    inputs, outputs = ["frame", "memory"], ["action", "memory_out"]
    if student.gentleness_input:
        args = (*args, torch.zeros(1, 1))
        inputs.append("gentleness")
    if student.fine is not None:
        args = (*args, torch.zeros(1, 1))
        inputs.append("integral")
        outputs.append("integral_out")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        torch.onnx.export(
            module,
            args,
            str(path),
            input_names=inputs,
            output_names=outputs,
            dynamic_axes={name: {0: "batch"} for name in inputs + outputs},
            opset_version=opset,
            dynamo=False,
        )
    return path


# ---------------------------------------------------------------------------- files
def save_student(student: StudentController, path_stem: str | Path) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` (weights) and ``<stem>.json`` (normalization, the controller's
    fields under ``"student"``, provenance and reference pairs); returns the two paths. A
    fine-positioning layer travels in the same files: its estimator's weights as
    ``knee_layer<i>.*`` in the ``.npz``, the rest of it (normalization, provenance, reference
    pairs) and its law under ``"student"`` / ``"fine_positioning"``."""
    meta = dict(student.actor.metadata)
    meta.update(student.metadata)  # provenance: top level, as the shipped actors keep it
    block: dict[str, Any] = {
        "format_version": STUDENT_FORMAT_VERSION,
        "frame_keys": list(FRAME_KEYS),
        "frame_dim": FRAME_DIM,
        "n_frames": student.n_frames,
        "stride": student.stride,
        "history": student.history,
        "ignored_keys": ["time_frac"],
        "gentleness_input": student.gentleness_input,
    }
    extra: dict[str, np.ndarray] = {}
    if student.fine is not None:
        estimator = _float32_with_reference(student.fine.estimator, None)
        extra = actor_arrays(estimator, KNEE_PREFIX)
        block["fine_positioning"] = {
            "law": asdict(student.fine.law),
            "estimator": actor_document(estimator),
        }
    meta.update(obs_preset=StudentController.obs_preset, obs_keys=list(EXO_PRESET_KEYS))
    meta["student"] = block
    return save_actor(_float32_with_reference(student.actor, meta), path_stem, extra)


#: Prefix of a fine-positioning layer's estimator arrays in a student's ``.npz``.
KNEE_PREFIX = "knee_layer"


def _float32_with_reference(actor: MLPActor, metadata: Mapping[str, Any] | None) -> MLPActor:
    """*actor* with its weights rounded to float32 (what the files hold) and *metadata*
    (default: its own), with reference pairs computed on those weights unless present."""
    weights = [(w.astype(np.float32), b.astype(np.float32)) for w, b in actor.weights]
    meta = dict(actor.metadata if metadata is None else metadata)
    out = MLPActor(
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
        mean = np.zeros(out.obs_dim) if out.obs_mean is None else out.obs_mean
        std = np.ones(out.obs_dim) if out.obs_var is None else np.sqrt(out.obs_var)
        x = mean + std * rng.standard_normal((8, out.obs_dim))
        out.metadata["reference"] = {"observations": x.tolist(), "actions": out(x).tolist()}
    return out


def load_student(path_stem: str | Path, check: bool = True) -> StudentController:
    """Read a controller written by :func:`save_student` (``check``: replay its reference
    pairs, ``ValueError`` if the files disagree with them)."""
    meta, arrays = read_actor_files(path_stem)
    return student_from_actor(actor_from_document(meta, arrays), arrays, path_stem, check)


def student_from_actor(
    actor: MLPActor, arrays: Mapping[str, np.ndarray], path_stem: str | Path, check: bool = True
) -> StudentController:
    """The controller around an actor read from a student file (*path_stem*, for the
    messages) and the file's *arrays* (:func:`~myoexo.policies.actor.read_actor_files`; a
    fine-positioning layer's estimator is among them): :func:`load_student` without reading
    the files again."""
    block = actor.metadata.get("student")
    if not isinstance(block, dict) or block.get("format_version") != STUDENT_FORMAT_VERSION:
        raise ValueError(f"{path_stem}: not a student controller file (no 'student' block)")
    if list(block["frame_keys"]) != list(FRAME_KEYS):
        raise ValueError(f"{path_stem}: frame keys {block['frame_keys']} != {list(FRAME_KEYS)}")
    if check:
        actor.check_reference()
    fine = None
    if "fine_positioning" in block:
        layer = block["fine_positioning"]
        estimator = actor_from_document(layer["estimator"], arrays, KNEE_PREFIX)
        if check:
            estimator.check_reference()
        # a layer written before the speed condition integrates at any speed
        law = FinePositioning(**{"speed_limit_deg_s": None, **layer["law"]})
        fine = FinePositioner(estimator, law)
    extra = {k: v for k, v in actor.metadata.items() if k not in _NOT_PROVENANCE}
    return StudentController(
        actor,
        n_frames=int(block["n_frames"]),
        stride=int(block["stride"]),
        metadata=extra,
        gentleness_input=bool(block.get("gentleness_input", False)),
        fine=fine,
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
