"""What a sweep is: its file, read and checked (:func:`read_sweep_file`: a bad value stops the
sweep before Ray starts) into a :class:`SweepSpec`, the preset of each of its trials
(:func:`build_preset`, :func:`trial_preset`) and the files of its folder. The keys of a sweep
file: :mod:`myoexo.studies.sweep`."""

from __future__ import annotations

import dataclasses
import json
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from myoexo.envs.options import OPTION_FIELDS, TASK_FIELDS, TwinOptions
from myoexo.training.presets import PRESETS, SACPreset, get_preset, parse_override
from myoexo.training.train import is_myoexo_env

#: Default parent folder of the sweeps (``results/`` is git-ignored).
DEFAULT_OUT = Path("results") / "sweeps"

#: Files of a sweep folder.
SETTINGS_FILE = "sweep.json"
RUNS_DIR = "runs"
TUNE_DIR = "tune"
RESULTS_STEM = "results"

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
        fields = {f.name for f in dataclasses.fields(SACPreset)} - {"name", "twin"}
        fields |= {*TASK_FIELDS, *OPTION_FIELDS}  # the twin's options, by their own names
        for section, keys in (("set", self.fixed), ("search", self.search)):
            bad = sorted(set(keys) - fields)
            _check(not bad, f"{section}: unknown preset field(s) {bad}; accepted: {sorted(fields)}")
        _check(
            "reward_weights" not in self.search,
            "search: put reward weights in the reward_weights section",
        )
        for key, value in self.search.items():
            _check(
                isinstance(value, list) or distribution(value) is not None,
                f"search.{key}: a list of values (grid) or {{distribution: args}}, got {value!r}",
            )
        for key, value in self.reward_weights.items():
            _check(
                isinstance(value, (int, float, list)) or distribution(value) is not None,
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


def distribution(value: Any) -> tuple[str, list[Any]] | None:
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
    dist = distribution(value)
    if dist is not None:
        name, args = dist
        return list(args) if name == "choice" else [args[0]]
    return list(value) if isinstance(value, list) else [value]


def _as_list(value: Any) -> list[Any]:
    return list(value) if isinstance(value, (list, tuple)) else [value]


def _coerce(value: Any, field_name: str | None = None) -> Any:
    """A searched value typed after its preset field (``field_name``) or as a reward weight
    (a number): YAML reads ``1e-4`` as text. Distributions keep their form; their bounds
    are checked by :func:`distribution`."""

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
    if isinstance(value, str) and TwinOptions.is_option(key):
        options = TwinOptions().with_override(f"{key}={value}")
        return dict(options.task).get(key) if key in TASK_FIELDS else getattr(options, key)
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


def trial_preset(config: Mapping[str, Any]) -> tuple[SACPreset, int]:
    """``(preset, seed)`` of a trial's resolved config."""
    preset = build_preset(
        config["preset"], config.get("set", {}), config["search"], config["reward_weights"]
    )
    return preset, int(config["seed"])
