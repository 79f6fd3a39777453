"""Does a stiffer human-exoskeleton interface rescue the device PID? (docs/reference.md
section 8, "Why the device PID fails").

Part 1: the device PID (``pid:feedback=exo``) and the paper's PID on twins whose coupling
springs and strap weld are all scaled by 0.5, 1, 2 and 4 (the perturbed twin's strap
stiffness factor, with its armature rule; damping, masses, friction, motor and sensors
nominal). Part 2: the device PID with one coupling element stiffened at a time.
10 subjects per level, evaluation root seed 0. About 2 minutes on one core::

    python docs/experiments/strap_stiffness.py [--out results/strap_check]
"""

from __future__ import annotations

import argparse
import dataclasses
from pathlib import Path

import pandas as pd

from myoexo.control.specs import build_controller, parse_controller_spec
from myoexo.envs import make_env
from myoexo.envs.robustness import RobustnessParams
from myoexo.evaluation.engine import evaluate_controller
from myoexo.model import TwinParams

SUBJECTS = 10
SCALES = (0.5, 1.0, 2.0, 4.0)


def run(spec: str, level: int, **env_kwargs: object) -> pd.DataFrame:
    """``spec`` on the first :data:`SUBJECTS` subjects of ``level`` (root seed 0)."""
    env = make_env(level, **env_kwargs)
    controller = build_controller(parse_controller_spec(spec), env)
    env.close()
    table, _ = evaluate_controller(controller, level, SUBJECTS, env_kwargs=env_kwargs, label=spec)
    return table


def all_springs(out: Path) -> None:
    """Part 1: every spring scaled together."""
    rows = []
    for k in SCALES:
        straps = RobustnessParams((k, k), (1.0, 1.0), 0.0, 0.0, 0.0, 0.0, ())
        for spec in ("pid:feedback=exo", "pid"):
            for level in range(4):
                table = run(spec, level, robustness=straps)
                table["strap_stiffness_scale"] = k
                rows.append(table)
    episodes = pd.concat(rows, ignore_index=True)
    episodes.to_csv(out / "episodes.csv", index=False)
    summary = episodes.groupby(["strap_stiffness_scale", "controller", "level"]).agg(
        abs_final_error_deg=("abs_final_error_deg", "mean"),
        settled_share=("settling_time_s", lambda s: s.notna().mean()),
        peak_interaction_torque_nm=("peak_interaction_torque_nm", "mean"),
        unstable=("unstable", "sum"),
    )
    summary.to_csv(out / "summary.csv")
    print(summary.to_markdown())


def one_element(out: Path) -> None:
    """Part 2: one coupling element stiffened at a time (the nominal twin otherwise)."""
    base = TwinParams()
    variants = {
        "nominal": {},
        "thigh slider x4": {"thigh_slide_stiffness_n_m": 4 * base.thigh_slide_stiffness_n_m},
        "cuff pins x4": {"pin_stiffness_nm_rad": 4 * base.pin_stiffness_nm_rad},
        "shank axial/abd 2.0 Nm/rad": {"shank_rotation_stiffness_nm_rad": 2.0},
        "shank axial/abd x4": {
            "shank_rotation_stiffness_nm_rad": 4 * base.shank_rotation_stiffness_nm_rad
        },
        # MuJoCo floors a solref time constant at 2 timesteps (4 ms): stiffness x1.56 at most
        "strap weld timeconst 4 ms (x1.56)": {"strap_solref": (0.004, base.strap_solref[1])},
    }
    rows = []
    for name, change in variants.items():
        twin = dataclasses.replace(base, **change)
        for level in range(3):
            table = run("pid:feedback=exo", level, twin=twin)
            rows.append(
                {
                    "variant": name,
                    "level": level,
                    "abs_final_error_deg": table.abs_final_error_deg.mean(),
                    "settled_share": table.settling_time_s.notna().mean(),
                    "unstable": int(table.unstable.sum()),
                }
            )
    parts = pd.DataFrame(rows)
    parts.to_csv(out / "parts.csv", index=False)
    print(parts.to_markdown(index=False))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path("results/strap_check"))
    args = parser.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    all_springs(args.out)
    one_element(args.out)


if __name__ == "__main__":
    main()
