"""What the MyoExoKnee env observes: the keys, presets and scales, and where every quantity
lives in one model's ``MjData``.

Every key is described once, in :data:`OBS_KEY_DOCS` (meaning and unit); the documentation
site's environment page (``docs/envs.md``) shows it as a table, with each key's size and
scale in the vector read from a built twin. This module only defines constants and the
:class:`ObsLayout` class: it builds no model and does not import the env
(``myoexo.envs.options`` reads :data:`OBS_PRESETS` from here).

Each step the env *gathers* every observed quantity, in physical units, into one fresh
float64 **raw buffer** laid out as :data:`RAW_KEYS` (:meth:`ObsLayout.gather`); ``obs_dict``
is one view of it per key (:meth:`ObsLayout.split`) and the observation vector is its
``obs_keys`` entries times their scales, as float32 (:meth:`ObsLayout.to_vec`). The sensor
model of :mod:`myoexo.envs.robustness` works on the raw buffer too.
"""

from __future__ import annotations

import operator
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import NamedTuple

import mujoco
import numpy as np

from myoexo.model import COUPLING_JOINTS, CUFF_SENSORS, EXO_JOINT, KNEE_JOINT, strap_knee_torque
from myoexo.model.data_buffer import buffer_gather
from myoexo.model.joint_torque import CoupledJointTorque, EqualityJointTorque
from myoexo.spasticity.levels import SPASTIC_MUSCLES

#: Cuff sensors of the twin: obs key (sensor name + unit) -> sensor name.
CUFF_OBS_KEYS: dict[str, str] = {f"{name}_{unit}": name for name, unit in CUFF_SENSORS.items()}

#: The twin's scalar state and drive (one entry each), in the order the vector gives them.
STATE_OBS_KEYS: tuple[str, ...] = (
    "knee_angle_rad",
    "knee_vel_rad_s",
    "exo_angle_rad",
    "exo_vel_rad_s",
    "target_rad",
    "error_rad",
    "command",
    "exo_torque_nm",
    "muscle_knee_torque_nm",
)
#: The strap coupling joints' positions and velocities (one entry per joint).
COUPLING_OBS_KEYS: tuple[str, ...] = ("coupling_qpos", "coupling_qvel")
#: The 11 spastic muscles' states (one entry per muscle).
MUSCLE_OBS_KEYS: tuple[str, ...] = (
    "spastic_act",
    "spastic_force",
    "spastic_length",
    "spastic_velocity",
)

#: The ``"full"`` preset: the twin's whole state, muscles included.
DEFAULT_OBS_KEYS: tuple[str, ...] = (
    *STATE_OBS_KEYS,
    *CUFF_OBS_KEYS,
    *COUPLING_OBS_KEYS,
    *MUSCLE_OBS_KEYS,
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

#: Fixed observation scales (vector = obs_dict value * scale; 1 where not listed); the
#: coupling scales come from the joint ranges of the model.
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

#: The raw buffer's scalars: the state ones between the time and the interaction torque
#: (``obs_dict`` and ``info`` only: the magnitude of the torque the shank strap transmits to
#: the human knee, ``cuff_knee_torque_nm`` with its sign; docs/reference.md section 5), and
#: time_frac.
SCALAR_KEYS: tuple[str, ...] = (
    "time",
    *STATE_OBS_KEYS,
    "interaction_torque_nm",
    "cuff_knee_torque_nm",
    "time_frac",
)
#: Every key of ``obs_dict`` (what ``obs_keys`` may name), in the raw buffer's order.
RAW_KEYS: tuple[str, ...] = (
    *SCALAR_KEYS,
    *CUFF_OBS_KEYS,
    *COUPLING_OBS_KEYS,
    *MUSCLE_OBS_KEYS,
)


class ObsKeyDoc(NamedTuple):
    """What one key of ``obs_dict`` holds."""

    key: str
    meaning: str
    unit: str


#: Every key of ``obs_dict`` (:data:`RAW_KEYS`, in its order): meaning and physical unit.
#: The value in ``obs_dict`` is in that unit; the vector holds it times its scale
#: (:data:`OBS_SCALES`; the coupling joints: one over each joint's half range).
OBS_KEY_DOCS: tuple[ObsKeyDoc, ...] = (
    ObsKeyDoc("time", "simulated time since the reset (obs_dict and info only)", "s"),
    ObsKeyDoc("knee_angle_rad", "human knee flexion", "rad"),
    ObsKeyDoc("knee_vel_rad_s", "human knee flexion velocity", "rad/s"),
    ObsKeyDoc("exo_angle_rad", "exo knee encoder angle", "rad"),
    ObsKeyDoc("exo_vel_rad_s", "exo knee velocity", "rad/s"),
    ObsKeyDoc("target_rad", "target knee flexion", "rad"),
    ObsKeyDoc("error_rad", "knee - target, > 0 while the knee is flexed short of it", "rad"),
    ObsKeyDoc("command", "last applied (clipped) motor command", "-"),
    ObsKeyDoc("exo_torque_nm", "exo motor torque", "Nm"),
    ObsKeyDoc("muscle_knee_torque_nm", "muscle torque along the coupled human knee", "Nm"),
    ObsKeyDoc(
        "interaction_torque_nm",
        "|torque the shank strap transmits to the human knee| (obs_dict and info only)",
        "Nm",
    ),
    ObsKeyDoc(
        "cuff_knee_torque_nm",
        "that torque with its sign, flexion positive (obs_dict and info only)",
        "Nm",
    ),
    ObsKeyDoc("time_frac", "time / episode duration", "-"),
    ObsKeyDoc("thigh_cuff_force_n", "thigh cuff interaction force, cuff frame", "N"),
    ObsKeyDoc("thigh_cuff_torque_nm", "thigh cuff interaction torque, cuff frame", "Nm"),
    ObsKeyDoc("shank_cuff_force_n", "shank cuff interaction force, cuff frame", "N"),
    ObsKeyDoc("shank_cuff_torque_nm", "shank cuff interaction torque, cuff frame", "Nm"),
    ObsKeyDoc(
        "coupling_qpos",
        "strap coupling joints: thigh slide, thigh pin, shank pin, shank ab/adduction "
        "and axial pins",
        "m (slide), rad (pins)",
    ),
    ObsKeyDoc("coupling_qvel", "their velocities", "m/s, rad/s"),
    ObsKeyDoc("spastic_act", "activation of the 11 spastic muscles", "-"),
    ObsKeyDoc("spastic_force", "their force / maximum isometric force", "-"),
    ObsKeyDoc("spastic_length", "their length, 0-1 over each muscle's length range", "-"),
    ObsKeyDoc("spastic_velocity", "their velocity / length range", "1/s"),
)


# Positions of the scalars in the raw buffer.
(
    _TIME,
    _KNEE_ANGLE,
    _KNEE_VEL,
    _EXO_ANGLE,
    _EXO_VEL,
    _TARGET,
    _ERROR,
    _COMMAND,
    _EXO_TORQUE,
    _MUSCLE_TORQUE,
    _INTERACTION_TORQUE,
    _CUFF_TORQUE,
    _TIME_FRAC,
) = range(len(SCALAR_KEYS))


class DataViews(NamedTuple):
    """What the env reads from one ``MjData`` every step, looked up once.

    ``qpos``, ``qvel``, ``ctrl``, ``qfrc_actuator`` are the data's arrays (views of its
    memory, valid as long as ``data``). ``buffer[gather_index]`` gathers every ``MjData``
    entry of the raw buffer (:attr:`ObsLayout.gathered`) in one numpy call
    (:func:`~myoexo.model.data_buffer.buffer_gather`).
    """

    data: mujoco.MjData
    qpos: np.ndarray
    qvel: np.ndarray
    ctrl: np.ndarray
    qfrc_actuator: np.ndarray
    buffer: np.ndarray
    gather_index: np.ndarray

    @classmethod
    def of(
        cls, data: mujoco.MjData, gathered: Sequence[tuple[str | None, np.ndarray]]
    ) -> DataViews:
        """Views of *data*, gathering ``[(field, indices), ...]`` in that order (a ``None``
        field: entries computed after the gather, which read the buffer's first entry).

        Raises:
            RuntimeError: If the arrays do not lie in one buffer of ``data.nbuffer`` bytes.
        """
        buffer, gather_index = buffer_gather(data, gathered)
        return cls(data, data.qpos, data.qvel, data.ctrl, data.qfrc_actuator, buffer, gather_index)


@dataclass(frozen=True, eq=False)
class ObsLayout:
    """Where the env's observed quantities live in one model, resolved once by name
    (:meth:`of`), and the functions between ``MjData``, the raw buffer, ``obs_dict`` and the
    observation vector.

    Attributes:
        obs_keys: The vector's entries, in order.
        coupling_joints: The strap coupling joints the model has (of ``COUPLING_JOINTS``).
        knee_qadr, knee_dadr: ``qpos`` / ``qvel`` address of the human knee.
        exo_qadr, exo_dadr: ``qpos`` / ``qvel`` address of the exo knee hinge.
        knee_torque: Muscle torque along the coupled human knee.
        strap_torque: The shank strap's torque along it (the interaction torque).
        target_rad: The target knee flexion (the ``target_rad`` entry).
        episode_duration_s: Denominator of ``time_frac``.
        slices: Raw buffer layout: key -> slice (:data:`RAW_KEYS` order).
        at: Key -> its first raw index.
        raw_size: Length of the raw buffer.
        info_len: Leading raw entries the info reads (the scalars and the cuff sensors).
        gathered: Every raw entry in order as ``(MjData field or None, indices)``; ``None``:
            computed by :meth:`gather`.
        raw_offset, raw_gain: raw = (gathered value - offset) * gain: the spastic force,
            length and velocity are normalized, every other entry kept exactly
            (``(x - 0) * 1 = x``).
        vec_index, vec_scale: vector = (raw[vec_index] * vec_scale) as float32.
    """

    obs_keys: tuple[str, ...]
    coupling_joints: tuple[str, ...]
    knee_qadr: int
    knee_dadr: int
    exo_qadr: int
    exo_dadr: int
    knee_torque: CoupledJointTorque
    strap_torque: EqualityJointTorque
    target_rad: float
    episode_duration_s: float
    slices: Mapping[str, slice]
    at: Mapping[str, int]
    raw_size: int
    info_len: int
    gathered: tuple[tuple[str | None, np.ndarray], ...]
    raw_offset: np.ndarray
    raw_gain: np.ndarray
    vec_index: np.ndarray
    vec_scale: np.ndarray
    _views_of: Callable[[np.ndarray], tuple[np.ndarray, ...]] = field(repr=False)

    @classmethod
    def of(
        cls,
        model: mujoco.MjModel,
        obs_keys: Iterable[str],
        target_rad: float,
        episode_duration_s: float,
    ) -> ObsLayout:
        """Resolve every name of the twin in *model* once.

        Raises:
            ValueError: If *obs_keys* names a key that is not in :data:`RAW_KEYS`.
        """
        m = model
        knee, exo = m.joint(KNEE_JOINT), m.joint(EXO_JOINT)
        knee_qadr, knee_dadr = int(knee.qposadr[0]), int(knee.dofadr[0])
        exo_qadr, exo_dadr = int(exo.qposadr[0]), int(exo.dofadr[0])

        joint = mujoco.mjtObj.mjOBJ_JOINT
        names = tuple(n for n in COUPLING_JOINTS if mujoco.mj_name2id(m, joint, n) >= 0)
        jids = [m.joint(n).id for n in names]
        coupling_qadr = np.array([m.jnt_qposadr[j] for j in jids], dtype=np.intp)
        coupling_dadr = np.array([m.jnt_dofadr[j] for j in jids], dtype=np.intp)
        half_range = np.array([0.5 * (m.jnt_range[j, 1] - m.jnt_range[j, 0]) for j in jids])
        coupling_scale = 1.0 / np.maximum(half_range, 1e-6)

        def sensor_entries(name: str) -> np.ndarray:
            sid = m.sensor(name).id
            adr, dim = int(m.sensor_adr[sid]), int(m.sensor_dim[sid])
            return np.arange(adr, adr + dim, dtype=np.intp)

        ids = np.array([m.actuator(n).id for n in SPASTIC_MUSCLES], dtype=np.intp)
        f0 = np.abs(m.actuator_gainprm[ids, 2])
        lr = m.actuator_lengthrange[ids]
        span = np.maximum(lr[:, 1] - lr[:, 0], 1e-6)

        # Where each key's entries come from: (MjData field, indices), in RAW_KEYS order;
        # the scalars that are no MjData entry are computed by gather (field None).
        read = {
            "knee_angle_rad": ("qpos", knee_qadr),
            "knee_vel_rad_s": ("qvel", knee_dadr),
            "exo_angle_rad": ("qpos", exo_qadr),
            "exo_vel_rad_s": ("qvel", exo_dadr),
            "exo_torque_nm": ("qfrc_actuator", exo_dadr),
        }
        sources: dict[str, tuple[str | None, np.ndarray]] = {
            key: (read[key][0], np.array([read[key][1]], dtype=np.intp))
            if key in read
            else (None, np.zeros(1, dtype=np.intp))
            for key in SCALAR_KEYS
        }
        sources.update({key: ("sensordata", sensor_entries(s)) for key, s in CUFF_OBS_KEYS.items()})
        sources.update(
            coupling_qpos=("qpos", coupling_qadr),
            coupling_qvel=("qvel", coupling_dadr),
            spastic_act=("act", m.actuator_actadr[ids].astype(np.intp)),
            spastic_force=("actuator_force", ids),
            spastic_length=("actuator_length", ids),
            spastic_velocity=("actuator_velocity", ids),
        )
        sources = {key: sources[key] for key in RAW_KEYS}  # the raw buffer's order
        sizes = {key: len(idx) for key, (_, idx) in sources.items()}
        slices: dict[str, slice] = {}
        i = 0
        for key, size in sizes.items():
            slices[key] = slice(i, i + size)
            i += size
        raw_size = i

        raw_offset = np.zeros(raw_size)
        raw_gain = np.ones(raw_size)
        raw_offset[slices["spastic_length"]] = lr[:, 0]
        raw_gain[slices["spastic_force"]] = -1.0 / f0
        raw_gain[slices["spastic_length"]] = 1.0 / span
        raw_gain[slices["spastic_velocity"]] = 1.0 / span

        obs_keys = tuple(obs_keys)
        unknown = [k for k in obs_keys if k not in slices]
        if unknown:
            raise ValueError(f"unknown obs_keys {unknown}; accepted: {list(slices)}")
        scales = {k: np.full(sizes[k], OBS_SCALES.get(k, 1.0)) for k in sizes}
        scales["coupling_qpos"] = coupling_scale
        scales["coupling_qvel"] = 0.1 * coupling_scale
        return cls(
            obs_keys=obs_keys,
            coupling_joints=names,
            knee_qadr=knee_qadr,
            knee_dadr=knee_dadr,
            exo_qadr=exo_qadr,
            exo_dadr=exo_dadr,
            knee_torque=CoupledJointTorque(m, KNEE_JOINT),
            strap_torque=strap_knee_torque(m),
            target_rad=float(target_rad),
            episode_duration_s=float(episode_duration_s),
            slices=slices,
            at={key: sl.start for key, sl in slices.items()},
            raw_size=raw_size,
            info_len=max(slices[k].stop for k in (*SCALAR_KEYS, *CUFF_OBS_KEYS)),
            gathered=tuple(sources.values()),
            raw_offset=raw_offset,
            raw_gain=raw_gain,
            vec_index=np.concatenate([np.arange(raw_size)[slices[k]] for k in obs_keys]),
            vec_scale=np.concatenate([scales[k] for k in obs_keys]),
            _views_of=operator.itemgetter(*slices.values()),
        )

    # -- MjData -> raw buffer -> obs_dict / vector ------------------------------------------
    def views(self, data: mujoco.MjData) -> DataViews:
        """What :meth:`gather` reads from *data* (set up once per ``MjData``)."""
        return DataViews.of(data, self.gathered)

    def gather(
        self, views: DataViews, command: float, forces_knee_rad: float | None = None
    ) -> np.ndarray:
        """Every observed quantity, in physical units, in a freshly allocated raw buffer.

        One index into the data's memory reads every ``MjData`` entry; the time, target,
        error, command, muscle and interaction torques and ``time_frac`` are written in
        after it; then the muscle block is normalized. Everything is read from ``views`` as
        it stands (see ``MyoExoKneeEnv.step`` for what that means in time after a step).

        Args:
            views: What to read (:meth:`views` of the env's or another ``MjData``).
            command: The last applied motor command.
            forces_knee_rad: Knee angle (rad) of the state the data's forces were computed
                at, for the muscle torque's knee transmission (default: the current angle).
        """
        raw = views.buffer[views.gather_index]
        time_s = views.data.time
        knee_rad = raw.item(_KNEE_ANGLE)
        if forces_knee_rad is None:
            forces_knee_rad = knee_rad
        muscle_torque_nm = self.knee_torque.torque_at(forces_knee_rad, views.qfrc_actuator)
        cuff_torque_nm = self.strap_torque(views.data, forces_knee_rad)
        target_rad = self.target_rad
        raw[_TIME] = time_s
        raw[_TARGET] = target_rad
        raw[_ERROR] = knee_rad - target_rad
        raw[_COMMAND] = command
        raw[_MUSCLE_TORQUE] = muscle_torque_nm
        raw[_INTERACTION_TORQUE] = abs(cuff_torque_nm)
        raw[_CUFF_TORQUE] = cuff_torque_nm
        raw[_TIME_FRAC] = time_s / self.episode_duration_s
        raw -= self.raw_offset
        raw *= self.raw_gain
        return raw

    def split(self, raw: np.ndarray) -> dict[str, np.ndarray]:
        """``obs_dict``: one view of *raw* per key (a new buffer per step: stored dicts are
        never overwritten)."""
        # one C call makes every view; the lengths match by construction (zip(strict=True)
        # costs ~1 us here)
        return dict(zip(RAW_KEYS, self._views_of(raw)))  # noqa: B905

    def to_vec(self, raw: np.ndarray) -> np.ndarray:
        """The observation vector: the ``obs_keys`` entries of *raw*, each times its scale."""
        return (raw[self.vec_index] * self.vec_scale).astype(np.float32)

    def dict_to_vec(self, obs_dict: Mapping[str, np.ndarray]) -> np.ndarray:
        """The observation vector of an ``obs_dict`` (a view of a raw buffer or any dict
        with every key)."""
        raw = obs_dict["time"].base
        if raw is None or raw.size != self.raw_size:  # a dict not made by split
            raw = np.concatenate([np.atleast_1d(obs_dict[k]).ravel() for k in self.slices])
        return self.to_vec(raw)

    def raw_std(self, noise_std: Iterable[tuple[str, float]]) -> np.ndarray:
        """Noise standard deviation of each raw entry from ``(key, std in the key's
        physical unit)`` pairs (normalized entries: times their gain).

        Raises:
            ValueError: If a key is not in :data:`RAW_KEYS`.
        """
        std = np.zeros(self.raw_size)
        for key, value in noise_std:
            if key not in self.slices:
                raise ValueError(
                    f"robustness.noise_std names unknown key {key!r}; accepted: {list(self.slices)}"
                )
            std[self.slices[key]] = value * np.abs(self.raw_gain[self.slices[key]])
        return std
