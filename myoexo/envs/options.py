"""One record of the twin's options: :class:`TwinOptions`.

Everything that makes one MyoExoKnee twin differ from another, beyond its level and its
subject, is one frozen, JSON-able value: the task (any :class:`~myoexo.envs.config.TaskParams`
field), the reward weights, the observation (a preset or explicit keys), the reflex model
(a registered name, :mod:`myoexo.spasticity.registry`) and robustness (a perturbed twin
per episode). It is built once, from the command line (one option per field:
``--reflex persistent --episode-duration-s 4``) or from a preset, and carried unchanged by
training, evaluation, distillation, sweeps and the frontier; every run folder and every
shipped policy records it (:meth:`TwinOptions.to_dict`),
and a policy's env is rebuilt from it (:meth:`TwinOptions.env_kwargs`)::

    options = TwinOptions.from_overrides(["reflex=persistent", "episode_duration_s=4"])
    env = make_env(2, **options.env_kwargs())

Each option has one name everywhere: the field names below, and the task's own field names
(``episode_duration_s``, ``target_angle_deg``, ...). The options apply to any env id whose
constructor takes them (no check on the id's name).
"""

from __future__ import annotations

import dataclasses
import typing
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from myoexo.envs.config import (
    DEFAULT_REWARD_WEIGHTS,
    TASK_FIELDS,
    TaskParams,
    check_gentleness,
)
from myoexo.envs.observation import OBS_PRESETS
from myoexo.runtime.fields import (
    add_options,
    convert,
    option,
    option_text,
    option_words,
    parse_assignments,
)
from myoexo.runtime.files import file_sha256
from myoexo.spasticity.personal import PersonalSubject, load_subject
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import get_reflex, reflex_parameters

#: Names of the options that are not task fields.
OPTION_FIELDS: tuple[str, ...] = (
    "reward_weights",
    "obs_preset",
    "obs_keys",
    "reflex",
    "robustness",
    "gentleness",
    "subject",
)

#: The options that change the twin's dynamics or task (what a policy is evaluated on);
#: the reward and the observation only change what a learner sees.
DYNAMICS_FIELDS: tuple[str, ...] = ("task", "reflex", "robustness", "subject")


def _pairs(value: Any, name: str) -> tuple[tuple[str, float], ...]:
    items = value.items() if isinstance(value, Mapping) else value
    try:
        pairs = tuple((str(k), float(v)) for k, v in items)
    except (TypeError, ValueError):
        raise ValueError(f"{name} = {value!r}: expected (name, number) pairs") from None
    return tuple(sorted(dict(pairs).items()))


@dataclass(frozen=True)
class TwinOptions:
    """The options of one twin variant (all default: the envs' defaults).

    Attributes:
        task: Overrides of :class:`~myoexo.envs.config.TaskParams` fields as sorted
            ``(field, value)`` pairs (seconds, degrees: the fields' own units), e.g.
            ``(("episode_duration_s", 4.0),)``.
        reward_weights: Overrides of the ``weighted_reward_keys``
            (:data:`~myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`) as sorted pairs.
        obs_preset: Observation preset (:data:`~myoexo.envs.observation.OBS_PRESETS`).
        obs_keys: Explicit observation entries (``()``: those of *obs_preset*).
        reflex: Registered reflex model (:func:`~myoexo.spasticity.reflex_names`).
        robustness: A perturbed twin per episode (:mod:`myoexo.envs.robustness`: straps,
            masses, friction, motor constant, sensor noise and latency).
        gentleness: The env's gentleness weight (its ``gentleness=``): ``""`` none (the
            study's reward and observation), ``"random"`` (drawn per reset: a policy that
            learns the whole range) or a number in [0, 1].
        subject: A personal twin (the env's ``subject=``): the report of ``myoexo twin
            fit-subject``, each episode's person drawn from the fit's uncertainty
            (:mod:`myoexo.spasticity.personal`); ``""``: the population.

    Raises:
        ValueError: An unknown task field, reward key, observation preset or reflex name
            (each message lists the accepted ones), or a task value out of its range.
    """

    task: tuple[tuple[str, float], ...] = option((), "task fields", flag="")
    reward_weights: tuple[tuple[str, float], ...] = option(
        (), "reward weights, e.g. inter:-0.5,act:-0.2", flag=""
    )
    obs_preset: str = option(
        "full", "observation preset", choices=sorted(OBS_PRESETS), metavar="PRESET"
    )
    obs_keys: tuple[str, ...] = option(
        (), "observation entries (default: those of the preset)", metavar="KEY"
    )
    reflex: str = option(DEFAULT_REFLEX, "reflex model of the twin", flag="")
    robustness: bool = option(
        False,
        "a perturbed twin per episode, drawn from the subject's seed (strap stiffness and "
        "damping x0.5-2, masses +-10 %, slide friction +-50 %, motor constant +-5 %, sensor "
        "noise, 10 ms latency)",
    )

    gentleness: str = option(
        "",
        "gentleness weight of the reward, also observed: a number in [0, 1], or 'random' "
        "(drawn per episode: one policy for the whole range)",
        metavar="WEIGHT|random",
    )
    subject: str = option(
        "",
        "a personal twin: the report of 'myoexo twin fit-subject' (JSON); each episode's "
        "person is drawn from the fit's uncertainty, at the level the fit used",
        metavar="FILE",
    )

    def __post_init__(self) -> None:
        gentleness = str(self.gentleness).strip().lower()
        if gentleness not in ("", "random"):
            gentleness = f"{check_gentleness(gentleness):g}"
        object.__setattr__(self, "gentleness", gentleness)
        task = _pairs(self.task, "task")
        unknown = sorted({k for k, _ in task} - set(TASK_FIELDS))
        if unknown:
            raise ValueError(f"task has unknown field(s) {unknown}; accepted: {list(TASK_FIELDS)}")
        TaskParams(**dict(task))  # each value in its range
        object.__setattr__(self, "task", task)
        weights = _pairs(self.reward_weights, "reward_weights")
        unknown = sorted({k for k, _ in weights} - set(DEFAULT_REWARD_WEIGHTS))
        if unknown:
            raise ValueError(
                f"reward_weights has unknown keys {unknown}; accepted: "
                f"{sorted(DEFAULT_REWARD_WEIGHTS)}"
            )
        object.__setattr__(self, "reward_weights", weights)
        if self.obs_preset not in OBS_PRESETS:
            raise ValueError(f"obs_preset = {self.obs_preset!r}; accepted: {sorted(OBS_PRESETS)}")
        object.__setattr__(self, "obs_keys", tuple(str(k) for k in self.obs_keys))
        if not isinstance(self.reflex, str):
            raise ValueError(
                f"reflex = {self.reflex!r}: the record takes a registered name (register a "
                "model with myoexo.spasticity.register_reflex)"
            )
        get_reflex(self.reflex)  # registered (the error lists the names)
        if not isinstance(self.robustness, bool):
            raise ValueError(f"robustness = {self.robustness!r}: expected True or False")
        object.__setattr__(self, "subject", str(self.subject))
        if self.subject:
            personal = load_subject(self.subject)  # one line naming the file if it is bad
            if personal.reflex != self.reflex:
                raise ValueError(
                    f"subject {self.subject} was fitted with the {personal.reflex!r} reflex, "
                    f"not {self.reflex!r}"
                )

    @property
    def personal(self) -> PersonalSubject | None:
        """The personal subject of :attr:`subject` (``None``: the population)."""
        return load_subject(self.subject) if self.subject else None

    # -- views ----------------------------------------------------------------------------
    @property
    def task_params(self) -> TaskParams:
        """The task these options give."""
        return TaskParams(**dict(self.task))

    @property
    def episode_duration_s(self) -> float | None:
        """The task's episode length if it is overridden, else ``None`` (the env's 8 s)."""
        return dict(self.task).get("episode_duration_s")

    def replace(self, **changes: Any) -> TwinOptions:
        """A copy with some options (or task fields, by their own names) replaced."""
        task = dict(self.task)
        for name in [n for n in changes if n in TASK_FIELDS]:
            value = changes.pop(name)
            if value is None:
                task.pop(name, None)
            else:
                task[name] = value
        return dataclasses.replace(self, task=tuple(task.items()), **changes)

    def env_kwargs(self) -> dict[str, Any]:
        """Keyword arguments of :func:`~myoexo.envs.make_env` (and ``gymnasium.make``) that
        build this twin: only the options that differ from the defaults, so an env id that
        takes none of them is built as it is."""
        kwargs: dict[str, Any] = dict(self.task)
        if self.reward_weights:
            kwargs["reward_weights"] = dict(self.reward_weights)
        if self.obs_keys:
            kwargs["obs_keys"] = list(self.obs_keys)
        elif self.obs_preset != "full":
            kwargs["obs_preset"] = self.obs_preset
        if self.reflex != DEFAULT_REFLEX:
            kwargs["reflex"] = self.reflex
        if self.robustness:
            kwargs["robustness"] = True
        if self.gentleness:
            kwargs["gentleness"] = (
                "random" if self.gentleness == "random" else float(self.gentleness)
            )
        if self.subject:
            kwargs["subject"] = self.subject
            kwargs["subject_noise"] = True  # draws from the fit's uncertainty
        return kwargs

    def nominal(self) -> TwinOptions:
        """These options on the nominal twin: robustness off, all else the same."""
        return self.replace(robustness=False)

    def dynamics(self) -> TwinOptions:
        """These options without the reward and the observation: what decides the twin's
        behaviour, and so whether two evaluations are of the same twin."""
        return TwinOptions(
            task=self.task, reflex=self.reflex, robustness=self.robustness, subject=self.subject
        )

    def describe(self) -> str:
        """A one-line description of the non-default options (``"default twin"`` if none)."""
        parts = [f"{k}={v:g}" for k, v in self.task]
        if self.reward_weights:
            parts.append("reward_weights=" + ",".join(f"{k}:{v:g}" for k, v in self.reward_weights))
        if self.obs_keys:
            parts.append("obs_keys=" + ",".join(self.obs_keys))
        elif self.obs_preset != "full":
            parts.append(f"obs_preset={self.obs_preset}")
        if self.reflex != DEFAULT_REFLEX:
            parts.append(f"reflex={self.reflex}")
        if self.robustness:
            parts.append("robustness=true")
        if self.gentleness:
            parts.append(f"gentleness={self.gentleness}")
        if self.subject:
            parts.append(f"subject={self.subject}")
        return " ".join(parts) or "default twin"

    # -- records --------------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """JSON-ready record (task and weights as objects; the reflex model's parameters
        under ``reflex_parameters``, for provenance)."""
        return {
            "task": dict(self.task),
            "reward_weights": dict(self.reward_weights),
            "obs_preset": self.obs_preset,
            "obs_keys": list(self.obs_keys),
            "reflex": self.reflex,
            "reflex_parameters": reflex_parameters(self.reflex),
            "robustness": self.robustness,
            "gentleness": self.gentleness,
            "subject": self.subject,
            **({"subject_sha256": file_sha256(self.subject)} if self.subject else {}),
        }

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> TwinOptions:
        """Rebuild the record of :meth:`to_dict` (``reflex_parameters`` is provenance and
        not read back; unknown keys raise)."""
        provenance = ("reflex_parameters", "subject_sha256")
        data = {k: v for k, v in dict(data).items() if k not in provenance}
        unknown = sorted(set(data) - {"task", *OPTION_FIELDS})
        if unknown:
            raise ValueError(
                f"twin options have unknown key(s) {unknown}; accepted: {['task', *OPTION_FIELDS]}"
            )
        return cls(
            task=_pairs(data.get("task", ()), "task"),
            reward_weights=_pairs(data.get("reward_weights", ()), "reward_weights"),
            obs_preset=str(data.get("obs_preset", "full")),
            obs_keys=tuple(data.get("obs_keys", ())),
            reflex=str(data.get("reflex", DEFAULT_REFLEX)),
            robustness=bool(data.get("robustness", False)),
            gentleness=str(data.get("gentleness", "")),
            subject=str(data.get("subject", "")),
        )

    # -- the command line -----------------------------------------------------------------
    @staticmethod
    def is_option(name: str) -> bool:
        """Whether *name* is a twin option (a task field or an option field)."""
        return name in TASK_FIELDS or name in OPTION_FIELDS

    def with_override(self, text: str) -> TwinOptions:
        """These options with one ``NAME=VALUE`` applied (a training or sweep setting).

        ``NAME`` is a task field (``episode_duration_s=4``; ``none`` resets it),
        ``reward_weights=inter:-0.5,act:-0.2``, ``obs_preset=exo``,
        ``obs_keys=knee_angle_rad,error_rad``, ``reflex=persistent``,
        ``robustness=true`` or ``gentleness=random``.

        Raises:
            ValueError: A malformed override or a bad value (naming the accepted ones).
        """
        try:
            ((name, raw),) = parse_assignments([text], "twin option").items()
        except ValueError:
            name, raw = "", ""
        if not self.is_option(name):
            raise ValueError(
                f"bad twin option {text!r}: expected NAME=VALUE with NAME in "
                f"{[*TASK_FIELDS, *OPTION_FIELDS]}"
            )
        types = {**typing.get_type_hints(TaskParams), **typing.get_type_hints(TwinOptions)}
        tp = float | None if name in TASK_FIELDS else types[name]
        if name == "reward_weights":
            tp = dict[str, float]
        try:
            return self.replace(**{name: convert(raw, tp, name)})
        except ValueError as exc:
            raise ValueError(f"bad value in twin option {text!r}: {exc}") from None

    @classmethod
    def from_overrides(
        cls, overrides: Iterable[str], base: TwinOptions | None = None
    ) -> TwinOptions:
        """*base* (default: the defaults) with each ``NAME=VALUE`` applied in order."""
        options = base or cls()
        for text in overrides:
            options = options.with_override(text)
        return options


def twin_mismatch(
    trained: TwinOptions, evaluated: TwinOptions, *, nominal_too: bool = False
) -> str | None:
    """A warning if a policy trained on *trained* is evaluated on another twin (task, reflex
    or robustness differ; reward and observation do not count), naming both; else ``None``.
    *nominal_too*: some of the policy's training envs ran on the nominal twin of *trained*
    (``--nominal-envs``), so that twin is one it was trained on too."""
    seen = [trained.dynamics()]
    if nominal_too and trained.robustness:
        seen.append(trained.nominal().dynamics())
    if evaluated.dynamics() in seen:
        return None
    return (
        f"trained on [{' and '.join(t.describe() for t in seen)}], evaluated on "
        f"[{evaluated.dynamics().describe()}]"
    )


# ----------------------------------------------------------------------------- CLI
def add_twin_arguments(parser: Any, *, observation: bool = False) -> None:
    """The twin options of a command, one per field: each task field
    (``--episode-duration-s 4``; not given: the task's default), ``--reflex NAME`` and
    ``--robustness``; with *observation* (a command that trains a policy), ``--obs-preset``,
    ``--obs-keys``, ``--gentleness`` and ``--reward-weights`` too (a command that evaluates
    policies runs each on its own observation, and rewards nothing)."""
    from myoexo.spasticity.registry import add_reflex_argument

    group = parser.add_argument_group("twin options")
    add_options(group, TaskParams, given_only=True)
    add_reflex_argument(group, default=DEFAULT_REFLEX)
    add_options(
        group,
        TwinOptions,
        exclude=() if observation else ("obs_preset", "obs_keys", "gentleness"),
    )
    if observation:
        group.add_argument(
            "--reward-weights",
            type=_reward_weights,
            metavar="NAME:VALUE,...",
            help="reward weights that differ from the env's, e.g. inter:-0.5,act:-0.2 "
            f"(terms: {', '.join(sorted(DEFAULT_REWARD_WEIGHTS))})",
        )


def _reward_weights(raw: str) -> dict[str, float]:
    """``--reward-weights`` text as a mapping (``inter:-0.5,act:-0.2``)."""
    import argparse

    try:
        return dict(convert(raw, dict[str, float], "--reward-weights"))
    except ValueError:
        raise argparse.ArgumentTypeError(f"{raw!r} is not NAME:VALUE,...") from None


def twin_words(twin: TwinOptions, *, observation: bool = False) -> list[str]:
    """The options of :func:`add_twin_arguments` that give *twin* (:func:`twin_from_args`
    reads them back): the task fields it overrides, ``--reflex`` when not the default, then
    its other options that differ from the defaults; with *observation*, the observation,
    gentleness and reward options too."""
    words = option_words(TaskParams(**dict(twin.task)))
    if twin.reflex != DEFAULT_REFLEX:
        words += ["--reflex", twin.reflex]
    hidden = () if observation else ("obs_preset", "obs_keys", "gentleness")
    words += option_words(twin, exclude=hidden)
    if observation and twin.reward_weights:
        words += ["--reward-weights", option_text(dict(twin.reward_weights), ":")]
    return words


def twin_from_args(args: Any, base: TwinOptions | None = None) -> TwinOptions:
    """The :class:`TwinOptions` of the options :func:`add_twin_arguments` added, on top of
    *base* (default: the defaults): only the options that were given change it."""
    options = base or TwinOptions()
    changes: dict[str, Any] = {n: getattr(args, n) for n in TASK_FIELDS if hasattr(args, n)}
    if getattr(args, "reflex", DEFAULT_REFLEX) != DEFAULT_REFLEX:
        changes["reflex"] = args.reflex
    if getattr(args, "robustness", False):
        changes["robustness"] = True
    if getattr(args, "gentleness", ""):
        changes["gentleness"] = args.gentleness
    if getattr(args, "subject", ""):
        changes["subject"] = args.subject
    for name in ("obs_preset", "obs_keys"):
        if hasattr(args, name) and getattr(args, name) != getattr(TwinOptions(), name):
            changes[name] = tuple(args.obs_keys) if name == "obs_keys" else args.obs_preset
    if getattr(args, "reward_weights", None):  # merged into the base's
        changes["reward_weights"] = {**dict(options.reward_weights), **args.reward_weights}
    return options.replace(**changes) if changes else options
