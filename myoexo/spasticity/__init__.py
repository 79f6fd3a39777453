"""Spastic stretch reflex of the knee muscles (paper Table I and eqs. 1-4).

The paper's model and the project's reading of it are in docs/reference.md section 2.

The reflex adds a spasticity coefficient ``SC_total`` (a fraction of maximum isometric force)
to the excitation of the 11 spastic knee muscles. It is the sum of an angle term and a
velocity term, each a "soft window" built from two sigmoids::

    phi(k, b, b0) = 1 / (1 + exp(k (b - b0)))                                  (eq. 2)
    sc_a(theta)   = s_theta [1 - (phi(k, theta, theta_flex) - phi(k, theta, theta_ext))]
    sc_v(v)       = s_v     [1 - (phi(k, v, v_upper) - phi(k, v, v_lower))]
    SC_total      = sc_a(theta) + sc_v(v)

with the knee angle ``theta`` in degrees (MyoSuite ``knee_angle_r``, flexion positive) and
the knee velocity ``v`` in rad/s (flexion positive). Inside a level's range each bracket is
~0, at a limit it is 1/2 and far outside it tends to 1. The paper's eq. 4 prints the two
velocity sigmoids in the other order, which read literally gives ``2 s_v`` inside the range;
we follow the text and eq. 3 (zero inside, ``s_v`` outside). One slope ``k`` per level acts
on both terms, so with ``k = 0.1`` (level 3) the velocity window is far wider than its range
and the velocity term stays near ``s_v / 2`` at rest: the "maintained" tone the paper
describes for levels 2 and 3.

The package, one module per part (each name is re-exported here):

* :mod:`~myoexo.spasticity.levels`: :class:`SpasticityParams` and :data:`LEVELS` (Table I),
  the spastic muscle groups, :func:`sample_subject` (individual subjects: 10 % Gaussian noise
  on every parameter);
* :mod:`~myoexo.spasticity.coefficients`: :func:`phi`, :func:`sc_angle`,
  :func:`sc_velocity`, :func:`sc_total` (numpy, vectorized) and their torch twins (autograd
  through the inputs and every parameter);
* :mod:`~myoexo.spasticity.registry`: the plug-in protocol of a reflex model
  (:class:`ReflexModel`: a frozen dataclass of its parameters, its step on a sensory record,
  or on the knee state with its torch twin, and its memory) and the registry
  (:func:`register_reflex`, :func:`get_reflex`, :func:`reflex_names`);
* :mod:`~myoexo.spasticity.sensory`: :class:`SensoryRecord`, what a reflex senses (the knee
  state and each spastic muscle's normalised fibre length, lengthening speed and force), and
  :class:`MuscleSensors`, which reads it from MuJoCo's muscle state;
* :mod:`~myoexo.spasticity.reflex`: the built-in models (``"stretch"``, ``"uniform"``,
  ``"persistent"``), their calibration data (:data:`CALIBRATION`, :data:`PERSISTENT`) and
  their torch twins;
* :mod:`~myoexo.spasticity.spindle`: ``"spindle"``, the stretch reflex read on each
  muscle's own fibre length and lengthening speed (:class:`SpindleReflex`), and
  ``"spindle_tsrt"``, the tonic-stretch-reflex-threshold reading on the same state;
* :mod:`~myoexo.spasticity.spindle_tone`: ``"spindle_tone"``, the envs' default:
  ``"spindle_tsrt"`` with a flexor length tone, a background tone and a phasic scale;
* :mod:`~myoexo.spasticity.delay`: the transmission delay line (of sensory records);
* :mod:`~myoexo.spasticity.stage`: :class:`SpasticityStage`, the reflex as a stage of
  MyoSuite's muscle-command pipeline (:mod:`myosuite.envs.muscle_stages`), and
  :class:`StageHost`, the smallest host it runs on;
* :mod:`~myoexo.spasticity.wrapper`: :class:`SpasticityWrapper`, a gymnasium wrapper that
  installs the stage on any MyoSuite env whose model has the 11 muscles and ``knee_angle_r``;
* the studies that fit the reflex (``myoexo twin calibrate``, :mod:`myoexo.studies.calibrate`:
  the stretch reflex, or with ``--reflex persistent`` the after-discharge, to the paper's
  PID) and the paper's Fig. 2b (:func:`myoexo.clinical.figures.plot_sc_curves`) live on the
  floors above (``docs/architecture.md``).

Example::

    from myosuite.utils import gym
    from myoexo.spasticity import SpasticityWrapper

    env = SpasticityWrapper(gym.make("myoLegWalk-v0"), level=2)
    env.reset(seed=0)
    env.spasticity.subject        # SpasticityParams of the drawn subject
"""

from myoexo.model.leg import KNEE_JOINT
from myoexo.spasticity.coefficients import (
    above,
    below,
    phi,
    phi_torch,
    sc_angle,
    sc_angle_torch,
    sc_total,
    sc_total_torch,
    sc_velocity,
    sc_velocity_torch,
)
from myoexo.spasticity.delay import DelayLine
from myoexo.spasticity.levels import (
    LEVELS,
    RANDOM_LEVEL,
    SPASTIC_EXTENSORS,
    SPASTIC_FLEXORS,
    SPASTIC_MUSCLES,
    SUBJECT_REL_STD,
    VALID_LEVELS,
    SpasticityParams,
    sample_subject,
)
from myoexo.spasticity.reflex import (
    BUILTIN_REFLEXES,
    CALIBRATION,
    DEFAULT_REFLEX,
    PERSISTENT,
    STRETCH_DELAY_S,
    UNCALIBRATED,
    LevelCalibration,
    PersistentParams,
    PersistentReflex,
    StretchCalibration,
    StretchReflex,
    UniformReflex,
    group_excitations,
    group_excitations_torch,
    persistent_step,
    persistent_step_torch,
)
from myoexo.spasticity.registry import (
    REFLEXES,
    ReflexModel,
    get_reflex,
    reflex_label,
    reflex_name,
    reflex_names,
    reflex_parameters,
    register_reflex,
    resolve_reflex,
)
from myoexo.spasticity.sensory import MuscleSensors, SensoryRecord
from myoexo.spasticity.spindle import SpindleReflex, spindle_geometry
from myoexo.spasticity.spindle_tone import SpindleToneReflex
from myoexo.spasticity.stage import STAGE_NAME, SpasticityStage, StageHost
from myoexo.spasticity.wrapper import SpasticityWrapper

__all__ = [
    "BUILTIN_REFLEXES",
    "CALIBRATION",
    "DEFAULT_REFLEX",
    "KNEE_JOINT",
    "LEVELS",
    "PERSISTENT",
    "RANDOM_LEVEL",
    "REFLEXES",
    "SPASTIC_EXTENSORS",
    "SPASTIC_FLEXORS",
    "SPASTIC_MUSCLES",
    "STAGE_NAME",
    "STRETCH_DELAY_S",
    "SUBJECT_REL_STD",
    "UNCALIBRATED",
    "VALID_LEVELS",
    "DelayLine",
    "LevelCalibration",
    "MuscleSensors",
    "PersistentParams",
    "PersistentReflex",
    "ReflexModel",
    "SensoryRecord",
    "SpasticityParams",
    "SpasticityStage",
    "SpasticityWrapper",
    "SpindleReflex",
    "SpindleToneReflex",
    "StageHost",
    "StretchCalibration",
    "StretchReflex",
    "UniformReflex",
    "above",
    "below",
    "get_reflex",
    "group_excitations",
    "group_excitations_torch",
    "persistent_step",
    "persistent_step_torch",
    "phi",
    "phi_torch",
    "reflex_label",
    "reflex_name",
    "reflex_names",
    "reflex_parameters",
    "register_reflex",
    "resolve_reflex",
    "sample_subject",
    "sc_angle",
    "sc_angle_torch",
    "sc_total",
    "sc_total_torch",
    "sc_velocity",
    "sc_velocity_torch",
    "spindle_geometry",
]
