"""Controllers named on the command line (``myoexo evaluate --controllers ...``).

A *spec* is a short string that a worker process can turn into a controller on its own (so
nothing unpicklable crosses process boundaries):

=================================  ==========================================================
spec                               controller
=================================  ==========================================================
``pid``                            :class:`~myoexo.control.pid.PID`, the paper's gains
``pid:kp=10,ki=30,kd=0.1``         PID with other gains (any of ``kp ki kd``)
``pid:feedback=exo``               PID on the exo encoder instead of the human knee
``pid:tuned=exo``                  a PID tuned for its sensors by Ziegler-Nichols on the twin
                                   (:data:`~myoexo.control.tuned.TUNED_PIDS`: ``exo``, the
                                   device PID on the encoder; ``latency``, the human knee
                                   read 10 ms late, for perturbed twins)
``pid:anti_windup=none``           ``clamping`` (default), ``back_calculation`` or ``none``
``pid:derivative=error``           derivative on the error instead of the measurement
``pid:textbook``                   plain parallel PID (derivative on error, no anti-windup)
``pid:ramp_s=0.6``                 setpoint ramped to the target over 0.6 s (a gentle start)
``pid:reference=minjerk``          the ramp's shape (with ``ramp_s``): ``linear`` (default)
                                   or ``minjerk`` (minimum jerk,
                                   :mod:`myoexo.control.reference`), e.g.
                                   ``pid:reference=minjerk,ramp_s=1``
``pid:step_lag_deg=4``             with a ramp: the setpoint steps to the target once the
                                   knee lags the ramp by more than 4 deg (where the leg
                                   resists), e.g.
                                   ``pid:reference=minjerk,ramp_s=0.45,step_lag_deg=4``
``pid:limit=0.6``                  command clipped at 0.6 (60 Nm)
``impedance``                      :class:`~myoexo.control.impedance.ImpedanceController`:
                                   a spring-damper (700 Nm/rad, 5 Nm s/rad: the paper's Kp
                                   and Kd x 100 Nm) on a 1 s minimum-jerk reference
``impedance:k=350,d=5``            its options: ``k`` (Nm/rad), ``d`` (Nm s/rad),
                                   ``duration_s``, ``feedback`` (``knee``/``exo``) and
                                   ``limit``, e.g. ``impedance:duration_s=1.5,limit=0.6``
``sac``                            the full-state policy shipped with the package
                                   (:func:`myoexo.load_policy`)
``student_exo``                    the deployable controller: the exo's own sensors, a
                                   memory of 10 frames, no clock (``load_policy
                                   ("student_exo")``, env ``obs_preset="exo"``)
``residual``                       the shipped correction on the minimum-jerk PID, trained
                                   on the current twin over the gentleness range (its
                                   default weight; ``residual@0.5`` at another)
``oracle``                         sampling-based MPC on a copy of the twin (true state):
                                   the achievable bound (:mod:`myoexo.control.oracle`);
                                   options ``samples``, ``horizon_s``, ``replan``, ``iters``
                                   and the torque-aware ``interaction_weight``,
                                   ``peak_weight``, ``ramp_s``; about 65 s of a core per
                                   episode (2 subjects x 4 levels: ~4.5 min on 2 cores)
``SPEC@W``                          a policy trained over the gentleness range
                                   (``myoexo policy train --gentleness random``) at weight
                                   W in [0, 1] (0: fastest, 1: gentlest), e.g.
                                   ``runs/g/model.zip@0.5``; without ``@W``, the default
                                   weight its metadata records
``guard:SPEC``                      any controller above with the stall guard on top: integral
                                   action once the knee stalls far from the target
                                   (:mod:`myoexo.control.guard`), e.g. ``guard:sac``
``path/to/actor.npz``              an exported numpy actor (``myoexo policy export``), with
                                   its ``.json`` beside it
``path/to/model.zip``              a stable-baselines3 SAC model (``SAC.load``); prefix
                                   ``ppo:``, ``sbx_sac:``, ``sbx_tqc:``, ``sbx_crossq:``
                                   (any alias of
                                   :data:`~myoexo.policies.algorithms.ALGORITHMS`)
=================================  ==========================================================

Options combine with commas: ``pid:feedback=exo,kp=5``. The spec's label (table column
``controller``) is the spec itself for ``pid``/``impedance``/``sac``/``oracle``, the file stem
for a model file. Controllers of one *seed group* (the checkpoints ``myoexo policy seeds``
selected in one folder, a distillation's seed copies: :attr:`ControllerSpec.seed_group`,
table column ``seed_group``) are one controller of the tables, over seeds and subjects. A
controller may need its own env (:func:`spec_env_kwargs`: the observation preset a policy was
trained on). A policy trained to correct a classical controller (``myoexo policy train
--residual-base SPEC``) runs on top of the base its metadata names
(:func:`with_residual_base`, :mod:`myoexo.control.residual`).
"""

from __future__ import annotations

import dataclasses
import json
import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from myoexo.control.impedance import ImpedanceConfig, ImpedanceController
from myoexo.control.pid import PID, PIDConfig, PIDGains
from myoexo.control.policy import GentleController, SB3Controller
from myoexo.control.protocol import Controller
from myoexo.control.residual import PacedBase, ResidualConfig, ResidualController
from myoexo.envs.config import check_gentleness
from myoexo.envs.options import TwinOptions
from myoexo.policies.algorithms import ALGORITHMS, load_sb3_model
from myoexo.policies.run_files import (
    AGGREGATE_FILE,
    CHECKPOINTS_DIR,
    CONFIG_FILE,
    MODEL_FILE,
    VECNORM_FILE,
    read_state,
)
from myoexo.runtime.fields import FieldError, convert, parse_assignments

_PID_KEYS = (
    "kp",
    "ki",
    "kd",
    "feedback",
    "anti_windup",
    "derivative",
    "textbook",
    "ramp_s",
    "limit",
    "tuned",
    "reference",
    "step_lag_deg",
)
#: Options of the ``impedance`` spec -> :class:`ImpedanceConfig` fields.
_IMPEDANCE_KEYS: dict[str, str] = {
    "k": "stiffness_nm_per_rad",
    "d": "damping_nm_s_per_rad",
    "duration_s": "duration_s",
    "feedback": "feedback",
    "limit": "output_limit",
}
#: The spec kinds of the classical (hand-designed, not learned) controllers.
CLASSICAL_KINDS: tuple[str, ...] = ("pid", "impedance")


#: Spec kinds that are learned policies (those that may take a gentleness weight, ``@W``).
POLICY_KINDS: tuple[str, ...] = ("shipped", "sb3", "actor")


class PolicyUnavailableError(RuntimeError):
    """The shipped policy (spec ``sac``) is not available in this installation."""


@dataclass(frozen=True)
class ControllerSpec:
    """A parsed controller spec.

    Attributes:
        kind: ``"pid"``, ``"impedance"``, ``"shipped"`` (``sac``, ``student_exo``),
            ``"oracle"``, ``"sb3"`` (a model file) or ``"actor"`` (an exported numpy actor,
            ``.npz`` + ``.json``).
        label: Name in tables and figures.
        text: The spec as given.
        path: Model file (``sb3``) or shipped policy name (``shipped``).
        algorithm: Alias of :data:`~myoexo.policies.algorithms.ALGORITHMS` (``sb3`` only).
        options: PID options (``pid``), as :class:`PIDConfig` keyword arguments,
            :class:`ImpedanceConfig` fields (``impedance``) or
            :class:`~myoexo.control.oracle.OracleConfig` fields (``oracle``).
        guard: The controller runs with the stall guard on top (``guard:SPEC``,
            :class:`~myoexo.control.guard.StallGuard`); ``kind`` and the rest describe SPEC.
        gentleness: The gentleness weight a policy trained over the weight range runs at
            (``SPEC@W``; its env appends the weight to the observation), ``None`` for
            any other controller.
        seed_group: The seed group the controller is one member of: the folder's name for
            a checkpoint of a ``myoexo policy seeds`` folder
            (``<seeds>/seed_<N>/checkpoints/<step>/model.zip``), the ``seed_group`` an
            exported actor's metadata records (a distillation seed's copy), ``guard:<group>``
            for a guarded member; ``None`` for a controller of its own.
    """

    kind: str
    label: str
    text: str
    path: str | None = None
    algorithm: str | None = None
    options: dict[str, Any] = field(default_factory=dict)
    guard: bool = False
    seed_group: str | None = None
    gentleness: float | None = None

    @property
    def slug(self) -> str:
        """File-system-safe form of the label (:func:`controller_slug`)."""
        return controller_slug(self.label)


def controller_slug(label: str) -> str:
    """File-system-safe form of a controller label (its folder and figure names)."""
    return re.sub(r"[^A-Za-z0-9_.+-]+", "_", label).strip("_") or "controller"


def parse_controller_spec(text: str) -> ControllerSpec:
    """Parse one spec (see the module docstring); ``ValueError`` on anything else."""
    text = text.strip()
    base, at, weight = text.rpartition("@")
    if at and not any(sep in weight for sep in "/\\:"):  # SPEC@W: a gentleness weight
        try:
            gentleness = check_gentleness(weight)
        except ValueError as exc:
            raise ValueError(f"controller {text!r}: {exc}") from None
        inner = parse_controller_spec(base)
        if inner.kind not in POLICY_KINDS:
            raise ValueError(
                f"controller {text!r}: only a policy takes a gentleness weight (@W); "
                f"{base!r} is a {inner.kind} controller"
            )
        group = f"{inner.seed_group}@{weight}" if inner.seed_group else None
        return dataclasses.replace(
            inner, label=f"{inner.label}@{weight}", text=text, gentleness=gentleness,
            seed_group=group,
        )  # fmt: skip
    head, _, tail = text.partition(":")
    if head.lower() == "guard":
        if not tail.strip():
            raise ValueError("controller 'guard:' needs the controller it guards: 'guard:sac'")
        inner = parse_controller_spec(tail)
        if inner.guard:
            raise ValueError(f"controller {text!r} guards a guarded controller")
        group = f"guard:{inner.seed_group}" if inner.seed_group else None
        return dataclasses.replace(
            inner, label=f"guard:{inner.label}", text=text, guard=True, seed_group=group
        )
    if head.lower() == "pid":
        return ControllerSpec(kind="pid", label=text, text=text, options=_pid_options(tail))
    if head.lower() == "impedance":
        return ControllerSpec(
            kind="impedance", label=text, text=text, options=_impedance_options(tail)
        )
    from myoexo.policies import SHIPPED_POLICIES

    if text.lower() in SHIPPED_POLICIES:
        return ControllerSpec(kind="shipped", label=text.lower(), text=text, path=text.lower())
    if head.lower() == "oracle":
        from myoexo.control.oracle import parse_oracle_options

        return ControllerSpec(
            kind="oracle", label=text, text=text, options=parse_oracle_options(tail)
        )
    algorithm = "sac"
    path_text = text
    if head.lower() in ALGORITHMS and tail:  # "td3:model.zip", "sbx_sac:model.zip"
        algorithm, path_text = head.lower(), tail
    path = Path(path_text).expanduser()
    if path.suffix == ".npz" and path.with_suffix(".json").is_file():  # an exported actor
        return ControllerSpec(
            kind="actor",
            label=path.stem,
            text=text,
            path=str(path.resolve()),
            seed_group=_actor_seed_group(path),
        )
    if path.suffix != ".zip":
        raise ValueError(
            f"unknown controller {text!r}: expected 'pid[:options]', 'impedance[:options]', "
            "'sac', 'student_exo', "
            "'oracle[:options]', the path of a stable-baselines3 model file (.zip) or of an "
            "exported actor (.npz beside its .json)"
        )
    if not path.is_file():
        raise ValueError(f"controller {text!r}: policy file {str(path)!r} does not exist")
    seeds = _seeds_folder(path)
    return ControllerSpec(
        kind="sb3",
        label=_model_label(path),
        text=text,
        path=str(path.resolve()),
        algorithm=algorithm,
        seed_group=seeds.name if seeds is not None else None,
    )


def _seeds_folder(path: Path) -> Path | None:
    """The ``myoexo policy seeds`` folder of a checkpoint's model file
    (``<seeds>/seed_<N>/checkpoints/<step>/model.zip``), as *path* names it; ``None`` for
    any other file."""
    if path.name != MODEL_FILE or path.parent.parent.name != CHECKPOINTS_DIR:
        return None
    run = path.parent.parent.parent
    prefix, _, number = run.name.partition("_")
    return run.parent if prefix == "seed" and number.isdigit() else None


def seeds_folder_of_spec(text: str) -> str | None:
    """The ``myoexo policy seeds`` folder, as the spec writes it, of a spec naming one of its
    checkpoints (``[ALGORITHM:]<seeds>/seed_<N>/checkpoints/<step>/model.zip``, what
    :func:`seeds_controllers` gives); ``None`` for any other spec. Reads no file."""
    head, _, tail = text.strip().partition(":")
    if tail and head.isidentifier():  # a prefix: an algorithm's, or guard:, pid:, oracle:
        if head.lower() not in ALGORITHMS:
            return None
        text = tail
    folder = _seeds_folder(Path(text))
    return folder.as_posix() if folder is not None else None


def _model_label(path: Path) -> str:
    """A model file's label: its stem, or ``<run>-<checkpoint>`` for the ``model.zip`` of a
    ``myoexo policy train`` checkpoint (``<run>/checkpoints/<step>/model.zip``), prefixed
    with the seeds folder for a ``myoexo policy seeds`` run (``<seeds>-seed_<N>-<step>``)."""
    if path.name == MODEL_FILE and path.parent.parent.name == CHECKPOINTS_DIR:
        run = path.parent.parent.parent
        label = f"{run.name}-{path.parent.name}"
        return f"{run.parent.name}-{label}" if _seeds_folder(path) is not None else label
    return path.stem


def _actor_seed_group(path: Path) -> str | None:
    """The ``seed_group`` an exported actor's metadata (``.json`` beside its ``.npz``)
    records, or ``None``."""
    try:
        group = json.loads(path.with_suffix(".json").read_text()).get("seed_group")
    except (OSError, ValueError, AttributeError):
        return None
    return str(group) if group else None


def seeds_controllers(seeds_dir: str | Path) -> list[str]:
    """The checkpoints ``myoexo policy seeds aggregate`` selected in *seeds_dir*, as controller
    specs (``<algorithm>:<checkpoint>/model.zip``, the algorithm from each checkpoint's
    state), one per seed in seed order: evaluated together they are one controller of the
    tables, over seeds and subjects (their labels share the folder's name).

    Raises:
        ValueError: *seeds_dir* has no aggregate (run ``myoexo policy seeds aggregate``).
    """
    path = Path(seeds_dir) / AGGREGATE_FILE
    if not path.is_file():
        raise ValueError(f"{str(path)!r} does not exist: run `myoexo policy seeds aggregate` first")
    chosen = json.loads(path.read_text())["selected_checkpoints"]
    specs = []
    for seed in sorted(chosen, key=int):
        checkpoint = Path(chosen[seed])
        specs.append(f"{_checkpoint_algorithm(checkpoint)}:{checkpoint / MODEL_FILE}")
    return specs


def _checkpoint_algorithm(checkpoint: Path) -> str:
    """The algorithm of a checkpoint: its state's, else its run's preset's (``"sac"``)."""
    algorithm = _checkpoint_state(str(checkpoint / MODEL_FILE)).get("algorithm")
    if algorithm is None:
        config = checkpoint.parent.parent / CONFIG_FILE
        preset = json.loads(config.read_text()).get("preset", {}) if config.is_file() else {}
        algorithm = preset.get("algorithm", "sac")
    return str(algorithm)


def _pid_options(tail: str) -> dict[str, Any]:
    options: dict[str, Any] = {}
    given = parse_assignments(tail, f"PID option in 'pid:{tail}'", bare=_PID_KEYS)
    for key, value in ((k.lower(), v) for k, v in given.items()):
        if key not in _PID_KEYS:
            raise ValueError(f"unknown PID option {key!r} in 'pid:{tail}'; accepted: {_PID_KEYS}")
        if key == "textbook":
            options["derivative_on_measurement"] = False
            options.setdefault("anti_windup", "none")
        elif key in ("kp", "ki", "kd", "ramp_s", "limit", "step_lag_deg"):
            options["output_limit" if key == "limit" else key] = convert(
                value, float, f"PID option {key}"
            )
        elif key == "tuned":
            from myoexo.control.tuned import tuned_pid

            tuned = tuned_pid(value.strip())
            options.setdefault("kp", tuned.gains.kp)
            options.setdefault("ki", tuned.gains.ki)
            options.setdefault("kd", tuned.gains.kd)
            options.setdefault("feedback", tuned.feedback)
        elif key == "derivative":
            if value not in ("measurement", "error"):
                raise ValueError(f"PID option derivative={value!r}; accepted: measurement, error")
            options["derivative_on_measurement"] = value == "measurement"
        elif not value:
            raise ValueError(f"PID option {key!r} needs a value ({key}=...)")
        else:
            options[key] = value
    pid_config(options)  # validate now, not in a worker
    return options


def _impedance_options(tail: str) -> dict[str, Any]:
    """``"k=700,d=5,duration_s=1,feedback=exo,limit=0.6"`` -> typed
    :class:`ImpedanceConfig` keyword arguments (validated)."""
    options: dict[str, Any] = {}
    for key, value in parse_assignments(tail, f"impedance option in 'impedance:{tail}'").items():
        name = _IMPEDANCE_KEYS.get(key.lower())
        if name is None:
            raise ValueError(
                f"unknown impedance option {key!r} in 'impedance:{tail}'; accepted: "
                f"{tuple(_IMPEDANCE_KEYS)}"
            )
        options[name] = (
            value if name == "feedback" else convert(value, float, f"impedance option {key}")
        )
    try:
        ImpedanceConfig(**options)  # validate now, not in a worker
    except FieldError as exc:
        option = next(k for k, v in _IMPEDANCE_KEYS.items() if v == exc.field)
        raise ValueError(f"impedance option {exc.describe(option)}") from None
    return options


def pid_config(options: dict[str, Any]) -> PIDConfig:
    """:class:`PIDConfig` from parsed PID options."""
    opts = dict(options)
    base = PIDGains()
    gains = PIDGains(
        kp=opts.pop("kp", base.kp), ki=opts.pop("ki", base.ki), kd=opts.pop("kd", base.kd)
    )
    return PIDConfig(gains=gains, **opts)


def load_shipped_policy(name: str = "sac") -> Any:
    """The shipped policy *name* as stored (:func:`myoexo.policies.load_policy`: a residual
    policy's correction alone, which :func:`build_controller` puts on its base), or
    :class:`PolicyUnavailableError` saying why not."""
    try:
        from myoexo.policies import load_policy

        return load_policy(name)
    except (ImportError, FileNotFoundError, OSError, AttributeError) as exc:
        raise PolicyUnavailableError(
            f"the shipped policy {name!r} is not available ({type(exc).__name__}: {exc})"
        ) from exc


def load_obs_normalizer(model_path: str) -> Any:
    """The ``VecNormalize`` statistics saved beside an SB3 model file (``None`` if none).

    A model trained with observation normalization (the ``cpu`` preset) must see the same
    normalization at evaluation; ``myoexo policy train`` checkpoints keep it in
    ``vecnormalize.pkl`` next to ``model.zip``.
    """
    import pickle

    path = Path(model_path).with_name(VECNORM_FILE)
    if not path.is_file():
        return None
    try:
        with open(path, "rb") as f:
            normalizer = pickle.load(f)
    except Exception as exc:
        raise ValueError(f"cannot read the observation statistics {path} ({exc})") from exc
    normalizer.training = False
    return normalizer


def load_actor_file(path: str) -> Any:
    """An exported controller file (``.npz`` + ``.json``: a numpy actor or a student,
    :func:`myoexo.policies.load_controller`), checked against its reference pairs;
    ``ValueError`` if it cannot be read."""
    from myoexo.policies import load_controller

    try:
        return load_controller(Path(path).with_suffix(""))
    except (OSError, KeyError) as exc:
        raise ValueError(f"cannot read the actor {path!r} ({type(exc).__name__}: {exc})") from exc


def build_controller(spec: ControllerSpec, env: Any) -> Controller:
    """The controller a spec names, sampled at ``env.unwrapped.dt`` where that matters (a
    policy trained over the gentleness range: at its weight, :func:`spec_gentleness`)."""
    controller = _build_plain(spec, env)
    if spec.guard or spec.kind not in POLICY_KINDS:
        return controller
    # a loaded shipped policy or exported actor carries its metadata: not read twice
    loaded = getattr(controller, "metadata", None) if spec.kind != "sb3" else None
    metadata = loaded if isinstance(loaded, Mapping) else policy_metadata(spec)
    controller = with_residual_base(controller, ResidualConfig.from_metadata(metadata), env)
    weight = spec_gentleness(spec, metadata)
    return controller if weight is None else GentleController(controller, weight)


def with_residual_base(
    controller: Controller, residual: ResidualConfig | None, env: Any
) -> Controller:
    """*controller* as it runs: on the base controller *residual* names
    (:class:`~myoexo.control.residual.ResidualController`, the base built on *env*), or as
    it is without one (``None``: a policy that commands the exo on its own; a policy's record
    is :meth:`ResidualConfig.from_metadata`)."""
    if residual is None:
        return controller
    return ResidualController(controller, residual_base(residual, env), residual.scale)


#: The option of a base controller spec that a paced base sets: its reference's duration.
PACE_OPTIONS: Mapping[str, str] = {"pid": "ramp_s", "impedance": "duration_s"}


def paced_base_spec(base: str) -> tuple[ControllerSpec, str]:
    """The residual base spec *base* of a paced base, and the option of it
    (:data:`PACE_OPTIONS`) the pace sets at each episode's weight.

    Raises:
        ValueError: *base* is no classical controller spec, is of a kind without a reference
            duration, or sets that duration itself.
    """
    spec = parse_classical_spec(base, "residual base")
    option = PACE_OPTIONS.get(spec.kind)
    if option is None:
        raise ValueError(
            f"a paced base sets the reference duration of {sorted(PACE_OPTIONS)}; got base {base!r}"
        )
    if option in spec.options:
        raise ValueError(
            f"base {base!r} sets {option}, which the pace sets from the gentleness weight: "
            "leave it out of the base"
        )
    return spec, option


def residual_base(residual: ResidualConfig, env: Any) -> Controller:
    """The base controller *residual* names, built on *env* (what
    :class:`~myoexo.control.residual.ResidualWrapper` trains on and
    :class:`~myoexo.control.residual.ResidualController` runs on): with a pace, a
    :class:`~myoexo.control.residual.PacedBase` that builds it at each episode's weight."""
    if residual.pace_s is None:
        return build_controller(parse_classical_spec(residual.base, "residual base"), env)
    spec, option = paced_base_spec(residual.base)

    def build(duration_s: float) -> Controller:
        return build_controller(
            dataclasses.replace(spec, options={**spec.options, option: duration_s}), env
        )

    return PacedBase(build, residual.pace_s)


def parse_classical_spec(text: str, role: str) -> ControllerSpec:
    """A classical controller spec (:data:`CLASSICAL_KINDS`) for *role*.

    Raises:
        ValueError: *text* is no spec, or names a learned policy or the oracle.
    """
    spec = parse_controller_spec(text)
    if spec.kind not in CLASSICAL_KINDS or spec.guard:
        raise ValueError(
            f"{role} {text!r} is a {'guarded ' if spec.guard else ''}{spec.kind} controller; "
            f"accepted: a classical controller spec ({', '.join(CLASSICAL_KINDS)}[:options])"
        )
    return spec


def _build_plain(spec: ControllerSpec, env: Any) -> Controller:
    """:func:`build_controller` without the gentleness weight."""
    if spec.guard:
        from myoexo.control.guard import StallGuard, StallGuardConfig, exo_guard

        inner = build_controller(dataclasses.replace(spec, guard=False), env)
        reads_exo = getattr(inner, "obs_preset", None) == "exo" or (
            isinstance(inner, (PID, ImpedanceController)) and inner.config.feedback == "exo"
        )
        config = dataclasses.replace(
            exo_guard() if reads_exo else StallGuardConfig(),
            control_period_s=float(env.unwrapped.dt),
        )
        return StallGuard(inner, config)
    if spec.kind == "pid":
        return PID.from_env(env, pid_config(spec.options))
    if spec.kind == "impedance":
        return ImpedanceController.from_env(env, ImpedanceConfig(**spec.options))
    if spec.kind == "shipped":
        return load_shipped_policy(spec.path or "sac")
    if spec.kind == "oracle":
        from myoexo.control.oracle import OracleMPC

        return OracleMPC.from_env(env, **spec.options)
    if spec.kind == "actor" and spec.path is not None:
        return load_actor_file(spec.path)
    if spec.kind == "sb3" and spec.path is not None:
        return SB3Controller(
            load_sb3_model(spec.path, spec.algorithm or "sac"),
            name=spec.label,
            obs_normalizer=load_obs_normalizer(spec.path),
        )
    raise ValueError(f"unknown controller kind {spec.kind!r}")


def _checkpoint_state(model_path: str) -> dict[str, Any]:
    """The state file beside a model file (``<checkpoint>/state.json``: what the checkpoint
    was trained on; ``{}`` for a model file outside a checkpoint)."""
    try:
        return read_state(Path(model_path).parent)
    except (OSError, ValueError):
        return {}


def policy_metadata(spec: ControllerSpec) -> dict[str, Any]:
    """Provenance a policy carries in its own files: the shipped or exported actor's
    metadata, or the checkpoint state beside a model file (``{}`` for the PID and the
    oracle)."""
    if spec.kind == "shipped":
        return dict(load_shipped_policy(spec.path or "sac").metadata)
    if spec.kind == "actor" and spec.path is not None:
        return dict(load_actor_file(spec.path).metadata)
    if spec.kind == "sb3" and spec.path is not None:
        return _checkpoint_state(spec.path)
    return {}


def twin_of_metadata(meta: Mapping[str, Any]) -> TwinOptions | None:
    """The twin a policy was trained on, from its metadata (``None`` if it records none). A
    record written before the twin options existed gives its observation preset and reward
    weights."""
    if isinstance(meta.get("twin"), dict):
        return TwinOptions.from_dict(meta["twin"])
    if "obs_preset" in meta:
        return TwinOptions(
            obs_preset=str(meta.get("obs_preset") or "full"),
            reward_weights=tuple(tuple(p) for p in meta.get("reward_weights") or ()),
        )
    return None


#: Metadata key of a policy trained with some envs on the nominal twin (``--nominal-envs``):
#: ``{"n_envs": N, "nominal_envs": K}``.
TRAINING_ENVS_KEY = "training_envs"


def trained_on_nominal_too(meta: Mapping[str, Any]) -> bool:
    """Whether a policy of this metadata was trained on the nominal twin of its (perturbed)
    twin too: some of its training envs were nominal (:data:`TRAINING_ENVS_KEY`)."""
    return bool((meta.get(TRAINING_ENVS_KEY) or {}).get("nominal_envs"))


def policy_twin(spec: ControllerSpec) -> TwinOptions | None:
    """The twin a policy was trained on, from its own files (``None`` for the PID, the
    oracle, and a model file that records none)."""
    return twin_of_metadata(policy_metadata(spec))


def _observation_kwargs(twin: TwinOptions | None) -> dict[str, Any]:
    if twin is None:
        return {}
    return TwinOptions(obs_preset=twin.obs_preset, obs_keys=twin.obs_keys).env_kwargs()


def spec_env_kwargs(spec: ControllerSpec) -> dict[str, Any]:
    """Env keyword arguments a controller needs: the observation of the twin it was trained
    on (its ``obs_preset`` or ``obs_keys``; ``{}`` for the full observation). A policy
    trained over the gentleness range runs on the plain observation: its controller
    (:class:`~myoexo.control.policy.GentleController`) appends the weight."""
    return _observation_kwargs(policy_twin(spec))


def spec_gentleness(
    spec: ControllerSpec, metadata: Mapping[str, Any] | None = None
) -> float | None:
    """The gentleness weight a policy runs at: ``SPEC@W``'s, else, for a policy trained over
    the gentleness range, the default weight its metadata records (``default_gentleness``);
    ``None`` for a controller that takes none. *metadata*: the policy's, where it is already
    loaded (default: read from its files, :func:`policy_metadata`).

    Raises:
        ValueError: A weight given to a policy trained without one, or a policy trained over
            the range that is named without a weight and records no default.
    """
    if spec.kind not in POLICY_KINDS:
        return None
    meta = policy_metadata(spec) if metadata is None else metadata
    twin = twin_of_metadata(meta)
    trained = twin.gentleness if twin is not None else ""
    if spec.gentleness is not None:
        if not trained:
            raise ValueError(
                f"controller {spec.text!r}: the policy was not trained with a gentleness "
                "weight (its twin records none); name it without @W"
            )
        return spec.gentleness
    if not trained:
        return None
    default = meta.get("default_gentleness")
    if default is None and trained != "random":
        default = float(trained)
    if default is None:
        raise ValueError(
            f"controller {spec.text!r} was trained over the gentleness range and records no "
            f"default weight: name a weight, e.g. '{spec.text}@0.5'"
        )
    return float(default)


def controller_env_kwargs(controller: Any) -> dict[str, Any]:
    """:func:`spec_env_kwargs` of a controller object: the observation its metadata records
    (a policy, the policy behind a callable adapter's ``fn`` or the controller a wrapper such
    as the stall guard holds as ``controller``), else its ``obs_preset``."""
    inner = getattr(controller, "controller", None)
    if inner is not None:
        return controller_env_kwargs(inner)
    for obj in (controller, getattr(controller, "fn", None)):
        meta = getattr(obj, "metadata", None)
        twin = twin_of_metadata(meta) if isinstance(meta, Mapping) else None
        preset = getattr(obj, "obs_preset", None)
        if twin is None and isinstance(preset, str):
            twin = TwinOptions(obs_preset=preset)
        if twin is not None:
            return _observation_kwargs(twin)
    return {}


def check_no_selection_leak(spec: ControllerSpec, root_seed: int) -> None:
    """Refuse to report a policy on the subjects that selected it.

    Raises:
        ValueError: The policy records ``selection_root_seed`` equal to ``root_seed``.
    """
    chosen_on = policy_metadata(spec).get("selection_root_seed")
    if chosen_on is not None and int(chosen_on) == int(root_seed):
        raise ValueError(
            f"controller {spec.text!r} was selected on the subjects of root seed {root_seed}; "
            "evaluating it there would report its selection subjects: use another root seed "
            "(the default evaluation root is 0, selection uses 1)"
        )
