"""Ziegler-Nichols tuning of the knee PID on the digital twin (``myoexo twin tune-pid``).

The paper tuned its PID "to a spasticity level of 1 following the Ziegler-Nichols method"
and reports Kp = 7, Ki = 40, Kd = 0.05 (docs/reference.md section 4). This module runs the
closed-loop ("ultimate sensitivity") procedure of Ziegler & Nichols, "Optimum settings for automatic
controllers", Trans. ASME 64 (1942), on the twin:

1. P-only control (Ki = Kd = 0) of the knee extension task at level 1, on the level's
   nominal Table I subject (or a seeded individual subject);
2. raise Kp until the knee oscillates with a sustained amplitude: bracket by doubling, then
   geometric bisection down to a relative tolerance; the smallest sustained gain is the
   ultimate gain ``Ku`` and the oscillation period there the ultimate period ``Tu``;
3. apply the classic PID table: ``Kp = 0.6 Ku``, ``Ti = Tu / 2``, ``Td = Tu / 8``, i.e.
   ``Ki = 1.2 Ku / Tu`` and ``Kd = 0.075 Ku Tu`` in parallel form.

"Sustained" is judged on the error after ``analysis_start_s`` (the transient of the 83 deg
extension excluded), mean removed: at least ``min_half_cycles`` zero crossings, a last
half-cycle amplitude of at least ``min_amplitude_deg``, and a ratio of the last to the first
half-cycle amplitudes of at least ``sustain_ratio`` (no more decay than that over the
window). The motor saturates at +-1 (100 Nm), so beyond ``Ku`` the loop settles into a
bounded limit cycle rather than diverging, which is what the test detects.

The paper's gains invert to ``Ku = Kp / 0.6 = 11.7`` and ``Tu = 1.2 Ku / Ki = 0.35 s``
(:func:`implied_ultimate`), for which the classic table would give ``Kd = 0.31``, six times
the paper's 0.05: the paper's Kd was evidently not taken from the table.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import json
import math
import shlex
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.pid import PID, PIDConfig, PIDGains
from myoexo.control.rollout import rollout
from myoexo.runtime.fields import (
    FieldError,
    add_options,
    check_fields,
    from_options,
    option,
    option_words,
)
from myoexo.spasticity.levels import VALID_LEVELS

#: Classic Ziegler-Nichols closed-loop PID table: Kp = a Ku, Ti = Tu / b, Td = Tu / c.
ZN_KP_FACTOR = 0.6
ZN_TI_FRACTION = 0.5
ZN_TD_FRACTION = 0.125


@dataclass(frozen=True)
class ZieglerNicholsSettings:
    """Settings of the ultimate-gain search (``level``, ``nominal_subject``, ``seed``,
    ``feedback``, ``latency_s``, ``target_angle_deg`` and ``rel_tol`` are options of
    ``myoexo twin tune-pid``).

    Attributes:
        level: Spasticity level of the tuning (paper: 1).
        nominal_subject: Use the level's nominal Table I parameters (no subject noise);
            ``False`` draws an individual subject from ``seed``.
        seed: Episode seed (start-angle perturbation; the subject if not nominal).
        feedback: Feedback signal of the P controller (``"knee"`` or ``"exo"``).
        latency_s: Sensor latency of the tuning twin (s, a whole number of 10-ms control
            periods; 0: exact sensors): tunes a PID for the latency it will run with, e.g.
            the perturbed twins' 10 ms. Only the latency is applied (no noise, no other
            perturbation), so the ultimate gain is that of the nominal plant seen late.
        target_angle_deg: Operating point of the test (knee target, deg); ``None``: the
            task's (7 deg). A target the motor cannot reach (the loop then sits saturated
            against a limit) gives no oscillation at any gain.
        kp_start: First gain tried (1/rad).
        kp_max: Give up above this gain (1/rad).
        rel_tol: Stop the bisection when ``hi / lo - 1 < rel_tol``.
        analysis_start_s: Start of the analysis window (s), after the extension transient.
        episode_duration_s: Episode length (s); ``None``: the env's default (8 s).
        min_half_cycles: Minimum zero crossings in the window for an oscillation.
        min_amplitude_deg: Minimum amplitude of the last half cycle (deg).
        sustain_ratio: Minimum ratio of last to first half-cycle amplitude.
    """

    level: int = option(1, "spasticity level of the tuning (paper: 1)", choices=VALID_LEVELS)
    nominal_subject: bool = option(
        True,
        "tune on the level's nominal Table I subject (--no-nominal-subject: an individual "
        "subject drawn from --seed)",
    )
    seed: int = option(0, "episode seed (the start angle; the subject if not nominal)", low=0)
    feedback: str = option("knee", "feedback signal of the P controller", choices=("knee", "exo"))
    latency_s: float = option(
        0.0,
        "sensor latency of the tuning twin, a whole number of 10-ms control periods (0: exact "
        "sensors)",
        low=0.0,
        high=1.0,
        unit="s",
    )
    target_angle_deg: float | None = option(
        None, "target knee angle of the test (default: the task's, 7 deg)", unit="deg"
    )
    kp_start: float = option(1.0, "first gain tried, 1/rad", low=0.0, above=True, flag="")
    kp_max: float = option(2000.0, "give up above this gain, 1/rad", low=0.0, above=True, flag="")
    rel_tol: float = option(
        0.03, "bisection tolerance (stop when hi / lo - 1 < it)", low=0.0, above=True, high=1.0
    )
    analysis_start_s: float = option(
        3.0, "start of the analysis window", low=0.0, unit="s", flag=""
    )
    episode_duration_s: float | None = option(
        None, "episode length (default: the env's)", unit="s", flag=""
    )
    min_half_cycles: int = option(
        6, "minimum zero crossings in the window for an oscillation", low=2, flag=""
    )
    min_amplitude_deg: float = option(
        0.05, "minimum amplitude of the last half cycle", low=0.0, unit="deg", flag=""
    )
    sustain_ratio: float = option(
        0.9,
        "minimum ratio of last to first half-cycle amplitude",
        low=0.0,
        above=True,
        high=1.5,
        flag="",
    )

    def __post_init__(self) -> None:
        from myoexo.envs.config import TaskParams

        check_fields(self)
        if not self.kp_start < self.kp_max:
            raise ValueError(f"need kp_start ({self.kp_start}) < kp_max ({self.kp_max})")
        task = {"target_angle_deg": self.target_angle_deg}
        task["episode_duration_s"] = self.episode_duration_s
        TaskParams(**{k: v for k, v in task.items() if v is not None})  # the task's ranges


@dataclass(frozen=True)
class Oscillation:
    """Oscillation of a signal about its mean over an analysis window.

    Attributes:
        half_cycles: Complete half cycles (between successive zero crossings).
        period_s: Mean period (twice the mean crossing interval), NaN if < 2 half cycles.
        first_amplitude: Peak |deviation| of the first half cycle.
        last_amplitude: Peak |deviation| of the last half cycle.
        amplitude_ratio: ``last_amplitude / first_amplitude`` (0 without half cycles).
    """

    half_cycles: int
    period_s: float
    first_amplitude: float
    last_amplitude: float
    amplitude_ratio: float


def analyze_oscillation(t_s: np.ndarray, y: np.ndarray, start_s: float = 0.0) -> Oscillation:
    """Zero crossings of ``y - mean(y)`` for ``t >= start_s``: period and amplitude decay."""
    t = np.asarray(t_s, dtype=float)
    y = np.asarray(y, dtype=float)
    sel = (t >= start_s) & np.isfinite(y)
    t, y = t[sel], y[sel]
    if y.size < 3:
        return Oscillation(0, math.nan, 0.0, 0.0, 0.0)
    yc = y - y.mean()
    neg = yc < 0.0
    idx = np.flatnonzero(neg[1:] != neg[:-1])  # sign change between idx and idx + 1
    # crossing times by linear interpolation
    frac = yc[idx] / (yc[idx] - yc[idx + 1])
    tc = t[idx] + frac * (t[idx + 1] - t[idx])
    amps = np.array([np.abs(yc[a + 1 : b + 1]).max() for a, b in itertools.pairwise(idx)])
    if amps.size == 0:
        return Oscillation(0, math.nan, 0.0, 0.0, 0.0)
    period = 2.0 * float(np.mean(np.diff(tc))) if tc.size >= 3 else math.nan
    return Oscillation(
        half_cycles=int(amps.size),
        period_s=period,
        first_amplitude=float(amps[0]),
        last_amplitude=float(amps[-1]),
        amplitude_ratio=float(amps[-1] / amps[0]) if amps[0] > 0 else 0.0,
    )


def classic_zn_gains(ku: float, tu_s: float) -> PIDGains:
    """Classic Ziegler-Nichols PID table in parallel form: ``Kp = 0.6 Ku``,
    ``Ki = Kp / (Tu / 2) = 1.2 Ku / Tu``, ``Kd = Kp Tu / 8 = 0.075 Ku Tu``."""
    if not (ku > 0 and tu_s > 0):
        raise ValueError(f"need Ku > 0 and Tu > 0, got Ku = {ku}, Tu = {tu_s}")
    kp = ZN_KP_FACTOR * ku
    return PIDGains(kp=kp, ki=kp / (ZN_TI_FRACTION * tu_s), kd=kp * ZN_TD_FRACTION * tu_s)


def implied_ultimate(gains: PIDGains) -> tuple[float, float]:
    """``(Ku, Tu)`` that the classic table maps to ``gains``' Kp and Ki (Kd not used)."""
    ku = gains.kp / ZN_KP_FACTOR
    return ku, gains.kp / (gains.ki * ZN_TI_FRACTION)


@dataclass(frozen=True)
class GainTrial:
    """One P-only episode of the search."""

    kp: float
    sustained: bool
    oscillation: Oscillation
    final_error_deg: float = math.nan
    saturated_fraction: float = math.nan


@dataclass(frozen=True)
class ZieglerNicholsResult:
    """Outcome of :func:`tune`.

    Attributes:
        ultimate_gain: ``Ku`` (1/rad), the smallest sustained gain found.
        ultimate_period_s: ``Tu`` (s), the oscillation period at ``Ku``.
        gains: Classic-table PID gains from ``Ku, Tu``.
        settings: The search settings.
        trials: Every P-only episode run, in order.
    """

    ultimate_gain: float
    ultimate_period_s: float
    gains: PIDGains
    settings: ZieglerNicholsSettings
    trials: tuple[GainTrial, ...] = field(default_factory=tuple)

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready summary, with the paper's gains and their implied ``Ku, Tu``."""
        paper = PIDGains()
        ku_p, tu_p = implied_ultimate(paper)
        return {
            "ultimate_gain_per_rad": self.ultimate_gain,
            "ultimate_period_s": self.ultimate_period_s,
            "zn_gains": asdict(self.gains),
            "paper_gains": asdict(paper),
            "paper_implied_ultimate_gain_per_rad": ku_p,
            "paper_implied_ultimate_period_s": tu_p,
            "settings": asdict(self.settings),
            "trials": [
                {"kp": tr.kp, "sustained": tr.sustained, **asdict(tr.oscillation)}
                for tr in self.trials
            ],
        }


def make_tuning_env(settings: ZieglerNicholsSettings, reflex: Any = None) -> Any:
    """The level's env; with ``nominal_subject`` its reflex keeps Table I's values; with a
    ``latency_s`` its sensors are that late (and exact). *reflex*: the reflex model (a
    registered name or a model; default: the envs' default)."""
    from myoexo.envs import make_env
    from myoexo.envs.robustness import RobustnessParams

    task = {
        name: value
        for name in ("episode_duration_s", "target_angle_deg")
        if (value := getattr(settings, name)) is not None
    }
    if reflex is not None:
        task["reflex"] = reflex
    robustness = None
    if settings.latency_s > 0.0:
        robustness = dataclasses.replace(RobustnessParams.nominal(), latency_s=settings.latency_s)
    return make_env(
        settings.level,
        subject_noise=not settings.nominal_subject,
        robustness=robustness,
        **task,
    )


def p_only_trial(env: Any, kp: float, settings: ZieglerNicholsSettings) -> GainTrial:
    """One episode under P-only control (no anti-windup needed: no integrator)."""
    config = PIDConfig(
        gains=PIDGains(kp=kp, ki=0.0, kd=0.0), anti_windup="none", feedback=settings.feedback
    )
    episode = rollout(
        env, PID.from_env(env, config), settings.seed, channels=("time_s", "error_deg", "command")
    )
    err = episode.signals["error_deg"]
    osc = analyze_oscillation(episode.signals["time_s"], err, settings.analysis_start_s)
    sustained = (
        osc.half_cycles >= settings.min_half_cycles
        and osc.last_amplitude >= settings.min_amplitude_deg
        and osc.amplitude_ratio >= settings.sustain_ratio
        and not episode.unstable
    )
    commands = episode.signals["command"][1:]  # the commands applied at the steps
    return GainTrial(
        kp=float(kp),
        sustained=bool(sustained),
        oscillation=osc,
        final_error_deg=float(err[-1]),
        saturated_fraction=float(np.mean(np.abs(commands) >= config.output_limit))
        if commands.size
        else 0.0,
    )


def tune(
    settings: ZieglerNicholsSettings | None = None,
    env: Any = None,
    log: Callable[[str], None] | None = None,
) -> ZieglerNicholsResult:
    """Run the Ziegler-Nichols ultimate-gain procedure on the twin.

    Args:
        settings: Search settings (defaults: level 1, nominal subject).
        env: Env to use (default: :func:`make_tuning_env`); closed only if created here.
        log: Called with one line per trial.

    Raises:
        RuntimeError: No sustained oscillation up to ``kp_max``.
    """
    s = settings or ZieglerNicholsSettings()
    own_env = env is None
    env = make_tuning_env(s) if own_env else env
    trials: list[GainTrial] = []

    def trial(kp: float) -> GainTrial:
        tr = p_only_trial(env, kp, s)
        trials.append(tr)
        if log:
            o = tr.oscillation
            log(
                f"Kp = {kp:9.3f}: {'sustained' if tr.sustained else 'decaying '}  "
                f"half cycles {o.half_cycles:3d}, last amplitude {o.last_amplitude:7.3f} deg, "
                f"ratio {o.amplitude_ratio:5.2f}, period {o.period_s:6.3f} s, final error "
                f"{tr.final_error_deg:6.2f} deg, saturated {100 * tr.saturated_fraction:3.0f} %"
            )
        return tr

    try:
        lo, hi = 0.0, s.kp_start
        hi_trial = trial(hi)
        while not hi_trial.sustained:
            lo, hi = hi, 2.0 * hi
            if hi > s.kp_max:
                last = trials[-1]
                why = (
                    "the knee is held off the target by something the motor cannot "
                    "overcome, e.g. a joint limit"
                    if last.saturated_fraction > 0.5
                    else "the loop is too damped for the closed-loop test"
                )
                raise RuntimeError(
                    f"no sustained oscillation up to Kp = {s.kp_max} (level {s.level}); at "
                    f"Kp = {last.kp:g} the final error was {last.final_error_deg:.2f} deg with "
                    f"the command saturated {100 * last.saturated_fraction:.0f} % of the time: "
                    + why
                )
            hi_trial = trial(hi)
        while lo > 0.0 and hi / lo - 1.0 > s.rel_tol:
            mid = math.sqrt(lo * hi)
            mid_trial = trial(mid)
            if mid_trial.sustained:
                hi, hi_trial = mid, mid_trial
            else:
                lo = mid
    finally:
        if own_env:
            env.close()
    ku, tu = hi_trial.kp, hi_trial.oscillation.period_s
    return ZieglerNicholsResult(
        ultimate_gain=ku,
        ultimate_period_s=tu,
        gains=classic_zn_gains(ku, tu),
        settings=s,
        trials=tuple(trials),
    )


def format_result(result: ZieglerNicholsResult) -> str:
    """Human-readable comparison of the tuned and the paper's gains."""
    g, p = result.gains, PIDGains()
    ku_p, tu_p = implied_ultimate(p)
    return "\n".join(
        [
            f"Ziegler-Nichols on the twin (level {result.settings.level}, "
            f"{'nominal' if result.settings.nominal_subject else 'seeded'} subject, "
            f"{result.settings.feedback} feedback, "
            f"{1000 * result.settings.latency_s:g} ms latency, target "
            f"{result.settings.target_angle_deg or 'of the task'} deg, "
            f"{len(result.trials)} P-only episodes):",
            f"  ultimate gain Ku = {result.ultimate_gain:.3f} /rad, "
            f"ultimate period Tu = {result.ultimate_period_s:.3f} s",
            "                      Kp (1/rad)  Ki (1/(rad s))  Kd (s/rad)",
            f"  classic ZN table    {g.kp:10.3f}  {g.ki:14.3f}  {g.kd:10.4f}",
            f"  paper               {p.kp:10.3f}  {p.ki:14.3f}  {p.kd:10.4f}",
            f"  (the paper's Kp, Ki imply Ku = {ku_p:.2f} /rad, Tu = {tu_p:.3f} s, "
            f"for which the table gives Kd = {classic_zn_gains(ku_p, tu_p).kd:.3f})",
        ]
    )


# ----------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class TuningOutput:
    """What ``myoexo twin tune-pid`` writes and prints (options of the command)."""

    out: Path | None = option(
        None, "write the result as JSON to this file (default: none)", metavar="FILE"
    )
    write: str | None = option(
        None,
        "write the result with its provenance as the package's tuned PID NAME "
        "(myoexo/assets/fits/pid_tuned_NAME.json), which pid:tuned=NAME then runs (default: "
        "none)",
        metavar="NAME",
    )
    quiet: bool = option(False, "no line per trial")

    def __post_init__(self) -> None:
        from myoexo.runtime.fits import fit_path

        check_fields(self)
        if self.write is not None:
            try:
                fit_path(self.write)
            except ValueError:
                raise FieldError(
                    type(self).__name__, "write", self.write, "must be a word (letters, digits, _)"
                ) from None


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin tune-pid``: the options of :class:`ZieglerNicholsSettings`
    and :class:`TuningOutput`."""
    add_options(parser, ZieglerNicholsSettings)
    add_options(parser, TuningOutput)


def run(args: argparse.Namespace) -> int:
    """``myoexo twin tune-pid``: print Ku, Tu, the table's gains and the paper's."""
    import sys

    settings = from_options(ZieglerNicholsSettings, args)
    output = from_options(TuningOutput, args)
    try:
        result = tune(settings, log=None if output.quiet else print)
    except (ValueError, RuntimeError) as exc:
        print(f"myoexo twin tune-pid: error: {exc}", file=sys.stderr)
        return 2
    print(format_result(result))
    if output.out is not None:
        output.out.parent.mkdir(parents=True, exist_ok=True)
        output.out.write_text(json.dumps(result.to_dict(), indent=2))
        print(f"written: {output.out}")
    if output.write is not None:
        from myoexo.control.tuned import write_tuned_pid

        try:
            path = write_tuned_pid(
                output.write, result.to_dict(), _provenance(settings, output.write)
            )
        except ValueError as exc:
            print(f"myoexo twin tune-pid: error: {exc}", file=sys.stderr)
            return 2
        print(f"written: {path}")
    return 0


def _provenance(settings: ZieglerNicholsSettings, name: str) -> dict[str, Any]:
    """What a ``--write NAME`` file records of how it was made (:func:`myoexo.runtime.fits
    .provenance`): the command (the options that differ from their defaults, ``--out`` and
    ``--quiet`` left out), the subject, the twin version, the package versions and the date."""
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import provenance

    parts = ["myoexo", "twin", "tune-pid", *option_words(settings), "--write", name]
    subject = (
        f"the nominal (Table I) subject of level {settings.level}"
        if settings.nominal_subject
        else f"an individual subject of level {settings.level}, seed {settings.seed}"
    )
    return provenance(shlex.join(parts), TWIN_VERSION, subject=subject)
