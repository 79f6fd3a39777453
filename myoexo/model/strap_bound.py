"""What the straps can physically pass on: the bound of the strap torque and of the
misalignment between the exo hinge and the human knee.

The strap torque on the knee (the interaction torque) is the torque the shank strap passes
from the lower exo to the shank. Newton's law for the lower exo (its shank link and shank
cuff, inertia ``I_exo`` about the hinge, the drive's armature included) and for the shank
and foot (inertia ``I_knee`` about the knee), moving together through a strap that does not
ring (the pins' damping, :class:`~myoexo.model.params.TwinParams`), shares every torque
between the two segments in proportion to their inertia::

    |tau_strap| <= tau_motor * I_knee / (I_exo + I_knee)
                 + tau_human * I_exo / (I_exo + I_knee)
                 + m_exo g r_exo
                 + (S(zeta) - 1) * 2 tau_motor * I_knee / (I_exo + I_knee)

where ``tau_motor`` is the motor's limit, ``tau_human`` the largest torque the leg's own
muscles can put on the knee (every muscle crossing the knee fully active, flexors or
extensors, at the knee angle where they are strongest: far more than a spastic reflex
drives) and ``m_exo g r_exo`` the lower exo's weight about the hinge. The last term is the
strap's own dynamics: the strap is a spring and damper (the two cuff pins in series) between
the lower exo and the shank, so a step of the motor torque reaches the shank with an
overshoot ``S(zeta)``, the peak of the force a Kelvin-Voigt element passes on when a step
force pushes a mass through it (``zeta`` its damping ratio against ``I_exo``; ``S`` is 1.83
at zeta 0.06, 1.15 at 0.9 and 1.05 at 2), and the largest step is a full reversal of the
motor, ``2 tau_motor``. No controller can make the strap pass more than that while the exo
moves inside its range: the motor cannot push harder, the leg's torques reach the exo only
in the share of the exo's inertia, and the strap rings no more than its damping allows.

The bound assumes the shank is never stopped by the exo's own end stop
(``exo_knee_range_deg``): there the stop halts the lower exo and the strap must stop the
shank's momentum, a torque of about ``omega * sqrt(k_strap * I_knee)`` at knee speed
``omega``, scaled by the strap's damping (``impact_torque_nm``), 300-400 Nm at the 13 rad/s a
bang-bang command reaches. The drive's end-stop protection (:mod:`myoexo.model.drive`)
brakes before the flexion stop, the one inside the knee's range, so that no command reaches
it faster than the contact speed; the knee's own limit comes before the extension stop.

The misalignment (knee angle minus exo hinge angle, ``info["misalignment_deg"]``) is bounded
by the coupling's design: each sagittal cuff pin absorbs misalignment within its range
(``thigh_pin_range_deg``, ``shank_pin_range_deg``: +-15 deg), so a misalignment beyond one
pin's range means the coupling has left what it was built to absorb
(:attr:`StrapBound.misalignment_deg`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from myoexo.model.exo import EXO_ACTUATOR, EXO_JOINT
from myoexo.model.joint_torque import CoupledJointTorque, joint_inertia
from myoexo.model.leg import KNEE_JOINT
from myoexo.model.posing import pose_twin

__all__ = [
    "StrapBound",
    "kelvin_voigt_impact_peak",
    "kelvin_voigt_step_peak",
    "strap_bound",
]

#: The cuff pins that carry the strap's rotation about the knee, in series.
SAGITTAL_PINS = ("exo_thigh_pin", "exo_shank_pin")

#: Knee angles (deg) over which the leg's strongest knee torque is searched.
_KNEE_ANGLES_DEG = tuple(range(0, 100, 5))

#: Standard gravity, m/s^2.
_G_M_S2 = 9.81


@dataclass(frozen=True)
class StrapBound:
    """The strap-torque bound of one twin and its parts (module docstring).

    Attributes:
        motor_limit_nm: The motor's peak torque.
        exo_inertia_kg_m2: Lower exo (shank link, shank cuff, drive armature) about the hinge.
        knee_inertia_kg_m2: Shank and foot about the knee, along its coupled motion.
        human_torque_nm: The largest knee torque of the leg's muscles, all fully active.
        exo_weight_nm: The lower exo's largest weight moment about the hinge.
        pin_stiffness_nm_rad: Stiffness of the two sagittal cuff pins in series (the strap's
            rotational stiffness about the knee).
        pin_damping_nm_s_rad: Damping of the two sagittal cuff pins in series.
        misalignment_deg: The misalignment bound: one cuff pin's range.
    """

    motor_limit_nm: float
    exo_inertia_kg_m2: float
    knee_inertia_kg_m2: float
    human_torque_nm: float
    exo_weight_nm: float
    pin_stiffness_nm_rad: float
    pin_damping_nm_s_rad: float
    misalignment_deg: float

    @property
    def exo_share(self) -> float:
        """``I_exo / (I_exo + I_knee)``: the share of a torque the strap passes from the
        segment it acts on to the other."""
        return self.exo_inertia_kg_m2 / (self.exo_inertia_kg_m2 + self.knee_inertia_kg_m2)

    @property
    def damping_ratio(self) -> float:
        """The strap's damping ratio against the lower exo's inertia."""
        return self.pin_damping_nm_s_rad / (
            2.0 * math.sqrt(self.pin_stiffness_nm_rad * self.exo_inertia_kg_m2)
        )

    @property
    def step_overshoot(self) -> float:
        """``S(zeta)``: the peak ratio of passed-on to applied force after a force step."""
        return kelvin_voigt_step_peak(self.damping_ratio)

    @property
    def torque_nm(self) -> float:
        """The bound of ``|strap torque|`` while the exo moves inside its range, Nm."""
        motor_share_nm = self.motor_limit_nm * (1.0 - self.exo_share)
        return (
            motor_share_nm
            + self.human_torque_nm * self.exo_share
            + self.exo_weight_nm
            + (self.step_overshoot - 1.0) * 2.0 * motor_share_nm
        )

    def impact_torque_nm(self, knee_speed_rad_s: float) -> float:
        """The strap torque that stops a shank moving at *knee_speed_rad_s* against the exo's
        end stop through the strap's stiffness and damping, Nm (added to :attr:`torque_nm`):
        ``omega sqrt(k I_knee)`` times the peak of a Kelvin-Voigt element's response to the
        shank's impact at its damping ratio against ``I_knee``."""
        k, inertia = self.pin_stiffness_nm_rad, self.knee_inertia_kg_m2
        zeta = self.pin_damping_nm_s_rad / (2.0 * math.sqrt(k * inertia))
        return abs(knee_speed_rad_s) * math.sqrt(k * inertia) * kelvin_voigt_impact_peak(zeta)


def _kelvin_voigt_peak(
    damping_ratio: float, force: float, speed: float, periods: float = 6.0, steps: int = 6000
) -> float:
    """The peak of ``k x + c v`` of a unit mass on a spring ``k = 1`` and a damper
    ``c = 2 zeta`` in parallel, from ``x = 0``, ``v = speed``, pushed by a constant *force*
    (exact discretisation of the linear ODE over *periods* undamped periods)."""
    from scipy.linalg import expm

    if not (math.isfinite(damping_ratio) and damping_ratio >= 0.0):
        raise ValueError(f"damping_ratio = {damping_ratio!r} must be a finite value >= 0")
    a = np.array([[0.0, 1.0], [-1.0, -2.0 * damping_ratio]])
    dt = periods * 2.0 * math.pi / steps
    phi = expm(a * dt)
    gamma = np.linalg.solve(a, (phi - np.eye(2)) @ np.array([0.0, force]))
    state = np.array([0.0, speed])
    peak = 2.0 * damping_ratio * speed
    for _ in range(steps):
        state = phi @ state + gamma
        peak = max(peak, float(state[0] + 2.0 * damping_ratio * state[1]))
    return peak


def kelvin_voigt_step_peak(damping_ratio: float) -> float:
    """The peak force a spring and a damper in parallel pass on when a unit step force pushes
    a mass through them from rest, per unit of the step: how much of a force step a damped
    strap passes on at its worst (2 undamped, falling towards 1 with damping)."""
    return _kelvin_voigt_peak(damping_ratio, force=1.0, speed=0.0)


def kelvin_voigt_impact_peak(damping_ratio: float) -> float:
    """The peak force a spring ``k`` and a damper in parallel pass on when a mass ``m`` hits
    them at speed ``v``, per unit of ``v sqrt(k m)`` (1 undamped)."""
    return _kelvin_voigt_peak(damping_ratio, force=0.0, speed=1.0)


def _muscle_knee_torque(model: mujoco.MjModel, data: mujoco.MjData) -> float:
    """The larger of the flexors' and the extensors' knee torque, all fully active, at the
    current pose (Nm; along the knee's coupled motion)."""
    muscles = np.flatnonzero(model.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE)
    knee = CoupledJointTorque(model, KNEE_JOINT)
    data.act[:] = 0.0
    mujoco.mj_forward(model, data)
    rest = knee(data)
    torques = []
    for i in muscles:
        data.act[:] = 0.0
        data.act[model.actuator_actadr[i]] = 1.0
        mujoco.mj_forward(model, data)
        torques.append(knee(data) - rest)
    data.act[:] = 0.0
    t = np.asarray(torques)
    return float(max(t[t > 0].sum(initial=0.0), -t[t < 0].sum(initial=0.0)))


def _series(a: float, b: float) -> float:
    """Two springs (or dampers) in series."""
    return a * b / (a + b) if a + b > 0.0 else 0.0


def strap_bound(model: mujoco.MjModel) -> StrapBound:
    """The strap bound of the twin *model* (its inertias at 90 deg flexion, its muscles over
    0-95 deg, its cuff pins' springs, dampers and ranges)."""
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=90.0)
    mujoco.mj_forward(model, data)
    exo_inertia = joint_inertia(model, data, EXO_JOINT)
    knee_inertia = joint_inertia(model, data, KNEE_JOINT)
    human = 0.0
    for angle in _KNEE_ANGLES_DEG:
        pose_twin(model, data, knee_angle_deg=float(angle))
        human = max(human, _muscle_knee_torque(model, data))
    # the lower exo's weight about the hinge: its subtree's mass times its centre's lever
    hinge = model.joint(EXO_JOINT)
    body = int(hinge.bodyid[0])
    mass = float(model.body_subtreemass[body])
    pose_twin(model, data, knee_angle_deg=0.0)  # the lever is largest with the shank level
    mujoco.mj_forward(model, data)
    lever = float(np.linalg.norm(data.subtree_com[body] - data.xanchor[hinge.id]))
    motor = model.actuator(EXO_ACTUATOR)
    pins = [model.joint(name) for name in SAGITTAL_PINS]
    stiffness = [float(model.jnt_stiffness[p.id]) for p in pins]
    damping = [float(model.dof_damping[p.dofadr[0]]) for p in pins]
    half_range_deg = [float(np.degrees(np.max(np.abs(model.jnt_range[p.id])))) for p in pins]
    return StrapBound(
        motor_limit_nm=float(np.max(np.abs(motor.forcerange))),
        exo_inertia_kg_m2=exo_inertia,
        knee_inertia_kg_m2=knee_inertia,
        human_torque_nm=human,
        exo_weight_nm=mass * _G_M_S2 * lever,
        pin_stiffness_nm_rad=_series(*stiffness),
        pin_damping_nm_s_rad=_series(*damping),
        misalignment_deg=round(min(half_range_deg), 3),  # the model stores radians
    )
