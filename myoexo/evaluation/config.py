"""What an evaluation runs, how its subjects are seeded, and its ``config.json``.

Pairing. Subject ``i`` of level ``l`` is the same simulated person for every controller:
its episode seed is :func:`subject_seed` ``(l, i, root_seed)``, the first 64-bit word of
``numpy.random.SeedSequence(root_seed, spawn_key=(l, i))``. The env draws the subject's
spasticity parameters and start-angle perturbation from that seed at ``reset`` and the
controller gets it in ``reset(seed)``; so an episode depends on (controller, level, i,
root seed) only, whatever the worker that runs it, and results are identical for any number
of workers.

A folder is tied to its run by ``config.json``: its ``run_key`` (the settings that change an
episode's content, including a fingerprint of the simulated twin) must match on resume.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import importlib
import json
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

import numpy as np

from myoexo.control.specs import ControllerSpec, policy_twin, spec_env_kwargs
from myoexo.envs.options import TwinOptions
from myoexo.runtime.fields import check_fields, option
from myoexo.runtime.files import file_sha256, package_versions, write_json_atomic
from myoexo.spasticity.levels import VALID_LEVELS

CONFIG_FILE = "config.json"

#: Root seed of the reported evaluations (``myoexo evaluate``'s default, the README's tables).
EVALUATION_ROOT_SEED = 0
#: Root seed of the subjects that *select* policies (training's periodic evaluation,
#: ``myoexo policy select``, the seed that is shipped, distillation). It differs from
#: :data:`EVALUATION_ROOT_SEED`, so no subject of a reported evaluation chose the checkpoint
#: being reported; :func:`check_no_selection_leak` enforces it for policies that record their
#: selection seed.
SELECTION_ROOT_SEED = 1
#: Root seed of the subjects the twin is *fitted* on (``myoexo twin calibrate``).
CALIBRATION_ROOT_SEED = 2
#: Root seed of the simulated people ``myoexo twin recovery`` records and fits (a personal
#: twin's own test): nothing else draws from it.
RECOVERY_ROOT_SEED = 5
#: Root seed of the subjects the device-side fits measure (``myoexo twin strap-lag``,
#: ``myoexo twin hold-slope``; the encoder guard's threshold was chosen there too): none of
#: the evaluation's, the selection's or the calibration's.
DEVICE_FIT_ROOT_SEED = 3

#: The three subject streams, by purpose: each root seeds its own
#: ``SeedSequence(root, spawn_key=(level, subject))`` stream, so the subjects of one purpose
#: are never those of another.
SUBJECT_ROOTS: Mapping[str, int] = MappingProxyType(
    {
        "evaluation": EVALUATION_ROOT_SEED,
        "selection": SELECTION_ROOT_SEED,
        "calibration": CALIBRATION_ROOT_SEED,
        "recovery": RECOVERY_ROOT_SEED,
    }
)


def device_fit_root_option() -> Any:
    """The ``root_seed`` field (option ``--seed``) of a device-side fit: default
    :data:`DEVICE_FIT_ROOT_SEED`; the fit's ``__post_init__`` refuses the evaluation root with
    :func:`check_fit_root`."""
    return option(
        DEVICE_FIT_ROOT_SEED,
        f"root seed of the subjects (their own root: the evaluation root {EVALUATION_ROOT_SEED} "
        "is refused)",
        low=0,
        flag="seed",
    )


def check_fit_root(root_seed: int, purpose: str) -> int:
    """Refuse to fit or choose anything on the evaluation subjects.

    Args:
        root_seed: The root seed of the subjects *purpose* would use.
        purpose: What is fitted or chosen there (``"calibration"``, ``"checkpoint selection"``,
            ...), for the message.

    Returns:
        *root_seed*, as an ``int``.

    Raises:
        ValueError: *root_seed* is :data:`EVALUATION_ROOT_SEED` (the message names the roots).
    """
    if int(root_seed) == EVALUATION_ROOT_SEED:
        raise ValueError(
            f"{purpose} on root seed {root_seed}: that is the evaluation root, whose subjects "
            "report results and must not fit or choose what they report; use the selection "
            f"root {SELECTION_ROOT_SEED} or the calibration root {CALIBRATION_ROOT_SEED}"
        )
    return int(root_seed)


#: How a subject's seed is derived (recorded in ``config.json``).
SEED_RULE = (
    "numpy.random.SeedSequence(root_seed, spawn_key=(level, subject)).generate_state(1, uint64)[0]"
)


@dataclass(frozen=True)
class EvaluationConfig:
    """What an evaluation runs (the worker count is not part of it: it changes no result).

    Attributes:
        controllers: Controller specs (:mod:`myoexo.control.specs`): ``pid``, ``sac``, a
            model path ...
        levels: Spasticity levels, each in :data:`~myoexo.spasticity.VALID_LEVELS`.
        subjects: Subjects per level (paper: 1000); with a personal twin
            (``twin.subject``), draws of that person from the fit's uncertainty, at the
            fit's level (the default levels become that one).
        root_seed: Root of every subject seed (:func:`subject_seed`).
        trace_stride: Keep every n-th control step in the stored traces.
        chunk_size: Subjects per unit of work (and per resume file).
        env_id: Gymnasium id of the env of a level, formatted with ``level``; any env
            registered with the MyoExoKnee API (e.g. a variant with other ``TaskParams`` or
            wrappers, ``"module:EnvId-v{level}"`` imports its module first).
        twin: The twin every controller runs on (:class:`~myoexo.envs.options.TwinOptions`:
            task, e.g. ``episode_duration_s``; reflex model; ``robustness``, a perturbed twin
            per episode drawn from its subject seed, the same for every controller; the
            reward weights and observation are each policy's own, from its files).
        selection: A selection run (e.g. the frontier's picking), not a result: it must run
            on a root other than the evaluation root (:func:`check_fit_root`) and may run
            policies on the root that selected them; its numbers are in-sample.
    """

    controllers: tuple[str, ...] = option(
        ("pid",),
        "controllers: 'pid[:kp=..,ki=..,kd=..,feedback=exo,anti_windup=..,ramp_s=..,"
        "reference=..,limit=..,tuned=..]' (ramp_s: a ramped setpoint, reference=minjerk: "
        "ramped along a minimum-jerk move; limit: a clipped command; tuned=exo: gains "
        "tuned on the exo encoder, tuned=latency: tuned for the perturbed twins' 10 ms "
        "latency), 'impedance[:k=..,d=..,duration_s=..,feedback=exo,limit=..]' (a "
        "spring-damper on a minimum-jerk reference; default k=700 Nm/rad, d=5 Nm s/rad, "
        "duration_s=1), 'sac' / 'student_exo' (the shipped policies; skipped with a message if "
        "absent), 'oracle[:samples=..,horizon_s=..]' (MPC on a copy of the twin: the "
        "achievable bound, about 65 s of a core per episode: 2 subjects x 4 levels take "
        "~4.5 min on 2 cores) or paths of SB3 .zip models",
        metavar="SPEC",
    )
    levels: tuple[int, ...] = option(
        VALID_LEVELS, "spasticity levels", choices=VALID_LEVELS, metavar="L"
    )
    subjects: int = option(1000, "subjects per level", low=1)
    root_seed: int = option(EVALUATION_ROOT_SEED, "root seed of the subjects", low=0, flag="seed")
    trace_stride: int = option(
        2, "store every n-th control step of the traces (2: 50 Hz)", low=1, metavar="N"
    )
    chunk_size: int = option(10, "subjects per resumable chunk", low=1, metavar="N")
    env_id: str = option(
        "MyoExoKnee-v{level}", "gymnasium id of a level's env, with '{level}'", metavar="ID"
    )
    twin: TwinOptions = field(default_factory=TwinOptions)
    selection: bool = False

    def __post_init__(self) -> None:
        if not isinstance(self.twin, TwinOptions):
            raise ValueError(f"twin = {self.twin!r}: expected TwinOptions")
        if self.selection:
            check_fit_root(self.root_seed, "a selection run")
        object.__setattr__(self, "controllers", tuple(self.controllers))
        object.__setattr__(self, "levels", tuple(int(v) for v in self.levels))
        personal = self.twin.personal
        if personal is not None and self.levels != (personal.level,):
            if self.levels != VALID_LEVELS:
                raise ValueError(
                    f"levels {self.levels}: the personal subject {self.twin.subject} is a "
                    f"level-{personal.level} twin; run level {personal.level} alone"
                )
            object.__setattr__(self, "levels", (personal.level,))
        if not self.controllers:
            raise ValueError("controllers is empty: name at least one (e.g. 'pid')")
        check_fields(self)
        if not self.levels:
            raise ValueError(f"levels is empty; accepted: {VALID_LEVELS}")
        if len(set(self.levels)) != len(self.levels):
            raise ValueError(f"levels {self.levels} has duplicates")
        if "{level}" not in self.env_id:
            raise ValueError(f"env_id = {self.env_id!r} must contain '{{level}}'")
        for level in self.levels:
            check_env_id(self.level_env_id(level))

    @property
    def episode_duration_s(self) -> float | None:
        """The twin's episode length if overridden (``None``: the env's 8 s)."""
        return self.twin.episode_duration_s

    @property
    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of every env of the run: the twin's task, reflex model and
        robustness (a controller's own observation on top; the reward is not scored)."""
        return self.twin.dynamics().env_kwargs()

    def level_env_id(self, level: int) -> str:
        """The env id of one level."""
        return self.env_id.format(level=level)

    @property
    def trace_samples(self) -> int:
        """Samples per stored trace (reset + every ``trace_stride``-th step)."""
        return self.twin.task_params.episode_steps // self.trace_stride + 1

    def run_key(self) -> dict[str, Any]:
        """Settings that change the content of an episode's file (checked on resume),
        including a fingerprint of the simulated twin, so that a folder filled by an older
        model is never silently extended."""
        return {
            "root_seed": int(self.root_seed),
            "trace_stride": int(self.trace_stride),
            "env_id": self.env_id,
            "env_fingerprint": env_fingerprint(self.level_env_id(self.levels[0])),
            "twin": self.twin.dynamics().to_dict(),
        }


def check_env_id(env_id: str) -> None:
    """Raise ``ValueError`` unless ``env_id`` names a registered env (``"module:EnvId-v0"``
    imports its module first, as ``gymnasium.make`` does)."""
    import gymnasium as gym

    module, _, name = env_id.rpartition(":")
    try:
        if module:
            importlib.import_module(module)
        gym.spec(name)
    except (ImportError, gym.error.Error) as exc:
        raise ValueError(f"env id {env_id!r} is not registered: {exc}") from None


@functools.lru_cache(maxsize=8)
def env_fingerprint(env_id: str) -> str:
    """SHA-256 (16 hex digits) of what defines an env's episodes: the compiled MuJoCo model
    (MJB bytes: geometry, masses, muscles, couplings, timestep), the task and reward
    parameters, the observation layout and the reflex model."""
    import mujoco

    from myoexo.envs import make_env

    env: Any = make_env(env_id).unwrapped  # a MyoExoKneeEnv
    try:
        model = env.model
        mjb = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
        mujoco.mj_saveModel(model, None, mjb)
        h = hashlib.sha256(mjb.tobytes())
        stage = getattr(env, "spasticity", None)
        for part in ("task", "reward_params", "obs_keys"):
            h.update(repr(getattr(env, part, None)).encode())
        h.update(repr(getattr(stage, "reflex", None)).encode())
    finally:
        env.close()
    return h.hexdigest()[:16]


def subject_seed(level: int, index: int, root_seed: int = 0) -> int:
    """Seed of subject ``index`` of ``level``: same person for every controller.

    ``numpy.random.SeedSequence(root_seed, spawn_key=(level, index))``'s first 64-bit word:
    independent streams per (level, index), stable across numpy versions (NEP 19).
    """
    if level < 0 or index < 0 or root_seed < 0:
        raise ValueError(
            f"level, index and root_seed must be >= 0, got {level}, {index}, {root_seed}"
        )
    ss = np.random.SeedSequence(int(root_seed), spawn_key=(int(level), int(index)))
    return int(ss.generate_state(1, dtype=np.uint64)[0])


def write_config(
    out_dir: Path, config: EvaluationConfig, specs: Sequence[ControllerSpec]
) -> dict[str, Any]:
    """Create or update ``config.json`` atomically; refuse a folder holding a different run."""
    path = out_dir / CONFIG_FILE
    previous: dict[str, Any] = {}
    if path.is_file():
        previous = json.loads(path.read_text())
        if previous.get("run_key") != config.run_key():
            raise ValueError(
                f"{out_dir} holds a run with other settings {previous.get('run_key')} than "
                f"this one {config.run_key()}; choose another --out folder"
            )
    controllers = dict(previous.get("controllers", {}))
    for spec in specs:
        entry: dict[str, Any] = {"spec": spec.text, "label": spec.label, "kind": spec.kind}
        if spec.kind in ("sb3", "actor") and spec.path:
            entry["sha256"] = file_sha256(spec.path)
        elif spec.kind == "shipped":  # a re-exported policy is another controller
            from myoexo.policies import shipped_path

            entry["sha256"] = file_sha256(str(shipped_path(spec.path or "sac")) + ".npz")
        # the twin this controller runs on (the run's, with the controller's observation)
        # and, for a policy, the one it was trained on
        observation = spec_env_kwargs(spec)
        entry["twin"] = config.twin.replace(
            obs_preset=observation.get("obs_preset", "full"),
            obs_keys=tuple(observation.get("obs_keys", ())),
        ).to_dict()
        trained = policy_twin(spec)
        if trained is not None:
            entry["trained_on"] = trained.to_dict()
        old = controllers.get(spec.slug)
        if old is not None and old != entry:
            raise ValueError(
                f"{out_dir} holds results of another controller under the label "
                f"{spec.slug!r} ({old}); choose another --out folder"
            )
        controllers[spec.slug] = entry
    from myoexo.model import TWIN_VERSION

    doc = {
        "twin_version": TWIN_VERSION,
        "run_key": config.run_key(),
        "config": {**dataclasses.asdict(config), "twin": config.twin.to_dict()},
        "controllers": controllers,
        "versions": package_versions(),
        "seed_rule": SEED_RULE,
    }
    write_json_atomic(path, doc, indent=2)
    return doc


def load_config(out_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``config.json`` of an evaluation folder."""
    path = Path(out_dir) / CONFIG_FILE
    if not path.is_file():
        raise ValueError(f"{str(out_dir)!r} has no {CONFIG_FILE}: not an evaluation folder")
    return json.loads(path.read_text())
