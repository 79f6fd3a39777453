"""The achievable bound: an oracle that sees the twin's true state and plans on a copy of it.

:class:`OracleMPC` is receding-horizon *predictive sampling* (the planner of MuJoCo MPC,
Howell et al. 2022): every ``replan`` control steps it copies the env's physics state and
the reflex's memory (its delay line and, for ``reflex="persistent"``, the after-discharge)
into a private ``MjData`` (the same ``MjModel``, so a perturbed twin is planned on as it
is), rolls out ``samples`` torque plans over ``horizon_s`` (the best plan so far, shifted,
plus Gaussian perturbations of it and the two saturated constants), and keeps the cheapest.
A plan is piecewise linear between ``knots`` values; the cost per control step is
``(e / 1 rad)^2 + torque_weight * u^2 + interaction_weight * (tau / 100 Nm)^2`` with ``e``
the human knee error and ``tau`` the interaction torque (the magnitude of the strap's torque
on the knee, ``interaction_torque_nm`` as the env reports it); the last step of the horizon
counts ``terminal_weight`` times and adds ``velocity_weight * (knee velocity)^2`` (end at
rest). With ``peak_weight``, a plan whose
interaction torque rises above the episode's peak so far pays ``peak_weight * (new peak^2 -
old peak^2) / (100 Nm)^2`` once: the planner trades the peak and the RMS of the interaction
torque against the error term, whose integral is what settling costs. With ``ramp_s``, the
error is taken against a reference that moves from the start angle to the target in
``ramp_s`` seconds (the oracle's counterpart of a ramped-setpoint PID: a slower start stretches
the muscles more slowly, so the reflex pushes back less). Sweeping ``ramp_s`` and
``peak_weight`` (``myoexo frontier --oracle``) traces the twin's frontier with a planner that
knows everything.

It is the one controller with privileged access: it ignores its sensor record
(:class:`~myoexo.envs.sensors.Measurements`, it declares no sensor) and reads the true state
from the env it was built on (its MuJoCo state, the reflex's memory, the true interaction
torque :attr:`MyoExoKneeEnv.interaction_torque_nm
<myoexo.envs.knee_exo.MyoExoKneeEnv.interaction_torque_nm>`). It knows the subject (its reflex
parameters are in the copied stage) and the exact dynamics, which no real controller does;
what it reaches is what the 100 Nm motor can reach on this twin. The paper never computed
such a bound. It is slow (a few hundred rollouts per second of simulated time: 15-65 s of a core per
8-s episode, quiet to loaded machine, a third of that in the frontier's cheap setting), so it is
evaluated on a few subjects per level (``myoexo evaluate
--controllers oracle --subjects 10``).

    from myoexo.control.oracle import OracleMPC
    env = make_env(3)
    ep = rollout(env, OracleMPC.from_env(env), seed=0)
"""

from __future__ import annotations

import math
import typing
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np

from myoexo.envs.sensors import Measurements
from myoexo.envs.twin import Twin
from myoexo.runtime.fields import convert, parse_assignments
from myoexo.spasticity.stage import SpasticityStage

#: Scale of the interaction torque in the cost (Nm): the motor's peak torque.
_TORQUE_SCALE_NM = 100.0


@dataclass(frozen=True)
class OracleConfig:
    """Predictive-sampling settings.

    Attributes:
        samples: Rollouts per plan (the previous best and the two saturated constants among
            them).
        horizon_s: Planning horizon (s).
        replan: Control steps between two plans (the plan is followed in between).
        knots: Values of the piecewise-linear torque plan over the horizon.
        noise: Standard deviation of the perturbation of the knots (normalized command) far
            from the target; it shrinks with the knee error ``|e|`` as ``noise *
            clip(|e| / noise_error_rad, 0.1, 1)`` (fine search where holding needs precision).
        noise_error_rad: Error below which the perturbation shrinks.
        iters: Sampling rounds per plan, each around the best of the previous round.
        torque_weight: Weight of ``u^2`` against ``(e / rad)^2`` in the cost.
        terminal_weight: Weight of the horizon's last step.
        velocity_weight: Weight of ``(knee velocity / 1 rad/s)^2`` in the last step's cost
            (the plan must end at rest, not swing through the target).
        interaction_weight: Weight of ``(interaction torque / 100 Nm)^2`` per control step
            (the RMS of the interaction torque; 0: the final-error bound).
        peak_weight: Weight of the rise of the squared episode peak of the interaction torque
            (in (100 Nm)^2) a plan causes (0: the peak is free).
        ramp_s: Duration (s) of the reference's ramp from the start angle to the target, in
            episode time (0: the target from the start).
    """

    samples: int = 12
    horizon_s: float = 0.3
    replan: int = 2
    knots: int = 4
    noise: float = 0.3
    noise_error_rad: float = 0.1
    iters: int = 1
    torque_weight: float = 1e-3
    terminal_weight: float = 10.0
    velocity_weight: float = 0.01
    interaction_weight: float = 0.0
    peak_weight: float = 0.0
    ramp_s: float = 0.0

    def __post_init__(self) -> None:
        for name in ("samples", "replan", "knots", "iters"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, int) or v < 1:
                raise ValueError(f"OracleConfig.{name} = {v!r} must be a positive integer")
        if self.samples < 3:
            raise ValueError(f"OracleConfig.samples = {self.samples} must be >= 3")
        if self.knots < 2:
            raise ValueError(f"OracleConfig.knots = {self.knots} must be >= 2")
        for name, low, high in (
            ("horizon_s", 1e-3, 10.0),
            ("noise", 0.0, 10.0),
            ("noise_error_rad", 1e-6, 10.0),
            ("torque_weight", 0.0, 1e6),
            ("terminal_weight", 0.0, 1e6),
            ("velocity_weight", 0.0, 1e6),
            ("interaction_weight", 0.0, 1e6),
            ("peak_weight", 0.0, 1e6),
            ("ramp_s", 0.0, 60.0),
        ):
            v = float(getattr(self, name))
            if not (math.isfinite(v) and low <= v <= high):
                raise ValueError(f"OracleConfig.{name} = {v!r} is outside [{low}, {high}]")


def parse_oracle_options(text: str) -> dict[str, Any]:
    """``"samples=16,horizon_s=0.4"`` -> typed :class:`OracleConfig` keyword arguments
    (validated)."""
    types = typing.get_type_hints(OracleConfig)
    options: dict[str, Any] = {}
    for key, value in parse_assignments(text, "oracle option").items():
        if key not in types:
            raise ValueError(f"unknown oracle option {key!r}; accepted: {sorted(types)}")
        options[key] = convert(value, types[key], f"oracle option {key}")
    OracleConfig(**options)
    return options


class OracleMPC:
    """Sampling-based MPC on a copy of the twin (see the module docstring).

    Args:
        env: The MyoExoKnee env it controls (wrappers allowed); it reads the true state
            from ``env.unwrapped`` (privileged: ``data``, the reflex stage, the interaction
            torque) at every step.
        config: Planner settings.
        seed: Seed of the sampling (``reset(seed)`` reseeds it).
    """

    name = "oracle"
    #: No sensor: its privileged access to the env replaces them.
    sensors: frozenset[str] = frozenset()

    def __init__(self, env: Any, config: OracleConfig | None = None, seed: int = 0) -> None:
        self.env = env.unwrapped
        self.config = config or OracleConfig()
        e = self.env
        # the planner's own twin, on its own data: a copy of the env's state, stepped with a
        # planning copy of its reflex stage (set at each plan)
        self._twin = Twin(e.model, e.spasticity, e.dt)
        self._torque_aware = self.config.interaction_weight > 0 or self.config.peak_weight > 0
        self._target_rad = math.radians(e.target_angle_deg)
        self._steps = max(2, round(self.config.horizon_s / e.dt))
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        self._state_spec = spec
        self._state = np.zeros(mujoco.mj_stateSize(e.model, spec))
        self._drive_state = 0
        # knot values -> per-step commands (linear interpolation matrix, steps x knots)
        t = np.linspace(0.0, self.config.knots - 1, self._steps)
        lo = np.minimum(np.floor(t).astype(int), self.config.knots - 2)
        w = t - lo
        basis = np.zeros((self._steps, self.config.knots))
        basis[np.arange(self._steps), lo] = 1.0 - w
        basis[np.arange(self._steps), lo + 1] = w
        self._basis = basis
        self._weights = np.ones(self._steps)
        self._weights[-1] = self.config.terminal_weight
        self.rng = np.random.default_rng(seed)
        self.reset(seed)

    @classmethod
    def from_env(cls, env: Any, seed: int = 0, **options: Any) -> OracleMPC:
        """An oracle for ``env`` with :class:`OracleConfig` fields as keyword arguments."""
        return cls(env, OracleConfig(**options), seed)

    def reset(self, seed: int | None = None) -> None:
        """New episode: forget the plan; reseed the sampling."""
        if seed is not None:
            self.rng = np.random.default_rng(int(seed))
        self._knots = np.full(self.config.knots, -1.0)  # start: full extension torque
        self._plan = self._basis @ self._knots
        self._step_in_plan = 0
        self._peak_nm = 0.0  # the episode's peak interaction torque so far
        self._start_rad: float | None = None  # knee angle at the first plan (ramp_s > 0)
        self.plans = 0

    # ------------------------------------------------------------------ planning
    def _rollout_cost(self, plan: np.ndarray, stage: SpasticityStage, delay: tuple) -> float:
        twin = self._twin
        d = twin.data
        mujoco.mj_setState(twin.model, d, self._state, self._state_spec)
        twin.set_drive_state(self._drive_state)
        twin.stage = stage
        stage.set_history_state(delay)
        cfg = self.config
        cost = 0.0
        tw, iw = cfg.torque_weight, cfg.interaction_weight
        peak = self._peak_nm
        ramping = cfg.ramp_s > 0 and d.time < cfg.ramp_s  # else the target is the reference
        target = self._target_rad
        for k in range(self._steps):
            u = float(plan[k])
            twin.step(u)
            reference = self._reference_rad(d.time) if ramping else target
            e = twin.knee_angle_rad - reference
            step_cost = e * e + tw * u * u
            if self._torque_aware:
                tau = twin.interaction_torque_nm  # as the env's interaction_torque_nm
                step_cost += iw * (tau / _TORQUE_SCALE_NM) ** 2
                peak = max(peak, tau)
            cost += self._weights[k] * step_cost
        v = twin.knee_velocity_rad_s
        rise = (peak**2 - self._peak_nm**2) / _TORQUE_SCALE_NM**2
        return cost + cfg.terminal_weight * cfg.velocity_weight * v * v + cfg.peak_weight * rise

    def _reference_rad(self, time_s: float) -> float:
        """The angle the error is taken against at episode time *time_s* (rad)."""
        ramp = self.config.ramp_s
        if ramp <= 0 or self._start_rad is None or time_s >= ramp:
            return self._target_rad
        return self._start_rad + (self._target_rad - self._start_rad) * time_s / ramp

    def _plan_now(self) -> None:
        e, cfg = self.env, self.config
        mujoco.mj_getState(e.model, e.data, self._state, self._state_spec)
        self._drive_state = e.twin.drive_state()
        if self._start_rad is None:
            self._start_rad = e.twin.knee_angle_rad
        stage = e.spasticity.planning_copy(e.model, e.dt)
        delay = e.spasticity.history_state()  # delay line + after-discharge
        # the best plan so far, shifted by the steps it has run
        shift = self._step_in_plan / max(self._steps - 1, 1) * (cfg.knots - 1)
        grid = np.arange(cfg.knots) + shift
        best = np.interp(grid, np.arange(cfg.knots), self._knots)
        best_cost = self._rollout_cost(self._basis @ best, stage, delay)
        candidates = [np.full(cfg.knots, -1.0), np.full(cfg.knots, 1.0)]
        error_rad = abs(e.twin.knee_angle_rad - self._target_rad)
        sigma = cfg.noise * min(1.0, max(0.1, error_rad / cfg.noise_error_rad))
        for _ in range(cfg.iters):
            n_random = cfg.samples - 1 - len(candidates)
            noise = self.rng.standard_normal((n_random, cfg.knots)) * sigma
            candidates.extend(np.clip(best + noise, -1.0, 1.0))
            for knots in candidates:
                c = self._rollout_cost(self._basis @ knots, stage, delay)
                if c < best_cost:
                    best, best_cost = knots, c
            candidates = []
        self._knots = best
        self._plan = self._basis @ best
        self._step_in_plan = 0
        self.plans += 1

    def act(self, obs: np.ndarray, measurements: Measurements | None = None) -> np.ndarray:
        """The next command of the current plan (a new plan every ``replan`` steps), from the
        env's true state (the record is not read)."""
        del obs, measurements
        if self._torque_aware:  # the env's true interaction torque of the last step
            self._peak_nm = max(self._peak_nm, self.env.interaction_torque_nm)
        if self._step_in_plan % self.config.replan == 0 or self._step_in_plan >= self._steps:
            self._plan_now()
        u = float(self._plan[min(self._step_in_plan, self._steps - 1)])
        self._step_in_plan += 1
        return np.array([u], dtype=np.float32)
