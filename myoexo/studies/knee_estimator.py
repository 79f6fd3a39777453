"""``myoexo policy knee-estimator``: give a student a fine-positioning layer fitted on its own
episodes.

The exo's encoder reads the exo's angle, not the knee's: the straps give under the motor's
torque, so a student that brings the encoder to the target leaves the knee a few tenths of a
degree off it, and the give changes from one patient's straps to the next. The device's own
readings (cuff forces and torques, motor torque, their recent history) carry that give. This
command fits a small network that reads the student's memory of frames and returns the knee
angle minus the encoder angle, and adds it to the student as a
:class:`~myoexo.policies.student.FinePositioner`: an integral of the target minus the
estimated knee, active near the target (:class:`~myoexo.policies.student.FinePositioning`).

The episodes: the raw student (without any layer it already has) on ``subjects`` subjects per
level and twin (nominal and perturbed, :mod:`myoexo.envs.robustness`) of the distillation's
training range (root ``root_seed`` from index ``subject_offset``: training subjects, never the
evaluation root, which is refused), at a gentleness weight drawn uniformly per episode for a
student with a weight input. The labels are the twin's true knee angle minus the encoder
angle at each step. The last ``held_out`` subjects of each level and twin are kept out of the
fit and report the estimator's error over the last second of their episodes.

The estimator and the law are written into the student's own files in place (the
estimator's weights as ``knee_layer<i>.*`` arrays in ``<stem>.npz``, the law in the
``"student"`` block of ``<stem>.json``), with the command, the subjects, the package versions
and the held-out errors as the estimator's provenance. ``--law-only`` keeps each student's
estimator and writes the law alone (the command that set it in the estimator's provenance,
``law_command``).
"""

from __future__ import annotations

import argparse
import math
import shlex
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

from myoexo.evaluation.config import check_fit_root
from myoexo.policies.actor import MLPActor, actor_paths
from myoexo.policies.student import (
    KNEE_OFFSET_RANGE_DEG,
    FinePositioner,
    FinePositioning,
    StudentController,
    load_student,
    save_student,
)
from myoexo.runtime.fields import add_options, check_fields, from_options, option, option_words
from myoexo.spasticity.levels import VALID_LEVELS

#: The last part of an episode the held-out error is read over, s (the hold).
HOLD_WINDOW_S = 1.0


@dataclass(frozen=True)
class KneeEstimatorSettings:
    """The episodes and the network of ``myoexo policy knee-estimator`` (its options; the
    estimator's provenance records every field)."""

    root_seed: int = option(
        1, "root seed of the subjects (the evaluation root 0 is refused)", low=0, flag="seed"
    )
    subject_offset: int = option(
        10_000, "index of the first subject (the distillation's training range)", low=0
    )
    subjects: int = option(60, "subjects per level and twin fitted on", low=1, high=10_000)
    held_out: int = option(10, "further subjects per level and twin, kept out of the fit", low=0)
    levels: tuple[int, ...] = option(VALID_LEVELS, "spasticity levels", choices=VALID_LEVELS)
    perturbed: bool = option(True, "also collect on perturbed twins (one draw per subject)")
    hidden: tuple[int, ...] = option((256, 256), "hidden layer widths", low=1)
    epochs: int = option(40, "training epochs", low=1)
    batch_size: int = option(1024, "minibatch size", low=1)
    lr: float = option(1e-3, "Adam learning rate (cosine decay to 1 %)", low=0.0, above=True)
    train_seed: int = option(0, "seed of the weight draws and of the network's training", low=0)

    def __post_init__(self) -> None:
        check_fields(self)
        check_fit_root(self.root_seed, "the knee estimator's fit")


@dataclass
class Collected:
    """Network inputs (the student's memory, newest first), labels (knee minus encoder, deg)
    and, per row, the level, the twin (1: perturbed), whether the subject is held out and
    whether the row lies in its episode's last :data:`HOLD_WINDOW_S`."""

    windows: np.ndarray
    offsets_deg: np.ndarray
    level: np.ndarray
    perturbed: np.ndarray
    held_out: np.ndarray
    hold: np.ndarray


def collect(
    student: StudentController, settings: KneeEstimatorSettings, log: Callable[[str], None]
) -> tuple[Collected, float]:
    """Run the raw student on the settings' subjects; returns the rows and the env's control
    period (s)."""
    from myoexo.control.policy import GentleController
    from myoexo.envs import make_env
    from myoexo.envs.config import GENTLENESS_RANGE
    from myoexo.evaluation.config import subject_seed

    raw = student.with_fine(None)
    rng = np.random.default_rng(settings.train_seed)
    parts: dict[str, list[np.ndarray]] = {k: [] for k in Collected.__dataclass_fields__}
    twins = (False, True) if settings.perturbed else (False,)
    period_s = math.nan
    for level in settings.levels:
        for perturbed in twins:
            env = make_env(level, obs_preset=raw.obs_preset, robustness=perturbed)
            bare: Any = env.unwrapped
            period_s = float(bare.dt)
            raw.bind(env)
            started = time.time()
            total = settings.subjects + settings.held_out
            for i in range(total):
                seed = subject_seed(level, settings.subject_offset + i, settings.root_seed)
                weight = float(rng.uniform(*GENTLENESS_RANGE))
                ctrl = GentleController(raw, weight) if raw.gentleness_input else raw
                obs, info = env.reset(seed=seed)
                ctrl.reset(seed)
                windows, offsets = [], []
                done = False
                while not done:
                    action = ctrl.act(obs, None)  # type: ignore[arg-type]
                    window = raw.last_window  # what the network read at this step
                    assert window is not None
                    windows.append(window)
                    offsets.append(info["knee_angle_deg"] - info["exo_angle_deg"])
                    obs, _, terminated, truncated, info = env.step(action)
                    done = terminated or truncated
                n = len(offsets)
                time_s = np.arange(n) * period_s
                parts["windows"].append(np.asarray(windows, np.float32))
                parts["offsets_deg"].append(np.asarray(offsets, np.float64))
                parts["level"].append(np.full(n, level))
                parts["perturbed"].append(np.full(n, int(perturbed)))
                parts["held_out"].append(np.full(n, i >= settings.subjects))
                parts["hold"].append(time_s >= time_s[-1] - HOLD_WINDOW_S)
            env.close()
            twin = "perturbed" if perturbed else "nominal"
            log(f"[knee] level {level}, {twin}: {total} episodes in {time.time() - started:.0f} s")
    return Collected(**{k: np.concatenate(v) for k, v in parts.items()}), period_s


def train_estimator(
    data: Collected, settings: KneeEstimatorSettings, log: Callable[[str], None]
) -> MLPActor:
    """Fit the offset (deg) on the rows not held out: ``R tanh(mlp(z))`` with ``R`` =
    :data:`~myoexo.policies.student.KNEE_OFFSET_RANGE_DEG`, mean-squared error, ``z`` the
    input standardised as :class:`~myoexo.policies.actor.MLPActor` does."""
    import torch
    from torch import nn

    fit = ~data.held_out
    x = data.windows[fit].astype(np.float64)
    mean, var = x.mean(axis=0), x.var(axis=0)
    var = np.where(var < 1e-10, 1.0, var)  # a constant input (the target) is only centred
    z = np.clip((x - mean) / np.sqrt(var + 1e-8), -10.0, 10.0)
    reach = KNEE_OFFSET_RANGE_DEG
    threads = torch.get_num_threads()
    torch.set_num_threads(1)  # on a busy machine extra threads only wait on each other
    try:
        module = _fit(z, data.offsets_deg[fit] / reach, settings, lambda rms: rms * reach, log)
    finally:
        torch.set_num_threads(threads)
    linears = [m for m in module if isinstance(m, nn.Linear)]
    weights = [
        (lin.weight.detach().double().numpy(), lin.bias.detach().double().numpy())
        for lin in linears
    ]
    return MLPActor(
        weights, activation="elu", obs_mean=mean, obs_var=var, action_low=-reach, action_high=reach
    )


def _fit(
    z: np.ndarray,
    y: np.ndarray,
    settings: KneeEstimatorSettings,
    in_deg: Callable[[float], float],
    log: Callable[[str], None],
) -> Any:
    """An MLP (``settings.hidden``, ELU) with a tanh head fitted to ``y`` on ``z`` by
    mean-squared error (Adam, cosine decay); *in_deg* turns its rms error into degrees."""
    import torch
    from torch import nn

    torch.manual_seed(settings.train_seed)
    inputs = torch.as_tensor(z, dtype=torch.float32)
    labels = torch.as_tensor(y, dtype=torch.float32)
    layers: list[nn.Module] = []
    width = inputs.shape[1]
    for h in settings.hidden:
        layers += [nn.Linear(width, h), nn.ELU()]
        width = h
    layers.append(nn.Linear(width, 1))
    module = nn.Sequential(*layers)
    opt = torch.optim.Adam(module.parameters(), lr=settings.lr)
    steps = max(1, math.ceil(len(labels) / settings.batch_size))
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(
        opt, T_max=settings.epochs * steps, eta_min=settings.lr * 0.01
    )
    gen = torch.Generator().manual_seed(settings.train_seed)
    for epoch in range(settings.epochs):
        perm = torch.randperm(len(labels), generator=gen)
        total = 0.0
        for k in range(steps):
            rows = perm[k * settings.batch_size : (k + 1) * settings.batch_size]
            loss = torch.mean((torch.tanh(module(inputs[rows])).squeeze(1) - labels[rows]) ** 2)
            opt.zero_grad(set_to_none=True)
            loss.backward()
            opt.step()
            sched.step()
            total += float(loss.detach()) * len(rows)
        if epoch + 1 in (1, settings.epochs) or (epoch + 1) % 10 == 0:
            rms = in_deg(math.sqrt(total / len(labels)))
            log(f"[knee]   epoch {epoch + 1}/{settings.epochs}: rms error {rms:.3f} deg")
    return module


def held_out_errors(estimator: MLPActor, data: Collected) -> list[dict[str, Any]]:
    """Per level and twin, the estimator's mean absolute error (deg) and the offset's spread
    (deg) over the held-out subjects' last :data:`HOLD_WINDOW_S`."""
    rows = []
    for level in np.unique(data.level):
        for perturbed in np.unique(data.perturbed):
            m = data.held_out & data.hold & (data.level == level) & (data.perturbed == perturbed)
            if not m.any():
                continue
            err = estimator(data.windows[m].astype(np.float64))[:, 0] - data.offsets_deg[m]
            rows.append(
                {
                    "level": int(level),
                    "twin": "perturbed" if perturbed else "nominal",
                    "abs_error_deg": float(np.mean(np.abs(err))),
                    "offset_sd_deg": float(np.std(data.offsets_deg[m])),
                }
            )
    return rows


def fit_knee_estimator(
    student: StudentController,
    settings: KneeEstimatorSettings,
    law: FinePositioning,
    command: str = "",
    log: Callable[[str], None] = print,
) -> StudentController:
    """The student with a fine-positioning layer fitted on its own episodes (module
    docstring); the law's control period is the env's."""
    from myoexo.model import TWIN_VERSION
    from myoexo.runtime.fits import provenance

    started = time.time()
    data, period_s = collect(student, settings, log)
    estimator = train_estimator(data, settings, log)
    errors = held_out_errors(estimator, data)
    for row in errors:
        log(
            f"[knee] held out, level {row['level']} {row['twin']}: |error| "
            f"{row['abs_error_deg']:.3f} deg over the last {HOLD_WINDOW_S:g} s (the offset "
            f"spreads {row['offset_sd_deg']:.2f} deg)"
        )
    estimator.metadata.update(
        trained_by="myoexo policy knee-estimator",
        output="knee angle minus exo encoder angle, deg",
        student_distill_seed=student.metadata.get("distill_config", {}).get("seed"),
        settings=asdict(settings),
        samples=int((~data.held_out).sum()),
        held_out_errors=errors,
        wall_time_s=round(time.time() - started, 1),
        **provenance(command, TWIN_VERSION, root_seed=settings.root_seed),
    )
    return _with_layer(student, estimator, law, period_s)


def _with_layer(
    student: StudentController, estimator: MLPActor, law: FinePositioning, period_s: float
) -> StudentController:
    """*student* with the layer of *estimator* and *law* at the control period *period_s*."""
    return student.with_fine(FinePositioner(estimator, replace(law, control_period_s=period_s)))


def with_law(
    student: StudentController, law: FinePositioning, command: str = ""
) -> StudentController:
    """The student with its layer's estimator and *law* (at the layer's control period),
    *command* recorded as the estimator's ``law_command``.

    Raises:
        ValueError: The student has no fine-positioning layer.
    """
    if student.fine is None:
        raise ValueError(
            "the student has no fine-positioning layer to give a law to: fit one first "
            "(myoexo policy knee-estimator without --law-only)"
        )
    estimator = student.fine.estimator
    estimator.metadata["law_command"] = command
    return _with_layer(student, estimator, law, student.fine.law.control_period_s)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Options of ``myoexo policy knee-estimator``: the students, then
    :class:`KneeEstimatorSettings`' and :class:`~myoexo.policies.student.FinePositioning`'s
    fields."""
    parser.add_argument(
        "students",
        nargs="+",
        metavar="STEM",
        help="student files (<stem>.npz + .json, e.g. a distillation's run/student); each "
        "gets its own estimator, written into its files",
    )
    parser.add_argument(
        "--law-only",
        action="store_true",
        help="keep each student's estimator and write only the integral law below (students "
        "that have a layer)",
    )
    add_options(parser, KneeEstimatorSettings)
    add_options(parser.add_argument_group("the integral law"), FinePositioning)


def run(args: argparse.Namespace) -> int:
    """Fit and write each student's layer."""
    settings = from_options(KneeEstimatorSettings, args)
    law = from_options(FinePositioning, args)
    law_only = ["--law-only"] if args.law_only else []
    options = [*law_only, *option_words(settings), *option_words(law)]
    command = shlex.join(["myoexo", "policy", "knee-estimator", *args.students, *options])
    for stem in args.students:
        path = actor_paths(stem)[0].with_suffix("")  # the files' own rule for a stem
        print(f"[knee] {path}")
        student = load_student(path)
        if args.law_only:
            student = with_law(student, law, command)
        else:
            student = fit_knee_estimator(student, settings, law, command)
        npz, _ = save_student(student, path)
        print(f"[knee] written: {npz} and its estimator")
    return 0


def main(argv: Sequence[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="myoexo policy knee-estimator", description=__doc__.split("\n")[0]
    )
    add_arguments(parser)
    return run(parser.parse_args(argv))


__all__ = [
    "KneeEstimatorSettings",
    "collect",
    "fit_knee_estimator",
    "held_out_errors",
    "train_estimator",
    "with_law",
]
