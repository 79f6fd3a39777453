"""Controllers of the exoskeleton: the paper's PID baseline, its Ziegler-Nichols tuning on the
twin, the impedance controller (a spring-damper on a minimum-jerk reference), and adapters
that make any learned policy a controller.

Every controller fits :class:`Controller` (``reset(seed)``, ``act(obs, measurements) ->
action``): it sees the observation and the record of its sensors (:class:`Measurements`,
:func:`read_sensors`), not the env's ``info``::

    import gymnasium as gym, myoexo
    from myoexo.control import PID, read_sensors

    env = gym.make("MyoExoKnee-v1")
    pid = PID.from_env(env)                  # Kp = 7, Ki = 40, Kd = 0.05 on the error in rad
    obs, info = env.reset(seed=0)
    pid.reset(seed=0)
    while True:                              # pid.sensors: the knee angle sensor
        obs, r, term, trunc, info = env.step(pid.act(obs, read_sensors(info, pid.sensors)))
        if term or trunc:
            break
"""

from myoexo.control.impedance import ImpedanceConfig, ImpedanceController
from myoexo.control.pid import ANTI_WINDUP_SCHEMES, PID, PIDConfig, PIDGains
from myoexo.control.policy import (
    CallableController,
    ConstantController,
    SB3Controller,
    as_controller,
)
from myoexo.control.protocol import Controller, declared_sensors
from myoexo.control.specs import ControllerSpec, build_controller, parse_controller_spec
from myoexo.envs.sensors import (
    KNEE_ANGLE_SENSOR,
    KneeAngleMeasurements,
    Measurements,
    read_sensors,
)

__all__ = [
    "ANTI_WINDUP_SCHEMES",
    "KNEE_ANGLE_SENSOR",
    "PID",
    "CallableController",
    "ConstantController",
    "Controller",
    "ControllerSpec",
    "ImpedanceConfig",
    "ImpedanceController",
    "KneeAngleMeasurements",
    "Measurements",
    "PIDConfig",
    "PIDGains",
    "SB3Controller",
    "as_controller",
    "build_controller",
    "declared_sensors",
    "parse_controller_spec",
    "read_sensors",
]
