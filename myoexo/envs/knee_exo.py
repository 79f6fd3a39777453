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
from typing import Any, ClassVar

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.utils import EzPickle
from myosuite.envs.gymnasium_env import CpuEnvAccessor, MyoGymnasiumEnv
from myosuite.envs.muscle_stages import CtrlStageHost

from myoexo.envs.config import RewardParams, TaskParams
from myoexo.model import (
    COUPLING_JOINTS,
    CUFF_SENSORS,
    EXO_ACTUATOR,
    EXO_JOINT,
    KNEE_JOINT,
    TwinParams,
    build_model,
    pose_twin,
)
from myoexo.model.joint_torque import CoupledJointTorque
from myoexo.model.scene import DEFAULT_CAMERA, MuscleColorizer
from myoexo.reflex import ReflexConfig
from myoexo.spasticity import SPASTIC_MUSCLES, SpasticityStage

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
        obs_keys: Observation entries (default :data:`DEFAULT_OBS_KEYS`).
        weighted_reward_keys: Shortcut overriding ``reward.weights``.
        subject_noise: Draw an individual subject (10 % variability) at every reset;
            ``False`` keeps Table I's nominal subject of the level (e.g. for PID tuning).
        reflex: Reflex model (:mod:`myoexo.reflex`): ``"stretch"`` (the calibrated stretch
            reflex with a 20 ms delay, default), ``"uniform"`` (the paper's ``SC_total`` on
            all 11 muscles, no delay: the first reading) or a ``ReflexConfig``.
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
        weighted_reward_keys: dict[str, float] | None = None,
        subject_noise: bool = True,
        reflex: str | ReflexConfig = "stretch",
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
            weighted_reward_keys=weighted_reward_keys,
            subject_noise=subject_noise,
            reflex=reflex,
            seed=seed,
            render_mode=render_mode,
        )

        self.model, self._mj_spec = build_model(self.twin_params)
        self.data = mujoco.MjData(self.model)
        self._ctrl_dt = float(self.model.opt.timestep * frame_skip)
        self.mj_instability_termination = False  # instability truncates, see step()
        self.obs_keys = list(obs_keys or self.DEFAULT_OBS_KEYS)
        self.rwd_keys_wt = dict(self.reward_params.weights)
        self._resolve_indices()

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
        # muscle block = (stacked [act, force, length, velocity] - offset) * gain
        self._muscle_offset = np.concatenate([np.zeros(n), np.zeros(n), lr[:, 0], np.zeros(n)])
        self._muscle_gain = np.concatenate([np.ones(n), -1.0 / f0, 1.0 / span, 1.0 / span])

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

    def _clear_episode_state(self) -> None:
        self._command = 0.0
        self._prev_command = 0.0
        self._prev_knee_vel = 0.0
        self._prev_tau_knee = 0.0
        self._steps = 0
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
    def _get_obs_dict(self, accessor: CpuEnvAccessor) -> dict[str, np.ndarray]:
        """Every quantity the env observes, in physical units (see the module docstring).

        The values are views into one freshly allocated buffer per call (gathered with
        index arrays resolved at construction), so stored dicts are never overwritten.
        """
        d = accessor.data
        knee = d.qpos[self._knee_qadr]
        exo_torque = d.qfrc_actuator[self._exo_dadr]
        muscle_torque = self._knee_torque(d)
        t = d.time
        ids = self._spastic_ids
        scalars = (
            t,
            knee,
            d.qvel[self._knee_dadr],
            d.qpos[self._exo_qadr],
            d.qvel[self._exo_dadr],
            self._target_rad,
            knee - self._target_rad,
            self._command,
            exo_torque,
            muscle_torque,
            abs(exo_torque) + abs(muscle_torque),
            t / self.task.episode_duration_s,
        )
        muscles = np.concatenate(
            (
                d.act[self._spastic_actadr],
                d.actuator_force[ids],
                d.actuator_length[ids],
                d.actuator_velocity[ids],
            )
        )
        muscles -= self._muscle_offset
        muscles *= self._muscle_gain
        raw = np.concatenate(
            (
                scalars,
                d.sensordata[self._sensor_idx],
                d.qpos[self._coupling_qadr],
                d.qvel[self._coupling_dadr],
                muscles,
            )
        )
        return {key: raw[sl] for key, sl in self._slices.items()}

    def _obs_dict_to_vec(self, obs_dict: dict[str, np.ndarray]) -> np.ndarray:
        """Flatten the ``obs_keys`` entries, each times its fixed scale (float32)."""
        raw = obs_dict["time"].base
        if raw is None or raw.size != self._raw_size:  # a dict not made by _get_obs_dict
            raw = np.concatenate([np.atleast_1d(obs_dict[k]).ravel() for k in self._slices])
        return (raw[self._vec_idx] * self._vec_scale).astype(np.float32)

    # ------------------------------------------------------------------ reward
    def get_reward_dict(self, obs_dict: dict[str, np.ndarray]) -> dict[str, Any]:
        """The paper's reward terms (docs/reference.md section 3) and their weighted sum."""
        p = self.reward_params
        e = float(obs_dict["error_rad"][0])
        knee_vel = float(obs_dict["knee_vel_rad_s"][0])
        tau = float(obs_dict["interaction_torque_nm"][0])
        d_tau = (tau - self._prev_tau_knee) / p.torque_scale_nm
        inter = d_tau * d_tau
        if tau > p.torque_threshold_nm:
            inter += (tau / p.torque_scale_nm) ** 2
        rwd = {
            "pose": math.exp(-e * e / (2.0 * p.sigma_rad**2)) - abs(e),
            "bonus": p.bonus
            if abs(e) < p.bonus_error_rad and abs(knee_vel) < p.bonus_vel_rad_s
            else 0.0,
            "inter": inter,
            "vel": abs(knee_vel - self._prev_knee_vel),
            "act": (self._command - self._prev_command) ** 2,
            "sparse": -abs(e),
            "solved": abs(e) < p.bonus_error_rad,
            "done": False,
        }
        rwd["dense"] = sum(w * rwd[k] for k, w in self.rwd_keys_wt.items())
        return rwd

    # ------------------------------------------------------------------ gymnasium API
    def _check_action(self, action: Any) -> float:
        a = np.asarray(action, dtype=np.float64)
        if a.size != 1 or a.ndim > 1:
            raise ValueError(
                f"action must have shape (1,) (the exo motor command), got shape {a.shape}"
            )
        u = float(a.reshape(()))
        if not math.isfinite(u):
            raise ValueError(f"action must be finite, got {u}; accepted range [-1, 1]")
        return min(1.0, max(-1.0, u))

    def step(
        self, action: Any, **kwargs: Any
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the exo command for one control period and return the 5-tuple.

        Physics: the position/velocity stages of the current state are valid at every step
        start (``reset``, ``forward`` and the end of each step run ``mj_forward``), so the
        first substep is ``mj_step2`` (actuation with the new ``ctrl``, acceleration,
        integration) instead of a full ``mj_step``; the remaining substeps are ``mj_step``
        and a final ``mj_forward`` makes every derived quantity (sensors, muscle forces)
        consistent with the returned state. The trajectory is the one ``mj_step`` x
        ``frame_skip`` gives, without computing the first substep's kinematics twice.
        """
        u = self._check_action(action)
        self._prev_command, self._command = self._command, u
        ctrl = self._ctrl
        ctrl[:] = 0.0
        ctrl[self._exo_act] = u
        m, d = self.model, self.data
        d.ctrl[:] = self._run_ctrl_stages(ctrl)
        t_expected = d.time + self._ctrl_dt
        mujoco.mj_step2(m, d)
        if self.frame_skip > 1:
            mujoco.mj_step(m, d, self.frame_skip - 1)
        mujoco.mj_forward(m, d)
        self._steps += 1
        # MuJoCo checks every substep for NaN/inf/huge qpos, qvel or qacc and then resets
        # the data (time -> 0, finite state): a time that went back is an instability.
        unstable = d.time < t_expected - 0.5 * m.opt.timestep

        obs_dict = self._get_obs_dict(self._accessor)
        rwd_dict = self.get_reward_dict(obs_dict)
        obs = self._obs_dict_to_vec(obs_dict)
        info = {k: v for k, v in rwd_dict.items() if k not in ("dense", "done")}
        info["obs_dict"] = obs_dict
        info["rwd_dict"] = rwd_dict
        self._prev_knee_vel = float(obs_dict["knee_vel_rad_s"][0])
        self._prev_tau_knee = float(obs_dict["interaction_torque_nm"][0])
        truncated = unstable or self._steps >= self.task.episode_steps
        self._add_info(info, obs_dict, unstable)
        if self.mujoco_render_frames:
            self.mj_render()
        return obs, float(rwd_dict["dense"]), bool(rwd_dict["done"]), truncated, info

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
        pose_twin(self.model, self.data, knee_angle_deg=start)
        mujoco.mj_forward(self.model, self.data)
        obs_dict = self._get_obs_dict(self._accessor)
        obs = self._ensure_obs_gymnasium_compliant(self._obs_dict_to_vec(obs_dict))
        self._prev_tau_knee = float(obs_dict["interaction_torque_nm"][0])
        info: dict[str, Any] = {}
        self._add_info(info, obs_dict, False)
        return obs, info

    def _add_info(self, info: dict[str, Any], obs_dict: dict[str, np.ndarray], unstable: bool):
        """Per-step quantities in clinical units (documented in the README's info table)."""
        knee_deg = math.degrees(obs_dict["knee_angle_rad"][0])
        stage = self.spasticity
        info.update(
            time_s=float(obs_dict["time"][0]),
            knee_angle_deg=knee_deg,
            knee_vel_rad_s=float(obs_dict["knee_vel_rad_s"][0]),
            exo_angle_deg=math.degrees(obs_dict["exo_angle_rad"][0]),
            target_angle_deg=self.task.target_angle_deg,
            error_deg=knee_deg - self.task.target_angle_deg,
            command=self._command,
            exo_torque_nm=float(obs_dict["exo_torque_nm"][0]),
            muscle_knee_torque_nm=float(obs_dict["muscle_knee_torque_nm"][0]),
            interaction_torque_nm=float(obs_dict["interaction_torque_nm"][0]),
            thigh_cuff_force_n=math.hypot(*obs_dict["thigh_cuff_force_n"]),
            shank_cuff_force_n=math.hypot(*obs_dict["shank_cuff_force_n"]),
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
