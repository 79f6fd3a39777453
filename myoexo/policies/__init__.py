"""The SAC policies shipped with myoexo (a model card each beside this file).

=============  ========================  ====================================================
name           files (``<stem>.npz/json``)  observation
=============  ========================  ====================================================
``sac``        ``sac_knee_exo``          ``obs_preset="full"``: the twin's whole state, muscle
                                         activations, forces and lengths included (simulation
                                         only); ``MODEL_CARD.md``
``sac_exo``    ``sac_exo_sensors``       ``obs_preset="exo"``: only what the exoskeleton
                                         measures (encoder, motor torque, cuff force/torque
                                         sensors, last command, time): deployable;
                                         ``MODEL_CARD_sac_exo.md``
=============  ========================  ====================================================

    import gymnasium as gym, myoexo

    policy = myoexo.load_policy()              # "sac"; offline: two small files in this folder
    device_policy = myoexo.load_policy("sac_exo")
    env = gym.make("MyoExoKnee-v1", obs_preset=device_policy.obs_preset)
    obs, info = env.reset(seed=0)
    action = policy.act(obs, info)                         # a myoexo Controller
    action, _ = policy.predict(obs, deterministic=True)   # SB3's signature
    action = policy(obs)                                   # or simply call it

The policy is the deterministic actor of a stable-baselines3 SAC run (observation
normalization included) as a numpy :class:`~myoexo.policies.actor.MLPActor`; ``to_torch()``
gives it as a torch module. Each was trained on ``MyoExoKneeRandom-v0`` and expects that
env's observation vector for its preset (``policy.obs_preset``; the keys are recorded as
``policy.metadata["obs_keys"]``).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from myoexo.policies.actor import MLPActor, load_actor, save_actor

#: File stem of the default shipped actor (``.npz`` weights + ``.json`` normalization and
#: provenance).
SHIPPED_POLICY = "sac_knee_exo"

#: Shipped policies: name -> file stem inside this folder.
SHIPPED_POLICIES: dict[str, str] = {"sac": SHIPPED_POLICY, "sac_exo": "sac_exo_sensors"}

__all__ = [
    "SHIPPED_POLICIES",
    "SHIPPED_POLICY",
    "MLPActor",
    "load_actor",
    "load_policy",
    "save_actor",
    "shipped_path",
]


def shipped_path(name: str = SHIPPED_POLICY) -> Path:
    """Path stem (no suffix) of a policy shipped in this package, by name
    (:data:`SHIPPED_POLICIES`) or file stem."""
    return Path(str(resources.files(__name__).joinpath(SHIPPED_POLICIES.get(name, name))))


def load_policy(name: str = "sac", check: bool = True) -> MLPActor:
    """Load a policy shipped with the package (no network, no SB3 needed).

    Args:
        name: ``"sac"`` (full-state observation), ``"sac_exo"`` (the exoskeleton's own
            sensors, deployable), or a file stem inside ``myoexo/policies/``.
        check: Replay the reference (observation, action) pairs stored at export time and
            raise ``ValueError`` if the loaded actor disagrees (corrupted or edited files).

    Raises:
        FileNotFoundError: No such shipped policy (the message lists the names).
    """
    path = shipped_path(name)
    if not path.with_suffix(".npz").is_file():
        raise FileNotFoundError(f"no shipped policy {name!r}; accepted: {sorted(SHIPPED_POLICIES)}")
    actor = load_actor(path)
    if check:
        actor.check_reference()
    return actor
