"""The spastic reflex as a stage of MyoSuite's muscle-command pipeline.

:class:`SpasticityStage` adds the reflex excitation of the chosen model
(:mod:`myoexo.spasticity.reflex`) to the 11 spastic muscles' entries of ``ctrl``
(:mod:`myosuite.envs.muscle_stages`); :class:`StageHost` is the smallest host it runs on
outside an env (a model, a data and a control period: clinical tests, planners).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any, NamedTuple

import numpy as np

from myoexo.model.leg import KNEE_JOINT  # the joint whose angle and velocity drive the reflex
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
from myoexo.spasticity.reflex import LevelCalibration, ReflexConfig, reflex_config

#: What :meth:`SpasticityStage.history_state` returns: the delay line's state and the
#: after-discharge ``r`` of the ``"persistent"`` model (0.0 for the others).
HistoryState = tuple[tuple[tuple[float, ...], tuple[float, ...], int], float]

#: Name of the stage in MyoSuite's muscle-command pipeline.
STAGE_NAME = "spasticity"

_RAD_TO_DEG = 180.0 / math.pi


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
    reflex's transmission delay (:class:`~myoexo.spasticity.delay.DelayLine`, whole control
    periods of the host's ``env.dt``), computes the current subject's reflex excitation with
    the chosen model (:mod:`myoexo.spasticity.reflex`: ``"stretch"``, each muscle group
    answering its own stretch, ``"uniform"``, the paper's ``SC_total`` on all 11
    muscles, or ``"persistent"``, ``"uniform"`` plus the flexors' after-discharge ``G r``
    whose state ``r`` remembers fast extensions for seconds) and adds it to the spastic
    muscles' entries of ``ctrl``, clipped to ``[0, 1]``;
    every other entry is left as it is. MyoSuite's (MuJoCo's) activation dynamics then act on
    the excitation. :meth:`reset` draws the next subject (and, with ``level="random"``, the next
    level, uniformly) from ``env.np_random`` and clears the delay line and the after-discharge
    (``"persistent"`` also draws the subject's gain ``G (1 + rel_std z)``, ``z`` from a child
    of ``env.np_random`` that leaves its stream where the other models leave it).
    :meth:`history_state` / :meth:`set_history_state` save and restore the reflex's memory
    (a planner's copy, :meth:`planning_copy`).

    The joint and actuator addresses are resolved once per model, so a step costs a few
    scalar operations and one fancy-indexed update of 11 entries.

    Args:
        level: Spasticity level (a key of :data:`LEVELS`) or ``"random"``.
        subject_noise: Draw individual subjects (10 % noise, :func:`sample_subject`) at
            reset; ``False`` keeps the level's nominal Table I parameters.
        rel_std: Relative standard deviation of the subject parameters.
        reflex: Reflex model: a preset name of :data:`~myoexo.spasticity.reflex.REFLEX_PRESETS`
            (``"stretch"``, the calibrated default, ``"uniform"`` or ``"persistent"``) or a
            :class:`~myoexo.spasticity.reflex.ReflexConfig`.
        flexors: Actuators stretched by knee extension (default: the paper's 6).
        extensors: Actuators stretched by knee flexion (default: the paper's 5).
        joint: Hinge joint whose angle and velocity drive the reflex.

    Attributes:
        level_setting: The configured level: an ``int`` level, or ``"random"``
            (:data:`RANDOM_LEVEL`, a new level at every reset).
        level: Level of the current subject. Until the first :meth:`reset` the stage uses the
            nominal parameters of its level (level 0 for ``"random"``).
        subject: :class:`SpasticityParams` of the current subject.
        reflex: The :class:`~myoexo.spasticity.reflex.ReflexConfig` in use.
        last_flexor_excitation: Reflex excitation added to the flexors at the last step.
        last_extensor_excitation: Reflex excitation added to the extensors at the last step.
        last_sc_total: Their sum (for ``"uniform"``: ``SC_total``, which both groups get;
            for ``"persistent"``: the flexors' ``SC_total + G r``); 0 before any step.
        last_after_discharge: The after-discharge ``r`` after the last step
            (``"persistent"``; 0 otherwise).

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
        self.level_setting: int | str = check_level_setting(level)
        initial = min(LEVELS) if self.level_setting == RANDOM_LEVEL else int(self.level_setting)
        if not (math.isfinite(rel_std) and rel_std >= 0.0):
            raise ValueError(f"rel_std must be a finite value >= 0, got {rel_std!r}.")
        if len(flexors) == 0 or len(extensors) == 0:
            raise ValueError("flexors and extensors must each name at least one actuator.")
        self.subject_noise = bool(subject_noise)
        self.rel_std = float(rel_std)
        self.reflex = reflex_config(reflex)
        # "persistent" is the uniform reading plus the flexors' after-discharge
        self._persistent = self.reflex.model == "persistent"
        self._uniform = self.reflex.model == "uniform" or self._persistent
        self._pic = self.reflex.persistent
        self._pic_r = 0.0  # the after-discharge state r (persistent model)
        self._pic_z = 0.0  # the subject's standard normal draw of its gain
        self._pic_gain = 0.0  # this subject's gain G (fraction of the excitation range)
        self._pic_rates = self._pic.rates(0.01)  # re-sized to the host's period in bind
        self._pic_half_slope = 0.5 * self._pic.ignition_slope_per_rad_s
        self._pic_v_ig = self._pic.ignition_velocity_rad_s
        self.last_after_discharge = 0.0
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
        if self._persistent:
            noise = 1.0 + self.rel_std * self._pic_z if self.subject_noise else 1.0
            self._pic_gain = self._pic.gain(level) * max(0.0, noise)

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
        if self._persistent and self.subject_noise:
            self._pic_z = self._gain_draw(rng)
        self._set_subject(level, subject)
        self.clear_history()

    @staticmethod
    def _gain_draw(rng: np.random.Generator) -> float:
        """The subject's standard normal for the after-discharge gain, from a child of *rng*
        (``Generator.spawn``: *rng*'s own stream is not advanced, so the rest of the episode,
        e.g. the env's start angle, draws what it draws under the other models)."""
        try:
            child = rng.spawn(1)[0]
        except (AttributeError, TypeError, ValueError):  # a generator without a seed sequence
            return float(rng.standard_normal())
        return float(child.standard_normal())

    def clear_history(self) -> None:
        """Forget the delayed knee states, the after-discharge and the last excitations (a
        new motion starts)."""
        self._delay.clear()
        self._pic_r = 0.0
        self.last_after_discharge = 0.0
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
        self._exc = np.empty(len(ids))  # the excitation added to each driven muscle
        self._ones = np.ones(len(ids))
        self._zeros = np.zeros(len(ids))
        period = float(control_period_s or model.opt.timestep)
        self._delay = DelayLine(round(self.reflex.delay_s / period))
        self._pic_rates = self._pic.rates(period)
        self._data_views: tuple | None = None  # (data, qpos, qvel) last seen by apply
        self._model = model

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
        """The reflex's memory: the delay line's state and the after-discharge ``r``, for
        :meth:`set_history_state` (a planner replays from here)."""
        return self._delay.state(), self._pic_r

    def set_history_state(self, state: HistoryState) -> None:
        """Restore a memory taken by :meth:`history_state` (of a stage of the same delay)."""
        delay, r = state
        self._delay.set_state(delay)
        self._pic_r = float(r)

    @property
    def after_discharge(self) -> float:
        """The after-discharge state ``r`` in [0, 1] (``"persistent"``; 0 for the others)."""
        return self._pic_r

    @property
    def after_discharge_gain(self) -> float:
        """This subject's gain ``G`` of the flexors' extra excitation ``G r``."""
        return self._pic_gain

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
        delayed) knee state, with the stage's model (for ``"persistent"``: without the
        after-discharge, which depends on the history, not on one state).

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
        if self._persistent:  # the flexors' after-discharge: a few scalar operations
            r = self._pic_r
            a_rise, a_decay = self._pic_rates
            # ignition gate sigmoid(slope (-v - v_ig)) = (1 + tanh(slope / 2 (...))) / 2
            gate = 0.5 * (1.0 + math.tanh(self._pic_half_slope * (-vel_rad_s - self._pic_v_ig)))
            r += gate * a_rise * (1.0 - r) - (1.0 - gate) * a_decay * r
            self._pic_r = r
            self.last_after_discharge = r
            flex += self._pic_gain * r
        ids = self._act_ids
        exc = self._exc  # preallocated: array-array operations, no scalar broadcasting
        nf = self._n_flex
        exc[:nf] = flex
        exc[nf:] = ext
        u = ctrl[ids]  # a copy (fancy indexing); clip in place, cheaper than np.clip
        u += exc
        np.minimum(u, self._ones, out=u)
        np.maximum(u, self._zeros, out=u)
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
        for key in (
            "_qpos_adr",
            "_dof_adr",
            "_exc",
            "_ones",
            "_zeros",
            "_act_ids",
            "_nu",
            "_n_flex",
            "_data_views",
        ):
            state.pop(key, None)
        return state

    def __repr__(self) -> str:
        return (
            f"SpasticityStage(level_setting={self.level_setting!r}, level={self.level}, "
            f"reflex={self.reflex.model!r}, delay_s={self.reflex.delay_s}, "
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
