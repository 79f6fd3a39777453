"""What a sweep is: its file, read and checked (:func:`read_sweep_file`: a bad value stops the
sweep before Ray starts) into a :class:`SweepSpec`, the training config of each of its trials
(:func:`build_config`, :func:`trial_config`) and the files of its folder. The keys of a sweep
file: :mod:`myoexo.studies.sweep`."""

from __future__ import annotations

import dataclasses
import json
import typing
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from myoexo.envs.options import OPTION_FIELDS, TASK_FIELDS, TwinOptions
from myoexo.runtime.fields import FieldError, check_fields, convert, literal, option
from myoexo.training.config import KNOWN_KWARGS, PRESETS, TrainConfig, get_preset, typed_kwarg
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

#: Training-config fields a sweep file may set or search (the seed is the sweep's ``seeds``,
#: the preset its ``preset``), beside the twin's options by their own names.
CONFIG_FIELDS: frozenset[str] = frozenset(
    f.name for f in dataclasses.fields(TrainConfig) if f.name not in ("name", "twin", "seed")
)

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
        fixed: Training-config fields (and twin options) set in every trial (``set``;
            ``algorithm_kwargs``: a mapping, merged into the preset's).
        search: Config field (or twin option) -> list (grid) or ``{distribution: args}``;
            ``algorithm_kwargs``: argument name -> list or distribution.
        reward_weights: Reward term -> weight, list (grid) or ``{distribution: args}``.
        num_samples: Draws of the distributions (Tune's ``num_samples``).
        scheduler: ``None``, ``"asha"`` or ``"median"``.
        grace_evals: Evaluations a trial runs before a scheduler may stop it.
        reduction_factor: ASHA's halving rate.
        metric: ``"score"`` or ``"shortfall"``, compared by the scheduler.
        cpus_per_trial: CPUs reserved per trial.
        max_concurrent_trials: Trials at once (0: as many as the CPUs allow).
    """

    name: str = option("", "folder of the sweep under the output folder")
    presets: tuple[str, ...] = option(("cpu",), "preset names (a grid)", choices=sorted(PRESETS))
    seeds: tuple[int, ...] = option((0,), "training seeds (a grid)", low=0)
    fixed: Mapping[str, Any] = field(default_factory=dict)
    search: Mapping[str, Any] = field(default_factory=dict)
    reward_weights: Mapping[str, Any] = field(default_factory=dict)
    num_samples: int = option(1, "draws of the distributions", low=1)
    scheduler: str | None = option(None, "early stopping", choices=SCHEDULERS)
    grace_evals: int = option(1, "evaluations before a trial may be stopped", low=1)
    reduction_factor: int = option(2, "ASHA's halving rate", low=1)
    metric: str = option("score", "what the scheduler compares", choices=sorted(METRICS))
    cpus_per_trial: float = option(1.0, "CPUs reserved per trial", low=0.0, above=True)
    max_concurrent_trials: int = option(0, "trials at once (0: as the CPUs allow)", low=0)

    def __post_init__(self) -> None:
        _check(bool(self.name) and "/" not in self.name, f"name {self.name!r} is not a folder")
        _check(bool(self.presets), "preset: name at least one")
        _check(bool(self.seeds), "seeds: name at least one")
        try:
            check_fields(self)
        except FieldError as exc:
            section = {"presets": "preset"}.get(exc.field, exc.field)
            raise ValueError(f"sweep file: {exc.describe(section)}") from None
        accepted = sorted(CONFIG_FIELDS | {*TASK_FIELDS, *OPTION_FIELDS})
        for section, keys in (("set", self.fixed), ("search", self.search)):
            bad = sorted(set(keys) - set(accepted))
            hint = [k for k in bad if k in KNOWN_KWARGS]
            _check(
                not bad,
                f"{section}: unknown training field(s) {bad}; accepted: {accepted}"
                + (f" ({hint} belong under algorithm_kwargs)" if hint else ""),
            )
        for section, kwargs in (
            ("set", self.fixed.get("algorithm_kwargs", {})),
            ("search", self.search.get("algorithm_kwargs", {})),
        ):
            _check(
                isinstance(kwargs, Mapping),
                f"{section}.algorithm_kwargs: a mapping of the algorithm's arguments",
            )
        _check(
            "reward_weights" not in self.search,
            "search: put reward weights in the reward_weights section",
        )
        for key, value in _search_entries(self.search):
            _check(
                isinstance(value, list) or distribution(value) is not None,
                f"search.{key}: a list of values (grid) or {{distribution: args}}, got {value!r}",
            )
        for key, value in self.reward_weights.items():
            _check(
                isinstance(value, (int, float, list)) or distribution(value) is not None,
                f"reward_weights.{key}: a number, a list or {{distribution: args}}, got {value!r}",
            )
        self._check_configs()

    def _check_configs(self) -> None:
        """Build the config of every grid value (the low bound of each distribution) once,
        and check its algorithm's arguments, so that a bad value stops the sweep before Ray
        starts."""
        probes: list[tuple[str, dict[str, Any], dict[str, float]]] = []
        for name in self.presets:
            probes.append((name, {}, {}))
            for key, value in _search_entries(self.search):
                probes.extend((name, _nested(key, v), {}) for v in _probe_values(value))
            for key, value in self.reward_weights.items():
                probes.extend((name, {}, {key: float(v)}) for v in _probe_values(value))
        for name, search, weights in probes:
            try:
                config = build_config(name, self.fixed, search, weights)
                config.resolved_kwargs()
            except FieldError as exc:
                raise ValueError(
                    f"sweep file: preset {name!r}: {exc.describe(exc.field)}"
                ) from None
            _check(
                config.eval_every_steps > 0 and is_myoexo_env(config.env_id),
                f"preset {name!r}: a sweep ranks trials on the periodic evaluation; set "
                "eval_every_steps > 0 on a MyoExoKnee env",
            )
            _check(
                config.eval_every_steps <= config.total_timesteps,
                f"preset {name!r}: eval_every_steps = {config.eval_every_steps} exceeds "
                f"total_timesteps = {config.total_timesteps}: no evaluation to rank",
            )

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (the sweep folder's ``sweep.json``)."""
        d = dataclasses.asdict(self)
        return json.loads(json.dumps(d))


def _check(ok: bool, message: str) -> None:
    if not ok:
        raise ValueError(f"sweep file: {message}")


def _search_entries(search: Mapping[str, Any]) -> list[tuple[str, Any]]:
    """``(key, grid or distribution)`` of a search section, an algorithm argument as
    ``algorithm_kwargs.NAME``."""
    out: list[tuple[str, Any]] = []
    for key, value in search.items():
        if key == "algorithm_kwargs" and isinstance(value, Mapping):
            out += [(f"algorithm_kwargs.{k}", v) for k, v in value.items()]
        else:
            out.append((key, value))
    return out


def _nested(key: str, value: Any) -> dict[str, Any]:
    """``{key: value}``, an ``algorithm_kwargs.NAME`` key as ``{"algorithm_kwargs": {NAME:
    value}}``."""
    head, _, name = key.partition(".")
    return {head: {name: value}} if name else {key: value}


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
    """A searched value typed after its config field or algorithm argument (``field_name``)
    or as a reward weight (a number): YAML reads ``1e-4`` as text. Distributions keep their
    form; their bounds are checked by :func:`distribution`."""

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
    search: dict[str, Any] = {}
    for key, value in data.get("search", {}).items():
        if key == "algorithm_kwargs" and isinstance(value, Mapping):
            search[key] = {str(k): _coerce(v, f"algorithm_kwargs.{k}") for k, v in value.items()}
        else:
            search[str(key)] = _coerce(value, str(key))
    weights = {str(k): _coerce(v) for k, v in data.get("reward_weights", {}).items()}
    return SweepSpec(
        name=str(data.get("name", path.stem)),
        presets=tuple(str(p) for p in _as_list(data.get("preset", "cpu"))),
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
    """A sweep file's value for config field, twin option or algorithm argument ``key``
    (``algorithm_kwargs.NAME``): text typed after it (YAML reads ``1e-4`` as text), lists as
    tuples."""
    _, _, name = key.partition(".")
    if name:  # an algorithm argument
        return typed_kwarg(name, literal(value) if isinstance(value, str) else value)
    if isinstance(value, str) and TwinOptions.is_option(key):
        options = TwinOptions().with_override(f"{key}={value}")
        return dict(options.task).get(key) if key in TASK_FIELDS else getattr(options, key)
    hint = typing.get_type_hints(TrainConfig).get(key)
    if isinstance(value, str) and hint is not None and hint is not str:
        return convert(value, hint, key)
    if isinstance(value, list):
        return tuple(tuple(v) if isinstance(v, list) else v for v in value)
    return value


def build_config(
    name: str,
    fixed: Mapping[str, Any],
    search: Mapping[str, Any],
    weights: Mapping[str, float],
    seed: int = 0,
) -> TrainConfig:
    """The training config of one trial: preset ``name`` with the fixed fields, the trial's
    searched fields (``algorithm_kwargs`` of both merged into the preset's), its reward
    weights on top of any fixed ones, and its seed."""
    changes = {k: v for k, v in {**fixed, **search}.items() if k != "algorithm_kwargs"}
    kwargs = {**fixed.get("algorithm_kwargs", {}), **search.get("algorithm_kwargs", {})}
    base = fixed.get("reward_weights", {})
    if isinstance(base, str):
        base = convert(base, dict[str, float], "reward_weights")
    merged = {str(k): float(v) for k, v in (base.items() if isinstance(base, Mapping) else base)}
    merged.update({str(k): float(v) for k, v in weights.items()})
    changes["reward_weights"] = tuple(sorted(merged.items()))
    return get_preset(name, **changes, algorithm_kwargs=kwargs, seed=int(seed))


def trial_config(config: Mapping[str, Any]) -> TrainConfig:
    """The training config of a trial's resolved Tune config (its seed included)."""
    return build_config(
        config["preset"],
        config.get("set", {}),
        config["search"],
        config["reward_weights"],
        int(config["seed"]),
    )
