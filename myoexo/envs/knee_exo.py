"""MyoExoKnee: knee extension with an exoskeleton on a spastic MyoSuite leg.

The task, observation and reward are specified in docs/reference.md section 3.

The agent commands the exoskeleton's knee motor only; the 40 muscles receive nothing but the
spastic reflex, which the :class:`~myoexo.spasticity.SpasticityStage` adds in MyoSuite's
muscle-command pipeline (``map -> noise -> fatigue -> reroute -> spasticity -> ctrl``), so
MyoSuite's own wrappers (``MotorNoiseWrapper``, ``FatigueWrapper``, ...) stack with it.

Episode: the seated subject's knee starts at 90 deg flexion (plus a small seeded
perturbation) and must be extended to 7 deg flexion; 8 s of simulated time at 100 Hz control.

Action (1-D, ``Box(-1, 1)``): exo motor command; ``u * 100 Nm`` at the exo knee hinge,
positive = flexion. Out-of-range values are clipped to [-1, 1] (what the motor driver does);
NaN/inf or a wrong shape raise ``ValueError``.

Observation (``obs_keys``, flattened in this order; each entry of ``obs_dict`` is in the
physical unit its name gives and is multiplied by the scale below in the vector):

============================  =====  ==========================================  =======
key                           size   meaning (unit)                              scale
============================  =====  ==========================================  =======
knee_angle_rad                1      human knee flexion (rad)                    1
knee_vel_rad_s                1      human knee flexion velocity (rad/s)         0.1
exo_angle_rad                 1      exo knee encoder (rad)                      1
exo_vel_rad_s                 1      exo knee velocity (rad/s)                   0.1
target_rad                    1      target knee flexion (rad)                   1
error_rad                     1      knee - target (rad), > 0 while flexed       1
command                       1      last applied motor command (-)              1
exo_torque_nm                 1      exo motor torque (Nm)                       0.01
muscle_knee_torque_nm         1      muscle torque along the coupled knee (Nm)   0.01
thigh_cuff_force_n            3      thigh cuff interaction force (N)            0.01
thigh_cuff_torque_nm          3      thigh cuff interaction torque (Nm)          0.02
shank_cuff_force_n            3      shank cuff interaction force (N)            0.01
shank_cuff_torque_nm          3      shank cuff interaction torque (Nm)          0.02
coupling_qpos                 n_c    strap coupling joints (m for the slide,     per joint:
                                     rad for the pins)                           1/range
coupling_qvel                 n_c    their velocities (m/s, rad/s)               0.1/range
spastic_act                   11     activation of the 11 spastic muscles (-)    1
spastic_force                 11     their force / max isometric force (-)       1
spastic_length                11     their length, 0..1 over the length range    1
spastic_velocity              11     their velocity / length range (1/s)         0.1
time_frac                     1      time / episode duration (-)                 1
============================  =====  ==========================================  =======

Timing after a step (details in :meth:`MyoExoKneeEnv.step`): angles, velocities, activations
and time are the state after the step; torques, cuff sensors and muscle force/length/velocity
are those MuJoCo computed in the step's last physics substep (one timestep earlier).

Reward (MyoSuite ``weighted_reward_keys``; docs/reference.md section 3, defaults in
:data:`~myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`): ``pose`` = exp(-e^2/(2 sigma^2)) - |e|;
``bonus`` = 0.01 while |e| < 0.05 rad and |knee vel| < 0.05 rad/s; ``inter`` =
(d tau_knee / 100 Nm)^2 + (tau_knee / 100 Nm)^2 when tau_knee > 75 Nm; ``vel`` = |d knee
vel|; ``act`` = (d u)^2. Penalties are magnitudes with negative weights.

Interaction torque (the paper's "sum of the torques applied at the knee: exo actuation and
spastic reflexes"): ``|exo torque| + |muscle torque at the human knee|``. A signed sum would
let an exo holding against a spastic flexor look like zero load; the magnitude sum is the
load the joint and the straps carry. Both components are in ``info`` for other readings.
"""

from __future__ import annotations

import dataclasses
import math
import operator
from collections.abc import Sequence
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.utils import EzPickle
from myosuite.envs.gymnasium_env import CpuEnvAccessor, MyoGymnasiumEnv
from myosuite.envs.muscle_stages import CtrlStageHost

from myoexo.envs.config import RewardParams, TaskParams
from myoexo.envs.robustness import RobustnessParams, SensorModel, TwinPerturbation
from myoexo.model import (
    COUPLING_JOINTS,
    CUFF_SENSORS,
    EXO_ACTUATOR,
    EXO_JOINT,
    KNEE_JOINT,
    STRAP_EQUALITY,
    TwinParams,
    build_model,
    pose_twin,
)
from myoexo.model.joint_torque import CoupledJointTorque
from myoexo.model.scene import DEFAULT_CAMERA, MuscleColorizer
from myoexo.spasticity.levels import SPASTIC_MUSCLES
from myoexo.spasticity.reflex import ReflexConfig
from myoexo.spasticity.stage import SpasticityStage

#: Cuff sensors of the twin: obs key (sensor name + unit) -> sensor name.
CUFF_OBS_KEYS: dict[str, str] = {f"{name}_{unit}": name for name, unit in CUFF_SENSORS.items()}

#: Fixed observation scales (vector = obs_dict value * scale); coupling scales come from the
#: joint ranges of the model.
OBS_SCALES: dict[str, float] = {
    "knee_vel_rad_s": 0.1,
    "exo_vel_rad_s": 0.1,
    "exo_torque_nm": 0.01,
    "muscle_knee_torque_nm": 0.01,
    "thigh_cuff_force_n": 0.01,
    "thigh_cuff_torque_nm": 0.02,
    "shank_cuff_force_n": 0.01,
    "shank_cuff_torque_nm": 0.02,
    "spastic_velocity": 0.1,
}

DEFAULT_OBS_KEYS: tuple[str, ...] = (
    "knee_angle_rad",
    "knee_vel_rad_s",
    "exo_angle_rad",
    "exo_vel_rad_s",
    "target_rad",
    "error_rad",
    "command",
    "exo_torque_nm",
    "muscle_knee_torque_nm",
    "thigh_cuff_force_n",
    "thigh_cuff_torque_nm",
    "shank_cuff_force_n",
    "shank_cuff_torque_nm",
    "coupling_qpos",
    "coupling_qvel",
    "spastic_act",
    "spastic_force",
    "spastic_length",
    "spastic_velocity",
    "time_frac",
)

#: What a real knee exoskeleton measures: its own encoder (angle, velocity), the motor torque,
#: the two cuffs' 6-axis force/torque sensors, the last command, the target and the time.
#: No human joint angle and no muscle state: a policy on these runs on a device.
EXO_SENSOR_OBS_KEYS: tuple[str, ...] = (
    "exo_angle_rad",
    "exo_vel_rad_s",
    "target_rad",
    "command",
    "exo_torque_nm",
    *CUFF_OBS_KEYS,
    "time_frac",
)

#: Observation presets (``obs_preset=`` of the env): name -> ``obs_keys``.
OBS_PRESETS: dict[str, tuple[str, ...]] = {
    "full": DEFAULT_OBS_KEYS,
    "exo": EXO_SENSOR_OBS_KEYS,
}

_SCALAR_KEYS: tuple[str, ...] = (
    "time",
    "knee_angle_rad",
    "knee_vel_rad_s",
    "exo_angle_rad",
    "exo_vel_rad_s",
    "target_rad",
    "error_rad",
    "command",
    "exo_torque_nm",
    "muscle_knee_torque_nm",
    "interaction_torque_nm",
    "time_frac",
)
_MUSCLE_KEYS: tuple[str, ...] = (
    "spastic_act",
    "spastic_force",
    "spastic_length",
    "spastic_velocity",
)


class MyoExoKneeEnv(CtrlStageHost, MyoGymnasiumEnv, EzPickle):
    """Exo-driven knee extension of a seated, spastic MyoSuite leg.

    Args:
        spasticity_level: Modified Ashworth level 0..3, or ``"random"`` (uniform per reset,
            as the paper trains). A new subject (parameters with 10 % variability) is
            drawn from the env's seeded RNG at every reset.
        task: Task parameters (start/target angle, duration, control period).
        reward: Reward shape and ``weights`` (the ``weighted_reward_keys``).
        twin: Parameters of the human + exo digital twin.
        obs_keys: Observation entries (default: those of ``obs_preset``).
        obs_preset: Named set of ``obs_keys`` (:data:`OBS_PRESETS`): ``"full"`` (default,
            :data:`DEFAULT_OBS_KEYS`: the twin's whole state, muscles included) or ``"exo"``
            (:data:`EXO_SENSOR_OBS_KEYS`: what the exoskeleton itself measures). Ignored
            when ``obs_keys`` is given.
        weighted_reward_keys: Shortcut overriding ``reward.weights``.
        subject_noise: Draw an individual subject (10 % variability) at every reset;
            ``False`` keeps Table I's nominal subject of the level (e.g. for PID tuning).
        reflex: Reflex model (:mod:`myoexo.spasticity.reflex`): ``"stretch"`` (the calibrated
            stretch reflex with a 20 ms delay, default), ``"uniform"`` (the paper's ``SC_total`` on
            all 11 muscles, no delay: the first reading) or a ``ReflexConfig``.
        robustness: Draw the twin's uncertain parts (strap stiffness and damping, masses,
            slide friction, motor torque constant) and sensor noise and latency at every
            reset (:class:`~myoexo.envs.robustness.RobustnessParams`; ``True``: the default
            ranges; ``None``/``False``: the nominal twin, exact sensors).
        seed: Seed of the env's RNG (``reset(seed=...)`` reseeds it).
        render_mode: ``None``, ``"human"`` or ``"rgb_array"``.
    """

    DEFAULT_OBS_KEYS: ClassVar[list[str]] = list(DEFAULT_OBS_KEYS)
    #: Model camera that ``render()`` shows (a fixed camera aimed at the knee).
    render_camera: str | None = DEFAULT_CAMERA
    #: Colours the muscles before each ``render()`` (made at the first render).
    _muscle_colorizer: MuscleColorizer | None = None

    def __init__(
        self,
        spasticity_level: int | str = 0,
        task: TaskParams | None = None,
        reward: RewardParams | None = None,
        twin: TwinParams | None = None,
        obs_keys: list[str] | tuple[str, ...] | None = None,
        obs_preset: str = "full",
        weighted_reward_keys: dict[str, float] | None = None,
        subject_noise: bool = True,
        reflex: str | ReflexConfig = "stretch",
        robustness: RobustnessParams | bool | None = None,
        seed: int | None = None,
        render_mode: str | None = None,
        **kwargs: Any,
    ) -> None:
        if kwargs:
            raise TypeError(f"MyoExoKneeEnv() got unexpected keyword arguments {sorted(kwargs)}")
        self.task = task if task is not None else TaskParams()
        reward = reward if reward is not None else RewardParams()
        if weighted_reward_keys is not None:
            reward = RewardParams(**{**reward.__dict__, "weights": dict(weighted_reward_keys)})
        self.reward_params = reward
        self.twin_params = twin if twin is not None else TwinParams()

        timestep_s = self.twin_params.timestep_s
        frame_skip = round(self.task.control_period_s / timestep_s)
        if frame_skip < 1 or not math.isclose(
            frame_skip * timestep_s, self.task.control_period_s, rel_tol=1e-9
        ):
            raise ValueError(
                f"control_period_s = {self.task.control_period_s} must be a whole multiple "
                f"of the physics timestep {timestep_s} s"
            )
        MyoGymnasiumEnv.__init__(self, frame_skip=frame_skip, render_mode=render_mode)
        EzPickle.__init__(
            self,
            spasticity_level=spasticity_level,
            task=task,
            reward=reward,
            twin=twin,
            obs_keys=obs_keys,
            obs_preset=obs_preset,
            weighted_reward_keys=weighted_reward_keys,
            subject_noise=subject_noise,
            reflex=reflex,
            robustness=robustness,
            seed=seed,
            render_mode=render_mode,
        )

        self.model, self._mj_spec = build_model(self.twin_params)
        self.data = mujoco.MjData(self.model)
        self._ctrl_dt = float(self.model.opt.timestep * frame_skip)
        self.mj_instability_termination = False  # instability truncates, see step()
        if obs_preset not in OBS_PRESETS:
            raise ValueError(f"obs_preset = {obs_preset!r}; accepted: {sorted(OBS_PRESETS)}")
        self.obs_preset = obs_preset if obs_keys is None else "custom"
        self.obs_keys = list(obs_keys or OBS_PRESETS[obs_preset])
        self.rwd_keys_wt = dict(self.reward_params.weights)
        self._resolve_indices()

        self._set_up_robustness(robustness, seed)
        self.spasticity = SpasticityStage(
            level=spasticity_level, subject_noise=subject_noise, reflex=reflex
        )
        self.add_ctrl_stage("spasticity", self.spasticity.apply, self.spasticity.reset)

        self._input_seed = seed
        gym.Env.reset(self, seed=seed)
        self._accessor = CpuEnvAccessor(self.model, self.data, self._ctrl_dt)
        self._clear_episode_state()
        pose_twin(self.model, self.data, knee_angle_deg=self.task.start_angle_deg)
        obs = self._obs_dict_to_vec(self._get_obs_dict(self._accessor))
        self.observation_space = self._unbounded_obs_space(obs.size)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    # ------------------------------------------------------------------ set-up
    def _resolve_indices(self) -> None:
        """Resolve every name once: the step gathers observations with index arrays."""
        m = self.model
        knee = m.joint(KNEE_JOINT)
        exo = m.joint(EXO_JOINT)
        self._knee_qadr = int(knee.qposadr[0])
        self._knee_dadr = int(knee.dofadr[0])
        self._exo_qadr = int(exo.qposadr[0])
        self._exo_dadr = int(exo.dofadr[0])
        self._exo_act = int(m.actuator(EXO_ACTUATOR).id)
        self._muscle_act_ind = m.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE
        self._knee_torque = CoupledJointTorque(m, KNEE_JOINT)
        self._ctrl = np.zeros(m.nu)

        names = [n for n in COUPLING_JOINTS if _has(m, mujoco.mjtObj.mjOBJ_JOINT, n)]
        self.coupling_joints = tuple(names)
        jids = [m.joint(n).id for n in names]
        self._coupling_qadr = np.array([m.jnt_qposadr[j] for j in jids], dtype=np.intp)
        self._coupling_dadr = np.array([m.jnt_dofadr[j] for j in jids], dtype=np.intp)
        half_range = np.array([0.5 * (m.jnt_range[j, 1] - m.jnt_range[j, 0]) for j in jids])
        coupling_scale = 1.0 / np.maximum(half_range, 1e-6)

        sensor_idx: list[int] = []
        for sensor in CUFF_OBS_KEYS.values():
            sid = m.sensor(sensor).id
            adr, dim = int(m.sensor_adr[sid]), int(m.sensor_dim[sid])
            sensor_idx.extend(range(adr, adr + dim))
        self._sensor_idx = np.array(sensor_idx, dtype=np.intp)

        ids = np.array([m.actuator(n).id for n in SPASTIC_MUSCLES], dtype=np.intp)
        self._spastic_ids = ids
        self._spastic_actadr = m.actuator_actadr[ids].astype(np.intp)
        f0 = np.abs(m.actuator_gainprm[ids, 2])
        lr = m.actuator_lengthrange[ids]
        span = np.maximum(lr[:, 1] - lr[:, 0], 1e-6)
        n = len(ids)

        # Layout of the raw observation buffer (physical units): key -> slice.
        nc = len(names)
        sizes = {**dict.fromkeys(_SCALAR_KEYS, 1), **dict.fromkeys(CUFF_OBS_KEYS, 3)}
        sizes.update(coupling_qpos=nc, coupling_qvel=nc)
        sizes.update(dict.fromkeys(_MUSCLE_KEYS, n))
        self._slices: dict[str, slice] = {}
        i = 0
        for key, size in sizes.items():
            self._slices[key] = slice(i, i + size)
            i += size
        self._raw_size = i
        # The raw entries after the scalars, in layout order, as (MjData field, indices):
        # _DataViews gathers them all with one index into the MjData's memory.
        self._gathered = (
            ("sensordata", self._sensor_idx),
            ("qpos", self._coupling_qadr),
            ("qvel", self._coupling_dadr),
            ("act", self._spastic_actadr),
            ("actuator_force", ids),
            ("actuator_length", ids),
            ("actuator_velocity", ids),
        )
        self._at = {key: sl.start for key, sl in self._slices.items()}  # key -> first index
        # the other keys of obs_dict and a getter of their views of raw (one C call)
        self._vector_keys = [k for k in self._slices if k not in _SCALAR_KEYS]
        self._vector_views = operator.itemgetter(*(self._slices[k] for k in self._vector_keys))
        # _add_info reads the scalars and the cuff sensors: the leading entries of the buffer
        self._info_len = max(self._slices[k].stop for k in (*_SCALAR_KEYS, *CUFF_OBS_KEYS))
        # raw buffer = (gathered values - offset) * gain: the muscle block [act, force,
        # length, velocity] is normalized, every other entry kept exactly ((x - 0) * 1 = x)
        self._raw_offset = np.zeros(i)
        self._raw_gain = np.ones(i)
        self._raw_offset[self._slices["spastic_length"]] = lr[:, 0]
        self._raw_gain[self._slices["spastic_force"]] = -1.0 / f0
        self._raw_gain[self._slices["spastic_length"]] = 1.0 / span
        self._raw_gain[self._slices["spastic_velocity"]] = 1.0 / span
        unknown = [k for k in self.obs_keys if k not in self._slices]
        if unknown:
            raise ValueError(f"unknown obs_keys {unknown}; accepted: {list(self._slices)}")

        scales = {k: np.full(sizes[k], OBS_SCALES.get(k, 1.0)) for k in sizes}
        scales["coupling_qpos"] = coupling_scale
        scales["coupling_qvel"] = 0.1 * coupling_scale
        self._vec_idx = np.concatenate(
            [np.arange(self._raw_size)[self._slices[k]] for k in self.obs_keys]
        )
        self._vec_scale = np.concatenate([scales[k] for k in self.obs_keys])
        self._target_rad = math.radians(self.task.target_angle_deg)
        self._half_timestep_s = 0.5 * float(m.opt.timestep)
        self._views: _DataViews | None = None
        self._stages_seen: tuple = ()  # see _run_ctrl_stages
        self._stage_applies: tuple = ()

    def _set_up_robustness(self, robustness: RobustnessParams | bool | None, seed: Any) -> None:
        if robustness is True:
            robustness = RobustnessParams()
        elif robustness is False:
            robustness = None
        if robustness is not None and not isinstance(robustness, RobustnessParams):
            raise ValueError(
                f"robustness = {robustness!r}: expected a RobustnessParams, True, False or None"
            )
        self.robustness: RobustnessParams | None = robustness
        self.twin_perturbation: TwinPerturbation | None = None
        self._sensor: SensorModel | None = None
        self.twin_draw: dict[str, Any] = {}
        self._robust_rng = np.random.default_rng(seed)
        if robustness is None:
            return
        m = self.model
        self.twin_perturbation = TwinPerturbation(
            m,
            robustness,
            self.coupling_joints,
            COUPLING_JOINTS[0],
            STRAP_EQUALITY if _has(m, mujoco.mjtObj.mjOBJ_EQUALITY, STRAP_EQUALITY) else None,
            EXO_ACTUATOR,
        )
        steps = robustness.latency_s / self._ctrl_dt
        if abs(steps - round(steps)) > 1e-6:
            raise ValueError(
                f"robustness.latency_s = {robustness.latency_s} s must be a whole number of "
                f"control periods ({self._ctrl_dt} s)"
            )
        std = np.zeros(self._raw_size)
        for key, value in robustness.noise_std:
            if key not in self._slices:
                raise ValueError(
                    f"robustness.noise_std names unknown key {key!r}; "
                    f"accepted: {list(self._slices)}"
                )
            std[self._slices[key]] = value * np.abs(self._raw_gain[self._slices[key]])
        self._sensor = SensorModel(std, round(steps))

    def _clear_episode_state(self) -> None:
        self._command = 0.0
        self._prev_command = 0.0
        self._prev_knee_vel = 0.0
        self._prev_tau_knee = 0.0
        self._steps = 0
        self._episode_steps = self.task.episode_steps
        self._subject: dict[str, float] = {}

    # ------------------------------------------------------------------ properties
    @property
    def dt(self) -> float:
        """Control period (s)."""
        return self._ctrl_dt

    @property
    def level(self) -> int:
        """Spasticity level of the current subject."""
        return int(self.spasticity.level)

    @property
    def target_angle_deg(self) -> float:
        """Target knee flexion (deg)."""
        return self.task.target_angle_deg

    @property
    def episode_steps(self) -> int:
        """Control steps per episode."""
        return self.task.episode_steps

    # ------------------------------------------------------------------ observation
    def _data_views(self) -> _DataViews:
        """What the step reads from ``self.data`` (:class:`_DataViews`), set up once per
        ``MjData`` object: an ``MjData`` array attribute is a view of memory that lives as
        long as the ``MjData``, so caching it saves a lookup and a new view per read."""
        views = self._views
        if views is None or views.data is not self.data:
            views = self._views = _DataViews.of(self.data, self._gathered)
        return views

    def _gather_raw(self, views: _DataViews, forces_knee_rad: float | None = None) -> np.ndarray:
        """Every observed quantity, in physical units, in a freshly allocated buffer.

        Layout ``self._slices``: the scalars of ``_SCALAR_KEYS``, then the cuff sensors,
        coupling joints and spastic muscles (``self._gathered``, one index into the data's
        buffer), the muscle block normalized. Everything is read from ``views`` as it
        stands (see :meth:`step` for what that means in time after a step).

        Args:
            views: What to read (:meth:`_data_views` or another ``MjData``'s).
            forces_knee_rad: Knee angle (rad) of the state the data's forces were computed
                at, for the muscle torque's knee transmission (default: the current angle).
        """
        qpos, qvel, qfrc = views.qpos, views.qvel, views.qfrc_actuator
        time_s = views.data.time
        knee_rad = qpos.item(self._knee_qadr)
        exo_torque_nm = qfrc.item(self._exo_dadr)
        if forces_knee_rad is None:
            forces_knee_rad = knee_rad
        muscle_torque_nm = self._knee_torque.torque_at(forces_knee_rad, qfrc)
        scalars = (  # _SCALAR_KEYS, in order
            time_s,
            knee_rad,
            qvel.item(self._knee_dadr),
            qpos.item(self._exo_qadr),
            qvel.item(self._exo_dadr),
            self._target_rad,
            knee_rad - self._target_rad,
            self._command,
            exo_torque_nm,
            muscle_torque_nm,
            abs(exo_torque_nm) + abs(muscle_torque_nm),
            time_s / self.task.episode_duration_s,
        )
        # then the cuff sensors, coupling joints, muscles: one index into the data's buffer
        raw = np.concatenate((scalars, views.buffer[views.gather_index]))
        raw -= self._raw_offset
        raw *= self._raw_gain
        return raw

    def _split_raw(self, raw: np.ndarray) -> dict[str, np.ndarray]:
        """``obs_dict``: one view of *raw* per key (a new buffer per step: stored dicts are
        never overwritten)."""
        # The scalars' 1-element views: iterating a column view makes them faster than
        # slicing. The lengths match by construction (zip(strict=True) costs ~1 us here).
        obs_dict = dict(zip(_SCALAR_KEYS, raw[: len(_SCALAR_KEYS), None]))  # noqa: B905
        obs_dict.update(zip(self._vector_keys, self._vector_views(raw)))  # noqa: B905
        return obs_dict

    def _get_obs_dict(self, accessor: CpuEnvAccessor) -> dict[str, np.ndarray]:
        """Every quantity the env observes, in physical units (see the module docstring),
        read from ``accessor.data`` as it stands.

        For all of it to refer to the current state, the data's derived quantities must be
        those of its state (true after ``reset``, ``forward()``, ``set_state`` or an
        ``mj_forward``). Right after a ``step`` they are the last substep's (see
        :meth:`step`, whose own observation evaluates the knee transmission at that substep's
        angle; this path evaluates it at the current angle).
        """
        d = accessor.data
        views = self._data_views() if d is self.data else _DataViews.of(d, self._gathered)
        return self._split_raw(self._gather_raw(views))

    def _raw_to_vec(self, raw: np.ndarray) -> np.ndarray:
        """The observation vector: the ``obs_keys`` entries of *raw*, each times its scale."""
        return (raw[self._vec_idx] * self._vec_scale).astype(np.float32)

    def _obs_dict_to_vec(self, obs_dict: dict[str, np.ndarray]) -> np.ndarray:
        """Flatten the ``obs_keys`` entries, each times its fixed scale (float32)."""
        raw = obs_dict["time"].base
        if raw is None or raw.size != self._raw_size:  # a dict not made by _get_obs_dict
            raw = np.concatenate([np.atleast_1d(obs_dict[k]).ravel() for k in self._slices])
        return self._raw_to_vec(raw)

    # ------------------------------------------------------------------ reward
    def get_reward_dict(self, obs_dict: dict[str, np.ndarray]) -> dict[str, Any]:
        """The paper's reward terms (docs/reference.md section 3) and their weighted sum."""
        return self._reward_terms(
            float(obs_dict["error_rad"][0]),
            float(obs_dict["knee_vel_rad_s"][0]),
            float(obs_dict["interaction_torque_nm"][0]),
        )

    def _reward_terms(
        self, error_rad: float, knee_vel_rad_s: float, interaction_torque_nm: float
    ) -> dict[str, Any]:
        """:meth:`get_reward_dict` from the three observed scalars it depends on."""
        p = self.reward_params
        e = error_rad
        tau = interaction_torque_nm
        d_tau = (tau - self._prev_tau_knee) / p.torque_scale_nm
        inter = d_tau * d_tau
        if tau > p.torque_threshold_nm:
            inter += (tau / p.torque_scale_nm) ** 2
        abs_e = abs(e)
        rwd = {
            "pose": math.exp(-e * e / (2.0 * p.sigma_rad**2)) - abs_e,
            "bonus": p.bonus
            if abs_e < p.bonus_error_rad and abs(knee_vel_rad_s) < p.bonus_vel_rad_s
            else 0.0,
            "inter": inter,
            "vel": abs(knee_vel_rad_s - self._prev_knee_vel),
            "act": (self._command - self._prev_command) ** 2,
            "sparse": -abs_e,
            "solved": abs_e < p.bonus_error_rad,
            "done": False,
        }
        dense = 0.0
        for key, weight in self.rwd_keys_wt.items():
            dense += weight * rwd[key]
        rwd["dense"] = dense
        return rwd

    # ------------------------------------------------------------------ gymnasium API
    def _check_action(self, action: Any) -> float:
        if type(action) is np.ndarray and action.shape == (1,) and action.dtype.kind == "f":
            u = float(action[0])  # fast path: what an agent sends
        else:
            a = np.asarray(action, dtype=np.float64)
            if a.size != 1 or a.ndim > 1:
                raise ValueError(
                    f"action must have shape (1,) (the exo motor command), got shape {a.shape}"
                )
            u = float(a.reshape(()))
        if not math.isfinite(u):
            raise ValueError(f"action must be finite, got {u}; accepted range [-1, 1]")
        return min(1.0, max(-1.0, u))

    def _run_ctrl_stages(self, ctrl: np.ndarray) -> np.ndarray:
        """Apply the installed stages to *ctrl* (:class:`CtrlStageHost`'s pipeline).

        The stage list is sorted once and kept until a stage is added or removed (the
        installed entries are compared by identity each step, which is cheaper than the
        host's sort).
        """
        installed = tuple(self._stage_store().values())
        if installed != self._stages_seen:
            self._stages_seen = installed
            self._stage_applies = tuple(apply for _, (_, apply, _) in self._stages_in_order())
        for apply in self._stage_applies:
            ctrl = apply(self, ctrl)
        return ctrl

    def step(
        self, action: Any, **kwargs: Any
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the exo command for one control period and return the 5-tuple.

        Physics: exactly ``mj_step(model, data, frame_skip)`` with this step's ``ctrl``
        (run as ``frame_skip - 1`` substeps and a last one, to note the knee angle in
        between; the state trajectory is bit-identical to raw ``mj_step``), and no extra
        ``mj_forward``: the returned quantities are what the state and the last substep
        provide. With ``t = info["time_s"]`` and ``h`` the physics
        timestep (the last substep integrated the state from ``t - h`` to ``t``):

        * **state, at t** (after the step): ``time``, ``time_frac``, ``knee_angle_rad``,
          ``knee_vel_rad_s``, ``exo_angle_rad``, ``exo_vel_rad_s``, ``error_rad``,
          ``coupling_qpos``, ``coupling_qvel``, ``spastic_act`` (MuJoCo's activation
          state) and the info entries made from them (``knee_angle_deg``, ...).
        * **forces and muscle paths, at t - h** (the state the last substep started from,
          with this step's command applied): ``exo_torque_nm``, ``muscle_knee_torque_nm``
          (its knee transmission is evaluated at the knee angle of t - h too),
          ``interaction_torque_nm``, the four cuff force/torque sensors, ``spastic_force``,
          ``spastic_length``, ``spastic_velocity``. These are what MuJoCo computed in the
          last substep (``actuator_force``, ``qfrc_actuator``, ``sensordata``, ...): the
          forces that acted over ``[t - h, t]``, all of one instant, equal to what
          ``mj_forward`` of the state at t - h gives (tests/test_envs.py checks it).
        * ``command``: this step's (clipped) command; ``sc_total``: the reflex excitation
          applied over the step, computed at the step start from the knee state the reflex
          reads (delayed by the reflex model's transmission delay).

        After ``reset`` everything refers to the initial state (``mj_forward``, zero
        command). If MuJoCo reset the data during the step (NaN/inf or a huge value:
        ``info["unstable"]``, the episode truncates), an ``mj_forward`` of the reset state
        makes every quantity refer to that state, so the observation stays finite.
        """
        u = self._check_action(action)
        self._prev_command, self._command = self._command, u
        views = self._data_views()
        ctrl = self._ctrl
        ctrl.fill(0.0)
        ctrl[self._exo_act] = u
        views.ctrl[:] = self._run_ctrl_stages(ctrl)
        m, d = self.model, self.data
        t_expected_s = d.time + self._ctrl_dt
        if self.frame_skip > 1:
            mujoco.mj_step(m, d, self.frame_skip - 1)
        forces_knee_rad = views.qpos.item(self._knee_qadr)  # knee angle at t - h
        mujoco.mj_step(m, d)
        self._steps += 1
        # MuJoCo checks every substep for NaN/inf/huge qpos, qvel or qacc and then resets
        # the data (time -> 0, finite state): a time that went back is an instability.
        unstable = d.time < t_expected_s - self._half_timestep_s
        if unstable:
            mujoco.mj_forward(m, d)
            forces_knee_rad = views.qpos.item(self._knee_qadr)

        raw = self._gather_raw(views, forces_knee_rad)
        obs_dict = self._split_raw(raw)
        values = raw[: self._info_len].tolist()  # python floats: cheapest for scalar math
        at = self._at
        knee_vel = values[at["knee_vel_rad_s"]]
        tau = values[at["interaction_torque_nm"]]
        rwd_dict = self._reward_terms(values[at["error_rad"]], knee_vel, tau)
        info = dict(rwd_dict)
        del info["dense"], info["done"]
        info["obs_dict"] = obs_dict
        info["rwd_dict"] = rwd_dict
        self._prev_knee_vel = knee_vel
        self._prev_tau_knee = tau
        truncated = unstable or self._steps >= self._episode_steps
        sensed = raw if self._sensor is None else self._sensor.measure(raw, self._robust_rng)
        self._add_info(info, values, unstable, sensed)
        if self.mujoco_render_frames:
            self.mj_render()
        reward = float(rwd_dict["dense"])
        return self._raw_to_vec(sensed), reward, bool(rwd_dict["done"]), truncated, info

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: new subject (seeded), knee at the start angle, exo at rest."""
        gym.Env.reset(self, seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        self._clear_episode_state()
        self._run_reset_stages()  # the spasticity stage draws this episode's subject
        self._subject = {
            k: float(v) for k, v in dataclasses.asdict(self.spasticity.subject).items()
        }
        noise = self.task.start_angle_noise_deg
        start = self.task.start_angle_deg + float(self.np_random.uniform(-noise, noise))
        if self.robustness is not None and seed is not None:
            # the perturbed twin has its own stream, so subjects stay those of the nominal env
            self._robust_rng = np.random.default_rng([int(seed), 0x0B057])
        if self.twin_perturbation is not None:
            self.twin_draw = self.twin_perturbation.apply(self._robust_rng)
        pose_twin(self.model, self.data, knee_angle_deg=start)
        mujoco.mj_forward(self.model, self.data)
        raw = self._gather_raw(self._data_views())
        sensed = raw if self._sensor is None else self._sensor.reset(raw, self._robust_rng)
        obs = self._ensure_obs_gymnasium_compliant(self._raw_to_vec(sensed))
        values = raw[: self._info_len].tolist()
        self._prev_tau_knee = values[self._at["interaction_torque_nm"]]
        info: dict[str, Any] = {}
        self._add_info(info, values, False, sensed)
        if self.twin_draw:
            info["twin_draw"] = dict(self.twin_draw)
        return obs, info

    def _add_info(
        self, info: dict[str, Any], values: list[float], unstable: bool, sensed: np.ndarray
    ):
        """Per-step quantities in clinical units (documented in the README's info table).

        Args:
            info: The dict to complete (in place; returned).
            values: The leading entries of the raw observation buffer (the scalars and the
                cuff sensors) as python floats.
            unstable: Whether MuJoCo reset the data during the step.
            sensed: The raw buffer as the sensors report it (the true one unless
                ``robustness`` adds noise and latency): ``measured_*`` entries.
        """
        at = self._at
        knee_deg = math.degrees(values[at["knee_angle_rad"]])
        exo_deg = math.degrees(values[at["exo_angle_rad"]])
        if self._sensor is None:
            measured_knee_deg, measured_exo_deg = knee_deg, exo_deg
        else:
            measured_knee_deg = math.degrees(sensed.item(at["knee_angle_rad"]))
            measured_exo_deg = math.degrees(sensed.item(at["exo_angle_rad"]))
        target_deg = self.task.target_angle_deg
        thigh, shank = at["thigh_cuff_force_n"], at["shank_cuff_force_n"]
        stage = self.spasticity
        info.update(
            time_s=values[at["time"]],
            knee_angle_deg=knee_deg,
            knee_vel_rad_s=values[at["knee_vel_rad_s"]],
            exo_angle_deg=exo_deg,
            measured_knee_angle_deg=measured_knee_deg,
            measured_exo_angle_deg=measured_exo_deg,
            target_angle_deg=target_deg,
            error_deg=knee_deg - target_deg,
            command=self._command,
            exo_torque_nm=values[at["exo_torque_nm"]],
            muscle_knee_torque_nm=values[at["muscle_knee_torque_nm"]],
            interaction_torque_nm=values[at["interaction_torque_nm"]],
            thigh_cuff_force_n=math.hypot(values[thigh], values[thigh + 1], values[thigh + 2]),
            shank_cuff_force_n=math.hypot(values[shank], values[shank + 1], values[shank + 2]),
            sc_total=float(stage.last_sc_total),
            level=int(stage.level),
            subject=self._subject,
            unstable=unstable,
        )
        return info

    def render(self, **kwargs: Any) -> Any:
        """MyoSuite's ``render()`` (camera :attr:`render_camera`, 640x480 unless ``kwargs``
        say otherwise), with every muscle coloured by its activation first (rest colour to
        red, :class:`~myoexo.model.scene.MuscleColorizer`)."""
        if self.render_mode is not None:
            if self._muscle_colorizer is None:
                self._muscle_colorizer = MuscleColorizer(self.model)
            self._muscle_colorizer(self.data)
        return super().render(**kwargs)

    def get_proprioception(self) -> tuple:
        """``(time, vector, dict)`` of what the exo itself senses (encoder, torque, cuffs)."""
        keys = ("exo_angle_rad", "exo_vel_rad_s", "exo_torque_nm", *CUFF_OBS_KEYS)
        od = self._get_obs_dict(self._accessor)
        pdict = {k: od[k] for k in keys}
        return float(self.data.time), np.concatenate([np.ravel(v) for v in pdict.values()]), pdict


def _has(model: mujoco.MjModel, obj: mujoco.mjtObj, name: str) -> bool:
    return mujoco.mj_name2id(model, obj, name) >= 0


class _DataViews(NamedTuple):
    """What the env reads from one ``MjData`` every step, looked up once.

    ``qpos``, ``qvel``, ``ctrl``, ``qfrc_actuator`` are the data's arrays (views of its
    memory, valid as long as ``data``). ``buffer[gather_index]`` gathers the array entries of
    the observation (``MyoExoKneeEnv._gathered``) in one numpy call instead of one call per
    array and a concatenation: MuJoCo allocates every per-model array of an ``mjData`` from
    one main buffer (``mjData.buffer``, ``nbuffer`` bytes, "all pointers point in it"), so a
    strided float64 view starting at the lowest of the arrays spans them all. ``buffer`` is
    read-only, its base is one of ``data``'s own arrays (it keeps ``data`` alive), and only
    the gathered entries, which lie inside their arrays, are ever read.
    """

    data: mujoco.MjData
    qpos: np.ndarray
    qvel: np.ndarray
    ctrl: np.ndarray
    qfrc_actuator: np.ndarray
    buffer: np.ndarray
    gather_index: np.ndarray

    @classmethod
    def of(cls, data: mujoco.MjData, gathered: Sequence[tuple[str, np.ndarray]]) -> _DataViews:
        """Views of *data*, gathering ``[(field, indices), ...]`` in that order.

        Raises:
            RuntimeError: If the arrays do not lie in one buffer of ``data.nbuffer`` bytes.
        """
        arrays = [getattr(data, field) for field, _ in gathered]
        addrs = [a.__array_interface__["data"][0] for a in arrays]
        lowest = int(np.argmin(addrs))
        start = addrs[lowest]
        end = max(addr + a.nbytes for addr, a in zip(addrs, arrays, strict=True))
        in_one_buffer = end - start <= data.nbuffer and all(
            a.dtype == np.float64 and a.ndim == 1 and (addr - start) % 8 == 0
            for addr, a in zip(addrs, arrays, strict=True)
        )
        if not in_one_buffer:
            raise RuntimeError(f"MjData arrays {[f for f, _ in gathered]} are not in one buffer")
        buffer = np.lib.stride_tricks.as_strided(
            arrays[lowest], shape=((end - start) // 8,), strides=(8,), writeable=False
        )
        gather_index = np.concatenate(
            [(addr - start) // 8 + idx for addr, (_, idx) in zip(addrs, gathered, strict=True)]
        ).astype(np.intp)
        return cls(data, data.qpos, data.qvel, data.ctrl, data.qfrc_actuator, buffer, gather_index)
