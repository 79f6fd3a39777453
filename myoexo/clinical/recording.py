"""A patient's clinical tests as files: the recording format, its reader and writer, and
synthetic recordings made on the twin.

One CSV file per test. Its metadata come first, one comment line each, ``# key: value``; a
test that is a time series (the pendulum, a passive stretch) then has a header row and one
row per sample; a test that is single values (the Tardieu angles, the MAS grade) has no rows,
its values are metadata. A pendulum recording::

    # test: pendulum
    # posture: seated
    # sampling_hz: 100
    # side: right
    # device: none
    time_s,knee_angle_deg
    0.0,24.8
    0.01,24.9
    ...

What the format holds is three tables, which the documentation shows as they are
(``docs/recordings.md``): :data:`EXAMS` (per test: its columns, its metadata, its posture and
sampling, the least it must hold), :data:`COLUMNS` (per column: unit, meaning, accepted
range) and :data:`KEYS` (per metadata key: meaning and accepted values).

The angle convention is the twin's (:attr:`myoexo.envs.twin.Twin.knee_angle_deg`): knee
flexion in degrees, 0 at full extension, positive in flexion (the seated rest is about 90);
a velocity is the flexion velocity (deg/s), a torque the torque the device applies to the
shank, flexion positive, Nm (an extension stretch of spastic flexors reads negative: the
resisting torque is ``-torque_nm``).

:func:`read_recording` refuses a bad file with one ``ValueError`` line that names the file
and what is wrong (the row and the line for a sample); it never changes what it reads.
:func:`write_recording` writes a :class:`Recording` that :func:`read_recording` reads back
equal, to the last bit. :func:`record_from_twin` makes a recording of one of the clinical
tests on the twin (:mod:`myoexo.clinical.pendulum`, :mod:`~myoexo.clinical.stretch`,
:mod:`~myoexo.clinical.tardieu`, :mod:`~myoexo.clinical.mas`) for a subject drawn from a
seed, with seeded sensor noise (:class:`SensorNoise`), and records how it was made under the
``synthetic_*`` keys, so a fit can be held against the truth.

CLI::

    myoexo clinic record --test pendulum|stretch-slow|stretch-fast|tardieu|mas --level L
                         [--subject-seed S] [--reflex NAME] [--posture seated|reclined]
                         [--angle-std-deg 0.5] [--torque-std-nm 0.5] ... --out FILE.csv
    myoexo clinic check-recording FILE...      (myoexo.clinical.check_recording)
"""

from __future__ import annotations

import argparse
import csv
import dataclasses
import io
import math
import re
from collections.abc import Callable, Mapping
from pathlib import Path
from types import MappingProxyType
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.runtime.fields import add_options, check_fields, from_options, option
from myoexo.spasticity.levels import LEVELS, VALID_LEVELS, SpasticityParams, check_level
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel, add_reflex_argument

if TYPE_CHECKING:
    import pandas as pd

    from myoexo.clinical.mas import MASExamParams
    from myoexo.clinical.pendulum import PendulumParams
    from myoexo.clinical.tardieu import TardieuParams

__all__ = [
    "COLUMNS",
    "EXAMS",
    "KEYS",
    "MAS_GRADES",
    "RADIANS_BOUND",
    "RECORDABLE",
    "SAMPLING_TOLERANCE",
    "ColumnSpec",
    "ExamSpec",
    "KeySpec",
    "MASGrading",
    "RecordOptions",
    "Recording",
    "SensorNoise",
    "add_arguments",
    "format_markdown",
    "read_recording",
    "record_from_twin",
    "run",
    "write_recording",
]


# ----------------------------------------------------------------------------- the format
@dataclasses.dataclass(frozen=True)
class ColumnSpec:
    """A column of a recording.

    Attributes:
        name: The column's header (its unit is its suffix).
        unit: Unit of its values.
        meaning: What it holds.
        low: Smallest accepted value, or ``None``.
        high: Largest accepted value, or ``None``.
    """

    name: str
    unit: str
    meaning: str
    low: float | None = None
    high: float | None = None

    def accepts(self, value: float) -> bool:
        """Whether *value* lies in the column's range."""
        return (self.low is None or value >= self.low) and (self.high is None or value <= self.high)

    def range_text(self) -> str:
        """The accepted range, ``[-20, 160] deg``."""
        low = "-inf" if self.low is None else f"{self.low:g}"
        high = "inf" if self.high is None else f"{self.high:g}"
        return f"[{low}, {high}] {self.unit}"


@dataclasses.dataclass(frozen=True)
class KeySpec:
    """A metadata key (``# key: value``).

    Attributes:
        key: The key.
        meaning: What its value says.
        kind: ``"text"`` (any one line), ``"choice"`` (one of *choices*), ``"number"`` or
            ``"integer"`` (in ``[low, high]``; ``(low, high]`` when *above*).
        choices: The accepted values of a ``"choice"``.
        low: Smallest accepted number, or ``None``.
        high: Largest accepted number, or ``None``.
        above: *low* itself is excluded.
        unit: Unit of a number.
    """

    key: str
    meaning: str
    kind: str = "text"
    choices: tuple[str, ...] = ()
    low: float | None = None
    high: float | None = None
    above: bool = False
    unit: str = ""

    def accepted(self) -> str:
        """What the key accepts, for the documentation and the messages."""
        if self.kind == "choice":
            return "one of " + ", ".join(self.choices)
        if self.kind == "text":
            return "one line of text"
        what = "a whole number" if self.kind == "integer" else "a number"
        if self.low is None and self.high is None:
            return what
        unit = f" {self.unit}" if self.unit else ""
        if self.high is None:
            return f"{what} {'>' if self.above else '>='} {self.low:g}{unit}"
        if self.low is None:
            return f"{what} <= {self.high:g}{unit}"
        left = "(" if self.above else "["
        return f"{what} in {left}{self.low:g}, {self.high:g}]{unit}"

    def problem(self, text: str) -> str | None:
        """What is wrong with the value *text* (``None``: it is accepted)."""
        if self.kind == "text":
            return None
        if self.kind == "choice":
            return None if text in self.choices else f"is not {self.accepted()}"
        try:
            value = int(text) if self.kind == "integer" else float(text)
        except ValueError:
            return f"is not {self.accepted()}"
        if not math.isfinite(value):
            return f"is not {self.accepted()}"
        if self.low is not None and (value <= self.low if self.above else value < self.low):
            return f"is not {self.accepted()}"
        if self.high is not None and value > self.high:
            return f"is not {self.accepted()}"
        return None


@dataclasses.dataclass(frozen=True)
class ExamSpec:
    """What the recording of one clinical test holds.

    Attributes:
        test: The value of its ``# test:`` line.
        what: The test, in a few words.
        posture: The posture it is taken in (documentation).
        sampling: How it is sampled (documentation).
        required_columns: Columns it must have, in the order the writer writes them
            (none: a test of single values, no rows).
        optional_columns: Columns it may have.
        required_keys: Metadata it must have (``test`` aside).
        optional_keys: Metadata it may have.
        min_samples: The fewest rows it may have.
        min_duration_s: The shortest time it may span, s.
    """

    test: str
    what: str
    posture: str
    sampling: str
    required_columns: tuple[str, ...] = ()
    optional_columns: tuple[str, ...] = ()
    required_keys: tuple[str, ...] = ()
    optional_keys: tuple[str, ...] = ()
    min_samples: int = 0
    min_duration_s: float = 0.0

    @property
    def rows(self) -> bool:
        """Whether the test is a time series (rows) rather than single values."""
        return bool(self.required_columns)

    @property
    def columns(self) -> tuple[str, ...]:
        """Its columns, required then optional."""
        return self.required_columns + self.optional_columns

    @property
    def keys(self) -> tuple[str, ...]:
        """Its metadata keys, required then optional (``test`` aside)."""
        return self.required_keys + self.optional_keys

    def columns_text(self) -> str:
        """``time_s, knee_angle_deg (required); torque_nm (optional)``."""
        text = ", ".join(self.required_columns) + " (required)"
        if self.optional_columns:
            text += "; " + ", ".join(self.optional_columns) + " (optional)"
        return text


#: The knee angle's accepted range, deg of flexion: hyperextension to past full flexion.
ANGLE_RANGE_DEG = (-20.0, 160.0)
_ANGLE_LOW, _ANGLE_HIGH = ANGLE_RANGE_DEG

#: The columns of a recording (one table: name, unit, meaning, accepted range).
COLUMNS: tuple[ColumnSpec, ...] = (
    ColumnSpec("time_s", "s", "time since the start of the recording, strictly increasing, "
               "one sample every 1 / sampling_hz", 0.0, 3600.0),
    ColumnSpec("knee_angle_deg", "deg", "knee flexion (0 = full extension, flexion positive): "
               "a goniometer, an inertial sensor or the device's encoder", *ANGLE_RANGE_DEG),
    ColumnSpec("knee_velocity_deg_s", "deg/s", "knee flexion velocity (a gyroscope), flexion "
               "positive", -2000.0, 2000.0),
    ColumnSpec("torque_nm", "Nm", "torque the dynamometer (or the exo) applies to the shank, "
               "flexion positive: an extension stretch of resisting flexors reads negative",
               -500.0, 500.0),
)  # fmt: skip
_COLUMNS: Mapping[str, ColumnSpec] = MappingProxyType({c.name: c for c in COLUMNS})

#: The accepted Modified Ashworth grades (Bohannon and Smith 1987).
MAS_GRADES: tuple[str, ...] = ("0", "1", "1+", "2", "3", "4")
#: The postures of the format: seated (hip about 90 deg, trunk upright) or reclined (trunk
#: back, thigh supported horizontal, as the clinic's pendulum test).
POSTURES: tuple[str, ...] = ("seated", "reclined")

#: The metadata keys (one table: key, meaning, accepted values).
KEYS: tuple[KeySpec, ...] = (
    KeySpec("posture", "posture of the test", "choice", POSTURES),
    KeySpec("hip_flexion_deg", "hip flexion during the test", "number", low=0.0, high=130.0,
            unit="deg"),
    KeySpec("sampling_hz", "sampling rate of the rows", "number", low=0.0, high=10_000.0,
            above=True, unit="Hz"),
    KeySpec("speed", "the stretch's speed: slow (V1, slower than the limb falls) or fast "
            "(V3, as fast as possible)", "choice", ("slow", "fast")),
    KeySpec("speed_rad_s", "the stretch's intended speed", "number", low=0.0, high=20.0,
            above=True, unit="rad/s"),
    KeySpec("r1_deg", "Tardieu R1: knee flexion at the catch of the fast stretch (an "
            "extension from the seated rest; R1 >= R2)", "number", low=_ANGLE_LOW,
            high=_ANGLE_HIGH, unit="deg"),
    KeySpec("r2_deg", "Tardieu R2: knee flexion at the end of the slow stretch's passive "
            "range (the popliteal angle)", "number", low=_ANGLE_LOW, high=_ANGLE_HIGH,
            unit="deg"),
    KeySpec("slow_rad_s", "Tardieu V1, the slow stretch's speed", "number", low=0.0, high=20.0,
            above=True, unit="rad/s"),
    KeySpec("fast_rad_s", "Tardieu V3, the fast stretch's speed", "number", low=0.0, high=20.0,
            above=True, unit="rad/s"),
    KeySpec("mas_grade", "Modified Ashworth grade of the knee flexors", "choice", MAS_GRADES),
    KeySpec("side", "the leg tested", "choice", ("right", "left")),
    KeySpec("device", "what the leg wore: nothing, or the exo (its mass and hinge in the "
            "motion)", "choice", ("none", "exo")),
    KeySpec("subject", "the subject's (pseudonymous) identifier"),
    KeySpec("source", "where the recording comes from (clinic, device, program)"),
    KeySpec("note", "a free note"),
    KeySpec("synthetic_level", "synthetic: the twin's spasticity level", "choice",
            tuple(map(str, VALID_LEVELS))),
    KeySpec("synthetic_subject_seed", "synthetic: the seed the subject was drawn with "
            "(absent: the level's nominal Table I subject)", "integer", low=0.0),
    KeySpec("synthetic_subject", "synthetic: the subject's reflex parameters "
            "(SpasticityParams, name=value,...), the truth a fit is held against"),
    KeySpec("synthetic_reflex", "synthetic: the twin's reflex model"),
    KeySpec("synthetic_twin_version", "synthetic: the twin's version (its passive knee and "
            "exo, myoexo.model.TWIN_VERSION)", "integer", low=1.0),
    KeySpec("synthetic_noise", "synthetic: the sensor noise added (SensorNoise, name=value,...)"),
)  # fmt: skip
_KEYS: Mapping[str, KeySpec] = MappingProxyType({k.key: k for k in KEYS})

_COMMON_KEYS = ("side", "device", "subject", "source", "note")
_SYNTHETIC_KEYS = tuple(k.key for k in KEYS if k.key.startswith("synthetic_"))

#: The tests a recording can hold (one table: columns, metadata, posture, sampling, least
#: content).
EXAMS: tuple[ExamSpec, ...] = (
    ExamSpec(
        "pendulum", "Wartenberg pendulum test: the relaxed shank released from extension "
        "swings freely under gravity",
        posture="seated (hip 90 deg) or reclined (trunk back, thigh horizontal): required",
        sampling="from the release (the first row) until the leg rests; 100 Hz or more",
        required_columns=("time_s", "knee_angle_deg"), optional_columns=("knee_velocity_deg_s",),
        required_keys=("posture", "sampling_hz"),
        optional_keys=("hip_flexion_deg", *_COMMON_KEYS, *_SYNTHETIC_KEYS),
        min_samples=20, min_duration_s=1.0,
    ),
    ExamSpec(
        "stretch", "a passive stretch of the relaxed knee, hand-held or instrumented, at one "
        "speed (a slow and a fast stretch: two files)",
        posture="seated unless said (posture, hip_flexion_deg)",
        sampling="the whole motion, holds included; 100 Hz or more",
        required_columns=("time_s", "knee_angle_deg"), optional_columns=("torque_nm",),
        required_keys=("speed", "sampling_hz"),
        optional_keys=("speed_rad_s", "posture", "hip_flexion_deg", *_COMMON_KEYS,
                       *_SYNTHETIC_KEYS),
        min_samples=10, min_duration_s=0.1,
    ),
    ExamSpec(
        "tardieu", "Tardieu test of the knee flexors: the angle of catch R1 at a fast "
        "extension, the passive range R2 at a slow one",
        posture="seated unless said (posture, hip_flexion_deg)",
        sampling="no rows: the two angles are metadata",
        required_keys=("r1_deg", "r2_deg"),
        optional_keys=("slow_rad_s", "fast_rad_s", "posture", "hip_flexion_deg", *_COMMON_KEYS,
                       *_SYNTHETIC_KEYS),
    ),
    ExamSpec(
        "mas", "Modified Ashworth grade of the knee flexors (a passive extension in about 1 s)",
        posture="seated unless said (posture, hip_flexion_deg)",
        sampling="no rows: the grade is metadata",
        required_keys=("mas_grade",),
        optional_keys=("posture", "hip_flexion_deg", *_COMMON_KEYS, *_SYNTHETIC_KEYS),
    ),
)  # fmt: skip
_EXAMS: Mapping[str, ExamSpec] = MappingProxyType({e.test: e for e in EXAMS})

#: The largest deviation of a sampling interval from ``1 / sampling_hz``, relative: 10 %.
SAMPLING_TOLERANCE = 0.10
#: Angles all within +-this (deg) that still move look like radians: the file is refused
#: with that hint (every test moves the knee by more than 3.2 deg).
RADIANS_BOUND = 3.2

_META = re.compile(r"#\s*(?P<key>[A-Za-z_][A-Za-z0-9_]*)\s*:(?P<value>.*)$")


def _tests_text() -> str:
    return ", ".join(_EXAMS)


def _num_text(value: float, decimals: int = 6) -> str:
    """A number as metadata text: rounded to *decimals*, whole numbers without ``.0``."""
    x = round(float(value), decimals)
    return str(int(x)) if x.is_integer() else repr(x)


# ----------------------------------------------------------------------------- checks
_Where = Callable[[int], str]


def _row(i: int) -> str:
    return f"row {i + 1}"


def _check(
    test: str, metadata: Mapping[str, str], columns: Mapping[str, np.ndarray], where: _Where
) -> None:
    """Raise a ``ValueError`` (without the file's name) at the first thing of a recording
    the format refuses; *where(i)* names the sample ``i``."""
    spec = _EXAMS.get(test)
    if spec is None:
        raise ValueError(f"unknown test {test!r}; accepted tests: {_tests_text()}")
    _check_metadata(spec, metadata)
    if not spec.rows:
        if columns:
            raise ValueError(
                f"a {test} recording holds no rows (its values are the metadata "
                f"{', '.join(spec.required_keys)}), got columns {', '.join(columns)}"
            )
        _check_values(spec, metadata)
        return
    _check_columns(spec, metadata, columns, where)


def _check_metadata(spec: ExamSpec, metadata: Mapping[str, str]) -> None:
    for key, value in metadata.items():
        if key == "test":
            raise ValueError("the metadata hold 'test' twice (it is the recording's test)")
        if key not in _KEYS:
            raise ValueError(
                f"unknown metadata key {key!r}; a {spec.test} recording's keys: test, "
                f"{', '.join(spec.keys)}"
            )
        if key not in spec.keys:
            raise ValueError(
                f"metadata key {key!r} is not one of a {spec.test} recording's (test, "
                f"{', '.join(spec.keys)})"
            )
        if not isinstance(value, str) or not value or value != value.strip() or "\n" in value:
            raise ValueError(f"metadata {key} = {value!r}: expected one line of text")
        problem = _KEYS[key].problem(value)
        if problem is not None:
            raise ValueError(f"metadata {key} = {value!r} {problem}")
    missing = [k for k in spec.required_keys if k not in metadata]
    if missing:
        raise ValueError(
            f"missing metadata {', '.join(repr(f'# {k}: ...') for k in missing)}; a "
            f"{spec.test} recording needs {', '.join(spec.required_keys)}"
        )


def _looks_like_radians(values: np.ndarray) -> bool:
    return bool(np.all(np.abs(values) < RADIANS_BOUND) and np.ptp(values) > 0.0)


def _check_values(spec: ExamSpec, metadata: Mapping[str, str]) -> None:
    """The single values of a test without rows: what holds between them."""
    if spec.test == "tardieu":
        r1, r2 = float(metadata["r1_deg"]), float(metadata["r2_deg"])
        if _looks_like_radians(np.array([r1, r2])):
            raise ValueError(
                f"r1_deg = {r1:g} and r2_deg = {r2:g} look like radians (both within "
                f"+-{RADIANS_BOUND:g}): the format takes degrees of knee flexion"
            )
        if r1 < r2:
            raise ValueError(
                f"r1_deg = {r1:g} is below r2_deg = {r2:g}: the catch (R1) comes before the "
                "end of the passive range (R2) along the extension, so in knee flexion "
                "R1 >= R2 (R1 = R2: no catch)"
            )
        if "slow_rad_s" in metadata and "fast_rad_s" in metadata:
            slow, fast = float(metadata["slow_rad_s"]), float(metadata["fast_rad_s"])
            if not slow < fast:
                raise ValueError(f"slow_rad_s = {slow:g} must be below fast_rad_s = {fast:g}")


def _check_columns(
    spec: ExamSpec, metadata: Mapping[str, str], columns: Mapping[str, np.ndarray], where: _Where
) -> None:
    accepted = f"a {spec.test} recording's columns: {spec.columns_text()}"
    for name in columns:
        if name not in spec.columns:
            raise ValueError(f"unknown column {name!r}; {accepted}")
    for name in spec.required_columns:
        if name not in columns:
            raise ValueError(f"missing column {name!r}; {accepted}")
    n = len(columns["time_s"])
    if n < spec.min_samples:
        raise ValueError(
            f"too few samples: {n} rows, a {spec.test} recording needs at least {spec.min_samples}"
        )
    for name in spec.columns:
        if name not in columns:
            continue
        values = columns[name]
        bad = np.flatnonzero(~np.isfinite(values))
        if bad.size:
            i = int(bad[0])
            raise ValueError(f"{name} is {values[i]} at {where(i)}: every value must be finite")
        col = _COLUMNS[name]
        low = -math.inf if col.low is None else col.low
        high = math.inf if col.high is None else col.high
        out = np.flatnonzero((values < low) | (values > high))
        if out.size:
            i = int(out[0])
            raise ValueError(f"{name} = {values[i]:g} at {where(i)} is outside {col.range_text()}")
    angle = columns["knee_angle_deg"]
    if _looks_like_radians(angle):
        raise ValueError(
            f"knee_angle_deg looks like radians: every value within +-{RADIANS_BOUND:g} "
            f"({angle.min():g} to {angle.max():g}) and moving; the format takes degrees of "
            "knee flexion (multiply radians by 180/pi)"
        )
    time = columns["time_s"]
    steps = np.diff(time)
    back = np.flatnonzero(steps <= 0.0)
    if back.size:
        i = int(back[0]) + 1
        raise ValueError(
            f"time_s is not strictly increasing at {where(i)}: {time[i]:g} s after "
            f"{time[i - 1]:g} s"
        )
    duration = float(time[-1] - time[0])
    if duration < spec.min_duration_s:
        raise ValueError(
            f"too short: {duration:g} s, a {spec.test} recording spans at least "
            f"{spec.min_duration_s:g} s"
        )
    period = 1.0 / float(metadata["sampling_hz"])
    off = np.flatnonzero(np.abs(steps - period) > SAMPLING_TOLERANCE * period)
    if off.size:
        i = int(off[0]) + 1
        raise ValueError(
            f"irregular sampling at {where(i)}: {steps[i - 1]:g} s after the previous sample, "
            f"sampling_hz {metadata['sampling_hz']} gives {period:g} s "
            f"+- {SAMPLING_TOLERANCE:.0%}"
        )


# ----------------------------------------------------------------------------- the recording
@dataclasses.dataclass(frozen=True, eq=False)
class Recording:
    """One clinical test of one subject: its test, its metadata and its columns.

    Checked when made (the same checks as :func:`read_recording`'s, a ``ValueError``
    naming what is wrong); two recordings are equal when their test, metadata and columns
    are, value for value.

    Attributes:
        test: The test (a name of :data:`EXAMS`: pendulum, stretch, tardieu, mas).
        metadata: Metadata key -> its value as text (``test`` aside; numbers may be given as
            numbers, they are kept as their text).
        columns: Column name -> its values (float64, read-only), in the order of the
            test's columns; empty for a test of single values.
    """

    test: str
    metadata: Mapping[str, str] = dataclasses.field(default_factory=dict)
    columns: Mapping[str, np.ndarray] = dataclasses.field(default_factory=dict)

    def __post_init__(self) -> None:
        self._make(_row)

    def _make(self, where: _Where) -> None:
        meta: dict[str, str] = {}
        for key, value in self.metadata.items():
            if isinstance(value, bool):
                raise ValueError(f"metadata {key} = {value!r}: expected text or a number")
            meta[str(key)] = _num_text(value, 12) if isinstance(value, (int, float)) else value
        spec = _EXAMS.get(self.test)
        order = spec.columns if spec is not None else ()
        names = [c for c in order if c in self.columns]
        names += [c for c in self.columns if c not in names]
        cols: dict[str, np.ndarray] = {}
        for name in names:
            try:
                values = np.array(self.columns[name], dtype=np.float64)
            except (TypeError, ValueError):
                raise ValueError(f"column {name!r} does not hold numbers") from None
            if values.ndim != 1:
                raise ValueError(f"column {name!r} is not one value per row")
            values.flags.writeable = False
            cols[name] = values
        if len({len(v) for v in cols.values()}) > 1:
            sizes = ", ".join(f"{k} {len(v)}" for k, v in cols.items())
            raise ValueError(f"the columns differ in length ({sizes})")
        _check(self.test, meta, cols, where)
        object.__setattr__(self, "metadata", MappingProxyType(meta))
        object.__setattr__(self, "columns", MappingProxyType(cols))

    @classmethod
    def _checked(
        cls, test: str, metadata: dict[str, str], columns: dict[str, np.ndarray], where: _Where
    ) -> Recording:
        """A recording whose messages name its samples with *where* (the reader's lines)."""
        self = cls.__new__(cls)
        object.__setattr__(self, "test", test)
        object.__setattr__(self, "metadata", metadata)
        object.__setattr__(self, "columns", columns)
        self._make(where)
        return self

    def __eq__(self, other: object) -> bool:
        if not isinstance(other, Recording):
            return NotImplemented
        return (
            self.test == other.test
            and dict(self.metadata) == dict(other.metadata)
            and list(self.columns) == list(other.columns)
            and all(np.array_equal(v, other.columns[k]) for k, v in self.columns.items())
        )

    __hash__ = None  # type: ignore[assignment]

    @property
    def spec(self) -> ExamSpec:
        """What the test's recording holds (:data:`EXAMS`)."""
        return _EXAMS[self.test]

    @property
    def samples(self) -> int:
        """Number of rows (0 for a test of single values)."""
        return len(self.columns["time_s"]) if self.columns else 0

    @property
    def duration_s(self) -> float:
        """Time from the first row to the last, s (0 without rows)."""
        if not self.columns:
            return 0.0
        time = self.columns["time_s"]
        return float(time[-1] - time[0])

    def number(self, key: str) -> float | None:
        """A numeric metadata value (``None`` if absent)."""
        return float(self.metadata[key]) if key in self.metadata else None

    def frame(self) -> pd.DataFrame:
        """The columns as a DataFrame (a copy; no rows for a test of single values)."""
        import pandas as pd

        return pd.DataFrame({k: np.array(v) for k, v in self.columns.items()})

    def synthetic_subject(self) -> SpasticityParams | None:
        """The reflex parameters a synthetic recording was made with (its
        ``synthetic_subject``), ``None`` for a recording of a patient."""
        text = self.metadata.get("synthetic_subject")
        if text is None:
            return None
        items = dict(item.split("=", 1) for item in text.split(","))
        return SpasticityParams(**{k.strip(): float(v) for k, v in items.items()})

    def summary(self) -> str:
        """One line: the test, its samples, duration and ranges (or its values)."""
        m = self.metadata
        if self.test == "tardieu":
            return f"tardieu, R1 {float(m['r1_deg']):g} deg, R2 {float(m['r2_deg']):g} deg"
        if self.test == "mas":
            return f"mas, grade {m['mas_grade']}"
        head = self.test if self.test != "stretch" else f"stretch ({m['speed']})"
        parts = [
            f"{head}, {self.samples} samples at {m['sampling_hz']} Hz, {self.duration_s:.2f} s"
        ]
        for name in self.columns:
            if name == "time_s":
                continue
            values = self.columns[name]
            unit = _COLUMNS[name].unit
            parts.append(f"{name} {values.min():.1f} to {values.max():.1f} {unit}")
        return ", ".join(parts)


# ----------------------------------------------------------------------------- reading
def read_recording(path: str | Path) -> Recording:
    """Read a recording (the module docstring's format).

    Raises:
        ValueError: One line, ``<path>: <what is wrong>``, for a file the format refuses
            (see :data:`EXAMS`, :data:`COLUMNS`, :data:`KEYS`; a sample is named by its
            row and its line). Nothing is changed, dropped or guessed.
        FileNotFoundError: If there is no such file.
    """
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a UTF-8 text file (a CSV recording)") from None
    try:
        return _parse(text)
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from None


def _parse(text: str) -> Recording:
    lines = text.splitlines()
    while lines and not lines[-1].strip():
        lines.pop()
    metadata: dict[str, str] = {}
    meta_lines: dict[str, int] = {}
    i = 0
    for i, line in enumerate(lines):  # after the loop, i is where the rows start
        stripped = line.strip()
        if not stripped.startswith("#"):
            break
        if stripped == "#":
            continue
        match = _META.fullmatch(stripped)
        if match is None:
            raise ValueError(f"line {i + 1}: {stripped!r} is not a '# key: value' line")
        key, value = match["key"], match["value"].strip()
        if not value:
            raise ValueError(f"line {i + 1}: metadata {key!r} has no value")
        if key in metadata:
            raise ValueError(
                f"line {i + 1}: metadata {key!r} given twice (first on line {meta_lines[key]})"
            )
        metadata[key], meta_lines[key] = value, i + 1
    else:
        i = len(lines)
    test = metadata.pop("test", None)
    if test is None:
        raise ValueError(f"no '# test: ...' line; accepted tests: {_tests_text()}")
    spec = _EXAMS.get(test)
    if spec is None:
        raise ValueError(f"unknown test {test!r}; accepted tests: {_tests_text()}")
    _check_metadata(spec, metadata)  # the metadata first, whatever the rows hold
    rest = lines[i:]
    if not spec.rows:
        if rest:
            raise ValueError(
                f"line {i + 1}: a {test} recording holds no rows (its values are the metadata "
                f"{', '.join(spec.required_keys)})"
            )
        return Recording._checked(test, metadata, {}, _row)
    if not rest:
        raise ValueError(f"no header row; a {test} recording's columns: {spec.columns_text()}")
    header_line = i + 1
    header = [name.strip() for name in next(csv.reader([rest[0]]))]
    seen: set[str] = set()
    for name in header:
        if not name:
            raise ValueError(f"line {header_line}: a column without a name")
        if name in seen:
            raise ValueError(f"line {header_line}: column {name!r} given twice")
        seen.add(name)
    rows = list(csv.reader(io.StringIO("\n".join(rest[1:])))) if rest[1:] else []
    values = np.empty((len(rows), len(header)))
    for r, row in enumerate(rows):
        at = f"row {r + 1} (line {header_line + 1 + r})"
        if len(row) != len(header):
            what = "an empty line" if not row else f"{len(row)} values"
            raise ValueError(f"{at}: {what} under {len(header)} columns")
        for c, cell in enumerate(row):
            try:
                values[r, c] = float(cell)
            except ValueError:
                shown = "empty" if not cell.strip() else f"{cell.strip()!r}, not a number"
                raise ValueError(f"{header[c]} is {shown} at {at}") from None

    def where(k: int) -> str:
        return f"row {k + 1} (line {header_line + 1 + k})"

    columns = {name: values[:, c] for c, name in enumerate(header)}
    return Recording._checked(test, metadata, columns, where)


# ----------------------------------------------------------------------------- writing
def recording_text(recording: Recording) -> str:
    """The file's text of *recording* (what :func:`write_recording` writes)."""
    lines = [f"# test: {recording.test}"]
    order = [k.key for k in KEYS]
    for key in sorted(recording.metadata, key=order.index):
        lines.append(f"# {key}: {recording.metadata[key]}")
    if recording.columns:
        names = list(recording.columns)
        lines.append(",".join(names))
        table = np.column_stack([recording.columns[n] for n in names])
        lines.extend(",".join(repr(float(x)) for x in row) for row in table)
    return "\n".join(lines) + "\n"


def write_recording(recording: Recording, path: str | Path) -> Path:
    """Write *recording* to *path* (atomically; its folder is made if missing):
    :func:`read_recording` reads it back equal. Returns the path."""
    from myoexo.runtime.files import write_text_atomic

    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path} is a folder: name the recording's .csv file")
    write_text_atomic(path, recording_text(recording))
    return path


# ----------------------------------------------------------------------------- synthetic
@dataclasses.dataclass(frozen=True)
class SensorNoise:
    """The sensors of a synthetic recording: Gaussian noise on every sample, then an
    optional quantisation (a step of 0: none); every value is then written to 4 decimals.

    Attributes:
        angle_std_deg: Goniometer noise, deg (0.5: an electrogoniometer's or an encoder's
            through the straps).
        velocity_std_deg_s: Gyroscope noise, deg/s.
        torque_std_nm: Torque sensor noise, Nm.
        angle_step_deg: Angle resolution, deg (0: none).
        torque_step_nm: Torque resolution, Nm (0: none).
    """

    angle_std_deg: float = option(0.5, "goniometer noise (std)", low=0.0, unit="deg")
    velocity_std_deg_s: float = option(
        2.0, "gyroscope noise (std)", low=0.0, unit="deg/s", metavar="DEG_S"
    )
    torque_std_nm: float = option(0.5, "torque sensor noise (std)", low=0.0, unit="Nm")
    angle_step_deg: float = option(0.0, "angle resolution (0: none)", low=0.0, unit="deg")
    torque_step_nm: float = option(0.0, "torque resolution (0: none)", low=0.0, unit="Nm")

    def __post_init__(self) -> None:
        check_fields(self)

    def text(self) -> str:
        """``angle_std_deg=0.5,...``: the ``synthetic_noise`` metadata."""
        return ",".join(
            f"{f.name}={_num_text(getattr(self, f.name))}" for f in dataclasses.fields(self)
        )


@dataclasses.dataclass(frozen=True)
class MASGrading:
    """How a synthetic MAS grade is read from the twin's MAS examination
    (:func:`myoexo.clinical.mas.run_mas_exam`: the resistance in excess of level 0's,
    ``onset_threshold_nm`` = 10 Nm counting as felt), after Bohannon and Smith (1987):

    * ``0``: no felt excess anywhere;
    * ``1``: felt over less than half of the range, only from ``end_position`` on (a catch
      or minimal resistance at the end of the range);
    * ``1+``: felt over less than half of the range, from earlier on;
    * ``2``: felt over half of the range or more;
    * ``3``: that, with a mean excess of ``considerable_nm`` or more (considerable
      increase in tone);
    * ``4``: the knee does not get past ``rigid_position`` of the range (rigid).

    Attributes:
        end_position: Range position from which a felt excess is "at the end of the range".
        considerable_nm: Mean excess over the range that is a considerable increase, Nm
            (35: between the nominal levels 2 and 3 of the default twin, 32 and 40 Nm).
        rigid_position: Range position the knee must pass not to be rigid.
    """

    end_position: float = option(
        0.75, "range position from which a catch is at the end", low=0.0, high=1.0
    )
    considerable_nm: float = option(
        35.0,
        "mean excess over level 0 that is a considerable increase",
        low=0.0,
        above=True,
        unit="Nm",
    )
    rigid_position: float = option(0.5, "range position the knee must pass not to be rigid",
                                   low=0.0, high=1.0)  # fmt: skip

    def __post_init__(self) -> None:
        check_fields(self)

    def grade(self, row: Mapping[Any, Any]) -> str:
        """The grade of one level's row of :meth:`myoexo.clinical.mas.MASExamResult.table`."""
        if float(row["reached_position"]) < self.rigid_position:
            return "4"
        onset = float(row["onset_position"])
        if math.isnan(onset):
            return "0"
        if float(row["resisted_fraction"]) < 0.5:
            return "1" if onset >= self.end_position else "1+"
        return "3" if float(row["excess_mean_nm"]) >= self.considerable_nm else "2"


#: What :func:`record_from_twin` records: name -> (the recording's test, the stretch's
#: speed).
RECORDABLE: Mapping[str, tuple[str, str | None]] = MappingProxyType(
    {
        "pendulum": ("pendulum", None),
        "stretch-slow": ("stretch", "slow"),
        "stretch-fast": ("stretch", "fast"),
        "tardieu": ("tardieu", None),
        "mas": ("mas", None),
    }
)
_DECIMALS = 4


def _sense(values: Any, std: float, step: float, rng: np.random.Generator) -> np.ndarray:
    x = np.asarray(values, dtype=np.float64) + std * rng.standard_normal(len(values))
    if step > 0.0:
        x = np.round(x / step) * step
    return np.round(x, _DECIMALS)


def _subject_text(subject: SpasticityParams) -> str:
    return ",".join(f"{f.name}={getattr(subject, f.name)!r}" for f in dataclasses.fields(subject))


def record_from_twin(
    test: str,
    level: int,
    subject_seed: int | None = None,
    *,
    noise: SensorNoise = SensorNoise(),
    reflex: str | ReflexModel = DEFAULT_REFLEX,
    posture: str = "seated",
    params: PendulumParams | TardieuParams | MASExamParams | None = None,
    grading: MASGrading = MASGrading(),
) -> Recording:
    """A synthetic recording of a clinical test on the twin.

    The subject is the one ``myoexo clinic <test> --levels L --subject-seed S`` runs
    (:func:`~myoexo.clinical.common.draw_subjects` of the level alone; no seed: the
    level's nominal Table I subject), wearing the exo (``device: exo``, right leg). What is
    sampled, every control step (100 Hz):

    * ``pendulum``: :func:`~myoexo.clinical.pendulum.run_pendulum` (seated or reclined),
      the free swing from the release on: knee angle and velocity;
    * ``stretch-slow`` / ``stretch-fast``: the Tardieu test's slow (V1) or fast (V3)
      extension (:func:`~myoexo.clinical.stretch.simulate_stretch`), holds included: knee
      angle and the exo's torque;
    * ``tardieu``: :func:`~myoexo.clinical.tardieu.run_tardieu`'s R1 and R2, each read
      with the goniometer's noise (no catch: R1 = R2; a noisy R1 below R2 is recorded as
      R2, as an examiner would);
    * ``mas``: the grade :class:`MASGrading` reads from
      :func:`~myoexo.clinical.mas.run_mas_exam` (no noise).

    The noise is drawn from a generator seeded with the subject seed and the test, so the
    same arguments give the same recording. The metadata record how it was made
    (``synthetic_level``, ``synthetic_subject_seed``, ``synthetic_subject``: the reflex
    parameters, ``synthetic_reflex``, ``synthetic_twin_version``, ``synthetic_noise``).

    Args:
        test: A name of :data:`RECORDABLE`.
        level: Spasticity level of the twin.
        subject_seed: Seed of the subject's draw (``None``: the nominal subject).
        noise: The sensors' noise.
        reflex: Reflex model of the twin.
        posture: ``seated`` or ``reclined`` (the pendulum only).
        params: The test's parameters (:class:`~myoexo.clinical.pendulum.PendulumParams`,
            :class:`~myoexo.clinical.tardieu.TardieuParams` for the stretches and the
            Tardieu test, :class:`~myoexo.clinical.mas.MASExamParams`; default: the
            clinical test's); their levels are replaced by *level*.
        grading: How the MAS grade is read.

    Raises:
        ValueError: If the test, the level, the posture, the parameters or the reflex is
            not accepted.
    """
    from myoexo.clinical.common import draw_subjects
    from myoexo.model.params import TWIN_VERSION, TwinParams
    from myoexo.spasticity.registry import reflex_label

    if test not in RECORDABLE:
        raise ValueError(f"unknown test {test!r}; recordable: {', '.join(RECORDABLE)}")
    level = check_level(level)
    if posture not in POSTURES:
        raise ValueError(f"posture {posture!r} is not one of {', '.join(POSTURES)}")
    if posture != "seated" and test != "pendulum":
        raise ValueError(f"posture {posture!r}: the twin's {test} test is seated only")
    if subject_seed is not None and (isinstance(subject_seed, bool) or subject_seed < 0):
        raise ValueError(f"subject_seed = {subject_seed!r} must be a whole number >= 0")
    label = reflex_label(reflex)
    subjects = None if subject_seed is None else draw_subjects((level,), int(subject_seed))
    subject = LEVELS[level] if subjects is None else subjects[level]
    kind, speed = RECORDABLE[test]
    entropy = [list(RECORDABLE).index(test)] + ([] if subject_seed is None else [subject_seed])
    rng = np.random.default_rng(entropy)
    meta: dict[str, str] = {
        "posture": posture,
        "hip_flexion_deg": _num_text(TwinParams().hip_flexion_deg),
        "side": "right",
        "device": "exo",
        "source": f"myoexo twin {TWIN_VERSION}, record_from_twin (synthetic)",
        "synthetic_level": str(level),
        "synthetic_subject": _subject_text(subject),
        "synthetic_reflex": label,
        "synthetic_twin_version": str(TWIN_VERSION),
        "synthetic_noise": noise.text(),
    }
    if subject_seed is not None:
        meta["synthetic_subject_seed"] = str(int(subject_seed))
    columns: dict[str, np.ndarray] = {}  # none for a test of single values
    if kind == "pendulum":
        meta_update, columns = _pendulum(level, subjects, reflex, posture, params, noise, rng)
        meta.update(meta_update)
    elif kind == "stretch":
        assert speed is not None
        meta_update, columns = _stretch(level, subject, reflex, speed, params, noise, rng)
        meta.update(meta_update)
    elif kind == "tardieu":
        meta.update(_tardieu(level, subjects, reflex, params, noise, rng))
    else:
        meta.update(_mas(level, subjects, reflex, params, grading))
    return Recording(kind, meta, columns)


def _params_of(params: Any, cls: type, test: str) -> Any:
    if params is None:
        return cls()
    if not isinstance(params, cls):
        raise ValueError(
            f"params for the {test} recording must be {cls.__name__}, got {type(params).__name__}"
        )
    return params


def _times(n: int, dt: float) -> np.ndarray:
    return np.round(np.arange(n) * dt, 9)


def _pendulum(
    level: int,
    subjects: Mapping[int, SpasticityParams] | None,
    reflex: str | ReflexModel,
    posture: str,
    params: Any,
    noise: SensorNoise,
    rng: np.random.Generator,
) -> tuple[dict[str, str], dict[str, np.ndarray]]:
    from myoexo.clinical.pendulum import POSTURES as PRESETS
    from myoexo.clinical.pendulum import PendulumParams, run_pendulum

    p = PRESETS[posture] if params is None else _params_of(params, PendulumParams, "pendulum")
    actual = "seated" if p.recline_deg == 0 else "reclined"
    if params is not None and actual != posture:
        raise ValueError(
            f"posture {posture!r} but the pendulum parameters are {actual} "
            f"(hip_flexion_deg = {p.hip_flexion_deg:g})"
        )
    result = run_pendulum(dataclasses.replace(p, levels=(level,)), reflex=reflex, subjects=subjects)
    swing = result.traces[result.traces["phase"] == "swing"]
    dt = p.drive.control_period_s
    time = swing["time_s"].to_numpy()
    if len(time) > 1:
        dt = float(time[1] - time[0])
    columns = {
        "time_s": _times(len(swing), dt),
        "knee_angle_deg": _sense(swing["knee_deg"], noise.angle_std_deg, noise.angle_step_deg, rng),
        "knee_velocity_deg_s": _sense(swing["knee_vel_deg_s"], noise.velocity_std_deg_s, 0.0, rng),
    }
    meta = {"sampling_hz": _num_text(1.0 / dt), "hip_flexion_deg": _num_text(p.hip_flexion_deg)}
    return meta, columns


def _stretch(
    level: int,
    subject: SpasticityParams,
    reflex: str | ReflexModel,
    speed: str,
    params: Any,
    noise: SensorNoise,
    rng: np.random.Generator,
) -> tuple[dict[str, str], dict[str, np.ndarray]]:
    from myoexo.clinical.common import default_twin
    from myoexo.clinical.stretch import simulate_stretch
    from myoexo.clinical.tardieu import TardieuParams

    tardieu = _params_of(params, TardieuParams, f"stretch-{speed}")
    vel = tardieu.slow_rad_s if speed == "slow" else tardieu.fast_rad_s
    model, pose = default_twin()
    trace = simulate_stretch(
        model, level, vel, tardieu.stretch(vel), pose=pose, subject=subject, reflex=reflex
    )
    time = trace["time_s"].to_numpy()
    dt = float(time[1] - time[0])
    columns = {
        "time_s": _times(len(trace), dt),
        "knee_angle_deg": _sense(trace["knee_deg"], noise.angle_std_deg, noise.angle_step_deg, rng),
        "torque_nm": _sense(trace["exo_torque_nm"], noise.torque_std_nm, noise.torque_step_nm, rng),
    }
    meta = {"sampling_hz": _num_text(1.0 / dt), "speed": speed, "speed_rad_s": _num_text(vel)}
    return meta, columns


def _tardieu(
    level: int,
    subjects: Mapping[int, SpasticityParams] | None,
    reflex: str | ReflexModel,
    params: Any,
    noise: SensorNoise,
    rng: np.random.Generator,
) -> dict[str, str]:
    from myoexo.clinical.tardieu import TardieuParams, run_tardieu

    p = _params_of(params, TardieuParams, "tardieu")
    result = run_tardieu(dataclasses.replace(p, levels=(level,)), reflex=reflex, subjects=subjects)
    table = result.table().iloc[0]
    r1, r2 = _sense([table["r1_deg"], table["r2_deg"]], noise.angle_std_deg,
                    noise.angle_step_deg, rng)  # fmt: skip
    r1 = max(r1, r2) if bool(table["catch"]) else r2
    return {
        "r1_deg": _num_text(r1, 1),
        "r2_deg": _num_text(r2, 1),
        "slow_rad_s": _num_text(p.slow_rad_s),
        "fast_rad_s": _num_text(p.fast_rad_s),
    }


def _mas(
    level: int,
    subjects: Mapping[int, SpasticityParams] | None,
    reflex: str | ReflexModel,
    params: Any,
    grading: MASGrading,
) -> dict[str, str]:
    from myoexo.clinical.mas import MASExamParams, run_mas_exam

    p = _params_of(params, MASExamParams, "mas")
    result = run_mas_exam(dataclasses.replace(p, levels=(level,)), reflex=reflex, subjects=subjects)
    return {"mas_grade": grading.grade(result.table().iloc[0].to_dict())}


# ----------------------------------------------------------------------------- docs
def _md_table(header: list[str], rows: list[list[str]]) -> str:
    def cell(text: str) -> str:
        return text.replace("|", "\\|").replace("\n", " ")

    lines = ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    lines += ["| " + " | ".join(cell(c) for c in row) + " |" for row in rows]
    return "\n".join(lines)


def format_markdown() -> str:
    """The format's three tables (:data:`EXAMS`, :data:`COLUMNS`, :data:`KEYS`) as Markdown:
    the documentation's, generated from them."""
    exams = _md_table(
        ["test", "what", "columns", "metadata", "posture", "sampling", "at least"],
        [
            [
                f"`{e.test}`",
                e.what,
                e.columns_text() if e.rows else "none (no rows)",
                ", ".join(f"`{k}`" for k in e.required_keys)
                + " (required); others: "
                + ", ".join(f"`{k}`" for k in e.optional_keys if not k.startswith("synthetic_"))
                + ", `synthetic_*`",
                e.posture,
                e.sampling,
                f"{e.min_samples} rows, {e.min_duration_s:g} s" if e.rows else "-",
            ]
            for e in EXAMS
        ],
    )
    columns = _md_table(
        ["column", "unit", "meaning", "accepted"],
        [[f"`{c.name}`", c.unit, c.meaning, c.range_text()] for c in COLUMNS],
    )

    def tests_of(key: str) -> str:
        tests = [e for e in EXAMS if key in e.keys]
        required = [e.test for e in tests if key in e.required_keys]
        text = "every test" if len(tests) == len(EXAMS) else ", ".join(e.test for e in tests)
        if required and len(required) == len(tests):
            return text + " (required)"
        return text + (f" (required: {', '.join(required)})" if required else "")

    keys = _md_table(
        ["key", "meaning", "accepted", "tests"],
        [[f"`{k.key}`", k.meaning, k.accepted(), tests_of(k.key)] for k in KEYS],
    )
    return (
        f"**The tests** (`# test: NAME`)\n\n{exams}\n\n**The columns**\n\n{columns}\n\n"
        f"**The metadata** (`# key: value`, before the header row; `test` first)\n\n{keys}\n\n"
        f"Sampling: every interval within {SAMPLING_TOLERANCE:.0%} of `1 / sampling_hz`. "
        f"Knee angles all within +-{RADIANS_BOUND:g} that move are refused as radians."
    )


# ----------------------------------------------------------------------------- CLI
@dataclasses.dataclass(frozen=True)
class RecordOptions:
    """What ``myoexo clinic record`` records and where (each field an option; ``--test``,
    ``--level`` and ``--out`` are required)."""

    test: str = option("pendulum", "the test to record", choices=tuple(RECORDABLE))
    level: int = option(0, "spasticity level of the twin", choices=VALID_LEVELS, metavar="L")
    out: Path = option(Path("recording.csv"), "the recording's CSV file", metavar="FILE")
    subject_seed: int | None = option(
        None, "draw the subject with this seed (default: the level's nominal subject)",
        low=0, metavar="N",
    )  # fmt: skip
    posture: str = option("seated", "posture (the pendulum only)", choices=POSTURES)
    reflex: str = option(DEFAULT_REFLEX, "reflex model of the twin", flag="")

    def __post_init__(self) -> None:
        check_fields(self)


_REQUIRED = ("test", "level", "out")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo clinic record``: :class:`RecordOptions`' fields, ``--reflex`` and
    :class:`SensorNoise`'s fields."""
    add_options(parser, RecordOptions)
    for action in parser._actions:
        if action.dest in _REQUIRED:
            action.required = True
            action.default = None
            action.help = (action.help or "").split(" (default:")[0] + " (required)"
    add_reflex_argument(parser, default=DEFAULT_REFLEX)
    add_options(parser, SensorNoise)


def run(args: argparse.Namespace) -> int:
    """Record the test on the twin, write the file, print its summary."""
    options = from_options(RecordOptions, args, reflex=args.reflex)
    noise = from_options(SensorNoise, args)
    if options.out.is_dir():
        raise ValueError(f"--out {options.out} is a folder: name the recording's .csv file")
    recording = record_from_twin(
        options.test,
        options.level,
        options.subject_seed,
        noise=noise,
        reflex=options.reflex,
        posture=options.posture,
    )
    path = write_recording(recording, options.out)
    print(f"wrote {path}: {recording.summary()}")
    return 0
