"""The Ray Tune glue of a sweep: the search space (:func:`param_space`), the trainable that
trains one configuration and reports each of its evaluations (:func:`run_trial`), and
:func:`run_sweep`, which runs the Tuner (or restores an interrupted one) and writes the
ranked table. Ray is imported when a sweep runs, not on import."""

from __future__ import annotations

import atexit
import json
import shutil
import tempfile
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from myoexo.runtime.files import write_json_atomic
from myoexo.studies.sweep.spec import (
    DEFAULT_OUT,
    METRICS,
    RUNS_DIR,
    SETTINGS_FILE,
    TUNE_DIR,
    SweepSpec,
    build_config,
    distribution,
    trial_config,
)
from myoexo.studies.sweep.table import evaluation_metrics, results_table, write_results
from myoexo.training import checkpoints as ck
from myoexo.training.config import TrainConfig

#: Seconds between two looks of a trial at its run's ``eval.csv``.
REPORT_POLL_S = 1.0

#: Seconds a stopped trial waits for its training to write its last checkpoint.
STOP_TIMEOUT_S = 60.0


# ----------------------------------------------------------------------------- trials
def param_space(spec: SweepSpec) -> dict[str, Any]:
    """Tune's search space of a sweep: ``preset``, ``seed``, ``set``, ``search`` (its
    ``algorithm_kwargs`` a mapping of searched arguments) and ``reward_weights`` (a trial's
    config has the same keys, resolved)."""
    from ray import tune

    def grid(values: Sequence[Any]) -> Any:
        return tune.grid_search(list(values)) if len(values) > 1 else values[0]

    def domain(value: Any) -> Any:
        dist = distribution(value)
        if dist is None:
            return tune.grid_search(list(value)) if isinstance(value, list) else value
        name, args = dist
        if name == "choice":
            return tune.choice(args)
        return getattr(tune, name)(*args)

    return {
        "preset": grid(spec.presets),
        "seed": grid(spec.seeds),
        "set": dict(spec.fixed),
        "search": {
            k: {a: domain(x) for a, x in v.items()} if k == "algorithm_kwargs" else domain(v)
            for k, v in spec.search.items()
        },
        "reward_weights": {k: domain(v) for k, v in spec.reward_weights.items()},
    }


def _stop_callback(stop: threading.Event) -> Any:
    """An SB3 callback that ends the training session once ``stop`` is set."""
    from stable_baselines3.common.callbacks import BaseCallback

    class StopOnEvent(BaseCallback):
        def _on_step(self) -> bool:
            return not stop.is_set()

    return StopOnEvent()


class _Training(threading.Thread):
    """A trial's training run (new, resumed or restarted), in the background while the
    trial's own thread reports its evaluations; setting :attr:`stop` ends it at the next
    step, with a resumable checkpoint."""

    def __init__(self, config: TrainConfig, run_dir: Path, verbose: int) -> None:
        super().__init__(name="myoexo-training", daemon=True)
        self.config, self.run_dir, self.verbose = config, run_dir, verbose
        self.stop = threading.Event()
        self.error: BaseException | None = None

    def run(self) -> None:
        from myoexo.training.train import resume, train

        callbacks = [_stop_callback(self.stop)]
        try:
            if (self.run_dir / ck.CONFIG_FILE).is_file():
                if ck.latest_checkpoint(self.run_dir, with_replay=True) is not None:
                    resume(self.run_dir, verbose=self.verbose, callbacks=callbacks)
                    return
                shutil.rmtree(self.run_dir)  # stopped before its first checkpoint: anew
            train(self.config, self.run_dir, verbose=self.verbose, callbacks=callbacks)
        except BaseException as exc:
            self.error = exc

    def end(self) -> None:
        """Stop the training and wait for its last checkpoint (a trial stopped by the
        scheduler, or its process exiting)."""
        if self.is_alive():
            self.stop.set()
            self.join(STOP_TIMEOUT_S)


def run_trial(config: dict[str, Any], runs_dir: str, verbose: int = 0) -> None:
    """Tune's function trainable: train one configuration in ``runs_dir/<trial id>`` and
    report each new evaluation of its ``eval.csv`` (:func:`evaluation_metrics`)."""
    from ray import tune

    train_config = trial_config(config)
    run_dir = Path(runs_dir) / tune.get_context().get_trial_id()
    reported = -1
    restored = tune.get_checkpoint()
    if restored is not None:
        with restored.as_directory() as folder:
            reported = int(json.loads((Path(folder) / "reported.json").read_text())["step"])
    training = _Training(train_config, run_dir, verbose)
    # a trial stopped by the scheduler ends with its process: stop the training cleanly
    # first (a daemon thread still printing at interpreter exit aborts it)
    atexit.register(training.end)
    training.start()
    try:
        while True:
            running = training.is_alive()  # before reading: the last rows are then seen
            for metrics in evaluation_metrics(run_dir, train_config.eval_levels, after=reported):
                _report(metrics)
                reported = int(metrics["step"])
            if not running:
                break
            training.join(REPORT_POLL_S)
    finally:
        training.end()
        atexit.unregister(training.end)
    if training.error is not None:
        raise training.error


def _report(metrics: dict[str, Any]) -> None:
    """``tune.report`` with a checkpoint holding the step, so that a restored trial reports
    only newer evaluations."""
    from ray import tune

    with tempfile.TemporaryDirectory() as tmp:
        (Path(tmp) / "reported.json").write_text(json.dumps({"step": metrics["step"]}))
        tune.report(metrics, checkpoint=tune.Checkpoint.from_directory(tmp))


# ----------------------------------------------------------------------------- running
def _trial_dirname(trial: Any) -> str:
    """Tune's folder (and name) of a trial: its id, which also names its run folder."""
    return str(trial.trial_id)


def _scheduler(spec: SweepSpec) -> Any:
    if spec.scheduler is None:
        return None
    from ray.tune.schedulers import ASHAScheduler, MedianStoppingRule

    if spec.scheduler == "asha":
        configs = [build_config(p, spec.fixed, {}, {}) for p in spec.presets]
        max_evals = max(c.total_timesteps // c.eval_every_steps for c in configs)
        return ASHAScheduler(
            time_attr="training_iteration",
            max_t=max(max_evals, spec.grace_evals),
            grace_period=spec.grace_evals,
            reduction_factor=spec.reduction_factor,
        )
    return MedianStoppingRule(time_attr="training_iteration", grace_period=spec.grace_evals)


def _check_folder(sweep_dir: Path, spec: SweepSpec) -> None:
    """Record the sweep in ``sweep.json``, or refuse a folder that holds another sweep."""
    path = sweep_dir / SETTINGS_FILE
    if path.is_file():
        previous = json.loads(path.read_text())
        if previous != spec.to_dict():
            raise ValueError(
                f"{sweep_dir} holds a sweep with other settings ({path.name}); resume it with "
                "its own file, or give this sweep another name or --out"
            )
    else:
        write_json_atomic(path, spec.to_dict(), indent=2)


@dataclass
class SweepResult:
    """Outcome of :func:`run_sweep`.

    Attributes:
        sweep_dir: The sweep folder.
        table: The ranked table (also in ``results.parquet`` / ``results.md``).
        errors: Trial id -> error text, for trials that failed.
        restored: Whether an interrupted sweep was continued.
    """

    sweep_dir: Path
    table: Any
    errors: dict[str, str]
    restored: bool


def run_sweep(
    spec: SweepSpec,
    out: str | Path = DEFAULT_OUT,
    address: str | None = None,
    num_cpus: int | None = None,
    verbose: int = 1,
) -> SweepResult:
    """Run (or continue) a sweep and write its ranked table.

    Args:
        spec: The sweep (:func:`read_sweep_file`).
        out: Parent folder; the sweep lives in ``out/spec.name``.
        address: Ray cluster to join (:func:`myoexo.runtime.ray_cluster.resolve_address`).
        num_cpus: CPUs of a local cluster (default: every core).
        verbose: 0 quiet, 1 Tune's status and each trial's evaluations, 2 more.
    """
    from myoexo.runtime.ray_cluster import ray_session, require_ray

    require_ray("myoexo policy sweep")
    sweep_dir = Path(out).resolve() / spec.name
    sweep_dir.mkdir(parents=True, exist_ok=True)
    _check_folder(sweep_dir, spec)
    runs_dir = sweep_dir / RUNS_DIR
    runs_dir.mkdir(exist_ok=True)
    with ray_session(num_cpus, address, "myoexo policy sweep"):
        from ray import tune

        trainable = tune.with_resources(
            tune.with_parameters(run_trial, runs_dir=str(runs_dir), verbose=verbose),
            {"cpu": spec.cpus_per_trial},
        )
        experiment = sweep_dir / TUNE_DIR
        restored = tune.Tuner.can_restore(str(experiment))
        if restored:
            tuner = tune.Tuner.restore(
                str(experiment), trainable, resume_unfinished=True, resume_errored=True
            )
        else:
            tuner = tune.Tuner(
                trainable,
                param_space=param_space(spec),
                tune_config=tune.TuneConfig(
                    metric=spec.metric,
                    mode=METRICS[spec.metric],
                    scheduler=_scheduler(spec),
                    num_samples=spec.num_samples,
                    max_concurrent_trials=spec.max_concurrent_trials or None,
                    trial_name_creator=_trial_dirname,
                    trial_dirname_creator=_trial_dirname,
                ),
                run_config=tune.RunConfig(
                    name=TUNE_DIR,
                    storage_path=str(sweep_dir),
                    verbose=min(verbose, 1),
                ),
            )
        grid = tuner.fit()
        results = [grid[i] for i in range(len(grid))]
        trials: list[dict[str, Any]] = [
            {
                "trial_id": Path(r.path).name,
                "config": r.config,
                "error": None if r.error is None else f"{type(r.error).__name__}: {r.error}",
            }
            for r in results
        ]
    table = results_table(spec, sweep_dir, trials)
    write_results(sweep_dir, table, spec)
    errors = {str(t["trial_id"]): str(t["error"]) for t in trials if t["error"]}
    return SweepResult(sweep_dir=sweep_dir, table=table, errors=errors, restored=restored)
