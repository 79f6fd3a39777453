"""The spasticity coefficient of Table I (eqs. 1-4) in numpy and, differentiable, in torch.

``SC_total(theta, v) = sc_a(theta) + sc_v(v)``: an angle and a velocity term, each a soft
window built from two sigmoids ``phi(k, b, b0) = 1 / (1 + exp(k (b - b0)))`` (eq. 2; written
with tanh, no overflow). The torch twins take tensors for the inputs and for every parameter,
so gradients flow to all of them. :func:`below` and :func:`above` are the one-sided sigmoids
the reflex models (:mod:`myoexo.spasticity.reflex`) build on.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import TYPE_CHECKING, Any

import numpy as np

from myoexo.spasticity.levels import SpasticityParams

if TYPE_CHECKING:  # torch is imported lazily: ``import myoexo`` must stay fast
    import torch


def below(x: Any, limit: float, k: float) -> Any:
    """``1 / (1 + exp(k (x - limit)))``: -> 1 below ``limit``, 1/2 at it, -> 0 above
    (eq. 2's ``phi``, evaluated with tanh: no overflow)."""
    return 0.5 * (1.0 - np.tanh(0.5 * k * (np.asarray(x, dtype=np.float64) - limit)))


def above(x: Any, limit: float, k: float) -> Any:
    """``1 - below(x, limit, k)``: -> 1 above ``limit``."""
    return 0.5 * (1.0 + np.tanh(0.5 * k * (np.asarray(x, dtype=np.float64) - limit)))


def _finite_array(name: str, value: Any) -> np.ndarray:
    arr = np.asarray(value, dtype=np.float64)
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} must be finite, got {value!r}.")
    return arr


def phi(k: float, b: Any, b0: float) -> np.ndarray:
    """Sigmoid of eq. 2, ``1 / (1 + exp(k (b - b0)))``, vectorized over *b*.

    Evaluated as ``(1 - tanh(k (b - b0) / 2)) / 2``, which is the same function without
    overflow for large ``k |b - b0|`` (:func:`below`: -> 1 below ``b0``).
    """
    return below(b, b0, k)


def angle_term(
    theta_deg: Any, half_k: Any, theta_ext_deg: Any, theta_flex_deg: Any, s_theta: Any, tanh: Any
) -> Any:
    """``sc_a`` from its constants, in any array library: ``s_theta / 2 * (2 - tanh(k/2
    (theta - theta_ext)) + tanh(k/2 (theta - theta_flex)))``, the same as eq. 3.

    The one copy of the angle term: :func:`sc_angle` (``tanh=np.tanh``), its torch twin
    (``torch.tanh``) and the reflex models' per-step scalar path (``math.tanh``) all call it,
    with ``half_k = k / 2``."""
    return (
        0.5
        * s_theta
        * (
            2.0
            - tanh(half_k * (theta_deg - theta_ext_deg))
            + tanh(half_k * (theta_deg - theta_flex_deg))
        )
    )


def velocity_term(
    vel_rad_s: Any, half_k: Any, v_lower_rad_s: Any, v_upper_rad_s: Any, s_v: Any, tanh: Any
) -> Any:
    """``sc_v`` from its constants, in any array library (see :func:`angle_term`; eq. 4)."""
    return (
        0.5
        * s_v
        * (
            2.0
            - tanh(half_k * (vel_rad_s - v_lower_rad_s))
            + tanh(half_k * (vel_rad_s - v_upper_rad_s))
        )
    )


def _scalar_or_array(out: np.ndarray) -> np.ndarray | float:
    return float(out) if out.ndim == 0 else out


def sc_angle(theta_deg: Any, params: SpasticityParams) -> np.ndarray | float:
    """Angle term ``sc_a`` of the spasticity coefficient.

    Args:
        theta_deg: Knee angle(s) in degrees, flexion positive (any array shape).
        params: Level or subject parameters.

    Returns:
        ``sc_a`` with the shape of *theta_deg* (a float for a scalar input).

    Raises:
        ValueError: If an angle is NaN or infinite.
    """
    theta = _finite_array("theta_deg", theta_deg)
    p = params
    return _scalar_or_array(
        angle_term(theta, 0.5 * p.k, p.theta_ext_deg, p.theta_flex_deg, p.s_theta, np.tanh)
    )


def sc_velocity(vel_rad_s: Any, params: SpasticityParams) -> np.ndarray | float:
    """Velocity term ``sc_v`` of the spasticity coefficient.

    Args:
        vel_rad_s: Knee velocity(ies) in rad/s, flexion positive (any array shape).
        params: Level or subject parameters.

    Returns:
        ``sc_v`` with the shape of *vel_rad_s* (a float for a scalar input).

    Raises:
        ValueError: If a velocity is NaN or infinite.
    """
    vel = _finite_array("vel_rad_s", vel_rad_s)
    p = params
    return _scalar_or_array(
        velocity_term(vel, 0.5 * p.k, p.v_lower_rad_s, p.v_upper_rad_s, p.s_v, np.tanh)
    )


def sc_total(theta_deg: Any, vel_rad_s: Any, params: SpasticityParams) -> np.ndarray | float:
    """Spasticity coefficient ``SC_total = sc_a(theta) + sc_v(v)`` (broadcast over inputs).

    Args:
        theta_deg: Knee angle(s) in degrees, flexion positive.
        vel_rad_s: Knee velocity(ies) in rad/s, flexion positive.
        params: Level or subject parameters.

    Returns:
        ``SC_total``, a fraction of maximum isometric force in ``[0, s_theta + s_v]``.

    Raises:
        ValueError: If an input is NaN or infinite.
    """
    return sc_angle(theta_deg, params) + sc_velocity(vel_rad_s, params)


# ----------------------------------------------------------------------------- torch twin
def tensor_getter(like: Any) -> Any:
    """``get(source, name)``, for the reflex models' torch twins: a mapping's or a
    dataclass's entry as a tensor like *like*."""
    import torch

    def get(source: Any, name: str) -> torch.Tensor:
        value = source[name] if isinstance(source, Mapping) else getattr(source, name)
        if isinstance(value, torch.Tensor):
            return value
        return torch.as_tensor(value, dtype=like.dtype, device=like.device)

    return get


def as_tensor(value: Any) -> torch.Tensor:
    """*value* as a tensor (float64 unless it is one already)."""
    import torch

    return value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float64)


_TorchParams = SpasticityParams | Mapping[str, Any]


def _torch_param(params: _TorchParams, name: str, like: torch.Tensor) -> torch.Tensor:
    import torch

    value = getattr(params, name) if isinstance(params, SpasticityParams) else params[name]
    if isinstance(value, torch.Tensor):
        return value
    return torch.as_tensor(value, dtype=like.dtype, device=like.device)


def _finite_tensor(name: str, value: Any) -> torch.Tensor:
    import torch

    tensor = (
        value if isinstance(value, torch.Tensor) else torch.as_tensor(value, dtype=torch.float64)
    )
    if not bool(torch.isfinite(tensor).all()):
        raise ValueError(f"{name} must be finite, got {value!r}.")
    return tensor


def phi_torch(k: torch.Tensor, b: torch.Tensor, b0: torch.Tensor) -> torch.Tensor:
    """Torch twin of :func:`phi` (differentiable in ``k``, ``b`` and ``b0``)."""
    import torch

    return 0.5 * (1.0 - torch.tanh(0.5 * k * (b - b0)))


def sc_angle_torch(theta_deg: Any, params: _TorchParams) -> torch.Tensor:
    """Torch twin of :func:`sc_angle`.

    Args:
        theta_deg: Knee angle(s) in degrees (tensor, or anything ``torch.as_tensor`` takes:
            float64 then).
        params: A :class:`SpasticityParams` (constants) or a mapping from its field names to
            tensors (or floats); gradients flow to every tensor given.

    Raises:
        ValueError: If an angle is NaN or infinite.
    """
    import torch

    theta = _finite_tensor("theta_deg", theta_deg)

    def get(name: str) -> torch.Tensor:
        return _torch_param(params, name, theta)

    return angle_term(
        theta, 0.5 * get("k"), get("theta_ext_deg"), get("theta_flex_deg"), get("s_theta"),
        torch.tanh,
    )  # fmt: skip


def sc_velocity_torch(vel_rad_s: Any, params: _TorchParams) -> torch.Tensor:
    """Torch twin of :func:`sc_velocity` (see :func:`sc_angle_torch` for *params*).

    Raises:
        ValueError: If a velocity is NaN or infinite.
    """
    import torch

    vel = _finite_tensor("vel_rad_s", vel_rad_s)

    def get(name: str) -> torch.Tensor:
        return _torch_param(params, name, vel)

    return velocity_term(
        vel, 0.5 * get("k"), get("v_lower_rad_s"), get("v_upper_rad_s"), get("s_v"), torch.tanh
    )


def sc_total_torch(theta_deg: Any, vel_rad_s: Any, params: _TorchParams) -> torch.Tensor:
    """Torch twin of :func:`sc_total`, differentiable in the inputs and every parameter.

    Example::

        p = {n: torch.tensor(v, dtype=torch.float64, requires_grad=True)
             for n, v in zip(SpasticityParams.field_names(), LEVELS[2].as_array())}
        sc_total_torch(torch.tensor(80.0, dtype=torch.float64), 0.3, p).backward()

    Raises:
        ValueError: If an input is NaN or infinite.
    """
    return sc_angle_torch(theta_deg, params) + sc_velocity_torch(vel_rad_s, params)
