"""Controllers of the exoskeleton: the paper's PID baseline, its Ziegler-Nichols tuning on the
twin, and adapters that make any learned policy a controller.

Every controller fits :class:`Controller` (``reset(seed)``, ``act(obs, info) -> action``)::

    import gymnasium as gym, myoexo
    from myoexo.control import PID

    env = gym.make("MyoExoKnee-v1")
    pid = PID.from_env(env)                  # Kp = 7, Ki = 40, Kd = 0.05 on the error in rad
    obs, info = env.reset(seed=0)
    pid.reset(seed=0)
    while True:
        obs, r, term, trunc, info = env.step(pid.act(obs, info))
        if term or trunc:
            break
"""

from myoexo.control.pid import ANTI_WINDUP_SCHEMES, PID, PIDConfig, PIDGains
from myoexo.control.policy import CallableController, SB3Controller, as_controller
from myoexo.control.protocol import Controller
from myoexo.control.specs import ControllerSpec, build_controller, parse_controller_spec

__all__ = [
    "ANTI_WINDUP_SCHEMES",
    "PID",
    "CallableController",
    "Controller",
    "ControllerSpec",
    "PIDConfig",
    "PIDGains",
    "SB3Controller",
    "as_controller",
    "build_controller",
    "parse_controller_spec",
]
