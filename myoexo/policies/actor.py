"""The deterministic SAC actor as a small, dependency-free object (numpy), and its files.

A trained SB3 SAC policy acts deterministically as ``tanh(mu(phi(z)))``: ``z`` the observation
normalized by the training run's running statistics, ``phi`` the hidden MLP, ``mu`` the
mean head, and tanh the squashing of the action into [-1, 1]. :class:`MLPActor` is exactly
that, from two files:

* ``<stem>.npz``: the layer weights ``layer{i}.weight`` (out x in) and ``layer{i}.bias``
  (the last layer is the mean head);
* ``<stem>.json``: format version, activation, observation normalization (``obs_mean``,
  ``obs_var``, ``epsilon``, ``clip_obs``; identity when ``normalize_obs`` is false), the
  env it was trained on, training provenance, and reference ``(observation, action)`` pairs
  computed with torch at export time (:meth:`MLPActor.check_reference` replays them).

Inference is float64 numpy (a few microseconds per step, no torch import); ``to_torch``
gives the same function as a ``torch.nn.Module`` (ONNX export, gradients).
"""

from __future__ import annotations

import json
import math
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from myoexo.envs.sensors import Measurements
from myoexo.runtime.files import atomic_path, write_json_atomic

#: Version of the file format written by :func:`save_actor`.
FORMAT_VERSION = 1

_ERF = np.frompyfunc(math.erf, 1, 1)


def _gelu(x: np.ndarray) -> np.ndarray:
    """Exact GELU, ``x * Phi(x)`` (torch's default, not the tanh approximation)."""
    erf = np.asarray(_ERF(x / math.sqrt(2.0)), dtype=np.float64)
    return 0.5 * x * (1.0 + erf)


def clip_in_place(x: np.ndarray, bound: float) -> np.ndarray:
    """*x* clipped to ``[-bound, bound]`` in place and returned (two ufuncs: ``np.clip``'s
    wrapper costs several us per call, which a decision every control step pays)."""
    np.maximum(x, -bound, out=x)
    return np.minimum(x, bound, out=x)


#: The hidden activations a numpy actor computes, by name.
ACTIVATIONS: dict[str, Callable[[np.ndarray], np.ndarray]] = {
    "gelu": _gelu,
    "relu": lambda x: np.maximum(x, 0.0),
    "tanh": np.tanh,
    "elu": lambda x: np.where(x > 0, x, np.expm1(np.minimum(x, 0.0))),
}


def sbx_actor_layers(policy: Any) -> tuple[list[tuple[np.ndarray, np.ndarray]], str]:
    """``(layers, activation)`` of an SBX squashed-Gaussian actor, as numpy arrays:
    ``Dense_0 .. Dense_{n-1}`` hidden, ``Dense_n`` the mean head, ``Dense_{n+1}`` the log-std
    head (flax kernels are (in, out): transposed to (out, in)). Other layers (CrossQ's batch
    renormalization) or an approximate GELU raise ``ValueError``: such an actor acts through
    its model. Reading the parameters waits for an update that is still computing them."""
    params = policy.actor_state.params
    if "params" in params:  # SAC / TQC wrap the layers; CrossQ's batch-norm state does not
        params = params["params"]
    names = sorted(params, key=lambda k: int(k.rpartition("_")[2]) if k[-1].isdigit() else -1)
    if not names or any(not n.startswith("Dense_") for n in names):
        raise ValueError(f"actor layers {sorted(params)} are not a plain MLP")
    dense = [(np.asarray(params[n]["kernel"]).T, np.asarray(params[n]["bias"])) for n in names]
    fn = policy.activation_fn
    base = getattr(fn, "func", fn)
    activation = getattr(base, "__name__", "")
    if activation == "gelu" and getattr(fn, "keywords", {}).get("approximate", True):
        raise ValueError("the actor's GELU is tanh-approximated; the numpy actor's is exact")
    if activation not in ACTIVATIONS:
        raise ValueError(f"activation {activation!r} is not supported by the numpy actor")
    return dense, activation


class MLPActor:
    """Deterministic squashed-Gaussian actor: ``action = tanh(mu(mlp(normalize(obs))))``.

    Args:
        weights: ``[(W0, b0), (W1, b1), ..., (W_mu, b_mu)]``, ``W`` of shape (out, in).
        activation: Hidden activation (``gelu``, ``relu``, ``tanh``, ``elu``).
        obs_mean: Mean subtracted from the observation (``None``: no normalization).
        obs_var: Variance of the observation (with ``obs_mean``).
        epsilon: Added to the variance before the square root.
        clip_obs: Clip of the normalized observation.
        action_low: Lower action bound(s); tanh's [-1, 1] is mapped affinely onto
            [action_low, action_high] (as SB3 does; identity for the exo's [-1, 1]).
        action_high: Upper action bound(s).
        metadata: Provenance (env id, steps, seed, ...), kept as given.

    The object is a myoexo :class:`~myoexo.control.protocol.Controller` (``reset(seed)``,
    ``act(obs, measurements)``, on the observation alone), follows SB3's ``predict(obs,
    state=None, episode_start=None, deterministic=True) -> (action, state)`` and is callable:
    ``actor(obs) -> action``.
    """

    def __init__(
        self,
        weights: list[tuple[np.ndarray, np.ndarray]],
        activation: str = "gelu",
        obs_mean: np.ndarray | None = None,
        obs_var: np.ndarray | None = None,
        epsilon: float = 1e-8,
        clip_obs: float = 10.0,
        action_low: float | np.ndarray = -1.0,
        action_high: float | np.ndarray = 1.0,
        metadata: Mapping[str, Any] | None = None,
    ) -> None:
        if activation not in ACTIVATIONS:
            raise ValueError(f"activation = {activation!r}; accepted: {sorted(ACTIVATIONS)}")
        if len(weights) < 1:
            raise ValueError("weights is empty: need at least the mean head")
        self.weights = [
            (np.asarray(w, dtype=np.float64), np.asarray(b, dtype=np.float64).reshape(-1))
            for w, b in weights
        ]
        for i, (w, b) in enumerate(self.weights):
            if w.ndim != 2 or w.shape[0] != b.size:
                raise ValueError(f"layer {i}: weight {w.shape} and bias {b.shape} do not match")
            if i and w.shape[1] != self.weights[i - 1][0].shape[0]:
                raise ValueError(f"layer {i}: input width {w.shape[1]} != previous output")
        self.activation = activation
        self.obs_dim = int(self.weights[0][0].shape[1])
        self.action_dim = int(self.weights[-1][0].shape[0])
        if (obs_mean is None) != (obs_var is None):
            raise ValueError("give both obs_mean and obs_var, or neither")
        self.obs_mean = None if obs_mean is None else np.asarray(obs_mean, np.float64).ravel()
        self.obs_var = None if obs_var is None else np.asarray(obs_var, np.float64).ravel()
        if (
            self.obs_mean is not None
            and self.obs_var is not None
            and not (self.obs_mean.size == self.obs_var.size == self.obs_dim)
        ):
            raise ValueError(
                f"obs_mean/obs_var sizes {self.obs_mean.size}/{self.obs_var.size} differ from "
                f"the actor's input size {self.obs_dim}"
            )
        self.epsilon = float(epsilon)
        self.clip_obs = float(clip_obs)
        self.action_low = np.array(np.broadcast_to(action_low, (self.action_dim,)), np.float64)
        self.action_high = np.array(np.broadcast_to(action_high, (self.action_dim,)), np.float64)
        if not np.all(self.action_high > self.action_low):
            raise ValueError(
                f"action_high {self.action_high.tolist()} must exceed action_low "
                f"{self.action_low.tolist()}"
            )
        self.metadata = dict(metadata or {})
        # what every call reads, computed once (the actor is not changed after construction)
        self._hidden = [(w.T, b) for w, b in self.weights[:-1]]
        self._head = (self.weights[-1][0].T, self.weights[-1][1])
        self._obs_std = None if self.obs_var is None else np.sqrt(self.obs_var + self.epsilon)
        self._span = self.action_high - self.action_low

    @property
    def obs_preset(self) -> str:
        """Observation preset of the env the actor was trained on (``"full"`` unless its
        metadata says otherwise): build its env with ``make_env(level, obs_preset=...)``."""
        return str(self.metadata.get("obs_preset") or "full")

    @property
    def selection_root_seed(self) -> int | None:
        """Root seed of the subjects that selected this checkpoint (``None``: not recorded);
        an evaluation on the same root would report the subjects that chose it."""
        seed = self.metadata.get("selection_root_seed")
        return None if seed is None else int(seed)

    # ------------------------------------------------------------------ inference
    def normalize(self, obs: np.ndarray) -> np.ndarray:
        """The observation as the network saw it in training (float64, same shape)."""
        x = np.asarray(obs, dtype=np.float64)
        if x.shape[-1:] != (self.obs_dim,):
            raise ValueError(
                f"observation of shape {x.shape}; expected (..., {self.obs_dim}) "
                f"({self.metadata.get('env_id', 'the training env')}'s observation)"
            )
        if self.obs_mean is None or self._obs_std is None:
            return x
        return clip_in_place((x - self.obs_mean) / self._obs_std, self.clip_obs)

    def __call__(self, obs: np.ndarray) -> np.ndarray:
        """Deterministic action(s) in [action_low, action_high], float32, shape
        ``(..., action_dim)``."""
        h = self.normalize(obs)
        act = ACTIVATIONS[self.activation]
        for w_t, b in self._hidden:
            h = act(h @ w_t + b)
        w_t, b = self._head
        squashed = np.tanh(h @ w_t + b)
        return (self.action_low + 0.5 * (squashed + 1.0) * self._span).astype(np.float32)

    def reset(self, seed: int | None = None) -> None:
        """Start of an episode: the deterministic actor has no state to clear."""
        del seed

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """The controller's decision: the deterministic action for one observation, shape
        ``(action_dim,)`` float32 in [action_low, action_high]. ``measurements`` is not
        read."""
        del measurements
        action = self(np.asarray(obs).reshape(self.obs_dim))
        if not np.isfinite(action).all():
            raise ValueError(f"the actor returned a non-finite action {action.tolist()}")
        return action

    def predict(
        self,
        observation: np.ndarray,
        state: Any = None,
        episode_start: Any = None,
        deterministic: bool = True,
    ) -> tuple[np.ndarray, Any]:
        """SB3-compatible ``predict``: ``(action, state)``; only the deterministic (mean)
        action exists here, so ``deterministic=False`` raises ``ValueError``."""
        del episode_start
        if not deterministic:
            raise ValueError(
                "MLPActor holds the deterministic actor only; load the SB3 checkpoint "
                "(model.zip) for stochastic actions"
            )
        return self(observation), state

    # ------------------------------------------------------------------ torch
    def to_torch(self) -> Any:
        """The same function as a float32 ``torch.nn.Module`` (normalization included)."""
        import torch
        from torch import nn

        acts = {"gelu": nn.GELU, "relu": nn.ReLU, "tanh": nn.Tanh, "elu": nn.ELU}
        layers: list[nn.Module] = []
        for i, (w, b) in enumerate(self.weights):
            lin = nn.Linear(w.shape[1], w.shape[0])
            with torch.no_grad():
                lin.weight.copy_(torch.as_tensor(w, dtype=torch.float32))
                lin.bias.copy_(torch.as_tensor(b, dtype=torch.float32))
            layers.append(lin)
            layers.append(acts[self.activation]() if i < len(self.weights) - 1 else nn.Tanh())
        mean = np.zeros(self.obs_dim) if self.obs_mean is None else self.obs_mean
        std = np.ones(self.obs_dim) if self._obs_std is None else self._obs_std
        clip = math.inf if self.obs_mean is None else self.clip_obs
        return _torch_actor_class()(
            nn.Sequential(*layers), mean, std, clip, self.action_low, self.action_high
        )

    # ------------------------------------------------------------------ checks
    def check_reference(self, atol: float = 1e-5) -> float:
        """Max |action - reference| over the stored reference pairs; ``ValueError`` if above
        ``atol`` or if there are none."""
        ref = self.metadata.get("reference")
        if not ref:
            raise ValueError("this actor has no reference (observation, action) pairs")
        obs = np.asarray(ref["observations"], dtype=np.float64)
        expected = np.asarray(ref["actions"], dtype=np.float64)
        err = float(np.max(np.abs(self(obs) - expected)))
        if err > atol:
            raise ValueError(f"actor differs from its reference actions by {err:.3g} > {atol}")
        return err


def _torch_actor_class() -> type:
    import torch
    from torch import nn

    class _TorchActor(nn.Module):
        """``low + (tanh(mlp(clip((obs - mean) / std))) + 1) (high - low) / 2`` in float32."""

        def __init__(
            self,
            mlp: nn.Module,
            mean: np.ndarray,
            std: np.ndarray,
            clip: float,
            low: np.ndarray,
            high: np.ndarray,
        ) -> None:
            super().__init__()
            self.mlp = mlp
            self.register_buffer("obs_mean", torch.as_tensor(mean, dtype=torch.float32))
            self.register_buffer("obs_std", torch.as_tensor(std, dtype=torch.float32))
            self.register_buffer("act_low", torch.as_tensor(low, dtype=torch.float32))
            self.register_buffer(
                "act_half_span", torch.as_tensor(high - low, dtype=torch.float32) / 2
            )
            self.unit_range = bool(np.all(low == -1.0) and np.all(high == 1.0))
            self.clip = float(clip)

        obs_mean: torch.Tensor
        obs_std: torch.Tensor
        act_low: torch.Tensor
        act_half_span: torch.Tensor

        def forward(self, obs: torch.Tensor) -> torch.Tensor:
            z = (obs - self.obs_mean) / self.obs_std
            if math.isfinite(self.clip):
                z = torch.clamp(z, -self.clip, self.clip)
            a = self.mlp(z)
            if self.unit_range:
                return a
            return self.act_low + (a + 1.0) * self.act_half_span

    return _TorchActor


# ---------------------------------------------------------------------------- files
#: Prefix of the actor's arrays in its ``.npz`` (``layer0.weight``, ``layer0.bias``, ...).
LAYER_PREFIX = "layer"


def actor_arrays(actor: MLPActor, prefix: str = LAYER_PREFIX) -> dict[str, np.ndarray]:
    """The actor's layers as float32 arrays named ``<prefix><i>.weight`` / ``.bias``."""
    arrays: dict[str, np.ndarray] = {}
    for i, (w, b) in enumerate(actor.weights):
        arrays[f"{prefix}{i}.weight"] = w.astype(np.float32)
        arrays[f"{prefix}{i}.bias"] = b.astype(np.float32)
    return arrays


def actor_document(actor: MLPActor) -> dict[str, Any]:
    """Everything of the actor but its weights, as JSON: format version, activation,
    normalization, action bounds and its metadata."""
    return {
        "format_version": FORMAT_VERSION,
        "activation": actor.activation,
        "obs_dim": actor.obs_dim,
        "action_dim": actor.action_dim,
        "normalize_obs": actor.obs_mean is not None,
        "obs_mean": None if actor.obs_mean is None else actor.obs_mean.tolist(),
        "obs_var": None if actor.obs_var is None else actor.obs_var.tolist(),
        "epsilon": actor.epsilon,
        "clip_obs": actor.clip_obs,
        "action_low": actor.action_low.tolist(),
        "action_high": actor.action_high.tolist(),
        **{k: v for k, v in actor.metadata.items() if k not in _STRUCTURAL},
    }


def actor_from_document(
    meta: Mapping[str, Any], arrays: Mapping[str, np.ndarray], prefix: str = LAYER_PREFIX
) -> MLPActor:
    """The actor of :func:`actor_document`'s *meta* and :func:`actor_arrays`' *arrays*."""
    n = sum(1 for k in arrays if k.startswith(prefix) and k.endswith(".weight"))
    weights = [(arrays[f"{prefix}{i}.weight"], arrays[f"{prefix}{i}.bias"]) for i in range(n)]
    norm = bool(meta["normalize_obs"])
    return MLPActor(
        weights,
        activation=meta["activation"],
        obs_mean=np.asarray(meta["obs_mean"]) if norm else None,
        obs_var=np.asarray(meta["obs_var"]) if norm else None,
        epsilon=float(meta["epsilon"]),
        clip_obs=float(meta["clip_obs"]),
        action_low=np.asarray(meta["action_low"]),
        action_high=np.asarray(meta["action_high"]),
        metadata={k: v for k, v in meta.items() if k not in _STRUCTURAL},
    )


def save_actor(
    actor: MLPActor, path_stem: str | Path, extra_arrays: Mapping[str, np.ndarray] | None = None
) -> tuple[Path, Path]:
    """Write ``<stem>.npz`` (weights, and *extra_arrays* beside them) and ``<stem>.json``
    (everything else, :func:`actor_document`).

    Returns:
        The two paths written.
    """
    stem = Path(path_stem)
    stem.parent.mkdir(parents=True, exist_ok=True)
    arrays: dict[str, Any] = {**actor_arrays(actor), **(extra_arrays or {})}
    npz, js = stem.with_suffix(".npz"), stem.with_suffix(".json")
    with atomic_path(npz) as tmp, open(tmp, "wb") as f:
        np.savez(f, **arrays)
    write_json_atomic(js, actor_document(actor), indent=1)
    return npz, js


_STRUCTURAL = {
    "format_version",
    "activation",
    "obs_dim",
    "action_dim",
    "normalize_obs",
    "obs_mean",
    "obs_var",
    "epsilon",
    "clip_obs",
    "action_low",
    "action_high",
}


def actor_paths(path_stem: str | Path) -> tuple[Path, Path]:
    """``(<stem>.npz, <stem>.json)`` of an actor's files (a suffix of *path_stem* is ignored).

    Raises:
        FileNotFoundError: Either file is missing.
    """
    stem = Path(path_stem)
    if stem.suffix in (".npz", ".json"):
        stem = stem.with_suffix("")
    npz, js = stem.with_suffix(".npz"), stem.with_suffix(".json")
    for p in (npz, js):
        if not p.is_file():
            raise FileNotFoundError(f"actor file {str(p)!r} does not exist")
    return npz, js


def read_actor_files(path_stem: str | Path) -> tuple[dict[str, Any], dict[str, np.ndarray]]:
    """The document and every array of the files :func:`save_actor` wrote (``<stem>.json``,
    ``<stem>.npz``; the arrays include the *extra_arrays* saved beside the weights).

    Raises:
        ValueError: The document's format is not the one this myoexo reads.
    """
    npz, js = actor_paths(path_stem)
    meta = json.loads(js.read_text())
    if meta.get("format_version") != FORMAT_VERSION:
        raise ValueError(
            f"{js}: format_version {meta.get('format_version')!r}, this myoexo reads "
            f"{FORMAT_VERSION}"
        )
    with np.load(npz) as data:
        return meta, {k: data[k] for k in data.files}


def load_actor(path_stem: str | Path) -> MLPActor:
    """Read an actor written by :func:`save_actor` (``<stem>.npz`` + ``<stem>.json``)."""
    return actor_from_document(*read_actor_files(path_stem))
