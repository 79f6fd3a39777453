"""Configuration fields: one declaration gives a field its doc, its accepted values, its
check and its command-line option.

A config is a frozen dataclass whose fields are declared with :func:`option`::

    @dataclass(frozen=True)
    class ValidationConfig:
        subjects: int = option(6, "subjects per level of the clinical tests", low=1, high=10_000)

        def __post_init__(self) -> None:
            check_fields(self)

:func:`check_fields` raises :class:`FieldError` (a ``ValueError``) naming the field, the
value and what is accepted; :func:`add_options` adds one ``--subjects`` option per field to a
command's parser (its help is the field's doc), and :func:`from_options` builds the config
from the parsed options. The command line reports a :class:`FieldError` under the option the
user typed (``--subjects = -1 is outside [1, 10000]``). ``NAME=VALUE`` text (a controller
spec's options, a mapping option) is read by :func:`parse_assignments` and converted by
:func:`convert`.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import math
import numbers
import types
import typing
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

from myoexo.runtime.files import output_folder

#: ``metadata`` key of a field declared with :func:`option`.
FIELD_KEY = "myoexo"


@dataclasses.dataclass(frozen=True)
class FieldSpec:
    """What a field accepts and how the command line spells it.

    Attributes:
        doc: One line: what the field is (the option's help).
        low: Smallest accepted value (numbers; each item of a tuple), or ``None``.
        high: Largest accepted value, or ``None``.
        above: ``low`` itself is excluded (a value must be greater).
        choices: The accepted values (strings; each item of a tuple), or ``None``.
        unit: Unit printed after the range (``"s"``, ``"deg"``).
        flag: The option's name without ``--`` (default: the field name, ``_`` as ``-``);
            ``""``: the field has no option.
        metavar: The option's placeholder in the help.
        folder: The field is an output folder (checked when the command line is read,
            :func:`~myoexo.runtime.files.output_folder`).
        short: A one-letter alias of the option, without ``-`` (``"v"``: ``-v``), or ``None``.
        const: The value of the option given without one (``--ship`` alone: ``"sac"``),
            or ``None`` (the option takes a value).
    """

    doc: str
    low: float | None = None
    high: float | None = None
    above: bool = False
    choices: tuple[Any, ...] | None = None
    unit: str = ""
    flag: str | None = None
    metavar: str | None = None
    folder: bool = False
    short: str | None = None
    const: Any = None

    def accepted(self) -> str:
        """What the field accepts, as the end of a sentence (``"is outside [1, 10000]"``)."""
        if self.choices is not None:
            return f"is not one of {', '.join(map(str, self.choices))}"
        unit = f" {self.unit}" if self.unit else ""
        if self.low is not None and self.high is not None:
            left = "(" if self.above else "["
            return f"is outside {left}{self.low:g}, {self.high:g}]{unit}"
        if self.low is not None:
            return f"must be {'>' if self.above else '>='} {self.low:g}{unit}"
        if self.high is not None:
            return f"must be <= {self.high:g}{unit}"
        return "is not accepted"

    def ok(self, value: Any) -> bool:
        """Whether one (scalar) value is accepted."""
        if self.choices is not None and value not in self.choices:
            return False
        if self.low is None and self.high is None:
            return True
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            return False
        if not math.isfinite(value):
            return False
        if self.low is not None and (value <= self.low if self.above else value < self.low):
            return False
        return self.high is None or value <= self.high


def option(
    default: Any = dataclasses.MISSING,
    doc: str = "",
    *,
    default_factory: Callable[[], Any] | Any = dataclasses.MISSING,
    low: float | None = None,
    high: float | None = None,
    above: bool = False,
    choices: Iterable[Any] | None = None,
    unit: str = "",
    flag: str | None = None,
    metavar: str | None = None,
    folder: bool = False,
    short: str | None = None,
    const: Any = None,
) -> Any:
    """A dataclass field with its doc and accepted values (:class:`FieldSpec`)."""
    spec = FieldSpec(
        doc=doc,
        low=low,
        high=high,
        above=above,
        choices=None if choices is None else tuple(choices),
        unit=unit,
        flag=flag,
        metavar=metavar,
        folder=folder,
        short=short,
        const=const,
    )
    if short is not None and (len(short) != 1 or not short.isalpha()):
        raise ValueError(f"short option {short!r}: expected one letter")
    if default_factory is not dataclasses.MISSING:
        return dataclasses.field(default_factory=default_factory, metadata={FIELD_KEY: spec})
    return dataclasses.field(default=default, metadata={FIELD_KEY: spec})


def field_spec(f: dataclasses.Field[Any]) -> FieldSpec | None:
    """The :class:`FieldSpec` of a field declared with :func:`option`, else ``None``."""
    return f.metadata.get(FIELD_KEY)


class FieldError(ValueError):
    """A config field holds a value it does not accept.

    Attributes:
        owner: The config's class name.
        field: The field's name.
        value: The value given.
        accepted: What is wrong with the value, as the end of a sentence
            (``"is outside [1, 10000]"``).
    """

    def __init__(self, owner: str, field: str, value: Any, accepted: str) -> None:
        self.owner, self.field, self.value, self.accepted = owner, field, value, accepted
        super().__init__(self.describe(f"{owner}.{field}"))

    def describe(self, name: str) -> str:
        """The message with the field called *name* (e.g. the option the user typed)."""
        return f"{name} = {self.value!r} {self.accepted}"


def check_fields(obj: Any) -> None:
    """Check every :func:`option` field of the dataclass *obj* (each item of a tuple);
    raise :class:`FieldError` at the first value it does not accept. ``None`` is accepted
    where it is the field's default or its type admits it (``float | None``)."""
    cls: type = type(obj)
    integers = _integer_fields(cls)
    optional = _optional_fields(cls)
    for f in dataclasses.fields(obj):
        spec = field_spec(f)
        if spec is None:
            continue
        value = getattr(obj, f.name)
        if value is None and (f.default is None or f.name in optional):
            continue
        items = value if isinstance(value, (tuple, list)) else (value,)
        if f.name in integers and not all(
            isinstance(i, numbers.Integral) and not isinstance(i, bool) for i in items
        ):
            raise FieldError(type(obj).__name__, f.name, value, "is not a whole number")
        if not all(spec.ok(item) for item in items):
            raise FieldError(type(obj).__name__, f.name, value, spec.accepted())


@functools.cache
def _integer_fields(cls: type) -> frozenset[str]:
    """Fields of *cls* typed ``int`` or ``tuple[int, ...]`` (optional or not)."""
    out = set()
    for name, tp in _hints(cls).items():
        tp, _ = _unwrap_optional(tp)
        if tp is int or (typing.get_origin(tp) is tuple and typing.get_args(tp)[:1] == (int,)):
            out.add(name)
    return frozenset(out)


@functools.cache
def _optional_fields(cls: type) -> frozenset[str]:
    """Fields of *cls* whose type admits ``None`` (``float | None``)."""
    return frozenset(name for name, tp in _hints(cls).items() if _unwrap_optional(tp)[1])


# ----------------------------------------------------------------------------- NAME=VALUE
def parse_assignments(
    text: str | Iterable[str], what: str = "option", bare: Iterable[str] = ()
) -> dict[str, str]:
    """``"a=1,b=x"`` (or the items of an iterable, each ``NAME=VALUE``) as a dict of raw
    strings, in order; a name of *bare* may stand alone (its value ``""``). Raises
    ``ValueError`` naming *what* for an item without ``=``, an empty name or a repeated
    name."""
    alone = set(bare)
    items = [p for p in text.split(",")] if isinstance(text, str) else list(text)
    out: dict[str, str] = {}
    for item in (i.strip() for i in items):
        if not item:
            continue
        name, eq, raw = item.partition("=")
        name = name.strip()
        if not name or not (eq or name in alone):
            raise ValueError(f"bad {what} {item!r}: expected NAME=VALUE")
        if name in out:
            raise ValueError(f"{what} {name!r} is given twice")
        out[name] = raw.strip()
    return out


def _unwrap_optional(tp: Any) -> tuple[Any, bool]:
    args = typing.get_args(tp)
    if typing.get_origin(tp) in (typing.Union, types.UnionType) and type(None) in args:
        rest = [a for a in args if a is not type(None)]
        return (rest[0] if len(rest) == 1 else tp), True
    return tp, False


def literal(raw: str) -> Any:
    """The value an untyped ``NAME=VALUE`` item spells: ``none``, ``true`` / ``false``, an
    integer, a number, else the text itself."""
    low = raw.strip().lower()
    if low == "none":
        return None
    if low in ("true", "false"):
        return low == "true"
    for tp in (int, float):
        try:
            return tp(raw)
        except ValueError:
            pass
    return raw.strip()


def convert(raw: str, tp: Any, name: str = "value") -> Any:
    """The text *raw* as a value of the type *tp* (``bool``, ``int``, ``float``, ``str``,
    ``Path``, ``tuple[X, ...]`` from comma-separated items, ``Mapping[str, float]`` from
    ``k:v`` pairs, ``Mapping[str, Any]`` from ``NAME=VALUE`` items (:func:`parse_assignments`;
    each value :func:`literal`), a union ``X | Y`` as the first of its types that reads it, an
    optional of these with ``none``). Raises ``ValueError`` naming *name*."""
    tp, optional = _unwrap_optional(tp)
    if optional and raw.strip().lower() == "none":
        return None
    origin = typing.get_origin(tp)
    if origin in (typing.Union, types.UnionType):
        members = typing.get_args(tp)
        for member in members:
            try:
                return convert(raw, member, name)
            except ValueError:
                continue
        names = " or ".join(getattr(m, "__name__", str(m)) for m in members)
        raise ValueError(f"{name} = {raw!r}: expected {names}")
    try:
        if tp is bool:
            low = raw.strip().lower()
            if low not in ("true", "false", "1", "0", "yes", "no"):
                raise ValueError("expected true or false")
            return low in ("true", "1", "yes")
        if tp is int or tp is float:
            try:
                return tp(raw)
            except ValueError:
                raise ValueError(
                    "is not a whole number" if tp is int else "is not a number"
                ) from None
        if tp in (str, Path):
            return tp(raw)
        if origin is tuple:
            (item, *_rest) = typing.get_args(tp)
            return tuple(convert(p, item, name) for p in raw.split(",") if p.strip())
        if origin in (dict, Mapping) or tp in (dict, Mapping):
            if typing.get_args(tp)[1:] == (Any,):  # NAME=VALUE items, each value a literal
                return {k: literal(v) for k, v in parse_assignments(raw, name).items()}
            pairs = [p.split(":", 1) for p in raw.split(",") if p.strip()]
            return {k.strip(): float(v) for k, v in pairs}
    except (TypeError, ValueError) as exc:
        sep = " " if str(exc).startswith("is ") else ": "
        raise ValueError(f"{name} = {raw!r}{sep}{exc}") from None
    raise TypeError(f"{name}: no conversion from text to {tp!r}")


# ----------------------------------------------------------------------------- command line
def _hints(cls: type) -> dict[str, Any]:
    import sys

    module = sys.modules.get(cls.__module__)
    return typing.get_type_hints(cls, vars(module) if module else None)


def _default_of(f: dataclasses.Field[Any]) -> Any:
    """The default of field *f* (its factory's value), or ``dataclasses.MISSING``."""
    if f.default is not dataclasses.MISSING:
        return f.default
    if f.default_factory is not dataclasses.MISSING:
        return f.default_factory()
    return dataclasses.MISSING


def option_fields(cls: type, exclude: Iterable[str] = ()) -> list[dataclasses.Field[Any]]:
    """The fields of *cls* that have a command-line option."""
    skip = set(exclude)
    return [
        f
        for f in dataclasses.fields(cls)
        if (s := field_spec(f)) is not None and s.flag != "" and f.name not in skip
    ]


def flag_of(f: dataclasses.Field[Any]) -> str:
    """The option of field *f* (``--episodes-per-round``)."""
    spec = field_spec(f)
    name = spec.flag if spec is not None and spec.flag else f.name.replace("_", "-")
    return f"--{name}"


def add_options(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup,
    cls: type,
    *,
    exclude: Iterable[str] = (),
    defaults: Mapping[str, Any] | None = None,
    given_only: bool = False,
) -> None:
    """One option per :func:`option` field of the dataclass *cls*: ``--name VALUE`` (a
    tuple takes several values, a ``bool`` is ``--name``/``--no-name``, a field with a
    ``short`` letter also ``-x``, one with a ``const`` also ``--name`` alone), its help the
    field's doc and default (*defaults* overrides a field's default for this command). The
    option's ``dest`` is the field's name; with *given_only*, an option not given leaves no
    attribute (its field keeps the config's own default)."""
    hints = _hints(cls)
    overrides = dict(defaults or {})
    for f in option_fields(cls, exclude):
        spec = field_spec(f)
        assert spec is not None
        tp, optional = _unwrap_optional(hints[f.name])
        if f.name in overrides:
            default = overrides[f.name]
        else:
            default = _default_of(f)
            default = None if default is dataclasses.MISSING else default
        shown = ", ".join(map(str, default)) if isinstance(default, tuple) else default
        if isinstance(shown, str) and not shown:
            shown = "none"
        elif spec.unit and isinstance(default, (int, float)):
            shown = f"{default:g} {spec.unit}"
        doc = spec.doc.replace("%", "%%")
        if spec.choices is not None:
            doc = f"{doc}: {', '.join(map(str, spec.choices))}"
        if "default" not in doc and tp is not bool:
            doc = f"{doc} (default: {shown})"
        kwargs: dict[str, Any] = {
            "dest": f.name,
            "default": argparse.SUPPRESS if given_only else default,
        }
        kwargs["metavar"] = spec.metavar or (
            spec.unit.upper() if spec.unit.isalpha() else flag_of(f)[2:].upper().replace("-", "_")
        )
        if tp is bool:
            kwargs.pop("metavar")
            kwargs["action"] = argparse.BooleanOptionalAction
            kwargs["help"] = doc
        else:
            origin = typing.get_origin(tp)
            item = typing.get_args(tp)[0] if origin is tuple else tp
            if origin is tuple:
                kwargs["nargs"] = "*" if not default else "+"
            if origin in (dict, Mapping):
                kwargs["type"] = _converter(tp)
                kwargs["metavar"] = spec.metavar or (
                    "NAME=VALUE,..." if typing.get_args(tp)[1:] == (Any,) else "NAME:VALUE,..."
                )
            elif spec.folder:
                kwargs["type"] = output_folder
            else:  # an optional scalar also reads "none"
                kwargs["type"] = _converter(hints[f.name] if optional and origin is None else item)
            if spec.const is not None:
                kwargs["nargs"], kwargs["const"] = "?", spec.const
            if spec.choices is not None:
                kwargs["choices"] = spec.choices
            kwargs["help"] = doc
        flags = [flag_of(f)] if spec.short is None else [f"-{spec.short}", flag_of(f)]
        parser.add_argument(*flags, **kwargs)


def _converter(tp: Any) -> Callable[[str], Any]:
    def parse(raw: str) -> Any:
        try:
            return convert(raw, tp)
        except ValueError:
            name = getattr(_unwrap_optional(tp)[0], "__name__", "value")
            raise argparse.ArgumentTypeError(f"{raw!r} is not a valid {name}") from None

    return parse


def add_positional(
    parser: argparse.ArgumentParser | argparse._ArgumentGroup, cls: type, name: str, **kwargs: Any
) -> None:
    """The field *name* of the dataclass *cls* (declared with ``flag=""``) as a positional
    argument of the command (``myoexo report DIR``): its help the field's doc, its type the
    field's (an output folder checked as :func:`add_options` checks one), its ``dest`` the
    field's name; *kwargs* go to ``add_argument`` (``nargs``, ``metavar``). Pass its value
    to :func:`from_options` as a fixed field."""
    (f,) = [f for f in dataclasses.fields(cls) if f.name == name]
    spec = field_spec(f)
    if spec is None:
        raise TypeError(f"{cls.__name__}.{name} is not declared with option()")
    tp, _ = _unwrap_optional(_hints(cls)[name])
    kwargs.setdefault("type", output_folder if spec.folder else _converter(tp))
    kwargs.setdefault("metavar", spec.metavar or name.upper())
    kwargs.setdefault("help", spec.doc.replace("%", "%%"))
    parser.add_argument(name, **kwargs)


def from_options(cls: type, args: argparse.Namespace, **fixed: Any) -> Any:
    """The *cls* config of the options :func:`add_options` added (fields without an option
    keep their defaults; *fixed* sets fields directly)."""
    values = {f.name: getattr(args, f.name) for f in option_fields(cls) if hasattr(args, f.name)}
    for name, value in values.items():
        if isinstance(value, list):
            values[name] = tuple(value)
    return cls(**{**values, **fixed})


def option_text(value: Any, pair: str = "=") -> str:
    """One value as :func:`convert` reads it back (a mapping's items joined by *pair*)."""
    if value is None:
        return "none"
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        short = f"{value:g}"
        return short if float(short) == value else repr(value)
    if isinstance(value, Mapping):
        return ",".join(f"{k}{pair}{option_text(v)}" for k, v in value.items())
    return str(value)


def option_words(settings: Any, *, exclude: Iterable[str] = ()) -> list[str]:
    """The command-line words that give the dataclass instance *settings* to a command whose
    options :func:`add_options` made: for each option field (not in *exclude*) whose value
    differs from its default, ``--flag VALUE`` (a ``bool`` as ``--flag`` / ``--no-flag``, a
    tuple as its items, ``None`` as ``none``). Parsing the words gives *settings* back
    (:func:`from_options`), so a record's command reproduces the run (``shlex.join`` them
    behind the command's name)."""
    hints = _hints(type(settings))
    words: list[str] = []
    for f in option_fields(type(settings), exclude):
        value = getattr(settings, f.name)
        if value == _default_of(f):
            continue
        flag = flag_of(f)
        if isinstance(value, bool):
            words.append(flag if value else f"--no-{flag[2:]}")
        elif isinstance(value, tuple):
            words += [flag, *map(option_text, value)]
        else:
            tp, _ = _unwrap_optional(hints[f.name])
            any_values = typing.get_args(tp)[1:] == (Any,)  # NAME=VALUE items, else k:v
            words += [flag, option_text(value, "=" if any_values else ":")]
    return words


def option_of(parser: argparse.ArgumentParser, dest: str) -> str | None:
    """The option string of *parser* whose ``dest`` is *dest* (its longest), else ``None``."""
    for action in parser._actions:
        if action.dest == dest and action.option_strings:
            return max(action.option_strings, key=len)
    return None


@dataclasses.dataclass(frozen=True)
class Execution:
    """How a command that runs many episodes uses this machine."""

    workers: int | None = option(None, "worker processes (default: all cores)", low=1)
    progress: bool = option(True, "show a progress bar")

    def __post_init__(self) -> None:
        check_fields(self)
