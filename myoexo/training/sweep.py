"""``myoexo sweep FILE``: Ray Tune over SAC training configurations, ranked on the paper's
acceptance criteria, resumable after the driver is killed.

    myoexo sweep sweeps/reward.yaml                       # a local cluster of every core
    myoexo sweep sweeps/reward.yaml --address auto        # the cluster of `ray start`

The sweep file (YAML, or TOML with the same keys)::

    name: reward-inter              # folder under --out (default: the file's name)
    preset: cpu                     # a preset name, or a list of them (searched)
    seeds: [0, 1]                   # one trial per seed, crossed with the rest
    set:                            # preset fields, the same in every trial
      total_timesteps: 500000
      eval_every_steps: 25000
    search:                         # preset fields searched: a list is a grid;
      learning_rate: {loguniform: [1.0e-4, 1.0e-3]}   # or choice / uniform / loguniform /
      batch_size: [128, 256]                          # randint: [low, high]
    reward_weights:                 # reward weights: a number (fixed), a list (grid) or a
      inter: [-0.5, -1.0]           # distribution, as in `search`
    num_samples: 1                  # draws of the distributions (each crossed with the grids)
    scheduler: asha                 # optional early stopping: asha or median
    grace_evals: 2                  # evaluations before a trial may be stopped
    reduction_factor: 2             # asha's halving rate
    metric: score                   # what the scheduler compares: score (max) or shortfall (min)
    cpus_per_trial: 1
    max_concurrent_trials: 0        # 0: as many as the CPUs allow

Only SAC is trained (:mod:`myoexo.training.train`) and the presets have no observation
variants, so neither an algorithm nor an observation set is a sweep key.

Each trial is a normal training run (:func:`~myoexo.training.train.train`) in
``<out>/<name>/runs/<trial id>/`` with its checkpoints, ``eval.csv`` and tensorboard logs.
While it trains, every new periodic evaluation of its ``eval.csv`` (the deterministic policy
against the PID on fixed subjects, :class:`~myoexo.training.callbacks.PaperMetricsEvalCallback`)
is reported to Tune with the acceptance criteria of :mod:`myoexo.evaluation.criteria`: the
score, the shortfall, whether it passes, and per level the final error and the peak / RMS
torque reductions against the PID. When the sweep ends, ``results.parquet`` and
``results.md`` rank every trial on its best evaluation: smallest shortfall first (0 = passes
every criterion), then largest mean peak-torque reduction, as ``myoexo select`` ranks
checkpoints; a policy snapshot exists for every evaluated step.

Resuming: the Tune experiment lives in ``<out>/<name>/tune``. Running the same command again
after the driver was killed restores it (``Tuner.restore``): finished trials are kept,
interrupted ones start again and continue their own run folder from its newest resumable
checkpoint (:func:`~myoexo.training.train.resume`), reporting only the evaluations Tune has
not seen. Ray and PyYAML come with the ``ray`` extra; nothing here imports them until a
sweep runs.
"""

from __future__ import annotations

import argparse
import atexit
import csv
import dataclasses
import json
import math
import shutil
import sys
import tempfile
import threading
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from myoexo.evaluation import criteria
from myoexo.evaluation.criteria import CRITERIA_METRICS
from myoexo.runtime.files import write_json_atomic
from myoexo.training import checkpoints as ck
from myoexo.training.presets import PRESETS, SACPreset, get_preset, parse_override
from myoexo.training.train import is_myoexo_env

#: Default parent folder of the sweeps (``results/`` is git-ignored).
DEFAULT_OUT = Path("results") / "sweeps"

#: Files of a sweep folder.
SETTINGS_FILE = "sweep.json"
RUNS_DIR = "runs"
TUNE_DIR = "tune"
RESULTS_STEM = "results"

#: Seconds between two looks of a trial at its run's ``eval.csv``.
REPORT_POLL_S = 1.0

#: Seconds a stopped trial waits for its training to write its last checkpoint.
STOP_TIMEOUT_S = 60.0

#: Distributions a sweep file may name -> number of arguments.
DISTRIBUTIONS: dict[str, int | None] = {
    "choice": None,
    "uniform": 2,
    "loguniform": 2,
    "randint": 2,
}

#: Metrics a scheduler may compare -> Tune's mode.
METRICS: dict[str, str] = {"score": "max", "shortfall": "min"}

SCHEDULERS: tuple[str, ...] = ("asha", "median")

#: Keys of a sweep file.
_KEYS = frozenset(
    {
        "name",
        "preset",
        "seeds",
        "set",
        "search",
        "reward_weights",
        "num_samples",
        "scheduler",
        "grace_evals",
        "reduction_factor",
        "metric",
        "cpus_per_trial",
        "max_concurrent_trials",
    }
)


# ----------------------------------------------------------------------------- the file
@dataclass(frozen=True)
class SweepSpec:
    """A sweep (the keys of a sweep file; see the module docstring).

    Attributes:
        name: Folder of the sweep under the output folder.
        presets: Preset names; more than one is a grid.
        seeds: Training seeds, a grid.
        fixed: Preset fields set in every trial (``set``).
        search: Preset field -> list (grid) or ``{distribution: args}``.
        reward_weights: Reward term -> weight, list (grid) or ``{distribution: args}``.
        num_samples: Draws of the distributions (Tune's ``num_samples``).
        scheduler: ``None``, ``"asha"`` or ``"median"``.
        grace_evals: Evaluations a trial runs before a scheduler may stop it.
        reduction_factor: ASHA's halving rate.
        metric: ``"score"`` or ``"shortfall"``, compared by the scheduler.
        cpus_per_trial: CPUs reserved per trial.
        max_concurrent_trials: Trials at once (0: as many as the CPUs allow).
    """

    name: str
    presets: tuple[str, ...] = ("cpu",)
    seeds: tuple[int, ...] = (0,)
    fixed: Mapping[str, Any] = field(default_factory=dict)
    search: Mapping[str, Any] = field(default_factory=dict)
    reward_weights: Mapping[str, Any] = field(default_factory=dict)
    num_samples: int = 1
    scheduler: str | None = None
    grace_evals: int = 1
    reduction_factor: int = 2
    metric: str = "score"
    cpus_per_trial: float = 1.0
    max_concurrent_trials: int = 0

    def __post_init__(self) -> None:
        _check(bool(self.name) and "/" not in self.name, f"name {self.name!r} is not a folder")
        _check(bool(self.presets), "preset: name at least one")
        unknown = sorted(set(self.presets) - set(PRESETS))
        _check(not unknown, f"unknown preset(s) {unknown}; accepted: {sorted(PRESETS)}")
        _check(
            bool(self.seeds) and all(_is_int(s) and s >= 0 for s in self.seeds),
            f"seeds {list(self.seeds)} must be integers >= 0",
        )
        for key in ("num_samples", "grace_evals", "reduction_factor"):
            value = getattr(self, key)
            _check(_is_int(value) and value >= 1, f"{key} = {value!r} must be an integer >= 1")
        _check(
            _is_int(self.max_concurrent_trials) and self.max_concurrent_trials >= 0,
            f"max_concurrent_trials = {self.max_concurrent_trials!r} must be an integer >= 0",
        )
        _check(
            isinstance(self.cpus_per_trial, (int, float)) and self.cpus_per_trial > 0,
            f"cpus_per_trial = {self.cpus_per_trial!r} must be > 0",
        )
        _check(
            self.scheduler is None or self.scheduler in SCHEDULERS,
            f"scheduler {self.scheduler!r}; accepted: {SCHEDULERS} or none",
        )
        _check(self.metric in METRICS, f"metric {self.metric!r}; accepted: {sorted(METRICS)}")
        fields = {f.name for f in dataclasses.fields(SACPreset)} - {"name"}
        for section, keys in (("set", self.fixed), ("search", self.search)):
            bad = sorted(set(keys) - fields)
            _check(not bad, f"{section}: unknown preset field(s) {bad}; accepted: {sorted(fields)}")
        _check(
            "reward_weights" not in self.search,
            "search: put reward weights in the reward_weights section",
        )
        for key, value in self.search.items():
            _check(
                isinstance(value, list) or _distribution(value) is not None,
                f"search.{key}: a list of values (grid) or {{distribution: args}}, got {value!r}",
            )
        for key, value in self.reward_weights.items():
            _check(
                isinstance(value, (int, float, list)) or _distribution(value) is not None,
                f"reward_weights.{key}: a number, a list or {{distribution: args}}, got {value!r}",
            )
        self._check_presets()

    def _check_presets(self) -> None:
        """Build the preset of every grid value (the low bound of each distribution) once,
        so that a bad value stops the sweep before Ray starts."""
        probes: list[tuple[str, dict[str, Any], dict[str, float]]] = []
        for name in self.presets:
            probes.append((name, {}, {}))
            for key, value in self.search.items():
                probes.extend((name, {key: v}, {}) for v in _probe_values(value))
            for key, value in self.reward_weights.items():
                probes.extend((name, {}, {key: float(v)}) for v in _probe_values(value))
        for name, search, weights in probes:
            preset = build_preset(name, self.fixed, search, weights)
            _check(
                preset.eval_every_steps > 0 and is_myoexo_env(preset.env_id),
                f"preset {name!r}: a sweep ranks trials on the periodic evaluation; set "
                "eval_every_steps > 0 on a MyoExoKnee env",
            )
            _check(
                preset.eval_every_steps <= preset.total_timesteps,
                f"preset {name!r}: eval_every_steps = {preset.eval_every_steps} exceeds "
                f"total_timesteps = {preset.total_timesteps}: no evaluation to rank",
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the sweep folder's ``sweep.json``)."""
        d = dataclasses.asdict(self)
        return json.loads(json.dumps(d))


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ValueError(f"sweep file: {message}")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _distribution(value: Any) -> tuple[str, list[Any]] | None:
    """``{name: args}`` -> ``(name, args)`` if a known distribution, else ``None``."""
    if not isinstance(value, Mapping) or len(value) != 1:
        return None
    ((name, args),) = value.items()
    if name not in DISTRIBUTIONS or not isinstance(args, list) or not args:
        return None
    n = DISTRIBUTIONS[name]
    if n is None:
        return name, list(args)
    if len(args) != n:
        raise ValueError(f"sweep file: {name} takes {n} arguments [low, high], got {args}")
    cast = int if name == "randint" else float
    try:  # YAML reads 1e-4 (no dot) as text
        bounds = [cast(a) for a in args if not isinstance(a, bool)]
    except (TypeError, ValueError):
        bounds = []
    if len(bounds) != n or not bounds[0] < bounds[1]:
        raise ValueError(f"sweep file: {name} bounds {args} must be two numbers, low < high")
    if name == "loguniform" and bounds[0] <= 0:
        raise ValueError(f"sweep file: loguniform bounds {args} must be > 0")
    return name, bounds


def _probe_values(value: Any) -> list[Any]:
    """Values that stand for a search entry when checking it: every grid value, the low
    bound of a distribution (every choice)."""
    dist = _distribution(value)
    if dist is not None:
        name, args = dist
        return list(args) if name == "choice" else [args[0]]
    return list(value) if isinstance(value, list) else [value]


def _as_list(value: Any) -> list[Any]:
    return list(value) if isinstance(value, (list, tuple)) else [value]


def _coerce(value: Any, field_name: str | None = None) -> Any:
    """A searched value typed after its preset field (``field_name``) or as a reward weight
    (a number): YAML reads ``1e-4`` as text. Distributions keep their form; their bounds
    are checked by :func:`_distribution`."""

    def one(v: Any) -> Any:
        if not isinstance(v, str):
            return v
        if field_name is not None:
            return _typed(field_name, v)
        try:
            return float(v)
        except ValueError:
            raise ValueError(f"sweep file: reward weight {v!r} is not a number") from None

    if isinstance(value, list):
        return [one(v) for v in value]
    if isinstance(value, Mapping):
        return dict(value)
    return one(value)


def read_sweep_file(path: str | Path) -> SweepSpec:
    """Read and check a sweep file (``.yaml``/``.yml`` or ``.toml``)."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"sweep file {str(path)!r} does not exist")
    text = path.read_text()
    if path.suffix.lower() == ".toml":
        try:
            import tomllib
        except ImportError:  # Python 3.10
            raise ValueError("a TOML sweep file needs Python >= 3.11; use YAML") from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as exc:
            raise ValueError(f"sweep file {path.name}: {exc}") from None
    elif path.suffix.lower() in (".yaml", ".yml"):
        try:
            import yaml
        except ImportError:
            raise ValueError("a YAML sweep file needs PyYAML: pip install 'myoexo[ray]'") from None
        try:
            data = yaml.safe_load(text)
        except yaml.YAMLError as exc:
            raise ValueError(f"sweep file {path.name}: {' '.join(str(exc).split())}") from None
    else:
        raise ValueError(f"sweep file {path.name}: expected .yaml, .yml or .toml")
    if not isinstance(data, dict):
        raise ValueError(f"sweep file {path.name}: expected a mapping of keys")
    unknown = sorted(set(data) - _KEYS)
    _check(not unknown, f"unknown key(s) {unknown}; accepted: {sorted(_KEYS)}")
    for section in ("set", "search", "reward_weights"):
        _check(isinstance(data.get(section, {}), dict), f"{section} must be a mapping")
    scheduler = data.get("scheduler")
    search = {str(k): _coerce(v, str(k)) for k, v in data.get("search", {}).items()}
    weights = {str(k): _coerce(v) for k, v in data.get("reward_weights", {}).items()}
    return SweepSpec(
        name=str(data.get("name", path.stem)),
        presets=tuple(_as_list(data.get("preset", "cpu"))),
        seeds=tuple(_as_list(data.get("seeds", 0))),
        fixed=dict(data.get("set", {})),
        search=search,
        reward_weights=weights,
        num_samples=data.get("num_samples", 1),
        scheduler=None if scheduler in (None, "none") else str(scheduler),
        grace_evals=data.get("grace_evals", 1),
        reduction_factor=data.get("reduction_factor", 2),
        metric=str(data.get("metric", "score")),
        cpus_per_trial=data.get("cpus_per_trial", 1.0),
        max_concurrent_trials=data.get("max_concurrent_trials", 0),
    )


# ----------------------------------------------------------------------------- trials
def _typed(key: str, value: Any) -> Any:
    """A sweep file's value for preset field ``key``: text typed after the field (YAML reads
    ``1e-4`` as text), lists as tuples."""
    if isinstance(value, str) and key != "name":
        return parse_override(f"{key}={value}")[1]
    if isinstance(value, list):
        return tuple(tuple(v) if isinstance(v, list) else v for v in value)
    return value


def build_preset(
    name: str,
    fixed: Mapping[str, Any],
    search: Mapping[str, Any],
    weights: Mapping[str, float],
) -> SACPreset:
    """The preset of one trial: ``name`` with the fixed fields, the trial's searched fields,
    and its reward weights on top of any fixed ones."""
    overrides = {k: _typed(k, v) for k, v in {**fixed, **search}.items()}
    merged: dict[str, float] = {}
    base = fixed.get("reward_weights", {})
    if isinstance(base, Mapping):
        merged.update({str(k): float(v) for k, v in base.items()})
    else:
        merged.update({str(k): float(v) for k, v in base})
    merged.update({str(k): float(v) for k, v in weights.items()})
    overrides["reward_weights"] = tuple(sorted(merged.items()))
    return get_preset(name, **overrides)


def param_space(spec: SweepSpec) -> dict[str, Any]:
    """Tune's search space of a sweep: ``preset``, ``seed``, ``set``, ``search`` and
    ``reward_weights`` (a trial's config has the same keys, resolved)."""
    from ray import tune

    def grid(values: Sequence[Any]) -> Any:
        return tune.grid_search(list(values)) if len(values) > 1 else values[0]

    def domain(value: Any) -> Any:
        dist = _distribution(value)
        if dist is None:
            return tune.grid_search(list(value)) if isinstance(value, list) else value
        name, args = dist
        if name == "choice":
            return tune.choice(args)
        return getattr(tune, name)(*args)

    return {
        "preset": grid(spec.presets),
        "seed": grid(spec.seeds),
        "set": dict(spec.fixed),
        "search": {k: domain(v) for k, v in spec.search.items()},
        "reward_weights": {k: domain(v) for k, v in spec.reward_weights.items()},
    }


def trial_preset(config: Mapping[str, Any]) -> tuple[SACPreset, int]:
    """``(preset, seed)`` of a trial's resolved config."""
    preset = build_preset(
        config["preset"], config.get("set", {}), config["search"], config["reward_weights"]
    )
    return preset, int(config["seed"])


def _stop_callback(stop: threading.Event) -> Any:
    """An SB3 callback that ends the training session once ``stop`` is set."""
    from stable_baselines3.common.callbacks import BaseCallback

    class StopOnEvent(BaseCallback):
        def _on_step(self) -> bool:
            return not stop.is_set()

    return StopOnEvent()


class _Training(threading.Thread):
    """A trial's training run (new, resumed or restarted), in the background while the
    trial's own thread reports its evaluations; setting :attr:`stop` ends it at the next
    step, with a resumable checkpoint."""

    def __init__(self, preset: SACPreset, run_dir: Path, seed: int, verbose: int) -> None:
        super().__init__(name="myoexo-training", daemon=True)
        self.preset, self.run_dir, self.seed, self.verbose = preset, run_dir, seed, verbose
        self.stop = threading.Event()
        self.error: BaseException | None = None

    def run(self) -> None:
        from myoexo.training.train import resume, train

        callbacks = [_stop_callback(self.stop)]
        try:
            if (self.run_dir / ck.CONFIG_FILE).is_file():
                if ck.latest_checkpoint(self.run_dir, with_replay=True) is not None:
                    resume(self.run_dir, verbose=self.verbose, callbacks=callbacks)
                    return
                shutil.rmtree(self.run_dir)  # stopped before its first checkpoint: anew
            train(self.preset, self.run_dir, self.seed, verbose=self.verbose, callbacks=callbacks)
        except BaseException as exc:
            self.error = exc

    def end(self) -> None:
        """Stop the training and wait for its last checkpoint (a trial stopped by the
        scheduler, or its process exiting)."""
        if self.is_alive():
            self.stop.set()
            self.join(STOP_TIMEOUT_S)


def run_trial(config: dict[str, Any], runs_dir: str, verbose: int = 0) -> None:
    """Tune's function trainable: train one configuration in ``runs_dir/<trial id>`` and
    report each new evaluation of its ``eval.csv`` (:func:`evaluation_metrics`)."""
    from ray import tune

    preset, seed = trial_preset(config)
    run_dir = Path(runs_dir) / tune.get_context().get_trial_id()
    reported = -1
    restored = tune.get_checkpoint()
    if restored is not None:
        with restored.as_directory() as folder:
            reported = int(json.loads((Path(folder) / "reported.json").read_text())["step"])
    training = _Training(preset, run_dir, seed, verbose)
    # a trial stopped by the scheduler ends with its process: stop the training cleanly
    # first (a daemon thread still printing at interpreter exit aborts it)
    atexit.register(training.end)
    training.start()
    try:
        while True:
            running = training.is_alive()  # before reading: the last rows are then seen
            for metrics in evaluation_metrics(run_dir, preset.eval_levels, after=reported):
                _report(metrics)
                reported = int(metrics["step"])
            if not running:
                break
            training.join(REPORT_POLL_S)
    finally:
        training.end()
        atexit.unregister(training.end)
    if training.error is not None:
        raise training.error


def _report(metrics: dict[str, Any]) -> None:
    """``tune.report`` with a checkpoint holding the step, so that a restored trial reports
    only newer evaluations."""
    from ray import tune

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "reported.json").write_text(json.dumps({"step": metrics["step"]}))
        tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(tmp))


# ----------------------------------------------------------------------------- metrics
def read_eval_rows(run_dir: Path) -> dict[tuple[int, int], dict[str, float]]:
    """The rows of a run's ``eval.csv`` keyed by ``(step, level)``: a step evaluated again
    after a resume keeps its newest row, and a row cut short by a kill is skipped."""
    path = Path(run_dir) / ck.EVAL_FILE
    rows: dict[tuple[int, int], dict[str, float]] = {}
    if not path.is_file():
        return rows
    with open(path, newline="") as f:
        for row in csv.DictReader(f):
            try:
                values = {k: float(v) for k, v in row.items() if k is not None}
                if None in row or len(values) != len(row):
                    continue
                rows[(int(values["step"]), int(values["level"]))] = values
            except (KeyError, TypeError, ValueError):
                continue
    return rows


def evaluation_metrics(
    run_dir: Path, levels: Sequence[int], after: int = -1
) -> list[dict[str, Any]]:
    """One dict per evaluated step after step ``after`` of a run (every level present),
    oldest first: the step,
    :func:`~myoexo.evaluation.criteria.score`, :func:`~myoexo.evaluation.criteria.shortfall`,
    ``passes`` (every criterion met), the mean peak-torque reduction against the PID, the
    fraction of unstable episodes, and per level ``L<l>_abs_final_error_deg``,
    ``L<l>_peak_reduction_pct``, ``L<l>_rms_reduction_pct`` and ``L<l>_pass``."""
    pid_path = Path(run_dir) / ck.EVAL_PID_FILE
    rows = read_eval_rows(run_dir)
    if not rows or not pid_path.is_file():
        return []
    pid = {int(k): v for k, v in json.loads(pid_path.read_text()).items()}
    out = []
    for step in sorted({s for s, _ in rows if s > after}):
        if not all((step, lv) in rows and lv in pid for lv in levels):
            continue
        sac = {lv: {m: rows[(step, lv)][m] for m in CRITERIA_METRICS} for lv in levels}
        table = criteria.compare(sac, {lv: pid[lv] for lv in levels})
        metrics: dict[str, Any] = {
            "step": int(step),
            "score": criteria.score(table),
            "shortfall": criteria.shortfall(table),
            "passes": bool(table["pass"].all()),
            "mean_peak_reduction_pct": float(table.peak_reduction_pct.mean()),
            "unstable_fraction": float(
                sum(rows[(step, lv)].get("unstable", 0.0) for lv in levels) / len(levels)
            ),
        }
        for lv, r in table.iterrows():
            metrics[f"L{lv}_abs_final_error_deg"] = float(r.sac_abs_final_error_deg)
            metrics[f"L{lv}_peak_reduction_pct"] = float(r.peak_reduction_pct)
            metrics[f"L{lv}_rms_reduction_pct"] = float(r.rms_reduction_pct)
            metrics[f"L{lv}_pass"] = bool(r["pass"])
        out.append(metrics)
    return out


def rank_key(metrics: Mapping[str, Any]) -> tuple[float, float]:
    """Order of evaluations and trials (smaller is better): shortfall, then the negated
    mean peak-torque reduction (as ``myoexo select`` orders checkpoints)."""
    shortfall = float(metrics.get("shortfall", math.inf))
    peak = float(metrics.get("mean_peak_reduction_pct", -math.inf))
    return (shortfall if math.isfinite(shortfall) else math.inf, -peak)


# ----------------------------------------------------------------------------- the table
def _scalar(value: Any) -> Any:
    """A table cell: numbers and text as they are, anything else as text."""
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return json.dumps(value)


def _run_steps(run_dir: Path) -> int:
    last = ck.latest_checkpoint(run_dir)
    return int(ck.read_state(last)["num_timesteps"]) if last is not None else 0


def results_table(spec: SweepSpec, sweep_dir: Path, trials: Sequence[Mapping[str, Any]]) -> Any:
    """The ranked table of a sweep: one row per trial (``trials``: dicts with ``trial_id``,
    ``config`` and ``error``), on each trial's best evaluation (:func:`rank_key`)."""
    import pandas as pd

    rows = []
    for trial in trials:
        config = trial["config"]
        run_dir = sweep_dir / RUNS_DIR / trial["trial_id"]
        preset, seed = trial_preset(config)
        evals = evaluation_metrics(run_dir, preset.eval_levels) if run_dir.is_dir() else []
        steps = _run_steps(run_dir) if run_dir.is_dir() else 0
        if trial.get("error"):
            status = "error"
        elif steps >= preset.total_timesteps:
            status = "done"
        else:
            status = "stopped"  # by the scheduler, or interrupted
        row: dict[str, Any] = {
            "trial": trial["trial_id"],
            "status": status,
            "preset": config["preset"],
            "seed": seed,
        }
        row.update({k: _scalar(v) for k, v in config["search"].items()})
        row.update({f"w_{k}": float(v) for k, v in config["reward_weights"].items()})
        row.update(steps=steps, evaluations=len(evals))
        best = min(evals, key=rank_key) if evals else {}
        row["best_step"] = best.get("step")
        for key in ("shortfall", "passes", "mean_peak_reduction_pct", "score"):
            row[key] = best.get(key)
        for lv in preset.eval_levels:
            for metric in ("abs_final_error_deg", "peak_reduction_pct"):
                row[f"L{lv}_{metric}"] = best.get(f"L{lv}_{metric}")
        row["last_step"] = evals[-1]["step"] if evals else None
        row["last_score"] = evals[-1]["score"] if evals else None
        row["run_dir"] = str(Path(RUNS_DIR) / trial["trial_id"])
        row["_key"] = rank_key(best)
        rows.append(row)
    rows.sort(key=lambda r: r["_key"])
    for i, row in enumerate(rows, start=1):
        row.pop("_key")
        row["rank"] = i
    table = pd.DataFrame(rows)
    if not table.empty:
        table = table[["rank", *[c for c in table.columns if c != "rank"]]]
    return table


def write_results(sweep_dir: Path, table: Any, spec: SweepSpec) -> tuple[Path, Path]:
    """``results.parquet`` and ``results.md`` (the table under a short heading)."""
    from myoexo.runtime.files import atomic_path, write_text_atomic

    parquet = sweep_dir / f"{RESULTS_STEM}.parquet"
    with atomic_path(parquet) as tmp:
        table.to_parquet(tmp, index=False)
    md = sweep_dir / f"{RESULTS_STEM}.md"
    heading = (
        f"# Sweep {spec.name}\n\n{len(table)} trials ranked on their best periodic "
        "evaluation against the PID: shortfall from the acceptance criteria (0 = every "
        "criterion met), then mean peak interaction-torque reduction (%).\n\n"
    )
    write_text_atomic(md, heading + table.to_markdown(index=False, floatfmt=".4g") + "\n")
    return parquet, md


# ----------------------------------------------------------------------------- running
def _trial_dirname(trial: Any) -> str:
    """Tune's folder (and name) of a trial: its id, which also names its run folder."""
    return str(trial.trial_id)


def _scheduler(spec: SweepSpec) -> Any:
    if spec.scheduler is None:
        return None
    from ray.tune.schedulers import ASHAScheduler, MedianStoppingRule

    if spec.scheduler == "asha":
        max_evals = max(
            build_preset(p, spec.fixed, {}, {}).total_timesteps
            // build_preset(p, spec.fixed, {}, {}).eval_every_steps
            for p in spec.presets
        )
        return ASHAScheduler(
            time_attr="training_iteration",
            max_t=max(max_evals, spec.grace_evals),
            grace_period=spec.grace_evals,
            reduction_factor=spec.reduction_factor,
        )
    return MedianStoppingRule(time_attr="training_iteration", grace_period=spec.grace_evals)


def _check_folder(sweep_dir: Path, spec: SweepSpec) -> None:
    """Record the sweep in ``sweep.json``, or refuse a folder that holds another sweep."""
    path = sweep_dir / SETTINGS_FILE
    if path.is_file():
        previous = json.loads(path.read_text())
        if previous != spec.to_dict():
            raise ValueError(
                f"{sweep_dir} holds a sweep with other settings ({path.name}); resume it with "
                "its own file, or give this sweep another name or --out"
            )
    else:
        write_json_atomic(path, spec.to_dict(), indent=2)


@dataclass
class SweepResult:
    """Outcome of :func:`run_sweep`.

    Attributes:
        sweep_dir: The sweep folder.
        table: The ranked table (also in ``results.parquet`` / ``results.md``).
        errors: Trial id -> error text, for trials that failed.
        restored: Whether an interrupted sweep was continued.
    """

    sweep_dir: Path
    table: Any
    errors: dict[str, str]
    restored: bool


def run_sweep(
    spec: SweepSpec,
    out: str | Path = DEFAULT_OUT,
    address: str | None = None,
    num_cpus: int | None = None,
    verbose: int = 1,
) -> SweepResult:
    """Run (or continue) a sweep and write its ranked table.

    Args:
        spec: The sweep (:func:`read_sweep_file`).
        out: Parent folder; the sweep lives in ``out/spec.name``.
        address: Ray cluster to join (:func:`myoexo.runtime.ray_cluster.resolve_address`).
        num_cpus: CPUs of a local cluster (default: every core).
        verbose: 0 quiet, 1 Tune's status and each trial's evaluations, 2 more.
    """
    from myoexo.runtime.ray_cluster import ray_session, require_ray

    require_ray("myoexo sweep")
    sweep_dir = Path(out).resolve() / spec.name
    sweep_dir.mkdir(parents=True, exist_ok=True)
    _check_folder(sweep_dir, spec)
    runs_dir = sweep_dir / RUNS_DIR
    runs_dir.mkdir(exist_ok=True)
    with ray_session(num_cpus, address, "myoexo sweep"):
        from ray import tune

        trainable = tune.with_resources(
            tune.with_parameters(run_trial, runs_dir=str(runs_dir), verbose=verbose),
            {"cpu": spec.cpus_per_trial},
        )
        experiment = sweep_dir / TUNE_DIR
        restored = tune.Tuner.can_restore(str(experiment))
        if restored:
            tuner = tune.Tuner.restore(
                str(experiment), trainable, resume_unfinished=True, resume_errored=True
            )
        else:
            tuner = tune.Tuner(
                trainable,
                param_space=param_space(spec),
                tune_config=tune.TuneConfig(
                    metric=spec.metric,
                    mode=METRICS[spec.metric],
                    scheduler=_scheduler(spec),
                    num_samples=spec.num_samples,
                    max_concurrent_trials=spec.max_concurrent_trials or None,
                    trial_name_creator=_trial_dirname,
                    trial_dirname_creator=_trial_dirname,
                ),
                run_config=tune.RunConfig(
                    name=TUNE_DIR,
                    storage_path=str(sweep_dir),
                    verbose=min(verbose, 1),
                ),
            )
        grid = tuner.fit()
        results = [grid[i] for i in range(len(grid))]
        trials: list[dict[str, Any]] = [
            {
                "trial_id": Path(r.path).name,
                "config": r.config,
                "error": None if r.error is None else f"{type(r.error).__name__}: {r.error}",
            }
            for r in results
        ]
    table = results_table(spec, sweep_dir, trials)
    write_results(sweep_dir, table, spec)
    errors = {str(t["trial_id"]): str(t["error"]) for t in trials if t["error"]}
    return SweepResult(sweep_dir=sweep_dir, table=table, errors=errors, restored=restored)


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo sweep``."""
    parser.add_argument("file", type=Path, help="sweep file (.yaml or .toml)")
    parser.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"parent folder of the sweep (default: {DEFAULT_OUT}); the sweep lives in "
        "OUT/<name>, and running the same command again continues it",
    )
    parser.add_argument(
        "--address",
        default=None,
        help="Ray cluster to join: HOST:PORT or 'auto' (default: the RAY_ADDRESS environment "
        "variable, else a local cluster that ends with the command)",
    )
    parser.add_argument(
        "--num-cpus",
        type=int,
        default=None,
        help="CPUs of the local cluster (default: every core; ignored with --address)",
    )
    parser.add_argument(
        "-v", "--verbose", type=int, default=1, help="0 quiet, 1 status and evaluations"
    )


#: Trials listed on the terminal at the end of a sweep (the table holds them all).
SHOWN_TRIALS = 5


def _lines(table: Any) -> Iterator[str]:
    for _, row in table.head(SHOWN_TRIALS).iterrows():
        if row["evaluations"] == 0:
            yield f"  {row['rank']}. {row['trial']} ({row['status']}): no evaluation"
            continue
        yield (
            f"  {row['rank']}. {row['trial']} ({row['status']}): shortfall "
            f"{row['shortfall']:.3f}, mean peak-torque reduction "
            f"{row['mean_peak_reduction_pct']:+.1f} % at step {int(row['best_step'])}"
        )


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo sweep``; 1 if a trial failed (its error is listed), else 0."""
    if args.num_cpus is not None and args.num_cpus <= 0:
        raise ValueError(f"--num-cpus {args.num_cpus} must be > 0")
    spec = read_sweep_file(args.file)
    result = run_sweep(spec, args.out, args.address, args.num_cpus, args.verbose)
    what = "continued" if result.restored else "ran"
    print(f"[sweep] {what} {spec.name}: {len(result.table)} trials, ranked:")
    for line in _lines(result.table):
        print(line)
    print(f"[sweep] table: {result.sweep_dir / RESULTS_STEM}.md (and .parquet)")
    for trial_id, error in result.errors.items():
        print(f"[sweep] trial {trial_id} failed: {error}", file=sys.stderr)
    return 1 if result.errors else 0
