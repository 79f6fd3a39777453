"""The reference study's reported results (docs/reference.md section 5), as data.

Values are transcribed from the paper's Results section; ``None`` where the paper gives no
number. ``"overshoot"`` / ``"< 1"`` entries are kept as the paper words them
(:attr:`PaperLevelResults.sac_final_error_text`, :attr:`PaperLevelResults.pid_final_error_text`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from myoexo.control.pid import PIDGains

#: Trials per level in the paper.
PAPER_TRIALS_PER_LEVEL = 1000


@dataclass(frozen=True)
class PaperLevelResults:
    """The paper's numbers for one spasticity level.

    Attributes:
        level: Spasticity level.
        sac_settling_time_s: SAC settling time (2 % band), s.
        sac_final_error_deg: SAC final error, deg, or ``None`` if only bounded.
        sac_final_error_text: As worded in the paper.
        sac_final_error_bound_deg: The bound the paper's SAC final error meets: 1 deg where
            it reports "< 1", its own value where it reports one (level 3: 11.45 deg).
        pid_final_error_deg: PID final error, deg (``None`` where the paper reports an
            overshoot instead).
        pid_final_error_text: As worded in the paper.
        rms_reduction_pct: RMS-to-settling reduction of SAC vs PID, %.
        peak_reduction_pct: Peak interaction torque reduction of SAC vs PID, %.
        peak_iqr_nm: Interquartile range of the peak torque quoted in the text, Nm.
    """

    level: int
    sac_settling_time_s: float
    sac_final_error_deg: float | None
    sac_final_error_text: str
    sac_final_error_bound_deg: float
    pid_final_error_deg: float | None
    pid_final_error_text: str
    rms_reduction_pct: float | None
    peak_reduction_pct: float
    peak_iqr_nm: float | None


PAPER_RESULTS: dict[int, PaperLevelResults] = {
    0: PaperLevelResults(0, 0.26, None, "< 1", 1.0, None, "overshoot", 35.3, 23.6, None),
    1: PaperLevelResults(1, 0.78, None, "< 1", 1.0, None, "overshoot", 9.7, 12.5, 48.0),
    2: PaperLevelResults(2, 3.77, None, "< 1", 1.0, 6.3, "6.3", 8.1, 8.8, 27.5),
    3: PaperLevelResults(3, 7.94, 11.45, "11.45", 11.45, 9.3, "9.3", None, 11.3, 13.0),
}


@dataclass(frozen=True)
class PaperHeadlines:
    """The paper's summary numbers (abstract and conclusion).

    Attributes:
        peak_reduction_pct: Mean peak-torque reduction of SAC vs PID over levels 1-2 (the
            spastic levels where the study's SAC reaches the target: (12.5 + 8.8) / 2), %.
        peak_reduction_nm: Mean peak-torque reduction, Nm.
        peak_reduction_std_nm: Its standard deviation, Nm.
        rms_reduction_pct: Mean RMS-to-settling reduction over levels 1-2 ((9.7 + 8.1) / 2),
            %.
        pid_gains: The PID gains (Ziegler-Nichols tuned at level 1).
        pid_tuning_level: Level the PID was tuned at.
    """

    peak_reduction_pct: float = 10.6
    peak_reduction_nm: float = 10.8
    peak_reduction_std_nm: float = 3.4
    rms_reduction_pct: float = 8.9
    pid_gains: PIDGains = field(default_factory=PIDGains)
    pid_tuning_level: int = 1


PAPER_HEADLINES = PaperHeadlines()
