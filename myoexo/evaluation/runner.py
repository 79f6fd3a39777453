"""The paper's evaluation protocol: N simulated subjects per level x controllers (SPEC 5).

Pairing. Subject ``i`` of level ``l`` is the same simulated person for every controller:
its episode seed is :func:`subject_seed` ``(l, i, root_seed)``, the first 64-bit word of
``numpy.random.SeedSequence(root_seed, spawn_key=(l, i))``. The env draws the subject's
spasticity parameters and start-angle perturbation from that seed at ``reset`` and the
controller gets it in ``reset(seed)``; so an episode depends on (controller, level, i,
root seed) only, whatever the worker that runs it, and results are identical for any number
of workers.

Work is cut into *chunks* (one controller, one level, ``chunk_size`` consecutive subjects),
run in worker processes (``spawn``; each keeps one env per level and one controller per
spec). A finished chunk is written atomically as one ``.npz`` file holding its table rows
and its per-step traces, so an interrupted run loses at most the chunks in flight, and
running the same command again only computes the missing chunks.

Output folder::

    config.json                      the run-defining settings, controllers, versions
    episodes.parquet, episodes.csv   one row per episode (see :func:`episode_row`)
    traces/<controller>/L<level>/<first>-<stop>.npz   finished chunks (rows + traces)

Traces are float32, every ``trace_stride``-th control step (default 2: 50 Hz), channels
:data:`TRACE_CHANNELS`, stored compressed: a few KB per episode, some tens of MB for the full
protocol (1000 subjects x 4 levels x 2 controllers), and never all in memory at once.
:func:`load_traces` gathers them per (controller, level).
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import math
import os
import sys
import tempfile
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.protocol import Controller
from myoexo.control.specs import (
    ControllerSpec,
    PolicyUnavailableError,
    build_controller,
    load_sb3_model,
    load_shipped_policy,
    parse_controller_spec,
)
from myoexo.evaluation.metrics import EpisodeMetrics, episode_metrics

#: Spasticity levels the envs implement (level 4 is excluded by the paper as unsafe).
VALID_LEVELS: tuple[int, ...] = (0, 1, 2, 3)

#: Per-step signals kept for the figures (keys of the env's ``info``).
TRACE_CHANNELS: tuple[str, ...] = (
    "knee_angle_deg",
    "exo_angle_deg",
    "error_deg",
    "command",
    "exo_torque_nm",
    "muscle_knee_torque_nm",
    "interaction_torque_nm",
    "sc_total",
)
#: Signals recorded at full rate for the metrics (traces keep a subset, downsampled).
_RECORDED = (*TRACE_CHANNELS, "time_s", "target_angle_deg")

CONFIG_FILE = "config.json"
TABLE_STEM = "episodes"
TRACES_DIR = "traces"


@dataclass(frozen=True)
class EvaluationConfig:
    """What an evaluation runs (the worker count is not part of it: it changes no result).

    Attributes:
        controllers: Controller specs (:mod:`myoexo.control.specs`): ``pid``, ``sac``, a
            model path ...
        levels: Spasticity levels, each in :data:`VALID_LEVELS`.
        subjects: Subjects per level (paper: 1000).
        root_seed: Root of every subject seed (:func:`subject_seed`).
        episode_duration_s: Simulated time per episode; ``None`` = the env's default (8 s).
        trace_stride: Keep every n-th control step in the stored traces.
        chunk_size: Subjects per unit of work (and per resume file).
        env_id: Gymnasium id of the env of a level, formatted with ``level``; any env
            registered with the MyoExoKnee API (e.g. a variant with other ``TaskParams`` or
            wrappers, ``"module:EnvId-v{level}"`` imports its module first).
    """

    controllers: tuple[str, ...] = ("pid",)
    levels: tuple[int, ...] = VALID_LEVELS
    subjects: int = 1000
    root_seed: int = 0
    episode_duration_s: float | None = None
    trace_stride: int = 2
    chunk_size: int = 10
    env_id: str = "MyoExoKnee-v{level}"

    def __post_init__(self) -> None:
        object.__setattr__(self, "controllers", tuple(self.controllers))
        object.__setattr__(self, "levels", tuple(int(v) for v in self.levels))
        if not self.controllers:
            raise ValueError("controllers is empty: name at least one (e.g. 'pid')")
        bad = [v for v in self.levels if v not in VALID_LEVELS]
        if bad or not self.levels:
            raise ValueError(
                f"unknown spasticity level(s) {bad or '(none given)'}; accepted: {VALID_LEVELS}"
            )
        if len(set(self.levels)) != len(self.levels):
            raise ValueError(f"levels {self.levels} has duplicates")
        for name in ("subjects", "trace_stride", "chunk_size"):
            value = getattr(self, name)
            if not isinstance(value, (int, np.integer)) or value <= 0:
                raise ValueError(f"{name} = {value!r} must be a positive integer")
        if not isinstance(self.root_seed, (int, np.integer)) or self.root_seed < 0:
            raise ValueError(f"root_seed = {self.root_seed!r} must be an integer >= 0")
        if "{level}" not in self.env_id:
            raise ValueError(f"env_id = {self.env_id!r} must contain '{{level}}'")
        d = self.episode_duration_s
        if d is not None and not (math.isfinite(d) and 0.0 < d <= 3600.0):
            raise ValueError(f"episode_duration_s = {d!r} must be in (0, 3600] s or None")

    def run_key(self) -> dict[str, Any]:
        """Settings that change the content of an episode's file (checked on resume),
        including a fingerprint of the simulated twin, so that a folder filled by an older
        model is never silently extended."""
        return {
            "root_seed": int(self.root_seed),
            "episode_duration_s": self.episode_duration_s,
            "trace_stride": int(self.trace_stride),
            "env_id": self.env_id,
            "env_fingerprint": env_fingerprint(self.env_id.format(level=self.levels[0])),
        }


@functools.lru_cache(maxsize=8)
def env_fingerprint(env_id: str) -> str:
    """SHA-256 (16 hex digits) of what defines an env's episodes: the compiled MuJoCo model
    (MJB bytes: geometry, masses, muscles, couplings, timestep), the task and reward
    parameters and the observation layout."""
    import gymnasium as gym
    import mujoco

    env = gym.make(env_id).unwrapped
    try:
        model = env.model
        mjb = np.zeros(mujoco.mj_sizeModel(model), dtype=np.uint8)
        mujoco.mj_saveModel(model, None, mjb)
        h = hashlib.sha256(mjb.tobytes())
        for part in ("task", "reward_params", "obs_keys"):
            h.update(repr(getattr(env, part, None)).encode())
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


def make_eval_env(
    level: int,
    episode_duration_s: float | None = None,
    env_id: str = EvaluationConfig.env_id,
) -> Any:
    """``gymnasium.make("MyoExoKnee-v<level>")``, optionally with another episode length."""
    import gymnasium as gym

    import myoexo  # noqa: F401  (registers the ids)

    if level not in VALID_LEVELS:
        raise ValueError(f"unknown spasticity level {level!r}; accepted: {VALID_LEVELS}")
    env_id = env_id.format(level=level)
    if episode_duration_s is None:
        return gym.make(env_id)
    from myoexo.envs.config import TaskParams

    task = TaskParams(episode_duration_s=episode_duration_s)
    return gym.make(env_id, task=task, max_episode_steps=task.episode_steps)


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
    """Run one episode of ``controller`` on ``env`` from ``env.reset(seed=seed)``.

    The controller is reset with the same seed; the episode runs until the env terminates
    or truncates it (8 s, or a physics divergence flagged in ``info["unstable"]``).
    """
    max_steps = int(getattr(env.unwrapped, "episode_steps", 0)) or 10_000
    buf = np.full((max_steps + 1, len(_RECORDED)), np.nan)
    obs, info = env.reset(seed=int(seed))
    controller.reset(int(seed))
    subject = {str(k): float(v) for k, v in dict(info.get("subject", {})).items()}
    level = int(info.get("level", getattr(env.unwrapped, "level", -1)))
    buf[0] = [info[k] for k in _RECORDED]
    n, unstable = 0, False
    while n < max_steps:
        action = controller.act(obs, info)
        obs, _, terminated, truncated, info = env.step(action)
        n += 1
        buf[n] = [info[k] for k in _RECORDED]
        unstable = unstable or bool(info.get("unstable", False))
        if terminated or truncated:
            break
    signals = {k: buf[: n + 1, j] for j, k in enumerate(_RECORDED)}
    return EpisodeResult(
        seed=int(seed),
        level=level,
        subject=subject,
        metrics=episode_metrics(signals),
        signals=signals,
        unstable=unstable,
        n_steps=n,
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
) -> tuple[Any, list[EpisodeResult]]:
    """In-process evaluation of a controller *object* (notebooks, tuning).

    Args:
        controller: Any :class:`~myoexo.control.protocol.Controller`.
        level: Spasticity level.
        subjects: Number of subjects (indices ``0..n-1``) or explicit subject indices; the
            same indices give the same persons as :func:`evaluate`.
        root_seed: Root seed of :func:`subject_seed`.
        episode_duration_s: Episode length (``None``: the env's default).
        label: Value of the ``controller`` column.

    Returns:
        ``(table, results)``: a pandas DataFrame (one row per episode) and the
        :class:`EpisodeResult` list with the full-rate signals.
    """
    import pandas as pd

    indices = list(range(subjects)) if isinstance(subjects, (int, np.integer)) else list(subjects)
    env = make_eval_env(level, episode_duration_s)
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
        name = f"{self.start:06d}-{self.stop:06d}.npz"
        return out_dir / TRACES_DIR / self.spec.slug / f"L{self.level}" / name


def plan_chunks(specs: Sequence[ControllerSpec], config: EvaluationConfig) -> list[Chunk]:
    """All chunks of a run, ordered level, subjects, controller (a partial run stays
    paired across controllers)."""
    chunks = []
    for level in config.levels:
        for start in range(0, config.subjects, config.chunk_size):
            stop = min(start + config.chunk_size, config.subjects)
            chunks.extend(Chunk(spec, level, start, stop) for spec in specs)
    return chunks


def n_trace_samples(config: EvaluationConfig) -> int:
    """Samples per stored trace (reset + every ``trace_stride``-th step)."""
    from myoexo.envs.config import TaskParams

    task = (
        TaskParams()
        if config.episode_duration_s is None
        else TaskParams(episode_duration_s=config.episode_duration_s)
    )
    return task.episode_steps // config.trace_stride + 1


#: Per-process caches of the workers: one env per (level, duration), one controller per spec.
_ENVS: dict[tuple[int, float | None, str], Any] = {}
_CONTROLLERS: dict[str, Controller] = {}


def _init_worker() -> None:
    """Worker start-up: one thread per process (the pool provides the parallelism)."""
    os.environ.setdefault("OMP_NUM_THREADS", "1")
    if "torch" in sys.modules:
        sys.modules["torch"].set_num_threads(1)


def _close_worker_state() -> None:
    for env in _ENVS.values():
        env.close()
    _ENVS.clear()
    _CONTROLLERS.clear()


def run_chunk(chunk: Chunk, config: EvaluationConfig, out_dir: str) -> tuple[Chunk, int]:
    """Run one chunk and store it atomically (its rows as JSON + its traces); returns
    ``(chunk, episodes run)``."""
    key = (chunk.level, config.episode_duration_s, config.env_id)
    env = _ENVS.get(key)
    if env is None:
        env = _ENVS[key] = make_eval_env(chunk.level, config.episode_duration_s, config.env_id)
    controller = _CONTROLLERS.get(chunk.spec.text)
    if controller is None:
        controller = _CONTROLLERS[chunk.spec.text] = build_controller(chunk.spec, env)
    n_samples = n_trace_samples(config)
    rows, traces = [], []
    for i in range(chunk.start, chunk.stop):
        result = run_episode(env, controller, subject_seed(chunk.level, i, config.root_seed))
        row = episode_row(result, chunk.spec.label, i)
        row["controller_spec"] = chunk.spec.text
        rows.append(row)
        traces.append(downsample_trace(result, config.trace_stride, n_samples))
    dt = float(env.unwrapped.dt)
    time_s = (np.arange(n_samples) * config.trace_stride * dt).astype(np.float32)
    _atomic_savez(
        chunk.path(Path(out_dir)),
        rows_json=np.array(json.dumps(rows, allow_nan=True)),
        traces=np.stack(traces),
        time_s=time_s,
        channels=np.array(TRACE_CHANNELS),
    )
    return chunk, len(rows)


def _atomic_savez(path: Path, **arrays: np.ndarray) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=".tmp-", suffix=".npz")
    try:
        with os.fdopen(fd, "wb") as f:
            np.savez_compressed(f, **arrays)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise


def _chunk_done(path: Path) -> bool:
    if not path.is_file():
        return False
    try:
        with np.load(path) as z:
            return {"rows_json", "traces"} <= set(z.files)
    except Exception:  # a truncated file from a crash outside the atomic write
        return False


# ----------------------------------------------------------------------------- the run
@dataclass
class EvaluationRun:
    """What :func:`evaluate` produced.

    Attributes:
        out_dir: The output folder.
        table: One row per episode (also in ``episodes.parquet`` / ``.csv``).
        controllers: Labels of the controllers evaluated.
        skipped: Spec -> reason, for controllers left out (e.g. no shipped policy yet).
        computed: Episodes computed by this call (the rest came from earlier runs).
    """

    out_dir: Path
    table: Any
    controllers: list[str]
    skipped: dict[str, str] = field(default_factory=dict)
    computed: int = 0


def resolve_controllers(
    specs_text: Iterable[str], log: Callable[[str], None] = print
) -> tuple[list[ControllerSpec], dict[str, str]]:
    """Parse and check every controller before anything is written.

    A model file that cannot be loaded raises ``ValueError``; ``sac`` without a shipped
    policy is skipped with a message (and reported in the second return value).
    """
    specs, skipped, labels = [], {}, {}
    for text in specs_text:
        spec = parse_controller_spec(text)
        if spec.kind == "sb3":
            load_sb3_model(spec.path, spec.algorithm)  # ValueError if unreadable
        elif spec.kind == "shipped":
            try:
                load_shipped_policy()
            except PolicyUnavailableError as exc:
                skipped[text] = str(exc)
                log(f"myoexo evaluate: skipping controller 'sac': {exc}")
                continue
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


def _file_sha256(path: str) -> str:
    h = hashlib.sha256()
    with open(path, "rb") as f:
        for block in iter(lambda: f.read(1 << 20), b""):
            h.update(block)
    return h.hexdigest()


def _versions() -> dict[str, str]:
    from importlib.metadata import PackageNotFoundError, version

    out = {"python": sys.version.split()[0]}
    for pkg in ("myoexo", "myosuite", "mujoco", "gymnasium", "numpy", "stable-baselines3", "torch"):
        try:
            out[pkg] = version(pkg)
        except PackageNotFoundError:
            out[pkg] = "not installed"
    return out


def _write_config(
    out_dir: Path, config: EvaluationConfig, specs: Sequence[ControllerSpec]
) -> dict[str, Any]:
    """Create or update ``config.json``; refuse a folder holding a different run."""
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
        entry = {"spec": spec.text, "label": spec.label, "kind": spec.kind}
        if spec.path:
            entry["sha256"] = _file_sha256(spec.path)
        old = controllers.get(spec.slug)
        if old is not None and old != entry:
            raise ValueError(
                f"{out_dir} holds results of another controller under the label "
                f"{spec.slug!r} ({old}); choose another --out folder"
            )
        controllers[spec.slug] = entry
    doc = {
        "run_key": config.run_key(),
        "config": dataclasses.asdict(config),
        "controllers": controllers,
        "versions": _versions(),
        "seed_rule": "numpy.random.SeedSequence(root_seed, spawn_key=(level, subject))"
        ".generate_state(1, uint64)[0]",
    }
    path.write_text(json.dumps(doc, indent=2))
    return doc


def evaluate(
    config: EvaluationConfig,
    out_dir: str | os.PathLike[str],
    workers: int | None = None,
    progress: bool = True,
    log: Callable[[str], None] = print,
) -> EvaluationRun:
    """Run (or continue) an evaluation and write its table.

    Args:
        config: What to run.
        out_dir: Output folder (created; a folder of the same run is continued).
        workers: Worker processes (default: all available cores); 1 runs in-process.
        progress: Show a tqdm progress bar.
        log: Where messages go.

    Raises:
        ValueError: Bad settings, an unreadable model file, or an output folder that holds
            a different run; nothing is written in those cases.
    """
    from tqdm.auto import tqdm

    if workers is None:
        workers = available_cores()
    if not isinstance(workers, (int, np.integer)) or workers <= 0:
        raise ValueError(f"workers = {workers!r} must be a positive integer")
    specs, skipped = resolve_controllers(config.controllers, log)
    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise ValueError(f"output path {str(out)!r} exists and is not a folder")
    out.mkdir(parents=True, exist_ok=True)
    _write_config(out, config, specs)
    for stale in (out / TRACES_DIR).glob("*/L*/.tmp-*"):  # writes cut short by a kill
        stale.unlink(missing_ok=True)

    chunks = plan_chunks(specs, config)
    todo = [c for c in chunks if not _chunk_done(c.path(out))]
    total = sum(c.stop - c.start for c in chunks)
    pending = sum(c.stop - c.start for c in todo)
    bar = tqdm(
        total=total,
        initial=total - pending,
        unit="episode",
        desc="evaluate",
        disable=not progress,
        dynamic_ncols=True,
    )
    computed = 0
    try:
        if workers == 1 or len(todo) <= 1:
            try:
                for chunk in todo:
                    _, n = run_chunk(chunk, config, str(out))
                    computed += n
                    bar.update(n)
            finally:
                _close_worker_state()
        elif todo:
            computed = _run_parallel(todo, config, out, min(workers, len(todo)), bar)
    finally:
        bar.close()
    table = collect_table(out, chunks)
    write_table(out, table)
    return EvaluationRun(
        out_dir=out,
        table=table,
        controllers=[s.label for s in specs],
        skipped=skipped,
        computed=computed,
    )


def _run_parallel(todo: list[Chunk], config: EvaluationConfig, out: Path, workers: int, bar):
    import multiprocessing as mp
    from concurrent.futures import FIRST_EXCEPTION, ProcessPoolExecutor, wait

    computed = 0
    ctx = mp.get_context("spawn")
    with ProcessPoolExecutor(workers, mp_context=ctx, initializer=_init_worker) as pool:
        futures = {pool.submit(run_chunk, c, config, str(out)) for c in todo}
        try:
            while futures:
                done, futures = wait(futures, return_when=FIRST_EXCEPTION)
                for fut in done:
                    _, n = fut.result()  # re-raises a worker's error
                    computed += n
                    bar.update(n)
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
    return computed


def available_cores() -> int:
    """CPU cores this process may use."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


# ----------------------------------------------------------------------------- reading
def _read_chunk(path: Path) -> tuple[list[dict[str, Any]], np.ndarray, np.ndarray]:
    with np.load(path) as z:
        return json.loads(str(z["rows_json"])), z["traces"], z["time_s"]


def collect_table(out_dir: str | os.PathLike[str], chunks: Sequence[Chunk]) -> Any:
    """The episode table of the given chunks (ordered as planned)."""
    import pandas as pd

    rows: list[dict[str, Any]] = []
    for chunk in chunks:
        rows.extend(_read_chunk(chunk.path(Path(out_dir)))[0])
    table = pd.DataFrame(rows)
    if not table.empty:
        order = {label: i for i, label in enumerate(dict.fromkeys(c.spec.label for c in chunks))}

        def sort_key(col: pd.Series) -> pd.Series:
            return col.map(order) if col.name == "controller" else col

        table = table.sort_values(["controller", "level", "subject"], key=sort_key)
        table = table.reset_index(drop=True)
    return table


def write_table(out_dir: str | os.PathLike[str], table: Any) -> None:
    """Write ``episodes.parquet`` and ``episodes.csv`` atomically."""
    out = Path(out_dir)
    for suffix, writer in ((".parquet", table.to_parquet), (".csv", table.to_csv)):
        final = out / f"{TABLE_STEM}{suffix}"
        tmp = out / f".tmp-{TABLE_STEM}{suffix}"
        writer(tmp, index=False)
        os.replace(tmp, final)


def load_table(out_dir: str | os.PathLike[str]) -> Any:
    """The episode table of an evaluation folder."""
    import pandas as pd

    path = Path(out_dir) / f"{TABLE_STEM}.parquet"
    if not path.is_file():
        raise ValueError(f"{str(out_dir)!r} has no {path.name}: not an evaluation folder")
    return pd.read_parquet(path)


def load_config(out_dir: str | os.PathLike[str]) -> dict[str, Any]:
    """The ``config.json`` of an evaluation folder."""
    path = Path(out_dir) / CONFIG_FILE
    if not path.is_file():
        raise ValueError(f"{str(out_dir)!r} has no {CONFIG_FILE}: not an evaluation folder")
    return json.loads(path.read_text())


@dataclass
class Traces:
    """Stored traces of one (controller, level).

    Attributes:
        time_s: Sample times (s), shape ``(n_samples,)``.
        subjects: Subject indices, shape ``(n_subjects,)``.
        data: Channel (:data:`TRACE_CHANNELS`) -> float32 ``(n_subjects, n_samples)``.
    """

    time_s: np.ndarray
    subjects: np.ndarray
    data: Mapping[str, np.ndarray]

    def __getitem__(self, channel: str) -> np.ndarray:
        return self.data[channel]


def load_traces(out_dir: str | os.PathLike[str], controller: str, level: int) -> Traces:
    """Gather the stored traces of one controller label and level (every stored chunk)."""
    slug = ControllerSpec(kind="", label=controller, text=controller).slug
    folder = Path(out_dir) / TRACES_DIR / slug / f"L{int(level)}"
    files = sorted(folder.glob("[0-9]*-[0-9]*.npz"))
    if not files:
        raise ValueError(f"no traces for controller {controller!r} at level {level} in {folder}")
    subjects, blocks, time_s = [], [], None
    for path in files:
        rows, traces, time_s = _read_chunk(path)
        subjects.extend(r["subject"] for r in rows)
        blocks.append(traces)
    stacked = np.concatenate(blocks)
    # chunks of runs with another chunk size may overlap: keep each subject once, in order
    subjects_arr, first = np.unique(np.asarray(subjects), return_index=True)
    stacked = stacked[first]
    return Traces(
        time_s=time_s,
        subjects=subjects_arr,
        data={k: stacked[:, :, j] for j, k in enumerate(TRACE_CHANNELS)},
    )
