"""Export a trained SAC policy: the deterministic actor (observation normalization included)
as a small numpy actor (``.npz`` + ``.json``, what :func:`myoexo.load_policy` reads) or ONNX.

CLI::

    myoexo policy export RUN --onnx actor.onnx            # newest checkpoint of RUN
    myoexo policy export RUN --checkpoint best --out my_actor
    myoexo policy export RUN --checkpoint 1200000 --ship   # into myoexo/policies/

``RUN`` is a run folder (``myoexo policy train``) or one of its ``checkpoints/step_*`` folders.
"""

from __future__ import annotations

import argparse
import json
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.control.residual import RESIDUAL_KEY, ResidualConfig
from myoexo.control.specs import TRAINING_ENVS_KEY
from myoexo.envs.options import TwinOptions
from myoexo.model import recorded_twin_version
from myoexo.policies.actor import MLPActor, save_actor, sbx_actor_layers
from myoexo.policies.student import StudentController
from myoexo.runtime.fields import add_options, add_positional, check_fields, from_options, option
from myoexo.training import checkpoints as ck

#: Reference observations stored with an exported actor (seeded standard normal, scaled).
N_REFERENCE = 8
REFERENCE_SEED = 20240601


def actor_from_sac(
    model: Any, vec_normalize: Any = None, metadata: dict[str, Any] | None = None
) -> MLPActor:
    """The deterministic actor of a SAC-family model as an :class:`MLPActor`.

    Args:
        model: A SAC / TQC model of stable-baselines3 or SBX (JAX) with an MLP
            actor on a flat Box observation.
        vec_normalize: The ``VecNormalize`` the model was trained behind (``None``: the
            model's own, if any); its observation statistics become the actor's.
        metadata: Provenance stored with the actor.
    """
    if hasattr(model.policy, "actor_state"):  # SBX (JAX)
        layers, activation = sbx_actor_layers(model.policy)
        weights = layers[:-1]  # the log-std head is not part of the deterministic actor
    else:
        weights, activation = _torch_actor_layers(model.policy)
    bounds = {"action_low": model.action_space.low, "action_high": model.action_space.high}
    vn = vec_normalize if vec_normalize is not None else model.get_vec_normalize_env()
    if vn is not None and vn.norm_obs:
        rms = vn.obs_rms
        return MLPActor(
            weights,
            activation,
            obs_mean=rms.mean,
            obs_var=rms.var,
            epsilon=vn.epsilon,
            clip_obs=vn.clip_obs,
            metadata=metadata,
            **bounds,
        )
    return MLPActor(weights, activation, metadata=metadata, **bounds)


def _torch_actor_layers(policy: Any) -> tuple[list[tuple[np.ndarray, np.ndarray]], str]:
    """``(weights, activation)`` of an SB3 (torch) squashed-Gaussian actor."""
    from torch import nn

    actor = policy.actor
    linears = [m for m in actor.latent_pi if isinstance(m, nn.Linear)]
    acts = {type(m).__name__.lower() for m in actor.latent_pi if not isinstance(m, nn.Linear)}
    if len(acts) > 1:
        raise ValueError(f"mixed hidden activations {sorted(acts)} are not supported")
    if getattr(actor, "use_sde", False):
        raise ValueError("gSDE actors are not supported by the export (use_sde=False)")
    weights = [
        (lin.weight.detach().cpu().numpy(), lin.bias.detach().cpu().numpy())
        for lin in [*linears, actor.mu]
    ]
    return weights, acts.pop() if acts else "gelu"


def reference_pairs(
    actor: MLPActor, model: Any = None, vec_normalize: Any = None
) -> dict[str, list[list[float]]]:
    """Fixed observations and the actions torch gives for them, for later consistency checks:
    the SB3 policy itself (behind ``vec_normalize``) when ``model`` is given, else
    :meth:`MLPActor.to_torch`."""
    import torch

    rng = np.random.default_rng(REFERENCE_SEED)
    mean = np.zeros(actor.obs_dim) if actor.obs_mean is None else actor.obs_mean
    std = np.ones(actor.obs_dim) if actor.obs_var is None else np.sqrt(actor.obs_var)
    obs = (mean + std * rng.standard_normal((N_REFERENCE, actor.obs_dim))).astype(np.float32)
    if model is not None:
        z = vec_normalize.normalize_obs(obs) if vec_normalize is not None else obs
        action, _ = model.predict(z, deterministic=True)
    else:
        with torch.no_grad():
            action = actor.to_torch()(torch.as_tensor(obs)).numpy()
    return {
        "observations": obs.astype(np.float64).tolist(),
        "actions": np.asarray(action, dtype=np.float64).tolist(),
    }


def deterministic_controller(
    model: Any,
    vec_normalize: Any = None,
    metadata: dict[str, Any] | None = None,
    name: str | None = None,
) -> Any:
    """A trained model's deterministic policy as a controller: its numpy actor
    (:func:`actor_from_sac`: SAC, TQC), or, for an actor the export does not cover (CrossQ's
    batch-renormalized layers), the SB3 model behind its observation statistics.

    Args:
        model: The SB3 model.
        vec_normalize: Its ``VecNormalize`` (``None``: the model's own, if any).
        metadata: Provenance; its ``obs_preset`` names the env the controller needs.
        name: Label of the SB3 fallback (default: the model's class name).
    """
    from myoexo.control.policy import SB3Controller

    try:
        return actor_from_sac(model, vec_normalize, metadata=metadata)
    except (ValueError, AttributeError):
        vn = vec_normalize if vec_normalize is not None else model.get_vec_normalize_env()
        return SB3Controller(
            model,
            name=name,
            obs_normalizer=vn,
            obs_preset=str((metadata or {}).get("obs_preset") or "full"),
        )


def _checkpoint_parts(
    checkpoint: Path, selection_root_seed: int | None = None
) -> tuple[Any, Any, dict[str, Any]]:
    """``(model, VecNormalize or None, provenance)`` of a checkpoint folder."""
    from stable_baselines3.common.vec_env import VecNormalize

    from myoexo.policies.algorithms import algorithm_class
    from myoexo.training.config import RECORD_KEYS, config_from_record

    checkpoint = Path(checkpoint)
    run_dir = checkpoint.parent.parent
    config = ck.read_config(run_dir) if (run_dir / ck.CONFIG_FILE).is_file() else {}
    holds_config = any(k in config for k in RECORD_KEYS)
    train_config = config_from_record(config) if holds_config else None
    state = ck.read_state(checkpoint)
    algorithm = train_config.algorithm if train_config else state.get("algorithm", "sac")
    model = algorithm_class(algorithm).load(checkpoint / ck.MODEL_FILE, device="cpu")
    vn = None
    if (checkpoint / ck.VECNORM_FILE).is_file():
        import pickle

        with open(checkpoint / ck.VECNORM_FILE, "rb") as f:
            vn = pickle.load(f)
        if not isinstance(vn, VecNormalize):
            raise ValueError(f"{checkpoint / ck.VECNORM_FILE} is not a VecNormalize pickle")
    # the twin the policy was trained on: the checkpoint's own record (older checkpoints:
    # the run's config)
    if state.get("twin"):
        twin = TwinOptions.from_dict(state["twin"])
    else:
        twin = train_config.twin if train_config else TwinOptions()
    meta = {
        "env_id": config.get("env_id"),
        "obs_keys": config.get("obs_keys"),
        "obs_preset": twin.obs_preset,
        "reward_weights": [list(p) for p in twin.reward_weights],
        "twin": twin.to_dict(),
        "twin_version": recorded_twin_version(state),
        "selection_root_seed": (
            selection_root_seed
            if selection_root_seed is not None
            else state.get("selection_root_seed")  # recorded by myoexo policy select
        ),
        "preset": train_config.name if train_config else None,
        "algorithm": algorithm,
        "seed": config.get("seed"),
        "num_timesteps": state.get("num_timesteps"),
        "train_wall_time_s": state.get("wall_time_s"),
        "n_updates": state.get("n_updates"),
        "checkpoint": f"{run_dir.name}/{ck.CHECKPOINTS_DIR}/{checkpoint.name}",
        "versions": config.get("versions"),
    }
    if state.get(RESIDUAL_KEY):  # a residual policy: the classical controller it corrects
        meta[RESIDUAL_KEY] = dict(state[RESIDUAL_KEY])
    # trained on both twins: the checkpoint's record (older checkpoints: the run's config)
    if state.get(TRAINING_ENVS_KEY):
        meta[TRAINING_ENVS_KEY] = dict(state[TRAINING_ENVS_KEY])
    elif train_config is not None and train_config.nominal_envs:
        meta[TRAINING_ENVS_KEY] = train_config.training_envs()
    return model, vn, meta


def load_checkpoint_actor(
    checkpoint: Path, with_reference: bool = True, selection_root_seed: int | None = None
) -> MLPActor:
    """:class:`MLPActor` of a checkpoint folder, with provenance and reference pairs.

    Args:
        checkpoint: A ``checkpoints/step_*`` folder of a ``myoexo policy train`` run.
        with_reference: Store (and check) reference observation/action pairs.
        selection_root_seed: Root seed of the subjects that selected this checkpoint
            (``myoexo policy select``), recorded so that an evaluation on that root is refused.
    """
    model, vn, meta = _checkpoint_parts(checkpoint, selection_root_seed)
    actor = actor_from_sac(model, vn, metadata=meta)
    if with_reference:
        actor.metadata["reference"] = reference_pairs(actor, model, vn)
        actor.check_reference()
    return actor


def load_checkpoint_controller(checkpoint: Path, gentleness: float | None = None) -> Any:
    """A checkpoint's deterministic policy as a controller with an ``obs_preset``
    (:func:`deterministic_controller`), on its residual base if it was trained on one and,
    if it was trained over the gentleness range, run at weight *gentleness* (the layout of
    training: ``GentleController(ResidualController(policy))``).

    Raises:
        ValueError: The policy was trained over the gentleness range and *gentleness* is
            ``None``, or it was not and *gentleness* is given.
    """
    model, vn, meta = _checkpoint_parts(checkpoint)
    gentle = trained_over_gentleness(meta)
    if gentle and gentleness is None:
        raise ValueError(
            f"{checkpoint} was trained over the gentleness range: give the weight it runs at "
            "(gentleness in [0, 1])"
        )
    if not gentle and gentleness is not None:
        raise ValueError(
            f"{checkpoint} was not trained with a gentleness weight; got gentleness={gentleness!r}"
        )
    controller = deterministic_controller(model, vn, meta, name=Path(checkpoint).name)
    residual = ResidualConfig.from_metadata(meta)
    if residual is not None:
        from myoexo.control.specs import with_residual_base
        from myoexo.envs import make_env

        twin = TwinOptions.from_dict(meta["twin"])
        env = make_env(0, **twin.env_kwargs())  # the base controller samples at its period
        try:
            controller = with_residual_base(controller, residual, env)
        finally:
            env.close()
    if gentleness is None:
        return controller
    from myoexo.control.policy import GentleController

    return GentleController(controller, gentleness)


#: The record ``myoexo policy gentleness`` writes (the default weight and its provenance).
GENTLENESS_RECORD_FILE = "gentleness.json"


def read_gentleness_record(path: Path) -> dict[str, Any]:
    """A ``gentleness.json`` of ``myoexo policy gentleness`` (or the folder holding one).

    Raises:
        ValueError: The file is missing or holds no ``default_gentleness``.
    """
    path = Path(path)
    if path.is_dir():
        path = path / GENTLENESS_RECORD_FILE
    try:
        record = json.loads(path.read_text())
        float(record["default_gentleness"])
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise ValueError(f"{str(path)!r} is no gentleness record ({exc})") from None
    return dict(record)


def record_default_gentleness(actor: MLPActor | StudentController, path: Path, source: str) -> None:
    """Make the default weight of the gentleness record at *path* (a ``gentleness.json`` or
    its folder) *actor*'s own (an exported policy or a distilled student): its metadata gains
    ``default_gentleness`` and the record, and the record's subjects become its selection
    root (evaluations there are refused).

    Raises:
        ValueError: *actor* was not trained over the gentleness range (*source* names it), or
            *path* holds no record.
    """
    if not trained_over_gentleness(actor.metadata):
        raise ValueError(
            f"{source} was not trained with a gentleness weight; drop --gentleness-record"
        )
    record = read_gentleness_record(Path(path))
    actor.metadata["default_gentleness"] = float(record["default_gentleness"])
    actor.metadata["gentleness_record"] = record
    actor.metadata["selection_root_seed"] = actor.metadata.get("selection_root_seed") or int(
        record["root_seed"]
    )


def trained_over_gentleness(metadata: dict[str, Any]) -> bool:
    """Whether a policy's metadata records a twin with a gentleness weight (its last
    observation entry is the weight)."""
    twin = metadata.get("twin")
    return isinstance(twin, dict) and bool(twin.get("gentleness"))


def export_onnx(actor: MLPActor, path: str | Path, opset: int = 17) -> Path:
    """Write the actor (normalization, MLP, tanh) as ONNX: input ``obs`` (batch, obs_dim)
    float32, output ``action`` (batch, action_dim) in [-1, 1]. A policy trained over the
    gentleness range takes the weight as an input of its own: ``obs`` (batch, obs_dim - 1)
    and ``gentleness`` (batch, 1)."""
    import torch

    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    module = actor.to_torch().eval()
    inputs: tuple[Any, ...] = (torch.zeros(1, actor.obs_dim),)
    names = ["obs"]
    if trained_over_gentleness(actor.metadata):
        module = _weight_input(module).eval()
        inputs = (torch.zeros(1, actor.obs_dim - 1), torch.zeros(1, 1))
        names = ["obs", "gentleness"]
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the TorchScript exporter's deprecation notice
        torch.onnx.export(
            module,
            inputs,
            str(path),
            input_names=names,
            output_names=["action"],
            dynamic_axes={**{n: {0: "batch"} for n in names}, "action": {0: "batch"}},
            opset_version=opset,
            dynamo=False,
        )
    return path


def _weight_input(module: Any) -> Any:
    """*module* with the gentleness weight as a second input, appended to the observation."""
    import torch

    class WeightInput(torch.nn.Module):
        def __init__(self, inner: Any) -> None:
            super().__init__()
            self.inner = inner

        def forward(self, obs: Any, gentleness: Any) -> Any:
            return self.inner(torch.cat([obs, gentleness], dim=-1))

    return WeightInput(module)


# ---------------------------------------------------------------------------- CLI
@dataclass(frozen=True)
class ExportRun:
    """What ``myoexo policy export`` exports (a run's checkpoint) and where it writes it."""

    run: str = option("", "training run folder, or one of its checkpoints/step_* folders", flag="")
    checkpoint: str = option(
        "latest",
        "'latest', 'best' (highest small-evaluation score) or a step number",
        metavar="CHECKPOINT",
    )
    onnx: str | None = option(None, "write the actor as ONNX to FILE", metavar="FILE")
    out: str | None = option(None, "write the numpy actor to STEM.npz + STEM.json", metavar="STEM")
    ship: str | None = option(
        None,
        "write the numpy actor into the package as NAME (default 'sac', what "
        "myoexo.load_policy() returns; 'student_exo' is written by myoexo policy distill)",
        metavar="NAME",
        const="sac",
    )
    selection_root_seed: int | None = option(
        None,
        "root seed of the subjects that chose this checkpoint (myoexo policy select's "
        "--root-seed); recorded, and evaluations on that root are refused (default: none)",
    )
    gentleness_record: str | None = option(
        None,
        "a `myoexo policy gentleness` record (gentleness.json or its folder): its default "
        "weight becomes the policy's (a policy trained with --gentleness random)",
        metavar="FILE",
    )
    seed_group: str | None = option(
        None,
        "the seed group the actor is one member of (the training configuration's name): "
        "the actors of one group, evaluated together, are one controller of the tables, "
        "with intervals over seeds and subjects",
        metavar="NAME",
    )

    def __post_init__(self) -> None:
        check_fields(self)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """Arguments of ``myoexo policy export`` (:class:`ExportRun`)."""
    add_positional(parser, ExportRun, "run")
    add_options(parser, ExportRun)


def run(args: argparse.Namespace) -> int:
    """Run ``myoexo policy export``."""
    options: ExportRun = from_options(ExportRun, args, run=args.run)
    if not (options.onnx or options.out or options.ship):
        raise SystemExit("policy export: nothing to do; give --onnx FILE, --out STEM or --ship")
    checkpoint = ck.resolve_checkpoint(options.run, options.checkpoint)
    actor = load_checkpoint_actor(checkpoint, selection_root_seed=options.selection_root_seed)
    if options.gentleness_record:
        record_default_gentleness(actor, Path(options.gentleness_record), str(checkpoint))
    if options.seed_group:
        actor.metadata["seed_group"] = options.seed_group
    print(f"checkpoint: {checkpoint} ({actor.metadata.get('num_timesteps')} steps)")
    if options.onnx:
        print(f"onnx:  {export_onnx(actor, options.onnx)}")
    stems = [Path(options.out)] if options.out else []
    if options.ship:
        from myoexo.policies import shipped_path

        stems.append(shipped_path(options.ship))
    for stem in stems:
        npz, js = save_actor(actor, stem)
        print(f"actor: {npz} + {js.name}")
    print(json.dumps({k: actor.metadata.get(k) for k in ("preset", "seed", "num_timesteps")}))
    return 0
