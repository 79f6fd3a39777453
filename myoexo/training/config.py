"""What a training run is: one :class:`TrainConfig`, and its named values, the presets
(:data:`PRESETS`: the paper's Table II ``paper``, a CPU budget ``cpu``, and ``ppo``).

A config holds the run's own fields (env, twin, envs, networks, checkpoints, evaluation,
seed) and the learning algorithm with its own keyword arguments, ``algorithm_kwargs``,
passed as they are to its class (``learning_rate``, ``buffer_size``, ``batch_size``, ...;
an argument not given keeps the class's default). Each field is an option of
``myoexo policy train`` (``--n-envs 2``, ``--algorithm-kwargs batch_size=512``), and
:meth:`TrainConfig.replace` changes any of them (twin options by their own names; the
algorithm's arguments merged)::

    config = get_preset("cpu", total_timesteps=500_000, reflex="persistent",
                        algorithm_kwargs={"batch_size": 512})

=====================  ==============  ==============  ============================================
field                  ``paper``       ``cpu``         why ``cpu`` differs
=====================  ==============  ==============  ============================================
net_arch               64-64 GELU      64-64 GELU      same networks (the shipped actor is the
                                                       paper's 93-64-64-1 shape, with our obs size)
total_timesteps        5e7             2e6             a 2-core CPU budget (2 M steps, ~2 h)
buffer_size            5e6             1e6             holds every transition of a 2 M-step run's
                                                       recent half (~1,250 episodes); ~0.6 GB
batch_size             4096            256             ~5x more gradient updates per CPU second
                                                       (126 upd/s at 256 vs 25 at 4096 measured on
                                                       one core); 256 is SAC's published default
learning_rate          1e-4            3e-4            fewer, smaller-batch updates: SAC's default
                                                       step size (Haarnoja 2018) learns faster
n_envs                 1               4               4 subjects/levels in flight decorrelate the
                                                       batch; DummyVecEnv, no IPC on 2 cores
gradient_steps/step    1 per env step  1 per 4 steps   the update budget, not the simulator, bounds
                                                       a CPU run: 0.25 update per transition
learning_starts        100             10,000          ~12 random episodes over all levels first
normalize_obs          no              yes             VecNormalize running mean/std on top of the
                                                       env's fixed O(1) scales (cuff forces and
                                                       muscle states have subject-dependent spread)
=====================  ==============  ==============  ============================================

(``buffer_size``, ``batch_size``, ``learning_rate``, ``learning_starts`` and the gradient
steps are SAC's own arguments, in ``algorithm_kwargs``.) Unchanged: Adam, tau = 0.05,
gamma = 0.99, two critics, entropy coefficient tuned automatically (SB3's ``"auto"``, target
entropy -1 for the 1-D action), tanh-squashed Gaussian actor (the paper's "tanh output").

Checkpoint cadence (both presets; ``paper``: every 1 M steps instead of 200 k): a resumable
checkpoint every ``checkpoint_every_s`` = 600 s or ``checkpoint_every_steps`` transitions,
whichever comes first; the first one ``first_checkpoint_steps`` = 1,000 transitions after
``learning_starts`` or ``first_checkpoint_s`` = 60 s into the run, whichever comes first;
the newest ``keep_resumable_checkpoints`` = 2 keep their replay buffer. A kill -9 loses at
most one interval (``docs/long_runs.md``).

A run folder records its config (``config.json``, :meth:`TrainConfig.to_dict`);
:func:`~myoexo.training.checkpoints.read_run_config` reads it back, also from a folder
written before the config held the algorithm's arguments as one mapping
(:func:`config_from_record`).
"""

from __future__ import annotations

import dataclasses
import inspect
import json
import math
import typing
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.control.residual import (
    PACE_RANGE_S,
    RESIDUAL_PENALTY_RANGE,
    RESIDUAL_SCALE_RANGE,
    ResidualConfig,
)
from myoexo.envs.options import OPTION_FIELDS, TASK_FIELDS, TwinOptions
from myoexo.policies.algorithms import ALGORITHMS, get_algorithm
from myoexo.runtime.fields import FieldError, FieldSpec, check_fields, convert, option
from myoexo.spasticity.levels import VALID_LEVELS

#: Largest ``settling_penalty`` (per control step; the study's reward terms are of order 1).
SETTLING_PENALTY_MAX = 10.0

#: Env every preset trains on (level drawn uniformly at every reset, as the paper trains).
DEFAULT_ENV_ID = "MyoExoKneeRandom-v0"

_ACTIVATIONS = ("gelu", "relu", "tanh", "elu")

#: Keyword arguments of an algorithm's class that the run sets itself (not in
#: ``algorithm_kwargs``): the networks are :attr:`TrainConfig.net_arch_pi` /
#: ``net_arch_qf`` / ``activation``, the seed is :attr:`TrainConfig.seed`.
RESERVED_KWARGS: tuple[str, ...] = (
    "policy",
    "env",
    "seed",
    "device",
    "verbose",
    "policy_kwargs",
    "tensorboard_log",
    "_init_setup_model",
)

#: The algorithm arguments the presets use: type and accepted values, checked when a config
#: is built (every argument is also checked against its class's signature when a run starts,
#: :meth:`TrainConfig.resolved_kwargs`).
KNOWN_KWARGS: dict[str, tuple[Any, FieldSpec]] = {
    "learning_rate": (float, FieldSpec("Adam step size", low=0.0, high=1.0, above=True)),
    "buffer_size": (int, FieldSpec("replay-buffer capacity (transitions)", low=1)),
    "learning_starts": (int, FieldSpec("random-policy transitions before learning", low=0)),
    "batch_size": (int, FieldSpec("transitions per gradient update", low=1)),
    "tau": (float, FieldSpec("Polyak coefficient of the targets", low=0.0, high=1.0, above=True)),
    "gamma": (float, FieldSpec("discount per 0.01-s control step", low=0.0, high=1.0)),
    "train_freq": (int, FieldSpec("vector steps between two training phases", low=1)),
    "gradient_steps": (int, FieldSpec("gradient updates per training phase", low=1)),
    "ent_coef": (float | str, FieldSpec("entropy coefficient, a number or auto[_<init>]")),
    "n_steps": (int, FieldSpec("PPO: vector steps per env in a rollout", low=1)),
    "n_epochs": (int, FieldSpec("PPO: passes over each rollout", low=1)),
    "gae_lambda": (float, FieldSpec("PPO: GAE lambda", low=0.0, high=1.0)),
    "clip_range": (float, FieldSpec("PPO: clip of the ratio", low=0.0, high=1.0, above=True)),
}

#: SAC's arguments in the presets ``cpu`` and, by default, a config of its own.
_SAC_KWARGS: dict[str, Any] = {
    "learning_rate": 3e-4,
    "buffer_size": 1_000_000,
    "learning_starts": 10_000,
    "batch_size": 256,
    "tau": 0.05,
    "gamma": 0.99,
    "train_freq": 1,
    "gradient_steps": 1,
    "ent_coef": "auto",
}


def typed_kwarg(name: str, value: Any) -> Any:
    """An ``algorithm_kwargs`` value typed and checked when its name is known
    (:data:`KNOWN_KWARGS`; text is read as the type, ``1e6`` is a whole number)."""
    if name not in KNOWN_KWARGS:
        return value
    tp, spec = KNOWN_KWARGS[name]

    def bad(accepted: str) -> FieldError:
        return FieldError("TrainConfig", "algorithm_kwargs", f"{name}={value}", accepted)

    if isinstance(value, str):
        try:
            value = convert(value, float if tp is int else tp, name)  # "1e6" for an int
        except ValueError:
            raise bad("is not a number") from None
    if isinstance(value, bool):
        raise bad("is not a number")
    if tp is int:
        if isinstance(value, float) and value.is_integer():
            value = int(value)
        if not isinstance(value, int):
            raise bad("is not a whole number")
    elif tp is float and isinstance(value, int):
        value = float(value)
    if name == "ent_coef":
        if isinstance(value, str):
            if not value.startswith("auto"):
                raise bad("is not a number >= 0 or auto[_<initial value>]")
            return value
        spec = FieldSpec(spec.doc, low=0.0)
    if not spec.ok(value):
        raise bad(spec.accepted())
    return value


@dataclass(frozen=True)
class TrainConfig:
    """Everything that defines a training run except its output folder (``config.json``).

    Each field is an option of ``myoexo policy train`` (``--total-timesteps``); the twin's
    options are their own (``--reflex``, ``--episode-duration-s``, ``--obs-preset``, ...),
    the algorithm's arguments one mapping (``--algorithm-kwargs learning_rate=3e-4``).
    """

    name: str = option("custom", "the preset the config started from (recorded)", flag="")
    seed: int = option(0, "seed of the learner (torch, numpy) and of the envs (seed + i)", low=0)
    env_id: str = option(
        DEFAULT_ENV_ID,
        "gymnasium id of the training env (its constructor takes the twin's options)",
    )
    twin: TwinOptions = option(
        doc="the twin trained on (the periodic evaluation: the same twin, nominal)",
        default_factory=TwinOptions,
        flag="",
    )
    algorithm: str = option("sac", "learning algorithm", choices=tuple(ALGORITHMS))
    algorithm_kwargs: Mapping[str, Any] = option(
        doc="the algorithm's own keyword arguments (learning_rate, buffer_size, batch_size, "
        "train_freq, gradient_steps, ...), merged into the preset's; NAME=none: the class's "
        "own value",
        default_factory=lambda: dict(_SAC_KWARGS),
    )
    total_timesteps: int = option(1_000_000, "env transitions (all envs) to train for", low=1)
    n_envs: int = option(1, "parallel envs; a vector step adds n_envs transitions", low=1)
    nominal_envs: int = option(
        0,
        "with the twin's robustness: how many of the n_envs (the last ones) train on the "
        "nominal twin, the others on perturbed twins (0: all perturbed)",
        low=0,
    )
    vec_env: str = option(
        "dummy", "envs in this process (dummy) or one process each (subproc)",
        choices=("dummy", "subproc"),
    )  # fmt: skip
    net_arch_pi: tuple[int, ...] = option((64, 64), "hidden layer widths of the actor", low=1)
    net_arch_qf: tuple[int, ...] = option(
        (64, 64), "hidden layer widths of each critic (PPO: of the value network)", low=1
    )
    activation: str = option("gelu", "hidden activation of every network", choices=_ACTIVATIONS)
    normalize_obs: bool = option(
        True, "normalize observations by their running mean and spread (VecNormalize)"
    )
    normalize_reward: bool = option(
        False, "normalize rewards by a running estimate of the return's spread (usual for PPO)"
    )
    clip_obs: float = option(10.0, "clip of the normalized observation", low=0.0, above=True)
    torch_threads: int = option(1, "torch threads of the learner", low=1)
    checkpoint_every_s: float = option(
        600.0, "wall time between two resumable checkpoints (0: no time cadence)",
        low=0.0, high=1e7, unit="s",
    )  # fmt: skip
    checkpoint_every_steps: int = option(
        200_000, "transitions between two resumable checkpoints (0: no step cadence)", low=0
    )
    first_checkpoint_steps: int = option(
        1_000, "first checkpoint this many transitions after learning_starts (0: none)", low=0
    )
    first_checkpoint_s: float = option(
        60.0, "... or this long into the first session, whichever comes first (0: none)",
        low=0.0, high=1e7, unit="s",
    )  # fmt: skip
    keep_resumable_checkpoints: int = option(
        2, "newest resumable checkpoints that keep their replay buffer", low=1
    )
    eval_every_steps: int = option(
        50_000, "transitions between two small evaluations against the PID (0: none)", low=0
    )
    eval_subjects: int = option(2, "fixed subjects per level of a small evaluation", low=1)
    eval_levels: tuple[int, ...] = option(
        VALID_LEVELS, "levels of the small evaluation", choices=VALID_LEVELS, metavar="LEVEL"
    )
    max_wall_time_s: float = option(
        0.0, "training wall-time budget, all sessions together (0: none)",
        low=0.0, high=1e7, unit="s",
    )  # fmt: skip
    residual_base: str = option(
        "",
        "residual learning: the classical controller spec the policy corrects, e.g. "
        "pid:reference=minjerk,ramp_s=0.6 (empty: the policy commands the exo on its own)",
        metavar="SPEC",
    )
    residual_scale: float = option(
        0.5, "residual learning: largest correction, a fraction of the 100 Nm motor",
        low=RESIDUAL_SCALE_RANGE[0], high=RESIDUAL_SCALE_RANGE[1], above=True,
    )  # fmt: skip
    residual_penalty: float = option(
        0.0, "residual learning: weight of the squared correction subtracted from the reward",
        low=RESIDUAL_PENALTY_RANGE[0], high=RESIDUAL_PENALTY_RANGE[1],
    )  # fmt: skip
    residual_pace_s: tuple[float, ...] = option(
        (),
        "residual learning over the gentleness range: the base's reference duration at "
        "weights 0 and 1 (FAST SLOW; the base PID's ramp_s or the impedance's duration_s, "
        "linear in the weight; none: the base spec's own)",
        low=PACE_RANGE_S[0], high=PACE_RANGE_S[1], unit="s", metavar="S",
    )  # fmt: skip

    settling_penalty: float = option(
        0.0,
        "hindsight reward: charged per control step before the episode settled (2 % band "
        "around its own final angle), once it has ended (0: none; off-policy learners only)",
        low=0.0, high=SETTLING_PENALTY_MAX,
    )  # fmt: skip
    torque_until_settling: bool = option(
        False,
        "hindsight reward: the interaction-torque terms (inter, and gentle at the episode's "
        "weight) count until the episode settled, as the study's torque measures do: they "
        "are refunded from its settling time on, once it has ended (off-policy learners only)",
    )

    def __post_init__(self) -> None:
        for name in ("net_arch_pi", "net_arch_qf", "eval_levels", "residual_pace_s"):
            value = getattr(self, name)
            if isinstance(value, (list, tuple)):
                object.__setattr__(self, name, tuple(value))
        if isinstance(self.algorithm, str):
            object.__setattr__(self, "algorithm", self.algorithm.lower())
        if not isinstance(self.twin, TwinOptions):
            raise FieldError("TrainConfig", "twin", self.twin, "is not a TwinOptions")
        if not isinstance(self.algorithm_kwargs, Mapping):
            raise FieldError(
                "TrainConfig", "algorithm_kwargs", self.algorithm_kwargs, "is not a mapping"
            )
        reserved = sorted(set(self.algorithm_kwargs) & set(RESERVED_KWARGS))
        if reserved:
            raise FieldError(
                "TrainConfig",
                "algorithm_kwargs",
                ",".join(reserved),
                "is set by the run itself (the networks: net_arch_pi, net_arch_qf, "
                "activation; the seed: seed)",
            )
        kwargs = {str(k): typed_kwarg(str(k), v) for k, v in self.algorithm_kwargs.items()}
        object.__setattr__(self, "algorithm_kwargs", kwargs)
        check_fields(self)
        if self.residual_base:
            from myoexo.control.specs import paced_base_spec, parse_classical_spec

            try:
                parse_classical_spec(self.residual_base, "residual base")
            except ValueError as exc:
                raise FieldError(
                    "TrainConfig", "residual_base", self.residual_base,
                    f"is not a classical controller spec ({exc})",
                ) from None  # fmt: skip
            if self.residual_pace_s:
                if self.twin.gentleness != "random":
                    raise FieldError(
                        "TrainConfig", "residual_pace_s", self.residual_pace_s,
                        "paces the base by the gentleness weight: train over the weight "
                        "range (gentleness random)",
                    )  # fmt: skip
                try:
                    _ = self.residual
                    paced_base_spec(self.residual_base)
                except ValueError as exc:
                    raise FieldError(
                        "TrainConfig", "residual_pace_s", self.residual_pace_s, str(exc)
                    ) from None
        elif self.residual_penalty or self.residual_pace_s:
            name = "residual_penalty" if self.residual_penalty else "residual_pace_s"
            raise FieldError(
                "TrainConfig", name, getattr(self, name),
                "shapes a correction, but no residual_base names what it corrects",
            )  # fmt: skip
        if self.nominal_envs and not self.twin.robustness:
            raise FieldError(
                "TrainConfig", "nominal_envs", self.nominal_envs,
                "shares the envs between nominal and perturbed twins: it needs the twin's "
                "robustness",
            )  # fmt: skip
        if self.nominal_envs >= self.n_envs:
            raise FieldError(
                "TrainConfig", "nominal_envs", self.nominal_envs,
                f"must be below n_envs = {self.n_envs} (at least one perturbed env)",
            )  # fmt: skip
        for name in ("net_arch_pi", "net_arch_qf", "eval_levels"):
            if not getattr(self, name):
                raise FieldError("TrainConfig", name, (), "is empty")
        for name in ("settling_penalty", "torque_until_settling"):
            if getattr(self, name) and get_algorithm(self.algorithm).on_policy:
                raise FieldError(
                    "TrainConfig", name, getattr(self, name),
                    f"rewrites stored rewards; {self.algorithm} keeps no replay buffer",
                )  # fmt: skip

    # -- changes ---------------------------------------------------------------------------
    def replace(self, **changes: Any) -> TrainConfig:
        """A copy with some fields changed: a field by its name (text is read as the field's
        type, e.g. a sweep file's ``"1e-4"``), a twin option by its own name
        (``reflex="persistent"``, ``episode_duration_s=4.0``,
        ``reward_weights="inter:-0.5"``), and ``algorithm_kwargs`` merged into this
        config's (a mapping, or ``"NAME=VALUE,..."`` text; a ``None`` value drops an
        argument: the class's default).

        Raises:
            ValueError: An unknown name (an algorithm argument given as a field is named
                as such) or a value the field does not accept (:class:`FieldError`).
        """
        names = {f.name for f in dataclasses.fields(TrainConfig)}
        twin_changes = {
            k: changes.pop(k) for k in list(changes) if k not in names and TwinOptions.is_option(k)
        }
        unknown = sorted(set(changes) - names)
        if unknown:
            hint = [k for k in unknown if k in KNOWN_KWARGS]
            more = (
                f"; {hint} belong to the algorithm: algorithm_kwargs={{{hint[0]!r}: ...}} "
                f"(command line: --algorithm-kwargs {hint[0]}=...)"
                if hint
                else ""
            )
            raise ValueError(
                f"unknown training field(s) {unknown}; accepted: {sorted(names - {'twin'})} "
                f"and the twin's options {[*TASK_FIELDS, *OPTION_FIELDS]}{more}"
            )
        hints = typing.get_type_hints(TrainConfig)
        values: dict[str, Any] = {}
        for name, value in changes.items():
            if name == "algorithm_kwargs":
                if isinstance(value, str):
                    value = convert(value, Mapping[str, Any], name)
                merged = {**self.algorithm_kwargs, **dict(value)}
                value = {k: v for k, v in merged.items() if v is not None}
            elif name == "twin":
                value = value if isinstance(value, TwinOptions) else TwinOptions.from_dict(value)
            elif isinstance(value, str) and hints[name] is not str:
                value = convert(value, hints[name], name)
            elif isinstance(value, list):
                value = tuple(value)
            values[name] = value
        twin: TwinOptions = values.pop("twin", self.twin)
        for name, value in twin_changes.items():
            if isinstance(value, str):
                twin = twin.with_override(f"{name}={value}")
            else:
                twin = twin.replace(**{name: value})
        return dataclasses.replace(self, twin=twin, **values)

    # -- the algorithm ---------------------------------------------------------------------
    def resolved_kwargs(self) -> dict[str, Any]:
        """Every keyword argument the algorithm's class gets besides those the run sets
        (:data:`RESERVED_KWARGS`): its defaults, overridden by ``algorithm_kwargs``. Loads
        the class (``ValueError`` naming the extra to install if it is missing).

        Raises:
            FieldError: An argument the class does not take, or arguments that do not fit
                together (a batch larger than the replay buffer or than a PPO rollout; a
                learned entropy coefficient for PPO).
        """
        algorithm = get_algorithm(self.algorithm)
        cls = algorithm.load_class()
        params = inspect.signature(cls.__init__).parameters
        kinds = (inspect.Parameter.POSITIONAL_OR_KEYWORD, inspect.Parameter.KEYWORD_ONLY)
        takes = [
            n for n, p in params.items() if p.kind in kinds and n not in ("self", *RESERVED_KWARGS)
        ]
        unknown = sorted(set(self.algorithm_kwargs) - set(takes))
        if unknown:
            raise FieldError(
                "TrainConfig",
                "algorithm_kwargs",
                ",".join(unknown),
                f"is not an argument of {algorithm.name} ({algorithm.package}.{cls.__name__}; "
                f"NAME=none drops one): its arguments are {', '.join(takes)}",
            )
        resolved = {n: params[n].default for n in takes if params[n].default is not params[n].empty}
        resolved.update(self.algorithm_kwargs)

        def clash(value: str, accepted: str) -> FieldError:
            return FieldError("TrainConfig", "algorithm_kwargs", value, accepted)

        batch = int(resolved.get("batch_size", 1))
        if algorithm.on_policy:
            if isinstance(resolved.get("ent_coef"), str):
                raise clash(
                    f"ent_coef={resolved['ent_coef']}",
                    f"is not a number: {algorithm.name} learns no entropy coefficient",
                )
            rollout = int(resolved["n_steps"]) * self.n_envs
            if batch > rollout:
                raise clash(
                    f"batch_size={batch}",
                    f"exceeds a rollout of n_steps * n_envs = {rollout} transitions",
                )
        elif "buffer_size" in resolved and batch > int(resolved["buffer_size"]):
            raise clash(f"batch_size={batch}", f"exceeds buffer_size = {resolved['buffer_size']}")
        return resolved

    def updates_per_transition(self, resolved: Mapping[str, Any] | None = None) -> float:
        """Gradient updates per env transition: off-policy ``gradient_steps / (train_freq *
        n_envs)``; PPO ``n_epochs * ceil(rollout / batch_size) / rollout``."""
        kw = self.resolved_kwargs() if resolved is None else resolved
        if get_algorithm(self.algorithm).on_policy:
            rollout = int(kw["n_steps"]) * self.n_envs
            return int(kw["n_epochs"]) * math.ceil(rollout / int(kw["batch_size"])) / rollout
        return float(kw["gradient_steps"]) / (int(kw["train_freq"]) * self.n_envs)

    @property
    def residual(self) -> ResidualConfig | None:
        """The residual record of a policy that corrects a classical controller
        (:class:`~myoexo.control.residual.ResidualConfig`), ``None`` without one."""
        if not self.residual_base:
            return None
        return ResidualConfig(
            base=self.residual_base,
            scale=self.residual_scale,
            penalty=self.residual_penalty,
            pace_s=tuple(self.residual_pace_s) if self.residual_pace_s else None,  # type: ignore[arg-type]
        )

    # -- records ---------------------------------------------------------------------------
    def training_envs(self) -> dict[str, int]:
        """How the training envs are shared between the twins, as a policy records it
        (:data:`~myoexo.control.specs.TRAINING_ENVS_KEY`): ``n_envs`` and ``nominal_envs``."""
        return {"n_envs": self.n_envs, "nominal_envs": self.nominal_envs}

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready field -> value (the twin as :meth:`TwinOptions.to_dict`)."""
        d: dict[str, Any] = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["twin"] = self.twin.to_dict()
        d["algorithm_kwargs"] = dict(self.algorithm_kwargs)
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = list(v)
        return d

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TrainConfig:
        """Rebuild a config from :meth:`to_dict`; unknown keys raise ``ValueError``."""
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ValueError(f"training config has unknown key(s) {unknown}")
        kwargs = dict(data)
        if isinstance(kwargs.get("twin"), Mapping):
            kwargs["twin"] = TwinOptions.from_dict(kwargs["twin"])
        return cls(**kwargs)


#: The named configs (``myoexo policy train --preset NAME``).
PRESETS: dict[str, TrainConfig] = {
    # the paper's Table II, exactly: actor 64-64 GELU with tanh-squashed Gaussian output, two
    # critics 64-64 GELU, replay 5e6, 5e7 steps, Adam lr 1e-4, tau 0.05, batch 4096, gamma
    # 0.99; what the paper does not give keeps SAC's and SB3's defaults: one env, one update
    # per env step, entropy coefficient learned, 100 random steps, raw observations (the
    # env's fixed scales make them O(1)). ~25 updates/s on one core: a GPU-cluster budget
    "paper": TrainConfig(
        name="paper",
        total_timesteps=50_000_000,
        n_envs=1,
        normalize_obs=False,
        checkpoint_every_steps=1_000_000,
        eval_every_steps=500_000,
        algorithm_kwargs={
            **_SAC_KWARGS,
            "learning_rate": 1e-4,
            "buffer_size": 5_000_000,
            "batch_size": 4096,
            "learning_starts": 100,
        },
    ),
    # Table II for a 2-core CPU (the table above): a policy beating the PID within 2 M env
    # steps, ~2 h; checkpoints every 10 min or 200 k steps, a small evaluation (2 fixed
    # subjects x 4 levels against the PID) every 50 k steps
    "cpu": TrainConfig(name="cpu", total_timesteps=2_000_000, n_envs=4),
    # SB3's PPO with many envs, the way simulation-bound exoskeleton controllers are trained
    # (MyoAssist; Luo et al. 2024): the networks and normalization of cpu; 16 envs in one
    # process, rollouts of 256 steps per env (4,096 transitions), 10 epochs over minibatches
    # of 512 (0.02 update per transition), GAE lambda 0.95, clip 0.2, no entropy bonus,
    # rewards normalized
    "ppo": TrainConfig(
        name="ppo",
        algorithm="ppo",
        total_timesteps=2_000_000,
        n_envs=16,
        normalize_reward=True,
        algorithm_kwargs={
            "learning_rate": 3e-4,
            "n_steps": 256,
            "batch_size": 512,
            "n_epochs": 10,
            "gamma": 0.99,
            "gae_lambda": 0.95,
            "clip_range": 0.2,
            "ent_coef": 0.0,
        },
    ),
}


def get_preset(name: str, **changes: Any) -> TrainConfig:
    """The preset ``name`` (:data:`PRESETS`) with *changes* (:meth:`TrainConfig.replace`:
    fields, twin options by their own names, ``algorithm_kwargs`` merged)::

        get_preset("cpu", reflex="persistent", algorithm_kwargs={"batch_size": 512})

    Raises:
        ValueError: Unknown preset, field or option, or a value out of range.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; accepted: {sorted(PRESETS)}")
    return PRESETS[name].replace(**changes) if changes else PRESETS[name]


# ----------------------------------------------------------------------------- saved configs
#: The algorithm arguments that a record written before ``algorithm_kwargs`` (a *preset*
#: record: every argument a field of its own) passed to its class, with the values an older
#: record that lacks one had.
_PRESET_RECORD_KWARGS: dict[bool, dict[str, Any]] = {
    False: dict(_SAC_KWARGS),  # off-policy (CrossQ: no tau)
    True: {  # on-policy
        "learning_rate": 3e-4,
        "n_steps": 256,
        "batch_size": 256,
        "n_epochs": 10,
        "gamma": 0.99,
        "gae_lambda": 0.95,
        "clip_range": 0.2,
        "ent_coef": 0.0,
    },
}


def _recorded_algorithm(name: Any) -> Any:
    """The :class:`~myoexo.policies.algorithms.Algorithm` an earlier record names; a clear
    ``ValueError`` for one this version no longer trains."""
    algorithm = str(name).lower()
    if algorithm not in ALGORITHMS:
        raise ValueError(
            f"this run was trained with algorithm {algorithm!r}, which myoexo no longer trains "
            f"(sb3-contrib's TQC and CrossQ are gone: their SBX versions are sbx_tqc and "
            f"sbx_crossq); accepted: {sorted(ALGORITHMS)}"
        )
    return get_algorithm(algorithm)


def _recorded_kwargs(algorithm: Any, values: Mapping[str, Any], base: Mapping[str, Any]) -> dict:
    """The arguments an earlier record's *algorithm* was given: of the preset fields in
    *values* (else *base*), those its kind of learner took (CrossQ: no ``tau``)."""
    used = _PRESET_RECORD_KWARGS[algorithm.on_policy]
    kwargs = {k: values.get(k, base.get(k, v)) for k, v in used.items()}
    if algorithm.class_name == "CrossQ":
        kwargs.pop("tau")
    return kwargs


def _from_preset_record(record: Mapping[str, Any], seed: Any) -> TrainConfig:
    """The config of a run written when every algorithm argument was a preset field."""
    record = dict(record)
    known = _recorded_algorithm(record.get("algorithm", "sac"))
    kwargs = _recorded_kwargs(known, record, {})
    if isinstance(record.get("twin"), Mapping):
        twin = TwinOptions.from_dict(record["twin"])
    else:  # written before the twin record: its observation and reward fields
        twin = TwinOptions(
            obs_preset=str(record.get("obs_preset") or "full"),
            reward_weights=tuple(tuple(p) for p in record.get("reward_weights") or ()),
        )
    base = PRESETS.get(str(record.get("name")), TrainConfig())
    names = {f.name for f in dataclasses.fields(TrainConfig)}
    run = {
        k: v for k, v in record.items() if k in names - {"twin", "algorithm", "algorithm_kwargs"}
    }
    if seed is not None:
        run["seed"] = int(seed)
    return dataclasses.replace(
        base, **run, twin=twin, algorithm=known.name, algorithm_kwargs=kwargs
    )


#: The keys under which a JSON record holds a training config (:func:`config_from_record`):
#: ``"config"``, and ``"preset"`` in a record of an earlier version.
RECORD_KEYS: tuple[str, ...] = ("config", "preset")


def config_from_record(record: Mapping[str, Any]) -> TrainConfig:
    """The config a JSON record holds: a run's ``config.json`` (``"config"``; a run written
    before ``algorithm_kwargs``: ``"preset"``, its algorithm arguments gathered into the
    mapping) or a seeds folder's ``seeds.json`` (``"config"``; an older one: a preset name
    and its ``--set`` items).

    Raises:
        ValueError: The record holds no config, or one this version cannot run.
    """
    if isinstance(record.get("config"), Mapping):
        return TrainConfig.from_dict(record["config"])
    preset = record.get("preset")
    if isinstance(preset, Mapping):
        return _from_preset_record(preset, record.get("seed"))
    if isinstance(preset, str):  # an older seeds.json: preset name + NAME=VALUE items
        from myoexo.runtime.fields import parse_assignments

        changes = parse_assignments(record.get("set") or [], "setting")
        names = {*_PRESET_RECORD_KWARGS[False], *_PRESET_RECORD_KWARGS[True]}
        values = {k: changes.pop(k) for k in list(changes) if k in names}
        known = _recorded_algorithm(changes.pop("algorithm", get_preset(preset).algorithm))
        config = get_preset(preset, **changes)
        kwargs = _recorded_kwargs(known, values, config.algorithm_kwargs)
        return dataclasses.replace(config, algorithm=known.name, algorithm_kwargs=kwargs)
    raise ValueError("the record holds no training config ('config' or 'preset')")


def read_config_file(path: str | Path) -> TrainConfig:
    """The config of a JSON file (:func:`config_from_record`): a run's ``config.json`` or a
    seeds folder's ``seeds.json``."""
    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{str(path)!r} does not exist")
    try:
        record = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise ValueError(f"{str(path)!r} is not JSON ({exc})") from None
    if not isinstance(record, Mapping):
        raise ValueError(f"{str(path)!r} holds no training config")
    return config_from_record(record)
