"""``myoexo calibrate``: fit a reflex model so that the paper's PID behaves as in the study.

Each reflex model registers its own fit (:func:`register_fit`, a :class:`ReflexFit` with the
options only that fit takes); ``--reflex MODEL`` runs it, and an option of another model's
fit is refused with one line naming whose it is. Built in: ``stretch`` and ``spindle`` (the
threshold fit below), ``persistent`` (:func:`calibrate_persistent`) and ``tsrt``
(:mod:`myoexo.studies.joint_fit`).

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

    myoexo calibrate --subjects 40 --verify-subjects 200 --out results/calibration

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

    myoexo calibrate --reflex persistent --subjects 30 --verify-subjects 200

prints :data:`myoexo.spasticity.reflex.PERSISTENT`'s gains and the table.
"""

from __future__ import annotations

import argparse
import dataclasses
import math
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
    "CalibrationResult",
    "CalibrationTargets",
    "PIDOutcome",
    "bisect_final_error",
    "calibrate",
    "calibrate_persistent",
    "pid_outcome",
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
        f"myoexo calibrate{model_flag} --subjects {subjects} --verify-subjects {verify_subjects} "
        f"--delay {delay_s} --extensor-gain {extensor_gain} --seed {root_seed}: fitted on "
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
        f"myoexo calibrate --reflex persistent --subjects {subjects} --verify-subjects "
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
# ------------------------------------------------------------------ the command line
@dataclass(frozen=True)
class FitOption:
    """One option of a model's fit: its flag, its default and the rest of
    ``ArgumentParser.add_argument``'s keywords (``type``, ``help``)."""

    flag: str
    default: Any
    kwargs: Mapping[str, Any] = dataclasses.field(default_factory=dict)

    @property
    def dest(self) -> str:
        return _dest(self.flag)


@dataclass(frozen=True)
class ReflexFit:
    """How ``myoexo calibrate --reflex MODEL`` fits one reflex model.

    Attributes:
        model: The registered reflex model it fits.
        help: One line on what is fitted, for ``--help``.
        run: ``run(args) -> exit status``: fit, report, and with ``--write`` (when
            :attr:`writes`) make the fit the package's.
        options: The options only this model's fit takes (the common ones: ``--subjects``,
            ``--verify-subjects``, ``--seed``, ``--out``, ``--write``).
        writes: Whether ``--write`` applies (a model whose parameters are chosen, not
            fitted, refuses it).
    """

    model: str
    help: str
    run: Callable[[argparse.Namespace], int]
    options: tuple[FitOption, ...] = ()
    writes: bool = True


_FITS: dict[str, ReflexFit] = {}


def _dest(flag: str) -> str:
    """The namespace attribute argparse makes of an option flag."""
    return flag.removeprefix("--").replace("-", "_")


def register_fit(fit: ReflexFit, *, replace: bool = False) -> ReflexFit:
    """Make *fit* what ``myoexo calibrate --reflex <fit.model>`` runs (a plug-in module that
    registers a reflex model registers its fit here too).

    Raises:
        ValueError: If the model has a fit already (unless *replace*), or an option of the
            fit has the flag of another fit's option with other settings.
    """
    if fit.model in _FITS and not replace:
        raise ValueError(f"the reflex model {fit.model!r} has a fit already")
    for option in fit.options:
        for other in _FITS.values():
            for theirs in other.options:
                if theirs.flag == option.flag and theirs != option and other.model != fit.model:
                    raise ValueError(
                        f"{option.flag} of the {fit.model!r} fit differs from the "
                        f"{other.model!r} fit's option of that name"
                    )
    _FITS[fit.model] = fit
    return fit


def fit_names() -> tuple[str, ...]:
    """The reflex models ``myoexo calibrate`` can fit."""
    return tuple(_FITS)


def _owners() -> dict[str, list[str]]:
    """Each model option's flag -> the models whose fit takes it."""
    owners: dict[str, list[str]] = {}
    for fit in _FITS.values():
        for option in fit.options:
            owners.setdefault(option.flag, []).append(fit.model)
    return owners


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo calibrate``: the common ones, then each model's own, grouped by
    the models that take them."""
    parser.add_argument(
        "--reflex",
        choices=fit_names(),
        default="stretch",
        help="the reflex model to fit (default: %(default)s); each model's own options "
        "are listed below under its name",
    )
    parser.add_argument("--subjects", type=int, default=40, help="subjects per level in the fit")
    parser.add_argument(
        "--verify-subjects", type=int, default=200, help="subjects per level of the check"
    )
    parser.add_argument(
        "--seed",
        type=int,
        default=CALIBRATION_ROOT_SEED,
        help=f"root seed of the fit's subjects (default: the calibration root "
        f"{CALIBRATION_ROOT_SEED}; the evaluation root {EVALUATION_ROOT_SEED} is refused); the "
        "verification runs on the evaluation root",
    )
    parser.add_argument(
        "--out", type=Path, default=None, help="folder for calibration.md and .csv (optional)"
    )
    parser.add_argument(
        "--write",
        action="store_true",
        help="make the fit the package's (myoexo/assets/fits/reflex_<model>.json, with its "
        "provenance), which the reflex model then reads; models: "
        + ", ".join(fit.model for fit in _FITS.values() if fit.writes),
    )
    groups: dict[str, argparse._ArgumentGroup] = {}
    added: set[str] = set()
    owners = _owners()
    for fit in _FITS.values():
        for option in fit.options:
            if option.flag in added:
                continue
            title = "--reflex " + ", ".join(owners[option.flag])
            group = groups.get(title) or groups.setdefault(title, parser.add_argument_group(title))
            kwargs = dict(option.kwargs)
            kwargs["help"] = f"{kwargs.get('help', '')} (default: {option.default})".strip()
            group.add_argument(option.flag, default=argparse.SUPPRESS, **kwargs)
            added.add(option.flag)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo calibrate``: the registered fit of ``--reflex``."""
    for name in ("subjects", "verify_subjects"):
        if getattr(args, name) < 2:
            raise ValueError(f"--{name.replace('_', '-')} = {getattr(args, name)} must be >= 2")
    model = getattr(args, "reflex", "stretch")
    if model not in _FITS:
        raise ValueError(f"--reflex {model!r} has no fit; fits: {', '.join(fit_names())}")
    fit = _FITS[model]
    mine = {option.flag for option in fit.options}
    for flag, models in _owners().items():
        if flag not in mine and hasattr(args, _dest(flag)):
            raise ValueError(
                f"{flag} is an option of --reflex {' / '.join(models)}, not of --reflex {model}"
            )
    for option in fit.options:
        if not hasattr(args, option.dest):
            setattr(args, option.dest, option.default)
    if getattr(args, "write", False) and not fit.writes:
        writers = ", ".join(f.model for f in _FITS.values() if f.writes)
        raise ValueError(
            f"--write with --reflex {model}: its parameters are chosen, not fitted; --write "
            f"takes {writers}"
        )
    return fit.run(args)


def _run_threshold_fit(args: argparse.Namespace) -> int:
    """The stretch or spindle reflex: the flexors' threshold shift at levels 2-3."""
    reflex = args.reflex
    base: StretchReflex = StretchReflex()
    if reflex == "spindle":
        from myoexo.spasticity.spindle import SpindleReflex, spindle_geometry

        base = SpindleReflex(geometry=spindle_geometry())
    result = calibrate(
        args.subjects,
        args.verify_subjects,
        args.delay,
        extensor_gain=args.extensor_gain,
        root_seed=args.seed,
        base=base,
    )
    code = _report(reflex, result.calibration.note, "", result, args.out)
    if getattr(args, "write", False):
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
    from myoexo.runtime.fits import provenance, write_fit

    command = calibration.note.split(":")[0]
    result = calibration.to_dict()
    if extra is not None:
        result = {"calibration": result, **extra}
    path = write_fit(
        name,
        result,
        provenance(f"{command} --write", TWIN_VERSION, root_seed=root_seed),
    )
    print(f"written: {path}")


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


def _run_persistent(args: argparse.Namespace) -> int:
    if not (math.isfinite(args.level1_fraction) and 0.0 <= args.level1_fraction <= 1.0):
        raise ValueError(f"--level1-fraction = {args.level1_fraction!r} is outside [0, 1]")
    result = calibrate_persistent(
        args.subjects,
        args.verify_subjects,
        level1_fraction=args.level1_fraction,
        ramp_s=args.ramp_s,
        root_seed=args.seed,
    )
    return _report("persistent", result.params.note, "PERSISTENT", result, args.out)


def _run_tsrt(args: argparse.Namespace) -> int:
    from myoexo.studies.joint_fit import calibrate_tsrt

    if args.clinical_subjects < 1:
        raise ValueError(f"--clinical-subjects = {args.clinical_subjects} must be >= 1")
    result = calibrate_tsrt(
        pid_subjects=args.subjects,
        clinical_subjects=args.clinical_subjects,
        sweeps=args.sweeps,
        verify_subjects=args.verify_subjects,
        root_seed=args.seed,
    )
    text = result.markdown()
    print(text)
    if args.out is not None:
        from myoexo.runtime.files import write_study_files

        write_study_files(args.out, {"calibration.md": text})
    if getattr(args, "write", False):
        from myoexo.spasticity.tsrt import TSRT_FIT

        _write_calibration(TSRT_FIT, result.calibration, result.fit_root_seed)
    return 0


_THRESHOLD_OPTIONS = (
    FitOption("--delay", STRETCH_DELAY_S, {"type": float, "help": "reflex delay, s"}),
    FitOption(
        "--extensor-gain",
        1.0,
        {"type": float, "help": "gain of the extensors' reflex at levels 1-3, fixed"},
    ),
)
register_fit(
    ReflexFit(
        "stretch",
        "the flexors' threshold shift at levels 2-3, to the paper's PID",
        _run_threshold_fit,
        _THRESHOLD_OPTIONS,
    )
)
register_fit(
    ReflexFit(
        "spindle",
        "the same fit on the muscles' fibre lengths measured on the twin",
        _run_threshold_fit,
        _THRESHOLD_OPTIONS,
    )
)
register_fit(
    ReflexFit(
        "persistent",
        "the after-discharge gains at levels 2-3 by bisection (chosen, not written)",
        _run_persistent,
        (
            FitOption(
                "--level1-fraction",
                0.5,
                {"type": float, "help": "level 1's gain as a fraction of level 2's"},
            ),
            FitOption(
                "--ramp-s",
                3.0,
                {"type": float, "help": "ramp of the gentle PID checked after the fit, s"},
            ),
        ),
        writes=False,
    )
)
register_fit(
    ReflexFit(
        "tsrt",
        "jointly to the PID table and the clinical rows (myoexo.studies.joint_fit)",
        _run_tsrt,
        (
            FitOption(
                "--clinical-subjects",
                1,
                {"type": int, "help": "subjects per level of the clinical tests in the fit"},
            ),
            FitOption("--sweeps", 2, {"type": int, "help": "coordinate sweeps of the joint fit"}),
        ),
    )
)
