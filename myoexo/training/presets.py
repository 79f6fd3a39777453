"""SAC hyper-parameter presets: the paper's Table II (``paper``) and a CPU budget (``cpu``).

A preset is a frozen dataclass; every field has a unit or a meaning in its docstring and the
class's default is the preset. :func:`get_preset` builds one by name with overrides
(``get_preset("cpu", total_timesteps=500_000)``), validating every value.

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

Unchanged: Adam, tau = 0.05, gamma = 0.99, two critics, entropy coefficient tuned
automatically (SB3's ``"auto"``, target entropy -1 for the 1-D action), tanh-squashed
Gaussian actor (the paper's "tanh output").

Checkpoint cadence (both presets; ``paper``: every 1 M steps instead of 200 k): a resumable
checkpoint every ``checkpoint_every_s`` = 600 s or ``checkpoint_every_steps`` transitions,
whichever comes first; the first one ``first_checkpoint_steps`` = 1,000 transitions after
``learning_starts`` or ``first_checkpoint_s`` = 60 s into the run, whichever comes first;
the newest ``keep_resumable_checkpoints`` = 2 keep their replay buffer. A kill -9 loses at
most one interval (``docs/long_runs.md``).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, ClassVar

from myoexo.envs.options import OPTION_FIELDS, TASK_FIELDS, TwinOptions
from myoexo.policies.algorithms import get_algorithm
from myoexo.spasticity.levels import VALID_LEVELS

#: Env every preset trains on (level drawn uniformly at every reset, as the paper trains).
DEFAULT_ENV_ID = "MyoExoKneeRandom-v0"

_VEC_ENVS = ("dummy", "subproc")
_ACTIVATIONS = ("gelu", "relu", "tanh", "elu")


@dataclass(frozen=True)
class SACPreset:
    """Everything that defines a SAC training run except the seed and the output folder.

    Attributes:
        name: Preset name (recorded in the run config).
        env_id: Gymnasium id of the training env (any id whose constructor takes the
            options of *twin*).
        twin: The twin trained on (:class:`~myoexo.envs.options.TwinOptions`: task, e.g.
            ``episode_duration_s``; reward weights; observation preset or keys; reflex
            model; robustness, a perturbed twin per episode). The periodic evaluation runs
            on the same twin without its robustness (the nominal twin). :func:`get_preset`
            and ``--set`` take each option by its own name (``reflex=persistent``).
        total_timesteps: Env transitions (all envs together) to train for.
        n_envs: Parallel envs; each vector step adds ``n_envs`` transitions.
        vec_env: ``"dummy"`` (envs in this process) or ``"subproc"`` (one process each).
        buffer_size: Replay-buffer capacity (transitions).
        batch_size: Transitions per gradient update.
        learning_rate: Adam step size of actor, critics and entropy coefficient.
        tau: Polyak coefficient of the target critics.
        gamma: Discount per control step (0.01 s): 0.99 is a 1-s horizon.
        train_freq: Vector steps between two training phases.
        gradient_steps: Gradient updates per training phase.
        learning_starts: Transitions collected with a random policy before learning.
        net_arch_pi: Hidden layer widths of the actor.
        net_arch_qf: Hidden layer widths of each critic.
        activation: Hidden activation (``gelu`` in the paper).
        ent_coef: Entropy coefficient, a float or ``"auto"`` (learned).
        normalize_obs: Wrap the envs in SB3's ``VecNormalize`` (observations only; off-policy
            SAC keeps raw rewards).
        clip_obs: Clip of the normalized observation (``VecNormalize.clip_obs``).
        torch_threads: ``torch.set_num_threads`` of the learner.
        checkpoint_every_s: Wall time (s) between two resumable checkpoints (model, replay
            buffer, normalization statistics, step counter); 0: no time-based cadence.
        checkpoint_every_steps: Transitions between two resumable checkpoints (0: no
            step-based cadence). With both cadences, whichever comes first.
        first_checkpoint_steps: The first resumable checkpoint of a run comes once
            ``learning_starts + first_checkpoint_steps`` transitions are collected (0: no
            early first checkpoint) ...
        first_checkpoint_s: ... or after this wall time (s) of its first session, whichever
            comes first (0: none), so that a run killed early does not start from scratch.
            Each applies only with its cadence on (``checkpoint_every_steps`` /
            ``checkpoint_every_s`` > 0).
        keep_resumable_checkpoints: Newest resumable checkpoints that keep their replay
            buffer (older ones become policy snapshots); with 2, a damaged newest checkpoint
            falls back to the previous one.
        eval_every_steps: Transitions between two small evaluations (0: none).
        eval_subjects: Fixed subjects per level in each small evaluation.
        eval_levels: Levels of the small evaluation.
        algorithm: ``"sac"`` (stable-baselines3), or from sb3-contrib (the ``contrib``
            extra) ``"tqc"`` (truncated quantile critics, Kuznetsov 2020) or ``"crossq"``
            (batch-renormalized critics without target networks, Bhatt 2024; ``tau`` is not
            used); SBX's ``"sbx_sac"``, ``"sbx_tqc"``, ``"sbx_crossq"`` (the ``jax`` extra);
            or the on-policy ``"ppo"`` (stable-baselines3; ``buffer_size``, ``tau``,
            ``train_freq``, ``gradient_steps`` and ``learning_starts`` are not used,
            ``net_arch_qf`` is its value network, ``batch_size`` its minibatch).
        n_steps: PPO: vector steps per env in one rollout (a rollout is ``n_steps * n_envs``
            transitions).
        n_epochs: PPO: passes over each rollout.
        gae_lambda: PPO: the GAE(lambda) bias-variance trade-off.
        clip_range: PPO: the clip of the probability ratio.
        normalize_reward: Also normalize rewards by a running estimate of the return's
            spread (``VecNormalize(norm_reward=True)``: usual for PPO, not for SAC).
        max_wall_time_s: Training wall-time budget (s, all sessions together; 0: none): the
            run ends at ``total_timesteps`` or at this wall time, whichever comes first, with a
            resumable checkpoint (runs compared on the same wall-clock budget).
    """

    name: str = "custom"
    env_id: str = DEFAULT_ENV_ID
    twin: TwinOptions = field(default_factory=TwinOptions)
    total_timesteps: int = 1_000_000
    n_envs: int = 1
    vec_env: str = "dummy"
    buffer_size: int = 1_000_000
    batch_size: int = 256
    learning_rate: float = 3e-4
    tau: float = 0.05
    gamma: float = 0.99
    train_freq: int = 1
    gradient_steps: int = 1
    learning_starts: int = 10_000
    net_arch_pi: tuple[int, ...] = (64, 64)
    net_arch_qf: tuple[int, ...] = (64, 64)
    activation: str = "gelu"
    ent_coef: str | float = "auto"
    normalize_obs: bool = True
    clip_obs: float = 10.0
    torch_threads: int = 1
    checkpoint_every_s: float = 600.0
    checkpoint_every_steps: int = 200_000
    first_checkpoint_steps: int = 1_000
    first_checkpoint_s: float = 60.0
    keep_resumable_checkpoints: int = 2
    eval_every_steps: int = 50_000
    eval_subjects: int = 2
    eval_levels: tuple[int, ...] = VALID_LEVELS
    algorithm: str = "sac"
    n_steps: int = 256
    n_epochs: int = 10
    gae_lambda: float = 0.95
    clip_range: float = 0.2
    normalize_reward: bool = False
    max_wall_time_s: float = 0.0

    _POSITIVE_INTS: ClassVar[tuple[str, ...]] = (
        "total_timesteps",
        "n_envs",
        "buffer_size",
        "batch_size",
        "train_freq",
        "gradient_steps",
        "torch_threads",
        "eval_subjects",
        "keep_resumable_checkpoints",
        "n_steps",
        "n_epochs",
    )

    def __post_init__(self) -> None:
        for f in ("net_arch_pi", "net_arch_qf", "eval_levels"):
            object.__setattr__(self, f, tuple(int(v) for v in getattr(self, f)))
        if not isinstance(self.twin, TwinOptions):
            raise ValueError(f"twin = {self.twin!r}: expected TwinOptions")
        for f in self._POSITIVE_INTS:
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int) or v <= 0:
                raise ValueError(f"{f} = {v!r} must be a positive integer")
        for f in (
            "learning_starts",
            "checkpoint_every_steps",
            "first_checkpoint_steps",
            "eval_every_steps",
        ):
            v = getattr(self, f)
            if isinstance(v, bool) or not isinstance(v, int) or v < 0:
                raise ValueError(f"{f} = {v!r} must be an integer >= 0")
        _check_float("learning_rate", self.learning_rate, 0.0, 1.0, low_open=True)
        _check_float("tau", self.tau, 0.0, 1.0, low_open=True)
        _check_float("gamma", self.gamma, 0.0, 1.0, high_open=True)
        _check_float("clip_obs", self.clip_obs, 0.0, 1e6, low_open=True)
        _check_float("checkpoint_every_s", self.checkpoint_every_s, 0.0, 1e7)
        _check_float("first_checkpoint_s", self.first_checkpoint_s, 0.0, 1e7)
        _check_float("gae_lambda", self.gae_lambda, 0.0, 1.0)
        _check_float("clip_range", self.clip_range, 0.0, 1.0, low_open=True)
        _check_float("max_wall_time_s", self.max_wall_time_s, 0.0, 1e7)
        algorithm = get_algorithm(self.algorithm, trainable=True)  # names the accepted ones
        if self.batch_size > self.buffer_size and not algorithm.on_policy:
            raise ValueError(
                f"batch_size = {self.batch_size} exceeds buffer_size = {self.buffer_size}"
            )
        if algorithm.on_policy:
            if isinstance(self.ent_coef, str):
                raise ValueError(
                    f"ent_coef = {self.ent_coef!r}: {self.algorithm} needs a float >= 0 (no "
                    "learned entropy coefficient)"
                )
            if self.batch_size > self.n_steps * self.n_envs:
                raise ValueError(
                    f"batch_size = {self.batch_size} exceeds a rollout of n_steps * n_envs = "
                    f"{self.n_steps * self.n_envs} transitions"
                )
        if self.vec_env not in _VEC_ENVS:
            raise ValueError(f"vec_env = {self.vec_env!r}; accepted: {_VEC_ENVS}")
        if self.activation not in _ACTIVATIONS:
            raise ValueError(f"activation = {self.activation!r}; accepted: {_ACTIVATIONS}")
        if (
            not self.net_arch_pi
            or not self.net_arch_qf
            or min(self.net_arch_pi + self.net_arch_qf) <= 0
        ):
            raise ValueError(
                f"net_arch_pi = {self.net_arch_pi}, net_arch_qf = {self.net_arch_qf}: "
                "need at least one hidden layer of positive width"
            )
        if isinstance(self.ent_coef, str):
            if not self.ent_coef.startswith("auto"):
                raise ValueError(f"ent_coef = {self.ent_coef!r}: a float > 0 or 'auto[_<init>]'")
        else:
            _check_float(
                "ent_coef", float(self.ent_coef), 0.0, 1e3, low_open=not algorithm.on_policy
            )
        bad = [v for v in self.eval_levels if v not in VALID_LEVELS]
        if bad:
            raise ValueError(f"eval_levels has unknown level(s) {bad}; accepted: {VALID_LEVELS}")

    @property
    def updates_per_transition(self) -> float:
        """Gradient updates per env transition: ``gradient_steps / (train_freq * n_envs)``."""
        return self.gradient_steps / (self.train_freq * self.n_envs)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready field -> value (the twin as :meth:`TwinOptions.to_dict`)."""
        d = {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}
        d["twin"] = self.twin.to_dict()
        for k, v in d.items():
            if isinstance(v, tuple):
                d[k] = [list(x) if isinstance(x, tuple) else x for x in v]
        return d


@dataclass(frozen=True)
class PaperPreset(SACPreset):
    """The paper's Table II, exactly.

    Actor 64-64 GELU with tanh-squashed Gaussian output, two critics 64-64 GELU, replay
    5e6, 5e7 steps, Adam lr 1e-4, tau 0.05, batch 4096, gamma 0.99. What the paper does not
    give keeps SAC's (Haarnoja 2018) and SB3's defaults: one env, one gradient update per
    env step, entropy coefficient learned, 100 random steps before learning, raw
    observations (the env's fixed scales already make them O(1)). On one CPU core this is
    ~25 updates/s: a GPU-cluster budget, recorded for reproducibility.
    """

    name: str = "paper"
    total_timesteps: int = 50_000_000
    n_envs: int = 1
    buffer_size: int = 5_000_000
    batch_size: int = 4096
    learning_rate: float = 1e-4
    tau: float = 0.05
    gamma: float = 0.99
    train_freq: int = 1
    gradient_steps: int = 1
    learning_starts: int = 100
    normalize_obs: bool = False
    checkpoint_every_steps: int = 1_000_000
    eval_every_steps: int = 500_000


@dataclass(frozen=True)
class CpuPreset(SACPreset):
    """Table II tuned for a 2-core CPU: a policy beating the PID within 2 M env steps, ~2 h.

    Changes from :class:`PaperPreset`, each for the update budget of a CPU (SB3 SAC, 64-64
    GELU, one torch thread: ~126 gradient updates/s at batch 256, ~25 at 4096):

    * ``batch_size`` 4096 -> 256: five times more updates per second; SAC's published
      default, ample for a 1-D action.
    * ``learning_rate`` 1e-4 -> 3e-4: with ~20x fewer updates than the paper, SAC's default
      step size.
    * ``n_envs`` 1 -> 4 (``DummyVecEnv``: no inter-process traffic on a shared 2-core
      machine) and ``gradient_steps`` / ``train_freq`` = 1 / 1: 0.25 update per transition,
      so 2 M steps cost 500 k updates (~70 min) and the simulator gets the rest.
    * ``buffer_size`` 5e6 -> 1e6 (~0.6 GB of float32 observations): the last 1,250
      episodes, over 300 per level.
    * ``learning_starts`` 100 -> 10,000: a dozen random episodes spread over the four
      levels before the first update.
    * ``normalize_obs``: running mean/std normalization (``VecNormalize``, clip 10) on top of
      the env's fixed scales; the statistics ship with the actor.
    * Checkpoints every 10 min or 200 k steps, whichever comes first (the first one 1 k steps
      after ``learning_starts`` or after 60 s), the last two with their replay buffer, and
      a small evaluation (2 fixed subjects x 4 levels against the PID) every 50 k steps.
    """

    name: str = "cpu"
    total_timesteps: int = 2_000_000
    n_envs: int = 4
    buffer_size: int = 1_000_000
    batch_size: int = 256
    learning_rate: float = 3e-4
    train_freq: int = 1
    gradient_steps: int = 1
    learning_starts: int = 10_000
    normalize_obs: bool = True
    checkpoint_every_s: float = 600.0
    eval_every_steps: int = 50_000
    eval_subjects: int = 2


@dataclass(frozen=True)
class PPOPreset(CpuPreset):
    """SB3's PPO with many envs, the way simulation-bound exoskeleton controllers are trained
    (MyoAssist; Luo et al. 2024): the same networks as ``cpu`` (actor 64-64 GELU, value
    network 64-64 GELU), observations normalized as there.

    * ``n_envs`` 16 in one process (``DummyVecEnv``), rollouts of ``n_steps`` = 256 per env:
      4,096 transitions (5 episodes' worth) per update phase.
    * ``n_epochs`` 10 over minibatches of ``batch_size`` = 512: 80 gradient updates per
      rollout, 0.02 per transition (SAC's ``cpu`` preset: 0.25).
    * SB3's PPO defaults otherwise: lr 3e-4, GAE lambda 0.95, clip 0.2, gamma 0.99 (the
      SAC presets' 1-s horizon), no entropy bonus (``ent_coef`` 0); rewards normalized
      (``normalize_reward``) as PPO expects.
    """

    name: str = "ppo"
    algorithm: str = "ppo"
    n_envs: int = 16
    n_steps: int = 256
    n_epochs: int = 10
    batch_size: int = 512
    ent_coef: str | float = 0.0
    normalize_reward: bool = True


#: Preset name -> class (its defaults are the preset).
PRESETS: dict[str, type[SACPreset]] = {"paper": PaperPreset, "cpu": CpuPreset, "ppo": PPOPreset}


def _with_twin_options(overrides: dict[str, Any]) -> dict[str, Any]:
    """*overrides* with the twin options given by their own names (``reflex="persistent"``,
    ``episode_duration_s=4.0``, ...) folded into ``twin``."""
    names = [k for k in overrides if TwinOptions.is_option(k)]
    if not names:
        return overrides
    rest = {k: v for k, v in overrides.items() if k not in names}
    twin = rest.get("twin", TwinOptions())
    twin = twin if isinstance(twin, TwinOptions) else TwinOptions.from_dict(twin)
    rest["twin"] = twin.replace(**{k: overrides[k] for k in names})
    return rest


def get_preset(name: str, **overrides: Any) -> SACPreset:
    """The preset ``name`` (``"paper"``, ``"cpu"`` or ``"ppo"``) with some fields replaced;
    a twin option given by its own name replaces that option of ``twin``
    (``get_preset("cpu", reflex="persistent", episode_duration_s=4.0)``).

    Raises:
        ValueError: Unknown preset, field or option, or a value out of range.
    """
    if name not in PRESETS:
        raise ValueError(f"unknown preset {name!r}; accepted: {sorted(PRESETS)}")
    cls = PRESETS[name]
    overrides = _with_twin_options(dict(overrides))
    fields = {f.name for f in dataclasses.fields(cls)}
    unknown = sorted(set(overrides) - fields)
    if unknown:
        raise ValueError(
            f"unknown preset field(s) {unknown}; accepted: {sorted(fields)} and the twin's "
            f"options {[*TASK_FIELDS, *OPTION_FIELDS]}"
        )
    return cls(**overrides)


def preset_from_dict(data: dict[str, Any]) -> SACPreset:
    """Rebuild a preset from :meth:`SACPreset.to_dict` (e.g. a run's ``config.json``)."""
    data = dict(data)
    name = data.get("name", "custom")
    cls = PRESETS.get(name, SACPreset)
    fields = {f.name for f in dataclasses.fields(cls)}
    kwargs = {k: v for k, v in data.items() if k in fields}
    if isinstance(kwargs.get("twin"), dict):
        kwargs["twin"] = TwinOptions.from_dict(kwargs["twin"])
    return cls(**kwargs)


def apply_overrides(preset: SACPreset, texts: Sequence[str]) -> SACPreset:
    """*preset* with each ``FIELD=VALUE`` of the command line (``--set``) applied: a preset
    field (:func:`parse_override`) or a twin option by its own name
    (:meth:`TwinOptions.with_override`: ``reflex=persistent``, ``episode_duration_s=4``,
    ``robustness=true``, ``reward_weights=inter:-0.5``, ``obs_preset=exo``).

    Raises:
        ValueError: A malformed override, an unknown name or a bad value.
    """
    twin = preset.twin
    fields: dict[str, Any] = {}
    for text in texts:
        key = text.partition("=")[0].strip()
        if TwinOptions.is_option(key):
            twin = twin.with_override(text)
        else:
            name, value = parse_override(text)
            fields[name] = value
    return dataclasses.replace(preset, twin=twin, **fields)


def parse_override(text: str) -> tuple[str, Any]:
    """``"field=value"`` -> ``(field, typed value)``, typed after the field's default."""
    key, eq, raw = text.partition("=")
    key = key.strip()
    fields = {f.name: f for f in dataclasses.fields(SACPreset) if f.name != "twin"}
    if not eq or key not in fields:
        raise ValueError(
            f"bad override {text!r}: expected FIELD=VALUE with FIELD in {sorted(fields)} or a "
            f"twin option in {[*TASK_FIELDS, *OPTION_FIELDS]}"
        )
    default = getattr(SACPreset(), key)
    raw = raw.strip()
    try:
        if key == "ent_coef":
            value: Any = raw if raw.startswith("auto") else float(raw)
        elif isinstance(default, bool):
            if raw.lower() not in ("true", "false", "1", "0"):
                raise ValueError(raw)
            value = raw.lower() in ("true", "1")
        elif isinstance(default, int):
            value = int(float(raw))
        elif isinstance(default, float):
            value = float(raw)
        elif isinstance(default, tuple):
            value = tuple(int(v) for v in raw.replace("-", ",").split(",") if v)
        else:
            value = raw
    except ValueError:
        raise ValueError(f"bad value in override {text!r} for field {key!r}") from None
    return key, value


def _check_float(
    name: str, value: float, low: float, high: float, low_open: bool = False, high_open=False
) -> None:
    ok = math.isfinite(value) and (value > low if low_open else value >= low)
    ok = ok and (value < high if high_open else value <= high)
    if not ok:
        lo, hi = "(" if low_open else "[", ")" if high_open else "]"
        raise ValueError(f"{name} = {value!r} is outside the accepted range {lo}{low}, {high}{hi}")
