"""Learning speed: each learner on the real env with the same networks, batch and updates per
transition, against the arithmetic limit of one core.

    python benchmarks/bench_training.py            # SB3 SAC vs SBX (JAX) SAC/TQC/CrossQ
    python benchmarks/bench_training.py --quick    # SB3 SAC vs SBX SAC, within ~4 minutes
    python benchmarks/bench_training.py --learners sac sbx_sac:16 sbx_tqc

A learner is ``ALGORITHM[:K]``: an algorithm of the training config (``sac``, ``sbx_sac``,
``sbx_sac_overlap``, ``sbx_tqc``, ``sbx_crossq``) that trains every ``K`` vector steps with
``K x n_envs`` gradient updates, i.e. one update per transition for every ``K`` (default 1;
a larger ``K`` runs many compiled updates per call). ``sbx_sac:KxN`` trains ``N`` seeds
together, their updates in one compiled call (``jax.vmap`` over seeds,
``SeedBatchedSAC`` of ``seed_batched_sac.py`` beside this script); its rates are
*seed-updates* per second (every seed's updates counted), the unit that compares it with
one seed trained alone. Every learner uses the ``cpu`` preset's networks (64-64 GELU),
batch (256) and env (``MyoExoKneeRandom-v0``, 4 envs). ``sbx_sac_overlap`` collects with a
numpy copy of the actor while its update call runs (``myoexo/policies/overlapped_sac.py``);
every timing waits for the last update to finish. Measured in one process, one learner after
the other:

1. **env**: transitions/s of the vector env under random actions (once: the simulator's
   share);
2. **updates**: gradient updates/s of the learner alone on a filled replay buffer;
3. **learn**: ``model.learn`` after learning has started: transitions/s and updates/s of a
   real run.

It also prints the FLOPs of one update (matrix products of the actor and both critics,
forward and backward) against one core's measured float32 matrix-multiply throughput (numpy,
one thread): the share of the arithmetic limit each learner reaches. The last line is
``learner speed-up vs SB3 SAC: N.NNx``: the fastest learner's updates/s inside ``learn`` over
SB3 SAC's, both at one update per transition.
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
from typing import Any

import numpy as np

FULL_LEARNERS = (
    "sac",
    "sbx_sac",
    "sbx_sac:16",
    "sbx_sac_overlap:16",
    "sbx_sac:64",
    "sbx_sac:16x2",
    "sbx_sac:16x5",
    "sbx_tqc:16",
    "sbx_crossq:16",
)
QUICK_LEARNERS = ("sac", "sbx_sac:16", "sbx_sac_overlap:16", "sbx_sac:16x5")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--learners", nargs="+", default=None, help="ALGORITHM[:K] ...")
    parser.add_argument("--quick", action="store_true", help="two learners, short runs")
    parser.add_argument("--env-steps", type=int, default=None)
    parser.add_argument("--updates", type=int, default=None)
    parser.add_argument("--learn-steps", type=int, default=None)
    parser.add_argument("--seed", type=int, default=0)
    args = parser.parse_args()
    learners = args.learners or (QUICK_LEARNERS if args.quick else FULL_LEARNERS)
    env_steps = args.env_steps or (1_000 if args.quick else 4_000)
    updates = args.updates or (300 if args.quick else 1_000)
    learn_steps = args.learn_steps or (2_000 if args.quick else 8_000)
    os.environ.setdefault(
        "XLA_FLAGS", "--xla_cpu_multi_thread_eigen=false intra_op_parallelism_threads=1"
    )

    gflops = matmul_gflops()
    print(f"one core, float32 matrix products (numpy, 1 thread): {gflops:.0f} GFLOP/s")
    rows = []
    env_sps = None
    for learner in learners:
        row = measure(
            learner, env_steps, updates, learn_steps, args.seed, measure_env=env_sps is None
        )
        env_sps = env_sps or row["env_sps"]
        row["limit_share"] = row["learn_ups"] * row["flop_per_update"] / (gflops * 1e9)
        rows.append(row)
    print()
    print(f"env alone: {env_sps:.0f} transitions/s (4 envs, random actions)")
    print(
        f"{'learner':<16}{'upd/transition':>15}{'updates/s':>11}{'learn upd/s':>13}"
        f"{'learn env steps/s':>19}{'MFLOP/update':>14}{'limit share':>13}"
    )
    for r in rows:
        print(
            f"{r['learner']:<16}{r['upd_per_transition']:>15.2f}{r['ups']:>11.0f}"
            f"{r['learn_ups']:>13.0f}{r['learn_sps']:>19.0f}{r['flop_per_update'] / 1e6:>14.1f}"
            f"{100 * r['limit_share']:>12.1f}%"
        )
    base = next((r for r in rows if r["learner"] in ("sac", "sac:1")), None)
    if base is None:
        print("learner speed-up vs SB3 SAC: n/a (sac not measured)")
        return
    best = max(rows, key=lambda r: r["learn_ups"])
    print(f"fastest: {best['learner']}")
    print(f"learner speed-up vs SB3 SAC: {best['learn_ups'] / base['learn_ups']:.2f}x")


def wait_for_updates(model: Any) -> None:
    """Block until a JAX learner's dispatched updates are computed (SB3's are synchronous)."""
    if hasattr(model.policy, "actor_state"):
        import jax

        jax.block_until_ready((model.policy.actor_state.params, model.policy.qf_state.params))


def matmul_gflops(n: int = 512, repeat: int = 20) -> float:
    """float32 matrix-multiply throughput of one core (best of ``repeat``)."""
    from threadpoolctl import threadpool_limits

    rng = np.random.default_rng(0)
    a = rng.standard_normal((n, n), dtype=np.float32)
    b = rng.standard_normal((n, n), dtype=np.float32)
    best = float("inf")
    with threadpool_limits(1):
        a @ b
        for _ in range(repeat):
            t0 = time.perf_counter()
            a @ b
            best = min(best, time.perf_counter() - t0)
    return 2.0 * n**3 / best / 1e9


def update_flops(
    obs_dim: int, act_dim: int, hidden_pi: tuple, hidden_qf: tuple, batch: int
) -> float:
    """Matrix-product FLOPs of one SAC update: the next action (actor forward), both target
    critics (forward), both critics (forward and backward: x3), the actor through both
    critics (forward and backward of the actor and the critics: x3)."""

    def mlp(sizes: list[int]) -> float:
        return 2.0 * sum(a * b for a, b in itertools.pairwise(sizes))

    actor = mlp([obs_dim, *hidden_pi, 2 * act_dim])
    critic = mlp([obs_dim + act_dim, *hidden_qf, 1])
    return batch * (actor + 2 * critic + 2 * 3 * critic + 3 * actor + 2 * 3 * critic)


def measure(
    learner: str, env_steps: int, updates: int, learn_steps: int, seed: int, measure_env: bool
) -> dict:
    """The three measurements of one learner."""
    import torch

    from myoexo.training.callbacks import RewardTermsCallback

    algorithm, _, k = learner.partition(":")
    k, _, n = k.partition("x")
    k_steps = int(k or 1)
    if n:
        return measure_batched(learner, algorithm, k_steps, int(n), updates, learn_steps, seed)
    preset = learner_preset(algorithm, k_steps)
    torch.set_num_threads(preset.torch_threads)
    venv, model, fill_sps = filled_model(preset, seed, env_steps)
    env_sps = fill_sps if measure_env else None

    kw = preset.algorithm_kwargs
    chunk = max(1, kw["gradient_steps"])
    model.train(gradient_steps=chunk, batch_size=kw["batch_size"])  # compile / warm up
    calls = max(1, updates // chunk)
    t0 = time.perf_counter()
    for _ in range(calls):
        model.train(gradient_steps=chunk, batch_size=kw["batch_size"])
    wait_for_updates(model)
    ups = calls * chunk / (time.perf_counter() - t0)

    model.learn(preset.n_envs * kw["train_freq"], reset_num_timesteps=False)  # warm up learn
    before = model._n_updates
    t0 = time.perf_counter()
    model.learn(learn_steps, callback=RewardTermsCallback(), reset_num_timesteps=False)
    wait_for_updates(model)
    dt = time.perf_counter() - t0
    learn_sps = learn_steps / dt
    learn_ups = (model._n_updates - before) / dt
    obs_dim = int(venv.observation_space.shape[0])
    flop = update_flops(obs_dim, 1, preset.net_arch_pi, preset.net_arch_qf, kw["batch_size"])
    print(
        f"[{learner}] updates alone {ups:.0f}/s; learn {learn_sps:.0f} transitions/s, "
        f"{learn_ups:.0f} updates/s",
        flush=True,
    )
    venv.close()
    return row(learner, preset, env_sps, ups, learn_sps, learn_ups, flop)


def measure_batched(
    learner: str,
    algorithm: str,
    k_steps: int,
    n_seeds: int,
    updates: int,
    learn_steps: int,
    seed: int,
) -> dict:
    """The updates and learn measurements of ``n_seeds`` seeds trained together, their
    updates vmapped in one call (rates in seed-updates/s and seed-transitions/s)."""
    from seed_batched_sac import SeedBatchedSAC, learn_seed_batched  # beside this script

    from myoexo.training.callbacks import RewardTermsCallback

    if algorithm != "sbx_sac":
        raise SystemExit(f"{learner}: only sbx_sac batches seeds")
    preset = learner_preset(algorithm, k_steps)
    filled = [filled_model(preset, seed + i, 1_000) for i in range(n_seeds)]
    venvs = [venv for venv, _, _ in filled]
    models = [model for _, model, _ in filled]
    batch = SeedBatchedSAC(models)
    kw = preset.algorithm_kwargs
    chunk = kw["gradient_steps"]
    batch.train(chunk)  # compile / warm up
    calls = max(1, updates // chunk)
    t0 = time.perf_counter()
    for _ in range(calls):
        batch.train(chunk)
    ups = n_seeds * calls * chunk / (time.perf_counter() - t0)

    learn_seed_batched(batch, preset.n_envs * kw["train_freq"])  # warm up learn
    before = sum(m._n_updates for m in models)
    t0 = time.perf_counter()
    learn_seed_batched(batch, learn_steps, [RewardTermsCallback() for _ in models])
    dt = time.perf_counter() - t0
    learn_ups = (sum(m._n_updates for m in models) - before) / dt
    obs_dim = int(venvs[0].observation_space.shape[0])
    flop = update_flops(obs_dim, 1, preset.net_arch_pi, preset.net_arch_qf, kw["batch_size"])
    print(
        f"[{learner}] {n_seeds} seeds in one call: updates alone {ups:.0f} seed-updates/s; "
        f"learn {n_seeds * learn_steps / dt:.0f} seed-transitions/s, {learn_ups:.0f} "
        "seed-updates/s",
        flush=True,
    )
    for venv in venvs:
        venv.close()
    return row(learner, preset, None, ups, n_seeds * learn_steps / dt, learn_ups, flop)


def learner_preset(algorithm: str, k_steps: int) -> Any:
    """The ``cpu`` preset with *algorithm*, training every *k_steps* vector steps with one
    update per transition (CrossQ: without ``tau``, it has no target networks)."""
    from myoexo.policies.algorithms import get_algorithm
    from myoexo.training import get_preset

    n_envs = get_preset("cpu").n_envs
    kwargs: dict[str, Any] = {"train_freq": k_steps, "gradient_steps": k_steps * n_envs}
    if get_algorithm(algorithm).class_name == "CrossQ":
        kwargs["tau"] = None
    return get_preset("cpu", algorithm=algorithm, algorithm_kwargs=kwargs)


def filled_model(preset: Any, seed: int, env_steps: int) -> tuple[Any, Any, float]:
    """A model of *preset* on its vector env, its replay buffer filled with *env_steps*
    transitions of random actions: ``(venv, model, transitions/s of the filling)``."""
    from stable_baselines3.common.logger import configure

    from myoexo.training.train import build_model, make_vec_env

    venv = make_vec_env(preset, seed)
    model = build_model(preset.replace(seed=seed), venv)
    model.learning_starts = 0
    model.set_logger(configure(None, []))
    rng = np.random.default_rng(seed)
    obs = venv.reset()
    n_vec = max(1, env_steps // preset.n_envs)
    t0 = time.perf_counter()
    for _ in range(n_vec):
        action = rng.uniform(-1.0, 1.0, (preset.n_envs, 1)).astype(np.float32)
        new_obs, reward, done, infos = venv.step(action)
        model.replay_buffer.add(obs, new_obs, action, reward, done, infos)
        obs = new_obs
    return venv, model, n_vec * preset.n_envs / (time.perf_counter() - t0)


def row(
    learner: str,
    preset: Any,
    env_sps: float | None,
    ups: float,
    learn_sps: float,
    learn_ups: float,
    flop: float,
) -> dict:
    """One learner's line of the table."""
    return {
        "learner": learner,
        "upd_per_transition": preset.updates_per_transition(preset.algorithm_kwargs),
        "env_sps": env_sps,
        "ups": ups,
        "learn_sps": learn_sps,
        "learn_ups": learn_ups,
        "flop_per_update": flop,
    }


if __name__ == "__main__":
    main()
