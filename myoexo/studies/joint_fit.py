"""The joint fit of the ``"tsrt"`` reflex (and of ``"spindle_tsrt"``, the same reflex on each
muscle's own fibre state, and ``"spindle_tone"``, that one with a length tone): the study's
PID table and the clinical rows together, on the calibration root.

``myoexo twin calibrate --reflex tsrt`` (or ``spindle_tsrt``, ``spindle_tone``) runs
:func:`calibrate_tsrt`. Its objective is the
validation table's (:mod:`myoexo.studies.validate`): the number of rows a candidate passes,
with a small continuous term that breaks ties towards the study's PID final errors (6.3 / 9.3
deg at levels 2-3, within 0.5 deg of the target at level 1), a velocity-dependent resistance
and spasticity angle that rise with the level, and catches inside the range. The search is
coordinate-wise: each sweep tries one step up and one down of every fitted field
(:data:`STEPS`) the model's level parameters have, at every spastic level (the velocity slope
is shared by the levels), keeps a step that raises the objective, and halves the steps for
the next sweep. Then the model's hold parameter of levels 2 and 3 (:data:`HOLD_PARAMETERS`:
the flexors' static threshold, as the stretch reflex's calibration fits it, or
``"spindle_tone"``'s tone) is fitted by bisection on the PID's mean final error, and the PID is
checked on the evaluation root. The fit reads the calibration root only (the evaluation root
is refused).

    myoexo twin calibrate --reflex tsrt --subjects 6 --clinical-subjects 1 --sweeps 2 \\
        --verify-subjects 50 --out docs/studies/calibration_tsrt
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from types import MappingProxyType
from typing import Any

from myoexo.evaluation.config import CALIBRATION_ROOT_SEED, EVALUATION_ROOT_SEED, check_fit_root
from myoexo.spasticity.levels import VALID_LEVELS
from myoexo.spasticity.spindle import SPINDLE_TSRT_FIT
from myoexo.spasticity.spindle_tone import SPINDLE_TONE_FIT
from myoexo.spasticity.tsrt import TSRT_FIT, TSRTCalibration, TSRTLevel, TSRTReflex
from myoexo.studies.pid_check import PIDOutcome, bisect_final_error, pid_outcome
from myoexo.studies.validate import ValidationConfig, measure_model, score

__all__ = [
    "CONSTRAINT_PENALTY",
    "CONSTRAINT_ROWS",
    "FITTED_MODELS",
    "HOLD_PARAMETERS",
    "STEPS",
    "JointFitResult",
    "calibrate_tsrt",
    "objective",
]

#: The first sweep's step of every fitted field (halved each sweep), and its bounds.
STEPS: Mapping[str, tuple[float, float, float]] = MappingProxyType(
    {
        "flexor_threshold_shift_deg": (4.0, -50.0, 150.0),
        "dynamic_shift_deg": (3.0, 0.0, 60.0),
        "flexor_gain": (0.2, 0.0, 20.0),
        "extensor_gain": (0.15, 0.0, 20.0),
        "extensor_threshold_shift_deg": (8.0, -100.0, 100.0),
        "flexor_tone": (0.02, 0.0, 1.0),
        "phasic_scale": (0.1, 0.0, 2.0),
        "phasic_threshold_offset_deg": (8.0, -100.0, 200.0),
        "background_tone": (0.02, 0.0, 0.5),
    }
)
#: The shared velocity slope's first step, 1/(rad/s), and its bounds.
VELOCITY_SLOPE_STEP: tuple[float, float, float] = (4.0, 1.0, 100.0)
#: The PID's final-error targets of the tie-break, deg (the study's table).
_TARGETS_DEG = {2: 6.3, 3: 9.3}


#: Rows the fit holds as constraints: each one a candidate misses costs it
#: :data:`CONSTRAINT_PENALTY` rows, so no number of other rows buys it back. A loop that
#: decays under a weak controller is what the Ziegler-Nichols tunings need; a knee that
#: rests under a constant command is what the strap-lag reading needs.
CONSTRAINT_ROWS: tuple[str, ...] = ("pid_weak_control", "constant_command_rest")
CONSTRAINT_PENALTY = 100.0


def objective(measures: Mapping[str, Any]) -> tuple[float, int]:
    """``(value, rows passed)`` of one candidate's measurements: the rows passed plus a
    tie-break in ``(-0.3, 0.3)`` (module docstring), less :data:`CONSTRAINT_PENALTY` per
    row of :data:`CONSTRAINT_ROWS` it misses."""
    scores = score(measures)
    passed = sum(ok for _, ok in scores.values())
    missed_constraints = sum(not scores[row][1] for row in CONSTRAINT_ROWS if row in scores)
    pid = measures["pid"]
    t = measures["tardieu"]
    vel = [float(t["velocity_nm"][lv]) for lv in VALID_LEVELS]
    ang = [float(t["r2_minus_r1_deg"][lv]) for lv in (1, 2, 3)]
    r1 = [float(t["r1_deg"][lv]) for lv in (1, 2, 3)]
    soft = (
        -sum(abs(pid[lv].final_error_deg - target) / 3.0 for lv, target in _TARGETS_DEG.items())
        - max(0.0, abs(pid[1].final_error_deg) - 0.5)
        + 0.02 * min(vel[2] - vel[1], vel[3] - vel[2], 20.0)
        + 0.02 * min(ang[1] - ang[0], ang[2] - ang[1], 20.0)
        - 0.02 * sum(max(0.0, r - 70.0) for r in r1)
    )
    value = passed + 0.3 * math.tanh(soft / 3.0) - CONSTRAINT_PENALTY * missed_constraints
    return value, passed


@dataclass(frozen=True)
class JointFitResult:
    """What :func:`calibrate_tsrt` found.

    Attributes:
        calibration: The fitted per-level parameters (with their provenance note).
        rows: Row key -> (value, passed) of the validation rows at the fitted values, on
            the fit's subjects (in-sample).
        fit_outcomes: Level -> the PID on the fit's subjects at the fitted threshold.
        outcomes: Level -> the PID on the check's subjects (the evaluation root).
        evaluations: Candidates measured.
        wall_time_s: Time the fit and the check took.
        fit_root_seed: Root seed of the fit's subjects.
        check_root_seed: Root seed of the check's subjects.
        reflex: The registered name of the fitted model.
    """

    calibration: TSRTCalibration
    rows: Mapping[str, tuple[str, bool]]
    fit_outcomes: Mapping[int, PIDOutcome]
    outcomes: Mapping[int, PIDOutcome]
    evaluations: int
    wall_time_s: float
    fit_root_seed: int = CALIBRATION_ROOT_SEED
    check_root_seed: int = EVALUATION_ROOT_SEED
    reflex: str = "tsrt"

    def snippet(self) -> str:
        """The fitted levels as Python (what the model's calibration reads from the
        package's fit once it is written with ``--write``)."""
        lines = ["{"]
        for level, c in sorted(self.calibration.levels.items()):
            fields = ", ".join(f"{f.name}={getattr(c, f.name):.4g}" for f in dataclasses.fields(c))
            lines.append(f"    {level}: {type(c).__name__}({fields}),")
        lines.append("}")
        return "\n".join(lines)

    def markdown(self) -> str:
        """The calibration record: note, fitted values, the fit's rows, the check."""
        passed = sum(ok for _, ok in self.rows.values())
        lines = [
            f"# Calibration of the {self.reflex} reflex",
            "",
            self.calibration.note,
            "",
            "Fitted values (the package's with --write: "
            f"myoexo/assets/fits/{FITTED_MODELS[self.reflex]}.json):",
            "",
            "```python",
            self.snippet(),
            "```",
            "",
            f"**The fit** (in-sample, root {self.fit_root_seed}): {passed} of "
            f"{len(self.rows)} validation rows pass on the fit's subjects; the PID at the "
            "fitted values:",
            "",
            "| level | subjects | PID final error (deg) | target (deg) |",
            "|---|---|---|---|",
        ]
        for level, out in sorted(self.fit_outcomes.items()):
            lines.append(
                f"| {level} | {out.subjects} | {out.final_error_deg:.2f} ± "
                f"{out.final_error_std_deg:.2f} | {_TARGETS_DEG[level]:g} |"
            )
        lines += [
            "",
            f"**The check** (root {self.check_root_seed}, subjects the fit never saw): the "
            "paper's PID",
            "",
            "| level | subjects | PID final error (deg) | overshoot (deg) | settled |",
            "|---|---|---|---|---|",
        ]
        for level, out in sorted(self.outcomes.items()):
            lines.append(
                f"| {level} | {out.subjects} | {out.final_error_deg:.2f} ± "
                f"{out.final_error_std_deg:.2f} | {out.overshoot_deg:.2f} | "
                f"{100 * out.settled_fraction:.0f} % |"
            )
        lines += ["", f"{self.evaluations} candidates; wall time {self.wall_time_s:.0f} s.", ""]
        return "\n".join(lines)


#: The registered models this fit takes (a :class:`~myoexo.spasticity.tsrt.TSRTReflex`
#: each, whose calibration it replaces) -> the package's fit its ``--write`` makes.
FITTED_MODELS: Mapping[str, str] = MappingProxyType(
    {"tsrt": TSRT_FIT, "spindle_tsrt": SPINDLE_TSRT_FIT, "spindle_tone": SPINDLE_TONE_FIT}
)


@dataclass(frozen=True)
class HoldParameter:
    """The level parameter the PID's final error at levels 2-3 is bisected on.

    Attributes:
        name: The :class:`~myoexo.spasticity.tsrt.TSRTLevel` field.
        half_bracket: The bisection's bracket is the fitted value +- this.
        tol: The bisection stops once the bracket is this narrow.
        digits: Decimals the result is rounded to.

    The bracket stays within the field's bounds in :data:`STEPS`.
    """

    name: str
    half_bracket: float
    tol: float
    digits: int


_THRESHOLD = HoldParameter("flexor_threshold_shift_deg", 15.0, 0.1, 2)
#: Each fitted model's hold parameter: the flexors' static threshold, or (``spindle_tone``)
#: the flexors' length tone, which holds the knee without the threshold's clonus.
HOLD_PARAMETERS: Mapping[str, HoldParameter] = MappingProxyType(
    {
        "tsrt": _THRESHOLD,
        "spindle_tsrt": _THRESHOLD,
        "spindle_tone": HoldParameter("flexor_tone", 0.1, 0.002, 3),
    }
)


def _model(levels: Mapping[int, TSRTLevel], base: TSRTReflex) -> TSRTReflex:
    calibration = type(base.calibration)(levels=MappingProxyType(dict(levels)))
    return dataclasses.replace(base, calibration=calibration)


def calibrate_tsrt(
    start: TSRTCalibration | None = None,
    pid_subjects: int = 6,
    clinical_subjects: int = 1,
    sweeps: int = 2,
    verify_subjects: int = 50,
    root_seed: int = CALIBRATION_ROOT_SEED,
    check_root_seed: int = EVALUATION_ROOT_SEED,
    log: Callable[[str], None] = print,
    reflex: str = "tsrt",
    start_source: str | None = None,
) -> JointFitResult:
    """Fit the ``"tsrt"`` reflex (or *reflex*, another reading of it) jointly to the PID
    table and the clinical rows (module docstring), starting from *start*.

    Args:
        start: The starting values (every spastic level must be listed; default: the
            model's own calibration, the package's fit: a re-run refines it; before its
            first ``--write``, ``"spindle_tsrt"``'s is ``"tsrt"``'s).
        pid_subjects: Subjects per level of the PID in the fit.
        clinical_subjects: Subjects per level of the clinical tests in the fit.
        sweeps: Coordinate sweeps (each halves the steps).
        verify_subjects: Subjects per level of the PID check on the evaluation root.
        root_seed: Root seed of the fit's subjects (the evaluation root is refused).
        check_root_seed: Root seed of the check.
        log: Progress lines.
        reflex: The model fitted, one of :data:`FITTED_MODELS`.
        start_source: The file *start* was read from (named in the provenance note as
            ``--start``).

    Raises:
        ValueError: If *reflex* is not one of :data:`FITTED_MODELS`, *start* is not the
            model's kind of calibration, the root is the evaluation root or *sweeps* is
            negative.
    """
    if reflex not in FITTED_MODELS:
        raise ValueError(f"reflex = {reflex!r}; the joint fit takes {list(FITTED_MODELS)}")
    from myoexo.spasticity.registry import get_reflex

    base = get_reflex(reflex)
    assert isinstance(base, TSRTReflex)
    if start is None:
        start = base.calibration
    if type(start) is not type(base.calibration):
        raise ValueError(
            f"start is a {type(start).__name__}; {reflex!r} takes a "
            f"{type(base.calibration).__name__}"
        )
    root_seed = check_fit_root(root_seed, "calibration")
    if sweeps < 0:
        raise ValueError(f"sweeps = {sweeps} must be >= 0")
    t0 = time.perf_counter()
    config = ValidationConfig(
        subjects=clinical_subjects, pid_subjects=pid_subjects, root_seed=root_seed
    )
    levels = {lv: start[lv] for lv in VALID_LEVELS if lv > 0}
    evaluations = 0

    def evaluate(candidate: Mapping[int, TSRTLevel]) -> tuple[float, int]:
        nonlocal evaluations
        evaluations += 1
        return objective(measure_model(_model(candidate, base), config))

    best, passed = evaluate(levels)
    log(f"start: {passed} rows, objective {best:.3f}")
    fields = {f.name for f in dataclasses.fields(levels[1])}
    steps = {name: step for name, (step, _, _) in STEPS.items() if name in fields}
    slope_step = VELOCITY_SLOPE_STEP[0]
    for sweep in range(sweeps):
        moves: list[tuple[int | None, str, float]] = [
            (lv, name, step) for lv in sorted(levels) for name, step in steps.items()
        ]
        moves.append((None, "velocity_slope_per_rad_s", slope_step))
        for level, name, step in moves:
            for sign in (1.0, -1.0):
                trial = dict(levels)
                if level is None:  # the shared velocity slope
                    _, low, high = VELOCITY_SLOPE_STEP
                    value = min(max(levels[1].velocity_slope_per_rad_s + sign * step, low), high)
                    trial = {lv: dataclasses.replace(c, **{name: value}) for lv, c in trial.items()}
                else:
                    _, low, high = STEPS[name]
                    value = min(max(getattr(levels[level], name) + sign * step, low), high)
                    trial[level] = dataclasses.replace(levels[level], **{name: value})
                val, n = evaluate(trial)
                log(f"  sweep {sweep} L{level or '*'} {name} {value:.3g}: {n} rows, {val:.3f}")
                if val > best:
                    best, passed, levels = val, n, trial
                    break
        steps = {name: step / 2 for name, step in steps.items()}
        slope_step /= 2
        log(f"sweep {sweep}: {passed} rows, objective {best:.3f}")

    fit_outcomes: dict[int, PIDOutcome] = {}
    hold = HOLD_PARAMETERS[reflex]
    for level, target in sorted(_TARGETS_DEG.items()):
        current = getattr(levels[level], hold.name)

        def outcome(value: float, level: int = level) -> PIDOutcome:
            trial = dict(levels)
            trial[level] = dataclasses.replace(levels[level], **{hold.name: value})
            return pid_outcome(level, _model(trial, base), pid_subjects, root_seed)

        _, low, high = STEPS[hold.name]
        bracket = (max(current - hold.half_bracket, low), min(current + hold.half_bracket, high))
        value, fit_outcomes[level] = bisect_final_error(
            outcome, bracket, target, hold.tol, level, hold.name
        )
        levels[level] = dataclasses.replace(levels[level], **{hold.name: round(value, hold.digits)})
        log(f"L{level}: {hold.name} {value:.{hold.digits}f}")
    rows = score(measure_model(_model(levels, base), config))
    outcomes = {
        lv: pid_outcome(lv, _model(levels, base), verify_subjects, check_root_seed)
        for lv in VALID_LEVELS
    }
    note = (
        f"myoexo twin calibrate --reflex {reflex} --subjects {pid_subjects} --clinical-subjects "
        f"{clinical_subjects} --sweeps {sweeps} --verify-subjects {verify_subjects} --seed "
        f"{root_seed}"
        + (f" --start {start_source}" if start_source else "")
        + f": fitted on root {root_seed} ({sum(ok for _, ok in rows.values())} of "
        f"{len(rows)} validation rows in-sample); check on root {check_root_seed}, PID final "
        "error "
        + ", ".join(
            f"L{lv} {o.final_error_deg:.2f} +- {o.final_error_std_deg:.2f} deg"
            for lv, o in outcomes.items()
        )
    )
    calibration = type(base.calibration)(
        levels=MappingProxyType(dict(levels)), note=note, root_seed=root_seed
    )
    return JointFitResult(
        calibration=calibration,
        rows=rows,
        fit_outcomes=fit_outcomes,
        outcomes=outcomes,
        evaluations=evaluations,
        wall_time_s=time.perf_counter() - t0,
        fit_root_seed=root_seed,
        check_root_seed=check_root_seed,
        reflex=reflex,
    )
