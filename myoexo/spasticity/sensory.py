"""What a reflex senses: the knee's state and each spastic muscle's own length, speed and force.

A spinal stretch reflex does not read the knee angle: muscle spindles sense their muscle's
fibre length and lengthening speed, Golgi tendon organs its force. :class:`SensoryRecord`
holds both views of one instant, the knee state (what the Table I models read) and, for every
spastic muscle (flexors first, then extensors, in the stage's order), MuJoCo's own muscle
state:

* ``fibre_length``: normalised fibre length ``L / L_opt``. MuJoCo's muscle model maps the
  actuator length over its ``lengthrange`` linearly onto the normalised range ``gainprm[0:2]``
  (``range``), so ``L = range[0] + (actuator_length - lengthrange[0]) / L0`` with ``L0 =
  (lengthrange[1] - lengthrange[0]) / (range[1] - range[0])``, the optimal fibre length in
  metres of actuator length (rigid tendons: the actuator's length change is the fibre's).
* ``lengthening_speed``: ``actuator_velocity / L0``, optimal lengths per second, positive
  while the muscle lengthens (is stretched).
* ``force_n``: the muscle's tension, N (``-actuator_force``: MuJoCo's muscle force is
  negative, pulling).

Timing: the knee state is the state at the start of the control step; the muscle quantities
are those MuJoCo computed in the last physics substep (after ``mj_forward`` at a reset, the
present state's). The stage's delay line carries whole records, so a model reads every field
of the same, delayed instant.
"""

from __future__ import annotations

from typing import Any, NamedTuple

import numpy as np

__all__ = ["MuscleSensors", "SensoryRecord"]


class SensoryRecord(NamedTuple):
    """One instant of what the reflex senses (module docstring).

    Attributes:
        knee_angle_deg: Knee flexion, deg.
        knee_vel_rad_s: Knee flexion velocity, rad/s.
        fibre_length: Normalised fibre length ``L / L_opt`` of each spastic muscle.
        lengthening_speed: Normalised lengthening speed, ``L_opt`` per s (> 0: stretched).
        force_n: Muscle tension, N.
        n_flexors: How many of the muscles (the first ones) are flexors.
    """

    knee_angle_deg: float
    knee_vel_rad_s: float
    fibre_length: np.ndarray
    lengthening_speed: np.ndarray
    force_n: np.ndarray
    n_flexors: int


class MuscleSensors:
    """Reads the :class:`SensoryRecord` of a set of muscle actuators of one model.

    Args:
        model: The MuJoCo model.
        actuator_ids: The muscles' actuator ids (flexors first).
        n_flexors: How many of them are flexors.

    Raises:
        ValueError: If an actuator is not a muscle with a positive length range.
    """

    def __init__(self, model: Any, actuator_ids: np.ndarray, n_flexors: int) -> None:
        import mujoco

        ids = np.asarray(actuator_ids, dtype=np.intp)
        bad = [int(i) for i in ids if model.actuator_dyntype[i] != mujoco.mjtDyn.mjDYN_MUSCLE]
        if bad:
            raise ValueError(f"actuators {bad} are not muscles: a sensory record needs muscles")
        lengthrange = model.actuator_lengthrange[ids]
        norm_range = model.actuator_gainprm[ids, 0:2]
        span = lengthrange[:, 1] - lengthrange[:, 0]
        if not (span > 0.0).all():
            raise ValueError(f"actuators {ids.tolist()} need a positive lengthrange")
        self.ids = ids
        self.n_flexors = int(n_flexors)
        #: Optimal fibre length of each muscle in metres of actuator length.
        self.optimal_length_m = span / (norm_range[:, 1] - norm_range[:, 0])
        self._inv_l0 = 1.0 / self.optimal_length_m
        self._offset = norm_range[:, 0] - lengthrange[:, 0] * self._inv_l0
        # entries: actuator length, velocity and force of each muscle, in that order;
        # record = entries * scale, the lengths plus offset
        n = len(ids)
        self._gathered = (
            ("actuator_length", ids),
            ("actuator_velocity", ids),
            ("actuator_force", ids),
        )
        self._scale = np.concatenate([self._inv_l0, self._inv_l0, np.full(n, -1.0)])
        self._slices = (slice(0, n), slice(n, 2 * n), slice(2 * n, 3 * n))

    def views(self, data: Any) -> tuple[np.ndarray, np.ndarray]:
        """``(view, index)``: ``view[index]`` are the entries :meth:`record` takes, read from
        *data* as it stands in one numpy call (:func:`~myoexo.model.data_buffer.buffer_gather`;
        set up once per ``MjData``)."""
        from myoexo.model.data_buffer import buffer_gather

        return buffer_gather(data, self._gathered)

    def record(
        self, entries: np.ndarray, knee_angle_deg: float, knee_vel_rad_s: float
    ) -> SensoryRecord:
        """The record of the muscles' actuator lengths, velocities and forces *entries* (one
        fresh float64 array, ``view[index]`` of :meth:`views`; normalised in place, the
        record's arrays are views of it), with the given knee state."""
        entries *= self._scale
        length, speed, force = self._slices
        fibre_length = entries[length]
        fibre_length += self._offset
        return SensoryRecord(
            knee_angle_deg,
            knee_vel_rad_s,
            fibre_length,
            entries[speed],
            entries[force],
            self.n_flexors,
        )

    def read(self, data: Any, knee_angle_deg: float, knee_vel_rad_s: float) -> SensoryRecord:
        """The record of *data* as it stands, with the given knee state."""
        ids = self.ids
        entries = np.concatenate(
            (data.actuator_length[ids], data.actuator_velocity[ids], data.actuator_force[ids])
        )
        return self.record(entries, knee_angle_deg, knee_vel_rad_s)
