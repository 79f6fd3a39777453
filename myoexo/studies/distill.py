"""``myoexo policy distill``: distil the full-state teacher into an exo-sensor student (DAgger).

The teacher is the shipped full-state policy (``sac``: it reads the human knee, the muscles
and the straps, which only the simulation knows). The student is a
:class:`~myoexo.policies.student.StudentController`: an MLP on its last frames of what the
exoskeleton measures (encoder, motor torque, cuff force/torque sensors, last command,
target; no episode clock). Plain behaviour cloning of the teacher's own trajectories fails
(the student's small errors take it to states the teacher never visits), so the data is
collected DAgger-style:

* round ``r`` runs ``episodes_per_round`` episodes (levels in turn, subjects of root seed
  :data:`~myoexo.evaluation.config.SELECTION_ROOT_SEED` from index ``subject_offset`` on,
  never the evaluation root 0); at each step the executed command is the teacher's with
  probability ``beta_r = beta_decay ** r`` (round 0: the teacher alone) and the student's
  otherwise; the teacher *labels every visited step* from the true full state;
* a ``robust_fraction`` of the episodes runs on perturbed twins (``robustness=True``: strap
  stiffness/damping, masses, friction, motor gain, sensor noise, 10 ms latency): the student
  reads the noisy, late sensor values of the env's observation, while the teacher labels
  from the exact state of the same step (``info["obs_dict"]``, the true buffer, flattened as
  the teacher's env would);
* after each round the student is trained (torch, CPU, warm-started) on the aggregated
  dataset and scored on held-apart selection subjects (root 1, indices ``0..n-1`` per level,
  nominal and perturbed twins; a student with the weight input at ``selection_weights``);
  the best round is the run's student (``--reselect DIR`` scores a finished run's rounds
  again under new selection settings).

Run folder (every file written atomically; ``--resume DIR`` continues after the last
finished round)::

    config.json                 settings (a resume keeps them)
    dataset.npz                 frames (N, FRAME_DIM), teacher labels (N,), episode starts
    student_round_<r>.npz/json  the student after round r
    student.npz/json            the selected (best) student so far
    history.json                per round: samples, beta, loss, selection scores, wall time

Examples::

    myoexo policy distill --run-dir runs/distill --rounds 8 --episodes-per-round 96 \
        --robust-fraction 0.5
    myoexo policy distill --run-dir runs/distill_s0 --fine-gain 20 --fine-width-rad 0.02 \
        --teacher-guard --seed 0                                # the shipped recipe, seed 0
    myoexo policy distill --resume runs/distill
    myoexo policy distill --resume runs/distill --rounds 12            # more rounds
    myoexo policy distill --reselect runs/distill --selection-weights 0 0.5 1  # no training
    myoexo policy distill --ship runs/distill_s0 runs/distill_s1 runs/distill_s2 \
        --name student_exo --seed-copies runs/student_seeds      # the seed rule picks one

Several seeds: each is its own run folder (``--seed``); ``--ship`` chooses one by the seed
rule (:data:`SHIP_RULE`, a typical seed on the selection subjects, not the best) and writes
every seed's student beside it so that ``myoexo evaluate`` reports them as one controller,
with intervals over seeds and subjects.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.guard import StallGuardConfig, StallIntegrator
from myoexo.control.protocol import Controller, declared_sensors
from myoexo.envs.config import GENTLENESS_RANGE
from myoexo.envs.options import TwinOptions, add_twin_arguments, twin_from_args
from myoexo.envs.sensors import read_sensors
from myoexo.evaluation.config import SELECTION_ROOT_SEED, check_fit_root, subject_seed
from myoexo.model import TWIN_VERSION
from myoexo.policies.actor import MLPActor
from myoexo.policies.student import (
    FRAME_DIM,
    StudentController,
    frame_indices,
    load_student,
    save_student,
)
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    check_fields,
    flag_of,
    from_options,
    option,
    option_fields,
)
from myoexo.runtime.files import package_versions, savez_atomic, write_json_atomic
from myoexo.runtime.lifecycle import FolderLock
from myoexo.spasticity.levels import VALID_LEVELS
from myoexo.training.checkpoints import CONFIG_FILE

#: Files of a distillation run folder besides the settings (``CONFIG_FILE``, named as in a
#: training run folder, :mod:`myoexo.training.checkpoints`).
DATASET_FILE = "dataset.npz"
HISTORY_FILE = "history.json"
BEST_STEM = "student"
#: A teacher label at or beyond this magnitude commands the motor's limit (labels are clipped).
LIMIT_LABEL = 1.0 - 1e-6


@dataclass(frozen=True)
class DistillConfig:
    """Settings of a distillation run (``config.json``); each field is an option of
    ``myoexo policy distill`` of its own name (``--episodes-per-round``).

    ``fine_gain`` adds a privileged fine-positioning term to the teacher's label,
    ``-fine_gain * e * exp(-(e / fine_width_rad)^2)`` with ``e`` the true knee error (rad):
    active only within about a degree of the target (the teacher ``sac`` settles 0.5-0.7 deg
    short at levels 0-1), zero far from it (levels 2-3, the transient). ``teacher_guard``
    labels with the teacher under the stall guard
    (:class:`~myoexo.control.guard.StallGuard`, its default settings, on the true knee
    error): once the knee has stalled far from the target, the labels carry the guard's
    integral action along the visited trajectory, so that the student, whose frames hold its
    last command, can learn to keep pushing (``guard:sac`` is the shipped full-state
    controller). ``twin``: the twin distilled on (task, e.g. ``episode_duration_s``, and
    reflex model; the teacher reads the full observation, the student the exo sensors;
    robustness is drawn per episode with ``robust_fraction``).
    """

    rounds: int = option(8, "DAgger rounds (round 0: the teacher drives)", low=1)
    episodes_per_round: int = option(96, "episodes collected per round (levels in turn)", low=1)
    levels: tuple[int, ...] = option(
        (0, 1, 2, 3), "spasticity levels of the collected subjects", choices=VALID_LEVELS,
        metavar="LEVEL",
    )  # fmt: skip
    robust_fraction: float = option(
        0.5, "share of episodes on perturbed twins (sensors, latency, twin changes)",
        low=0.0, high=1.0,
    )  # fmt: skip
    beta_decay: float = option(
        0.5, "the teacher's command is executed with probability beta_decay ** round",
        low=0.0, high=1.0,
    )  # fmt: skip
    action_noise_std: float = option(
        0.0, "Gaussian noise on the executed command (the label stays the teacher's)", low=0.0
    )
    n_frames: int = option(10, "frames the student sees", low=1)
    stride: int = option(2, "control steps between two frames", low=1)
    hidden: tuple[int, ...] = option((256, 256), "hidden layer widths of the student", low=1)
    activation: str = option(
        "elu", "hidden activation of the student", choices=("gelu", "relu", "tanh", "elu")
    )
    epochs_first: int = option(20, "training epochs after round 0", low=1)
    epochs: int = option(8, "training epochs after each later round", low=1)
    batch_size: int = option(512, "Adam minibatch size", low=1)
    lr: float = option(1e-3, "Adam step size", low=0.0, above=True)
    weight_decay: float = option(0.0, "Adam weight decay", low=0.0)
    smoothness_weight: float = option(
        0.0,
        "weight of the temporal smoothness term: the mean change of the student's command "
        "between consecutive control steps of an episode (priced by smoothness_norm), added "
        "to the imitation loss (CAPS, Mysore et al. 2021; 0: imitation alone)",
        low=0.0,
    )
    smoothness_norm: str = option(
        "squared",
        "how the smoothness term prices a change of the command between consecutive steps: "
        "'squared' (its mean square, which also slows a monotone move) or 'absolute' (its "
        "mean absolute value: the command's total variation per step, the smoothness measure "
        "of the tables, which a monotone move of any speed pays only its height for)",
        choices=("squared", "absolute"),
    )
    output_reach: float = option(
        1.0,
        "the student's tanh head spans [-reach, reach] and its command is then clipped to "
        "[-1, 1]: above 1 a finite output holds the motor's limit where the teacher does "
        "(1: the tanh alone, which approaches the limit but never reaches it)",
        low=1.0,
        high=2.0,
    )
    limit_margin: float = option(
        0.0,
        "a label at the motor's limit is met only by a command at least this far beyond it "
        "(then clipped), so that the student holds the limit through sensor noise and "
        "latency (0: any command at or beyond the limit; below output_reach - 1)",
        low=0.0,
    )
    teacher: str = option(
        "sac",
        "full-state policy that labels the states: a shipped one (sac, or residual on its base "
        "at its default gentleness weight; residual@W at weight W) or an exported actor's "
        "STEM.npz (myoexo policy export --out STEM)",
    )
    fine_gain: float = option(
        0.0, "privileged fine-positioning term on the teacher's labels (0: the teacher alone)",
        low=0.0,
    )  # fmt: skip
    fine_width_rad: float = option(
        0.02, "width of the fine-positioning term", low=0.0, above=True, unit="rad"
    )
    teacher_guard: bool = option(
        False, "label with the teacher under the stall guard (guard:sac) on the true knee"
    )
    gentleness_input: bool = option(
        False,
        "the student takes the gentleness weight as an input: each episode draws a weight "
        "uniformly over [0, 1] and the teacher (trained over the weight range) labels at it; "
        "the student is selected at --selection-weights (default: the teacher's default weight)",
    )
    selection_weights: tuple[float, ...] = option(
        (),
        "gentleness weights at which a student with the weight input is selected: each round's "
        "selection error is its mean over them (none given: the teacher's default weight)",
        low=0.0,
        high=1.0,
        metavar="W",
    )
    root_seed: int = option(
        SELECTION_ROOT_SEED,
        "root seed of the training and selection subjects (never the evaluation root)",
        low=0,
    )
    subject_offset: int = option(10_000, "first subject index of the training episodes", low=0)
    selection_subjects: int = option(
        8, "selection subjects per level and twin (0: the last round is the student)", low=0
    )
    twin: TwinOptions = option(doc="the twin distilled on", default_factory=TwinOptions, flag="")
    seed: int = option(0, "seed of the mixture draws, the noise and torch", low=0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "levels", tuple(self.levels))
        object.__setattr__(self, "hidden", tuple(self.hidden))
        object.__setattr__(self, "selection_weights", tuple(self.selection_weights))
        check_fields(self)
        if self.selection_weights and not self.gentleness_input:
            raise FieldError(
                "DistillConfig",
                "selection_weights",
                self.selection_weights,
                "is for a student with the weight input (gentleness_input = true)",
            )
        check_fit_root(self.root_seed, "distillation (it trains and selects the student)")
        if self.subject_offset < self.selection_subjects:
            raise FieldError(
                "DistillConfig",
                "subject_offset",
                self.subject_offset,
                f"must exceed selection_subjects = {self.selection_subjects} (disjoint subjects)",
            )
        for name in ("levels", "hidden"):
            if not getattr(self, name):
                raise FieldError("DistillConfig", name, (), "is empty")
        if self.limit_margin and not self.limit_margin < self.output_reach - 1.0:
            raise FieldError(
                "DistillConfig", "limit_margin", self.limit_margin,
                f"must be below output_reach - 1 = {self.output_reach - 1.0:g} (the head's "
                "outputs stop short of the reach)",
            )  # fmt: skip
        if self.twin.robustness:
            raise ValueError(
                "twin robustness = true: distillation draws perturbed twins per episode with "
                "robust_fraction (1.0: every episode perturbed)"
            )
        if self.twin.obs_keys or self.twin.obs_preset != "full":
            raise ValueError(
                f"twin observation [{self.twin.describe()}]: the teacher reads the full "
                "observation and the student the exo sensors; give no observation option"
            )

    @property
    def episode_duration_s(self) -> float | None:
        """The twin's episode length if overridden (``None``: the env's 8 s)."""
        return self.twin.episode_duration_s

    def beta(self, round_index: int) -> float:
        """Probability that the teacher's command is executed in a round."""
        return 1.0 if round_index == 0 else float(self.beta_decay**round_index)

    def to_json(self) -> dict[str, Any]:
        return {**dataclasses.asdict(self), "twin": self.twin.to_dict()}

    @classmethod
    def from_json(cls, doc: dict[str, Any]) -> DistillConfig:
        names = {f.name for f in dataclasses.fields(cls)}
        kwargs = {k: v for k, v in doc.items() if k in names}
        twin = kwargs.get("twin")
        if isinstance(twin, dict):
            kwargs["twin"] = TwinOptions.from_dict(twin)
        elif doc.get("episode_duration_s") is not None:  # a run written before the record
            kwargs["twin"] = TwinOptions().replace(episode_duration_s=doc["episode_duration_s"])
        return cls(**kwargs)


# ---------------------------------------------------------------------------- teacher
def true_full_observation(env: Any, info: dict[str, Any] | None) -> np.ndarray:
    """The ``obs_preset="full"`` vector of the env's *true* state (no sensor noise or
    latency): from ``info["obs_dict"]`` after a step, from the state itself after a reset."""
    u = env.unwrapped
    od = (info or {}).get("obs_dict")
    if od is None:
        od = u._get_obs_dict(u._accessor)
    return np.asarray(u._obs_dict_to_vec(od), dtype=np.float64)


class Expert:
    """The labelling expert: the teacher on the true full state, plus the optional
    fine-positioning term on the true knee error and the optional stall guard on it
    (:class:`DistillConfig`). With the guard, or a teacher with a state of its own (a
    residual policy's base controller), it has a state: :meth:`reset` at each episode's
    start, then one call per control step.

    Args:
        teacher: The teacher's actor (its metadata names its observation).
        fine_gain, fine_width_rad, guard: See :class:`DistillConfig`.
        controller: The teacher as it runs (:func:`teacher_controller`: a residual policy
            on its base, a gentleness-trained one at its weight); it then labels, reading
            the full observation and its sensors from the step's ``info``. ``None``: the
            actor alone labels.
    """

    def __init__(
        self,
        teacher: MLPActor,
        fine_gain: float = 0.0,
        fine_width_rad: float = 0.02,
        guard: StallGuardConfig | None = None,
        controller: Controller | None = None,
    ):
        self.teacher = teacher
        self.controller = controller
        self._sensors = frozenset() if controller is None else declared_sensors(controller)
        self.fine_gain = float(fine_gain)
        self.fine_width_rad = float(fine_width_rad)
        keys = list(teacher.metadata.get("obs_keys") or [])
        if (self.fine_gain or guard is not None) and keys[:6] != [
            "knee_angle_rad", "knee_vel_rad_s", "exo_angle_rad", "exo_vel_rad_s",
            "target_rad", "error_rad",
        ]:  # fmt: skip
            raise ValueError(f"the teacher's observation has no error_rad at index 5: {keys}")
        self.guard = None if guard is None else StallIntegrator(guard)

    def set_gentleness(self, weight: float) -> None:
        """Label at the gentleness weight *weight* from now on (a teacher trained over the
        weight range, run as a controller).

        Raises:
            ValueError: The teacher takes no weight.
        """
        from myoexo.control.policy import GentleController

        if not isinstance(self.controller, GentleController):
            raise ValueError("the teacher takes no gentleness weight")
        self.controller = GentleController(self.controller.controller, weight)

    def reset(self, seed: int | None = None) -> None:
        """Start an episode (disengages the guard, resets the teacher's controller)."""
        if self.guard is not None:
            self.guard.reset(seed)
        if self.controller is not None:
            self.controller.reset(seed)

    def __call__(self, x_full: np.ndarray, info: dict[str, Any] | None = None) -> np.ndarray:
        """The label of one step: *x_full* the true full observation, *info* the step's
        ``info`` (what a teacher's controller reads its sensors from)."""
        if self.controller is None:
            a = self.teacher(x_full)
        else:
            if info is None:
                raise ValueError("a teacher that runs as a controller needs the step's info")
            a = self.controller.act(x_full, read_sensors(info, self._sensors))
        e = float(x_full[5])  # error_rad (scale 1): knee minus target, true state
        if self.fine_gain:
            a = a - self.fine_gain * e * math.exp(-((e / self.fine_width_rad) ** 2))
        a = np.clip(np.asarray(a, np.float32).reshape(1), -1.0, 1.0)
        return a if self.guard is None else self.guard.correct(a, e)


def load_teacher(name: str = "sac") -> MLPActor:
    """The full-state teacher's actor (checked against its reference pairs): a shipped
    policy by name, or an exported actor by the path of its ``.npz`` (beside its
    ``.json``, e.g. ``myoexo policy export RUN --out STEM``); *name* may carry a gentleness
    weight (``residual@0.5``, ``runs/teacher.npz@0.5``)."""
    from myoexo.policies import load_controller, load_policy

    stem = name.rpartition("@")[0] if "@" in name else name
    if stem.endswith(".npz"):
        teacher = load_controller(Path(stem).with_suffix(""))
    else:
        teacher = load_policy(stem)
    if not isinstance(teacher, MLPActor):
        raise ValueError(f"teacher {name!r} is not a plain actor ({type(teacher).__name__})")
    if teacher.obs_preset != "full":
        raise ValueError(f"teacher {name!r} reads obs_preset {teacher.obs_preset!r}, not 'full'")
    return teacher


def teacher_controller(name: str, actor: MLPActor, env: Any) -> Controller | None:
    """The teacher *name* as it runs on *env*, where its actor alone is not the teacher: a
    residual policy on its base controller, a policy trained over the gentleness range at
    its weight (``NAME@W``, else its default); ``None`` for a plain actor."""
    from myoexo.control.residual import ResidualConfig
    from myoexo.control.specs import build_controller, parse_controller_spec
    from myoexo.training.export import trained_over_gentleness

    meta = actor.metadata
    if ResidualConfig.from_metadata(meta) is None and not trained_over_gentleness(meta):
        return None
    return build_controller(parse_controller_spec(name), env)


# ---------------------------------------------------------------------------- collection
@dataclass
class Episodes:
    """Collected steps: frames (what the student read), teacher labels, episode starts."""

    frames: np.ndarray = field(default_factory=lambda: np.zeros((0, FRAME_DIM), np.float32))
    labels: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))
    starts: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    rounds: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    #: Each step's gentleness weight (the episode's; 0 where the student takes none, and
    #: where none is given).
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float32))

    def __post_init__(self) -> None:
        if self.weights.size == 0:
            self.weights = np.zeros(self.labels.size, np.float32)

    @property
    def size(self) -> int:
        return int(self.labels.size)

    def extend(self, other: Episodes) -> Episodes:
        return Episodes(
            np.concatenate([self.frames, other.frames]),
            np.concatenate([self.labels, other.labels]),
            np.concatenate([self.starts, other.starts + self.size]),
            np.concatenate([self.rounds, other.rounds]),
            np.concatenate([self.weights, other.weights]),
        )

    def save(self, path: Path) -> None:
        savez_atomic(
            path,
            frames=self.frames,
            labels=self.labels,
            starts=self.starts,
            rounds=self.rounds,
            weights=self.weights,
        )

    @classmethod
    def load(cls, path: Path) -> Episodes:
        with np.load(path) as d:
            weights = d["weights"] if "weights" in d.files else np.zeros(0, np.float32)
            return cls(d["frames"], d["labels"], d["starts"], d["rounds"], weights)

    def stack_index(self, n_frames: int, stride: int) -> np.ndarray:
        """``(N, n_frames)`` row indices of each sample's frames, newest first, the
        episode's first frame repeating before its start (as the controller's memory)."""
        n = self.size
        ep_start = np.zeros(n, dtype=np.int64)
        bounds = np.append(self.starts, n)
        for a, b in itertools.pairwise(bounds):
            ep_start[a:b] = a
        t = np.arange(n, dtype=np.int64) - ep_start
        lag = np.arange(n_frames, dtype=np.int64) * stride
        return ep_start[:, None] + np.maximum(t[:, None] - lag[None, :], 0)


class EnvPool:
    """One ``obs_preset="full"`` env of the twin per (level, perturbed), built on first use."""

    def __init__(self, twin: TwinOptions | None = None) -> None:
        self.twin = twin or TwinOptions()
        self._envs: dict[tuple[int, bool], Any] = {}

    def get(self, level: int, perturbed: bool) -> Any:
        from myoexo.envs import make_env

        key = (int(level), bool(perturbed))
        if key not in self._envs:
            options = self.twin.replace(robustness=bool(perturbed))
            self._envs[key] = make_env(int(level), **options.env_kwargs())
        return self._envs[key]

    def close(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()


def collect_episode(
    env: Any,
    teacher: Callable[[np.ndarray, dict[str, Any]], np.ndarray],
    student: StudentController | None,
    seed: int,
    beta: float,
    rng: np.random.Generator,
    action_noise_std: float = 0.0,
    gentleness: float | None = None,
) -> tuple[np.ndarray, np.ndarray, dict[str, float]]:
    """One episode: the executed command is the teacher's with probability ``beta`` per
    step (always without a student), else the student's; every step is labelled by the
    teacher from the true full state. With *gentleness*, the teacher labels at that weight
    (:meth:`Expert.set_gentleness`) and the student reads it as its last input. Returns
    ``(frames, labels, summary)``."""
    idx = frame_indices(list(env.unwrapped.obs_keys))
    if gentleness is not None:
        teacher.set_gentleness(gentleness)  # type: ignore[attr-defined]
    obs, info = env.reset(seed=int(seed))
    reset = getattr(teacher, "reset", None)
    if reset is not None:  # a stateful expert (the stall guard) starts its episode
        reset(seed)
    if student is not None:
        student.bind(env).reset(seed)
    frames, labels = [], []
    max_steps = int(env.unwrapped.episode_steps)
    for _ in range(max_steps):
        x_teacher = true_full_observation(env, info)
        a_teacher = teacher(x_teacher, info)
        frames.append(np.asarray(obs, np.float64)[idx])
        labels.append(float(a_teacher[0]))
        if student is not None:
            # its exo sensors are in the observation (and its weight last, where it takes one)
            a_student = student.act(obs if gentleness is None else np.append(obs, gentleness))
            a = a_teacher if rng.random() < beta else a_student
        else:
            a = a_teacher
        if action_noise_std > 0.0:
            a = a + action_noise_std * rng.standard_normal(1)
        a = np.clip(np.asarray(a, np.float32).reshape(1), -1.0, 1.0)
        obs, _, terminated, truncated, info = env.step(a)
        if terminated or truncated:
            break
    summary = {"final_error_deg": float(info["error_deg"]), "level": int(info["level"])}
    return np.asarray(frames, np.float32), np.asarray(labels, np.float32), summary


def collect_round(
    config: DistillConfig,
    round_index: int,
    teacher: Callable[[np.ndarray, dict[str, Any]], np.ndarray],
    student: StudentController | None,
    envs: EnvPool,
) -> tuple[Episodes, dict[str, Any]]:
    """The episodes of one round (deterministic given the config and the round)."""
    rng = np.random.default_rng([int(config.seed), int(round_index), 0xDA66E4])
    beta = config.beta(round_index) if student is not None else 1.0
    parts: list[tuple[np.ndarray, np.ndarray, float]] = []
    errors: dict[str, list[float]] = {}
    n_levels = len(config.levels)
    for j in range(config.episodes_per_round):
        level = config.levels[j % n_levels]
        perturbed = bool(rng.random() < config.robust_fraction)
        weight = float(rng.uniform(*GENTLENESS_RANGE)) if config.gentleness_input else None
        index = config.subject_offset + round_index * config.episodes_per_round + j
        seed = subject_seed(level, index, config.root_seed)
        frames, labels, summary = collect_episode(
            envs.get(level, perturbed),
            teacher,
            student,
            seed,
            beta,
            rng,
            config.action_noise_std,
            weight,
        )
        parts.append((frames, labels, 0.0 if weight is None else weight))
        key = f"L{level}{'p' if perturbed else ''}"
        errors.setdefault(key, []).append(abs(summary["final_error_deg"]))
    sizes = [p[1].size for p in parts]
    starts = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
    eps = Episodes(
        np.concatenate([p[0] for p in parts]),
        np.concatenate([p[1] for p in parts]),
        starts,
        np.full(int(sum(sizes)), round_index, np.int32),
        np.concatenate([np.full(p[1].size, p[2], np.float32) for p in parts]),
    )
    stats = {
        "beta": beta,
        "episodes": config.episodes_per_round,
        "samples": eps.size,
        "driven_abs_final_error_deg": {k: float(np.mean(v)) for k, v in sorted(errors.items())},
    }
    return eps, stats


# ---------------------------------------------------------------------------- training
def _normalization(frames: np.ndarray, n_frames: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-feature mean and variance of the frames, tiled over the stacked frames; a
    constant feature (the target) gets variance 1 (so it is only centred)."""
    mean = frames.astype(np.float64).mean(axis=0)
    var = frames.astype(np.float64).var(axis=0)
    var = np.where(var < 1e-10, 1.0, var)
    return np.tile(mean, n_frames), np.tile(var, n_frames)


def _build_module(config: DistillConfig, in_dim: int) -> Any:
    from torch import nn

    acts = {"gelu": nn.GELU, "relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU}
    layers: list[Any] = []
    width = in_dim
    for h in config.hidden:
        layers += [nn.Linear(width, h), acts[config.activation]()]
        width = h
    layers.append(nn.Linear(width, 1))
    return nn.Sequential(*layers)


def _module_from_actor(actor: MLPActor, config: DistillConfig) -> Any:
    import torch

    module = _build_module(config, actor.obs_dim)
    linears = [m for m in module if isinstance(m, torch.nn.Linear)]
    with torch.no_grad():
        for lin, (w, b) in zip(linears, actor.weights, strict=True):
            lin.weight.copy_(torch.as_tensor(w, dtype=torch.float32))
            lin.bias.copy_(torch.as_tensor(b, dtype=torch.float32))
    return module


def imitation_error(pred: Any, target: Any, margin: float = 0.0) -> Any:
    """The student's error on a batch of labels (torch tensors): ``pred - target``, except
    that a label at the motor's limit is met by any command at least *margin* beyond it
    (the command is then clipped to the limit), so such a label pulls a command only up to
    ``limit + margin`` and never back."""
    import torch

    upper, lower = target >= LIMIT_LABEL, target <= -LIMIT_LABEL
    if margin:
        target = target + margin * (upper.float() - lower.float())
    err = pred - target
    err = torch.where(upper & (err > 0.0), torch.zeros_like(err), err)
    return torch.where(lower & (err < 0.0), torch.zeros_like(err), err)


def train_student(
    config: DistillConfig,
    data: Episodes,
    epochs: int,
    previous: StudentController | None,
    seed: int,
    log: Callable[[str], None] = print,
) -> tuple[StudentController, dict[str, float]]:
    """Fit the student to the teacher's labels (MSE on the head's output, ``output_reach x
    tanh``; a label at the motor's limit counts only a command short of it), warm-started
    from ``previous`` (its input normalization is recomputed on the aggregated data, and
    its first layer re-expressed so that the warm start is the same function)."""
    import torch

    torch.set_num_threads(1)
    torch.manual_seed(seed)
    weighted = config.gentleness_input
    in_dim = config.n_frames * FRAME_DIM + int(weighted)
    mean, var = _normalization(data.frames, config.n_frames)
    if weighted:  # the weight's column last, normalised by the uniform draw's moments
        low, high = GENTLENESS_RANGE
        mean, var = np.append(mean, 0.5 * (low + high)), np.append(var, (high - low) ** 2 / 12)
    std = np.sqrt(var + 1e-8)
    if previous is not None:
        module = _module_from_actor(previous.actor, config)
        old = previous.actor
        old_mean = old.obs_mean if old.obs_mean is not None else np.zeros(in_dim)
        old_std = np.sqrt(old.obs_var + old.epsilon) if old.obs_var is not None else np.ones(in_dim)
        # z_old = (x - m_old) / s_old = (z_new * s_new + m_new - m_old) / s_old
        first = module[0]
        with torch.no_grad():
            w = first.weight.double().numpy()
            b = first.bias.double().numpy()
            scale = std / old_std
            shift = (mean - old_mean) / old_std
            first.weight.copy_(torch.as_tensor(w * scale[None, :], dtype=torch.float32))
            first.bias.copy_(torch.as_tensor(b + w @ shift, dtype=torch.float32))
    else:
        module = _build_module(config, in_dim)
    z = np.clip((data.frames - mean[:FRAME_DIM]) / std[:FRAME_DIM], -10.0, 10.0)  # as MLPActor
    frames = torch.as_tensor(z, dtype=torch.float32)
    z_weight = (
        torch.as_tensor((data.weights - mean[-1]) / std[-1], dtype=torch.float32)
        if weighted
        else None
    )
    index = torch.as_tensor(data.stack_index(config.n_frames, config.stride))
    reach = float(config.output_reach)
    labels = torch.as_tensor(data.labels, dtype=torch.float32)
    # each step's next step in the same episode (the last step of an episode: itself)
    following = np.arange(1, labels.numel() + 1)
    following[np.append(data.starts[1:], labels.numel()) - 1] -= 1
    next_row = torch.as_tensor(following)

    def command(rows: Any) -> Any:
        x = frames[index[rows]].flatten(1)
        if z_weight is not None:
            x = torch.cat([x, z_weight[rows].unsqueeze(1)], dim=1)
        return reach * torch.tanh(module(x)).squeeze(1)

    margin = float(config.limit_margin)

    opt = torch.optim.Adam(module.parameters(), lr=config.lr, weight_decay=config.weight_decay)
    n = labels.numel()
    gen = torch.Generator().manual_seed(seed)
    steps_per_epoch = max(1, math.ceil(n / config.batch_size))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(
        opt, T_max=max(1, epochs * steps_per_epoch), eta_min=config.lr * 0.05
    )
    loss_value = float("nan")
    for epoch in range(epochs):
        perm = torch.randperm(n, generator=gen)
        total, count = 0.0, 0
        for k in range(steps_per_epoch):
            rows = perm[k * config.batch_size : (k + 1) * config.batch_size]
            pred = command(rows)
            mse = torch.mean(imitation_error(pred, labels[rows], margin) ** 2)
            loss = mse
            if config.smoothness_weight > 0.0:  # on the executed (clipped) command
                step = torch.clamp(command(next_row[rows]), -1.0, 1.0) - torch.clamp(
                    pred, -1.0, 1.0
                )
                change = step**2 if config.smoothness_norm == "squared" else torch.abs(step)
                loss = mse + config.smoothness_weight * torch.mean(change)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            total += float(mse.detach()) * rows.numel()
            count += rows.numel()
        loss_value = total / max(count, 1)
        log(f"[distill]   epoch {epoch + 1}/{epochs}: mse {loss_value:.3e}")
    linears = [m for m in module if isinstance(m, torch.nn.Linear)]
    weights = [
        (lin.weight.detach().double().numpy(), lin.bias.detach().double().numpy())
        for lin in linears
    ]
    actor = MLPActor(
        weights,
        activation=config.activation,
        obs_mean=mean,
        obs_var=var,
        action_low=-reach,
        action_high=reach,
    )
    student = StudentController(actor, config.n_frames, config.stride, gentleness_input=weighted)
    return student, {"train_mse": loss_value}


# ---------------------------------------------------------------------------- selection
def selection_scores(
    student: StudentController,
    config: DistillConfig,
    envs: EnvPool,
    gentleness: float | None = None,
) -> dict[str, float]:
    """Mean |final error| (deg) of the student on the selection subjects (root
    ``config.root_seed``, indices ``0..selection_subjects-1``), per level and twin, and
    ``score``: their mean. A student that takes the gentleness weight runs at each of
    ``config.selection_weights`` (the mean over them), or, where none is given, at
    *gentleness* (the teacher's default weight; 0 if ``None``)."""
    from myoexo.control.rollout import rollout
    from myoexo.evaluation.metrics import episode_metrics

    controllers: list[Any] = [student]
    if student.gentleness_input:
        from myoexo.control.policy import GentleController

        weights = config.selection_weights or (float(gentleness or 0.0),)
        controllers = [GentleController(student, float(w)) for w in weights]
    out: dict[str, float] = {}
    for perturbed in (False, True):
        for level in config.levels:
            env = envs.get(level, perturbed)
            student.bind(env)
            errs = []
            for controller, i in itertools.product(controllers, range(config.selection_subjects)):
                ep = rollout(
                    env,
                    controller,
                    subject_seed(level, i, config.root_seed),
                    channels=(
                        "time_s",
                        "knee_angle_deg",
                        "target_angle_deg",
                        "interaction_torque_nm",
                        "exo_torque_nm",
                        "command",
                    ),
                )
                errs.append(episode_metrics(ep.signals).abs_final_error_deg)
            out[f"L{level}{'p' if perturbed else ''}"] = float(np.mean(errs))
    out["score"] = float(np.mean(list(out.values()))) if out else float("nan")
    return out


# ---------------------------------------------------------------------------- the run
def _round_stem(run_dir: Path, r: int) -> Path:
    return run_dir / f"student_round_{r:02d}"


def _saved_rounds(run_dir: Path, history: dict[str, Any]) -> list[dict[str, Any]]:
    """The history's rounds whose student file was written (a round cut before it is not)."""
    return [
        h
        for h in history["rounds"]
        if _round_stem(run_dir, h["round"]).with_suffix(".npz").is_file()
    ]


def distill(
    config: DistillConfig,
    run_dir: str | Path,
    resume: bool = False,
    rounds: int | None = None,
    log: Callable[[str], None] = print,
) -> dict[str, Any]:
    """Run (or continue) a distillation in ``run_dir``; returns the history document.

    ``resume``: continue after the last finished round with the saved settings (``rounds``
    may raise their number). A new run refuses a folder that already holds one. The folder
    is locked for the run (:class:`~myoexo.runtime.lifecycle.FolderLock`): a second writer
    stops with the holder's name.
    """
    run_dir = Path(run_dir)
    if resume and not (run_dir / CONFIG_FILE).is_file():
        raise ValueError(f"{run_dir} has no {CONFIG_FILE}: nothing to resume")
    run_dir.mkdir(parents=True, exist_ok=True)
    with FolderLock(run_dir, "distillation folder"):
        return _distill(config, run_dir, resume, rounds, log)


def _distill(
    config: DistillConfig,
    run_dir: Path,
    resume: bool,
    rounds: int | None,
    log: Callable[[str], None],
) -> dict[str, Any]:
    """:func:`distill` in its locked folder."""
    import torch

    torch.set_num_threads(1)
    cfg_path, data_path, hist_path = (
        run_dir / CONFIG_FILE,
        run_dir / DATASET_FILE,
        run_dir / HISTORY_FILE,
    )
    if resume:
        doc = json.loads(cfg_path.read_text())
        config = DistillConfig.from_json(doc["config"])
        if rounds is not None and rounds != config.rounds:
            config = dataclasses.replace(config, rounds=int(rounds))
            doc["config"] = config.to_json()
            write_json_atomic(cfg_path, doc, indent=2)
        history = json.loads(hist_path.read_text()) if hist_path.is_file() else {"rounds": []}
    else:
        if cfg_path.exists():
            raise ValueError(f"{run_dir} already holds a distillation run; use --resume")
        if rounds is not None:
            config = dataclasses.replace(config, rounds=int(rounds))
        write_json_atomic(
            cfg_path,
            {"config": config.to_json(), "versions": package_versions(), "kind": "distill"},
            indent=2,
        )
        history = {"rounds": []}
    done = _saved_rounds(run_dir, history)
    history["rounds"] = done
    start = len(done)
    data = Episodes.load(data_path) if start and data_path.is_file() else Episodes()
    if start and data.size and int(data.rounds.max()) >= start:  # a round cut after the data
        keep = data.rounds < start
        data = _subset(data, keep)
    student = load_student(_round_stem(run_dir, start - 1)) if start else None
    actor = load_teacher(config.teacher)
    provenance = teacher_provenance(actor)
    guard = StallGuardConfig() if config.teacher_guard else None
    envs = EnvPool(config.twin)
    controller = teacher_controller(config.teacher, actor, envs.get(config.levels[0], False))
    default_weight = getattr(controller, "gentleness", None)
    if config.gentleness_input and default_weight is None:
        raise ValueError(
            f"gentleness_input: the teacher {config.teacher!r} was not trained over the "
            "gentleness range (it takes no weight)"
        )
    teacher = Expert(actor, config.fine_gain, config.fine_width_rad, guard, controller)
    try:
        for r in range(start, config.rounds):
            t0 = time.time()
            log(f"[distill] round {r}: collecting (beta {config.beta(r) if student else 1.0:.3f})")
            new, stats = collect_round(config, r, teacher, student, envs)
            data = data.extend(new)
            data.save(data_path)
            t1 = time.time()
            epochs = config.epochs_first if student is None else config.epochs
            log(f"[distill] round {r}: {new.size} new samples, {data.size} in all; training")
            student, fit = train_student(config, data, epochs, student, config.seed + r, log)
            t2 = time.time()
            scores = (
                selection_scores(student, config, envs, default_weight)
                if config.selection_subjects
                else {}
            )
            entry = {
                "round": r,
                **stats,
                "dataset_size": data.size,
                "epochs": epochs,
                **fit,
                "selection": scores,
                "collect_s": round(t1 - t0, 1),
                "train_s": round(t2 - t1, 1),
                "select_s": round(time.time() - t2, 1),
            }
            student.metadata.update(
                _provenance(config, provenance, r, data.size, scores, default_weight)
            )
            save_student(student, _round_stem(run_dir, r))
            history["rounds"].append(entry)
            best = _best_round(history["rounds"])
            history["best_round"] = best
            write_json_atomic(hist_path, history, indent=1)
            _copy_student(_round_stem(run_dir, best), run_dir / BEST_STEM)
            log(
                f"[distill] round {r} done in {time.time() - t0:.0f} s: mse "
                f"{fit['train_mse']:.2e}, selection "
                f"{json.dumps({k: round(v, 2) for k, v in scores.items()})}; best round {best}"
            )
    finally:
        envs.close()
    return history


#: The settings :func:`reselect` may change: those of the selection alone.
RESELECT_FIELDS: tuple[str, ...] = ("selection_weights", "selection_subjects")


def reselect(
    run_dir: str | Path, log: Callable[[str], None] = print, **changes: Any
) -> dict[str, Any]:
    """Choose a finished run's student again under new selection settings, without
    retraining: every saved round is scored again (:func:`selection_scores`) with the run's
    settings changed by *changes* (only :data:`RESELECT_FIELDS`), and the best round becomes
    ``student.npz``. The run's ``config.json`` takes the new settings; ``history.json`` keeps
    each round's earlier scores (``selection_before``) and records the earlier settings and
    best round under ``reselected``. Returns the history document.

    Raises:
        ValueError: a change outside :data:`RESELECT_FIELDS`, a folder without a finished
            round, or settings that select nothing (``selection_subjects = 0``).
    """
    bad = sorted(set(changes) - set(RESELECT_FIELDS))
    if bad:
        raise ValueError(f"reselect changes {bad}: only {list(RESELECT_FIELDS)} may change")
    run_dir = Path(run_dir)
    cfg_path, hist_path = run_dir / CONFIG_FILE, run_dir / HISTORY_FILE
    if not (cfg_path.is_file() and hist_path.is_file()):
        raise ValueError(f"{run_dir} holds no distillation run ({CONFIG_FILE}, {HISTORY_FILE})")
    with FolderLock(run_dir, "distillation folder"):
        doc = json.loads(cfg_path.read_text())
        before = DistillConfig.from_json(doc["config"])
        config = dataclasses.replace(before, **changes)
        if not config.selection_subjects:
            raise ValueError("reselect with selection_subjects = 0: nothing to select on")
        history = json.loads(hist_path.read_text())
        rounds = _saved_rounds(run_dir, history)
        if not rounds:
            raise ValueError(f"{run_dir} has no finished round to select from")
        envs = EnvPool(config.twin)
        try:
            controller = teacher_controller(
                config.teacher, load_teacher(config.teacher), envs.get(config.levels[0], False)
            )
            default_weight = getattr(controller, "gentleness", None)
            for h in rounds:
                t0 = time.time()
                stem = _round_stem(run_dir, h["round"])
                student = load_student(stem)
                scores = selection_scores(student, config, envs, default_weight)
                h.setdefault("selection_before", h["selection"])
                h["selection"], h["select_s"] = scores, round(time.time() - t0, 1)
                student.metadata["selection_scores"] = scores
                student.metadata["distill_config"] = config.to_json()
                save_student(student, stem)
                log(
                    f"[reselect] round {h['round']}: "
                    f"{json.dumps({k: round(v, 2) for k, v in scores.items()})}"
                )
        finally:
            envs.close()
        history["rounds"] = rounds
        history["reselected"] = {
            "from": {k: getattr(before, k) for k in RESELECT_FIELDS},
            "best_round_before": history.get("best_round"),
            "versions": package_versions(),
        }
        history["best_round"] = _best_round(rounds)
        write_json_atomic(hist_path, history, indent=1)
        doc["config"] = config.to_json()
        write_json_atomic(cfg_path, doc, indent=2)
        _copy_student(_round_stem(run_dir, history["best_round"]), run_dir / BEST_STEM)
        log(
            f"[reselect] {run_dir}: best round {history['best_round']} "
            f"(before: {history['reselected']['best_round_before']})"
        )
    return history


def _subset(data: Episodes, keep: np.ndarray) -> Episodes:
    starts = [int(s) for s in data.starts if keep[s]]
    idx = np.flatnonzero(keep)
    remap = {int(old): new for new, old in enumerate(idx)}
    return Episodes(
        data.frames[idx],
        data.labels[idx],
        np.array([remap[s] for s in starts], np.int64),
        data.rounds[idx],
        data.weights[idx],
    )


def _best_round(rounds: Sequence[dict[str, Any]]) -> int:
    scored = [(h["selection"].get("score", math.inf), h["round"]) for h in rounds]
    if all(not math.isfinite(s) for s, _ in scored):
        return int(rounds[-1]["round"])
    return int(min(scored)[1])


def _copy_student(src: Path, dst: Path) -> None:
    save_student(load_student(src), dst)


#: Provenance of the teacher copied into a student's metadata (which ``sac`` labelled it).
TEACHER_KEYS: tuple[str, ...] = ("checkpoint", "training_seeds", "ship_seed", "num_timesteps")


def teacher_provenance(teacher: MLPActor) -> dict[str, Any]:
    """The teacher's own provenance (:data:`TEACHER_KEYS` present in its metadata)."""
    return {k: teacher.metadata[k] for k in TEACHER_KEYS if k in teacher.metadata}


def _provenance(
    config: DistillConfig,
    teacher: dict[str, Any],
    r: int,
    n: int,
    scores: dict[str, float],
    default_gentleness: float | None = None,
) -> dict[str, Any]:
    twin = config.twin.replace(obs_preset=StudentController.obs_preset)
    weighted: dict[str, Any] = {}
    if config.gentleness_input:  # it runs behind a GentleController, at its default weight
        twin = twin.replace(gentleness="random")
        weighted = {"default_gentleness": float(default_gentleness or 0.0)}
    return {
        **weighted,
        "trained_by": "myoexo policy distill (DAgger)",
        "teacher": config.teacher,
        "teacher_provenance": teacher,
        "fine_gain": config.fine_gain,
        "fine_width_rad": config.fine_width_rad,
        "teacher_guard": config.teacher_guard,
        "round": r,
        "dataset_size": int(n),
        "selection_root_seed": int(config.root_seed),
        "selection_scores": scores,
        "distill_config": config.to_json(),
        "env_id": f"MyoExoKnee-v{{level}} (levels {list(config.levels)})",
        "twin": twin.to_dict(),
        "twin_version": TWIN_VERSION,
    }


# ---------------------------------------------------------------------------- seeds
#: How the shipped student is chosen among distillation seeds.
SHIP_RULE = (
    "the seed whose selection errors (root 1, per level and twin) lie closest to the "
    "across-seed means (closest_seed)"
)


def seed_group_name(name: str, n_seeds: int) -> str:
    """The seed group of :func:`ship_students`'s seed copies: ``<name>_<n>seeds``."""
    return f"{name}_{int(n_seeds)}seeds"


def seed_copy_stem(folder: str | Path, name: str, n_seeds: int, seed: int, r: int) -> Path:
    """Where :func:`ship_students` writes one seed's student for an evaluation over seeds:
    ``<folder>/<group>-seed_<seed>-round_<r>`` (*group*: :func:`seed_group_name`, which the
    copy's metadata records as ``seed_group``, so that ``myoexo evaluate`` pools the copies
    into one controller: :attr:`~myoexo.control.specs.ControllerSpec.seed_group`)."""
    group = seed_group_name(name, n_seeds)
    return Path(folder) / f"{group}-seed_{int(seed)}-round_{int(r):02d}"


def ship_students(
    run_dirs: Sequence[str | Path],
    name: str | None = None,
    stem: str | Path | None = None,
    seed_copies: str | Path | None = None,
    log: Callable[[str], None] = print,
    gentleness_record: str | Path | None = None,
) -> StudentController:
    """Choose one of several distillation seeds' students by :data:`SHIP_RULE`.

    Each run's student is its selected round (``student.npz``); the rule compares the
    seeds' selection errors (root 1, never the evaluation root). The chosen student gets
    ``distill_seeds``, ``ship_seed`` and ``ship_rule`` in its metadata and is written into
    the package as *name* (:func:`myoexo.load_policy`) and/or to *stem*; *seed_copies*
    receives every seed's student under :func:`seed_copy_stem`, to evaluate them together.
    With *gentleness_record* (a ``myoexo policy gentleness`` record, its folder or its
    ``gentleness.json``), every student written takes that record's default weight as its
    own (:func:`~myoexo.training.export.record_default_gentleness`; without it a student
    runs at its teacher's default).

    Raises:
        ValueError: fewer than two runs, a run without a student, two runs of one seed, or
            a gentleness record for students without a gentleness input (or no record).
    """
    import pandas as pd

    from myoexo.policies import shipped_path
    from myoexo.training.export import record_default_gentleness
    from myoexo.training.seeds import closest_seed

    if len(run_dirs) < 2:
        raise ValueError(f"{len(run_dirs)} distillation run(s) given: the rule needs >= 2")
    students: dict[int, tuple[StudentController, int]] = {}
    rows = []
    for run_dir in map(Path, run_dirs):
        if not (run_dir / f"{BEST_STEM}.npz").is_file():
            raise ValueError(f"{run_dir} has no {BEST_STEM}.npz: not a finished distillation")
        student = load_student(run_dir / BEST_STEM)
        seed = int(student.metadata["distill_config"]["seed"])
        if seed in students:
            raise ValueError(f"two runs of distillation seed {seed}: {list(map(str, run_dirs))}")
        if gentleness_record is not None:
            record_default_gentleness(student, Path(gentleness_record), str(run_dir))
        students[seed] = (student, int(student.metadata["round"]))
        for key, value in student.metadata["selection_scores"].items():
            if key != "score":
                rows.append({"seed": seed, "level": key, "selection_error_deg": float(value)})
    ship = closest_seed(pd.DataFrame(rows), metrics=("selection_error_deg",))
    seeds = sorted(students)
    for seed in seeds:
        student, r = students[seed]
        score = student.metadata["selection_scores"]["score"]
        mark = "  <- shipped" if seed == ship else ""
        log(f"[distill] seed {seed}: round {r}, selection score {score:.2f} deg{mark}")
        if seed_copies is not None:
            group = seed_group_name(name or "student", len(seeds))
            copy = StudentController(
                student.actor,
                n_frames=student.n_frames,
                stride=student.stride,
                metadata={**student.metadata, "seed_group": group},
                gentleness_input=student.gentleness_input,
                fine=student.fine,
            )
            save_student(copy, seed_copy_stem(seed_copies, name or "student", len(seeds), seed, r))
    chosen = students[ship][0]
    chosen.metadata.update(distill_seeds=seeds, ship_seed=ship, ship_rule=SHIP_RULE)
    for target in ([Path(stem)] if stem else []) + ([shipped_path(name)] if name else []):
        npz, _ = save_student(chosen, target)
        log(f"[distill] student: {npz} (seed {ship} of {seeds})")
    return chosen


# ---------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class DistillRun:
    """The run of ``myoexo policy distill``: its folder (or the run it continues), the
    finished seeds it ships instead, where it writes the chosen student, how much it tells."""

    run_dir: Path | None = option(
        None, "output folder (default: runs/distill_<timestamp>)", folder=True
    )
    ship: tuple[str, ...] | None = option(
        None,
        "choose among finished runs of several seeds by the seed rule (closest_seed on "
        "the selection errors) instead of distilling; with --name, --export, --seed-copies",
        metavar="DIR",
    )
    name: str | None = option(
        None, "with --ship: write the chosen student into the package under NAME", metavar="NAME"
    )
    seed_copies: Path | None = option(
        None,
        "with --ship: every seed's student as DIR/<name>_<n>seeds-seed_<s>-round_<r>, "
        "for `myoexo evaluate --controllers DIR/*.npz` (one controller over seeds)",
        metavar="DIR",
        folder=True,
    )
    resume: str | None = option(
        None,
        "continue the run in DIR with its saved settings (--rounds: raise their number)",
        metavar="DIR",
    )
    reselect: str | None = option(
        None,
        "choose the finished run in DIR's student again, without retraining, at new selection "
        "settings (--selection-weights, --selection-subjects): every round is scored again",
        metavar="DIR",
    )
    gentleness_record: str | None = option(
        None,
        "with --ship: the default weight of every student written is that of this `myoexo "
        "policy gentleness` record (its folder or gentleness.json), not the teacher's",
        metavar="DIR",
    )
    export: str | None = option(None, "write the selected student to STEM", metavar="STEM")
    onnx: str | None = option(None, "write the selected student as ONNX", metavar="FILE")
    quiet: bool = option(False, "no per-epoch lines", short="q")

    def __post_init__(self) -> None:
        check_fields(self)
        if self.ship is not None and not self.ship:
            raise FieldError("DistillRun", "ship", self.ship, "names no run folder")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo policy distill``: one per :class:`DistillConfig` field, the twin's
    options, and the run's (:class:`DistillRun`)."""
    add_options(parser, DistillRun)
    add_options(parser.add_argument_group("distillation"), DistillConfig, given_only=True)
    add_twin_arguments(parser)


def _fixed_settings_given(args: argparse.Namespace, allowed: Sequence[str]) -> list[str]:
    """The options typed on the command line that set a run's fixed settings: every
    :class:`DistillConfig` field but *allowed*, and the twin's options."""
    given = [
        flag_of(f)
        for f in option_fields(DistillConfig)
        if hasattr(args, f.name) and f.name not in allowed
    ]
    if twin_from_args(args) != TwinOptions():
        given.append("the twin options")
    return given


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo policy distill``; 0 when every round is done."""
    from myoexo.policies.student import export_student_onnx

    options = from_options(DistillRun, args)

    def log(msg: str) -> None:
        if not (options.quiet and "epoch" in msg):
            print(msg, flush=True)

    if options.ship:
        chosen = ship_students(
            options.ship,
            options.name,
            options.export,
            options.seed_copies,
            log=log,
            gentleness_record=options.gentleness_record,
        )
        if options.onnx:
            print(f"onnx: {export_student_onnx(chosen, options.onnx)}")
        return 0
    if options.reselect:
        fixed = _fixed_settings_given(args, RESELECT_FIELDS)
        if fixed:
            raise ValueError(
                "--reselect keeps the run's settings but --selection-weights and "
                f"--selection-subjects; drop {', '.join(fixed)}"
            )
        changes = {name: getattr(args, name) for name in RESELECT_FIELDS if hasattr(args, name)}
        run_dir = Path(options.reselect)
        reselect(run_dir, log=log, **changes)
    elif options.resume:
        fixed = _fixed_settings_given(args, ("rounds",))
        if fixed:
            raise ValueError(
                f"--resume keeps the run's saved settings (--rounds raises their number); "
                f"drop {', '.join(fixed)}"
            )
        run_dir = Path(options.resume)
        distill(
            DistillConfig(), run_dir, resume=True, rounds=getattr(args, "rounds", None), log=log
        )
    else:
        config = from_options(DistillConfig, args, twin=twin_from_args(args))
        run_dir = Path(options.run_dir or f"runs/distill_{time.strftime('%Y%m%d-%H%M%S')}")
        distill(config, run_dir, resume=False, log=log)
    best = load_student(run_dir / BEST_STEM)
    if options.export:
        print(f"student: {save_student(best, options.export)[0]}")
    if options.onnx:
        print(f"onnx: {export_student_onnx(best, options.onnx)}")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="myoexo policy distill", description=__doc__.split("\n")[0]
    )
    add_arguments(parser)
    return run(parser.parse_args(argv))


if __name__ == "__main__":
    raise SystemExit(main())
