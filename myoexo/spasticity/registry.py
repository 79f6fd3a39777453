"""Reflex models as plug-ins: the protocol a model follows and the registry of named models.

A reflex model is a **frozen dataclass of its parameters** (units in the field names) that
subclasses :class:`ReflexModel` and answers four questions:

* :meth:`~ReflexModel.subject_constants`: what the per-step maths needs of one subject
  (computed once per subject, at reset);
* :meth:`~ReflexModel.excite`: one excitation per spastic muscle from a (delayed)
  :class:`~myoexo.spasticity.sensory.SensoryRecord` (the knee's state and each muscle's own
  normalised fibre length, lengthening speed and force), and the model's next memory. A
  model of two muscle groups driven by the knee state implements :meth:`~ReflexModel.step`
  instead: the excitation ``(flexors, extensors)`` at one knee state, which the default
  :meth:`~ReflexModel.excite` gives every muscle of each group;
* :meth:`~ReflexModel.step_torch`: its torch twin, differentiable in the knee state and in
  the subject's parameters;
* :meth:`~ReflexModel.initial_memory`: the memory a new motion starts with (a tuple of
  floats: what :meth:`SpasticityStage.history_state
  <myoexo.spasticity.stage.SpasticityStage.history_state>` saves and restores; ``()`` for a
  model without memory).

The :class:`~myoexo.spasticity.stage.SpasticityStage` only calls these: it holds the
transmission delay line of sensory records (``delay_s``, a field every model has) and the
memory, and writes the excitations into MyoSuite's ``ctrl``. A model is registered under a name with
:func:`register_reflex` and found with :func:`get_reflex`; every place that takes a reflex
(``gymnasium.make(..., reflex=...)``, :class:`~myoexo.spasticity.SpasticityWrapper`, the
CLI's ``--reflex``, the clinical tests) takes a registered name or a model
instance. Example (docs: "Reflex models", "Adding a reflex model")::

    import dataclasses
    from myoexo.spasticity import get_reflex, register_reflex

    slow = dataclasses.replace(get_reflex("stretch"), delay_s=0.04)
    register_reflex("stretch_40ms", slow)
    env = gymnasium.make("MyoExoKnee-v2", reflex="stretch_40ms")
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

if TYPE_CHECKING:  # torch is imported lazily
    import torch

    from myoexo.spasticity.levels import SpasticityParams
    from myoexo.spasticity.sensory import SensoryRecord

#: The memory of a reflex model: a tuple of floats (``()``: none).
Memory = tuple[float, ...]

#: Longest transmission delay a model may have, s.
MAX_DELAY_S = 0.2


def check_parameter(owner: str, name: str, value: Any, low: float, high: float, unit: str) -> None:
    """Raise a ``ValueError`` naming ``owner.name``, the value and the accepted range unless
    *value* is a real number (no ``bool``) in ``[low, high]`` *unit*: the check of every
    bounded reflex-model parameter."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    if not (ok and math.isfinite(value) and low <= value <= high):
        raise ValueError(f"{owner}.{name} = {value!r} is outside [{low}, {high}] {unit}")


def individual_factors(rng: Any, rel_std: float, size: int) -> np.ndarray:
    """*size* factors ``max(0, 1 + rel_std z)`` of a subject's own parameters, ``z`` standard
    normal from ``rng.spawn(1)[0]``, so *rng*'s own stream is not advanced (a generator
    without a seed sequence is drawn from directly): the draw of
    :meth:`ReflexModel.draw_individual`."""
    try:
        child = rng.spawn(1)[0]
    except (AttributeError, TypeError, ValueError):  # a generator without a seed sequence
        z = np.asarray(rng.standard_normal(size), dtype=float)
    else:
        z = np.asarray(child.standard_normal(size), dtype=float)
    factors: np.ndarray = np.maximum(0.0, 1.0 + rel_std * z)
    return factors


@dataclass(frozen=True)
class ReflexModel(abc.ABC):
    """Base of every reflex model: a frozen dataclass of the model's parameters.

    Subclasses add their parameters as dataclass fields (with defaults and units in their
    names) and implement :meth:`subject_constants` and either :meth:`excite` (a model on the
    muscles' own state) or :meth:`step` and :meth:`step_torch` (a model of two groups on the
    knee state); a model with a memory also overrides :meth:`initial_memory`, and one with
    an individual draw of its own :meth:`draw_individual`. Instances are values: equal
    parameters, equal models; ``dataclasses.replace(model, ...)`` gives a variant.

    Attributes:
        delay_s: Transmission delay of the knee state the reflex reads, s (rounded to whole
            control periods of the host; 0 = the present state).
    """

    delay_s: float = 0.0

    def __post_init__(self) -> None:
        if not (
            isinstance(self.delay_s, (int, float))
            and math.isfinite(self.delay_s)
            and 0.0 <= self.delay_s <= MAX_DELAY_S
        ):
            raise ValueError(
                f"{type(self).__name__}.delay_s = {self.delay_s!r} is outside [0, {MAX_DELAY_S}] s"
            )

    # -- per subject ----------------------------------------------------------------------
    def draw_individual(self, rng: np.random.Generator, rel_std: float) -> Any:
        """The model's own individual draw at a reset with subject noise (default: none).

        It must leave *rng*'s stream where it found it (draw from a child,
        ``rng.spawn(1)[0]``), so the rest of the episode draws the same under every model.
        The value is passed to :meth:`subject_constants` as *individual*."""
        return None

    @abc.abstractmethod
    def subject_constants(
        self,
        level: int,
        subject: SpasticityParams,
        individual: Any,
        control_period_s: float,
    ) -> Any:
        """The constants of one subject that :meth:`step` reads (python floats are fastest).

        Args:
            level: The subject's spasticity level (0..3).
            subject: The subject's Table I parameters.
            individual: What :meth:`draw_individual` drew for this subject (``None``: the
                nominal subject).
            control_period_s: Time between two steps, s (the host's control period).
        """

    # -- the step -------------------------------------------------------------------------
    def initial_memory(self) -> Memory:
        """The memory a new motion starts with (default: none)."""
        return ()

    def excite(
        self, constants: Any, memory: Memory, record: SensoryRecord
    ) -> tuple[Sequence[float], Memory]:
        """One control step: the excitation added to each spastic muscle (flexors first, the
        record's order; fractions of the excitation range, before the clip to ``[0, 1]``)
        and the memory after the step.

        The default gives each group :meth:`step`'s excitation at the record's knee state;
        a model on the muscles' own state overrides this (and need not implement
        :meth:`step`).

        Args:
            constants: What :meth:`subject_constants` returned.
            memory: The memory before the step.
            record: What the reflex senses, delayed by the transmission delay.
        """
        flex, ext, memory = self.step(
            constants, memory, record.knee_angle_deg, record.knee_vel_rad_s
        )
        n, nf = len(record.fibre_length), record.n_flexors
        return (flex,) * nf + (ext,) * (n - nf), memory

    def step(
        self, constants: Any, memory: Memory, theta_deg: float, vel_rad_s: float
    ) -> tuple[float, float, Memory]:
        """One control step of a two-group model on the knee state:
        ``(flexor, extensor, next_memory)``.

        Args:
            constants: What :meth:`subject_constants` returned.
            memory: The memory before the step.
            theta_deg: Knee angle the reflex reads, deg (flexion positive; delayed).
            vel_rad_s: Knee velocity the reflex reads, rad/s (flexion positive; delayed).

        Returns:
            The excitation added to each flexor and to each extensor (fractions of the
            excitation range, before the clip to ``[0, 1]``) and the memory after the step.

        Raises:
            NotImplementedError: For a model that implements :meth:`excite` only.
        """
        raise NotImplementedError(
            f"{type(self).__name__} reads the muscles' own state: call excite with a SensoryRecord"
        )

    def sc_total(self, flexor: float, extensor: float) -> float:
        """The scalar the env reports as ``sc_total`` for one step's excitations (default:
        their sum; a model whose groups share one excitation reports that one)."""
        return flexor + extensor

    def step_torch(
        self,
        level: int,
        subject: Mapping[str, Any],
        memory: tuple[torch.Tensor, ...] | Memory,
        theta_deg: torch.Tensor,
        vel_rad_s: torch.Tensor,
        control_period_s: float,
        individual: Any = None,
    ) -> tuple[torch.Tensor, torch.Tensor, tuple[torch.Tensor, ...]]:
        """Torch twin of :meth:`step`: differentiable in the knee state, the memory and every
        subject parameter given as a tensor (*subject* maps
        :class:`~myoexo.spasticity.SpasticityParams` field names to tensors or floats; the
        model's own parameters are its fields).

        Raises:
            NotImplementedError: For a model without a torch twin (the fits that need
                gradients, ``myoexo twin calibrate``, cannot fit it).
        """
        raise NotImplementedError(f"{type(self).__name__} has no torch twin of its step")


class MemorylessGroupReflex(ReflexModel):
    """A reflex without memory whose per-level parameters live in a ``calibration`` field
    (``calibration[level]``) and whose step is one function of the knee state, written once
    for floats and for torch: subclasses give :meth:`constants` (a subject's constants),
    :meth:`terms` (``(flexor, extensor)`` from them, in any array library) and
    :meth:`terms_torch` (the differentiable twin from the subject's parameters)."""

    calibration: Any

    @abc.abstractmethod
    def constants(self, subject: Any, level_parameters: Any) -> Any:
        """The subject's constants with its level's parameters."""

    @abc.abstractmethod
    def terms(self, theta_deg: Any, vel_rad_s: Any, constants: Any, tanh: Any) -> tuple[Any, Any]:
        """``(flexor, extensor)`` excitations; *tanh* is the array library's."""

    @abc.abstractmethod
    def terms_torch(
        self, theta_deg: Any, vel_rad_s: Any, subject: Mapping[str, Any], level_parameters: Any
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """The torch twin of :meth:`terms` from the subject's parameters."""

    def subject_constants(
        self, level: int, subject: SpasticityParams, individual: Any, control_period_s: float
    ) -> Any:
        return self.constants(subject, self.calibration[level])

    def step(
        self, constants: Any, memory: Memory, theta_deg: float, vel_rad_s: float
    ) -> tuple[float, float, Memory]:
        flex, ext = self.terms(theta_deg, vel_rad_s, constants, math.tanh)
        return flex, ext, memory

    def step_torch(
        self,
        level: int,
        subject: Mapping[str, Any],
        memory: Any,
        theta_deg: torch.Tensor,
        vel_rad_s: torch.Tensor,
        control_period_s: float,
        individual: Any = None,
    ) -> tuple[torch.Tensor, torch.Tensor, tuple[torch.Tensor, ...]]:
        flex, ext = self.terms_torch(theta_deg, vel_rad_s, subject, self.calibration[level])
        return flex, ext, tuple(memory)


_REGISTRY: dict[str, ReflexModel] = {}

#: Environment variable naming modules (comma-separated) that register reflex models when
#: imported; ``myoexo --plugin MODULE`` sets it, so worker processes import them too.
PLUGINS_ENV = "MYOEXO_PLUGINS"

#: Entry-point group of installed packages' plug-in modules (each entry point is imported).
ENTRY_POINT_GROUP = "myoexo.plugins"

_imported_plugins: set[str] = set()


def load_plugins(modules: str | None = None) -> list[str]:
    """Import the plug-in modules that register reflex models: those named in *modules*
    (comma-separated; default: the ``MYOEXO_PLUGINS`` environment variable) and the
    ``myoexo.plugins`` entry points of installed packages, each once per process.

    Returns:
        The modules imported by this call.

    Raises:
        ImportError: If a named module cannot be imported (the message names it).
    """
    import importlib
    import os

    names = [m.strip() for m in (modules or os.environ.get(PLUGINS_ENV, "")).split(",")]
    todo = [m for m in names if m and m not in _imported_plugins]
    if ENTRY_POINT_GROUP not in _imported_plugins:
        from importlib.metadata import entry_points

        _imported_plugins.add(ENTRY_POINT_GROUP)
        todo += [ep.value.split(":")[0] for ep in entry_points(group=ENTRY_POINT_GROUP)]
    done = []
    for module in todo:
        if module in _imported_plugins:
            continue
        try:
            importlib.import_module(module)
        except ImportError as exc:
            raise ImportError(
                f"plug-in module {module!r} (from {PLUGINS_ENV} or --plugin) cannot be "
                f"imported: {exc}"
            ) from exc
        _imported_plugins.add(module)
        done.append(module)
    return done


#: Read-only view of the registry: name -> model.
REFLEXES: Mapping[str, ReflexModel] = MappingProxyType(_REGISTRY)


def register_reflex(name: str, model: ReflexModel, *, replace: bool = False) -> ReflexModel:
    """Register *model* under *name*; returns *model*.

    Args:
        name: A non-empty name without ``=``, ``,``, ``:`` or spaces (it is typed on the
            command line: ``--reflex NAME``).
        model: An instance of a :class:`ReflexModel` subclass.
        replace: Allow replacing a model registered under *name* before.

    Raises:
        TypeError: If *model* is no :class:`ReflexModel`.
        ValueError: If *name* is malformed, or taken and *replace* is false.
    """
    if not isinstance(model, ReflexModel):
        raise TypeError(
            f"register_reflex({name!r}, ...) needs a ReflexModel instance, got "
            f"{type(model).__name__}"
        )
    if not isinstance(name, str) or not name or any(c in name for c in "=,: \t\n"):
        raise ValueError(
            f"reflex name {name!r} must be a non-empty string without '=', ',', ':' or spaces"
        )
    if name in _REGISTRY and not replace and _REGISTRY[name] != model:
        raise ValueError(
            f"a reflex model is already registered as {name!r}; pass replace=True to replace it"
        )
    _REGISTRY[name] = model
    return model


def reflex_names() -> tuple[str, ...]:
    """The registered names, sorted (plug-in modules imported first, :func:`load_plugins`)."""
    load_plugins()
    return tuple(sorted(_REGISTRY))


def get_reflex(name: str) -> ReflexModel:
    """The model registered under *name*.

    Raises:
        ValueError: If no model is registered under *name* (the message lists the names).
    """
    if isinstance(name, str) and name not in _REGISTRY:
        load_plugins()
    try:
        return _REGISTRY[name]
    except (KeyError, TypeError):
        raise ValueError(
            f"reflex = {name!r} is not a registered reflex model; registered: "
            f"{', '.join(reflex_names())} (register one with "
            "myoexo.spasticity.register_reflex, in a module that "
            f"{PLUGINS_ENV} or myoexo --plugin names for the command line and worker processes)"
        ) from None


def resolve_reflex(reflex: str | ReflexModel) -> ReflexModel:
    """A model from a registered name or a model instance (``ValueError`` otherwise)."""
    if isinstance(reflex, ReflexModel):
        return reflex
    if isinstance(reflex, str):
        return get_reflex(reflex)
    raise ValueError(
        f"reflex = {reflex!r}: expected a registered name ({', '.join(reflex_names())}) or a "
        "ReflexModel instance"
    )


def reflex_name(reflex: str | ReflexModel) -> str | None:
    """The registered name of *reflex* (a name is checked; an instance is looked up by
    value: the first name, sorted, whose model equals it); ``None`` for an unregistered
    instance."""
    if isinstance(reflex, str):
        get_reflex(reflex)
        return reflex
    for name in reflex_names():
        if _REGISTRY[name] == reflex:
            return name
    return None


def reflex_label(reflex: str | ReflexModel) -> str:
    """A label for tables: the registered name, or ``"<ClassName> (custom)"``."""
    name = reflex_name(reflex)
    return name if name is not None else f"{type(reflex).__name__} (custom)"


def calibration_to_dict(calibration: Any) -> dict[str, Any]:
    """A per-level calibration (``levels``: level -> a dataclass of the level's parameters,
    ``note``, ``root_seed``) as JSON-ready data: what a fit file holds."""
    return {
        "levels": {
            str(lv): dataclasses.asdict(value) for lv, value in sorted(calibration.levels.items())
        },
        "note": calibration.note,
        "root_seed": calibration.root_seed,
    }


def calibration_from_dict(cls: type[Any], level_cls: type[Any], doc: Mapping[str, Any]) -> Any:
    """The calibration of class *cls* (levels of *level_cls*) that :func:`calibration_to_dict`
    wrote."""
    levels = {int(lv): level_cls(**value) for lv, value in doc["levels"].items()}
    root = doc.get("root_seed")
    return cls(
        levels=MappingProxyType(levels),
        note=str(doc.get("note", "")),
        root_seed=None if root is None else int(root),
    )


def reflex_parameters(reflex: str | ReflexModel) -> dict[str, Any]:
    """The model's parameters as JSON-able data: ``{"class": ..., **fields}`` (nested
    dataclasses and mappings become dicts; level keys become strings)."""
    model = resolve_reflex(reflex)

    def plain(value: Any) -> Any:
        if dataclasses.is_dataclass(value) and not isinstance(value, type):
            return {f.name: plain(getattr(value, f.name)) for f in dataclasses.fields(value)}
        if isinstance(value, Mapping):
            return {str(k): plain(v) for k, v in value.items()}
        if isinstance(value, (tuple, list)):
            return [plain(v) for v in value]
        return value

    return {"class": f"{type(model).__module__}.{type(model).__qualname__}", **plain(model)}


#: Fields of a reflex model's parameters that are provenance, not dynamics.
PROVENANCE_FIELDS = frozenset({"note", "root_seed"})


def reflex_parameter_changes(recorded: Mapping[str, Any], reflex: str | ReflexModel) -> list[str]:
    """How the parameters *recorded* with a policy (:func:`reflex_parameters` when it was
    trained) differ from *reflex*'s now: one ``"path: recorded -> now"`` per changed value
    (provenance fields, :data:`PROVENANCE_FIELDS`, do not count); empty if none does."""

    def flat(value: Any, path: str = "") -> dict[str, Any]:
        if isinstance(value, Mapping):
            out: dict[str, Any] = {}
            for k, v in value.items():
                if k not in PROVENANCE_FIELDS:
                    out.update(flat(v, f"{path}.{k}" if path else str(k)))
            return out
        return {path: value}

    before, now = flat(dict(recorded)), flat(reflex_parameters(reflex))
    return [
        f"{key}: {before.get(key, 'absent')} -> {now.get(key, 'absent')}"
        for key in sorted(set(before) | set(now))
        if not _same_value(before.get(key), now.get(key))
    ]


#: Relative tolerance under which two recorded floats are the same parameter: a re-fit that
#: measures the same geometry on another MuJoCo build differs in the last digits.
_PARAMETER_RTOL = 1e-9


def _same_value(a: Any, b: Any) -> bool:
    """Whether two recorded parameter values are the same: equal, or numbers (or lists of
    numbers) equal within :data:`_PARAMETER_RTOL`."""
    if a == b:
        return True
    numbers = (int, float)
    if isinstance(a, numbers) and isinstance(b, numbers):
        return (
            not isinstance(a, bool)
            and not isinstance(b, bool)
            and math.isclose(a, b, rel_tol=_PARAMETER_RTOL, abs_tol=0.0)
        )
    if isinstance(a, list | tuple) and isinstance(b, list | tuple) and len(a) == len(b):
        return all(_same_value(x, y) for x, y in zip(a, b, strict=True))
    return False


def reflex_argument(name: str) -> str:
    """``argparse`` type of a ``--reflex`` option: a registered name (plug-ins included),
    else ``argparse.ArgumentTypeError`` listing the registered names."""
    import argparse

    try:
        get_reflex(name)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None
    return name


def add_reflex_argument(parser: Any, default: str, flag: str = "--reflex") -> None:
    """Add the ``--reflex NAME`` option: its help lists the registered models."""
    parser.add_argument(
        flag,
        type=reflex_argument,
        default=default,
        metavar="NAME",
        help=f"reflex model of the twin, a registered name: {', '.join(reflex_names())} or one "
        f"a plug-in module registers (myoexo --plugin MODULE) (default: {default})",
    )
