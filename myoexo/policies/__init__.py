"""The SAC policy shipped with myoexo (see ``MODEL_CARD.md`` beside this file).

    import gymnasium as gym, myoexo

    policy = myoexo.load_policy()              # offline: two small files in this folder
    env = gym.make("MyoExoKnee-v1")
    obs, info = env.reset(seed=0)
    action = policy.act(obs, info)                         # a myoexo Controller
    action, _ = policy.predict(obs, deterministic=True)   # SB3's signature
    action = policy(obs)                                   # or simply call it

The policy is the deterministic actor of a stable-baselines3 SAC run (observation
normalization included) as a numpy :class:`~myoexo.policies.actor.MLPActor`; ``to_torch()``
gives it as a torch module. It was trained on ``MyoExoKneeRandom-v0`` and expects that env's
observation vector (``env.unwrapped.obs_keys`` in the default order).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from myoexo.policies.actor import MLPActor, load_actor, save_actor

#: File stem of the shipped actor (``.npz`` weights + ``.json`` normalization and provenance).
SHIPPED_POLICY = "sac_knee_exo"

__all__ = ["SHIPPED_POLICY", "MLPActor", "load_actor", "load_policy", "save_actor", "shipped_path"]


def shipped_path(name: str = SHIPPED_POLICY) -> Path:
    """Path stem of a policy shipped in this package (no suffix)."""
    return Path(str(resources.files(__name__).joinpath(name)))


def load_policy(name: str = SHIPPED_POLICY, check: bool = True) -> MLPActor:
    """Load a policy shipped with the package (no network, no SB3 needed).

    Args:
        name: File stem inside ``myoexo/policies/``.
        check: Replay the reference (observation, action) pairs stored at export time and
            raise ``ValueError`` if the loaded actor disagrees (corrupted or edited files).

    Raises:
        FileNotFoundError: No such shipped policy.
    """
    actor = load_actor(shipped_path(name))
    if check:
        actor.check_reference()
    return actor
