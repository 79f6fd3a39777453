"""The evaluation engine: episodes with metrics, and chunks of subjects.

Work is cut into *chunks* (one controller, one level, ``chunk_size`` consecutive subjects),
each run by :func:`run_chunk` (in a worker keeping one env per level and one controller per
spec: :mod:`.backends`) and stored as it finishes (:mod:`.storage`). Running the same
command again only computes the missing chunks; an episode depends only on (controller,
level, subject, root seed) (:mod:`.config`), so the table is the same whatever the number of
workers. :func:`~myoexo.evaluation.runner.evaluate` runs a whole protocol.
"""

from __future__ import annotations

import os
import sys
import warnings
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.protocol import Controller
from myoexo.control.rollout import rollout
from myoexo.control.specs import (
    ControllerSpec,
    PolicyUnavailableError,
    build_controller,
    check_no_selection_leak,
    controller_env_kwargs,
    load_actor_file,
    load_shipped_policy,
    parse_controller_spec,
    policy_metadata,
    spec_env_kwargs,
    trained_on_nominal_too,
    twin_of_metadata,
)
from myoexo.envs.options import TwinOptions, twin_mismatch
from myoexo.evaluation.config import EvaluationConfig, subject_seed
from myoexo.evaluation.metrics import EpisodeMetrics, episode_metrics
from myoexo.evaluation.storage import (
    TRACE_CHANNELS,
    chunk_path,
    save_chunk,
)
from myoexo.policies.algorithms import load_sb3_model
from myoexo.runtime.lifecycle import die_with_parent, ignore_signals
from myoexo.spasticity.registry import reflex_parameter_changes

#: Signals recorded at full rate for the metrics (traces keep a subset, downsampled).
RECORDED_CHANNELS: tuple[str, ...] = (*TRACE_CHANNELS, "time_s", "target_angle_deg")


# ----------------------------------------------------------------------------- episodes
@dataclass
class EpisodeResult:
    """One episode: its metrics, subject, and full-rate signals.

    Attributes:
        seed: Episode seed.
        level: Spasticity level.
        subject: The subject's spasticity parameters (``info["subject"]``).
        metrics: :class:`~myoexo.evaluation.metrics.EpisodeMetrics`.
        signals: ``info`` key -> array over the samples (reset + every step), float64.
        unstable: The physics diverged and the env truncated the episode.
        n_steps: Control steps run.
    """

    seed: int
    level: int
    subject: dict[str, float]
    metrics: EpisodeMetrics
    signals: dict[str, np.ndarray]
    unstable: bool
    n_steps: int


def run_episode(env: Any, controller: Controller, seed: int) -> EpisodeResult:
    """One episode (:func:`~myoexo.control.rollout.rollout`) and its metrics."""
    ep = rollout(env, controller, seed, channels=RECORDED_CHANNELS)
    return EpisodeResult(
        seed=ep.seed,
        level=ep.level,
        subject=ep.subject,
        metrics=episode_metrics(ep.signals),
        signals=ep.signals,
        unstable=ep.unstable,
        n_steps=ep.n_steps,
    )


def episode_row(result: EpisodeResult, controller: str, subject_index: int) -> dict[str, Any]:
    """The table row of an episode: ``controller, level, subject, seed, unstable, n_steps``,
    the subject's parameters as ``subject_<name>``, then the metrics."""
    row: dict[str, Any] = {
        "controller": controller,
        "level": result.level,
        "subject": int(subject_index),
        "seed": int(result.seed),
        "unstable": bool(result.unstable),
        "n_steps": int(result.n_steps),
    }
    row.update({f"subject_{k}": v for k, v in result.subject.items()})
    row.update(result.metrics.as_dict())
    return row


def downsample_trace(result: EpisodeResult, stride: int, n_samples: int) -> np.ndarray:
    """Traces of one episode as float32 ``(n_samples, len(TRACE_CHANNELS))``: every
    ``stride``-th sample, NaN-padded if the episode ended early."""
    out = np.full((n_samples, len(TRACE_CHANNELS)), np.nan, dtype=np.float32)
    for j, key in enumerate(TRACE_CHANNELS):
        x = result.signals[key][::stride][:n_samples]
        out[: x.size, j] = x
    return out


def evaluate_controller(
    controller: Controller,
    level: int,
    subjects: int | Sequence[int],
    root_seed: int = 0,
    episode_duration_s: float | None = None,
    label: str = "controller",
    env_kwargs: Mapping[str, Any] | None = None,
) -> tuple[Any, list[EpisodeResult]]:
    """In-process evaluation of a controller *object* (notebooks, tuning, selection).

    Args:
        controller: Any :class:`~myoexo.control.protocol.Controller`.
        level: Spasticity level.
        subjects: Number of subjects (indices ``0..n-1``) or explicit subject indices; the
            same indices give the same persons as :func:`evaluate`.
        root_seed: Root seed of :func:`~.config.subject_seed`.
        episode_duration_s: Episode length (``None``: the env's default).
        label: Value of the ``controller`` column.
        env_kwargs: More :func:`~myoexo.envs.make_env` arguments (e.g. the ``obs_preset``
            of a policy; default: the policy's own ``obs_preset`` attribute, if any).

    Returns:
        ``(table, results)``: a pandas DataFrame (one row per episode) and the
        :class:`EpisodeResult` list with the full-rate signals.
    """
    import pandas as pd

    from myoexo.envs import make_env

    indices = list(range(subjects)) if isinstance(subjects, (int, np.integer)) else list(subjects)
    kwargs = {**controller_env_kwargs(controller), **dict(env_kwargs or {})}
    if episode_duration_s is not None:
        kwargs["episode_duration_s"] = episode_duration_s
    env = make_env(level, **kwargs)
    try:
        results = [run_episode(env, controller, subject_seed(level, i, root_seed)) for i in indices]
    finally:
        env.close()
    rows = [episode_row(r, label, i) for r, i in zip(results, indices, strict=True)]
    return pd.DataFrame(rows), results


# ----------------------------------------------------------------------------- chunks
@dataclass(frozen=True)
class Chunk:
    """Unit of work: subjects ``start..stop-1`` of one level under one controller."""

    spec: ControllerSpec
    level: int
    start: int
    stop: int

    def path(self, out_dir: Path) -> Path:
        """Where the finished chunk is stored."""
        return chunk_path(out_dir, self.spec.label, self.level, self.start, self.stop)


def plan_chunks(specs: Sequence[ControllerSpec], config: EvaluationConfig) -> list[Chunk]:
    """All chunks of a run, ordered level, subjects, controller (a partial run stays
    paired across controllers)."""
    chunks: list[Chunk] = []
    for level in config.levels:
        for start in range(0, config.subjects, config.chunk_size):
            stop = min(start + config.chunk_size, config.subjects)
            chunks.extend(Chunk(spec, level, start, stop) for spec in specs)
    return chunks


#: Per-process caches of the workers: one env per env id, duration and env keyword arguments
#: (a policy's observation preset), one controller per spec, the env keyword arguments of
#: each spec.
_ENVS: dict[tuple[str, str, str], Any] = {}
_CONTROLLERS: dict[str, Controller] = {}
_SPEC_ENV_KWARGS: dict[str, dict[str, Any]] = {}


def init_worker(parent_pid: int | None = None) -> None:
    """Worker start-up: one thread per process (the pool provides the parallelism), SIGINT
    left to the driver (it stops the pool itself), and an end with the driver
    (:func:`myoexo.runtime.lifecycle.die_with_parent`)."""
    ignore_signals()
    if parent_pid is not None:
        die_with_parent(parent_pid)
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def close_worker_state() -> None:
    for env in _ENVS.values():
        env.close()
    _ENVS.clear()
    _CONTROLLERS.clear()
    _SPEC_ENV_KWARGS.clear()


def run_chunk(chunk: Chunk, config: EvaluationConfig, out_dir: str) -> tuple[Chunk, int]:
    """Run one chunk and store it atomically; returns ``(chunk, episodes run)``."""
    from myoexo.envs import make_env

    spec_kwargs = _SPEC_ENV_KWARGS.get(chunk.spec.text)
    if spec_kwargs is None:  # reads the policy's files: once per worker, not per chunk
        spec_kwargs = _SPEC_ENV_KWARGS[chunk.spec.text] = spec_env_kwargs(chunk.spec)
    env_kwargs = {**config.env_kwargs, **spec_kwargs}
    # the oracle plans on a copy of its env: it gets an env of its own, per level
    owner = chunk.spec.text if chunk.spec.kind == "oracle" else ""
    env_id = config.level_env_id(chunk.level)
    key = (env_id, repr(sorted(env_kwargs.items())), owner)
    env = _ENVS.get(key)
    if env is None:
        env = _ENVS[key] = make_env(env_id, **env_kwargs)
    controller_key = f"{chunk.spec.text}@{env_id}" if owner else chunk.spec.text
    controller = _CONTROLLERS.get(controller_key)
    if controller is None:
        controller = _CONTROLLERS[controller_key] = build_controller(chunk.spec, env)
    n_samples = config.trace_samples
    rows, traces = [], []
    for i in range(chunk.start, chunk.stop):
        result = run_episode(env, controller, subject_seed(chunk.level, i, config.root_seed))
        row = episode_row(result, chunk.spec.label, i)
        row["controller_spec"] = chunk.spec.text
        rows.append(row)
        traces.append(downsample_trace(result, config.trace_stride, n_samples))
    base: Any = env.unwrapped  # a MyoExoKneeEnv
    dt = float(base.dt)
    time_s = (np.arange(n_samples) * config.trace_stride * dt).astype(np.float32)
    save_chunk(chunk.path(Path(out_dir)), rows, np.stack(traces), time_s)
    return chunk, len(rows)


# ----------------------------------------------------------------------------- controllers
class TwinMismatchWarning(UserWarning):
    """A policy is evaluated on another twin than the one it was trained on."""


def _parameter_mismatch(meta: Mapping[str, Any], twin: TwinOptions) -> str | None:
    """A warning if the policy's twin (in its metadata *meta*) recorded its reflex model's
    parameters and they differ from that model's now (e.g. a re-fitted calibration), else
    ``None``."""
    recorded = (meta.get("twin") or {}).get("reflex_parameters")
    if not recorded:
        return None
    changes = reflex_parameter_changes(recorded, twin.reflex)
    if not changes:
        return None
    return (
        f"trained on the reflex model {twin.reflex!r} with other parameters than it has now "
        f"({'; '.join(changes)})"
    )


def _version_mismatch(meta: Mapping[str, Any]) -> str | None:
    """A warning if the policy of metadata *meta* was trained on another twin version than
    today's (:data:`~myoexo.model.TWIN_VERSION`; a policy that records none was trained on
    version 1), else ``None``."""
    from myoexo.model import TWIN_VERSION, recorded_twin_version

    version = recorded_twin_version(meta)
    if version == TWIN_VERSION:
        return None
    return (
        f"trained on twin version {version}, evaluated on version {TWIN_VERSION} "
        "(CHANGELOG.md says what changed)"
    )


def resolve_controllers(
    specs_text: Iterable[str],
    log: Callable[[str], None] = print,
    root_seed: int | None = None,
    twin: TwinOptions | None = None,
) -> tuple[list[ControllerSpec], dict[str, str]]:
    """Parse and check every controller before anything is written.

    A model file that cannot be loaded raises ``ValueError``; ``sac`` without a shipped
    policy is skipped with a message (and reported in the second return value). With
    ``root_seed``, a policy selected on that root's subjects raises ``ValueError``
    (:func:`~myoexo.control.specs.check_no_selection_leak`). With ``twin``, a policy trained
    on another twin (task, reflex model or robustness) is evaluated with a
    :class:`TwinMismatchWarning` that names both twins (also logged).
    """
    specs: list[ControllerSpec] = []
    skipped: dict[str, str] = {}
    labels: dict[str, str] = {}
    for text in specs_text:
        spec = parse_controller_spec(text)
        if spec.kind == "sb3":
            load_sb3_model(str(spec.path), str(spec.algorithm))  # ValueError if unreadable
        elif spec.kind == "actor":
            load_actor_file(str(spec.path))  # ValueError if unreadable or inconsistent
        elif spec.kind == "shipped":
            try:
                load_shipped_policy(spec.path or "sac")
            except PolicyUnavailableError as exc:
                skipped[text] = str(exc)
                log(f"myoexo evaluate: skipping controller {text!r}: {exc}")
                continue
        if root_seed is not None:
            check_no_selection_leak(spec, root_seed)
        meta = policy_metadata(spec) if twin is not None else {}  # the policy's files, read once
        trained = twin_of_metadata(meta)
        mismatch = None
        if trained is not None and twin is not None:
            both = trained_on_nominal_too(meta)
            options = twin_mismatch(trained, twin, nominal_too=both)  # reflex, task, robustness
            found = (
                options,
                _version_mismatch(meta),
                None if options else _parameter_mismatch(meta, twin),
            )
            mismatch = "; and ".join(m for m in found if m) or None
        if mismatch:
            message = f"controller {text!r} was {mismatch}"
            log(f"myoexo evaluate: warning: {message}")
            warnings.warn(message, TwinMismatchWarning, stacklevel=2)
        if spec.slug in labels:
            raise ValueError(
                f"controllers {labels[spec.slug]!r} and {text!r} have the same label "
                f"{spec.slug!r}; rename one model file"
            )
        labels[spec.slug] = text
        specs.append(spec)
    if not specs:
        raise ValueError(f"no controller left to evaluate (skipped: {skipped})")
    return specs, skipped
