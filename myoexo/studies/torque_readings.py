"""``myoexo twin torque-readings``: which reading of "the interaction torque at the knee" is the
study's?

The study measures "interaction torques, expressed as the sum of the total torque applied at
the knee joint, including the Exo actuation and the spastic reflexes", and reports them as
peak and RMS reductions of its SAC against its PID. It does not say how the sum is taken.
This study runs the paper's PID and a policy (default: the shipped ``sac``) on the same
subjects of the calibration root and reads four candidates from each step's ``info``:

``cuff``
    ``interaction_torque_nm``: the magnitude of the torque the shank strap transmits to the
    human knee (the envs' reading, :func:`myoexo.model.strap_knee_torque`);
``abs_sum``
    ``torque_abs_sum_nm``: ``|exo torque| + |muscle torque along the knee|``;
``signed_sum``
    ``torque_signed_sum_nm``: ``exo torque + muscle torque`` (its magnitude);
``exo``
    ``exo_torque_nm``: the motor torque alone (its magnitude).

and holds each against the study: its per-level peak reductions (23.6 / 12.5 / 8.8 / 11.3 %),
its mean peak reduction (10.8 +- 3.4 Nm), its levels 1-2 mean (10.6 %), the scale of its
PID's peaks (a 100 Nm motor: about 80-120 Nm) and its torque rising with the level over
levels 0-2. The docs' comparison table (``docs/studies/torque_readings``) is its output::

    myoexo twin torque-readings --subjects 12 --out docs/studies/torque_readings
"""

from __future__ import annotations

import argparse
import time
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.evaluation.config import CALIBRATION_ROOT_SEED, check_fit_root, subject_seed
from myoexo.runtime.fields import add_options, check_fields, from_options, option
from myoexo.spasticity.levels import VALID_LEVELS

if TYPE_CHECKING:
    import pandas as pd

__all__ = [
    "READINGS",
    "STUDY",
    "TorqueReadingsConfig",
    "add_arguments",
    "compare",
    "measure",
    "run",
]

#: The candidate readings: name -> the ``info`` key read (its magnitude is taken).
READINGS: Mapping[str, str] = {
    "cuff": "interaction_torque_nm",
    "abs_sum": "torque_abs_sum_nm",
    "signed_sum": "torque_signed_sum_nm",
    "exo": "exo_torque_nm",
}

#: What the study reports of its interaction torque (its SAC against its PID).
STUDY: Mapping[str, Any] = {
    "peak_reduction_pct": {0: 23.6, 1: 12.5, 2: 8.8, 3: 11.3},
    "mean_reduction_nm": (10.8, 3.4),
    "levels_12_reduction_pct": 10.6,
    "pid_peak_nm": (80.0, 120.0),
}

_CHANNELS = (
    "time_s",
    "knee_angle_deg",
    "target_angle_deg",
    "command",
    "exo_torque_nm",
    "interaction_torque_nm",
    *(key for key in READINGS.values() if key not in ("interaction_torque_nm", "exo_torque_nm")),
)


def measure(
    policy: str = "sac", subjects: int = 12, root_seed: int = CALIBRATION_ROOT_SEED
) -> pd.DataFrame:
    """Peak and RMS-to-settling of every reading, per controller, level and subject.

    Returns:
        One row per (controller, level, subject): ``final_error_deg`` and, per reading,
        ``<reading>_peak_nm`` and ``<reading>_rms_nm``.
    """
    import gymnasium as gym
    import pandas as pd

    import myoexo  # noqa: F401  (registers the ids)
    from myoexo.control import PID
    from myoexo.control.rollout import rollout
    from myoexo.control.specs import build_controller, parse_controller_spec, spec_env_kwargs
    from myoexo.evaluation.metrics import episode_metrics

    root_seed = check_fit_root(root_seed, "the torque-readings study")
    spec = parse_controller_spec(policy)
    rows = []
    for level in VALID_LEVELS:
        envs = {"pid": gym.make(f"MyoExoKnee-v{level}")}
        envs[policy] = gym.make(f"MyoExoKnee-v{level}", **spec_env_kwargs(spec))
        controllers = {
            "pid": PID.from_env(envs["pid"]),
            policy: build_controller(spec, envs[policy]),
        }
        for name, env in envs.items():
            for i in range(subjects):
                ep = rollout(env, controllers[name], subject_seed(level, i, root_seed), _CHANNELS)
                s = ep.signals
                row: dict[str, Any] = {"controller": name, "level": level, "subject": i}
                row["final_error_deg"] = episode_metrics(s).final_error_deg
                for reading, key in READINGS.items():
                    m = episode_metrics({**s, "interaction_torque_nm": np.abs(s[key])})
                    row[f"{reading}_peak_nm"] = m.peak_interaction_torque_nm
                    row[f"{reading}_rms_nm"] = m.rms_interaction_torque_nm
                rows.append(row)
            env.close()
    return pd.DataFrame(rows)


def compare(episodes: pd.DataFrame, policy: str = "sac") -> pd.DataFrame:
    """Per reading: the PID's and the policy's mean peaks per level, the reductions, and the
    study's criteria, each ``True`` where the reading meets it (see the module docstring)."""
    import pandas as pd

    means = episodes.groupby(["controller", "level"]).mean(numeric_only=True)
    records = []
    lo, hi = STUDY["pid_peak_nm"]
    study_nm, study_sd = STUDY["mean_reduction_nm"]
    for reading in READINGS:
        col = f"{reading}_peak_nm"
        pid = np.array([means.loc[("pid", lv), col] for lv in VALID_LEVELS])
        ours = np.array([means.loc[(policy, lv), col] for lv in VALID_LEVELS])
        red_nm = pid - ours
        red_pct = 100.0 * red_nm / np.maximum(pid, 1e-9)
        study_pct = np.array([STUDY["peak_reduction_pct"][lv] for lv in VALID_LEVELS])
        l12 = float(red_pct[1:3].mean())
        records.append(
            {
                "reading": reading,
                "PID peak L0-3 (Nm)": " / ".join(f"{v:.0f}" for v in pid),
                f"{policy} peak L0-3 (Nm)": " / ".join(f"{v:.0f}" for v in ours),
                "peak reduction L0-3 (%)": " / ".join(f"{v:.1f}" for v in red_pct),
                "mean gap to the study's reductions (points)": float(
                    np.abs(red_pct - study_pct).mean()
                ),
                "levels 1-2 reduction (%)": l12,
                "reduction (Nm), mean ± SD over levels": f"{red_nm.mean():.1f} ± "
                f"{red_nm.std(ddof=1):.1f}",
                "PID peak on the study's scale": bool(np.all((pid >= lo) & (pid <= hi))),
                "reduction in Nm within the study's ± SD": bool(
                    abs(red_nm.mean() - study_nm) <= study_sd
                ),
                "levels 1-2 within 3 points of 10.6 %": bool(
                    abs(l12 - STUDY["levels_12_reduction_pct"]) <= 3.0
                ),
                "PID peak rises over levels 0-2": bool(pid[0] < pid[1] < pid[2]),
            }
        )
    return pd.DataFrame(records)


def markdown(table: pd.DataFrame, episodes: pd.DataFrame, policy: str, wall_s: float) -> str:
    """The docs' comparison table with its provenance."""
    subjects = int(episodes["subject"].nunique())
    lines = [
        "<!-- generated by myoexo twin torque-readings: do not edit -->",
        f"The paper's PID and `{policy}` on the same {subjects} subjects per level of the "
        f"calibration root (root seed {CALIBRATION_ROOT_SEED}); peaks are means over the "
        f"subjects of each episode's largest |reading|; {wall_s:.0f} s. The study: peak "
        "reductions 23.6 / 12.5 / 8.8 / 11.3 %, 10.8 ± 3.4 Nm, 10.6 % over levels 1-2, a "
        "100 Nm motor, its torque rising with the level over levels 0-2.",
        "",
    ]
    shown = table.copy()
    for col in shown.columns:
        if shown[col].dtype == bool:
            shown[col] = shown[col].map({True: "yes", False: "no"})
    shown["mean gap to the study's reductions (points)"] = shown[
        "mean gap to the study's reductions (points)"
    ].map(lambda v: f"{v:.1f}")
    shown["levels 1-2 reduction (%)"] = shown["levels 1-2 reduction (%)"].map(lambda v: f"{v:.1f}")
    lines.append("| " + " | ".join(shown.columns) + " |")
    lines.append("|" + "---|" * len(shown.columns))
    for _, rec in shown.iterrows():
        lines.append("| " + " | ".join(str(v) for v in rec) + " |")
    return "\n".join(lines) + "\n"


# ----------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class TorqueReadingsConfig:
    """What ``myoexo twin torque-readings`` runs (each field is an option of the command)."""

    policy: str = option(
        "sac", "the controller compared with the paper's PID (a controller spec)", metavar="SPEC"
    )
    subjects: int = option(12, "subjects per level", low=2, high=10_000)
    root_seed: int = option(
        CALIBRATION_ROOT_SEED,
        "root seed of the subjects (the calibration root; the evaluation root 0 is refused)",
        low=0,
        flag="seed",
    )
    out: Path | None = option(
        None,
        "folder for torque_readings.md and episodes.csv (default: none, print only)",
        folder=True,
        metavar="DIR",
    )

    def __post_init__(self) -> None:
        check_fields(self)
        check_fit_root(self.root_seed, "the torque-readings study")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin torque-readings``: :class:`TorqueReadingsConfig`'s fields."""
    add_options(parser, TorqueReadingsConfig)


def run(args: argparse.Namespace) -> int:
    """Measure, compare, print, optionally write."""
    config = from_options(TorqueReadingsConfig, args)
    t0 = time.perf_counter()
    episodes = measure(config.policy, config.subjects, config.root_seed)
    table = compare(episodes, config.policy)
    text = markdown(table, episodes, config.policy, time.perf_counter() - t0)
    print(text)
    if config.out is not None:
        from myoexo.runtime.files import write_study_files

        files = {"torque_readings.md": text, "episodes.csv": episodes}
        print("wrote " + ", ".join(str(p) for p in write_study_files(config.out, files)))
    return 0
