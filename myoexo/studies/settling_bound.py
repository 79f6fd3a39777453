"""``myoexo twin settling-bound``: can any command settle the knee sooner than the paper's PID
where the muscles hold it short of the target, and at what interaction torque?

At levels 2-3 the paper's PID drives the motor to its limit from the start and the reflex
holds the knee several degrees short of the target: the PID's final error is the hold, and
its settling time is how soon the knee comes to rest there. Whether a controller can settle
sooner than the PID *and* be gentler (the study's claim) is a property of the twin, which this
command measures with an oracle that knows the subject: for every subject it searches a
family of open-loop commands and keeps the one that settles soonest at the PID's final error.

The family is the PID's own saturated push, its onset softened, with one **brake pulse**:
the motor's full extension command (-1), reached linearly over ``rise_s`` from 0 (0: at
once), except ``brake_command`` over ``[brake_start_s, brake_start_s + brake_duration_s)``.
A pulse timed before the reflex's catch slows the shank so that it meets the hold without
the bounce that keeps the PID out of the settling band; a softer onset lowers the strap's
first torque peak. The pushes without a pulse are in the family too. Every candidate is an
episode of the twin on that subject (the evaluation's metrics: settling in the 2 % band of
the step, RMS interaction torque up to settling, peak interaction torque, final error over
the last window).

Per subject it keeps:

* **fastest**: the soonest settling at a final error within ``error_tolerance_deg`` of the
  PID's, whatever the torque;
* **gentler**: the same, among the candidates whose peak and RMS interaction torques are both
  at most the PID's.

A subject where *gentler* settles sooner than the PID shows the claim within the motor's
reach on this twin (an open-loop command that knows the subject: a bound, not a controller a
device could run); one where no candidate does shows it out of reach of this family only.
Subjects come from the selection root (1) by default; the evaluation root 0 is refused.
"""

from __future__ import annotations

import argparse
import itertools
import math
import shlex
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.policy import ACTION_HIGH, ACTION_LOW
from myoexo.envs.sensors import Measurements
from myoexo.evaluation.config import SELECTION_ROOT_SEED, check_fit_root
from myoexo.runtime.fields import add_options, check_fields, from_options, option, option_words
from myoexo.spasticity.levels import VALID_LEVELS

#: The motor's full command towards the target (extension).
PUSH_COMMAND = -1.0

#: Columns of an episode's outcome, in the evaluation's names.
OUTCOME = (
    "abs_final_error_deg",
    "settling_time_s",
    "peak_interaction_torque_nm",
    "rms_interaction_torque_nm",
)


@dataclass(frozen=True)
class SettlingBoundSettings:
    """The subjects and the brake-pulse family searched (options of ``myoexo twin
    settling-bound``)."""

    root_seed: int = option(
        SELECTION_ROOT_SEED,
        "root seed of the subjects (the evaluation root 0 is refused)",
        low=0,
        flag="seed",
    )
    subjects: int = option(10, "subjects per level", low=1, high=1000)
    levels: tuple[int, ...] = option((2, 3), "levels searched", choices=VALID_LEVELS)
    rise_s: tuple[float, ...] = option(
        (0.0, 0.05, 0.1, 0.2),
        "times the push takes to rise from 0 to the full command",
        low=0.0,
        unit="s",
        flag="",
    )
    brake_start_s: tuple[float, ...] = option(
        tuple(round(0.05 * k, 2) for k in range(1, 17)),
        "times the brake pulse starts at",
        low=0.0,
        unit="s",
        flag="",
    )
    brake_duration_s: tuple[float, ...] = option(
        (0.02, 0.05, 0.1), "durations of the pulse", low=0.0, above=True, unit="s", flag=""
    )
    brake_command: tuple[float, ...] = option(
        (0.0, 1.0), "commands during the pulse", low=ACTION_LOW, high=ACTION_HIGH, flag=""
    )
    error_tolerance_deg: float = option(
        0.05,
        "a candidate counts if its final error is within this of the PID's",
        low=0.0,
        unit="deg",
        flag="",
    )
    workers: int = option(2, "processes (one subject at a time each)", low=1, high=256)

    def __post_init__(self) -> None:
        check_fields(self)
        check_fit_root(self.root_seed, "the settling bound")
        for name in ("rise_s", "brake_start_s", "brake_duration_s", "brake_command"):
            if not getattr(self, name):
                raise ValueError(f"{name} is empty: name at least one value")

    def candidates(self) -> list[tuple[float, float, float, float]]:
        """``(rise_s, brake_start_s, brake_duration_s, brake_command)`` of every candidate;
        the constant push (``(0, 0, 0, -1)``: no rise, no pulse) first."""
        pulses = itertools.product(self.brake_start_s, self.brake_duration_s, self.brake_command)
        no_pulse = (0.0, 0.0, PUSH_COMMAND)
        rises = dict.fromkeys((0.0, *self.rise_s))
        shapes = [no_pulse, *pulses]
        return [(rise, *shape) for rise in rises for shape in shapes]


class BrakePulse:
    """The open-loop command of the search: :data:`PUSH_COMMAND`, reached linearly over
    *rise_s*, at every control step except *command* over ``[start_s, start_s +
    duration_s)`` (module docstring).

    Args:
        rise_s: Time the push takes to reach the full command from 0, s (0: at once).
        start_s: When the pulse starts, s from the episode's start.
        duration_s: How long it lasts, s (0: the constant push).
        command: The command during the pulse, in [-1, 1].
        dt: The env's control period, s.
    """

    sensors: frozenset[str] = frozenset()

    def __init__(
        self, rise_s: float, start_s: float, duration_s: float, command: float, dt: float
    ) -> None:
        if not (ACTION_LOW <= command <= ACTION_HIGH):
            raise ValueError(
                f"BrakePulse command = {command!r} is outside [{ACTION_LOW:g}, {ACTION_HIGH:g}]"
            )
        self._first = round(start_s / dt)
        self._stop = self._first + round(duration_s / dt)
        self._rise_steps = max(1, round(rise_s / dt))
        self._push = np.array([PUSH_COMMAND], dtype=np.float32)
        self._brake = np.array([command], dtype=np.float32)
        self._step = 0

    def reset(self, seed: int | None = None) -> None:
        """Back to the episode's first step."""
        del seed
        self._step = 0

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """The command of this control step."""
        step = self._step
        self._step += 1
        if self._first <= step < self._stop:
            return self._brake
        if step + 1 < self._rise_steps:
            return np.array([PUSH_COMMAND * (step + 1) / self._rise_steps], dtype=np.float32)
        return self._push


def _outcome(env: Any, controller: Any, seed: int) -> dict[str, float]:
    from myoexo.evaluation.engine import run_episode

    metrics = run_episode(env, controller, seed).metrics.as_dict()
    return {k: float(metrics[k]) for k in OUTCOME}


def search_subject(settings: SettlingBoundSettings, level: int, index: int) -> dict[str, Any]:
    """The PID's outcome on one subject and the fastest and gentler candidates (module
    docstring); ``nan`` where no candidate qualifies."""
    from myoexo.control.specs import build_controller, parse_controller_spec
    from myoexo.envs import make_env
    from myoexo.evaluation.config import subject_seed

    env = make_env(level)
    try:
        seed = subject_seed(level, index, settings.root_seed)
        dt = float(env.unwrapped.dt)  # type: ignore[attr-defined]
        pid = _outcome(env, build_controller(parse_controller_spec("pid"), env), seed)
        tried = [
            (candidate, _outcome(env, BrakePulse(*candidate, dt=dt), seed))
            for candidate in settings.candidates()
        ]
    finally:
        env.close()
    row: dict[str, Any] = {"level": level, "subject": index}
    row.update({f"pid_{k}": v for k, v in pid.items()})
    row.update({f"push_{k}": v for k, v in tried[0][1].items()})
    accurate = [
        (c, o)
        for c, o in tried
        if o["abs_final_error_deg"] <= pid["abs_final_error_deg"] + settings.error_tolerance_deg
        and math.isfinite(o["settling_time_s"])
    ]
    gentler = [
        (c, o)
        for c, o in accurate
        if o["peak_interaction_torque_nm"] <= pid["peak_interaction_torque_nm"]
        and o["rms_interaction_torque_nm"] <= pid["rms_interaction_torque_nm"]
    ]
    for name, group in (("fastest", accurate), ("gentler", gentler)):
        best = min(group, key=lambda item: item[1]["settling_time_s"], default=None)
        rise, start, duration, command = best[0] if best else (math.nan,) * 4
        row.update({f"{name}_{k}": (best[1][k] if best else math.nan) for k in OUTCOME})
        row.update(
            {
                f"{name}_rise_s": rise,
                f"{name}_brake_start_s": start,
                f"{name}_brake_duration_s": duration,
                f"{name}_brake_command": command,
            }
        )
    row["candidates"] = len(tried)
    return row


def _search(job: tuple[SettlingBoundSettings, int, int]) -> dict[str, Any]:
    return search_subject(*job)


def settling_bound(settings: SettlingBoundSettings, log: Any = None) -> Any:
    """One row per subject (:func:`search_subject`), every level, on ``settings.workers``
    processes."""
    import pandas as pd

    from myoexo.runtime.lifecycle import process_map

    jobs = [(settings, lv, i) for lv in settings.levels for i in range(settings.subjects)]
    rows = []
    for row in process_map(_search, jobs, settings.workers):
        rows.append(row)
        if log is not None:
            log(_line(row))
    return pd.DataFrame(rows)


def _line(row: dict[str, Any]) -> str:
    return (
        f"level {row['level']} subject {row['subject']}: PID settles in "
        f"{row['pid_settling_time_s']:.2f} s, the constant push {row['push_settling_time_s']:.2f}"
        f" s, the fastest pulse {row['fastest_settling_time_s']:.2f} s, the fastest gentler "
        f"one {row['gentler_settling_time_s']:.2f} s"
    )


def summary(table: Any) -> Any:
    """Per level: the mean settling time, peak and RMS torque of the PID, the constant push,
    the fastest and the gentler candidates over the subjects where one was found, the PID's
    mean settling time over the same subjects, and how many subjects each settles sooner
    than the PID."""
    import pandas as pd

    rows = []
    for level, group in table.groupby("level"):
        for who in ("pid", "push", "fastest", "gentler"):
            settle = group[f"{who}_settling_time_s"]
            found = settle.notna()
            rows.append(
                {
                    "level": int(level),
                    "command": who,
                    "settling_time_s": float(settle.mean()),
                    "pid_settling_time_s": float(group.pid_settling_time_s[found].mean()),
                    "peak_interaction_torque_nm": float(
                        group[f"{who}_peak_interaction_torque_nm"].mean()
                    ),
                    "rms_interaction_torque_nm": float(
                        group[f"{who}_rms_interaction_torque_nm"].mean()
                    ),
                    "abs_final_error_deg": float(group[f"{who}_abs_final_error_deg"].mean()),
                    "found": int(found.sum()),
                    "sooner_than_pid": int((settle < group.pid_settling_time_s).sum()),
                    "subjects": len(group),
                }
            )
    return pd.DataFrame(rows)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo twin settling-bound``: :class:`SettlingBoundSettings`' fields and
    the output folder."""
    add_options(parser, SettlingBoundSettings)
    parser.add_argument(
        "--out", type=Path, default=None, help="write subjects.csv, summary.md and provenance.json"
    )


def run(args: argparse.Namespace) -> int:
    """``myoexo twin settling-bound``: search every subject, print the per-level summary."""
    import json
    import time

    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import provenance

    settings = from_options(SettlingBoundSettings, args)
    t0 = time.perf_counter()
    table = settling_bound(settings, log=print)
    wall_min = (time.perf_counter() - t0) / 60.0
    result = summary(table)
    text = (
        f"Settling bound on {settings.subjects} subjects per level of root {settings.root_seed} "
        f"(`myoexo twin settling-bound`; {len(settings.candidates())} open-loop commands per "
        f"subject; {wall_min:.1f} min on {settings.workers} processes). `pid`: the paper's PID; "
        "`push`: the motor's full extension command throughout; `fastest`: the brake pulse "
        "that settles soonest at the PID's final error; `gentler`: the same with peak and RMS "
        "interaction torque at most the PID's (per subject). Means over the subjects where "
        "one was found (`found`), the PID's settling time over the same subjects beside "
        "them.\n\n" + result.to_markdown(index=False, floatfmt=".3g") + "\n"
    )
    print(text)
    if args.out is not None:
        out = Path(args.out)
        out.mkdir(parents=True, exist_ok=True)
        table.to_csv(out / "subjects.csv", index=False)
        (out / "summary.md").write_text(text)
        options = option_words(settings, exclude=("workers",))
        record = provenance(
            shlex.join(["myoexo", "twin", "settling-bound", *options, "--out", str(out)]),
            TWIN_VERSION,
            root_seed=settings.root_seed,
            wall_min=round(wall_min, 2),
            settings=asdict(settings),
        )
        (out / "provenance.json").write_text(json.dumps(record, indent=2) + "\n")
        print(f"written: {out}")
    return 0
