"""Numerical stability of the perturbed twin at the corners of its documented ranges.

The twin integrates its coupling springs explicitly (semi-implicit Euler, 2 ms). Before the
perturbation raised the coupling armature with the strap stiffness and scaled the weld in
MuJoCo's own terms (:mod:`myoexo.envs.robustness`), stiff straps (x1.6-2) let an exo-chain
mode near 50 Hz grow by ~1 % per physics step: episodes chattered for seconds, then MuJoCo
reset the data.
"""

from __future__ import annotations

import numpy as np
import pytest

from myoexo.envs import make_env
from myoexo.envs.robustness import RobustnessParams

#: (strap stiffness scale, strap damping scale): the corners and edges of the default ranges.
CORNERS = [(2.0, 0.5), (2.0, 1.0), (2.0, 1.4), (2.0, 2.0), (0.5, 0.5), (0.5, 2.0)]
#: The pins the straps load (the shank pin carries the stiff, light cuff).
PINS = ("exo_thigh_pin", "exo_shank_pin")
#: Bound on the pins' speed (rad/s). The nominal twin reaches ~20 under a +-1 bang-bang at
#: the control rate; the chattering stiff draws reached hundreds before they diverged.
MAX_PIN_SPEED_RAD_S = 50.0


def _corner_env(k: float, c: float, duration_s: float = 3.0):
    params = RobustnessParams(strap_stiffness_scale=(k, k), strap_damping_scale=(c, c))
    return make_env(2, robustness=params, episode_duration_s=duration_s)


def _fast_modes_radius(model, data) -> float:
    """Largest |eigenvalue| of the one-physics-step transition among its modes above
    100 rad/s (0.2 rad per 2 ms step): the numerical ones, not the leg's slow dynamics."""
    import mujoco

    nx = 2 * model.nv + model.na
    a = np.zeros((nx, nx))
    probe = mujoco.MjData(model)
    mujoco.mj_copyData(probe, model, data)
    mujoco.mjd_transitionFD(model, probe, 1e-7, 1, a, None, None, None)
    ev = np.linalg.eigvals(a)
    ev = ev[np.abs(np.angle(ev)) > 0.2]
    return float(np.abs(ev).max())


@pytest.mark.parametrize("k, c", CORNERS)
def test_extreme_draw_survives_bang_bang(k, c):
    env = _corner_env(k, c)
    base = env.unwrapped
    dofs = [base.model.joint(name).dofadr[0] for name in PINS]
    try:
        for seed, period in ((0, 1), (1, 10)):  # +-1 flipped every step / every 10 steps
            env.reset(seed=seed)
            peak, n = 0.0, 0
            while True:
                u = 1.0 if (n // period) % 2 else -1.0
                _, _, terminated, truncated, info = env.step(np.array([u], np.float32))
                n += 1
                assert not info["unstable"], f"k={k}, c={c}, period {period}: step {n}"
                peak = max(peak, float(np.abs(base.data.qvel[dofs]).max()))
                if terminated or truncated:
                    break
            assert n == base.episode_steps
            assert peak < MAX_PIN_SPEED_RAD_S, (k, c, period, peak)
    finally:
        env.close()


@pytest.mark.parametrize("k, c", CORNERS)
def test_extreme_draw_has_no_growing_fast_mode(k, c):
    """Near rest and in a fast extension, every fast mode decays at least as fast as the
    nominal twin's slowest-decaying one (0.986 per step). (Not at the reset state itself: the
    loop is closed exactly there, on the kink of the weld's impedance, where finite
    differences are meaningless.)"""
    env = _corner_env(k, c, duration_s=1.0)
    base = env.unwrapped
    try:
        env.reset(seed=0)
        env.step(np.zeros(1, np.float32))
        radii = [_fast_modes_radius(base.model, base.data)]
        for _ in range(10):
            env.step(np.array([-1.0], np.float32))
        radii.append(_fast_modes_radius(base.model, base.data))
    finally:
        env.close()
    assert max(radii) < 0.99, (k, c, radii)


def _weld_kb(env) -> tuple[float, float]:
    """The strap weld's reference stiffness and damping (MuJoCo's efc_KBIP) at the reset."""
    import mujoco

    from myoexo.model import STRAP_EQUALITY

    m, d = env.unwrapped.model, env.unwrapped.data
    mujoco.mj_forward(m, d)
    eq = m.equality(STRAP_EQUALITY).id
    row = next(
        i
        for i in range(d.nefc)
        if d.efc_type[i] == mujoco.mjtConstraint.mjCNSTR_EQUALITY and d.efc_id[i] == eq
    )
    return float(d.efc_KBIP[row, 0]), float(d.efc_KBIP[row, 1])


@pytest.mark.parametrize("k, c", [(2.0, 0.5), (2.0, 2.0), (0.5, 1.0), (1.6, 1.4)])
def test_weld_stiffness_and_damping_scale_by_the_draw(k, c):
    nominal = _corner_env(1.0, 1.0, duration_s=0.1)
    env = _corner_env(k, c, duration_s=0.1)
    try:
        nominal.reset(seed=0)
        env.reset(seed=0)
        (k0, b0), (k1, b1) = _weld_kb(nominal), _weld_kb(env)
    finally:
        nominal.close()
        env.close()
    assert k1 / k0 == pytest.approx(k, rel=1e-9)
    assert b1 / b0 == pytest.approx(c, rel=1e-9)


def test_weld_damping_past_its_explicit_limit_raises():
    with pytest.raises(ValueError, match="strap_damping_scale"):
        make_env(0, robustness=RobustnessParams(strap_damping_scale=(0.5, 2.5)))
