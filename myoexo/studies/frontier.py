"""What the twin allows: the trade-off between interaction torque and settling, per level.

    myoexo frontier --out results/frontier --subjects 10
    myoexo frontier --out results/frontier --subjects 10 --controllers sac --seeds-dir runs/s5
    myoexo frontier --out results/frontier --subjects 10 --oracle   # + the torque-aware oracle

Every controller runs on the same subjects of the **selection root** (root seed 1, a
selection run: :attr:`~myoexo.evaluation.config.EvaluationConfig.selection`) through the
evaluation protocol (:func:`~myoexo.evaluation.runner.evaluate`, resumable, in
``OUT/selection``): the
paper's PID, the device PID on the exo encoder (``pid:feedback=exo``; tuned on the encoder,
``pid:tuned=exo``), the *shaped* PIDs a
reviewer asks for first (a setpoint ramped over ``ramp_s`` seconds, linearly over
:data:`RAMPS_S` or along a minimum-jerk move over :data:`MINJERK_RAMPS_S`, a command clipped at
``limit`` x 100 Nm: :class:`~myoexo.control.pid.PIDConfig`), the impedance controller (a
spring-damper on a minimum-jerk reference, :mod:`myoexo.control.impedance`) at the stiffnesses
of :data:`IMPEDANCE_STIFFNESSES` and the durations of :data:`IMPEDANCE_DURATIONS_S`
(:func:`classical_specs`: the classical families a learned controller must beat), and
whatever ``--controllers`` adds (the shipped policies, model files), and with ``--oracle``
the torque-aware oracle (:mod:`myoexo.control.oracle`: predictive sampling on a copy of the
true twin) at the settings of :data:`ORACLE_SWEEP`, in its cheap configuration
(:data:`CHEAP_ORACLE`). Per level and controller: the mean settling time, peak interaction
torque, RMS interaction torque up to settling and absolute final error. A level's
**accuracy** is the acceptance bound of the final error
(:class:`~myoexo.evaluation.criteria.Criteria`: 1 deg at levels 0-2, 11.45 deg at level 3)
where some controller meets it on these subjects, else ``--accuracy-deg`` (1 deg) above the
best any of them reaches (the stall that the motor limit sets); a controller is
**accurate** when its mean absolute final error is strictly below it. The **frontier** of a
level is the set of accurate controllers that no other accurate one beats on both settling
time and peak torque, *picked* on the selection subjects.

The picked points are then **confirmed** on ``--confirm-subjects`` subjects of the
evaluation root (root seed 0, in ``OUT/evaluation``), which played no part in the picking:
a point is **reachable** only if it is accurate there too (strictly below the level's
accuracy). The table gives both sets of numbers; only the confirmed ones are results.

The study's SAC is placed at its reported reductions from *our* paper's-PID values (peak and
RMS reduced by the study's percentages, its settling times), so that it can be read against
the frontier on this twin. With ``--seeds-dir`` (one or more folders), each seed's selected
policy
(``aggregate.json`` of ``myoexo policy seeds aggregate``) is a point of its own (the spread over
seeds). Files: ``frontier.csv`` (every point on the selection subjects, with
``accurate`` and ``on_frontier``, and for the frontier's points their ``confirmed_*``
numbers and ``reachable``), ``frontier.md``, ``frontier_level<L>.png`` and ``frontier.png``
(all levels, the selection subjects).
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.envs.options import TwinOptions, add_twin_arguments, twin_from_args
from myoexo.evaluation.config import SELECTION_ROOT_SEED
from myoexo.evaluation.paper import PAPER_RESULTS
from myoexo.runtime.fields import Execution, add_options, check_fields, from_options, option
from myoexo.spasticity.levels import VALID_LEVELS

#: Ramp durations (s) of the ramped-setpoint PIDs (linear ramps).
RAMPS_S: tuple[float, ...] = (0.3, 0.6, 1.0, 1.5, 3.0)
#: Ramp durations (s) of the PIDs whose setpoint follows a minimum-jerk move (0.4 and 0.45 s:
#: the paces between 0.35 and 0.5 s on the level-0 frontier of 20 selection subjects).
MINJERK_RAMPS_S: tuple[float, ...] = (0.4, 0.45, 0.6, 1.0, 1.5, 2.0, 3.0)
#: Stiffnesses (Nm/rad) of the impedance controllers: the paper's Kp x 100 Nm and twice it;
#: each with the damping of the paper's ratio Kd / Kp (:data:`IMPEDANCE_DAMPING_PER_STIFFNESS`;
#: at 1400 Nm/rad the default 5 Nm s/rad leaves the knee cycling at level 1).
IMPEDANCE_STIFFNESSES: tuple[float, ...] = (700.0, 1400.0)
#: Damping per stiffness of the impedance controllers (s): the paper's Kd / Kp = 0.05 / 7.
IMPEDANCE_DAMPING_PER_STIFFNESS = 0.05 / 7.0
#: Reference durations (s) of the impedance controllers.
IMPEDANCE_DURATIONS_S: tuple[float, ...] = (0.6, 1.0, 1.5, 2.0)
#: Command limits (x 100 Nm) of the clipped PIDs.
LIMITS: tuple[float, ...] = (0.5, 0.6, 0.8)
#: The oracle's cheap configuration for the frontier: 8 rollouts per plan, a plan every 4th
#: control step, 2 rollouts per step against the 6 of
#: :class:`~myoexo.control.oracle.OracleConfig`'s default (12 every 2nd step), 3x fewer.
CHEAP_ORACLE = "samples=8,replan=4"
#: Torque-aware oracle settings of ``myoexo frontier --oracle``: none (the final-error bound),
#: a reference ramped over 0.6 s and 1.5 s, and a penalty on the rise of the peak.
ORACLE_SWEEP: tuple[str, ...] = ("", "ramp_s=0.6", "ramp_s=1.5", "peak_weight=3")
#: Accuracy band of the frontier (deg above the best mean |final error| of the level).
ACCURACY_DEG = 1.0
#: Columns of a frontier point (per level and controller, means over subjects).
POINT_METRICS: tuple[str, ...] = (
    "abs_final_error_deg",
    "settling_time_s",
    "peak_interaction_torque_nm",
    "rms_interaction_torque_nm",
)
#: Columns a frontier point gets from the evaluation subjects (as ``confirmed_<name>``).
CONFIRMED_METRICS: tuple[str, ...] = (*POINT_METRICS, "settled_share", "episodes")


def shaped_pid_specs(
    ramps_s: Sequence[float] = RAMPS_S,
    limits: Sequence[float] = LIMITS,
    minjerk_ramps_s: Sequence[float] = MINJERK_RAMPS_S,
) -> list[str]:
    """The baseline PID specs: the paper's PID, the device PID, ramped (linearly and along
    a minimum-jerk move) and clipped."""
    specs = ["pid", "pid:feedback=exo", "pid:tuned=exo"]
    specs += [f"pid:ramp_s={r:g}" for r in ramps_s]
    specs += [f"pid:reference=minjerk,ramp_s={r:g}" for r in minjerk_ramps_s]
    specs += [f"pid:limit={lim:g}" for lim in limits]
    return specs


def impedance_specs(
    stiffnesses: Sequence[float] = IMPEDANCE_STIFFNESSES,
    durations_s: Sequence[float] = IMPEDANCE_DURATIONS_S,
) -> list[str]:
    """The impedance controller's specs: each stiffness (with the paper's damping ratio,
    :data:`IMPEDANCE_DAMPING_PER_STIFFNESS`) at each reference duration."""
    return [
        f"impedance:k={k:g},d={k * IMPEDANCE_DAMPING_PER_STIFFNESS:.3g},duration_s={t:g}"
        for k in stiffnesses
        for t in durations_s
    ]


def classical_specs() -> list[str]:
    """Every classical controller of the frontier: :func:`shaped_pid_specs` and
    :func:`impedance_specs`."""
    return [*shaped_pid_specs(), *impedance_specs()]


def oracle_specs(sweep: Sequence[str] = ORACLE_SWEEP, base: str = CHEAP_ORACLE) -> list[str]:
    """Controller specs of the oracle at each setting of *sweep* on top of *base*."""
    return [f"oracle:{base}" + (f",{extra}" if extra else "") for extra in sweep]


def points(table: Any) -> Any:
    """Per (controller, level): the means of :data:`POINT_METRICS` (settling time over the
    settled episodes), the share of settled episodes, the episode count and the controller's
    seed group (``seed_group``, where the table has the column)."""
    from myoexo.evaluation.stats import SEED_GROUP

    grouped = table.groupby(["controller", "level"])
    out = grouped[list(POINT_METRICS)].mean()
    out["settled_share"] = grouped["settling_time_s"].apply(lambda s: float(s.notna().mean()))
    out["episodes"] = grouped.size()
    if SEED_GROUP in table:
        out[SEED_GROUP] = grouped[SEED_GROUP].first()
    return out.reset_index()


def level_accuracy(group: Any, accuracy_deg: float = ACCURACY_DEG) -> float:
    """A level's accuracy bound from its measured points (*group*: one level's rows): the
    criteria's final-error bound if some point meets it, else *accuracy_deg* above the best
    mean absolute final error (deg)."""
    from myoexo.evaluation.criteria import Criteria

    level = int(group.level.iloc[0])
    bound = float(Criteria().final_error_deg[level])
    best = float(group.abs_final_error_deg.min())
    return bound if best < bound else best + accuracy_deg


def mark_frontier(pts: Any, accuracy_deg: float = ACCURACY_DEG) -> Any:
    """Add ``accuracy_deg`` (the level's bound, :func:`level_accuracy`), ``accurate`` and
    ``on_frontier`` (see the module docstring) to *pts*."""
    pts = pts.copy()
    pts["accurate"] = False
    pts["on_frontier"] = False
    pts["accuracy_deg"] = math.nan
    for level, group in pts.groupby("level"):
        measured = group[~group.controller.str.startswith("paper")]
        limit = level_accuracy(measured, accuracy_deg)
        pts.loc[pts.level == level, "accuracy_deg"] = limit
        accurate = group.index[
            (group.abs_final_error_deg < limit)
            & group.settling_time_s.notna()
            & ~group.controller.str.startswith("paper")
        ]
        pts.loc[accurate, "accurate"] = True
        for i in accurate:
            ts, peak = pts.at[i, "settling_time_s"], pts.at[i, "peak_interaction_torque_nm"]
            dominated = any(
                pts.at[j, "settling_time_s"] <= ts
                and pts.at[j, "peak_interaction_torque_nm"] <= peak
                and (
                    pts.at[j, "settling_time_s"] < ts
                    or pts.at[j, "peak_interaction_torque_nm"] < peak
                )
                for j in accurate
                if j != i
            )
            pts.at[i, "on_frontier"] = not dominated
    return pts


def confirm(pts: Any, confirmed: Any) -> Any:
    """Add the evaluation root's numbers (*confirmed*: :func:`points` of the confirmation
    run) to the frontier's points of *pts* as ``confirmed_<metric>``, and ``reachable``: on
    the frontier and strictly below the level's accuracy there as well."""
    pts = pts.copy()
    conf = confirmed.set_index(["controller", "level"])
    pts["reachable"] = False
    for metric in CONFIRMED_METRICS:
        pts[f"confirmed_{metric}"] = math.nan
    for i, p in pts[pts.on_frontier].iterrows():
        key = (p.controller, p.level)
        if key not in conf.index:
            continue
        row = conf.loc[key]
        for metric in CONFIRMED_METRICS:
            pts.at[i, f"confirmed_{metric}"] = float(row[metric])
        pts.at[i, "reachable"] = bool(
            row.abs_final_error_deg < p.accuracy_deg and math.isfinite(row.settling_time_s)
        )
    return pts


def paper_points(pts: Any, pid_label: str = "pid") -> Any:
    """The study's SAC per level at its reported reductions from our PID's values."""
    import pandas as pd

    rows = []
    for level, res in PAPER_RESULTS.items():
        pid = pts[(pts.controller == pid_label) & (pts.level == level)]
        if pid.empty:
            continue
        p = pid.iloc[0]
        rms_red = res.rms_reduction_pct if res.rms_reduction_pct is not None else math.nan
        rows.append(
            {
                "controller": "paper SAC (at its reductions from our PID)",
                "level": level,
                "abs_final_error_deg": res.sac_final_error_bound_deg,
                "settling_time_s": res.sac_settling_time_s,
                "peak_interaction_torque_nm": p.peak_interaction_torque_nm
                * (1 - res.peak_reduction_pct / 100),
                "rms_interaction_torque_nm": p.rms_interaction_torque_nm * (1 - rms_red / 100),
                "settled_share": math.nan,
                "episodes": 0,
            }
        )
    return pd.DataFrame(rows)


#: Colours of the other controllers' groups (a policy, or one seeds folder's seeds), in order.
_GROUP_COLORS = ("tab:orange", "tab:brown", "tab:pink", "tab:olive", "gold", "tab:gray")


def point_group(label: str, seed_group: Any = None) -> str:
    """Legend entry of a point: the members of a seed group share their group's
    (``<group> (seeds)``); any other label is its own."""
    return f"{seed_group} (seeds)" if isinstance(seed_group, str) and seed_group else label


def plot_frontier(pts: Any, level: int | None = None) -> Any:
    """Peak interaction torque vs settling time, one panel per level (or one level), one
    legend beside the panels."""
    from matplotlib.figure import Figure

    levels = [level] if level is not None else sorted(pts.level.unique())
    fig = Figure(figsize=(3.6 * len(levels) + 3.0, 3.6), layout="constrained")
    axes = fig.subplots(1, len(levels), squeeze=False)[0]
    styles = {
        "pid": ("black", "^", "paper's PID"),
        "pid:feedback=exo": ("grey", "v", "device PID (exo encoder)"),
        "pid:tuned=exo": ("dimgrey", "<", "device PID, tuned on the encoder"),
    }
    groups = pts["seed_group"] if "seed_group" in pts else [None] * len(pts)
    others = sorted({point_group(str(c), g) for c, g in zip(pts.controller, groups, strict=True)})
    legend: dict[str, Any] = {}
    for ax, lv in zip(axes, levels, strict=True):
        group = pts[pts.level == lv]
        front = group[group.on_frontier].sort_values("settling_time_s")
        (line,) = ax.step(
            front.settling_time_s,
            front.peak_interaction_torque_nm,
            where="post",
            color="tab:green",
            lw=1.5,
        )
        legend.setdefault("frontier (accurate, non-dominated)", line)
        for _, p in group.iterrows():
            label = str(p.controller)
            ts = p.settling_time_s if math.isfinite(p.settling_time_s) else 8.0
            if label in styles:
                color, marker, name = styles[label]
            elif label.startswith("pid:ramp"):
                color, marker, name = "tab:blue", "o", "ramped PID"
            elif label.startswith("pid:reference=minjerk"):
                color, marker, name = "tab:olive", "o", "minimum-jerk PID"
            elif label.startswith("pid:limit"):
                color, marker, name = "tab:cyan", "s", "clipped PID"
            elif label.startswith("impedance"):
                color, marker, name = "tab:brown", "X", "impedance (spring-damper)"
            elif label.startswith("paper"):
                color, marker, name = "tab:red", "*", "paper SAC (its reductions)"
            elif label.startswith("oracle"):
                color, marker, name = "tab:purple", "P", "oracle (true state; settings)"
            else:
                name = point_group(label, p.get("seed_group"))
                color = _GROUP_COLORS[others.index(name) % len(_GROUP_COLORS)]
                marker = "D"
            handle = ax.scatter(
                ts,
                p.peak_interaction_torque_nm,
                color=color,
                marker=marker,
                s=60 if marker == "*" else 28,
                facecolors=color if p.accurate or label.startswith("paper") else "none",
            )
            legend.setdefault(name, handle)
        ax.set_title(f"level {lv}")
        ax.set_xlabel("settling time (s; 8 = never)")
        ax.set_ylabel("peak interaction torque (Nm)")
        ax.grid(alpha=0.3)
    fig.legend(legend.values(), legend.keys(), fontsize=7, loc="outside right center")
    fig.suptitle("Torque vs settling on the twin (filled: accurate; hollow: not)", fontsize=9)
    return fig


def markdown(pts: Any) -> str:
    """The frontier table as Markdown: every point on the selection subjects (in-sample),
    and the frontier's points confirmed on the evaluation subjects."""
    cols = [
        "level", "controller", *POINT_METRICS, "settled_share", "accuracy_deg", "accurate",
        "on_frontier",
    ]  # fmt: skip
    picked = str(pts[cols].sort_values(["level", "settling_time_s"]).to_markdown(index=False))
    parts = ["Picked on the selection subjects (in-sample):", "", picked]
    if "reachable" in pts:
        conf_cols = ["level", "controller", "accuracy_deg"]
        conf_cols += [f"confirmed_{m}" for m in CONFIRMED_METRICS]
        front = pts[pts.on_frontier].sort_values(["level", "confirmed_settling_time_s"])
        parts += [
            "",
            "The frontier confirmed on the evaluation subjects (reachable: accurate there too):",
            "",
            str(front[[*conf_cols, "reachable"]].to_markdown(index=False)),
        ]
    return "\n".join(parts)


def write_markdown(folder: Path) -> str:
    """Write ``frontier.md`` of *folder* from its ``frontier.csv`` (so the table is what the
    file gives) and return it."""
    import pandas as pd

    text = markdown(pd.read_csv(Path(folder) / "frontier.csv")) + "\n"
    (Path(folder) / "frontier.md").write_text(text)
    return text


def build_frontier(
    out: Path,
    subjects: int,
    controllers: Sequence[str] = (),
    seeds_dirs: Sequence[Path] = (),
    workers: int | None = None,
    accuracy_deg: float = ACCURACY_DEG,
    levels: Sequence[int] = VALID_LEVELS,
    progress: bool = True,
    oracle: bool = False,
    twin: TwinOptions | None = None,
    confirm_subjects: int | None = None,
    selection_root_seed: int = SELECTION_ROOT_SEED,
) -> Any:
    """Pick the frontier of the controllers on *subjects* selection subjects of one twin
    (*twin*, default: the default twin; with ``oracle``, also the torque-aware oracle at
    :data:`ORACLE_SWEEP`), confirm its points on *confirm_subjects* (default: *subjects*)
    evaluation subjects, and write the frontier files.

    Raises:
        ValueError: *selection_root_seed* is the evaluation root, or a run was stopped.
    """
    import pandas as pd

    from myoexo.control.specs import seeds_controllers
    from myoexo.evaluation.config import EvaluationConfig
    from myoexo.evaluation.runner import evaluate

    specs = [*classical_specs(), *controllers, *(oracle_specs() if oracle else [])]
    for seeds_dir in seeds_dirs:
        specs += seeds_controllers(seeds_dir)
    twin = twin or TwinOptions()
    picking = EvaluationConfig(
        controllers=tuple(specs),
        levels=tuple(levels),
        subjects=subjects,
        root_seed=selection_root_seed,  # a selection run refuses the evaluation root
        twin=twin,
        selection=True,
    )
    run = evaluate(picking, Path(out) / "selection", workers=workers, progress=progress)
    if run.table is None:
        raise ValueError(f"the evaluation was stopped ({run.stopped_by}); run again to finish")
    pts = points(run.table)
    pts = pd.concat([pts, paper_points(pts)], ignore_index=True)
    pts = mark_frontier(pts, accuracy_deg)
    by_label = {parse_label(s): s for s in specs}
    picked = [by_label[c] for c in dict.fromkeys(pts.controller[pts.on_frontier])]
    checking = EvaluationConfig(
        controllers=tuple(dict.fromkeys(["pid", *picked])),
        levels=tuple(levels),
        subjects=confirm_subjects or subjects,
        twin=twin,
    )
    run = evaluate(checking, Path(out) / "evaluation", workers=workers, progress=progress)
    if run.table is None:
        raise ValueError(f"the evaluation was stopped ({run.stopped_by}); run again to finish")
    pts = confirm(pts, points(run.table))
    out = Path(out)
    pts.to_csv(out / "frontier.csv", index=False)
    write_markdown(out)
    for lv in levels:
        plot_frontier(pts, lv).savefig(out / f"frontier_level{lv}.png", dpi=130)
    plot_frontier(pts).savefig(out / "frontier.png", dpi=130)
    return pts


def parse_label(spec: str) -> str:
    """The table label of a controller spec (its parsed label)."""
    from myoexo.control.specs import parse_controller_spec

    return parse_controller_spec(spec).label


@dataclass(frozen=True)
class FrontierConfig:
    """What ``myoexo frontier`` runs (each field is an option of the command; the twin's
    options and :class:`~myoexo.runtime.fields.Execution`'s are its other options)."""

    out: Path = option(Path("results/frontier"), "output folder", folder=True, metavar="DIR")
    subjects: int = option(
        10,
        "selection subjects per level (the picking); with the default 10, the run takes about "
        "900 s of a core (~8 min on 2 cores) without --oracle",
        low=1,
    )
    confirm_subjects: int | None = option(
        None,
        "evaluation subjects per level that confirm the picked points (default: --subjects)",
        low=1,
        metavar="SUBJECTS",
    )
    controllers: tuple[str, ...] = option(
        (), "more controller specs (e.g. sac oracle)", metavar="SPEC"
    )
    seeds_dir: tuple[Path, ...] = option(
        (),
        "aggregated `myoexo policy seeds` folders (each seed's selected checkpoint a point)",
        metavar="DIR",
    )
    oracle: bool = option(
        False,
        "add the torque-aware oracle at its sweep settings (slow: ~23 s of a core per "
        "episode, 4 settings: with 10 subjects about 1 h of a core more, ~30 min on 2 cores)",
    )
    accuracy_deg: float = option(
        ACCURACY_DEG,
        "accuracy band above the level's best mean |final error|",
        low=0.0,
        above=True,
        unit="deg",
    )

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo frontier``: :class:`FrontierConfig`'s fields, the twin's options
    and :class:`~myoexo.runtime.fields.Execution`'s."""
    add_options(parser, FrontierConfig)
    add_twin_arguments(parser)
    add_options(parser.add_argument_group("how to run"), Execution)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo frontier``."""
    config = from_options(FrontierConfig, args)
    execution = from_options(Execution, args)
    pts = build_frontier(
        config.out,
        config.subjects,
        config.controllers,
        config.seeds_dir,
        execution.workers,
        config.accuracy_deg,
        progress=execution.progress,
        oracle=config.oracle,
        twin=twin_from_args(args),
        confirm_subjects=config.confirm_subjects,
    )
    classical = pts.controller.str.startswith(("pid", "impedance", "paper"))
    print(markdown(pts[pts.on_frontier | classical]))
    print(f"wrote {config.out}/frontier.csv, frontier.md, frontier.png, frontier_level*.png")
    return 0
