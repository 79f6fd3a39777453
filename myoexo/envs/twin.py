"""The twin as one object: the MuJoCo model and data, the reflex stage, named quantities and
the one ``step``.

In the manner of dm_control's ``Physics``, :class:`Twin` owns what the simulation is (the
compiled twin, its ``MjData``, the :class:`~myoexo.spasticity.SpasticityStage` that excites
the spastic muscles) and names what a task, a controller or a clinical test reads:

* the knee and the exo hinge: ``knee_angle_deg``, ``knee_velocity_rad_s``,
  ``exo_angle_deg``, ``exo_velocity_rad_s``, ``misalignment_deg``;
* the straps: ``strap_torque_nm`` (the torque the shank strap transmits to the knee along its
  coupled motion, flexion positive), ``interaction_torque_nm`` (its magnitude: the study's
  interaction torque, the one every env, criterion and reward reads) and
  ``cuff_forces_n`` (the two cuffs' force magnitudes);
* the leg: ``muscle_torque_nm`` (the muscles' torque along the knee),
  ``leg_torque_nm`` (the muscles' and the passive knee's springs') and
  ``sensory_record()`` (each spastic muscle's normalised fibre length, lengthening speed and
  force, :class:`~myoexo.spasticity.SensoryRecord`);
* ``step(command)``: one control period: the exo motor's command (in ``[-1, 1]``, the
  fraction of its torque limit) as the drive applies it (its end-stop protection,
  :mod:`myoexo.model.drive`, brakes at any physics timestep where the command would carry
  the limb into the flexion stop; ``applied_command`` and ``braking``), the reflex's
  excitations on the muscles, ``frame_skip`` physics steps.

The env (:class:`~myoexo.envs.MyoExoKneeEnv`, as ``env.twin``), the oracle's planner and the
clinical tests' drive step the twin through it; nothing else calls ``mj_step`` on it.

Timing: the state accessors read the state as it stands (after a step: the state at its
end). The force accessors read what MuJoCo computed in the last physics substep, from the
state the substep started at (after ``mj_forward``: the present state's); ``strap_torque_nm``
evaluates the strap's constraint force along the knee at that substep's knee angle
(:attr:`force_knee_angle_rad`).
"""

from __future__ import annotations

import math
from collections.abc import Callable

import mujoco
import numpy as np

from myoexo.model import EXO_ACTUATOR, EXO_JOINT, KNEE_ANGLE_SENSOR, KNEE_JOINT, strap_knee_torque
from myoexo.model.drive import stop_protection
from myoexo.model.joint_torque import CoupledJointTorque
from myoexo.spasticity import SensoryRecord, SpasticityStage

__all__ = ["Twin", "frame_skip_of"]

_RAD_TO_DEG = 180.0 / math.pi
#: Control periods the drive keeps checking every timestep after it braked (the check at
#: the period's start assumes the leg adds at most the motor's authority; right after a
#: braking the stretched strap still passes more on).
_WATCH_PERIODS = 10


def frame_skip_of(control_period_s: float, timestep_s: float) -> int:
    """The physics steps one control period takes.

    Raises:
        ValueError: If the period is not a whole number (>= 1) of timesteps.
    """
    frame_skip = round(control_period_s / timestep_s)
    if frame_skip < 1 or not math.isclose(frame_skip * timestep_s, control_period_s, rel_tol=1e-9):
        raise ValueError(
            f"control_period_s = {control_period_s} must be a whole multiple of the physics "
            f"timestep {timestep_s} s"
        )
    return frame_skip


class Twin:
    """The stepping twin (module docstring).

    Args:
        model: The compiled twin (:func:`~myoexo.model.build_model`).
        stage: The reflex stage that excites the spastic muscles.
        control_period_s: Time one :meth:`step` advances, s (a whole number of physics
            timesteps).
        data: The ``MjData`` to step (default: a new one).
        stages: What turns a step's control vector (the exo command in place, every muscle
            0) into the applied ``ctrl`` (default: the reflex stage's ``apply``). An env
            with MyoSuite control stages of its own passes its stage pipeline.
        seed: Seed of :attr:`np_random` (the reflex stage draws a subject from it at
            :meth:`reset_reflex`).

    Raises:
        ValueError: If the control period is not a whole number of physics timesteps.
    """

    def __init__(
        self,
        model: mujoco.MjModel,
        stage: SpasticityStage,
        control_period_s: float,
        *,
        data: mujoco.MjData | None = None,
        stages: Callable[[np.ndarray], np.ndarray] | None = None,
        seed: int = 0,
    ) -> None:
        timestep_s = float(model.opt.timestep)
        frame_skip = frame_skip_of(control_period_s, timestep_s)
        self.model = model
        self.data = mujoco.MjData(model) if data is None else data
        self.stage = stage
        self.frame_skip = frame_skip
        #: Control period, s (what the reflex stage's delay line counts in).
        self.dt = frame_skip * timestep_s
        self.np_random = np.random.default_rng(seed)
        self._stages = stages
        knee = model.joint(KNEE_JOINT)
        exo = model.joint(EXO_JOINT)
        self._knee_q, self._knee_d = int(knee.qposadr[0]), int(knee.dofadr[0])
        self._exo_q, self._exo_d = int(exo.qposadr[0]), int(exo.dofadr[0])
        self.exo_actuator = int(model.actuator(EXO_ACTUATOR).id)
        self._knee = CoupledJointTorque(model, KNEE_JOINT)
        self._knee_dofs = self._knee.dofs
        self._strap = strap_knee_torque(model)
        self._cuffs = tuple(
            (int(model.sensor(name).adr[0]), int(model.sensor(name).dim[0]))
            for name in ("thigh_cuff_force", "shank_cuff_force")
        )
        # the knee angle each mj_step started from
        self._knee_sensor = int(model.sensor(KNEE_ANGLE_SENSOR).adr[0])
        self._ctrl = np.zeros(model.nu)
        #: The drive's end-stop protection (``None``: the model's drive has none).
        self.protection = stop_protection(model)
        #: The motor command the drive applied in the last physics timestep.
        self.applied_command = 0.0
        #: Whether the drive braked in the last control period instead of applying the
        #: command it was given.
        self.braking = False
        self._command = 0.0
        self._protected = False
        self._protect_periods = 0
        self._half_timestep_s = 0.5 * timestep_s
        #: The knee angle (rad) at the start of the last physics substep, where the force
        #: accessors were computed.
        self.force_knee_angle_rad = float(self.data.qpos[self._knee_q])

    # ------------------------------------------------------------------ stepping
    def apply_command(self, command: float, *, powered: bool = True) -> np.ndarray:
        """Write the ``ctrl`` of one control step: the exo motor's *command* (with *powered*
        False the motor is off: the command is 0 and the drive does not act) and the reflex's
        (and any other stage's) excitations on the muscles. Returns ``data.ctrl``. When the
        hinge is near its braking curve, :meth:`advance` lets the drive's protection decide
        the motor's command at every physics timestep."""
        if not powered:
            command = 0.0
        protection = self.protection
        d = self.data
        if not powered or protection is None:
            self._protected = False
        elif self._protect_periods > 0:  # braked lately: the strap may still carry momentum
            self._protect_periods -= 1
            self._protected = True
        else:
            self._protected = protection.near(
                d.qpos.item(self._exo_q), d.qvel.item(self._knee_d), self.dt
            )
        self._command = self.applied_command = command
        self.braking = False
        ctrl = self._ctrl
        ctrl.fill(0.0)
        ctrl[self.exo_actuator] = command
        applied = self.stage.apply(self, ctrl) if self._stages is None else self._stages(ctrl)
        d.ctrl[:] = applied
        return d.ctrl

    def advance(self) -> bool:
        """Run one control period of physics with the ``ctrl`` in place (``frame_skip`` steps,
        :attr:`force_knee_angle_rad` read from the knee-angle sensor, which MuJoCo computes
        at the start of each; one at a time, each with the drive's command, when the drive
        protects its stops). Returns whether MuJoCo
        found the simulation unstable and reset its data (the time went back); the data then
        holds the reset state, forward-computed."""
        m, d = self.model, self.data
        t_expected_s = d.time + self.dt
        if self._protected:
            self._advance_protected()
        else:
            mujoco.mj_step(m, d, self.frame_skip)
            self.force_knee_angle_rad = d.sensordata.item(self._knee_sensor)
        unstable = d.time < t_expected_s - self._half_timestep_s
        if unstable:
            mujoco.mj_forward(m, d)
            self.force_knee_angle_rad = d.qpos.item(self._knee_q)
        return unstable

    def _advance_protected(self) -> None:
        """The control period, one physics timestep at a time, each with the command the
        drive's protection applies (:attr:`braking`: whether it braked in any)."""
        m, d = self.model, self.data
        protection = self.protection
        assert protection is not None
        qpos, qvel, ctrl = d.qpos, d.qvel, d.ctrl
        exo_q, knee_d, exo_a = self._exo_q, self._knee_d, self.exo_actuator
        command = self._command
        for _ in range(self.frame_skip):
            applied = protection.command(qpos.item(exo_q), qvel.item(knee_d), command)
            if applied != command:
                self.braking = True
                self._protect_periods = _WATCH_PERIODS
            ctrl[exo_a] = applied
            self.applied_command = applied
            self.force_knee_angle_rad = qpos.item(self._knee_q)
            mujoco.mj_step(m, d)

    def step(self, command: float, *, powered: bool = True) -> bool:
        """One control step: :meth:`apply_command` then :meth:`advance`. Returns whether the
        simulation went unstable."""
        self.apply_command(command, powered=powered)
        return self.advance()

    def forward(self) -> None:
        """``mj_forward`` of the present state: every accessor then refers to it."""
        mujoco.mj_forward(self.model, self.data)
        self.force_knee_angle_rad = self.data.qpos.item(self._knee_q)

    def drive_state(self) -> int:
        """The drive's protection state (the control periods it goes on checking every
        timestep), for :meth:`set_drive_state` (e.g. to replay from here in a planner)."""
        return self._protect_periods

    def set_drive_state(self, state: int = 0) -> None:
        """Restore a state taken by :meth:`drive_state` (default: the drive at rest, as at
        the start of an episode)."""
        self._protect_periods = int(state)
        self.braking = False

    def reset_reflex(self) -> None:
        """Draw the reflex stage's next subject (from :attr:`np_random`) and clear its delay
        line."""
        self.stage.reset(self)

    # ------------------------------------------------------------------ the knee and the exo
    @property
    def knee_angle_rad(self) -> float:
        """Knee flexion, rad (0 = full extension)."""
        return self.data.qpos.item(self._knee_q)

    @property
    def knee_angle_deg(self) -> float:
        """Knee flexion, deg (0 = full extension)."""
        return self.data.qpos.item(self._knee_q) * _RAD_TO_DEG

    @property
    def knee_velocity_rad_s(self) -> float:
        """Knee flexion velocity, rad/s."""
        return self.data.qvel.item(self._knee_d)

    @property
    def exo_angle_deg(self) -> float:
        """Exo hinge angle (the encoder's reading), deg."""
        return self.data.qpos.item(self._exo_q) * _RAD_TO_DEG

    @property
    def exo_velocity_rad_s(self) -> float:
        """Exo hinge velocity, rad/s."""
        return self.data.qvel.item(self._exo_d)

    @property
    def misalignment_deg(self) -> float:
        """Knee angle less exo hinge angle, deg."""
        return (self.data.qpos.item(self._knee_q) - self.data.qpos.item(self._exo_q)) * _RAD_TO_DEG

    # ------------------------------------------------------------------ forces
    @property
    def exo_torque_nm(self) -> float:
        """The exo motor's torque, Nm."""
        return float(self.data.actuator_force[self.exo_actuator])

    @property
    def strap_torque_nm(self) -> float:
        """The shank strap's torque on the knee along its coupled motion, Nm (flexion
        positive)."""
        return self._strap(self.data, self.force_knee_angle_rad)

    @property
    def interaction_torque_nm(self) -> float:
        """The interaction torque: the strap torque's magnitude, Nm."""
        return abs(self.strap_torque_nm)

    @property
    def cuff_forces_n(self) -> tuple[float, float]:
        """The thigh and shank cuffs' force magnitudes, N."""
        s = self.data.sensordata
        return tuple(  # type: ignore[return-value]
            float(np.linalg.norm(s[adr : adr + dim])) for adr, dim in self._cuffs
        )

    @property
    def muscle_torque_nm(self) -> float:
        """The muscles' torque along the knee's coupled motion, Nm (flexion positive)."""
        return self._knee.torque_of_dofs(
            self.force_knee_angle_rad, self.data.qfrc_actuator[self._knee_dofs]
        )

    @property
    def leg_torque_nm(self) -> float:
        """The leg's own torque along the knee: its muscles' and its passive knee's springs
        (:mod:`myoexo.model.passive_knee`), Nm (flexion positive)."""
        d, dofs = self.data, self._knee_dofs
        return self._knee.torque_of_dofs(
            self.force_knee_angle_rad, d.qfrc_actuator[dofs] + d.qfrc_spring[dofs]
        )

    def sensory_record(self) -> SensoryRecord:
        """What the reflex senses now: the knee state and each spastic muscle's normalised
        fibre length, lengthening speed and force (undelayed)."""
        return self.stage.sensory_record(self)

    def __repr__(self) -> str:
        return (
            f"Twin(knee {self.knee_angle_deg:.1f} deg, exo {self.exo_angle_deg:.1f} deg, "
            f"t {self.data.time:.3f} s, level {self.stage.level})"
        )
