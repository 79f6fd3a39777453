"""The passive knee: Riener and Edrich's measured elastic moment and a viscous damper.

A healthy relaxed knee resists motion through its muscles' and tendons' passive stretch, its
ligaments and its capsule. Riener and Edrich (1999) measured the total passive elastic knee
moment on healthy adults at many hip, knee and ankle angles and fitted one closed form
(:data:`RIENER_EDRICH_1999`; angles in degrees, hip and knee flexion positive, the moment
flexing positive)::

    M = exp(c1 + a1 A + k1 K + h1 H) - exp(c2 + a2 A + k2 K + h2 H) + c0 + exp(c3 + k3 K)

The first term is the knee flexors' stretch (the hamstrings lengthen as the hip flexes and
the knee extends), the second the extensors' (rectus femoris lengthens as the hip extends
and the knee flexes), the last the structures that stop hyperextension.

The twin (``TwinParams.passive_knee = "riener_edrich"``) takes the knee's passive moment from
that fit, not from its muscles' passive fibres, whose sum at hip 90 deg is 6-11 Nm
stiffer than the measurement over knee 20-60 deg and at hip 40 deg 2-4 Nm too weak in
extension beyond knee 40 deg:

* the knee-crossing muscles (:data:`KNEE_MUSCLES`) lose their passive force (MuJoCo's
  ``fpmax``, ``biasprm[7]``, set to 1e-6: it must be positive); their active force and
  fibre state are unchanged. The gastrocnemii thereby lose their passive share at the ankle
  too, which the free ankle's other muscles (soleus, tibialis, peronei) keep;
* the moment is built into the model as springs, which MuJoCo evaluates in every substep at
  no cost to Python: a cubic spring on ``knee_angle_r`` and two one-sided cubic springs, fixed
  tendons on the knee angle whose dead band is ``(-inf, knot_low]`` and ``[knot_high, inf)``.
  Their nine coefficients are the least-squares fit of the moment at the locked hip
  (:func:`knee_springs`, about 0.05 Nm RMS over 0-120 deg of knee flexion);
* the knee is damped at ``TwinParams.knee_damping_nm_s_rad`` and its dependent coordinates
  (Rajagopal's tibia translations and rotations, the patella) are not damped, so the flexion
  sees exactly that damping (MyoSuite damps every coordinate at 0.5 Nm s/rad, an effective
  0.97 Nm s/rad along the flexion).

The hip is locked in the twin, so ``H`` is the twin's ``hip_flexion_deg``; the ankle is free
and ``A`` is taken at its neutral 0 deg, where the ankle's share of the moment is read.
"""

from __future__ import annotations

import copy
import functools
import math
from dataclasses import dataclass

import mujoco
import numpy as np

__all__ = [
    "KNEE_MUSCLES",
    "KNEE_SPRING_TENDONS",
    "RIENER_EDRICH_1999",
    "KneeSprings",
    "PassiveKneeScaler",
    "PassiveMomentFit",
    "install_passive_knee",
    "knee_springs",
    "scale_passive_knee",
]

#: The muscles with a knee moment arm in the seated leg (checked against the model's moment
#: arms in the tests).
KNEE_MUSCLES: tuple[str, ...] = (
    "bflh_r",
    "bfsh_r",
    "gaslat_r",
    "gasmed_r",
    "grac_r",
    "recfem_r",
    "sart_r",
    "semimem_r",
    "semiten_r",
    "tfl_r",
    "vasint_r",
    "vaslat_r",
    "vasmed_r",
)

#: The knee's dependent coordinates (tied to the flexion by polynomial joint equalities).
_DEPENDENT_KNEE_JOINTS: tuple[str, ...] = (
    "knee_angle_translation2_r",
    "knee_angle_translation1_r",
    "knee_angle_rotation2_r",
    "knee_angle_rotation3_r",
    "knee_angle_beta_translation2_r",
    "knee_angle_beta_translation1_r",
    "knee_angle_beta_rotation1_r",
)


@dataclass(frozen=True)
class PassiveMomentFit:
    """Coefficients of a double-exponential passive joint moment (Riener and Edrich's form).

    ``M = exp(c1 + a1 A + k1 K + h1 H) - exp(c2 + a2 A + k2 K + h2 H) + c0 + exp(c3 + k3 K)``
    in Nm, angles ``A`` (ankle), ``K`` (knee), ``H`` (hip) in degrees.

    Attributes:
        source: The measurement the coefficients come from.
    """

    c1: float
    a1: float
    k1: float
    h1: float
    c2: float
    a2: float
    k2: float
    h2: float
    c0: float
    c3: float
    k3: float
    source: str

    def moment_nm(
        self, knee_deg: np.ndarray | float, hip_deg: float, ankle_deg: float = 0.0
    ) -> np.ndarray:
        """The passive knee moment (Nm, flexing positive) at the given angles (deg)."""
        knee = np.asarray(knee_deg, dtype=float)
        return (
            np.exp(self.c1 + self.a1 * ankle_deg + self.k1 * knee + self.h1 * hip_deg)
            - np.exp(self.c2 + self.a2 * ankle_deg + self.k2 * knee + self.h2 * hip_deg)
            + self.c0
            + np.exp(self.c3 + self.k3 * knee)
        )


#: Riener R, Edrich T (1999) Identification of passive elastic joint moments in the lower
#: extremities. J Biomech 32:539-544: the knee moment of their healthy adults.
RIENER_EDRICH_1999 = PassiveMomentFit(
    c1=1.800,
    a1=-0.0460,
    k1=-0.0352,
    h1=0.0217,
    c2=-3.971,
    a2=-0.0004,
    k2=0.0495,
    h2=-0.0128,
    c0=-4.820,
    c3=2.220,
    k3=-0.150,
    source="Riener and Edrich 1999, J Biomech 32:539-544 (healthy adults)",
)


@dataclass(frozen=True)
class KneeSprings:
    """The MuJoCo springs that carry a passive knee moment at one hip angle.

    Torque on the knee flexion (Nm, flexing positive), ``x`` the knee angle (rad)::

        -(p1 d + p2 d^2 + p3 d^3),       d = x - springref_rad           (joint spring)
        -(l1 e + l2 e^2 + l3 e^3),       e = min(x - knot_low_rad, 0)    (tendon, low side)
        -(u1 e + u2 e^2 + u3 e^3),       e = max(x - knot_high_rad, 0)   (tendon, high side)

    Attributes:
        springref_rad: The joint spring's reference angle.
        knot_low_rad, knot_high_rad: Where the one-sided springs start.
        joint, low, high: Each spring's (linear, quadratic, cubic) coefficients (Nm/rad^n).
        rms_error_nm, max_error_nm: The fit's error against the moment it fits, over the
            knee's 0-120 deg.
    """

    springref_rad: float
    knot_low_rad: float
    knot_high_rad: float
    joint: tuple[float, float, float]
    low: tuple[float, float, float]
    high: tuple[float, float, float]
    rms_error_nm: float
    max_error_nm: float

    def moment_nm(self, knee_deg: np.ndarray | float) -> np.ndarray:
        """The springs' torque (Nm, flexing positive) at knee angles (deg)."""
        x = np.radians(np.asarray(knee_deg, dtype=float))
        return -(
            _cubic(self.joint, x - self.springref_rad)
            + _cubic(self.low, np.minimum(x - self.knot_low_rad, 0.0))
            + _cubic(self.high, np.maximum(x - self.knot_high_rad, 0.0))
        )


def _cubic(coef: tuple[float, float, float], d: np.ndarray) -> np.ndarray:
    return coef[0] * d + coef[1] * d * d + coef[2] * d * d * d


#: Knee range (deg) the springs are fitted over (the model knee's range), its sampling, the
#: one-sided springs' knots (deg) and the candidate reference angles of the joint spring.
_FIT_RANGE_DEG = (0.0, 120.0)
_FIT_SAMPLES = 241
_KNOTS_DEG = (22.5, 60.0)
_SPRINGREF_CANDIDATES_DEG = np.arange(-60.0, 205.0, 5.0)


@functools.lru_cache(maxsize=16)
def knee_springs(
    hip_deg: float, fit: PassiveMomentFit = RIENER_EDRICH_1999, ankle_deg: float = 0.0
) -> KneeSprings:
    """Fit the knee springs to *fit*'s moment at the hip angle *hip_deg* (linear least
    squares for each candidate reference angle; the best one is kept). Cached: a twin's build
    fits them for its leg alone (the knee axis) and for the coupled twin."""
    knee_deg = np.linspace(*_FIT_RANGE_DEG, _FIT_SAMPLES)
    x = np.radians(knee_deg)
    target = fit.moment_nm(knee_deg, hip_deg, ankle_deg)
    lo, hi = (math.radians(v) for v in _KNOTS_DEG)
    e_lo, e_hi = np.minimum(x - lo, 0.0), np.maximum(x - hi, 0.0)
    best: tuple[float, float, np.ndarray, np.ndarray] | None = None
    for ref_deg in _SPRINGREF_CANDIDATES_DEG:
        d = x - math.radians(ref_deg)
        basis = -np.column_stack([d, d * d, d**3, e_lo, e_lo**2, e_lo**3, e_hi, e_hi**2, e_hi**3])
        coef, *_ = np.linalg.lstsq(basis, target, rcond=None)
        residual = basis @ coef - target
        rms = float(np.sqrt(np.mean(residual**2)))
        if best is None or rms < best[0]:
            best = (rms, math.radians(ref_deg), coef, residual)
    assert best is not None
    rms, ref, coef, residual = best
    c = [float(v) for v in coef]
    return KneeSprings(
        springref_rad=ref,
        knot_low_rad=lo,
        knot_high_rad=hi,
        joint=(c[0], c[1], c[2]),
        low=(c[3], c[4], c[5]),
        high=(c[6], c[7], c[8]),
        rms_error_nm=rms,
        max_error_nm=float(np.abs(residual).max()),
    )


#: The knee muscles' ``fpmax`` (peak passive force over peak active force): MuJoCo requires
#: it > 0 (and its XML writer keeps 1e-6), and 1e-6 of a 5 kN muscle is 5 mN.
_NO_PASSIVE_FPMAX = 1e-6
#: Names of the two one-sided spring tendons.
KNEE_SPRING_TENDONS: tuple[str, str] = ("knee_passive_low", "knee_passive_high")
#: A tendon length far outside the knee's range: the open end of a one-sided dead band.
_FAR_RAD = 100.0


def install_passive_knee(
    spec: mujoco.MjSpec, *, knee_joint: str, hip_deg: float, damping_nm_s_rad: float
) -> KneeSprings:
    """Give the seated leg's knee Riener and Edrich's passive moment and the damping
    *damping_nm_s_rad* (see the module docstring); edits *spec* in place.

    Returns:
        The springs installed.
    """
    springs = knee_springs(hip_deg)
    for name in KNEE_MUSCLES:
        actuator = spec.actuator(name)
        for field in ("gainprm", "biasprm"):  # MJCF writes a muscle's fpmax from gainprm
            prm = np.array(getattr(actuator, field), dtype=float)
            prm[7] = _NO_PASSIVE_FPMAX
            setattr(actuator, field, prm)
    knee = spec.joint(knee_joint)
    knee.springref = springs.springref_rad
    knee.stiffness = np.array(springs.joint)
    knee.damping = np.array([damping_nm_s_rad, 0.0, 0.0])
    for name in _DEPENDENT_KNEE_JOINTS:
        spec.joint(name).damping = np.zeros(3)
    deadbands = ((springs.knot_low_rad, _FAR_RAD), (-_FAR_RAD, springs.knot_high_rad))
    for name, coef, band in zip(
        KNEE_SPRING_TENDONS, (springs.low, springs.high), deadbands, strict=True
    ):
        tendon = spec.add_tendon()
        tendon.name = name
        tendon.stiffness = np.array(coef)
        tendon.springlength = np.array(band)
        tendon.wrap_joint(knee_joint, 1.0)
    return springs


class PassiveKneeScaler:
    """Scales one built twin's passive knee in place: every coefficient of the knee springs
    (the joint's cubic spring and the two one-sided spring tendons) times a stiffness scale,
    the knee's damping times a damping scale.

    The nominal coefficients are copied once; :meth:`apply` writes nominal x scale, so
    scalings never accumulate. A personal twin (:mod:`myoexo.spasticity.personal`) scales
    its passive knee this way at every reset.

    Args:
        model: A twin built with the passive knee (:func:`install_passive_knee`), modified
            in place by :meth:`apply`. The knee is the joint its spring tendons wrap.
    """

    def __init__(self, model: mujoco.MjModel) -> None:
        self.model = model
        self._tendons = np.array([model.tendon(n).id for n in KNEE_SPRING_TENDONS], dtype=np.intp)
        self._joint = int(model.wrap_objid[model.tendon_adr[self._tendons[0]]])
        self._dof = int(model.jnt_dofadr[self._joint])
        self._nominal = {
            "jnt_stiffness": float(model.jnt_stiffness[self._joint]),
            "jnt_stiffnesspoly": model.jnt_stiffnesspoly[self._joint].copy(),
            "tendon_stiffness": model.tendon_stiffness[self._tendons].copy(),
            "tendon_stiffnesspoly": model.tendon_stiffnesspoly[self._tendons].copy(),
            "dof_damping": float(model.dof_damping[self._dof]),
            "dof_dampingpoly": model.dof_dampingpoly[self._dof].copy(),
        }

    def apply(self, stiffness_scale: float, damping_scale: float) -> None:
        """Write the nominal passive knee times the scales into the model.

        Raises:
            ValueError: If a scale is not a finite number > 0.
        """
        for name, value in (("stiffness_scale", stiffness_scale), ("damping_scale", damping_scale)):
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"{name} = {value!r} must be a finite number > 0")
        m, nom, j, t, dof = self.model, self._nominal, self._joint, self._tendons, self._dof
        m.jnt_stiffness[j] = nom["jnt_stiffness"] * stiffness_scale
        m.jnt_stiffnesspoly[j] = nom["jnt_stiffnesspoly"] * stiffness_scale
        m.tendon_stiffness[t] = nom["tendon_stiffness"] * stiffness_scale
        m.tendon_stiffnesspoly[t] = nom["tendon_stiffnesspoly"] * stiffness_scale
        m.dof_damping[dof] = nom["dof_damping"] * damping_scale
        m.dof_dampingpoly[dof] = nom["dof_dampingpoly"] * damping_scale


def scale_passive_knee(
    model: mujoco.MjModel, stiffness_scale: float, damping_scale: float
) -> mujoco.MjModel:
    """A copy of the twin *model* whose passive knee is scaled (:class:`PassiveKneeScaler`)."""
    m = copy.copy(model)
    PassiveKneeScaler(m).apply(stiffness_scale, damping_scale)
    return m
