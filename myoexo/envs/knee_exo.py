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

Observation (``obs_keys``, flattened in the order given): each entry of ``obs_dict`` is in
the physical unit its name gives and is multiplied by a fixed scale in the vector. The keys,
their meaning and unit are defined once in :data:`myoexo.envs.observation.OBS_KEY_DOCS`
(scales: :data:`~myoexo.envs.observation.OBS_SCALES`); the documentation site's
environment page (``docs/envs.md``) shows them as a table with sizes and scales.

Timing after a step (details in :meth:`MyoExoKneeEnv.step`): angles, velocities, activations
and time are the state after the step; torques, cuff sensors and muscle force/length/velocity
are those MuJoCo computed in the step's last physics substep (one timestep earlier).

Reward (MyoSuite ``weighted_reward_keys``; docs/reference.md section 3): the terms are
:data:`myoexo.envs.reward.REWARD_TERMS`, their default weights
:data:`~myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`. Penalties are magnitudes with negative
weights.

Interaction torque (the paper's "sum of the torques applied at the knee: exo actuation and
spastic reflexes"): the magnitude of the torque the shank strap transmits to the human knee,
along its coupled motion (the strap weld's constraint force, :func:`myoexo.model
.strap_knee_torque`). Of four readings compared on the paper's PID and the shipped policy
(docs/reference.md section 5: also ``|exo| + |muscle|``, the signed sum of exo and muscle
torques, and the exo torque alone), it is what the exo applies to the leg, on the study's
scale (the PID peaks at about 102 Nm with a 100 Nm motor; the torque the straps can pass on
is bounded, :mod:`myoexo.model.strap_bound`). The others stay in ``info``:
``cuff_knee_torque_nm`` (signed), ``torque_abs_sum_nm``, ``torque_signed_sum_nm``,
``exo_torque_nm``; ``misalignment_deg`` is the knee angle less the exo hinge angle.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping
from typing import Any, ClassVar, NamedTuple

import gymnasium as gym
import mujoco
import numpy as np
from gymnasium.envs.registration import EnvSpec
from gymnasium.utils import EzPickle
from myosuite.envs.gymnasium_env import CpuEnvAccessor, MyoGymnasiumEnv
from myosuite.envs.muscle_stages import CtrlStage, CtrlStageHost, ResetStage

from myoexo.envs.config import (
    DEFAULT_REWARD_WEIGHTS,
    GENTLENESS_RANGE,
    TASK_FIELDS,
    RewardParams,
    TaskParams,
    check_gentleness,
)
from myoexo.envs.observation import (
    CUFF_OBS_KEYS,
    DEFAULT_OBS_KEYS,
    EXO_SENSOR_OBS_KEYS,
    OBS_PRESETS,
    OBS_SCALES,
    DataViews,
    ObsLayout,
)
from myoexo.envs.reward import reward_dict
from myoexo.envs.robustness import (
    RobustnessParams,
    SensorModel,
    TwinPerturbation,
    robustness_params,
    twin_perturbation,
)
from myoexo.envs.twin import Twin, frame_skip_of
from myoexo.model import TwinParams, build_model, pose_twin
from myoexo.model.passive_knee import PassiveKneeScaler
from myoexo.model.scene import DEFAULT_CAMERA, MuscleColorizer
from myoexo.spasticity.personal import PersonalSubject, load_subject
from myoexo.spasticity.reflex import DEFAULT_REFLEX
from myoexo.spasticity.registry import ReflexModel, reflex_label
from myoexo.spasticity.stage import STAGE_NAME, SpasticityStage

__all__ = [
    "CUFF_OBS_KEYS",
    "DEFAULT_OBS_KEYS",
    "EXO_SENSOR_OBS_KEYS",
    "OBS_PRESETS",
    "OBS_SCALES",
    "MyoExoKneeEnv",
]

#: The exo-sensed entries of :meth:`MyoExoKneeEnv.get_proprioception`.
_PROPRIOCEPTION_KEYS = ("exo_angle_rad", "exo_vel_rad_s", "exo_torque_nm", *CUFF_OBS_KEYS)


class _InfoAt(NamedTuple):
    """Positions in the raw observation buffer of the entries a step and its info read."""

    time: int
    knee_angle_rad: int
    knee_vel_rad_s: int
    exo_angle_rad: int
    exo_vel_rad_s: int
    error_rad: int
    exo_torque_nm: int
    muscle_knee_torque_nm: int
    interaction_torque_nm: int
    cuff_knee_torque_nm: int
    thigh_cuff_force_n: int
    shank_cuff_force_n: int


class MyoExoKneeEnv(CtrlStageHost, MyoGymnasiumEnv, EzPickle):
    """Exo-driven knee extension of a seated, spastic MyoSuite leg.

    Args:
        spasticity_level: Modified Ashworth level 0..3, or ``"random"`` (uniform per reset,
            as the paper trains). A new subject (parameters with 10 % variability) is
            drawn from the env's seeded RNG at every reset.
        reward_weights: Overrides of the reward weights, by key
            (:data:`~myoexo.envs.config.DEFAULT_REWARD_WEIGHTS`: MyoSuite's
            ``weighted_reward_keys``); an unknown key raises ``ValueError``.
        obs_preset: Named set of ``obs_keys`` (:data:`OBS_PRESETS`): ``"full"`` (default,
            :data:`DEFAULT_OBS_KEYS`: the twin's whole state, muscles included) or ``"exo"``
            (:data:`EXO_SENSOR_OBS_KEYS`: what the exoskeleton itself measures). Ignored
            when ``obs_keys`` is given.
        obs_keys: Observation entries (default: those of ``obs_preset``).
        subject_noise: Draw an individual subject at every reset: from the population (10 %
            variability) or, with *subject*, from the personal fit's uncertainty.
            ``False`` keeps Table I's nominal subject of the level (e.g. for PID tuning), or
            the personal fit's point. ``None`` (default): ``True`` for the population,
            ``False`` for a personal subject.
        subject: A personal twin: the report of ``myoexo twin fit-subject`` (a path) or a
            :class:`~myoexo.spasticity.personal.PersonalSubject`. Its fitted reflex record
            and passive knee (the scales of the knee's springs and damping) replace the
            population's subject; the env's level must be the one its fit used, and the
            reflex model the one it was fitted with. ``None``: the population.
        reflex: Reflex model: a registered name (:func:`~myoexo.spasticity.reflex_names`;
            ``"spindle_tone"``, the default: the tonic-stretch-reflex-threshold reading on
            each muscle's own fibre length and speed with a flexor length tone and a
            background tone, 20 ms delay; ``"spindle"``, the calibrated stretch reflex read
            on each muscle's own fibre length and speed; ``"stretch"``, the same on the knee
            angle; ``"uniform"``, the paper's ``SC_total`` on all 11 muscles, no delay;
            ``"persistent"``, with the flexors' after-discharge; ``"tsrt"``; any the user
            registered) or a :class:`~myoexo.spasticity.ReflexModel` instance.
        robustness: Draw the twin's uncertain parts (strap stiffness and damping, masses,
            slide friction, motor torque constant) and sensor noise and latency at every
            reset (:class:`~myoexo.envs.robustness.RobustnessParams`; ``True``: the default
            ranges; ``None``/``False``: the nominal twin, exact sensors).
        gentleness: The trade-off between speed and interaction torque, a weight in [0, 1]
            (:data:`~myoexo.envs.config.GENTLENESS_RANGE`): the reward's ``gentle`` term
            (the interaction torque's peak and square) enters ``dense`` times this weight,
            and the weight is
            the observation vector's last entry, so one policy learns the whole range and
            takes the weight as an input. ``"random"``: drawn uniformly per reset (for
            training). ``None`` (default): the study's reward and observation.
        reward: The reward's shape (:class:`~myoexo.envs.config.RewardParams`; default: the
            study's).
        twin: The human + exo model (:class:`~myoexo.model.TwinParams`; default: today's
            twin version).
        seed: Seed of the env's RNG (``reset(seed=...)`` reseeds it).
        render_mode: ``None``, ``"human"`` or ``"rgb_array"``.
        **task: Task fields, each by its own name (:class:`~myoexo.envs.config.TaskParams`:
            ``start_angle_deg``, ``start_angle_noise_deg``, ``target_angle_deg``,
            ``episode_duration_s``, ``control_period_s``), e.g.
            ``gym.make("MyoExoKnee-v1", episode_duration_s=4.0)``. Every argument is a
            literal or a record, so tools whose env arguments are literals
            (``examine_env --env_args``, rl_zoo3's YAML ``env_kwargs``, RLlib's
            ``env_config``) pass them unchanged.

    An unknown keyword argument raises Python's own ``TypeError`` (``__init__() got an
    unexpected keyword argument 'x'``), the message other libraries' env builders look for.

    The episode ends by truncation after ``task.episode_steps`` control steps (800: 8 s at
    100 Hz), which the env counts itself, or at an instability; ``spec.max_episode_steps``
    reports that length (gymnasium adds no ``TimeLimit``, see
    :mod:`myoexo.envs.registration`).
    """

    DEFAULT_OBS_KEYS: ClassVar[list[str]] = list(DEFAULT_OBS_KEYS)
    #: Model camera that ``render()`` shows (a fixed camera aimed at the knee).
    render_camera: str | None = DEFAULT_CAMERA
    #: Colours the muscles before each ``render()`` (made at the first render).
    _muscle_colorizer: MuscleColorizer | None = None
    _spec: EnvSpec | None = None

    def __init__(
        self,
        spasticity_level: int | str = 0,
        *,
        reward_weights: Mapping[str, float] | None = None,
        obs_preset: str = "full",
        obs_keys: list[str] | tuple[str, ...] | None = None,
        reflex: str | ReflexModel = DEFAULT_REFLEX,
        robustness: RobustnessParams | bool | None = None,
        subject_noise: bool | None = None,
        subject: str | PersonalSubject | None = None,
        gentleness: float | str | None = None,
        reward: RewardParams | None = None,
        twin: TwinParams | None = None,
        seed: int | None = None,
        render_mode: str | None = None,
        **task: float,
    ) -> None:
        unknown = sorted(set(task) - set(TASK_FIELDS))
        if unknown:  # Python's own wording, which other libraries' env builders look for
            raise TypeError(
                f"{type(self).__name__}.__init__() got an unexpected keyword argument "
                f"{unknown[0]!r}"
            )
        self.task = TaskParams(**task)
        reward = reward if reward is not None else RewardParams()
        if reward_weights is not None:
            unknown = sorted(set(reward_weights) - set(DEFAULT_REWARD_WEIGHTS))
            if unknown:
                raise ValueError(
                    f"reward_weights has unknown keys {unknown}; accepted: "
                    f"{sorted(DEFAULT_REWARD_WEIGHTS)}"
                )
            weights = {**reward.weights, **{k: float(v) for k, v in reward_weights.items()}}
            reward = dataclasses.replace(reward, weights=weights)
        self.reward_params = reward
        self.gentleness_draw = gentleness == "random"
        #: The episode's gentleness weight (``None``: the study's reward and observation).
        self.gentleness: float | None = (
            None
            if gentleness is None
            else GENTLENESS_RANGE[0]
            if self.gentleness_draw
            else check_gentleness(gentleness)
        )
        self.twin_params = twin if twin is not None else TwinParams()
        self._subject: dict[str, float] = {}

        frame_skip = frame_skip_of(self.task.control_period_s, self.twin_params.timestep_s)
        MyoGymnasiumEnv.__init__(self, frame_skip=frame_skip, render_mode=render_mode)
        EzPickle.__init__(
            self,
            spasticity_level,
            reward_weights=reward_weights,
            obs_preset=obs_preset,
            obs_keys=obs_keys,
            reflex=reflex,
            robustness=robustness,
            subject_noise=subject_noise,
            subject=subject,
            gentleness=gentleness,
            reward=reward,
            twin=twin,
            seed=seed,
            render_mode=render_mode,
            **task,
        )

        self.model, self._mj_spec = build_model(self.twin_params)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self._ctrl_dt = float(m.opt.timestep * frame_skip)
        self.mj_instability_termination = False  # instability truncates, see step()

        # observation: keys and where they live in the model (observation.py)
        if obs_preset not in OBS_PRESETS:
            raise ValueError(f"obs_preset = {obs_preset!r}; accepted: {sorted(OBS_PRESETS)}")
        self.obs_preset = obs_preset if obs_keys is None else "custom"
        self.obs_keys = list(obs_keys or OBS_PRESETS[obs_preset])
        self.obs_layout = ObsLayout.of(
            m,
            self.obs_keys,
            target_rad=math.radians(self.task.target_angle_deg),
            episode_duration_s=self.task.episode_duration_s,
        )
        self.coupling_joints = self.obs_layout.coupling_joints
        #: Positions of the raw entries the step and its info read, looked up once.
        self._info_at = _InfoAt(*(self.obs_layout.at[k] for k in _InfoAt._fields))
        self._views: DataViews | None = None  # see _data_views

        # action: the exo motor's ctrl entry (the twin's); the muscles get the ctrl stages'
        # excitations
        self._muscle_act_ind = m.actuator_dyntype == mujoco.mjtDyn.mjDYN_MUSCLE
        self._stage_applies: tuple | None = None  # see _run_ctrl_stages

        # reward (reward.py): MyoSuite's weighted_reward_keys
        self.rwd_keys_wt = dict(self.reward_params.weights)

        # robustness (robustness.py): perturbed twin and sensor model, own seeded stream
        self.robustness = robustness_params(robustness)
        self.twin_perturbation: TwinPerturbation | None = None
        self._sensor: SensorModel | None = None
        self.twin_draw: dict[str, Any] = {}
        self._robust_rng = np.random.default_rng(seed)
        if self.robustness is not None:
            self.twin_perturbation = twin_perturbation(m, self.robustness, self.coupling_joints)
            self._sensor = SensorModel.with_latency(
                self.obs_layout.raw_std(self.robustness.noise_std),
                self.robustness.latency_s,
                self._ctrl_dt,
            )

        #: The personal twin (``None``: the population's subjects).
        self.personal = _personal(subject, spasticity_level, reflex)
        draws = subject_noise if subject_noise is not None else self.personal is None
        self._personal_draws = bool(draws) and self.personal is not None
        self._knee_scaler = None if self.personal is None else PassiveKneeScaler(m)
        self.spasticity = SpasticityStage(
            level=spasticity_level,
            subject_noise=bool(draws) and self.personal is None,
            reflex=reflex,
        )
        self.add_ctrl_stage(STAGE_NAME, self.spasticity.apply, self.spasticity.reset)
        #: The stepping twin (:class:`~myoexo.envs.twin.Twin`): this env's model, data and
        #: reflex stage, stepped through this env's control stages.
        self.twin = Twin(
            m, self.spasticity, self._ctrl_dt, data=self.data, stages=self._run_ctrl_stages
        )

        self._input_seed = seed
        gym.Env.reset(self, seed=seed)
        self._accessor = CpuEnvAccessor(m, self.data, self._ctrl_dt)
        self._clear_episode_state()
        pose_twin(m, self.data, knee_angle_deg=self.task.start_angle_deg)
        obs = self._obs_dict_to_vec(self._get_obs_dict(self._accessor))
        self.observation_space = self._unbounded_obs_space(obs.size)
        self.action_space = gym.spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def _set_personal(self) -> dict[str, float]:
        """Set this episode's person: the personal fit's point or a draw from its uncertainty
        (from ``np_random``, after the spasticity stage's reset, before the start angle).
        Returns the passive knee's scales."""
        personal, scaler = self.personal, self._knee_scaler
        assert personal is not None and scaler is not None
        drawn = personal.draw(self.np_random) if self._personal_draws else personal.point()
        subject, stiffness_scale, damping_scale = drawn
        self.spasticity.set_subject(subject)
        scaler.apply(stiffness_scale, damping_scale)
        return {"stiffness_scale": stiffness_scale, "damping_scale": damping_scale}

    def _clear_episode_state(self) -> None:
        self._command = 0.0
        self._prev_command = 0.0
        self._prev_knee_vel = 0.0
        self._prev_tau_knee = 0.0
        self._peak_tau = math.inf
        self._steps = 0
        self._episode_steps = self.task.episode_steps
        self._subject = {}

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

    @property
    def interaction_torque_nm(self) -> float:
        """The true interaction torque of the last reset or step (Nm), the value of its
        ``info["interaction_torque_nm"]``: part of the twin's state, which no sensor record
        holds (:mod:`myoexo.envs.sensors`); the privileged oracle reads it here."""
        return float(self._prev_tau_knee)

    @property
    def spec(self) -> EnvSpec | None:
        """gymnasium's spec of the env (set by ``gymnasium.make``), whose
        ``max_episode_steps`` is the env's own episode length (:attr:`episode_steps`):
        the env truncates there itself, so gymnasium adds no ``TimeLimit`` (registered
        without one), and tools that read the spec (MyoSuite's ``examine_env``, rl_zoo3,
        wrappers) see the length of this env's task, whatever ``task`` it was built with."""
        return self._spec

    @spec.setter
    def spec(self, spec: EnvSpec | None) -> None:
        if spec is not None and spec.max_episode_steps is None:
            spec = dataclasses.replace(spec, max_episode_steps=self.episode_steps)
        self._spec = spec

    # ------------------------------------------------------------------ observation
    def _data_views(self) -> DataViews:
        """What the step reads from ``self.data`` (:class:`DataViews`), set up once per
        ``MjData`` object: an ``MjData`` array attribute is a view of memory that lives as
        long as the ``MjData``, so caching it saves a lookup and a new view per read."""
        views = self._views
        if views is None or views.data is not self.data:
            views = self._views = self.obs_layout.views(self.data)
        return views

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
        layout = self.obs_layout
        views = self._data_views() if d is self.data else layout.views(d)
        return layout.split(layout.gather(views, self._command))

    def _obs_dict_to_vec(self, obs_dict: dict[str, np.ndarray]) -> np.ndarray:
        """Flatten the ``obs_keys`` entries, each times its fixed scale (float32), and the
        gentleness weight last (an env built with one)."""
        return self._with_gentleness(self.obs_layout.dict_to_vec(obs_dict))

    def _with_gentleness(self, vec: np.ndarray) -> np.ndarray:
        """*vec* with the gentleness weight appended (as is without one)."""
        g = self.gentleness
        if g is None:
            return vec
        return np.append(vec, np.float32(g))

    def get_proprioception(self) -> tuple:
        """``(time, vector, dict)`` of what the exo itself senses (encoder, torque, cuffs)."""
        od = self._get_obs_dict(self._accessor)
        pdict = {k: od[k] for k in _PROPRIOCEPTION_KEYS}
        return float(self.data.time), np.concatenate([np.ravel(v) for v in pdict.values()]), pdict

    # ------------------------------------------------------------------ reward
    def get_reward_dict(self, obs_dict: dict[str, np.ndarray]) -> dict[str, Any]:
        """The paper's reward terms (docs/reference.md section 3, :mod:`myoexo.envs.reward`)
        and their weighted sum, against the previous step's command, velocity and torque."""
        return reward_dict(
            float(obs_dict["error_rad"][0]),
            float(obs_dict["knee_vel_rad_s"][0]),
            float(obs_dict["interaction_torque_nm"][0]),
            self._command,
            self._prev_command,
            self._prev_knee_vel,
            self._prev_tau_knee,
            self.reward_params,
            self.rwd_keys_wt,
            self.gentleness or 0.0,
            self._peak_tau,
        )

    # ------------------------------------------------------------------ action
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

    def add_ctrl_stage(
        self,
        name: str,
        apply: CtrlStage,
        reset: ResetStage | None = None,
        order: float | None = None,
    ) -> None:
        """Install a stage (:meth:`CtrlStageHost.add_ctrl_stage`); it runs from the next
        step on."""
        super().add_ctrl_stage(name, apply, reset, order)
        self._stage_applies = None

    def remove_ctrl_stage(self, name: str) -> None:
        """Uninstall a stage (no-op if it is not installed)."""
        super().remove_ctrl_stage(name)
        self._stage_applies = None

    def _run_ctrl_stages(self, ctrl: np.ndarray) -> np.ndarray:
        """Apply the installed stages to *ctrl* (:class:`CtrlStageHost`'s pipeline).

        The stage order is sorted once and kept until :meth:`add_ctrl_stage` or
        :meth:`remove_ctrl_stage` changes the stages (the host sorts them every step).
        """
        applies = self._stage_applies
        if applies is None:
            applies = self._stage_applies = tuple(
                apply for _, (_, apply, _) in self._stages_in_order()
            )
        for apply in applies:
            ctrl = apply(self, ctrl)
        return ctrl

    # ------------------------------------------------------------------ gymnasium API
    def step(
        self, action: Any, **kwargs: Any
    ) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        """Apply the exo command for one control period and return the 5-tuple.

        Physics: :meth:`Twin.step <myoexo.envs.twin.Twin.step>`, exactly ``mj_step(model, data,
        frame_skip)`` with this step's ``ctrl``
        (the knee angle the last substep started from is read from the twin's knee-angle
        sensor; the state trajectory is bit-identical to raw ``mj_step``; near the flexion
        stop the drive's end-stop protection may set the motor's command of each substep,
        ``info["drive_braking"]``), and no extra
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
        prev_command = self._prev_command = self._command
        self._command = u
        views = self._data_views()
        layout = self.obs_layout
        # MuJoCo checks every substep for NaN/inf/huge qpos, qvel or qacc and then resets
        # the data (time -> 0, finite state): the twin reports that as an instability.
        twin = self.twin
        unstable = twin.step(u)
        forces_knee_rad = twin.force_knee_angle_rad  # knee angle at t - h
        self._steps += 1

        raw = layout.gather(views, u, forces_knee_rad)
        values = raw[: layout.info_len].tolist()  # python floats: cheapest for scalar math
        at = self._info_at
        knee_vel = values[at.knee_vel_rad_s]
        tau = values[at.interaction_torque_nm]
        rwd_dict = reward_dict(
            values[at.error_rad],
            knee_vel,
            tau,
            u,
            prev_command,
            self._prev_knee_vel,
            self._prev_tau_knee,
            self.reward_params,
            self.rwd_keys_wt,
            self.gentleness or 0.0,
            self._peak_tau,
        )
        if tau > self._peak_tau:
            self._peak_tau = tau
        self._prev_knee_vel = knee_vel
        self._prev_tau_knee = tau
        sensed = raw if self._sensor is None else self._sensor.measure(raw, self._robust_rng)
        info = self._step_info(rwd_dict, layout.split(raw), values, unstable, sensed)
        if self.mujoco_render_frames:
            self.mj_render()
        truncated = unstable or self._steps >= self._episode_steps
        reward = float(rwd_dict["dense"])
        obs = self._with_gentleness(layout.to_vec(sensed))
        return obs, reward, bool(rwd_dict["done"]), truncated, info

    def reset(
        self, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """Start an episode: new subject (seeded), knee at the start angle, exo at rest."""
        gym.Env.reset(self, seed=seed)
        mujoco.mj_resetData(self.model, self.data)
        self.twin.set_drive_state()
        self._clear_episode_state()
        self._run_reset_stages()  # the spasticity stage draws this episode's subject
        scales = self._set_personal() if self.personal is not None else {}
        subject = dataclasses.asdict(self.spasticity.subject)
        self._subject = {**{k: float(v) for k, v in subject.items()}, **scales}
        noise = self.task.start_angle_noise_deg
        start = self.task.start_angle_deg + float(self.np_random.uniform(-noise, noise))
        if self.robustness is not None and seed is not None:
            # the perturbed twin has its own stream, so subjects stay those of the nominal env
            self._robust_rng = np.random.default_rng([int(seed), 0x0B057])
        if self.twin_perturbation is not None:
            self.twin_draw = self.twin_perturbation.apply(self._robust_rng)
        pose_twin(self.model, self.data, knee_angle_deg=start)
        mujoco.mj_forward(self.model, self.data)
        layout = self.obs_layout
        raw = layout.gather(self._data_views(), self._command)
        sensed = raw if self._sensor is None else self._sensor.reset(raw, self._robust_rng)
        if self.gentleness_draw:  # drawn last: subjects and start angles stay the env's
            self.gentleness = float(self.np_random.uniform(*GENTLENESS_RANGE))
        obs = self._ensure_obs_gymnasium_compliant(self._with_gentleness(layout.to_vec(sensed)))
        values = raw[: layout.info_len].tolist()
        self._prev_tau_knee = values[self._info_at.interaction_torque_nm]
        if self.gentleness is not None:
            self._peak_tau = self._prev_tau_knee
        info = self._add_info({}, values, False, sensed)
        if self.twin_draw:
            info["twin_draw"] = dict(self.twin_draw)
        return obs, info

    # ------------------------------------------------------------------ info
    def _step_info(
        self,
        rwd_dict: dict[str, Any],
        obs_dict: dict[str, np.ndarray],
        values: list[float],
        unstable: bool,
        sensed: np.ndarray,
    ) -> dict[str, Any]:
        """A step's info: MyoSuite's (the reward terms, ``obs_dict``, ``rwd_dict``) and the
        clinical quantities of :meth:`_add_info`."""
        info = dict(rwd_dict)
        del info["dense"], info["done"]
        info["obs_dict"] = obs_dict
        info["rwd_dict"] = rwd_dict
        return self._add_info(info, values, unstable, sensed)

    def _add_info(
        self, info: dict[str, Any], values: list[float], unstable: bool, sensed: np.ndarray
    ) -> dict[str, Any]:
        """Per-step quantities in clinical units (listed on the documentation site's
        environment page, ``docs/envs.md``).

        Args:
            info: The dict to complete (in place; returned).
            values: The leading entries of the raw observation buffer (the scalars and the
                cuff sensors) as python floats.
            unstable: Whether MuJoCo reset the data during the step.
            sensed: The raw buffer as the sensors report it (the true one unless
                ``robustness`` adds noise and latency): ``measured_*`` entries, what
                :func:`~myoexo.envs.sensors.read_sensors` gives a controller.
        """
        at = self._info_at
        knee_deg = math.degrees(values[at.knee_angle_rad])
        exo_deg = math.degrees(values[at.exo_angle_rad])
        # the sensed entries read one by one (a perturbed twin's buffer is the whole state)
        read = values.__getitem__ if self._sensor is None else sensed.item
        measured_knee_deg = math.degrees(read(at.knee_angle_rad))
        measured_exo_deg = math.degrees(read(at.exo_angle_rad))
        target_deg = self.task.target_angle_deg
        thigh, shank = at.thigh_cuff_force_n, at.shank_cuff_force_n
        exo_nm, muscle_nm = values[at.exo_torque_nm], values[at.muscle_knee_torque_nm]
        stage = self.spasticity
        info.update(
            time_s=values[at.time],
            knee_angle_deg=knee_deg,
            knee_vel_rad_s=values[at.knee_vel_rad_s],
            exo_angle_deg=exo_deg,
            misalignment_deg=knee_deg - exo_deg,
            measured_knee_angle_deg=measured_knee_deg,
            measured_exo_angle_deg=measured_exo_deg,
            measured_knee_velocity_deg_s=math.degrees(read(at.knee_vel_rad_s)),
            measured_exo_velocity_deg_s=math.degrees(read(at.exo_vel_rad_s)),
            measured_exo_torque_nm=read(at.exo_torque_nm),
            target_angle_deg=target_deg,
            error_deg=knee_deg - target_deg,
            command=self._command,
            drive_braking=self.twin.braking,
            exo_torque_nm=exo_nm,
            muscle_knee_torque_nm=muscle_nm,
            interaction_torque_nm=values[at.interaction_torque_nm],
            cuff_knee_torque_nm=values[at.cuff_knee_torque_nm],
            torque_abs_sum_nm=abs(exo_nm) + abs(muscle_nm),
            torque_signed_sum_nm=exo_nm + muscle_nm,
            thigh_cuff_force_n=math.hypot(values[thigh], values[thigh + 1], values[thigh + 2]),
            shank_cuff_force_n=math.hypot(values[shank], values[shank + 1], values[shank + 2]),
            sc_total=float(stage.last_sc_total),
            level=int(stage.level),
            gentleness=self.gentleness,
            subject=self._subject,
            unstable=unstable,
        )
        return info

    # ------------------------------------------------------------------ render
    def render(self, **kwargs: Any) -> Any:
        """MyoSuite's ``render()`` (camera :attr:`render_camera`, 640x480 unless ``kwargs``
        say otherwise), with every muscle coloured by its activation first (rest colour to
        red, :class:`~myoexo.model.scene.MuscleColorizer`)."""
        if self.render_mode is not None:
            if self._muscle_colorizer is None:
                self._muscle_colorizer = MuscleColorizer(self.model)
            self._muscle_colorizer(self.data)
        return super().render(**kwargs)


def _personal(
    subject: str | PersonalSubject | None, level: int | str, reflex: str | ReflexModel
) -> PersonalSubject | None:
    """The env's personal subject, checked against its level and reflex model."""
    if subject is None:
        return None
    personal = subject if isinstance(subject, PersonalSubject) else load_subject(subject)
    if isinstance(level, bool) or level != personal.level:
        raise ValueError(
            f"subject {personal.source or '(in memory)'} was fitted with level "
            f"{personal.level}'s reflex calibration, but the env's level is {level!r}: build "
            f"it as MyoExoKnee-v{personal.level} (spasticity_level={personal.level})"
        )
    if reflex_label(reflex) != personal.reflex:
        raise ValueError(
            f"subject {personal.source or '(in memory)'} was fitted with the "
            f"{personal.reflex!r} reflex, but the env's reflex is {reflex_label(reflex)!r}"
        )
    return personal
