"""Training speed of a preset: env steps/s, gradient updates/s, and both inside ``learn``.

    python benchmarks/bench_training.py                  # the cpu preset on MyoExoKneeRandom-v0
    python benchmarks/bench_training.py --preset paper --learn-steps 2000
    python benchmarks/bench_training.py --algorithms sac tqc crossq   # the same, per algorithm

Measured in one process, one after the other:

1. **env**: transitions/s of the preset's vector env (``n_envs`` copies, VecNormalize) under
   uniformly random actions: the simulator's share.
2. **updates**: SAC gradient updates/s at the preset's batch size, on a replay buffer filled
   by (1): the learner's share.
3. **learn**: ``model.learn`` for ``--learn-steps`` transitions after learning has started,
   with the run's callbacks minus evaluation/checkpoints: transitions/s and updates/s of a
   real run, and the projected wall time of the preset's full step budget.
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--preset", default="cpu")
    parser.add_argument("--env-id", default=None, help="override the preset's env id")
    parser.add_argument("--env-steps", type=int, default=4_000)
    parser.add_argument("--updates", type=int, default=1_000)
    parser.add_argument("--learn-steps", type=int, default=8_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--algorithms",
        nargs="+",
        default=["sac"],
        help="preset algorithms to measure one after the other (sac, tqc, crossq)",
    )
    args = parser.parse_args()
    for algorithm in args.algorithms:
        measure(args, algorithm)


def measure(args: argparse.Namespace, algorithm: str) -> None:
    """Print the three measurements for one algorithm."""
    import torch

    from myoexo.training import get_preset
    from myoexo.training.callbacks import RewardTermsCallback
    from myoexo.training.train import build_sac, make_vec_env

    overrides: dict = {"env_id": args.env_id} if args.env_id else {}
    overrides["algorithm"] = algorithm
    preset = get_preset(args.preset, **overrides)
    torch.set_num_threads(preset.torch_threads)
    print(
        f"[{algorithm}] preset {preset.name}: {preset.env_id}, "
        f"n_envs {preset.n_envs} ({preset.vec_env}), "
        f"batch {preset.batch_size}, {preset.updates_per_transition:.3g} updates/transition, "
        f"torch threads {torch.get_num_threads()}"
    )

    venv = make_vec_env(preset, args.seed)
    model = build_sac(preset, venv, args.seed)
    model.learning_starts = 0

    # 1. env alone (random actions), filling the replay buffer on the way
    rng = np.random.default_rng(args.seed)
    obs = venv.reset()
    n_vec = max(1, args.env_steps // preset.n_envs)
    t0 = time.perf_counter()
    for _ in range(n_vec):
        action = rng.uniform(-1.0, 1.0, (preset.n_envs, 1)).astype(np.float32)
        new_obs, reward, done, infos = venv.step(action)
        model.replay_buffer.add(obs, new_obs, action, reward, done, infos)
        obs = new_obs
    env_sps = n_vec * preset.n_envs / (time.perf_counter() - t0)
    print(f"env:     {env_sps:8.0f} transitions/s ({n_vec * preset.n_envs} transitions)")

    # 2. learner alone
    from stable_baselines3.common.logger import configure

    model.set_logger(configure(None, []))
    model.train(gradient_steps=10, batch_size=preset.batch_size)  # warm-up
    t0 = time.perf_counter()
    model.train(gradient_steps=args.updates, batch_size=preset.batch_size)
    ups = args.updates / (time.perf_counter() - t0)
    print(f"updates: {ups:8.1f} gradient updates/s at batch {preset.batch_size}")

    # 3. both, inside learn()
    before = model._n_updates
    t0 = time.perf_counter()
    model.learn(args.learn_steps, callback=RewardTermsCallback(), reset_num_timesteps=False)
    dt = time.perf_counter() - t0
    learn_sps = args.learn_steps / dt
    learn_ups = (model._n_updates - before) / dt
    hours = preset.total_timesteps / learn_sps / 3600
    print(f"learn:   {learn_sps:8.0f} transitions/s, {learn_ups:.1f} updates/s")
    print(
        f"ratios:  env/learn {env_sps / learn_sps:.1f}x; the learner takes "
        f"{100 * (1 - learn_sps / env_sps):.0f} % of a training step's time"
    )
    print(f"projected: {preset.total_timesteps:,} transitions in {hours:.1f} h at this rate")
    venv.close()


if __name__ == "__main__":
    main()
