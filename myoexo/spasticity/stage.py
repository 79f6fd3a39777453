"""The spastic reflex as a stage of MyoSuite's muscle-command pipeline.

:class:`SpasticityStage` adds the reflex excitation of the chosen model
(:mod:`myoexo.spasticity.reflex`) to the 11 spastic muscles' entries of ``ctrl``
(:mod:`myosuite.envs.muscle_stages`); :class:`StageHost` is the smallest host it runs on
outside an env (a model, a data and a control period: clinical tests, planners).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from myoexo.model.leg import KNEE_JOINT  # the joint whose angle and velocity drive the reflex
from myoexo.spasticity.coefficients import sc_total
from myoexo.spasticity.delay import DelayLine
from myoexo.spasticity.levels import (
    LEVELS,
    RANDOM_LEVEL,
    SPASTIC_EXTENSORS,
    SPASTIC_FLEXORS,
    SUBJECT_REL_STD,
    VALID_LEVELS,
    SpasticityParams,
    check_level,
    check_level_setting,
    sample_subject,
)
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import Memory, ReflexModel, reflex_label, resolve_reflex
from myoexo.spasticity.sensory import MuscleSensors, SensoryRecord

#: What :meth:`SpasticityStage.history_state` returns: the delay line's state and the reflex
#: model's memory (e.g. the after-discharge ``(r,)`` of ``"persistent"``; ``()`` for the
#: models without one).
HistoryState = tuple[tuple[tuple[Any, ...], int], Memory]

#: Name of the stage in MyoSuite's muscle-command pipeline.
STAGE_NAME = "spasticity"

#: Control period the model's constants assume until the stage is bound to a host, s.
DEFAULT_CONTROL_PERIOD_S = 0.01

_RAD_TO_DEG = 180.0 / math.pi


class SpasticityStage:
    """The spastic reflex as a stage of MyoSuite's muscle-command pipeline.

    Install it on a MyoSuite env (a :class:`~myosuite.envs.muscle_stages.CtrlStageHost`)::

        stage = SpasticityStage(level=2)
        env.unwrapped.add_ctrl_stage(STAGE_NAME, stage.apply, stage.reset)

    or use :class:`SpasticityWrapper`. Each control step :meth:`apply` reads the angle (deg)
    and velocity (rad/s) of ``knee_angle_r`` from ``env.data``, passes them through the
    reflex's transmission delay (:class:`~myoexo.spasticity.delay.DelayLine`, whole control
    periods of the host's ``env.dt``), asks the reflex model for the current subject's
    excitation of the two muscle groups (:meth:`ReflexModel.step
    <myoexo.spasticity.registry.ReflexModel.step>`: a registered model such as
    ``"stretch"``, ``"uniform"`` or ``"persistent"``, :mod:`myoexo.spasticity.reflex`, or
    one of the user's, :mod:`myoexo.spasticity.registry`) and adds it to the spastic
    muscles' entries of ``ctrl``, clipped to ``[0, 1]``; every other entry is left as it
    is. MyoSuite's (MuJoCo's) activation dynamics then act on the excitation. :meth:`reset`
    draws the next subject (and, with ``level="random"``, the next level, uniformly) from
    ``env.np_random`` (plus the model's own individual draw, which leaves that stream where
    it found it) and clears the delay line and the model's memory. :meth:`history_state` /
    :meth:`set_history_state` save and restore the reflex's memory (a planner's copy,
    :meth:`planning_copy`).

    The joint and actuator addresses are resolved once per model, so a step costs a few
    scalar operations and one fancy-indexed update of 11 entries.

    Args:
        level: Spasticity level (a key of :data:`LEVELS`) or ``"random"``.
        subject_noise: Draw individual subjects (10 % noise, :func:`sample_subject`) at
            reset; ``False`` keeps the level's nominal Table I parameters.
        rel_std: Relative standard deviation of the subject parameters.
        reflex: Reflex model: a registered name (:func:`~myoexo.spasticity.reflex_names`:
            ``"stretch"``, the calibrated default, ``"uniform"``, ``"persistent"`` and any
            the user registered) or a :class:`~myoexo.spasticity.ReflexModel` instance.
        flexors: Actuators stretched by knee extension (default: the paper's 6).
        extensors: Actuators stretched by knee flexion (default: the paper's 5).
        joint: Hinge joint whose angle and velocity drive the reflex.

    Attributes:
        level_setting: The configured level: an ``int`` level, or ``"random"``
            (:data:`RANDOM_LEVEL`, a new level at every reset).
        level: Level of the current subject. Until the first :meth:`reset` the stage uses the
            nominal parameters of its level (level 0 for ``"random"``).
        subject: :class:`SpasticityParams` of the current subject.
        reflex: The :class:`~myoexo.spasticity.ReflexModel` in use.
        reflex_name: Its registered name (``"<ClassName> (custom)"`` for an unregistered
            instance).
        constants: The current subject's constants of the model
            (:meth:`~myoexo.spasticity.ReflexModel.subject_constants`).
        memory: The model's memory after the last step (e.g. ``(r,)``, the after-discharge
            of ``"persistent"``; ``()`` for a model without one).
        last_flexor_excitation: Reflex excitation added to the flexors at the last step.
        last_extensor_excitation: Reflex excitation added to the extensors at the last step.
        last_sc_total: The model's report of the two
            (:meth:`~myoexo.spasticity.ReflexModel.sc_total`: their sum; for ``"uniform"``
            ``SC_total``, which both groups get; for ``"persistent"`` the flexors' ``SC_total
            + G r``); 0 before any step.

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
        reflex: str | ReflexModel = DEFAULT_REFLEX,
        flexors: Sequence[str] = SPASTIC_FLEXORS,
        extensors: Sequence[str] = SPASTIC_EXTENSORS,
        joint: str = KNEE_JOINT,
    ) -> None:
        self.level_setting: int | str = check_level_setting(level)
        initial = min(LEVELS) if self.level_setting == RANDOM_LEVEL else int(self.level_setting)
        if not (math.isfinite(rel_std) and rel_std >= 0.0):
            raise ValueError(f"rel_std must be a finite value >= 0, got {rel_std!r}.")
        if len(flexors) == 0 or len(extensors) == 0:
            raise ValueError("flexors and extensors must each name at least one actuator.")
        self.subject_noise = bool(subject_noise)
        self.rel_std = float(rel_std)
        self.reflex: ReflexModel = resolve_reflex(reflex)
        self.reflex_name = reflex_label(self.reflex)
        self.memory: Memory = self.reflex.initial_memory()
        self._individual: Any = None  # the model's own draw for the current subject
        self._period_s = DEFAULT_CONTROL_PERIOD_S  # the host's, from bind on
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
        self.constants = self.reflex.subject_constants(
            level, subject, self._individual, self._period_s
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
        self._set_subject(self.level if level is None else check_level(level), subject)

    def set_level(self, level: int | str) -> None:
        """Change the level (or ``"random"``) used from the next :meth:`reset` on."""
        self.level_setting = check_level_setting(level)

    def reset(self, env: Any) -> None:
        """Draw the next level (``"random"`` only) and subject from ``env.np_random``; clear
        the delay line."""
        rng = env.np_random
        if self.level_setting == RANDOM_LEVEL:
            level = VALID_LEVELS[int(rng.integers(len(VALID_LEVELS)))]
        else:
            level = int(self.level_setting)
        subject = sample_subject(level, rng, self.rel_std) if self.subject_noise else LEVELS[level]
        if self.subject_noise:
            self._individual = self.reflex.draw_individual(rng, self.rel_std)
        self._set_subject(level, subject)
        self.clear_history()

    def clear_history(self) -> None:
        """Forget the delayed knee states, the model's memory and the last excitations (a
        new motion starts)."""
        self._delay.clear()
        self.memory = self.reflex.initial_memory()
        if self._model is not None:
            self._exc[:] = 0.0
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
        self._sensors = MuscleSensors(model, self._act_ids, self._n_flex)
        # a two-group model on the knee state: its step, written into each group directly
        self._groups = type(self.reflex).excite is ReflexModel.excite
        self._nu = int(model.nu)
        self._exc = np.empty(len(ids))  # the excitation added to each driven muscle
        self._ones = np.ones(len(ids))
        self._zeros = np.zeros(len(ids))
        period = float(control_period_s or model.opt.timestep)
        self._delay = DelayLine(round(self.reflex.delay_s / period))
        # (data, qpos, qvel, muscle view, muscle index) of the data apply last read
        self._data_views: tuple | None = None
        self._model = model
        if period != self._period_s:  # the model's per-step rates follow the period
            self._period_s = period
            self._set_subject(self.level, self.subject)

    def planning_copy(self, model: Any, control_period_s: float) -> SpasticityStage:
        """A copy of this stage (bound to *model* first if it is not yet) with the same
        subject and a delay line of its own: it can be run ahead on another ``MjData`` of
        the model and reset to this stage's history (:meth:`history_state`, which holds the
        delay line and the after-discharge) without touching this stage."""
        import copy

        if self._model is not model:
            self.bind(model, control_period_s)
        twin = copy.copy(self)
        twin._delay = copy.deepcopy(self._delay)
        twin._exc = self._exc.copy()  # scratch buffer of its own
        twin._data_views = None
        return twin

    def history_state(self) -> HistoryState:
        """The reflex's memory: the delay line's state and the model's memory, for
        :meth:`set_history_state` (a planner replays from here)."""
        return self._delay.state(), self.memory

    def set_history_state(self, state: HistoryState) -> None:
        """Restore a memory taken by :meth:`history_state` (of a stage of the same delay)."""
        delay, memory = state
        self._delay.set_state(delay)
        self.memory = tuple(memory)

    @property
    def last_excitations(self) -> np.ndarray:
        """The reflex excitation added to each driven muscle at the last step (a copy;
        :attr:`muscles`' order, before the clip to ``[0, 1]``; zeros before any step)."""
        if self._model is None:
            return np.zeros(len(self.muscles))
        return self._exc.copy()

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
        """The paper's ``SC_total`` of the current subject at one state
        (:func:`~myoexo.spasticity.sc_total`; the ``"uniform"`` model's excitation of every
        muscle).

        Raises:
            ValueError: If the angle or the velocity is NaN or infinite.
        """
        return float(sc_total(theta_deg, vel_rad_s, self.subject))

    def sensory_record(self, env: Any) -> SensoryRecord:
        """What the reflex senses in *env*'s data as it stands (undelayed; the delay line is
        not touched)."""
        model = env.model
        if model is not self._model:
            self.bind(model, getattr(env, "dt", None))
        data = env.data
        return self._sensors.read(
            data,
            data.qpos.item(self._qpos_adr) * _RAD_TO_DEG,
            data.qvel.item(self._dof_adr),
        )

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
        if views is None or views[0] is not data:  # what it reads of the data, set up once
            views = self._data_views = (data, data.qpos, data.qvel, *self._sensors.views(data))
        _, qpos, qvel, sensed, sensed_index = views
        record = self._delay.push(
            self._sensors.record(
                sensed[sensed_index],
                qpos.item(self._qpos_adr) * _RAD_TO_DEG,
                qvel.item(self._dof_adr),
            )
        )
        theta_deg, vel_rad_s = record.knee_angle_deg, record.knee_vel_rad_s
        if not (math.isfinite(theta_deg) and math.isfinite(vel_rad_s)):
            raise ValueError(
                f"Knee state must be finite, got theta_deg={theta_deg!r}, vel_rad_s={vel_rad_s!r}."
            )
        reflex = self.reflex
        ids = self._act_ids
        exc = self._exc  # preallocated: array-array operations, no scalar broadcasting
        nf = self._n_flex
        if self._groups:
            flex, ext, self.memory = reflex.step(self.constants, self.memory, theta_deg, vel_rad_s)
            exc[:nf] = flex
            exc[nf:] = ext
        else:
            exc[:], self.memory = reflex.excite(self.constants, self.memory, record)
            excitations = exc.tolist()  # a python mean: numpy's costs ~10 us on 11 values
            flex = sum(excitations[:nf]) / nf
            ext = sum(excitations[nf:]) / (len(excitations) - nf)
        u = ctrl[ids]  # a copy (fancy indexing); clip in place, cheaper than np.clip
        u += exc
        np.minimum(u, self._ones, out=u)
        np.maximum(u, self._zeros, out=u)
        ctrl[ids] = u
        self.last_flexor_excitation = flex
        self.last_extensor_excitation = ext
        self.last_sc_total = reflex.sc_total(flex, ext)
        return ctrl

    def __call__(self, env: Any, ctrl: np.ndarray) -> np.ndarray:
        """Same as :meth:`apply`."""
        return self.apply(env, ctrl)

    def __getstate__(self) -> dict[str, Any]:
        state = dict(self.__dict__)
        state["_model"] = None  # re-bound on the first step after unpickling
        for key in (
            "_qpos_adr",
            "_dof_adr",
            "_exc",
            "_ones",
            "_zeros",
            "_act_ids",
            "_nu",
            "_n_flex",
            "_sensors",
            "_groups",
            "_data_views",
        ):
            state.pop(key, None)
        return state

    def __repr__(self) -> str:
        return (
            f"SpasticityStage(level_setting={self.level_setting!r}, level={self.level}, "
            f"reflex={self.reflex_name!r}, delay_s={self.reflex.delay_s}, "
            f"subject_noise={self.subject_noise}, subject={self.subject})"
        )


class StageHost:
    """What :meth:`SpasticityStage.apply` and :meth:`SpasticityStage.reset` need of an env,
    outside one: the MuJoCo ``model`` and ``data``, the control period ``dt`` (s) of the
    apply calls (it sizes the reflex's delay line) and ``np_random`` (a seeded generator,
    for :meth:`~SpasticityStage.reset`'s subject draw).

    Args:
        model: The MuJoCo model with the spastic muscles and the knee joint.
        data: The data the stage reads the knee state from.
        dt: Control period of the apply calls, s.
        seed: Seed of ``np_random``.
    """

    def __init__(self, model: Any, data: Any, dt: float, seed: int = 0) -> None:
        self.model, self.data, self.dt = model, data, float(dt)
        self.np_random = np.random.default_rng(seed)
