"""``myoexo policy sweep FILE``: Ray Tune over training configurations, ranked on the paper's
acceptance criteria, resumable after the driver is killed.

    myoexo policy sweep sweeps/reward.yaml                       # a local cluster of every core
    myoexo policy sweep sweeps/reward.yaml --address auto        # the cluster of `ray start`

The sweep file (YAML, or TOML with the same keys)::

    name: reward-inter              # folder under --out (default: the file's name)
    preset: cpu                     # a preset name, or a list of them (searched)
    seeds: [0, 1]                   # one trial per seed, crossed with the rest
    set:                            # training-config fields (and the twin's options by
      total_timesteps: 500000       # their own names), the same in every trial
      eval_every_steps: 25000
      algorithm: sbx_sac
      algorithm_kwargs: {train_freq: 16, gradient_steps: 64}  # merged into the preset's
    search:                         # fields searched: a list is a grid; or choice /
      n_envs: [2, 4]                # uniform / loguniform / randint: [low, high]
      algorithm_kwargs:             # the algorithm's arguments, searched the same way
        learning_rate: {loguniform: [1.0e-4, 1.0e-3]}
        batch_size: [128, 256]
    reward_weights:                 # reward weights: a number (fixed), a list (grid) or a
      inter: [-0.5, -1.0]           # distribution, as in `search`
    num_samples: 1                  # draws of the distributions (each crossed with the grids)
    scheduler: asha                 # optional early stopping: asha or median
    grace_evals: 2                  # evaluations before a trial may be stopped
    reduction_factor: 2             # asha's halving rate
    metric: score                   # what the scheduler compares: score (max) or shortfall (min)
    cpus_per_trial: 1
    max_concurrent_trials: 0        # 0: as many as the CPUs allow

The keys of ``set`` and ``search`` are the fields of
:class:`~myoexo.training.config.TrainConfig` (the options of ``myoexo policy train``, without
the seed: ``seeds``) and the twin's options (``reflex``, ``episode_duration_s``,
``obs_preset``, ...); an algorithm argument under ``algorithm_kwargs``.

Each trial is a normal training run (:func:`~myoexo.training.train.train`) in
``<out>/<name>/runs/<trial id>/`` with its checkpoints, ``eval.csv`` and tensorboard logs.
While it trains, every new periodic evaluation of its ``eval.csv`` (the deterministic policy
against the PID on fixed subjects, :class:`~myoexo.training.callbacks.PaperMetricsEvalCallback`)
is reported to Tune with the acceptance criteria of :mod:`myoexo.evaluation.criteria`: the
score, the shortfall, whether it passes, and per level the final error and the peak / RMS
torque reductions against the PID. When the sweep ends, ``results.parquet`` and
``results.md`` rank every trial on its best evaluation: smallest shortfall first (0 = passes
every criterion), then largest mean peak-torque reduction, as ``myoexo policy select`` ranks
checkpoints; a policy snapshot exists for every evaluated step.

Resuming: the Tune experiment lives in ``<out>/<name>/tune``. Running the same command again
after the driver was killed restores it (``Tuner.restore``): finished trials are kept,
interrupted ones start again and continue their own run folder from its newest resumable
checkpoint (:func:`~myoexo.training.train.resume`), reporting only the evaluations Tune has
not seen. Ray and PyYAML come with the ``ray`` extra; nothing here imports them until a
sweep runs.

The modules, one job each: :mod:`~myoexo.studies.sweep.spec` (the sweep file, checked, and
the training config of each trial), :mod:`~myoexo.studies.sweep.tune` (the Ray Tune glue: search
space, trainable, :func:`~myoexo.studies.sweep.tune.run_sweep`),
:mod:`~myoexo.studies.sweep.table` (the evaluations scored on the acceptance criteria and the
ranked table) and :mod:`~myoexo.studies.sweep.cli` (the command). Their public names are
also found here (each submodule is imported on first use).
"""

from __future__ import annotations

from myoexo.runtime.lazy import lazy_exports

#: Public name -> the submodule that defines it.
_HOMES: dict[str, str] = {
    "DEFAULT_OUT": "spec",
    "DISTRIBUTIONS": "spec",
    "METRICS": "spec",
    "RESULTS_STEM": "spec",
    "RUNS_DIR": "spec",
    "SCHEDULERS": "spec",
    "SETTINGS_FILE": "spec",
    "TUNE_DIR": "spec",
    "SweepSpec": "spec",
    "CONFIG_FIELDS": "spec",
    "build_config": "spec",
    "distribution": "spec",
    "read_sweep_file": "spec",
    "trial_config": "spec",
    "REPORT_POLL_S": "tune",
    "STOP_TIMEOUT_S": "tune",
    "SweepResult": "tune",
    "param_space": "tune",
    "run_sweep": "tune",
    "run_trial": "tune",
    "evaluation_metrics": "table",
    "rank_key": "table",
    "read_eval_rows": "table",
    "results_table": "table",
    "write_results": "table",
    "SHOWN_TRIALS": "cli",
    "add_arguments": "cli",
    "run": "cli",
}

__all__ = sorted(_HOMES)


__getattr__, __dir__ = lazy_exports(__name__, _HOMES)
