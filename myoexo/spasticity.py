"""Spastic stretch reflex of the knee muscles (paper Table I and eqs. 1-4).

The paper's model and the project's reading of it are in docs/reference.md section 2.

The reflex adds a spasticity coefficient ``SC_total`` (a fraction of maximum isometric force)
to the excitation of the 11 spastic knee muscles. It is the sum of an angle term and a
velocity term, each a "soft window" built from two sigmoids::

    phi(k, b, b0) = 1 / (1 + exp(k (b - b0)))                                  (eq. 1)
    sc_a(theta)   = s_theta [1 - (phi(k, theta, theta_flex) - phi(k, theta, theta_ext))]
    sc_v(v)       = s_v     [1 - (phi(k, v, v_upper) - phi(k, v, v_lower))]
    SC_total      = sc_a(theta) + sc_v(v)

with the knee angle ``theta`` in degrees (MyoSuite ``knee_angle_r``, flexion positive) and
the knee velocity ``v`` in rad/s (flexion positive). Inside a level's range each bracket is
~0, at a limit it is 1/2 and far outside it tends to 1. The paper's eq. 4 prints the two
velocity sigmoids in the other order, which read literally gives ``2 s_v`` inside the range;
we follow the text and eq. 3 (zero inside, ``s_v`` outside). One slope ``k`` per level acts
on both terms, so with ``k = 0.1`` (level 3) the velocity window is far wider than its range
and the velocity term stays near ``s_v / 2`` at rest: the "maintained" tone the paper
describes for levels 2 and 3.

Contents:

* :class:`SpasticityParams` and :data:`LEVELS` (Table I), :func:`sample_subject` (individual
  subjects: 10 % Gaussian noise on every parameter);
* numpy functions :func:`phi`, :func:`sc_angle`, :func:`sc_velocity`, :func:`sc_total`
  (vectorized) and their torch twins (autograd through the inputs and every parameter);
* :class:`SpasticityStage`, the reflex as a stage of MyoSuite's muscle-command pipeline
  (:mod:`myosuite.envs.muscle_stages`), and :class:`SpasticityWrapper`, a gymnasium wrapper
  that installs it on any MyoSuite env whose model has the 11 muscles and ``knee_angle_r``.

Example::

    from myosuite.utils import gym
    from myoexo.spasticity import SpasticityWrapper

    env = SpasticityWrapper(gym.make("myoLegWalk-v0"), level=2)
    env.reset(seed=0)
    env.spasticity.subject        # SpasticityParams of the drawn subject
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping, Sequence
from types import MappingProxyType
from typing import TYPE_CHECKING, Any, NamedTuple

import gymnasium as gym
import numpy as np
from gymnasium.utils import RecordConstructorArgs

from myoexo.model.leg import KNEE_JOINT  # the joint whose angle and velocity drive the reflex
from myoexo.reflex import DelayLine, LevelCalibration, ReflexConfig, below, reflex_config

if TYPE_CHECKING:  # torch is imported lazily: ``import myoexo`` must stay fast
    import torch

__all__ = [
    "KNEE_JOINT",
    "LEVELS",
    "RANDOM_LEVEL",
    "SPASTIC_EXTENSORS",
    "SPASTIC_FLEXORS",
    "SPASTIC_MUSCLES",
    "STAGE_NAME",
    "SUBJECT_REL_STD",
    "VALID_LEVELS",
    "SpasticityParams",
    "SpasticityStage",
    "SpasticityWrapper",
    "phi",
    "phi_torch",
    "sample_subject",
    "sc_angle",
    "sc_angle_torch",
    "sc_total",
    "sc_total_torch",
    "sc_velocity",
    "sc_velocity_torch",
]

#: Spastic knee flexors (docs/reference.md section 2).
SPASTIC_FLEXORS: tuple[str, ...] = (
    "gaslat_r",
    "gasmed_r",
    "semimem_r",
    "semiten_r",
    "bflh_r",
    "bfsh_r",
)
#: Spastic knee extensors; the paper groups gracilis with them.
SPASTIC_EXTENSORS: tuple[str, ...] = ("grac_r", "vasmed_r", "vaslat_r", "vasint_r", "recfem_r")
#: The 11 muscles that receive ``SC_total``: flexors then extensors.
SPASTIC_MUSCLES: tuple[str, ...] = SPASTIC_FLEXORS + SPASTIC_EXTENSORS
#: Name of the stage in MyoSuite's muscle-command pipeline.
STAGE_NAME = "spasticity"
#: Standard deviation of a subject's parameters, relative to the level's nominal |value|.
SUBJECT_REL_STD = 0.10

_RAD_TO_DEG = 180.0 / math.pi
_MAX_SUBJECT_DRAWS = 100


@dataclasses.dataclass(frozen=True)
class SpasticityParams:
    """Parameters of the spastic reflex of one level or one subject (paper Table I).

    Attributes:
        theta_ext_deg: Lower (extension-side) limit of the reflex-free angle range, deg.
        theta_flex_deg: Upper (flexion-side) limit of the reflex-free angle range, deg.
        v_lower_rad_s: Lower limit of the reflex-free velocity range, rad/s.
        v_upper_rad_s: Upper limit of the reflex-free velocity range, rad/s.
        s_theta: Gain of the angle term, fraction of maximum isometric force (>= 0).
        s_v: Gain of the velocity term, fraction of maximum isometric force (>= 0).
        k: Sigmoid slope (>= 0), in 1/deg for the angle term and s/rad for the velocity term.

    Raises:
        ValueError: If a value is not finite, a gain or ``k`` is negative, or a range is
            empty (lower limit not below the upper one).
    """

    theta_ext_deg: float
    theta_flex_deg: float
    v_lower_rad_s: float
    v_upper_rad_s: float
    s_theta: float
    s_v: float
    k: float

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not isinstance(value, (int, float, np.floating, np.integer)) or isinstance(
                value, bool
            ):
                raise ValueError(
                    f"SpasticityParams.{field.name} must be a real number, got {value!r}."
                )
            if not math.isfinite(value):
                raise ValueError(f"SpasticityParams.{field.name} must be finite, got {value!r}.")
            object.__setattr__(self, field.name, float(value))
        for name in ("s_theta", "s_v", "k"):
            if getattr(self, name) < 0.0:
                raise ValueError(
                    f"SpasticityParams.{name} must be >= 0, got {getattr(self, name)!r}."
                )
        if not self.theta_ext_deg < self.theta_flex_deg:
            raise ValueError(
                "SpasticityParams needs theta_ext_deg < theta_flex_deg, got "
                f"theta_ext_deg={self.theta_ext_deg!r}, theta_flex_deg={self.theta_flex_deg!r}."
            )
        if not self.v_lower_rad_s < self.v_upper_rad_s:
            raise ValueError(
                "SpasticityParams needs v_lower_rad_s < v_upper_rad_s, got "
                f"v_lower_rad_s={self.v_lower_rad_s!r}, v_upper_rad_s={self.v_upper_rad_s!r}."
            )

    @classmethod
    def field_names(cls) -> tuple[str, ...]:
        """Names of the parameters, in the order of :meth:`as_array`."""
        return tuple(f.name for f in dataclasses.fields(cls))

    def as_array(self) -> np.ndarray:
        """The parameters as a float64 array of shape ``(7,)`` (order of the fields)."""
        return np.array(dataclasses.astuple(self), dtype=np.float64)

    @classmethod
    def from_array(cls, values: Sequence[float] | np.ndarray) -> SpasticityParams:
        """Inverse of :meth:`as_array` (validated)."""
        values = np.asarray(values, dtype=np.float64)
        names = cls.field_names()
        if values.shape != (len(names),):
            raise ValueError(f"Expected {len(names)} values {names}, got shape {values.shape}.")
        return cls(**{n: float(v) for n, v in zip(names, values, strict=True)})


#: Table I of the paper: spasticity levels (Modified Ashworth Scale) 0..3. Level 4 is not
#: modelled (excluded by the paper as unsafe).
LEVELS: Mapping[int, SpasticityParams] = MappingProxyType(
    {
        0: SpasticityParams(-45.0, 95.0, -10.0, 10.0, s_theta=0.0, s_v=0.0, k=0.0),
        1: SpasticityParams(-35.0, 80.0, -1.0, 1.0, s_theta=0.2, s_v=0.2, k=0.5),
        2: SpasticityParams(-30.0, 75.0, -0.5, 0.5, s_theta=0.3, s_v=0.3, k=0.2),
        3: SpasticityParams(-15.0, 60.0, -0.25, 0.25, s_theta=0.3, s_v=0.5, k=0.1),
    }
)


#: The levels the twin models, in order (Table I; level 4 is left out as unsafe).
VALID_LEVELS: tuple[int, ...] = tuple(sorted(LEVELS))
#: Level setting that draws the level uniformly from :data:`VALID_LEVELS` at every reset.
RANDOM_LEVEL = "random"


def _check_level_setting(level: Any) -> int | str:
    """A level (``int`` of :data:`VALID_LEVELS`) or :data:`RANDOM_LEVEL`, or a ``ValueError``."""
    if isinstance(level, str) and level == RANDOM_LEVEL:
        return RANDOM_LEVEL
    return _check_level(level)


def _check_level(level: Any) -> int:
    """The level as an ``int`` key of :data:`LEVELS`, or a ``ValueError``."""
    if isinstance(level, (bool, np.bool_)) or not isinstance(level, (int, np.integer)):
        raise ValueError(f"Unknown spasticity level {level!r}; expected one of {sorted(LEVELS)}.")
    if int(level) not in LEVELS:
        raise ValueError(f"Unknown spasticity level {level!r}; expected one of {sorted(LEVELS)}.")
    return int(level)


def sample_subject(
    level: int, rng: np.random.Generator, rel_std: float = SUBJECT_REL_STD
) -> SpasticityParams:
    """Draw an individual subject of a level.

    Every parameter ``p`` of the level becomes ``p + rel_std * |p| * z`` with independent
    standard normals ``z`` (7 draws from *rng*). A draw that would be invalid (a negative
    gain or an empty range: more than 7 standard deviations away with the default
    ``rel_std``) is redrawn.

    Args:
        level: Spasticity level, a key of :data:`LEVELS`.
        rng: Source of randomness (for an env: ``env.np_random``); same state, same subject.
        rel_std: Standard deviation relative to each parameter's nominal absolute value.

    Returns:
        The subject's parameters.

    Raises:
        ValueError: If *level* is unknown or *rel_std* is negative or not finite.
    """
    nominal = LEVELS[_check_level(level)].as_array()
    if not (math.isfinite(rel_std) and rel_std >= 0.0):
        raise ValueError(f"rel_std must be a finite value >= 0, got {rel_std!r}.")
    if not isinstance(rng, np.random.Generator):
        raise ValueError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}.")
    std = rel_std * np.abs(nominal)
    for _ in range(_MAX_SUBJECT_DRAWS):
        try:
            return SpasticityParams.from_array(nominal + std * rng.standard_normal(nominal.size))
        except ValueError:
            continue
    raise RuntimeError(  # pragma: no cover - needs rel_std far beyond any sensible value
        f"No valid subject of level {level} in {_MAX_SUBJECT_DRAWS} draws with rel_std={rel_std}."
    )


# ----------------------------------------------------------------------------- numpy model


def _finite_array(name: str, value: Any) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}.")
    return arr


def phi(k: float, b: Any, b0: float) -> np.ndarray:
    """Sigmoid of eq. 1, ``1 / (1 + exp(k (b - b0)))``, vectorized over *b*.

    Evaluated as ``(1 - tanh(k (b - b0) / 2)) / 2``, which is the same function without
    overflow for large ``k |b - b0|`` (:func:`myoexo.reflex.below`: -> 1 below ``b0``).
    """
    return below(b, b0, k)


def _outside_window(x: np.ndarray, k: float, upper: float, lower: float, scale: float):
    """``scale * [1 - (phi(k, x, upper) - phi(k, x, lower))]``: ~0 inside ``[lower, upper]``,
    ``scale / 2`` at a limit, -> ``scale`` far outside (the shape of eqs. 2 and 3)."""
    out = scale * (1.0 - (phi(k, x, upper) - phi(k, x, lower)))
    return float(out) if out.ndim == 0 else out


def sc_angle(theta_deg: Any, params: SpasticityParams) -> np.ndarray | float:
    """Angle term ``sc_a`` of the spasticity coefficient.

    Args:
        theta_deg: Knee angle(s) in degrees, flexion positive (any array shape).
        params: Level or subject parameters.

    Returns:
        ``sc_a`` with the shape of *theta_deg* (a float for a scalar input).

    Raises:
        ValueError: If an angle is NaN or infinite.
    """
    theta = _finite_array("theta_deg", theta_deg)
    p = params
    return _outside_window(theta, p.k, p.theta_flex_deg, p.theta_ext_deg, p.s_theta)


def sc_velocity(vel_rad_s: Any, params: SpasticityParams) -> np.ndarray | float:
    """Velocity term ``sc_v`` of the spasticity coefficient.

    Args:
        vel_rad_s: Knee velocity(ies) in rad/s, flexion positive (any array shape).
        params: Level or subject parameters.

    Returns:
        ``sc_v`` with the shape of *vel_rad_s* (a float for a scalar input).

    Raises:
        ValueError: If a velocity is NaN or infinite.
    """
    vel = _finite_array("vel_rad_s", vel_rad_s)
    p = params
    return _outside_window(vel, p.k, p.v_upper_rad_s, p.v_lower_rad_s, p.s_v)


def sc_total(theta_deg: Any, vel_rad_s: Any, params: SpasticityParams) -> np.ndarray | float:
    """Spasticity coefficient ``SC_total = sc_a(theta) + sc_v(v)`` (broadcast over inputs).

    Args:
        theta_deg: Knee angle(s) in degrees, flexion positive.
        vel_rad_s: Knee velocity(ies) in rad/s, flexion positive.
        params: Level or subject parameters.

    Returns:
        ``SC_total``, a fraction of maximum isometric force in ``[0, s_theta + s_v]``.

    Raises:
        ValueError: If an input is NaN or infinite.
    """
    return sc_angle(theta_deg, params) + sc_velocity(vel_rad_s, params)


# ----------------------------------------------------------------------------- torch twin

_TorchParams = SpasticityParams | Mapping[str, Any]


def _torch_param(params: _TorchParams, name: str, like: torch.Tensor) -> torch.Tensor:
    import torch

    value = getattr(params, name) if isinstance(params, SpasticityParams) else params[name]
    if isinstance(value, torch.Tensor):
        return value
    return torch.as_tensor(value, dtype=like.dtype, device=like.device)


def _finite_tensor(name: str, value: Any) -> torch.Tensor:
    import torch

    tensor = (
        value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float64)
    )
    if not bool(torch.isfinite(tensor).all()):
        raise ValueError(f"{name} must be finite, got {value!r}.")
    return tensor


def phi_torch(k: torch.Tensor, b: torch.Tensor, b0: torch.Tensor) -> torch.Tensor:
    """Torch twin of :func:`phi` (differentiable in ``k``, ``b`` and ``b0``)."""
    import torch

    return 0.5 * (1.0 - torch.tanh(0.5 * k * (b - b0)))


def sc_angle_torch(theta_deg: Any, params: _TorchParams) -> torch.Tensor:
    """Torch twin of :func:`sc_angle`.

    Args:
        theta_deg: Knee angle(s) in degrees (tensor, or anything ``torch.as_tensor`` takes:
            float64 then).
        params: A :class:`SpasticityParams` (constants) or a mapping from its field names to
            tensors (or floats); gradients flow to every tensor given.

    Raises:
        ValueError: If an angle is NaN or infinite.
    """
    theta = _finite_tensor("theta_deg", theta_deg)
    k = _torch_param(params, "k", theta)
    window = phi_torch(k, theta, _torch_param(params, "theta_flex_deg", theta)) - phi_torch(
        k, theta, _torch_param(params, "theta_ext_deg", theta)
    )
    return _torch_param(params, "s_theta", theta) * (1.0 - window)


def sc_velocity_torch(vel_rad_s: Any, params: _TorchParams) -> torch.Tensor:
    """Torch twin of :func:`sc_velocity` (see :func:`sc_angle_torch` for *params*).

    Raises:
        ValueError: If a velocity is NaN or infinite.
    """
    vel = _finite_tensor("vel_rad_s", vel_rad_s)
    k = _torch_param(params, "k", vel)
    window = phi_torch(k, vel, _torch_param(params, "v_upper_rad_s", vel)) - phi_torch(
        k, vel, _torch_param(params, "v_lower_rad_s", vel)
    )
    return _torch_param(params, "s_v", vel) * (1.0 - window)


def sc_total_torch(theta_deg: Any, vel_rad_s: Any, params: _TorchParams) -> torch.Tensor:
    """Torch twin of :func:`sc_total`, differentiable in the inputs and every parameter.

    Example::

        p = {n: torch.tensor(v, dtype=torch.float64, requires_grad=True)
             for n, v in zip(SpasticityParams.field_names(), LEVELS[2].as_array())}
        sc_total_torch(torch.tensor(80.0, dtype=torch.float64), 0.3, p).backward()

    Raises:
        ValueError: If an input is NaN or infinite.
    """
    return sc_angle_torch(theta_deg, params) + sc_velocity_torch(vel_rad_s, params)


# ----------------------------------------------------------------------------- MyoSuite stage


class _StepCoefficients(NamedTuple):
    """A subject's constants of the per-step reflex (python floats: scalar math is fastest).

    ``phi(k, x, lim) = (1 - tanh(k (x - lim) / 2)) / 2``, so every window is written with
    the halved slope; the gains are multiplied in once per subject."""

    half_k: float
    flex_theta_deg: float  # flexors' angle threshold (Table I's theta_ext + calibration shift)
    theta_ext_deg: float  # Table I's extension-side limit (the uniform model's)
    theta_flex_deg: float
    v_lower_rad_s: float
    v_upper_rad_s: float
    flex_s_theta: float  # gain x s_theta of the flexors' angle term
    flex_s_v: float
    ext_s_theta: float
    ext_s_v: float


class SpasticityStage:
    """The spastic reflex as a stage of MyoSuite's muscle-command pipeline.

    Install it on a MyoSuite env (a :class:`~myosuite.envs.muscle_stages.CtrlStageHost`)::

        stage = SpasticityStage(level=2)
        env.unwrapped.add_ctrl_stage(STAGE_NAME, stage.apply, stage.reset)

    or use :class:`SpasticityWrapper`. Each control step :meth:`apply` reads the angle (deg)
    and velocity (rad/s) of ``knee_angle_r`` from ``env.data``, passes them through the
    reflex's transmission delay (:class:`~myoexo.reflex.DelayLine`, whole control periods of
    the host's ``env.dt``), computes the current subject's reflex excitation with the chosen
    model (:mod:`myoexo.reflex`: ``"stretch"``, each muscle group answering its own stretch,
    or ``"uniform"``, the paper's ``SC_total`` on all 11 muscles) and adds it to the spastic
    muscles' entries of ``ctrl``, clipped to ``[0, 1]``; every other entry is left as it is.
    MyoSuite's (MuJoCo's) activation dynamics then act on the excitation. :meth:`reset` draws
    the next subject (and, with ``level="random"``, the next level, uniformly) from
    ``env.np_random`` and clears the delay line.

    The joint and actuator addresses are resolved once per model, so a step costs a few
    scalar operations and one fancy-indexed update of 11 entries.

    Args:
        level: Spasticity level (a key of :data:`LEVELS`) or ``"random"``.
        subject_noise: Draw individual subjects (10 % noise, :func:`sample_subject`) at
            reset; ``False`` keeps the level's nominal Table I parameters.
        rel_std: Relative standard deviation of the subject parameters.
        reflex: Reflex model: a preset name of :data:`~myoexo.reflex.REFLEX_PRESETS`
            (``"stretch"``, the calibrated default, or ``"uniform"``) or a
            :class:`~myoexo.reflex.ReflexConfig`.
        flexors: Actuators stretched by knee extension (default: the paper's 6).
        extensors: Actuators stretched by knee flexion (default: the paper's 5).
        joint: Hinge joint whose angle and velocity drive the reflex.

    Attributes:
        level_setting: The configured level: an ``int`` level, or ``"random"``
            (:data:`RANDOM_LEVEL`, a new level at every reset).
        level: Level of the current subject. Until the first :meth:`reset` the stage uses the
            nominal parameters of its level (level 0 for ``"random"``).
        subject: :class:`SpasticityParams` of the current subject.
        reflex: The :class:`~myoexo.reflex.ReflexConfig` in use.
        last_flexor_excitation: Reflex excitation added to the flexors at the last step.
        last_extensor_excitation: Reflex excitation added to the extensors at the last step.
        last_sc_total: Their sum (for ``"uniform"``: ``SC_total``, which both groups get);
            0 before any step.

    Raises:
        ValueError: If *level* or *reflex* is unknown, *rel_std* invalid or a group empty.
    """

    name = STAGE_NAME

    def __init__(
        self,
        level: int | str = 2,
        *,
        subject_noise: bool = True,
        rel_std: float = SUBJECT_REL_STD,
        reflex: str | ReflexConfig = "stretch",
        flexors: Sequence[str] = SPASTIC_FLEXORS,
        extensors: Sequence[str] = SPASTIC_EXTENSORS,
        joint: str = KNEE_JOINT,
    ) -> None:
        self.level_setting: int | str = _check_level_setting(level)
        initial = min(LEVELS) if self.level_setting == RANDOM_LEVEL else int(self.level_setting)
        if not (math.isfinite(rel_std) and rel_std >= 0.0):
            raise ValueError(f"rel_std must be a finite value >= 0, got {rel_std!r}.")
        if len(flexors) == 0 or len(extensors) == 0:
            raise ValueError("flexors and extensors must each name at least one actuator.")
        self.subject_noise = bool(subject_noise)
        self.rel_std = float(rel_std)
        self.reflex = reflex_config(reflex)
        self._uniform = self.reflex.model == "uniform"
        self.flexors = tuple(flexors)
        self.extensors = tuple(extensors)
        self.muscles = self.flexors + self.extensors
        self.joint = joint
        self.last_sc_total = 0.0
        self.last_flexor_excitation = 0.0
        self.last_extensor_excitation = 0.0
        self._model: Any = None
        self._delay = DelayLine(0)
        self._set_subject(initial, LEVELS[initial])

    # -- subject --------------------------------------------------------------------------
    def _set_subject(self, level: int, subject: SpasticityParams) -> None:
        self.level = level
        self.subject = subject
        p = subject
        if self._uniform:
            cal = LevelCalibration()
        else:
            cal = self.reflex.calibration[level]
        self._coef = _StepCoefficients(
            half_k=0.5 * p.k,
            flex_theta_deg=p.theta_ext_deg + cal.flexor_threshold_shift_deg,
            theta_ext_deg=p.theta_ext_deg,
            theta_flex_deg=p.theta_flex_deg,
            v_lower_rad_s=p.v_lower_rad_s,
            v_upper_rad_s=p.v_upper_rad_s,
            flex_s_theta=cal.flexor_gain * p.s_theta,
            flex_s_v=cal.flexor_gain * p.s_v,
            ext_s_theta=cal.extensor_gain * p.s_theta,
            ext_s_v=cal.extensor_gain * p.s_v,
        )

    def set_subject(self, subject: SpasticityParams, level: int | None = None) -> None:
        """Use *subject* from now until the next :meth:`reset` (e.g. a stretch test).

        Args:
            subject: Reflex parameters.
            level: Level to report in :attr:`level` and whose calibration applies
                (default: unchanged).
        """
        if not isinstance(subject, SpasticityParams):
            raise ValueError(f"subject must be SpasticityParams, got {type(subject).__name__}.")
        self._set_subject(self.level if level is None else _check_level(level), subject)

    def set_level(self, level: int | str) -> None:
        """Change the level (or ``"random"``) used from the next :meth:`reset` on."""
        self.level_setting = _check_level_setting(level)

    def reset(self, env: Any) -> None:
        """Draw the next level (``"random"`` only) and subject from ``env.np_random``; clear
        the delay line."""
        rng = env.np_random
        if self.level_setting == RANDOM_LEVEL:
            level = VALID_LEVELS[int(rng.integers(len(VALID_LEVELS)))]
        else:
            level = int(self.level_setting)
        subject = sample_subject(level, rng, self.rel_std) if self.subject_noise else LEVELS[level]
        self._set_subject(level, subject)
        self.clear_history()

    def clear_history(self) -> None:
        """Forget the delayed knee states and the last excitations (a new motion starts)."""
        self._delay.clear()
        self.last_sc_total = 0.0
        self.last_flexor_excitation = 0.0
        self.last_extensor_excitation = 0.0

    # -- model binding ----------------------------------------------------------------------
    def bind(self, model: Any, control_period_s: float | None = None) -> None:
        """Resolve the joint address and muscle actuator ids of *model* (done once per model)
        and size the delay line for the host's control period.

        Args:
            model: The MuJoCo model.
            control_period_s: Time between two :meth:`apply` calls (default: the model's
                timestep).

        Raises:
            ValueError: If the joint is missing or not a hinge, or a muscle is missing.
        """
        import mujoco

        jid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, self.joint)
        if jid < 0:
            raise ValueError(f"The model has no joint {self.joint!r}; the reflex needs it.")
        if model.jnt_type[jid] != mujoco.mjtJoint.mjJNT_HINGE:
            raise ValueError(f"Joint {self.joint!r} must be a hinge joint.")
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, n) for n in self.muscles]
        missing = [n for n, i in zip(self.muscles, ids, strict=True) if i < 0]
        if missing:
            raise ValueError(
                f"The model has no actuators {missing}; the reflex drives {self.muscles}."
            )
        self._qpos_adr = int(model.jnt_qposadr[jid])
        self._dof_adr = int(model.jnt_dofadr[jid])
        self._act_ids = np.asarray(ids, dtype=np.intp)
        self._n_flex = len(self.flexors)
        self._nu = int(model.nu)
        period = float(control_period_s or model.opt.timestep)
        self._delay = DelayLine(round(self.reflex.delay_s / period))
        self._data_views: tuple | None = None  # (data, qpos, qvel) last seen by apply
        self._model = model

    def planning_copy(self, model: Any, control_period_s: float) -> SpasticityStage:
        """A copy of this stage (bound to *model* first if it is not yet) with the same
        subject and a delay line of its own: it can be run ahead on another ``MjData`` of
        the model and reset to this stage's history (:attr:`delay_line` ``.state()``)
        without touching this stage."""
        import copy

        if self._model is not model:
            self.bind(model, control_period_s)
        twin = copy.copy(self)
        twin._delay = copy.deepcopy(self._delay)
        twin._data_views = None
        return twin

    @property
    def delay_line(self) -> DelayLine:
        """The reflex's transmission delay line (the delayed knee states)."""
        return self._delay

    @property
    def actuator_ids(self) -> np.ndarray:
        """Actuator ids of the driven muscles in the bound model (after the first step)."""
        if self._model is None:
            raise RuntimeError("The stage is not bound to a model yet (call bind or apply).")
        return self._act_ids

    @property
    def delay_steps(self) -> int:
        """Delay of the knee state the reflex reads, in control steps."""
        return self._delay.delay_steps

    # -- the stage ----------------------------------------------------------------------------
    def sc_now(self, theta_deg: float, vel_rad_s: float) -> float:
        """``SC_total`` of the current subject at one state (scalar fast path of
        :func:`sc_total`; the ``"uniform"`` model's excitation of every muscle).

        Raises:
            ValueError: If the angle or the velocity is NaN or infinite.
        """
        return self._excitations(theta_deg, vel_rad_s, uniform=True)[0]

    def excitations_now(self, theta_deg: float, vel_rad_s: float) -> tuple[float, float]:
        """``(flexor, extensor)`` reflex excitation of the current subject at one (already
        delayed) knee state, with the stage's model.

        Raises:
            ValueError: If the angle or the velocity is NaN or infinite.
        """
        return self._excitations(theta_deg, vel_rad_s, uniform=self._uniform)

    def _excitations(
        self, theta_deg: float, vel_rad_s: float, uniform: bool
    ) -> tuple[float, float]:
        if not (math.isfinite(theta_deg) and math.isfinite(vel_rad_s)):
            raise ValueError(
                f"Knee state must be finite, got theta_deg={theta_deg!r}, vel_rad_s={vel_rad_s!r}."
            )
        c = self._coef
        tanh = math.tanh
        hk = c.half_k
        # below(x; lim) = (1 - tanh(hk (x - lim))) / 2, above(x; lim) = (1 + tanh(...)) / 2
        if uniform:
            p = self.subject
            sc = 0.5 * p.s_theta * (
                2.0
                - tanh(hk * (theta_deg - c.theta_ext_deg))
                + tanh(hk * (theta_deg - c.theta_flex_deg))
            ) + 0.5 * p.s_v * (
                2.0
                - tanh(hk * (vel_rad_s - c.v_lower_rad_s))
                + tanh(hk * (vel_rad_s - c.v_upper_rad_s))
            )
            return sc, sc
        flex = 0.5 * (
            c.flex_s_theta * (1.0 - tanh(hk * (theta_deg - c.flex_theta_deg)))
            + c.flex_s_v * (1.0 - tanh(hk * (vel_rad_s - c.v_lower_rad_s)))
        )
        ext = 0.5 * (
            c.ext_s_theta * (1.0 + tanh(hk * (theta_deg - c.theta_flex_deg)))
            + c.ext_s_v * (1.0 + tanh(hk * (vel_rad_s - c.v_upper_rad_s)))
        )
        return flex, ext

    def apply(self, env: Any, ctrl: np.ndarray) -> np.ndarray:
        """Add the reflex excitation to the spastic muscles' entries of *ctrl* (in place;
        returned).

        Args:
            env: Host with ``model`` and ``data`` (a MyoSuite env, or any such object); its
                ``dt`` (if any) is the control period of the delay line.
            ctrl: The full control vector (``model.nu`` entries), excitations in ``[0, 1]``.

        Raises:
            ValueError: If *ctrl* has the wrong length or the knee state is not finite.
        """
        model = env.model
        if model is not self._model:
            self.bind(model, getattr(env, "dt", None))
        if ctrl.shape[0] != self._nu:
            raise ValueError(f"ctrl has {ctrl.shape[0]} entries, the model {self._nu} actuators.")
        data = env.data
        views = self._data_views
        if views is None or views[0] is not data:  # its qpos/qvel views, looked up once
            views = self._data_views = (data, data.qpos, data.qvel)
        theta_deg, vel_rad_s = self._delay.push(
            views[1].item(self._qpos_adr) * _RAD_TO_DEG, views[2].item(self._dof_adr)
        )
        flex, ext = self._excitations(theta_deg, vel_rad_s, self._uniform)
        ids = self._act_ids
        u = ctrl[ids]  # a copy (fancy indexing); clip in place, cheaper than np.clip
        nf = self._n_flex
        u[:nf] += flex
        u[nf:] += ext
        np.minimum(u, 1.0, out=u)
        np.maximum(u, 0.0, out=u)
        ctrl[ids] = u
        self.last_flexor_excitation = flex
        self.last_extensor_excitation = ext
        self.last_sc_total = flex if self._uniform else flex + ext
        return ctrl

    def __call__(self, env: Any, ctrl: np.ndarray) -> np.ndarray:
        """Same as :meth:`apply`."""
        return self.apply(env, ctrl)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_model"] = None  # re-bound on the first step after unpickling
        for key in ("_qpos_adr", "_dof_adr", "_act_ids", "_nu", "_n_flex", "_data_views"):
            state.pop(key, None)
        return state

    def __repr__(self) -> str:
        return (
            f"SpasticityStage(level_setting={self.level_setting!r}, level={self.level}, "
            f"reflex={self.reflex.model!r}, delay_s={self.reflex.delay_s}, "
            f"subject_noise={self.subject_noise}, subject={self.subject})"
        )


class SpasticityWrapper(RecordConstructorArgs, gym.Wrapper):
    """Install a :class:`SpasticityStage` on a MyoSuite env (CPU; like ``CtrlStageWrapper``).

    The stage runs after MyoSuite's built-in stages (noise, fatigue, reroute), right before
    ``ctrl`` is written, unless an explicit *order* puts it earlier. The stage is
    ``env.spasticity`` (also reachable through outer wrappers with
    ``env.get_wrapper_attr("spasticity")``). The wrapper pickles as its constructor
    arguments and re-installs the stage on the rebuilt env.

    Args:
        env: A MyoSuite env whose pipeline runs muscle stages and whose model has the 11
            spastic muscles and ``knee_angle_r`` (e.g. ``myoLegWalk-v0``).
        level: Spasticity level 0..3 or ``"random"``.
        subject_noise: Draw individual subjects at reset (see :class:`SpasticityStage`).
        reflex: Reflex model, a preset name (``"stretch"``, ``"uniform"``) or a
            :class:`~myoexo.reflex.ReflexConfig` (see :class:`SpasticityStage`).
        order: MyoSuite stage order (``None``: after the built-in stages).

    Raises:
        TypeError: If the env does not run muscle stages.
        ValueError: If *level* is unknown or the model lacks a muscle or the knee joint.
    """

    def __init__(
        self,
        env: gym.Env,
        level: int | str = 2,
        subject_noise: bool = True,
        reflex: str | ReflexConfig = "stretch",
        order: float | None = None,
    ) -> None:
        RecordConstructorArgs.__init__(
            self, level=level, subject_noise=subject_noise, reflex=reflex, order=order
        )
        gym.Wrapper.__init__(self, env)
        host: Any = env.unwrapped
        if not getattr(host, "supports_ctrl_stages", False):
            raise TypeError(
                f"SpasticityWrapper needs an env whose action pipeline runs muscle stages; "
                f"{type(host).__name__} does not."
            )
        self._kwargs = {
            "level": level,
            "subject_noise": subject_noise,
            "reflex": reflex,
            "order": order,
        }
        self.spasticity = SpasticityStage(level, subject_noise=subject_noise, reflex=reflex)
        # fail now, not at the first step
        self.spasticity.bind(host.model, getattr(host, "dt", None))
        host.add_ctrl_stage(STAGE_NAME, self.spasticity.apply, self.spasticity.reset, order=order)

    def __getstate__(self) -> dict[str, Any]:
        return {"env": self.env, "kwargs": dict(self._kwargs)}

    def __setstate__(self, state: dict[str, Any]) -> None:
        SpasticityWrapper.__init__(self, state["env"], **state["kwargs"])
