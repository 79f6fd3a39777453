"""Per-episode metrics of the evaluation protocol, with standard definitions.

The protocol and the paper's metric definitions are in docs/reference.md section 5.

The knee extension is read as a step response of the knee angle ``y(t)`` from ``y0`` (about
90 deg) towards the target (7 deg). Step-response quantities follow the definitions of
MATLAB's ``stepinfo`` and python-control's ``step_info`` (Astrom & Murray, *Feedback
Systems*, 2nd ed., 2021, sec. 5.3), applied to a step that starts at ``y0`` rather than at 0:

* **final value** ``yf``: mean of ``y`` over the last ``final_window_s`` of the episode
  (python-control takes the last sample; a short mean is robust to a jittery learned policy
  and equal to it for a settled response).
* **settling time**: time after which ``|y - yf| <= threshold * |yf - y0|`` holds until the
  end (threshold 2 %: the paper's "2 % band of the final value", the band being a fraction
  of the step, as in ``stepinfo``). The time of the first sample of that final stretch;
  NaN if the last sample is outside the band.
* **rise time**: from 10 % to 90 % of the step ``yf - y0`` (first crossings).
* **overshoot** (%): ``100 * max(0, max((y - yf) * sign(yf - y0))) / |yf - y0|``, the peak
  excursion beyond the final value relative to the step.

Task quantities:

* **final error** (deg): ``knee - target`` averaged over the final window (positive: the
  knee stayed flexed short of the target; the paper's 6.3 and 9.3 deg of the PID).
* **target overshoot** (deg): how far the knee went past the target,
  ``max(0, max(target - knee))``; the paper's "overshoot" of the PID at levels 0 and 1.
* **final swing** (deg): ``max(knee) - min(knee)`` over the last ``swing_window_s`` (1 s) of
  the episode: 0 for a knee at rest, the peak-to-peak amplitude of a limit cycle that the
  final error, a mean over 0.1 s, reads at one phase of the cycle.

Torque and command quantities (interaction torque: the env's ``interaction_torque_nm``, the
paper's "sum of the torques applied at the knee: exo + spastic reflexes"):

* **RMS of the interaction torque up to the settling time** (Nm): ``sqrt(mean(tau^2))`` over
  the samples with ``t <= settling time`` (the whole episode if it did not settle).
* **peak interaction torque** (Nm): ``max |tau|`` over the episode.
* **peak misalignment** (deg): ``max |knee - exo hinge|`` over the episode, how far the
  straps let the exo sit from the knee (NaN without the ``exo_angle_deg`` signal).
* **control effort**: RMS of the normalized command ``u``.
* **smoothness**: the total variation of the command ``sum |u[k+1] - u[k]|`` and the
  spectral smoothness ``Sm = 2 / (n fs) sum_i M_i f_i`` of Mysore et al., "Regularizing
  Action Policies for Smooth Control with Reinforcement Learning", ICRA 2021 (``M_i``
  amplitude of the frequency ``f_i`` of the command's spectrum, ``n`` number of frequency
  bins, ``fs`` sampling rate; 0 for a constant command, larger = more high-frequency
  content).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import asdict, dataclass

import numpy as np

#: Default settling band: 2 % of the step (the paper's).
SETTLING_THRESHOLD = 0.02
#: Default window over which the final value is averaged (s).
FINAL_WINDOW_S = 0.1
#: Default window of the final swing (s): several periods of a limit cycle at the hold.
FINAL_SWING_WINDOW_S = 1.0
#: Default rise-time limits (fractions of the step).
RISE_TIME_LIMITS = (0.1, 0.9)


def _as_1d(name: str, x: np.ndarray) -> np.ndarray:
    a = np.asarray(x, dtype=np.float64).reshape(-1)
    if a.size == 0:
        raise ValueError(f"{name} is empty")
    return a


def end_window(t_s: np.ndarray, window_s: float) -> np.ndarray:
    """The samples of an episode's last ``window_s``: the mask ``t >= t_end - window_s``, the
    sample exactly ``window_s`` before the end included (at least the last sample)."""
    t = _as_1d("t_s", t_s)
    if window_s < 0:
        raise ValueError(f"window_s = {window_s} must be >= 0")
    return t >= t[-1] - window_s - 1e-12


def final_value(t_s: np.ndarray, y: np.ndarray, window_s: float = FINAL_WINDOW_S) -> float:
    """Mean of ``y`` over the episode's last ``window_s`` (:func:`end_window`)."""
    return float(np.mean(_as_1d("y", y)[end_window(t_s, window_s)]))


def settling_time(
    t_s: np.ndarray,
    y: np.ndarray,
    threshold: float = SETTLING_THRESHOLD,
    y_final: float | None = None,
    y_initial: float | None = None,
) -> float:
    """Time (s) from which ``|y - y_final| <= threshold * |y_final - y_initial|`` until the end.

    Args:
        t_s: Sample times (s), increasing.
        y: Response samples.
        threshold: Band half-width as a fraction of the step (0.02 = 2 %).
        y_final: Final value (default: the last sample).
        y_initial: Initial value (default: the first sample).

    Returns:
        The time of the first sample of the final in-band stretch (``t_s[0]`` if always in
        band), NaN if the last sample is out of band.
    """
    t, y = _as_1d("t_s", t_s), _as_1d("y", y)
    if t.shape != y.shape:
        raise ValueError(f"t_s and y differ in length: {t.size} != {y.size}")
    if not 0.0 < threshold < 1.0:
        raise ValueError(f"threshold = {threshold} must be in (0, 1)")
    yf = y[-1] if y_final is None else float(y_final)
    y0 = y[0] if y_initial is None else float(y_initial)
    band = threshold * abs(yf - y0)
    outside = np.flatnonzero(~(np.abs(y - yf) <= band))  # NaN counts as outside
    if outside.size == 0:
        return float(t[0])
    last = outside[-1]
    return float(t[last + 1]) if last + 1 < t.size else math.nan


def rise_time(
    t_s: np.ndarray,
    y: np.ndarray,
    limits: tuple[float, float] = RISE_TIME_LIMITS,
    y_final: float | None = None,
    y_initial: float | None = None,
) -> float:
    """Time (s) between the first crossings of ``limits[0]`` and ``limits[1]`` of the step
    ``y_final - y_initial``; NaN if the upper limit is never reached."""
    t, y = _as_1d("t_s", t_s), _as_1d("y", y)
    lo, hi = limits
    if not 0.0 <= lo < hi <= 1.0:
        raise ValueError(f"limits = {limits} must satisfy 0 <= low < high <= 1")
    yf = y[-1] if y_final is None else float(y_final)
    y0 = y[0] if y_initial is None else float(y_initial)
    step = yf - y0
    if step == 0.0:
        return math.nan
    progress = (y - y0) / step
    i_lo = np.flatnonzero(progress >= lo)
    i_hi = np.flatnonzero(progress >= hi)
    if i_lo.size == 0 or i_hi.size == 0:
        return math.nan
    return float(t[i_hi[0]] - t[i_lo[0]])


def overshoot_pct(y: np.ndarray, y_final: float | None = None, y_initial: float | None = None):
    """Percent overshoot: peak excursion beyond the final value, in % of the step."""
    y = _as_1d("y", y)
    yf = y[-1] if y_final is None else float(y_final)
    y0 = y[0] if y_initial is None else float(y_initial)
    step = yf - y0
    if step == 0.0:
        return math.nan
    excursion = np.nanmax((y - yf) * np.sign(step))
    return float(100.0 * max(0.0, excursion) / abs(step))


def rms(x: np.ndarray) -> float:
    """Root mean square ``sqrt(mean(x^2))``."""
    x = _as_1d("x", x)
    return float(np.sqrt(np.mean(x * x)))


def total_variation(u: np.ndarray) -> float:
    """Total variation ``sum |u[k+1] - u[k]|`` of a sampled signal."""
    u = _as_1d("u", u)
    return float(np.abs(np.diff(u)).sum())


def spectral_smoothness(u: np.ndarray, sample_rate_hz: float) -> float:
    """Mysore et al. (ICRA 2021) smoothness ``Sm = 2 / (n fs) sum_i M_i f_i`` (lower = smoother).

    ``M_i = |FFT(u)_i| / N`` is the amplitude of the frequency ``f_i`` of the one-sided
    spectrum (``n`` bins) of the ``N`` samples; a sinusoid of amplitude ``A`` at ``f0`` (on a
    bin) gives ``2 A f0 / (n fs)``, a constant gives 0.
    """
    u = _as_1d("u", u)
    if not sample_rate_hz > 0:
        raise ValueError(f"sample_rate_hz = {sample_rate_hz} must be > 0")
    amplitude = np.abs(np.fft.rfft(u)) / u.size
    amplitude[1:] *= 2.0  # one-sided: fold the negative frequencies
    if u.size % 2 == 0:
        amplitude[-1] /= 2.0  # the Nyquist bin has no mirror
    freqs = np.fft.rfftfreq(u.size, d=1.0 / sample_rate_hz)
    return float(2.0 / (freqs.size * sample_rate_hz) * np.sum(amplitude * freqs))


@dataclass(frozen=True)
class EpisodeMetrics:
    """Metrics of one episode (definitions in the module docstring; NaN where undefined)."""

    final_error_deg: float
    abs_final_error_deg: float
    final_swing_deg: float
    target_overshoot_deg: float
    overshoot_pct: float
    rise_time_s: float
    settling_time_s: float
    rms_interaction_torque_nm: float
    peak_interaction_torque_nm: float
    peak_exo_torque_nm: float
    peak_misalignment_deg: float
    command_rms: float
    command_total_variation: float
    command_smoothness: float

    def as_dict(self) -> dict[str, float]:
        """Field name -> value."""
        return asdict(self)


#: Per-step signals :func:`episode_metrics` needs (keys of the env's ``info``).
REQUIRED_SIGNALS: tuple[str, ...] = (
    "time_s",
    "knee_angle_deg",
    "target_angle_deg",
    "command",
    "exo_torque_nm",
    "interaction_torque_nm",
)


def episode_metrics(
    signals: Mapping[str, np.ndarray],
    threshold: float = SETTLING_THRESHOLD,
    final_window_s: float = FINAL_WINDOW_S,
    swing_window_s: float = FINAL_SWING_WINDOW_S,
) -> EpisodeMetrics:
    """All metrics of one episode from its per-step signals.

    Args:
        signals: Arrays over the episode's samples (reset included) for every key of
            :data:`REQUIRED_SIGNALS`, in the env's units (s, deg, Nm, normalized command);
            ``exo_angle_deg`` too for the peak misalignment.
        threshold: Settling band (fraction of the step).
        final_window_s: Window of the final value (s).
        swing_window_s: Window of the final swing (s).
    """
    missing = [k for k in REQUIRED_SIGNALS if k not in signals]
    if missing:
        raise ValueError(f"episode_metrics: missing signals {missing}")
    t = _as_1d("time_s", signals["time_s"])
    knee = _as_1d("knee_angle_deg", signals["knee_angle_deg"])
    target = _as_1d("target_angle_deg", signals["target_angle_deg"])
    u = _as_1d("command", signals["command"])
    tau = _as_1d("interaction_torque_nm", signals["interaction_torque_nm"])
    exo = _as_1d("exo_torque_nm", signals["exo_torque_nm"])
    exo_angle = signals.get("exo_angle_deg")
    misalignment = (
        float(np.nanmax(np.abs(knee - _as_1d("exo_angle_deg", exo_angle))))
        if exo_angle is not None
        else math.nan
    )

    y0 = float(knee[0])
    yf = final_value(t, knee, final_window_s)
    final_err = final_value(t, knee - target, final_window_s)
    ts = settling_time(t, knee, threshold, y_final=yf, y_initial=y0)
    upto = t <= ts + 1e-9 if math.isfinite(ts) else np.ones_like(t, dtype=bool)
    dt = float(np.median(np.diff(t))) if t.size > 1 else math.nan
    return EpisodeMetrics(
        final_error_deg=final_err,
        abs_final_error_deg=abs(final_err),
        final_swing_deg=float(np.ptp(knee[end_window(t, swing_window_s)])),
        target_overshoot_deg=float(max(0.0, np.max(target - knee))),
        overshoot_pct=overshoot_pct(knee, y_final=yf, y_initial=y0),
        rise_time_s=rise_time(t, knee, y_final=yf, y_initial=y0),
        settling_time_s=ts,
        rms_interaction_torque_nm=rms(tau[upto]),
        peak_interaction_torque_nm=float(np.max(np.abs(tau))),
        peak_exo_torque_nm=float(np.max(np.abs(exo))),
        peak_misalignment_deg=misalignment,
        command_rms=rms(u),
        command_total_variation=total_variation(u),
        command_smoothness=spectral_smoothness(u, 1.0 / dt) if math.isfinite(dt) else math.nan,
    )
