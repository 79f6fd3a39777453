"""What the twin does not know: per-episode perturbations of its uncertain parts.

A real exoskeleton on a real leg differs from the nominal twin in ways no measurement pins
down: how tight the straps are, segment masses, the slider's friction, the motor's torque
constant, and its sensors are noisy and late. :class:`RobustnessParams` gives each a range;
with ``make_env(level, robustness=RobustnessParams())`` (or ``robustness=True``) the env
draws a new twin at every reset, from a generator seeded by the reset seed (so the same seed
gives the same perturbed twin and the subject/start angle are those of the nominal env):

=============================  ==============================  ===============================
part                           default range                   applied to
=============================  ==============================  ===============================
strap stiffness                x0.5-2 (log-uniform)            the five coupling joints'
                                                               springs (and, above x1, their
                                                               armature by scale^2, see
                                                               below); the shank weld's
                                                               stiffness
strap damping                  x0.5-2 (log-uniform)            the coupling joints' damping;
                                                               the weld's damping
segment masses and inertias    +-10 % (uniform, per body)      every body with mass
slide friction                 +-50 % (uniform)                the thigh slider's frictionloss
motor torque constant          +-5 % (uniform)                 the exo motor's gain and
                                                               torque limit
sensor noise                   Gaussian, std per observation   the observation vector and
                               key (:data:`DEFAULT_NOISE_STD`)  ``info["measured_*"]``
sensor latency                 10 ms                           the same (whole control steps)
=============================  ==============================  ===============================

Numerical stability of the stiff draws. The twin runs MuJoCo's semi-implicit Euler at 2 ms,
which integrates joint damping implicitly but joint springs explicitly. Two rules keep every
draw in these ranges as stable as the nominal twin (``tests/test_stability.py``):

* The weld is scaled in MuJoCo's own terms. A ``solref = (timeconst, dampratio)`` row has the
  reference stiffness ``1 / (dmax timeconst dampratio)^2`` and damping ``2 / (dmax
  timeconst)``: stiffness x k and damping x c are ``(timeconst / c, dampratio x c /
  sqrt(k))``. Where ``timeconst / c`` would fall under MuJoCo's 2-timestep floor (c > 1.25 at
  the nominal 5 ms and 2 ms) the same stiffness and damping are written in the direct form
  ``(-stiffness, -damping)``, which MuJoCo does not floor; the damping range is checked
  against the weld's explicit limit (:data:`MAX_WELD_HB`). A mass-spring-damper reading of
  ``solref``, ``(timeconst / sqrt(k), dampratio x c / sqrt(k))``, would stiffen the weld by
  ``k^2 / c^2`` (x12.5 at k = 2, c = 0.5) and leave its damping independent of c.
* A stiffer strap (k > 1) raises the coupling joints' armature (their numerical rotor
  inertia) by ``k^2``. The shank cuff pin carries 2000 Nm/rad on 4.5e-3 kg m^2 (the 0.2 kg
  cuff about the pin, 4e-3 of it armature, ``TwinParams.pin_armature_kg_m2``): ``omega h``
  = 1.3, under the explicit limit 2, and with the ``k^2`` scaling it falls to 1.0 at x2;
  an armature x k (which keeps ``sqrt(stiffness / armature)``) would leave a bang-bang
  command at the 50 Hz control rate driving the pins 3-4 times faster than on the nominal
  twin. The other couplings are slow (``omega h`` < 0.5 at x2).

What is *measured* (the observation and the sensor record a controller reads,
:mod:`myoexo.envs.sensors`, made from ``info["measured_*"]``) is noisy and late; what is
*scored* (``info["knee_angle_deg"]``, the interaction torque, the reward) stays the true state.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from myoexo.model import COUPLING_JOINTS, EXO_ACTUATOR, STRAP_EQUALITY

#: Default sensor noise: observation key -> standard deviation in the key's physical unit.
#: Encoders 0.1 deg / 0.01 rad/s (a 14-bit encoder and a filtered derivative), motor torque
#: 1 Nm (current-based estimate), cuff sensors 1 N / 0.1 Nm, muscle states 1 % of their
#: normalized range (simulation-only keys). Keys not listed are exact (target, command,
#: time).
DEFAULT_NOISE_STD: dict[str, float] = {
    "knee_angle_rad": math.radians(0.1),
    "knee_vel_rad_s": 0.01,
    "exo_angle_rad": math.radians(0.1),
    "exo_vel_rad_s": 0.01,
    "error_rad": math.radians(0.1),
    "exo_torque_nm": 1.0,
    "muscle_knee_torque_nm": 1.0,
    "thigh_cuff_force_n": 1.0,
    "thigh_cuff_torque_nm": 0.1,
    "shank_cuff_force_n": 1.0,
    "shank_cuff_torque_nm": 0.1,
    "coupling_qpos": 1e-4,
    "coupling_qvel": 1e-3,
    "spastic_act": 0.01,
    "spastic_force": 0.01,
    "spastic_length": 0.01,
    "spastic_velocity": 0.01,
}


#: Largest accepted ``timestep x damping`` of the strap weld's reference (explicit limit 2),
#: see :meth:`TwinPerturbation._check_weld_damping`.
MAX_WELD_HB = 1.8


@dataclass(frozen=True)
class RobustnessParams:
    """Ranges of the twin's uncertain parts (defaults: the ranges of the module docstring).

    Attributes:
        strap_stiffness_scale: (low, high) of the strap stiffness factor, log-uniform.
        strap_damping_scale: (low, high) of the strap damping factor, log-uniform.
        mass_rel: Half-width of the uniform relative change of each body's mass and inertia.
        slide_friction_rel: Half-width of the uniform relative change of the slide friction.
        motor_gain_rel: Half-width of the uniform relative change of the motor torque constant.
        latency_s: Sensor latency (s), a whole number of control periods (0: none).
        noise_std: ``(obs key, std in its physical unit)`` pairs (empty: no noise).
    """

    strap_stiffness_scale: tuple[float, float] = (0.5, 2.0)
    strap_damping_scale: tuple[float, float] = (0.5, 2.0)
    mass_rel: float = 0.10
    slide_friction_rel: float = 0.50
    motor_gain_rel: float = 0.05
    latency_s: float = 0.010
    noise_std: tuple[tuple[str, float], ...] = field(
        default_factory=lambda: tuple(DEFAULT_NOISE_STD.items())
    )

    def __post_init__(self) -> None:
        for name in ("strap_stiffness_scale", "strap_damping_scale"):
            lo, hi = (float(v) for v in getattr(self, name))
            if not (0.0 < lo <= hi < 1e3):
                raise ValueError(f"{name} = {(lo, hi)} must satisfy 0 < low <= high < 1000")
            object.__setattr__(self, name, (lo, hi))
        for name in ("mass_rel", "slide_friction_rel", "motor_gain_rel"):
            v = float(getattr(self, name))
            if not (0.0 <= v < 1.0):
                raise ValueError(f"{name} = {v!r} is outside the accepted range [0, 1)")
        if not (math.isfinite(self.latency_s) and 0.0 <= self.latency_s <= 1.0):
            raise ValueError(f"latency_s = {self.latency_s!r} is outside [0, 1] s")
        pairs = tuple((str(k), float(v)) for k, v in dict(self.noise_std).items())
        bad = [(k, v) for k, v in pairs if not (math.isfinite(v) and v >= 0.0)]
        if bad:
            raise ValueError(f"noise_std has negative or non-finite values {bad}")
        object.__setattr__(self, "noise_std", pairs)

    @classmethod
    def nominal(cls) -> RobustnessParams:
        """No perturbation at all (every range collapsed; for tests)."""
        return cls((1.0, 1.0), (1.0, 1.0), 0.0, 0.0, 0.0, 0.0, ())


def robustness_params(robustness: RobustnessParams | bool | None) -> RobustnessParams | None:
    """The env's ``robustness=`` argument as parameters: ``True`` -> the default ranges,
    ``False``/``None`` -> ``None`` (the nominal twin, exact sensors).

    Raises:
        ValueError: If it is anything else.
    """
    if robustness is True:
        return RobustnessParams()
    if robustness is False or robustness is None:
        return None
    if not isinstance(robustness, RobustnessParams):
        raise ValueError(
            f"robustness = {robustness!r}: expected a RobustnessParams, True, False or None"
        )
    return robustness


def twin_perturbation(
    model: mujoco.MjModel, params: RobustnessParams, coupling_joints: tuple[str, ...]
) -> TwinPerturbation:
    """The :class:`TwinPerturbation` of the MyoExoKnee twin: its coupling joints, the thigh
    slider (the first coupling joint), the shank strap weld if the model has one, the exo
    motor."""
    has_weld = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_EQUALITY, STRAP_EQUALITY) >= 0
    return TwinPerturbation(
        model,
        params,
        coupling_joints,
        COUPLING_JOINTS[0],
        STRAP_EQUALITY if has_weld else None,
        EXO_ACTUATOR,
    )


class TwinPerturbation:
    """Draws and applies :class:`RobustnessParams` to one env's model at every reset.

    The nominal values are copied once; :meth:`apply` restores them and scales them anew,
    so perturbations never accumulate.

    Args:
        model: The env's ``MjModel`` (modified in place).
        params: The ranges.
        coupling_joints: Names of the strap coupling joints.
        slide_joint: Name of the thigh slider.
        strap_equality: Name of the shank strap weld (``None``: no weld).
        motor: Name of the exo motor actuator.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        params: RobustnessParams,
        coupling_joints: tuple[str, ...],
        slide_joint: str,
        strap_equality: str | None,
        motor: str,
    ) -> None:
        self.model = model
        self.params = params
        jids = np.array([model.joint(n).id for n in coupling_joints], dtype=np.intp)
        self._jids = jids
        self._dofs = model.jnt_dofadr[jids].astype(np.intp)
        self._slide_dof = int(model.jnt_dofadr[model.joint(slide_joint).id])
        self._eq = None if strap_equality is None else int(model.equality(strap_equality).id)
        self._motor = int(model.actuator(motor).id)
        self._bodies = np.flatnonzero(model.body_mass > 0.0)
        self._min_tc_s = 2.0 * float(model.opt.timestep)
        if self._eq is not None:
            self._check_weld_damping(model, params.strap_damping_scale[1])
        self._nominal = {
            "jnt_stiffness": model.jnt_stiffness[jids].copy(),
            "dof_damping": model.dof_damping[self._dofs].copy(),
            "frictionloss": float(model.dof_frictionloss[self._slide_dof]),
            "body_mass": model.body_mass.copy(),
            "body_inertia": model.body_inertia.copy(),
            "gain": float(model.actuator_gainprm[self._motor, 0]),
            "forcerange": model.actuator_forcerange[self._motor].copy(),
            "dof_armature": model.dof_armature[self._dofs].copy(),
            "eq_solref": None if self._eq is None else model.eq_solref[self._eq].copy(),
        }

    def apply(self, rng: np.random.Generator) -> dict[str, Any]:
        """Draw a twin and write it into the model; returns the drawn factors."""
        p, m, nom = self.params, self.model, self._nominal

        def log_uniform(bounds: tuple[float, float]) -> float:
            lo, hi = bounds
            return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))

        k = log_uniform(p.strap_stiffness_scale)
        c = log_uniform(p.strap_damping_scale)
        mass = 1.0 + rng.uniform(-p.mass_rel, p.mass_rel, size=self._bodies.size)
        friction = 1.0 + float(rng.uniform(-p.slide_friction_rel, p.slide_friction_rel))
        gain = 1.0 + float(rng.uniform(-p.motor_gain_rel, p.motor_gain_rel))

        m.jnt_stiffness[self._jids] = nom["jnt_stiffness"] * k
        m.dof_damping[self._dofs] = nom["dof_damping"] * c
        # a stiffer strap never speeds the shank pin up past the nominal (module docstring)
        m.dof_armature[self._dofs] = nom["dof_armature"] * max(k, 1.0) ** 2
        m.dof_frictionloss[self._slide_dof] = nom["frictionloss"] * friction
        m.body_mass[:] = nom["body_mass"]
        m.body_inertia[:] = nom["body_inertia"]
        m.body_mass[self._bodies] *= mass
        m.body_inertia[self._bodies] *= mass[:, None]
        m.actuator_gainprm[self._motor, 0] = nom["gain"] * gain
        m.actuator_forcerange[self._motor] = nom["forcerange"] * gain
        if self._eq is not None:
            m.eq_solref[self._eq] = self.weld_solref(k, c)
        return {
            "strap_stiffness_scale": k,
            "strap_damping_scale": c,
            "mass_scale_mean": float(mass.mean()) if mass.size else 1.0,
            "slide_friction_scale": friction,
            "motor_gain_scale": gain,
        }

    def _check_weld_damping(self, model: mujoco.MjModel, c_max: float) -> None:
        """Raise ``ValueError`` if the weld's damping at x ``c_max`` is past its explicit limit.

        MuJoCo evaluates a constraint's reference damping ``B`` at the step's start: the weld
        diverges as ``h B`` nears 2 (at the nominal 5 ms / 2 ms, ``h B`` = 0.81 x the damping
        scale; x2.45 diverged at x2 stiffness, x2.3 did not). Accepted: ``h B <= MAX_WELD_HB``.
        """
        tc, ratio = (float(v) for v in model.eq_solref[self._eq])
        dmax = float(model.eq_solimp[self._eq, 1])
        b_nom = -ratio / dmax if tc <= 0.0 else 2.0 / (dmax * max(tc, self._min_tc_s))
        hb = float(model.opt.timestep) * b_nom * c_max
        if hb > MAX_WELD_HB:
            raise ValueError(
                f"strap_damping_scale up to x{c_max:g} gives the strap weld h*B = {hb:.2f} > "
                f"{MAX_WELD_HB} (explicit limit 2): at most "
                f"x{MAX_WELD_HB / (hb / c_max):.2f} with this timestep and strap solref"
            )

    def weld_solref(self, k: float, c: float) -> tuple[float, float]:
        """The strap weld's ``solref`` for stiffness x ``k`` and damping x ``c``.

        MuJoCo's reference stiffness is ``1 / (dmax timeconst dampratio)^2`` and its damping
        ``2 / (dmax timeconst)`` (``dmax`` of ``solimp``), ``timeconst`` floored at 2
        timesteps; the direct form ``(-stiffness, -damping)`` is scaled as it is.
        """
        tc, ratio = (float(v) for v in self._nominal["eq_solref"])
        if tc <= 0.0:  # direct (-stiffness, -damping)
            return tc * k, ratio * c
        tc_nom = max(tc, self._min_tc_s)  # the time constant MuJoCo uses for the nominal weld
        if tc_nom / c >= self._min_tc_s:
            return tc_nom / c, ratio * c / math.sqrt(k)
        # past the floor: the same stiffness and damping in the direct form (not floored)
        return -k / (tc_nom * ratio) ** 2, -2.0 * c / tc_nom


class SensorModel:
    """Noise and latency of what the controller reads.

    Works on the env's raw observation buffer (physical units): :meth:`measure` adds the
    noise and returns the buffer of ``delay_steps`` control steps earlier (the reset's
    buffer until then).

    Args:
        std_raw: Noise standard deviation of each raw entry (0: exact).
        delay_steps: Latency in control steps.
    """

    @classmethod
    def with_latency(
        cls, std_raw: np.ndarray, latency_s: float, control_period_s: float
    ) -> SensorModel:
        """A sensor model whose latency is *latency_s* (a whole number of control periods).

        Raises:
            ValueError: If the latency is not a whole number of control periods.
        """
        steps = latency_s / control_period_s
        if abs(steps - round(steps)) > 1e-6:
            raise ValueError(
                f"robustness.latency_s = {latency_s} s must be a whole number of "
                f"control periods ({control_period_s} s)"
            )
        return cls(std_raw, round(steps))

    def __init__(self, std_raw: np.ndarray, delay_steps: int) -> None:
        self.std_raw = np.asarray(std_raw, dtype=np.float64)
        self._noisy = np.flatnonzero(self.std_raw > 0.0)
        self._std = self.std_raw[self._noisy]
        self.delay_steps = int(delay_steps)
        self._buffer: list[np.ndarray] = []

    def _noise(self, raw: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        out = raw.copy()
        if self._noisy.size:
            out[self._noisy] += self._std * rng.standard_normal(self._noisy.size)
        return out

    def reset(self, raw: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Start of an episode: the delay line holds the reset's (noisy) reading."""
        first = self._noise(raw, rng)
        self._buffer = [first] * self.delay_steps
        return first

    def measure(self, raw: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """This step's reading: noisy, ``delay_steps`` control steps old."""
        self._buffer.append(self._noise(raw, rng))
        return self._buffer.pop(0)
