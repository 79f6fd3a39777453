"""``myoexo twin fit-subject``: a personal twin fitted to one patient's clinical recordings.

The recordings are the files of :mod:`myoexo.clinical.recording` (a pendulum test, a slow
and a fast passive stretch, the Tardieu angles, the MAS grade; any subset, one file each).
The twin replays each test on a candidate subject and the fit moves the candidate until the
replays match the recordings::

    myoexo twin fit-subject slow.csv fast.csv pendulum.csv tardieu.csv mas.csv \\
        --out subject.json [--level L] [--budget 1000] [--popsize 10] [--seed 1]

**What is fitted** (:data:`PARAMETERS`, each with its bounds, unit and meaning). The subject
record of the reflex, :class:`~myoexo.spasticity.SpasticityParams`, is what varies from one
subject to the next in the twin (:func:`~myoexo.spasticity.sample_subject`): the windows of
the angle and velocity terms, their two gains and the sigmoid slope, seven numbers. The
default reflex (``"spindle_tone"``) maps them onto each muscle's fibre state with the
level's calibration (its fitted per-level parameters, ``myoexo twin calibrate``):
the calibration and the 20 ms transmission delay belong to the model and the level, not to
a subject, so they are not fitted; the level is ``--level`` (by default the recordings'
``synthetic_level``, else their MAS grade 0-3). The passive knee is the twin's, not a
subject's: its elastic moment (Riener and Edrich's, built as springs,
:mod:`myoexo.model.passive_knee`) has no ``TwinParams`` field to scale, and its damping is
the twin-wide ``TwinParams.knee_damping_nm_s_rad``. Both are fitted as scales of the built
twin (``stiffness_scale`` multiplies every knee spring's coefficients, ``damping_scale`` the
knee's damping); the report gives the damping as the ``TwinParams`` override it amounts to.
Which recordings inform which parameter::

    theta_ext_deg     slow stretch (the flexors' tone near the end of the range),
                      Tardieu R2; fast stretch
    theta_flex_deg    every stretch's start at 90 deg (the extensors' tone), the
                      pendulum's resting angle
    v_lower_rad_s     fast stretch (the catch), Tardieu R1, MAS grade
    v_upper_rad_s     pendulum (the shank falls into flexion); nothing else flexes fast
    s_theta           slow stretch's torque, pendulum's resting angle
    s_v               fast stretch's torque, Tardieu R1, MAS grade
    k                 the shape of every onset: all of them
    stiffness_scale   slow stretch's torque (passive at that speed), pendulum's resting
                      angle and frequency
    damping_scale     pendulum's decay (small beside the exo's and the muscles' own)

**Objective.** Each time series (a stretch, the pendulum's swing) is replayed on the
candidate: the stretch by the clinical stretch test at the recording's speed
(:func:`~myoexo.clinical.stretch.simulate_stretch`, the Tardieu test's protocol from the
seated rest), the pendulum by the twin's pendulum test in the recording's posture. The twin
is sampled at the recording's times (where both run) and the trace contributes its RMS
angle error (deg) plus ``torque_weight`` x its RMS torque error (Nm) where the recording has
torque. A Tardieu recording adds ``tardieu_weight`` x (|R1 error| + |R2 error|) (deg; the
replay's R1 and R2 come from the same two stretches, free when the stretch recordings were
taken at the Tardieu speeds), a MAS recording ``mas_weight`` x the number of grades between
the recorded grade and the replay's (:class:`~myoexo.clinical.recording.MASGrading`, the
excess over level 0 on the same candidate twin). The objective is their sum.

**Optimiser: CMA-ES** (Hansen's ``cma`` package). The objective has no gradient to follow:
each evaluation is a MuJoCo simulation with contacts, range stops and a saturating motor,
the reflex's windows are steep sigmoids, and the Tardieu and MAS terms are steps. CMA-ES
needs only objective values, ranks candidates instead of differencing them (a step or a
kink does not mislead it), is robust for the few parameters here (9), keeps every
candidate inside the bounds (its ``bounds`` option) and is the standard choice for this
kind of black-box fit. Every parameter is searched normalised to [0, 1] inside its bounds
(on a log scale for the scales and the slope ``k``), from the level's nominal subject with
the twin's own passive knee (scales 1), with step ``sigma0``; ``--seed`` seeds it,
``--budget`` bounds the number of objective evaluations (whole generations of
``--popsize``).

**Uncertainty: curvature of the objective** (a finite-difference Hessian, ``--uncertainty
hessian``; ``diagonal`` computes its diagonal only, 2n + 1 evaluations instead of 2n^2 + 1).
The Hessian ``H`` of the time-series part of the objective (the Tardieu and MAS steps have
no curvature) is taken by central differences in the normalised coordinates, step
``fd_step``, at the fit (moved one step inside the bounds where it lies closer to them).
A parameter's interval is where the objective rises by at most ``rise`` (5 %) of its value
there: the half-width ``sqrt(2 rise f H^-1_jj)`` (marginal: the other parameters may
compensate) and ``sqrt(2 rise f / H_jj)`` (conditional: the others held). The rise is a
tolerance, not a likelihood: the residuals of a fit are mostly model error and correlated in
time, so no noise model gives an honest confidence level (on synthetic subjects the truth
fell outside several intervals: they say how sharply the recordings constrain a parameter,
not what they cover). The report also gives CMA-ES's
own final spread per parameter (``sigma`` x the square root of its covariance's diagonal).

**Identifiability.** A parameter is *not identifiable* from the recordings when its
marginal interval spans more than half of its bounds (half-width above
:data:`IDENTIFIABLE_HALF_WIDTH` = 0.25 normalised; conditional in ``diagonal`` mode), when
the objective is flat or concave along it (``H_jj <= 0`` or a flat direction of ``H`` that
involves it), or when no time series was recorded.

**Long fits.** A progress bar counts the evaluations. After every generation the CMA-ES
state (and the random generator's) is pickled to ``<out>.partial``; the same command run
again continues from it (a larger ``--budget`` continues further; other recordings or
settings are refused). Ctrl-C (or SIGTERM) stops at the end of the current evaluation, the
partial file stays, and the command exits 130 (143). The finished fit writes ``--out`` and
removes the partial file.

**The report** (``--out``, JSON, and printed): the fitted subject and passive knee, each
parameter's start, fit, interval and identifiability (and the truth of a synthetic
recording), each trace's RMS errors at the start and at the fit next to van der Krogt et
al. 2016's 1.1 deg (slow stretch) and 5.9 deg (fast stretch), the single values recorded
and replayed, the optimiser's record and the provenance (the command, each recording's
sha256, the package versions, the budget and the seed).

A recording the reader refuses stops the command before any simulation: one line naming
the file and the problem, exit status 2, nothing written.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import pickle
import shlex
import sys
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.model.passive_knee import scale_passive_knee
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    check_fields,
    from_options,
    option,
    option_words,
)
from myoexo.runtime.files import file_sha256
from myoexo.spasticity.levels import LEVELS, VALID_LEVELS, SpasticityParams
from myoexo.spasticity.personal import PASSIVE_SCALES, from_unit, to_unit
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import add_reflex_argument

if TYPE_CHECKING:
    import mujoco

    from myoexo.clinical.recording import Recording

__all__ = [
    "IDENTIFIABLE_HALF_WIDTH",
    "PARAMETERS",
    "VAN_DER_KROGT_2016_RMS_DEG",
    "Evaluation",
    "FitParameter",
    "FitSettings",
    "FitStopped",
    "SubjectObjective",
    "Target",
    "add_arguments",
    "fit_subject",
    "format_report",
    "partial_path",
    "read_targets",
    "run",
    "scale_passive_knee",
]


# ----------------------------------------------------------------------------- parameters
@dataclasses.dataclass(frozen=True)
class FitParameter:
    """One fitted parameter.

    Attributes:
        name: Its name (a :class:`~myoexo.spasticity.SpasticityParams` field, or
            ``stiffness_scale`` / ``damping_scale`` of the passive knee).
        low: Lower bound.
        high: Upper bound.
        unit: Unit (``-``: none).
        meaning: What it is.
        informed_by: The recordings that inform it (module docstring).
        log: Searched on a log scale (a positive quantity that varies by factors).
    """

    name: str
    low: float
    high: float
    unit: str
    meaning: str
    informed_by: str
    log: bool = False

    def __post_init__(self) -> None:
        if not self.low < self.high or (self.log and self.low <= 0.0):
            raise ValueError(f"FitParameter {self.name}: bounds [{self.low}, {self.high}]")

    @property
    def passive(self) -> bool:
        """Whether it is a parameter of the passive knee (not of the reflex)."""
        return self.name in PASSIVE_NAMES

    def normalise(self, value: float) -> float:
        """*value* as its position in [0, 1] inside the bounds (clipped)."""
        return to_unit(value, self.low, self.high, self.log)

    def value(self, u: float) -> float:
        """The value at the position *u* in [0, 1] (clipped)."""
        return from_unit(u, self.low, self.high, self.log)


#: The passive knee's fitted scales.
PASSIVE_NAMES: tuple[str, ...] = tuple(PASSIVE_SCALES)

#: The parameters a fit can move, their bounds (levels 1-3 of Table I with their 10 %
#: spread, and room), units and meaning.
PARAMETERS: tuple[FitParameter, ...] = (
    FitParameter("theta_ext_deg", -50.0, 0.0, "deg",
                 "Table I's extension-side angle limit; the flexors' angle threshold is it "
                 "plus the level's calibrated shift", "slow stretch, Tardieu R2, fast stretch"),
    FitParameter("theta_flex_deg", 40.0, 110.0, "deg",
                 "flexion-side angle limit: the extensors' angle threshold",
                 "every stretch's start, pendulum resting angle"),
    FitParameter("v_lower_rad_s", -1.5, -0.1, "rad/s",
                 "extension-side velocity limit: the flexors' velocity threshold",
                 "fast stretch, Tardieu R1, MAS"),
    FitParameter("v_upper_rad_s", 0.1, 1.5, "rad/s",
                 "flexion-side velocity limit: the extensors' velocity threshold", "pendulum"),
    FitParameter("s_theta", 0.0, 0.6, "-", "gain of the angle term (fraction of the "
                 "muscles' peak force)", "slow stretch, pendulum resting angle"),
    FitParameter("s_v", 0.0, 1.0, "-", "gain of the velocity term (fraction of the "
                 "muscles' peak force)", "fast stretch, Tardieu R1, MAS, pendulum"),
    FitParameter("k", 0.03, 1.0, "1/deg, s/rad", "slope of the windows' sigmoids",
                 "all (the shape of each onset)", log=True),
    FitParameter("stiffness_scale", 0.5, 3.0, "-",
                 "factor on the passive knee's elastic moment (Riener and Edrich's springs)",
                 "slow stretch torque, pendulum resting angle and frequency", log=True),
    FitParameter("damping_scale", 0.25, 10.0, "-",
                 "factor on the knee's viscous damping (TwinParams.knee_damping_nm_s_rad)",
                 "pendulum decay", log=True),
)  # fmt: skip
_BY_NAME: Mapping[str, FitParameter] = {p.name: p for p in PARAMETERS}
PARAMETER_NAMES: tuple[str, ...] = tuple(p.name for p in PARAMETERS)

#: van der Krogt et al. 2016 (J NeuroEng Rehabil 13:64): the RMS angle error of their
#: neuromusculoskeletal model against instrumented slow and fast passive stretches, deg.
VAN_DER_KROGT_2016_RMS_DEG: Mapping[str, float] = {"slow": 1.1, "fast": 5.9}

#: A parameter whose interval's half-width exceeds this (normalised: a quarter of its
#: bounds, so the interval spans more than half of them) is not identifiable.
IDENTIFIABLE_HALF_WIDTH = 0.25

#: The objective of a candidate whose replay fails (a simulation that diverges).
_FAILED = 1e3
#: The partial state's format.
_PARTIAL_VERSION = 1


# ----------------------------------------------------------------------------- settings
@dataclasses.dataclass(frozen=True)
class FitSettings:
    """How ``myoexo twin fit-subject`` fits (each field an option; the recordings are the
    command's positional arguments)."""

    out: Path = option(Path("subject.json"), "the fit's report (JSON)", metavar="FILE")
    level: int | None = option(
        None,
        "spasticity level whose calibration the subject's reflex uses (default: the "
        "recordings' synthetic_level, else their MAS grade 0-3)",
        choices=VALID_LEVELS,
        metavar="L",
    )
    reflex: str = option(DEFAULT_REFLEX, "reflex model of the twin", flag="")
    budget: int = option(
        1000, "objective evaluations of CMA-ES (whole generations)", low=1, metavar="N"
    )
    popsize: int = option(10, "CMA-ES population per generation", low=2, high=1000, metavar="N")
    sigma0: float = option(
        0.1, "CMA-ES's initial step, normalised (bounds = [0, 1])",
        low=0.0, above=True, high=0.5, metavar="STEP",
    )  # fmt: skip
    seed: int = option(1, "seed of CMA-ES's sampling", low=1)
    parameters: tuple[str, ...] = option(
        PARAMETER_NAMES,
        "the parameters fitted (the others stay at the start: the level's nominal subject, "
        "scales 1)",
        choices=PARAMETER_NAMES,
        metavar="NAME",
    )
    torque_weight: float = option(
        1.0,
        "objective (deg) per Nm of a trace's RMS torque error",
        low=0.0,
        unit="deg/Nm",
        metavar="WEIGHT",
    )
    tardieu_weight: float = option(
        0.1,
        "objective (deg) per deg of Tardieu R1 or R2 error",
        low=0.0,
        unit="deg/deg",
        metavar="WEIGHT",
    )
    mas_weight: float = option(
        1.0, "objective (deg) per MAS grade of error", low=0.0, unit="deg", metavar="WEIGHT"
    )
    uncertainty: str = option(
        "hessian",
        "the finite-difference Hessian for the intervals: full (2n^2 + 1 evaluations) or its "
        "diagonal (2n + 1)",
        choices=("hessian", "diagonal"),
        metavar="KIND",
    )
    fd_step: float = option(
        0.02, "finite-difference step, normalised", low=0.0, above=True, high=0.2, metavar="STEP"
    )
    rise: float = option(
        0.05, "relative rise of the objective that bounds a parameter's interval",
        low=0.0, above=True, high=1.0, metavar="FRACTION",
    )  # fmt: skip
    progress: bool = option(True, "show a progress bar")

    def __post_init__(self) -> None:
        check_fields(self)
        object.__setattr__(self, "parameters", tuple(dict.fromkeys(self.parameters)))
        if not self.parameters:
            raise FieldError(type(self).__name__, "parameters", (), "is empty: name one")
        if self.budget < self.popsize:
            raise ValueError(
                f"--budget {self.budget} is below --popsize {self.popsize}: CMA-ES evaluates "
                "whole generations"
            )


def partial_path(out: Path) -> Path:
    """Where the fit to *out* keeps its state between generations: ``<out>.partial``."""
    return out.with_name(out.name + ".partial")


class FitStopped(Exception):
    """The fit stopped on a signal; its state is in the partial file."""

    def __init__(self, path: Path, evaluations: int) -> None:
        super().__init__(f"stopped after {evaluations} evaluations; state kept in {path}")
        self.path = path
        self.evaluations = evaluations


# ----------------------------------------------------------------------------- recordings
@dataclasses.dataclass(frozen=True)
class Target:
    """One recording and what the twin replays of it.

    Attributes:
        path: Its file.
        recording: What the file holds.
        kind: Its test (``stretch``, ``pendulum``, ``tardieu``, ``mas``).
        label: The test as ``myoexo clinic record`` names it (``stretch-slow``,
            ``pendulum-seated``, ...).
    """

    path: Path
    recording: Recording
    kind: str
    label: str

    @property
    def series(self) -> bool:
        """Whether it is a time series (a stretch, the pendulum)."""
        return self.kind in ("stretch", "pendulum")


def read_targets(paths: Sequence[Path]) -> list[Target]:
    """The recordings *paths*, read (a bad file: the reader's ``ValueError``)."""
    from myoexo.clinical.recording import read_recording

    targets = []
    for path in paths:
        rec = read_recording(path)
        label = rec.test
        if rec.test == "stretch":
            label = f"stretch-{rec.metadata['speed']}"
        elif rec.test == "pendulum":
            label = f"pendulum-{rec.metadata['posture']}"
        targets.append(Target(Path(path), rec, rec.test, label))
    return targets


def _level_of(targets: Sequence[Target], level: int | None) -> int:
    if level is not None:
        return level
    synthetic = {
        t.recording.metadata["synthetic_level"]
        for t in targets
        if "synthetic_level" in t.recording.metadata
    }
    if len(synthetic) > 1:
        raise ValueError(
            f"the recordings were made at different levels ({', '.join(sorted(synthetic))}): "
            "give --level"
        )
    if synthetic:
        return int(synthetic.pop())
    grades = {t.recording.metadata["mas_grade"] for t in targets if t.kind == "mas"}
    if len(grades) == 1 and (grade := grades.pop()) in ("0", "1", "2", "3"):
        return int(grade)
    raise ValueError(
        "no level: give --level L (the recordings carry no synthetic_level and no MAS grade "
        "of 0-3); the level picks the calibration of the reflex the subject is fitted under"
    )


# ----------------------------------------------------------------------------- the objective
@dataclasses.dataclass(frozen=True)
class Evaluation:
    """The objective of one candidate and its parts.

    Attributes:
        objective: The whole objective (deg).
        smooth: Its time-series part (the traces' RMS terms; what the Hessian differences).
        traces: Per time-series recording: ``file, test, angle_rms_deg`` and, where the
            recording has torque, ``torque_rms_nm``.
        values: Per single-value recording: ``file, test``, what was recorded and what the
            replay gave.
    """

    objective: float
    smooth: float
    traces: tuple[dict[str, Any], ...] = ()
    values: tuple[dict[str, Any], ...] = ()


def _rms(a: np.ndarray, b: np.ndarray) -> float:
    return float(np.sqrt(np.mean((a - b) ** 2)))


def _on_times(times: np.ndarray, sim_t: np.ndarray, sim_v: np.ndarray) -> np.ndarray:
    return np.interp(times, sim_t, sim_v)


class SubjectObjective:
    """The objective of a fit (module docstring): the recordings replayed on a candidate.

    Args:
        targets: The recordings.
        level: The level whose calibration applies.
        reflex: The reflex model.
        settings: The weights.
    """

    def __init__(
        self, targets: Sequence[Target], level: int, reflex: str, settings: FitSettings
    ) -> None:
        from myoexo.clinical.common import twin_model

        self.targets = list(targets)
        self.level = level
        self.reflex = reflex
        self.settings = settings
        self._seated = twin_model()
        self._pendulum_models: dict[float, mujoco.MjModel] = {}

    # -- the candidate
    def start(self) -> dict[str, float]:
        """The start point: the level's nominal subject, scales 1."""
        values = {f.name: float(getattr(LEVELS[self.level], f.name)) for f in _subject_fields()}
        values.update({name: 1.0 for name in PASSIVE_NAMES})
        return values

    @staticmethod
    def subject(values: Mapping[str, float]) -> SpasticityParams:
        """The reflex parameters of *values*."""
        return SpasticityParams(**{f.name: values[f.name] for f in _subject_fields()})

    # -- replays
    def _stretch(self, model: mujoco.MjModel, subject: SpasticityParams, speed: float) -> Any:
        from myoexo.clinical.stretch import simulate_stretch
        from myoexo.clinical.tardieu import TardieuParams
        from myoexo.model import pose_twin

        params = TardieuParams().stretch(speed)
        trace = simulate_stretch(
            model, self.level, speed, params, pose=pose_twin, subject=subject, reflex=self.reflex
        )
        trace["leg_resisting_nm"] = -params.direction * trace["leg_torque_nm"]
        return trace

    def _pendulum(
        self, values: Mapping[str, float], subject: SpasticityParams, rec: Recording
    ) -> tuple[np.ndarray, np.ndarray]:
        from myoexo.clinical.common import control_substeps, simulate_drive, twin_model
        from myoexo.clinical.pendulum import POSTURES, reclined_gravity
        from myoexo.model import TwinParams, pose_twin

        p = POSTURES[rec.metadata["posture"]]
        hip = rec.number("hip_flexion_deg")
        if hip is not None:
            p = dataclasses.replace(p, hip_flexion_deg=hip)
        base = self._pendulum_models.get(p.hip_flexion_deg)
        if base is None:
            base = twin_model(TwinParams(hip_flexion_deg=p.hip_flexion_deg))
            base.opt.gravity[:] = reclined_gravity(p.recline_deg)
            self._pendulum_models[p.hip_flexion_deg] = base
        model = scale_passive_knee(base, values["stiffness_scale"], values["damping_scale"])
        _, dt = control_substeps(p.drive, model)
        n_hold, n_swing = round(p.hold_s / dt), round(p.swing_s / dt)
        ref = np.full(n_hold + n_swing, p.start_deg)
        _, col = simulate_drive(
            model, self.level, ref, np.zeros_like(ref), pose=pose_twin, start_deg=p.start_deg,
            powered=np.arange(len(ref)) < n_hold, drive=p.drive, reflex=self.reflex,
            subject=subject,
        )  # fmt: skip
        return np.arange(n_swing) * dt, col["knee_deg"][n_hold:]

    def __call__(self, values: Mapping[str, float], single_values: bool = True) -> Evaluation:
        """Replay every recording on the candidate *values* (every name of
        :data:`PARAMETERS`); *single_values*: the Tardieu and MAS terms too."""
        try:
            return self._evaluate(values, single_values)
        except (ValueError, FloatingPointError, RuntimeError):
            return Evaluation(_FAILED, _FAILED)

    def _evaluate(self, values: Mapping[str, float], single_values: bool) -> Evaluation:
        s = self.settings
        subject = self.subject(values)
        seated = scale_passive_knee(
            self._seated, values["stiffness_scale"], values["damping_scale"]
        )
        stretches: dict[float, Any] = {}

        def stretch(speed: float) -> Any:
            if speed not in stretches:
                stretches[speed] = self._stretch(seated, subject, speed)
            return stretches[speed]

        traces: list[dict[str, Any]] = []
        found: list[dict[str, Any]] = []
        smooth = penalty = 0.0
        for t in self.targets:
            rec, m = t.recording, t.recording.metadata
            row: dict[str, Any] = {"file": t.path.name, "test": t.label}
            if t.kind == "stretch":
                speed = rec.number("speed_rad_s") or _default_speed(m["speed"])
                trace = stretch(speed)
                sim_t = trace["time_s"].to_numpy()
                times = rec.columns["time_s"]
                inside = times <= sim_t[-1]
                row["angle_rms_deg"] = _rms(
                    rec.columns["knee_angle_deg"][inside],
                    _on_times(times[inside], sim_t, trace["knee_deg"].to_numpy()),
                )
                cost = row["angle_rms_deg"]
                if "torque_nm" in rec.columns:
                    row["torque_rms_nm"] = _rms(
                        rec.columns["torque_nm"][inside],
                        _on_times(times[inside], sim_t, trace["exo_torque_nm"].to_numpy()),
                    )
                    cost += s.torque_weight * row["torque_rms_nm"]
                row["samples"] = int(inside.sum())
            elif t.kind == "pendulum":
                sim_t, knee = self._pendulum(values, subject, rec)
                times = rec.columns["time_s"]
                inside = times <= sim_t[-1]
                row["angle_rms_deg"] = _rms(
                    rec.columns["knee_angle_deg"][inside], _on_times(times[inside], sim_t, knee)
                )
                row["samples"] = int(inside.sum())
                cost = row["angle_rms_deg"]
            else:
                if single_values:
                    row.update(self._single(t, seated, subject, stretch))
                    penalty += row.pop("_penalty")
                    found.append(row)
                continue
            if not math.isfinite(cost):
                return Evaluation(_FAILED, _FAILED)
            smooth += cost
            traces.append(row)
        objective = smooth + penalty
        if not math.isfinite(objective):
            return Evaluation(_FAILED, _FAILED)
        return Evaluation(objective, smooth, tuple(traces), tuple(found))

    def _single(
        self,
        t: Target,
        seated: mujoco.MjModel,
        subject: SpasticityParams,
        stretch: Callable[[float], Any],
    ) -> dict[str, Any]:
        from myoexo.clinical.recording import MAS_GRADES, MASGrading

        s, rec = self.settings, t.recording
        if t.kind == "tardieu":
            from myoexo.clinical.tardieu import TardieuParams, analyse_tardieu

            defaults = TardieuParams()
            slow = rec.number("slow_rad_s") or defaults.slow_rad_s
            fast = rec.number("fast_rad_s") or defaults.fast_rad_s
            p = TardieuParams(slow_rad_s=slow, fast_rad_s=fast)
            got = analyse_tardieu(stretch(slow), stretch(fast), p)
            r1, r2 = float(rec.metadata["r1_deg"]), float(rec.metadata["r2_deg"])
            error = abs(got["r1_deg"] - r1) + abs(got["r2_deg"] - r2)
            return {
                "recorded": {"r1_deg": r1, "r2_deg": r2},
                "replayed": {"r1_deg": got["r1_deg"], "r2_deg": got["r2_deg"]},
                "error": error,
                "_penalty": s.tardieu_weight * error,
            }
        from myoexo.clinical.mas import MASExamParams, run_mas_exam
        from myoexo.model import pose_twin

        result = run_mas_exam(
            MASExamParams(levels=(self.level,)), reflex=self.reflex,
            subjects={self.level: subject}, model=seated, pose=pose_twin,
        )  # fmt: skip
        grade = MASGrading().grade(result.table().iloc[0].to_dict())
        recorded = rec.metadata["mas_grade"]
        steps = abs(MAS_GRADES.index(grade) - MAS_GRADES.index(recorded))
        return {
            "recorded": {"mas_grade": recorded},
            "replayed": {"mas_grade": grade},
            "error": steps,
            "_penalty": s.mas_weight * steps,
        }


def _subject_fields() -> tuple[dataclasses.Field[Any], ...]:
    return dataclasses.fields(SpasticityParams)


def _default_speed(speed: str) -> float:
    from myoexo.clinical.tardieu import TardieuParams

    p = TardieuParams()
    return p.slow_rad_s if speed == "slow" else p.fast_rad_s


# ----------------------------------------------------------------------------- the fit
@dataclasses.dataclass
class _State:
    """What ``<out>.partial`` holds between generations."""

    key: str
    es: Any
    rng: Any
    start: Evaluation
    best_u: np.ndarray
    best: Evaluation
    evaluations: int = 0
    generations: int = 0
    history: list[tuple[int, float]] = dataclasses.field(default_factory=list)
    resumed_at: list[int] = dataclasses.field(default_factory=list)
    stop_reason: str = ""
    hessian: dict[tuple[tuple[int, int], ...], float] = dataclasses.field(default_factory=dict)
    hessian_center: Any = None
    version: int = _PARTIAL_VERSION


def _key(shas: Sequence[str], settings: FitSettings, level: int) -> str:
    fixed = {
        k: v
        for k, v in dataclasses.asdict(settings).items()
        if k not in ("out", "budget", "progress")
    }
    doc = {"recordings": list(shas), "settings": fixed, "level": level}
    return hashlib.sha256(json.dumps(doc, sort_keys=True, default=str).encode()).hexdigest()


def _save(path: Path, state: _State) -> None:
    from myoexo.runtime.files import atomic_path

    with atomic_path(path) as tmp:
        tmp.write_bytes(pickle.dumps(state))


def _load(path: Path, key: str) -> _State | None:
    if not path.is_file():
        return None
    try:
        state = pickle.loads(path.read_bytes())
    except Exception as exc:  # a truncated or foreign file
        raise ValueError(
            f"{path}: not a fit's partial state ({type(exc).__name__}): remove it to start over"
        ) from None
    if not isinstance(state, _State) or state.version != _PARTIAL_VERSION:
        raise ValueError(f"{path}: not this version's partial state: remove it to start over")
    if state.key != key:
        raise ValueError(
            f"{path} was made by a fit of other recordings or settings (all but --budget, "
            "--out and --progress must be the same to continue it): remove it to start over"
        )
    return state


def _values(u: np.ndarray, names: Sequence[str], start: Mapping[str, float]) -> dict[str, float]:
    values = dict(start)
    for name, ui in zip(names, u, strict=True):
        values[name] = _BY_NAME[name].value(float(ui))
    return values


def fit_subject(
    paths: Sequence[str | Path],
    settings: FitSettings = FitSettings(),
    *,
    stop: Any = None,
    log: Callable[[str], None] | None = None,
) -> dict[str, Any]:
    """Fit a personal twin to the recordings *paths* (module docstring); write
    ``settings.out`` and return the report.

    Args:
        paths: The recordings (one test each).
        settings: The fit's settings.
        stop: An object whose ``received`` becomes true to stop
            (:class:`~myoexo.runtime.lifecycle.StopSignals`): the fit raises
            :class:`FitStopped` after the evaluation under way, its partial state kept.
        log: Where to say that a fit continues from its partial state.

    Raises:
        ValueError: A recording the reader refuses (``<file>: <problem>``), no level to
            fit at, a partial state of another fit; nothing is written.
        FitStopped: *stop* was received.
    """
    import cma

    from myoexo.spasticity.registry import reflex_label

    files = [Path(p) for p in paths]
    if not files:
        raise ValueError("no recording: name at least one file")
    out = settings.out
    if out.is_dir():
        raise ValueError(f"--out {out} is a folder: name the report's .json file")
    targets = read_targets(files)  # a bad file stops here, before anything is written
    level = _level_of(targets, settings.level)
    reflex = reflex_label(settings.reflex)
    shas = [file_sha256(p) for p in files]
    names = list(settings.parameters)
    objective = SubjectObjective(targets, level, settings.reflex, settings)
    start_values = objective.start()
    u0 = np.array([_BY_NAME[n].normalise(start_values[n]) for n in names])
    part = partial_path(out)
    key = _key(shas, settings, level)
    state = _load(part, key)

    def values_of(u: np.ndarray) -> dict[str, float]:
        return _values(u, names, start_values)

    def stopping() -> bool:
        return stop is not None and bool(getattr(stop, "received", None))

    def check_stop() -> None:
        if stopping():
            raise FitStopped(part, state.evaluations if state is not None else 0)

    if state is None:
        opts = {
            "bounds": [0.0, 1.0], "popsize": settings.popsize, "seed": settings.seed,
            "verbose": -9, "verb_log": 0, "verb_disp": 0, "maxfevals": np.inf,
        }  # fmt: skip
        es = cma.CMAEvolutionStrategy(u0.tolist(), settings.sigma0, opts)
        first = objective(values_of(u0))
        state = _State(key, es, _cma_rng(), first, u0.copy(), first)
        part.parent.mkdir(parents=True, exist_ok=True)
        _save(part, state)
    else:
        state.resumed_at.append(state.evaluations)
        np.random.set_state(state.rng)  # noqa: NPY002 - cma samples from numpy's global RNG
        if log is not None:
            log(f"continuing from {part}: {state.evaluations} evaluations done")

    bar = _bar(settings, state.evaluations)
    try:
        while not state.stop_reason and state.evaluations + settings.popsize <= settings.budget:
            es = state.es
            xs = es.ask()
            evals = []
            for x in xs:
                e = objective(values_of(np.asarray(x)))
                evals.append(e)
                bar.update(1)
                if len(evals) < len(xs):
                    check_stop()
            es.tell(xs, [e.objective for e in evals])
            for x, e in zip(xs, evals, strict=True):
                if e.objective < state.best.objective:
                    state.best, state.best_u = e, np.asarray(x, dtype=float).copy()
            state.evaluations += len(xs)
            state.generations += 1
            state.history.append((state.evaluations, state.best.objective))
            reasons = {k: v for k, v in es.stop().items() if k != "maxfevals"}
            if reasons:
                state.stop_reason = ", ".join(f"{k}={v}" for k, v in reasons.items())
            state.rng = _cma_rng()
            _save(part, state)
            bar.set_postfix(best=f"{state.best.objective:.3f}")
            check_stop()
    finally:
        bar.close()
    hessian = _hessian(objective, state, names, values_of, settings, part, stopping, check_stop)
    report = _report(
        files, shas, targets, settings, level, reflex, names, start_values, state, hessian
    )
    out.parent.mkdir(parents=True, exist_ok=True)
    from myoexo.runtime.files import write_json_atomic

    write_json_atomic(out, report, indent=2)
    part.unlink(missing_ok=True)
    return report


def _cma_rng() -> Any:
    """The state of numpy's global generator, which ``cma`` samples from (its ``seed`` seeds
    it): kept with the CMA-ES state so that a resumed fit samples as an unbroken one."""
    return np.random.get_state()  # noqa: NPY002


def _bar(settings: FitSettings, done: int) -> Any:
    from tqdm.auto import tqdm

    return tqdm(
        total=settings.budget,
        initial=min(done, settings.budget),
        desc="fit-subject",
        unit="eval",
        disable=not settings.progress,
    )


def _hessian(
    objective: SubjectObjective,
    state: _State,
    names: Sequence[str],
    values_of: Callable[[np.ndarray], dict[str, float]],
    settings: FitSettings,
    part: Path,
    stopping: Callable[[], bool],
    check_stop: Callable[[], None],
) -> dict[str, Any]:
    """The finite-difference Hessian of the smooth objective at the fit (module docstring),
    each evaluation kept in the partial state as it is made."""
    n, h = len(names), settings.fd_step
    center = np.clip(state.best_u, h, 1.0 - h)
    moved = bool(np.any(center != state.best_u))
    if state.hessian_center is None or not np.array_equal(state.hessian_center, center):
        state.hessian, state.hessian_center = {}, center  # a continued search moved the fit
    stencils: list[tuple[tuple[int, int], ...]] = [()]
    for j in range(n):
        stencils += [((j, 1),), ((j, -1),)]
    if settings.uncertainty == "hessian":
        for j in range(n):
            for k in range(j + 1, n):
                stencils += [((j, a), (k, b)) for a in (1, -1) for b in (1, -1)]
    if not moved:
        state.hessian.setdefault((), state.best.smooth)
    todo = [s for s in stencils if s not in state.hessian]
    if todo:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(stencils), initial=len(stencils) - len(todo), desc="hessian",
                   unit="eval", disable=not settings.progress)  # fmt: skip
        try:
            for i, stencil in enumerate(todo):
                u = center.copy()
                for j, sign in stencil:
                    u[j] += sign * h
                state.hessian[stencil] = objective(values_of(u), single_values=False).smooth
                bar.update(1)
                last = i == len(todo) - 1
                if i % 5 == 4 or last:
                    _save(part, state)
                if not last and stopping():
                    _save(part, state)
                    check_stop()
        finally:
            bar.close()
    f = state.hessian
    f0 = f[()]
    hess = np.full((n, n), np.nan)
    for j in range(n):
        hess[j, j] = (f[((j, 1),)] - 2.0 * f0 + f[((j, -1),)]) / h**2
        if settings.uncertainty == "hessian":
            for k in range(j + 1, n):
                v = (
                    f[((j, 1), (k, 1))] - f[((j, 1), (k, -1))]
                    - f[((j, -1), (k, 1))] + f[((j, -1), (k, -1))]
                ) / (4.0 * h * h)  # fmt: skip
                hess[j, k] = hess[k, j] = v
    return {
        "center": center,
        "moved": moved,
        "objective": f0,
        "matrix": hess,
        "evaluations": len(stencils),
    }


# ----------------------------------------------------------------------------- the report
def _half_widths(hess: np.ndarray, f0: float, rise: float, full: bool) -> tuple[Any, Any]:
    """Conditional and marginal half-widths (normalised; ``inf``: flat), ``None`` marginal
    without the full Hessian."""
    n = len(hess)
    budget = 2.0 * rise * f0
    diag = np.diag(hess)
    conditional = np.where(diag > 0.0, np.sqrt(budget / np.where(diag > 0.0, diag, 1.0)), np.inf)
    if not full:
        return conditional, None
    sym = 0.5 * (hess + hess.T)
    lam, vec = np.linalg.eigh(sym)
    floor = 1e-9 * max(float(np.abs(lam).max()), 1e-300)
    marginal = np.zeros(n)
    for i in range(n):
        flat = lam <= floor
        if np.any(flat & (np.abs(vec[i]) > 0.1)):
            marginal[i] = np.inf
            continue
        ok = ~flat
        marginal[i] = math.sqrt(budget * float(np.sum(vec[i, ok] ** 2 / lam[ok])))
    return conditional, marginal


def _interval(p: FitParameter, u: float, half: float) -> list[float]:
    if not math.isfinite(half):
        return [p.low, p.high]
    return [p.value(u - half), p.value(u + half)]


def _report(
    paths: Sequence[Path],
    shas: Sequence[str],
    targets: Sequence[Target],
    settings: FitSettings,
    level: int,
    reflex: str,
    names: Sequence[str],
    start_values: Mapping[str, float],
    state: _State,
    hessian: Mapping[str, Any],
) -> dict[str, Any]:
    import cma

    from myoexo.model.params import TWIN_VERSION, TwinParams
    from myoexo.runtime.fits import provenance

    fitted = _values(state.best_u, names, start_values)
    truth = _truth(targets)
    f0 = float(hessian["objective"])
    full = settings.uncertainty == "hessian"
    has_series = any(t.series for t in targets)
    if has_series and f0 > 0.0:
        conditional, marginal = _half_widths(hessian["matrix"], f0, settings.rise, full)
    else:
        conditional = np.full(len(names), np.inf)
        marginal = np.full(len(names), np.inf) if full else None
    stds = np.asarray(state.es.result.stds, dtype=float)
    rows = []
    for i, name in enumerate(names):
        p = _BY_NAME[name]
        u = float(state.best_u[i])
        half = float(marginal[i] if marginal is not None else conditional[i])
        curvature = float(hessian["matrix"][i, i])
        identifiable = has_series and math.isfinite(half) and half <= IDENTIFIABLE_HALF_WIDTH
        rows.append(
            {
                "name": name,
                "unit": p.unit,
                "meaning": p.meaning,
                "informed_by": p.informed_by,
                "bounds": [p.low, p.high],
                "log_scale": p.log,
                "start": start_values[name],
                "fitted": fitted[name],
                "fitted_normalised": u,
                **({"truth": truth[name]} if truth is not None else {}),
                "interval": _interval(p, u, half),
                "half_width_normalised": _finite(half),
                "half_width_conditional_normalised": _finite(float(conditional[i])),
                "relative_curvature": _finite(curvature / f0) if f0 > 0 else None,
                "cma_std_normalised": float(stds[i]),
                "identifiable": bool(identifiable),
            }
        )
    traces = []
    starts = {r["file"] + r["test"]: r for r in state.start.traces}
    for row in state.best.traces:
        speed = row["test"].removeprefix("stretch-") if row["test"].startswith("stretch") else ""
        before = starts.get(row["file"] + row["test"], {})
        traces.append(
            {
                **row,
                "start_angle_rms_deg": before.get("angle_rms_deg"),
                **(
                    {"start_torque_rms_nm": before.get("torque_rms_nm")}
                    if "torque_rms_nm" in row
                    else {}
                ),
                "van_der_krogt_2016_rms_deg": VAN_DER_KROGT_2016_RMS_DEG.get(speed),
            }
        )
    subject = {f.name: fitted[f.name] for f in _subject_fields()}
    damping = TwinParams().knee_damping_nm_s_rad * fitted["damping_scale"]
    notes = _notes(targets, reflex)
    command = _command(paths, settings, level)
    versions_extra = {"cma": cma.__version__}
    prov = provenance(
        command,
        TWIN_VERSION,
        recordings=[{"file": str(p), "sha256": s} for p, s in zip(paths, shas, strict=True)],
        budget=settings.budget,
        seed=settings.seed,
    )
    prov["versions"] = {**prov["versions"], **versions_extra}
    not_identified = [r["name"] for r in rows if not r["identifiable"]]
    return {
        "level": level,
        "reflex": reflex,
        "subject": subject,
        "passive_knee": {
            "stiffness_scale": fitted["stiffness_scale"],
            "damping_scale": fitted["damping_scale"],
            "twin_overrides": {"knee_damping_nm_s_rad": damping},
            "how": "stiffness_scale multiplies the knee springs' coefficients of the built "
            "twin (no TwinParams field); damping_scale the knee's damping, which "
            "TwinParams.knee_damping_nm_s_rad sets",
        },
        "fitted_parameters": list(names),
        "parameters": rows,
        "not_identifiable": not_identified,
        "objective": {
            "start": state.start.objective,
            "fitted": state.best.objective,
            "time_series_at_fit": state.best.smooth,
        },
        "traces": traces,
        "single_values": [dict(v) for v in state.best.values],
        "uncertainty": {
            "method": (
                "finite-difference Hessian of the time-series objective in normalised "
                "coordinates"
                + (" (full)" if full else " (diagonal only: conditional intervals)")
                + f"; interval where the objective rises by at most {settings.rise:g} of "
                "its value"
            ),
            "fd_step_normalised": settings.fd_step,
            "rise": settings.rise,
            "center_moved_inside_bounds": bool(hessian["moved"]),
            "objective_at_center": f0,
            "identifiable_half_width_normalised": IDENTIFIABLE_HALF_WIDTH,
            "hessian_normalised": [[_finite(float(v)) for v in row] for row in hessian["matrix"]],
            "evaluations": int(hessian["evaluations"]),
        },
        "optimiser": {
            "method": "CMA-ES",
            "package": f"cma {cma.__version__}",
            "budget": settings.budget,
            "popsize": settings.popsize,
            "sigma0_normalised": settings.sigma0,
            "seed": settings.seed,
            "generations": state.generations,
            "evaluations": state.evaluations,
            "start_evaluations": 1,
            "resumed_at_evaluations": list(state.resumed_at),
            "stopped_early": state.stop_reason or None,
            "best_by_generation": [[n, f] for n, f in state.history],
            "weights": {
                "torque_deg_per_nm": settings.torque_weight,
                "tardieu_deg_per_deg": settings.tardieu_weight,
                "mas_deg_per_grade": settings.mas_weight,
            },
        },
        "notes": notes,
        "provenance": prov,
    }


def _finite(x: float) -> float | None:
    return x if math.isfinite(x) else None


def _truth(targets: Sequence[Target]) -> dict[str, float] | None:
    """The synthetic subject all the recordings were made on (scales 1: the twin's own
    passive knee), or ``None``."""
    subjects = [t.recording.synthetic_subject() for t in targets]
    if not subjects or any(s is None for s in subjects):
        return None
    first = subjects[0]
    if any(s != first for s in subjects):
        return None
    assert first is not None
    return {**dataclasses.asdict(first), **{name: 1.0 for name in PASSIVE_NAMES}}


def _notes(targets: Sequence[Target], reflex: str) -> list[str]:
    from myoexo.model.params import TWIN_VERSION, TwinParams

    seated_hip = TwinParams().hip_flexion_deg  # the twin's stretches, Tardieu and MAS
    notes = []
    for t in targets:
        m = t.recording.metadata
        if m.get("synthetic_reflex", reflex) != reflex:
            notes.append(
                f"{t.path.name}: made with reflex {m['synthetic_reflex']}, fitted {reflex}"
            )
        version = m.get("synthetic_twin_version")
        if version is not None and int(version) != TWIN_VERSION:
            notes.append(f"{t.path.name}: made on twin {version}, fitted on twin {TWIN_VERSION}")
        if m.get("device") == "none":
            notes.append(f"{t.path.name}: recorded without the exo; the twin wears it")
        if t.kind != "pendulum" and (
            m.get("posture", "seated") != "seated"
            or float(m.get("hip_flexion_deg", seated_hip)) != seated_hip
        ):
            notes.append(
                f"{t.path.name}: not seated at hip {seated_hip:g} deg; the twin replays it so"
            )
    return notes


def _command(paths: Sequence[Path], settings: FitSettings, level: int) -> str:
    options = option_words(settings, exclude=("level", "progress"))
    words = ["myoexo", "twin", "fit-subject", *map(str, paths), *options]
    words += ["--level", str(level), "--reflex", str(settings.reflex)]
    return shlex.join(words)


def _num(x: float | None) -> str:
    return "-" if x is None else f"{x:.2f}"


def format_report(report: Mapping[str, Any]) -> str:
    """The report as text: the parameters, the traces, the single values."""
    lines = [
        f"level {report['level']}, reflex {report['reflex']}: objective "
        f"{report['objective']['start']:.3f} at the start -> {report['objective']['fitted']:.3f} "
        f"({report['optimiser']['evaluations']} evaluations of CMA-ES)"
    ]
    truth = any("truth" in r for r in report["parameters"])
    head = f"{'parameter':<16}{'start':>9}{'fitted':>9}  {'interval':<20}"
    lines.append(head + (f"{'truth':>9}" if truth else "") + "  identifiable")
    for r in report["parameters"]:
        lo, hi = r["interval"]
        line = f"{r['name']:<16}{r['start']:>9.3f}{r['fitted']:>9.3f}  [{lo:.3g}, {hi:.3g}]"
        line = f"{line:<56}"
        if truth:
            line += f"{r['truth']:>9.3f}"
        lines.append(line + ("  yes" if r["identifiable"] else "  no"))
    for t in report["traces"]:
        text = (
            f"{t['file']} ({t['test']}): angle RMS {_num(t['start_angle_rms_deg'])} -> "
            f"{_num(t['angle_rms_deg'])} deg"
        )
        if "torque_rms_nm" in t:
            text += (
                f", torque RMS {_num(t['start_torque_rms_nm'])} -> {_num(t['torque_rms_nm'])} Nm"
            )
        if t["van_der_krogt_2016_rms_deg"] is not None:
            text += f" (van der Krogt et al. 2016: {t['van_der_krogt_2016_rms_deg']:g} deg)"
        lines.append(text)
    for v in report["single_values"]:
        lines.append(
            f"{v['file']} ({v['test']}): recorded {v['recorded']}, replayed {v['replayed']}"
        )
    if report["not_identifiable"]:
        lines.append(
            "not identifiable from these recordings: " + ", ".join(report["not_identifiable"])
        )
    lines.extend(f"note: {n}" for n in report["notes"])
    return "\n".join(lines)


# ----------------------------------------------------------------------------- CLI
def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin fit-subject``: the recordings, :class:`FitSettings`' fields
    and ``--reflex``."""
    parser.add_argument(
        "recordings", nargs="+", type=Path, metavar="RECORDING",
        help="a recording of the patient (CSV, the clinical recording format), one test each",
    )  # fmt: skip
    add_options(parser, FitSettings)
    add_reflex_argument(parser, default=DEFAULT_REFLEX)


def run(args: argparse.Namespace) -> int:
    """Fit, write ``--out``, print the report; a signal stops with the state kept."""
    from myoexo.runtime.lifecycle import StopSignals, signal_exit_status

    settings = from_options(FitSettings, args, reflex=args.reflex)
    with StopSignals() as stop:
        try:
            report = fit_subject(args.recordings, settings, stop=stop, log=print)
        except FitStopped as exc:
            print(
                f"myoexo twin fit-subject: {stop.name or 'stopped'}: {exc}; run the same "
                "command to continue",
                file=sys.stderr,
            )
            return signal_exit_status(stop.received or 2)
    print(format_report(report))
    print(f"wrote {settings.out}")
    return 0
