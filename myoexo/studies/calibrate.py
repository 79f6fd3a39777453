"""``myoexo twin calibrate``: fit a reflex model so that the paper's PID behaves as in the study.

Each reflex model registers its own fit (:func:`register_fit`, a :class:`ReflexFit` with the
options only that fit takes); ``--reflex MODEL`` runs it, and an option of another model's
fit is refused with one line naming whose it is. Built in: ``stretch`` and ``spindle`` (the
threshold fit below), ``persistent`` (:func:`calibrate_persistent`), ``tsrt`` and
``spindle_tsrt`` (:mod:`myoexo.studies.joint_fit`).

The study reports what its Ziegler-Nichols PID (Kp = 7, Ki = 40, Kd = 0.05 on the error in
rad) does on its twin: it overshoots the 7 deg target at levels 0 and 1 and stops short of it
by 6.3 deg at level 2 and 9.3 deg at level 3 (docs/reference.md section 5). Those four facts
are the calibration targets; the paper's SAC results are *not* used here (checkpoint selection
aims at them, so they are targets of the policies, not independent predictions).

What is fitted (:class:`~myoexo.spasticity.reflex.LevelCalibration`): per level 2 and 3, the
shift of the flexors' extension-side angle threshold (Table I's ``theta_ext`` lies outside
the motion). The PID's mean final error grows monotonically with the shift (a threshold further
inside the range stops the knee earlier), so each level is a one-dimensional root search
(bisection) on fixed subjects (the same seeds at every trial: the objective is deterministic).
Levels 0 and 1
are not fitted; they are checked (overshoot, final error < 1 deg). Gains stay 1 unless given.

    myoexo twin calibrate --subjects 40 --verify-subjects 200 --out results/calibration

prints the fitted :class:`~myoexo.spasticity.reflex.StretchCalibration` and the verification
table: PID final error and overshoot per level next to the paper's, on ``--verify-subjects``
subjects per level. ``--write`` makes the fit the package's
(``myoexo/assets/fits/reflex_stretch.json``, with its provenance), which
:data:`myoexo.spasticity.reflex.CALIBRATION` reads.

``--reflex persistent`` fits the ``"persistent"`` model instead
(:func:`calibrate_persistent`): the after-discharge gains ``G`` of levels 2 and 3 by the
same bisection on the PID's mean final error (a larger gain stalls it further), level 1's
gain ``--level1-fraction`` x level 2's, then verifies every level and runs the PID on a
target ramped over ``--ramp-s`` s (``PIDConfig(ramp_s=...)``, the gentle approach) at levels 2-3::

    myoexo twin calibrate --reflex persistent --subjects 30 --verify-subjects 200

prints :data:`myoexo.spasticity.reflex.PERSISTENT`'s gains and the table.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import time
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any

from myoexo.evaluation.config import (
    CALIBRATION_ROOT_SEED,
    EVALUATION_ROOT_SEED,
    check_fit_root,
)
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    check_fields,
    flag_of,
    from_options,
    option,
    option_fields,
)
from myoexo.spasticity.levels import VALID_LEVELS
from myoexo.spasticity.reflex import (
    PERSISTENT,
    STRETCH_DELAY_S,
    LevelCalibration,
    PersistentParams,
    PersistentReflex,
    StretchCalibration,
    StretchReflex,
)
from myoexo.studies.pid_check import PIDOutcome, bisect_final_error, pid_outcome

__all__ = [
    "CalibrationConfig",
    "CalibrationResult",
    "CalibrationTargets",
    "PIDOutcome",
    "PersistentFitOptions",
    "ReflexFit",
    "ThresholdFitOptions",
    "TsrtFitOptions",
    "bisect_final_error",
    "calibrate",
    "calibrate_persistent",
    "fit_names",
    "pid_outcome",
    "register_fit",
]


@dataclass(frozen=True)
class CalibrationTargets:
    """What the paper's PID does in the study, per level.

    Attributes:
        pid_final_error_deg: Level -> the PID's final error (knee - target, deg) to fit.
        tolerance_deg: Accepted distance of the mean final error from its target.
        overshoot_levels: Levels where the PID must overshoot the target and end within
            ``final_error_bound_deg`` of it.
        final_error_bound_deg: Bound of the mean absolute final error at those levels.
    """

    pid_final_error_deg: Mapping[int, float] = dataclasses.field(
        default_factory=lambda: MappingProxyType({2: 6.3, 3: 9.3})
    )
    tolerance_deg: float = 1.5
    overshoot_levels: tuple[int, ...] = (0, 1)
    final_error_bound_deg: float = 1.0


def _with_level(
    calibration: StretchCalibration, level: int, value: LevelCalibration
) -> StretchCalibration:
    levels = dict(calibration.levels)
    levels[level] = value
    return StretchCalibration(levels=MappingProxyType(levels), note=calibration.note)


def fit_threshold_shift(
    level: int,
    target_final_error_deg: float,
    base: StretchReflex,
    subjects: int,
    root_seed: int = CALIBRATION_ROOT_SEED,
    bracket_deg: tuple[float, float] = (0.0, 100.0),
    tol_deg: float = 0.1,
    log: Callable[[str], None] | None = None,
) -> tuple[float, PIDOutcome]:
    """Bisection on the flexors' threshold shift of ``level`` until the PID's mean final
    error meets ``target_final_error_deg``.

    Returns:
        ``(shift_deg, outcome at that shift)``.

    Raises:
        ValueError: The target is not bracketed by ``bracket_deg``.
    """
    root_seed = check_fit_root(root_seed, "calibration")

    def outcome(shift: float) -> PIDOutcome:
        current = base.calibration[level]
        cal = _with_level(
            base.calibration,
            level,
            dataclasses.replace(current, flexor_threshold_shift_deg=shift),
        )
        out = pid_outcome(level, dataclasses.replace(base, calibration=cal), subjects, root_seed)
        if log:
            log(
                f"  L{level} shift {shift:7.3f} deg: final error {out.final_error_deg:6.2f} "
                f"+- {out.final_error_std_deg:5.2f} deg, overshoot {out.overshoot_deg:5.2f} deg"
            )
        return out

    return bisect_final_error(outcome, bracket_deg, target_final_error_deg, tol_deg, level, "shift")


@dataclass(frozen=True)
class CalibrationResult:
    """What :func:`calibrate` found.

    Attributes:
        calibration: The fitted per-level parameters.
        reflex: The reflex config with them.
        outcomes: Level -> the PID's outcome on the verification subjects (the check, on
            the evaluation root).
        targets: The targets.
        wall_time_s: Time the fit and the verification took.
        fit_outcomes: Fitted level -> the PID's outcome on the fit's own subjects at the
            fitted value (the fit, in-sample).
        fit_root_seed: Root seed of the fit's subjects.
        check_root_seed: Root seed of the verification's subjects.
    """

    calibration: StretchCalibration
    reflex: StretchReflex
    outcomes: Mapping[int, PIDOutcome]
    targets: CalibrationTargets
    wall_time_s: float
    fit_outcomes: Mapping[int, PIDOutcome] = dataclasses.field(default_factory=dict)
    fit_root_seed: int = CALIBRATION_ROOT_SEED
    check_root_seed: int = EVALUATION_ROOT_SEED

    def table(self) -> Any:
        """Per level: the PID's final error and overshoot next to the paper's, and whether
        the target is met (pandas)."""
        import pandas as pd

        from myoexo.evaluation.paper import PAPER_RESULTS

        rows = []
        t = self.targets
        for level, out in self.outcomes.items():
            target = t.pid_final_error_deg.get(level)
            if target is not None:
                ok = abs(out.final_error_deg - target) <= t.tolerance_deg
            elif level in t.overshoot_levels:
                ok = out.overshoot_deg > 0.0 and abs(out.final_error_deg) < t.final_error_bound_deg
            else:
                ok = True
            rows.append(
                {
                    "level": level,
                    "subjects": out.subjects,
                    "PID final error (deg)": f"{out.final_error_deg:.2f} ± "
                    f"{out.final_error_std_deg:.2f}",
                    "paper": PAPER_RESULTS[level].pid_final_error_text,
                    "PID overshoot (deg)": f"{out.overshoot_deg:.2f}",
                    "settled": f"{100 * out.settled_fraction:.0f} %",
                    "target met": "yes" if ok else "no",
                }
            )
        return pd.DataFrame(rows)

    def snippet(self) -> str:
        """The fitted calibration as Python, for :data:`myoexo.spasticity.reflex.CALIBRATION`."""
        lines = ["{"]
        for level, c in sorted(self.calibration.levels.items()):
            lines.append(
                f"    {level}: LevelCalibration(flexor_gain={c.flexor_gain:g}, "
                f"extensor_gain={c.extensor_gain:g}, "
                f"flexor_threshold_shift_deg={c.flexor_threshold_shift_deg:.2f}),"
            )
        lines.append("}")
        return "\n".join(lines)


def calibrate(
    subjects: int = 40,
    verify_subjects: int = 200,
    delay_s: float = STRETCH_DELAY_S,
    extensor_gain: float = 1.0,
    targets: CalibrationTargets | None = None,
    root_seed: int = CALIBRATION_ROOT_SEED,
    levels: Sequence[int] = VALID_LEVELS,
    log: Callable[[str], None] = print,
    check_root_seed: int = EVALUATION_ROOT_SEED,
    base: StretchReflex | None = None,
) -> CalibrationResult:
    """Fit the threshold shifts of the target levels, then verify every level.

    Args:
        subjects: Subjects per level during the fit.
        verify_subjects: Subjects per level of the verification (paper protocol: 1000).
        delay_s: Reflex delay of the fitted model, s.
        extensor_gain: Gain of the extensors' reflex at levels 1-3 (fixed, not fitted).
        targets: What to fit (default :class:`CalibrationTargets`).
        root_seed: Root seed of the subjects the fit uses (the calibration root; the
            evaluation root is refused).
        levels: Levels to verify.
        log: Progress lines.
        check_root_seed: Root seed of the verification's subjects (default: the evaluation
            root, where the fitted twin is then checked, not fitted).
        base: The model whose calibration is fitted (default ``StretchReflex``; a
            :class:`~myoexo.spasticity.spindle.SpindleReflex` is fitted the same way).
    """
    root_seed = check_fit_root(root_seed, "calibration")
    t0 = time.perf_counter()
    tg = targets or CalibrationTargets()
    cal = StretchCalibration(
        levels=MappingProxyType(
            {lv: LevelCalibration(extensor_gain=extensor_gain) for lv in VALID_LEVELS if lv > 0}
        )
    )
    reflex = dataclasses.replace(base or StretchReflex(), delay_s=delay_s, calibration=cal)
    fitted: dict[int, PIDOutcome] = {}
    for level, target in sorted(tg.pid_final_error_deg.items()):
        log(f"fitting level {level}: PID final error -> {target} deg ({subjects} subjects)")
        shift, fitted[level] = fit_threshold_shift(
            level, target, reflex, subjects, root_seed, log=log
        )
        cal = _with_level(
            cal, level, dataclasses.replace(cal[level], flexor_threshold_shift_deg=round(shift, 2))
        )
        reflex = dataclasses.replace(reflex, calibration=cal)
    log(f"verifying on {verify_subjects} subjects per level")
    outcomes = {lv: pid_outcome(lv, reflex, verify_subjects, check_root_seed) for lv in levels}
    elapsed = time.perf_counter() - t0
    model_flag = "" if type(reflex) is StretchReflex else " --reflex spindle"
    note = (
        f"myoexo twin calibrate{model_flag} --subjects {subjects} "
        f"--verify-subjects {verify_subjects} "
        f"--delay-s {delay_s} --extensor-gain {extensor_gain} --seed {root_seed}: fitted on "
        f"root {root_seed}; check on root {check_root_seed}, PID final error "
        + ", ".join(
            f"L{lv} {o.final_error_deg:.2f} +- {o.final_error_std_deg:.2f} deg"
            for lv, o in outcomes.items()
        )
    )
    cal = StretchCalibration(levels=cal.levels, note=note, root_seed=root_seed)
    return CalibrationResult(
        calibration=cal,
        reflex=dataclasses.replace(reflex, calibration=cal),
        outcomes=outcomes,
        targets=tg,
        wall_time_s=elapsed,
        fit_outcomes=fitted,
        fit_root_seed=root_seed,
        check_root_seed=check_root_seed,
    )


# ------------------------------------------------------------------ the persistent reflex
def _with_gains(
    reflex: PersistentReflex, gains: Mapping[int, float], note: str = ""
) -> PersistentReflex:
    params = dataclasses.replace(
        reflex.after_discharge,
        gains=MappingProxyType(dict(gains)),
        note=note or reflex.after_discharge.note,
    )
    return dataclasses.replace(reflex, after_discharge=params)


def fit_persistent_gain(
    level: int,
    target_final_error_deg: float,
    base: PersistentReflex,
    subjects: int,
    root_seed: int = CALIBRATION_ROOT_SEED,
    bracket: tuple[float, float] = (0.3, 1.0),
    tol: float = 0.004,
    log: Callable[[str], None] | None = None,
) -> tuple[float, PIDOutcome]:
    """Bisection on the after-discharge gain ``G`` of ``level`` (the ``"persistent"`` model)
    until the paper's PID's mean final error meets ``target_final_error_deg`` (a larger gain
    holds the knee further from the target).

    Returns:
        ``(gain, outcome at that gain)``.

    Raises:
        ValueError: The target is not bracketed by ``bracket``.
    """
    root_seed = check_fit_root(root_seed, "calibration")

    def outcome(gain: float) -> PIDOutcome:
        gains = dict(base.after_discharge.gains)
        gains[level] = gain
        out = pid_outcome(level, _with_gains(base, gains), subjects, root_seed)
        if log:
            log(
                f"  L{level} gain {gain:6.4f}: final error {out.final_error_deg:6.2f} "
                f"+- {out.final_error_std_deg:5.2f} deg, overshoot {out.overshoot_deg:5.2f} deg"
            )
        return out

    return bisect_final_error(outcome, bracket, target_final_error_deg, tol, level, "gain")


@dataclass(frozen=True)
class PersistentCalibrationResult:
    """What :func:`calibrate_persistent` found.

    Attributes:
        params: The fitted after-discharge (:class:`~myoexo.spasticity.reflex.PersistentParams`,
            its ``note`` the provenance).
        reflex: The reflex config with it.
        outcomes: Level -> the paper's PID on the verification subjects.
        ramped: Level -> the same PID following a target ramped over ``ramp_s``.
        ramp_s: Duration of the ramp, s.
        targets: The targets.
        wall_time_s: Time the fit and the verification took.
        fit_outcomes: Fitted level -> the PID on the fit's own subjects at the fitted gain
            (the fit, in-sample).
        fit_root_seed: Root seed of the fit's subjects.
        check_root_seed: Root seed of the verification's subjects.
    """

    params: PersistentParams
    reflex: PersistentReflex
    outcomes: Mapping[int, PIDOutcome]
    ramped: Mapping[int, PIDOutcome]
    ramp_s: float
    targets: CalibrationTargets
    wall_time_s: float
    fit_outcomes: Mapping[int, PIDOutcome] = dataclasses.field(default_factory=dict)
    fit_root_seed: int = CALIBRATION_ROOT_SEED
    check_root_seed: int = EVALUATION_ROOT_SEED

    def table(self) -> Any:
        """Per level: the PID (and the ramped PID) next to the paper's PID (pandas)."""
        import pandas as pd

        from myoexo.evaluation.paper import PAPER_RESULTS

        rows = []
        for level, out in self.outcomes.items():
            ramp = self.ramped.get(level)
            rows.append(
                {
                    "level": level,
                    "gain": f"{self.params.gain(level):.4f}",
                    "subjects": out.subjects,
                    "PID final error (deg)": f"{out.final_error_deg:.2f} ± "
                    f"{out.final_error_std_deg:.2f}",
                    "paper": PAPER_RESULTS[level].pid_final_error_text,
                    "PID overshoot (deg)": f"{out.overshoot_deg:.2f}",
                    "PID peak exo (Nm)": f"{out.peak_exo_torque_nm:.0f}",
                    f"ramped {self.ramp_s:g} s final error (deg)": "-"
                    if ramp is None
                    else f"{ramp.final_error_deg:.2f} ± {ramp.final_error_std_deg:.2f}",
                    "ramped peak exo (Nm)": "-"
                    if ramp is None
                    else f"{ramp.peak_exo_torque_nm:.0f}",
                    "ramped settling (s)": "-" if ramp is None else f"{ramp.settling_time_s:.2f}",
                }
            )
        return pd.DataFrame(rows)

    def snippet(self) -> str:
        """The fitted gains as Python, for :data:`myoexo.spasticity.reflex.PERSISTENT`."""
        items = ", ".join(f"{lv}: {g:.4f}" for lv, g in sorted(self.params.gains.items()))
        return f"gains=MappingProxyType({{{items}}})"


def calibrate_persistent(
    subjects: int = 30,
    verify_subjects: int = 200,
    level1_fraction: float = 0.5,
    ramp_s: float = 3.0,
    targets: CalibrationTargets | None = None,
    root_seed: int = CALIBRATION_ROOT_SEED,
    levels: Sequence[int] = VALID_LEVELS,
    base: PersistentParams = PERSISTENT,
    log: Callable[[str], None] = print,
    check_root_seed: int = EVALUATION_ROOT_SEED,
) -> PersistentCalibrationResult:
    """Fit the after-discharge gains of the target levels (2, 3) of the ``"persistent"``
    model, set level 1's to ``level1_fraction`` x level 2's (chosen, not fitted; checked:
    the PID must still reach the target), then verify every level and run the ramped PID at
    the fitted levels.

    Args:
        subjects: Subjects per level during the fit.
        verify_subjects: Subjects per level of the verification.
        level1_fraction: Level 1's gain as a fraction of level 2's.
        ramp_s: Ramp duration of the gentle controller, s.
        targets: What to fit (default :class:`CalibrationTargets`).
        root_seed: Root seed of the subjects the fit uses (the calibration root; the
            evaluation root is refused).
        levels: Levels to verify.
        base: The after-discharge's other parameters (threshold, time constants).
        log: Progress lines.
        check_root_seed: Root seed of the verification's subjects (default: the evaluation
            root).
    """
    root_seed = check_fit_root(root_seed, "calibration")
    t0 = time.perf_counter()
    tg = targets or CalibrationTargets()
    gains = {lv: 0.0 for lv in VALID_LEVELS}
    reflex = PersistentReflex(after_discharge=base)
    reflex = _with_gains(reflex, gains)
    fitted: dict[int, PIDOutcome] = {}
    for level, target in sorted(tg.pid_final_error_deg.items()):
        log(f"fitting level {level}: PID final error -> {target} deg ({subjects} subjects)")
        gain, fitted[level] = fit_persistent_gain(
            level, target, reflex, subjects, root_seed, log=log
        )
        gains[level] = round(gain, 4)
        reflex = _with_gains(reflex, gains)
    if 2 in gains and 1 in gains:
        gains[1] = round(level1_fraction * gains[2], 4)
        reflex = _with_gains(reflex, gains)
    log(f"verifying on {verify_subjects} subjects per level")
    outcomes = {lv: pid_outcome(lv, reflex, verify_subjects, check_root_seed) for lv in levels}
    log(f"ramped PID ({ramp_s:g} s) on {verify_subjects} subjects per fitted level")
    ramped = {
        lv: pid_outcome(lv, reflex, verify_subjects, check_root_seed, ramp_s=ramp_s)
        for lv in sorted(tg.pid_final_error_deg)
        if lv in levels
    }
    elapsed = time.perf_counter() - t0
    note = (
        f"myoexo twin calibrate --reflex persistent --subjects {subjects} --verify-subjects "
        f"{verify_subjects} --level1-fraction {level1_fraction} --seed {root_seed}: fitted on "
        f"root {root_seed}; check on root {check_root_seed}, PID final error "
        + ", ".join(
            f"L{lv} {o.final_error_deg:.2f} +- {o.final_error_std_deg:.2f} deg"
            for lv, o in outcomes.items()
        )
        + f"; PID ramped over {ramp_s:g} s: "
        + ", ".join(
            f"L{lv} {o.final_error_deg:.2f} +- {o.final_error_std_deg:.2f} deg"
            for lv, o in ramped.items()
        )
    )
    params = dataclasses.replace(reflex.after_discharge, note=note, root_seed=root_seed)
    return PersistentCalibrationResult(
        params=params,
        reflex=dataclasses.replace(reflex, after_discharge=params),
        outcomes=outcomes,
        ramped=ramped,
        ramp_s=ramp_s,
        targets=tg,
        wall_time_s=elapsed,
        fit_outcomes=fitted,
        fit_root_seed=root_seed,
        check_root_seed=check_root_seed,
    )


# ----------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class CalibrationConfig:
    """The options of ``myoexo twin calibrate`` that every model's fit takes (each field is
    an option; a model's own options are the fields of its fit's :attr:`ReflexFit.options`).

    Raises:
        ValueError: A field out of its range (:class:`~myoexo.runtime.fields.FieldError`), a
            model without a fit, the evaluation root, or ``write`` for a model whose
            parameters are chosen, not fitted.
    """

    reflex: str = option(
        "stretch",
        "the reflex model to fit; each model's own options are listed below under its name",
        metavar="MODEL",
    )
    subjects: int = option(40, "subjects per level in the fit", low=2)
    verify_subjects: int = option(200, "subjects per level of the check", low=2)
    root_seed: int = option(
        CALIBRATION_ROOT_SEED,
        f"root seed of the fit's subjects (the calibration root; the evaluation root "
        f"{EVALUATION_ROOT_SEED} is refused); the verification runs on the evaluation root",
        low=0,
        flag="seed",
    )
    out: Path | None = option(
        None,
        "folder for calibration.md and .csv (default: none, print only)",
        folder=True,
        metavar="DIR",
    )
    write: bool = option(
        False,
        "make the fit the package's (myoexo/assets/fits/reflex_<model>.json, with its "
        "provenance), which the reflex model then reads (a model whose parameters are "
        "chosen, not fitted, refuses it)",
    )

    def __post_init__(self) -> None:
        check_fields(self)
        if self.reflex not in _FITS:
            raise FieldError(
                type(self).__name__, "reflex", self.reflex, f"has no fit; fits: {', '.join(_FITS)}"
            )
        check_fit_root(self.root_seed, "calibration")
        if self.write and not _FITS[self.reflex].writes:
            writers = ", ".join(f.model for f in _FITS.values() if f.writes)
            raise ValueError(
                f"--write with --reflex {self.reflex}: its parameters are chosen, not fitted; "
                f"--write takes {writers}"
            )


@dataclass(frozen=True)
class ReflexFit:
    """How ``myoexo twin calibrate --reflex MODEL`` fits one reflex model.

    Attributes:
        model: The registered reflex model it fits.
        help: One line on what is fitted (the description of its options in ``--help``).
        run: ``run(config, options) -> exit status``: fit, report, and with
            ``config.write`` (when :attr:`writes`) make the fit the package's; *config* is
            the :class:`CalibrationConfig`, *options* an instance of :attr:`options` (``None``
            without).
        options: A frozen dataclass whose :func:`~myoexo.runtime.fields.option` fields are
            the options only this model's fit takes (``None``: none), e.g.
            :class:`ThresholdFitOptions`; their values are checked
            (:func:`~myoexo.runtime.fields.check_fields`) before the fit runs.
        writes: Whether ``--write`` applies (a model whose parameters are chosen, not
            fitted, refuses it).
    """

    model: str
    help: str
    run: Callable[[CalibrationConfig, Any], int]
    options: type | None = None
    writes: bool = True


_FITS: dict[str, ReflexFit] = {}


def _fit_fields(fit: ReflexFit) -> dict[str, dataclasses.Field[Any]]:
    """The option fields of a fit's own options, by name."""
    return {} if fit.options is None else {f.name: f for f in option_fields(fit.options)}


def _declaration(cls: type, f: dataclasses.Field[Any]) -> tuple[Any, ...]:
    """What makes two option fields the same option: type, default and spec."""
    import typing

    return (typing.get_type_hints(cls)[f.name], f.default, f.metadata)


def register_fit(fit: ReflexFit, *, replace: bool = False) -> ReflexFit:
    """Make *fit* what ``myoexo twin calibrate --reflex <fit.model>`` runs (a plug-in module
    that registers a reflex model registers its fit here too).

    Raises:
        ValueError: If the model has a fit already (unless *replace*), or an option of the
            fit is a common option (:class:`CalibrationConfig`) or has the name of another
            fit's option with other settings.
    """
    if fit.model in _FITS and not replace:
        raise ValueError(f"the reflex model {fit.model!r} has a fit already")
    if fit.options is not None and not dataclasses.is_dataclass(fit.options):
        raise ValueError(f"the {fit.model!r} fit's options {fit.options!r} are not a dataclass")
    common = {f.name for f in dataclasses.fields(CalibrationConfig)}
    for name, field in _fit_fields(fit).items():
        if name in common:
            raise ValueError(f"{flag_of(field)} of the {fit.model!r} fit is a common option")
        for other in _FITS.values():
            theirs = _fit_fields(other).get(name)
            if (
                other.model != fit.model
                and theirs is not None
                and other.options is not None
                and fit.options is not None
                and _declaration(other.options, theirs) != _declaration(fit.options, field)
            ):
                raise ValueError(
                    f"{flag_of(field)} of the {fit.model!r} fit differs from the "
                    f"{other.model!r} fit's option of that name"
                )
    _FITS[fit.model] = fit
    return fit


def fit_names() -> tuple[str, ...]:
    """The reflex models ``myoexo twin calibrate`` can fit."""
    return tuple(_FITS)


def _owners() -> dict[str, tuple[dataclasses.Field[Any], list[str]]]:
    """Each model option's name -> its field and the models whose fit takes it."""
    owners: dict[str, tuple[dataclasses.Field[Any], list[str]]] = {}
    for fit in _FITS.values():
        for name, field in _fit_fields(fit).items():
            owners.setdefault(name, (field, []))[1].append(fit.model)
    return owners


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin calibrate``: :class:`CalibrationConfig`'s fields, then each
    model's own (the fields of its fit's options), grouped by the models that take them."""
    add_options(parser, CalibrationConfig)
    groups: dict[str, argparse._ArgumentGroup] = {}
    added: set[str] = set()
    owners = _owners()
    for fit in _FITS.values():
        names = list(_fit_fields(fit))
        for name in names:
            if name in added or fit.options is None:
                continue
            models = owners[name][1]
            title = "--reflex " + ", ".join(models)
            if title not in groups:
                about = "; ".join(f"{m}: {_FITS[m].help}" for m in models)
                groups[title] = parser.add_argument_group(title, about)
            group = groups[title]
            others = [n for n in names if n != name]
            add_options(group, fit.options, exclude=others, given_only=True)
            added.add(name)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo twin calibrate``: the registered fit of ``--reflex``."""
    config = from_options(CalibrationConfig, args)
    fit = _FITS[config.reflex]
    mine = _fit_fields(fit)
    for name, (field, models) in _owners().items():
        if name not in mine and hasattr(args, name):
            raise ValueError(
                f"{flag_of(field)} is an option of --reflex {' / '.join(models)}, not of "
                f"--reflex {config.reflex}"
            )
    options = None if fit.options is None else from_options(fit.options, args)
    if options is not None:
        check_fields(options)  # a plug-in's options class may not check its own
    return fit.run(config, options)


@dataclass(frozen=True)
class ThresholdFitOptions:
    """The options of the threshold fit (``--reflex stretch`` and ``spindle``)."""

    delay_s: float = option(STRETCH_DELAY_S, "reflex delay", low=0.0, high=1.0, unit="s")
    extensor_gain: float = option(
        1.0, "gain of the extensors' reflex at levels 1-3, fixed", low=0.0
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class PersistentFitOptions:
    """The options of the ``persistent`` fit (:func:`calibrate_persistent`)."""

    level1_fraction: float = option(
        0.5, "level 1's gain as a fraction of level 2's", low=0.0, high=1.0
    )
    ramp_s: float = option(
        3.0, "ramp of the gentle PID checked after the fit", low=0.0, high=60.0, unit="s"
    )

    def __post_init__(self) -> None:
        check_fields(self)


@dataclass(frozen=True)
class TsrtFitOptions:
    """The options of the ``tsrt`` fit (:func:`myoexo.studies.joint_fit.calibrate_tsrt`)."""

    clinical_subjects: int = option(
        1, "subjects per level of the clinical tests in the fit", low=1, high=10_000
    )
    sweeps: int = option(2, "coordinate sweeps of the joint fit", low=0)
    start: Path | None = option(
        None,
        "JSON of the values the search starts from (a calibration's levels, or a fit file; "
        "default: the model's current fit)",
        metavar="JSON",
    )

    def __post_init__(self) -> None:
        check_fields(self)


def _run_threshold_fit(config: CalibrationConfig, options: ThresholdFitOptions) -> int:
    """The stretch or spindle reflex: the flexors' threshold shift at levels 2-3."""
    reflex = config.reflex
    base: StretchReflex = StretchReflex()
    if reflex == "spindle":
        from myoexo.spasticity.spindle import SpindleReflex, spindle_geometry

        base = SpindleReflex(geometry=spindle_geometry())
    result = calibrate(
        config.subjects,
        config.verify_subjects,
        options.delay_s,
        extensor_gain=options.extensor_gain,
        root_seed=config.root_seed,
        base=base,
    )
    code = _report(reflex, result.calibration.note, "", result, config.out)
    if config.write:
        if reflex == "spindle":
            from myoexo.spasticity.spindle import SPINDLE_FIT

            _write_calibration(
                SPINDLE_FIT,
                result.calibration,
                result.fit_root_seed,
                {"geometry": base.geometry.to_dict()},  # type: ignore[attr-defined]
            )
        else:
            from myoexo.spasticity.reflex import STRETCH_FIT

            _write_calibration(STRETCH_FIT, result.calibration, result.fit_root_seed)
    return code


def _write_calibration(
    name: str, calibration: Any, root_seed: int, extra: dict[str, Any] | None = None
) -> None:
    """Make a reflex model's fitted *calibration* the package's fit *name*, with its
    provenance (the command is the calibration note's, which names every option); with
    *extra*, the fit is ``{"calibration": ..., **extra}``."""
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import write_command_fit

    command = calibration.note.split(":")[0]
    result = calibration.to_dict()
    if extra is not None:
        result = {"calibration": result, **extra}
    write_command_fit(name, result, command, TWIN_VERSION, root_seed=root_seed)


def fit_table(result: Any) -> Any:
    """The fit's own numbers: per fitted level, the PID on the fit's subjects at the fitted
    value, next to its target (in-sample; pandas)."""
    import pandas as pd

    rows = [
        {
            "level": level,
            "subjects": out.subjects,
            "PID final error (deg)": f"{out.final_error_deg:.2f} ± {out.final_error_std_deg:.2f}",
            "target (deg)": f"{result.targets.pid_final_error_deg[level]:g}",
        }
        for level, out in sorted(result.fit_outcomes.items())
    ]
    return pd.DataFrame(rows)


def _report(model: str, note: str, constant: str, result: Any, out: Path | None) -> int:
    """Print the calibration's text (and write ``calibration.md`` / ``.csv`` to *out*): the
    fit's own numbers on the calibration root, labelled as the fit, then the check on the
    evaluation root."""
    table = result.table()
    where = (
        f"in myoexo.spasticity.reflex.{constant}"
        if constant
        else f"the package's with --write: myoexo/assets/fits/reflex_{model}.json"
    )
    text = (
        f"# Calibration of the {model} reflex\n\n{note}\n\n"
        f"Fitted values ({where}):\n\n```python\n"
        f"{result.snippet()}\n```\n\n"
        f"**The fit** (in-sample: the subjects of root {result.fit_root_seed} the values were "
        f"fitted on):\n\n{fit_table(result).to_markdown(index=False)}\n\n"
        f"**The check** (root {result.check_root_seed}, subjects the fit never saw):\n\n"
        f"{table.to_markdown(index=False)}\n\n"
        f"Wall time {result.wall_time_s:.0f} s.\n"
    )
    print(text)
    if out is not None:
        from myoexo.runtime.files import atomic_path, write_text_atomic

        write_text_atomic(out / "calibration.md", text)
        with atomic_path(out / "calibration.csv") as path:
            table.to_csv(path, index=False)
    return 0


def _run_persistent(config: CalibrationConfig, options: PersistentFitOptions) -> int:
    result = calibrate_persistent(
        config.subjects,
        config.verify_subjects,
        level1_fraction=options.level1_fraction,
        ramp_s=options.ramp_s,
        root_seed=config.root_seed,
    )
    return _report("persistent", result.params.note, "PERSISTENT", result, config.out)


def _run_tsrt(config: CalibrationConfig, options: TsrtFitOptions) -> int:
    """The tsrt reflex, on the knee angle or (``spindle_tsrt``) on each muscle's state."""
    from myoexo.spasticity.registry import get_reflex
    from myoexo.studies.joint_fit import calibrate_tsrt

    start = None
    if options.start is not None:
        doc = json.loads(Path(options.start).read_text())
        levels = doc.get("result", doc) if isinstance(doc, dict) else None
        if not isinstance(levels, dict) or not isinstance(levels.get("levels"), dict):
            raise ValueError(
                f"--start {options.start}: expected a calibration's JSON with its 'levels' "
                "(as the fit's calibration.to_dict() or a package fit file holds it)"
            )
        kind = type(get_reflex(config.reflex).calibration)  # type: ignore[attr-defined]
        start = kind.from_dict(levels)
    result = calibrate_tsrt(
        start=start,
        start_source=None if options.start is None else str(options.start),
        pid_subjects=config.subjects,
        clinical_subjects=options.clinical_subjects,
        sweeps=options.sweeps,
        verify_subjects=config.verify_subjects,
        root_seed=config.root_seed,
        reflex=config.reflex,
    )
    text = result.markdown()
    print(text)
    if config.out is not None:
        from myoexo.runtime.files import write_study_files

        write_study_files(config.out, {"calibration.md": text})
    if config.write:
        from myoexo.studies.joint_fit import FITTED_MODELS

        _write_calibration(FITTED_MODELS[config.reflex], result.calibration, result.fit_root_seed)
    return 0


register_fit(
    ReflexFit(
        "stretch",
        "the flexors' threshold shift at levels 2-3, to the paper's PID",
        _run_threshold_fit,
        ThresholdFitOptions,
    )
)
register_fit(
    ReflexFit(
        "spindle",
        "the same fit on the muscles' fibre lengths measured on the twin",
        _run_threshold_fit,
        ThresholdFitOptions,
    )
)
register_fit(
    ReflexFit(
        "persistent",
        "the after-discharge gains at levels 2-3 by bisection (chosen, not written)",
        _run_persistent,
        PersistentFitOptions,
        writes=False,
    )
)
register_fit(
    ReflexFit(
        "tsrt",
        "jointly to the PID table and the clinical rows (myoexo.studies.joint_fit)",
        _run_tsrt,
        TsrtFitOptions,
    )
)
register_fit(
    ReflexFit(
        "spindle_tsrt",
        "the same joint fit on the muscles' fibre lengths, from tsrt's fit",
        _run_tsrt,
        TsrtFitOptions,
    )
)
register_fit(
    ReflexFit(
        "spindle_tone",
        "spindle_tsrt's joint fit with the flexors' length tone and a phasic scale per level",
        _run_tsrt,
        TsrtFitOptions,
    )
)
