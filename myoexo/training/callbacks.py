"""stable-baselines3 callbacks of a myoexo training run.

* :class:`RewardTermsCallback`: per-episode means of the reward terms (``info["rwd_dict"]``)
  and the paper's episode quantities per level, to the SB3 logger (tensorboard, CSV).
* :class:`SettlingRewardCallback`: a hindsight reward for settling sooner: once an episode
  ends, each of its stored transitions before its settling time is charged a penalty (and,
  optionally, those from it on get their torque terms back).
* :class:`PaperMetricsEvalCallback`: every ``eval_every_steps``, the deterministic policy on
  a few fixed subjects per level, next to the PID on the same subjects: final error, peak
  and RMS interaction torque (docs/reference.md section 5), and the score that ranks
  checkpoints (:func:`myoexo.evaluation.criteria.ranking_score`).
* :class:`PeriodicCheckpointCallback`: model + replay buffer + normalization statistics +
  step counter every ``every_s`` seconds or ``every_steps`` transitions, whichever comes
  first, a first one soon after learning starts, and at the end of training.
* :class:`StopOnSignalCallback`: ends ``learn`` at the next step once SIGTERM / SIGINT was
  received (:class:`myoexo.runtime.lifecycle.StopSignals`); the checkpoint callback then writes
  the final checkpoint.
"""

from __future__ import annotations

import csv
import json
import math
import time
import warnings
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from myoexo.control.residual import ResidualConfig
from myoexo.envs.options import TwinOptions
from myoexo.envs.reward import torque_cost
from myoexo.evaluation import criteria
from myoexo.evaluation.config import SELECTION_ROOT_SEED, check_fit_root
from myoexo.evaluation.criteria import CRITERIA_METRICS
from myoexo.evaluation.metrics import (
    FINAL_WINDOW_S,
    SETTLING_THRESHOLD,
    final_value,
    settling_time,
)
from myoexo.runtime.files import write_json_atomic
from myoexo.runtime.lifecycle import StopSignals
from myoexo.spasticity.levels import VALID_LEVELS
from myoexo.training import checkpoints as ck

#: Reward-dict entries that are not reward terms.
_NOT_TERMS = frozenset({"done", "solved"})


class RewardTermsCallback(BaseCallback):
    """Log each reward term's mean per step over every finished episode.

    Tensorboard keys: ``reward_terms/<term>`` (raw term; ``dense`` is the weighted sum the
    agent maximizes), ``episode/L<level>/final_error_deg``,
    ``episode/L<level>/peak_interaction_torque_nm`` and ``episode/L<level>/return``. Envs
    without ``rwd_dict`` (a stand-in env) log nothing.
    """

    def __init__(self, verbose: int = 0) -> None:
        super().__init__(verbose)
        self._sums: list[dict[str, float]] = []
        self._count: list[int] = []
        self._peak: list[float] = []
        self._return: list[float] = []

    def _on_training_start(self) -> None:
        n = self.training_env.num_envs
        self._sums = [defaultdict(float) for _ in range(n)]
        self._count = [0] * n
        self._peak = [0.0] * n
        self._return = [0.0] * n

    def _on_step(self) -> bool:
        infos = self.locals.get("infos", ())
        dones = self.locals.get("dones", ())
        rewards = self.locals.get("rewards", ())
        for i, info in enumerate(infos):
            rwd = info.get("rwd_dict")
            if rwd is None:
                continue
            sums = self._sums[i]
            for key, value in rwd.items():
                if key not in _NOT_TERMS:
                    sums[key] += float(np.asarray(value).reshape(-1)[0])
            self._count[i] += 1
            self._return[i] += float(rewards[i])
            self._peak[i] = max(self._peak[i], float(info.get("interaction_torque_nm", 0.0)))
            if dones[i]:
                self._log_episode(i, info)
        return True

    def _log_episode(self, i: int, info: dict[str, Any]) -> None:
        n = max(self._count[i], 1)
        for key, total in self._sums[i].items():
            self.logger.record_mean(f"reward_terms/{key}", total / n)
        level = info.get("level")
        if level is not None:
            tag = f"episode/L{int(level)}"
            self.logger.record_mean(
                f"{tag}/final_error_deg", float(info.get("error_deg", math.nan))
            )
            self.logger.record_mean(f"{tag}/peak_interaction_torque_nm", self._peak[i])
            self.logger.record_mean(f"{tag}/return", self._return[i])
            if info.get("unstable"):
                self.logger.record_mean("episode/unstable", 1.0)
        self._sums[i] = defaultdict(float)
        self._count[i] = 0
        self._peak[i] = 0.0
        self._return[i] = 0.0


class SettlingRewardCallback(BaseCallback):
    """A hindsight reward for settling sooner, for an off-policy learner.

    Settling time is the paper's (``myoexo.evaluation.metrics.settling_time``): the knee
    stays within 2 % of the step around the episode's final angle (its mean over the last
    0.1 s) from then on, the step measured from the first control step; an episode that
    never settles counts as settled at its end. No env can reward it at the step it
    happens, since it depends on how the episode ends; so once an episode of an env has
    ended, this callback subtracts ``penalty`` from the reward stored in the replay buffer
    for each of that episode's control steps before its settling time (the episode's sum:
    ``-penalty x settling steps``), before the next update. The knee angle is read from
    ``info["error_deg"]`` (knee minus target), the time from ``info["time_s"]``. A run
    resumed from a checkpoint leaves uncharged the episodes that were running when it
    stopped (their ends were never seen).

    With ``torque_until_settling``, the reward's interaction-torque terms count until the
    episode settles, as the study's peak and RMS torque do: each step from the settling time
    on gets back what its ``inter`` and ``gentle`` terms cost it (``-w_inter x inter +
    gentleness x gentle``, :func:`~myoexo.envs.reward.torque_cost` of the step's ``info`` and
    the env's ``rwd_keys_wt``), so holding the knee at the target costs the policy no torque
    penalty.

    Args:
        penalty: Charged per control step before settling (>= 0).
        threshold: Band half-width, a fraction of the step.
        torque_until_settling: Refund the torque terms from the settling time on.

    Raises:
        ValueError: *penalty* is negative, or neither a penalty nor the refund is asked.
    """

    def __init__(
        self,
        penalty: float,
        threshold: float = SETTLING_THRESHOLD,
        torque_until_settling: bool = False,
        verbose: int = 0,
    ) -> None:
        super().__init__(verbose)
        if not penalty >= 0.0:
            raise ValueError(f"penalty = {penalty} must be >= 0")
        if not (penalty or torque_until_settling):
            raise ValueError("nothing to relabel: penalty = 0 and no torque_until_settling")
        self.penalty = float(penalty)
        self.threshold = float(threshold)
        self.torque_until_settling = bool(torque_until_settling)
        self._buffer: Any = None
        self._weights: list[dict[str, float]] = []  # each env's ``rwd_keys_wt``
        self._first_row: list[int] = []  # buffer row of each env's episode's first step
        self._errors: list[list[float]] = []
        self._times: list[list[float]] = []
        self._torque_paid: list[list[float]] = []
        self._due: list[tuple[int, np.ndarray, Any]] = []  # env, rows, reward change

    def _on_training_start(self) -> None:
        self._buffer = getattr(self.model, "replay_buffer", None)
        if self._buffer is None:
            raise TypeError(f"{type(self.model).__name__} keeps no replay buffer to relabel")
        n = self.training_env.num_envs
        if self.torque_until_settling:
            self._weights = [dict(w) for w in self.training_env.get_attr("rwd_keys_wt")]
        self._first_row = [int(self._buffer.pos)] * n
        self._errors = [[] for _ in range(n)]
        self._times = [[] for _ in range(n)]
        self._torque_paid = [[] for _ in range(n)]
        self._due = []

    def _on_step(self) -> bool:
        dones = self.locals["dones"]
        size = self._buffer.buffer_size
        for i, info in enumerate(self.locals["infos"]):
            self._errors[i].append(float(info["error_deg"]))
            self._times[i].append(float(info["time_s"]))
            if self.torque_until_settling:
                gentleness = info.get("gentleness") or 0.0
                self._torque_paid[i].append(torque_cost(info, self._weights[i], gentleness))
            if dones[i]:
                n_steps = len(self._errors[i])
                steps = self.settling_steps(self._times[i], self._errors[i])
                first = self._first_row[i]
                if self.penalty:
                    self._due.append((i, (first + np.arange(steps)) % size, -self.penalty))
                if self.torque_until_settling and steps < n_steps:
                    rows = (first + np.arange(steps, n_steps)) % size
                    self._due.append((i, rows, np.asarray(self._torque_paid[i][steps:])))
                # this step's transition goes to the buffer's current row; the next, after it
                self._first_row[i] = (int(self._buffer.pos) + 1) % size
                self._errors[i], self._times[i], self._torque_paid[i] = [], [], []
        return True

    def settling_steps(self, times_s: list[float], errors_deg: list[float]) -> int:
        """Control steps of an episode before its settling time (all of them if unsettled)."""
        t, y = np.asarray(times_s), np.asarray(errors_deg)
        ts = settling_time(t, y, self.threshold, y_final=final_value(t, y, FINAL_WINDOW_S))
        return y.size if math.isnan(ts) else int(np.searchsorted(t, ts - 1e-9))

    def _on_rollout_end(self) -> None:
        """Charge the ended episodes, whose transitions are all stored by now."""
        for i, rows, change in self._due:
            self._buffer.rewards[rows, i] += change
        self._due = []


@dataclass(frozen=True)
class SmallEvalSpec:
    """The periodic small evaluation.

    Attributes:
        levels: Spasticity levels.
        subjects: Fixed subjects per level (indices ``0..subjects-1`` of
            :func:`myoexo.evaluation.subject_seed`, the full protocol's first subjects).
        root_seed: Root seed of the subjects (:data:`SELECTION_ROOT_SEED`, never the
            reported evaluation's root; and held out from training: the training
            envs draw their subjects from the training seed, not from these).
        twin: The twin of the evaluation (:class:`~myoexo.envs.options.TwinOptions`: the
            run's own, on the nominal twin: its observation, task and reflex model).
        residual: The classical controller a residual policy corrects
            (:class:`~myoexo.control.residual.ResidualConfig`; ``None``: the policy alone).
    """

    levels: tuple[int, ...] = VALID_LEVELS
    subjects: int = 2
    root_seed: int = SELECTION_ROOT_SEED
    twin: TwinOptions = field(default_factory=TwinOptions)
    residual: ResidualConfig | None = None

    def __post_init__(self) -> None:
        check_fit_root(self.root_seed, "the periodic evaluation (it scores checkpoints)")


class EvaluationAborted(Exception):
    """A small evaluation given up because training is stopping (SIGTERM / SIGINT)."""


def _level_means(
    controller: Any,
    level: int,
    spec: SmallEvalSpec,
    env: Any,
    stop: StopSignals | None = None,
) -> dict[str, float]:
    from myoexo.evaluation import run_episode, subject_seed

    rows = []
    for i in range(spec.subjects):
        if stop is not None and stop.received is not None:
            raise EvaluationAborted(f"stopped by {stop.name}")
        res = run_episode(env, controller, subject_seed(level, i, spec.root_seed))
        m = res.metrics.as_dict()
        rows.append([m[k] for k in CRITERIA_METRICS] + [float(res.unstable)])
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # NaN settling time of every subject
        means = np.nanmean(np.array(rows, dtype=np.float64), axis=0)
    return dict(zip([*CRITERIA_METRICS, "unstable"], map(float, means), strict=True))


class PaperMetricsEvalCallback(BaseCallback):
    """Small periodic evaluation of the deterministic policy against the PID.

    Logs ``eval/L<level>/<metric>`` and ``eval/L<level>/peak_vs_pid_pct`` (negative = less
    peak torque than the PID) and ``eval/score`` (:func:`myoexo.evaluation.criteria.ranking_score`)
    to the SB3 logger,
    appends the rows to ``<run>/eval.csv`` and keeps :attr:`last_score` for the
    checkpoints. The PID's numbers are computed once per run (``eval_pid.json``).

    Once ``stop`` has received a signal, no evaluation starts and the one running is given
    up before its next episode (no row, no score): the stop of a run waits for one episode,
    not for a whole evaluation.

    Args:
        run_dir: Run folder.
        every_steps: Transitions between evaluations.
        spec: Levels, subjects and bounds.
        stop: The training's stop flag (:class:`~myoexo.runtime.lifecycle.StopSignals`).
    """

    def __init__(
        self,
        run_dir: Path,
        every_steps: int,
        spec: SmallEvalSpec,
        verbose: int = 0,
        stop: StopSignals | None = None,
    ):
        super().__init__(verbose)
        self.stop = stop
        if every_steps <= 0:
            raise ValueError(f"every_steps = {every_steps} must be > 0")
        self.run_dir = Path(run_dir)
        self.every_steps = int(every_steps)
        self.spec = spec
        self.last_score: float | None = None
        self.last_eval_step: int | None = None
        self.last_metrics: dict[int, dict[str, float]] = {}
        self._envs: dict[int, Any] = {}
        self._pid: dict[int, dict[str, float]] = {}
        self._next = 0

    def _env(self, level: int) -> Any:
        if level not in self._envs:
            from myoexo.envs import make_env

            self._envs[level] = make_env(level, **self.spec.twin.env_kwargs())
        return self._envs[level]

    def _on_training_start(self) -> None:
        self._next = (self.num_timesteps // self.every_steps + 1) * self.every_steps
        path = self.run_dir / ck.EVAL_PID_FILE
        if path.is_file():
            self._pid = {int(k): v for k, v in json.loads(path.read_text()).items()}
        missing = [lv for lv in self.spec.levels if lv not in self._pid]
        if missing:
            from myoexo.control import build_controller, parse_controller_spec

            try:
                for level in missing:
                    env = self._env(level)
                    pid = build_controller(parse_controller_spec("pid"), env)
                    self._pid[level] = _level_means(pid, level, self.spec, env, self.stop)
            except EvaluationAborted:
                return  # stopping: the next session computes the PID's numbers
            write_json_atomic(path, {str(k): v for k, v in sorted(self._pid.items())})

    def _stopping(self) -> bool:
        return self.stop is not None and self.stop.received is not None

    def _on_step(self) -> bool:
        if self.num_timesteps >= self._next:
            self._next += self.every_steps
            if not self._stopping():
                try:
                    self.evaluate()
                except EvaluationAborted:
                    pass  # stopping: this step goes without an evaluation
        return True

    def evaluate(self) -> float:
        """Run the small evaluation now; returns the score.

        Raises:
            EvaluationAborted: Training is stopping (the evaluation was given up).
        """
        from myoexo.control.specs import with_residual_base
        from myoexo.training.export import deterministic_controller

        actor = deterministic_controller(self.model)
        t0 = time.perf_counter()
        sac = {}
        for lv in self.spec.levels:
            env = self._env(lv)
            controller = with_residual_base(actor, self.spec.residual, env)
            sac[lv] = _level_means(controller, lv, self.spec, env, self.stop)
        score = criteria.ranking_score(
            criteria.compare_with_pid(sac, {lv: self._pid[lv] for lv in sac})
        )
        rows = []
        for level, m in sac.items():
            pid_peak = self._pid[level]["peak_interaction_torque_nm"]
            rel = 100.0 * (m["peak_interaction_torque_nm"] - pid_peak) / max(pid_peak, 1e-9)
            for key, value in m.items():
                self.logger.record(f"eval/L{level}/{key}", value)
            self.logger.record(f"eval/L{level}/peak_vs_pid_pct", rel)
            rows.append({"step": self.num_timesteps, "level": level, **m, "peak_vs_pid_pct": rel})
        self.logger.record("eval/score", score)
        self.logger.record("eval/wall_time_s", time.perf_counter() - t0)
        self.logger.dump(self.num_timesteps)
        self._append_rows(rows, score)
        self.last_score, self.last_metrics = score, sac
        self.last_eval_step = self.num_timesteps
        if self.verbose:
            errs = " ".join(f"L{lv}:{m['abs_final_error_deg']:.2f}" for lv, m in sac.items())
            print(f"[eval] step {self.num_timesteps}: score {score:+.3f}, |final err| deg {errs}")
        return score

    def _append_rows(self, rows: list[dict[str, Any]], score: float) -> None:
        path = self.run_dir / ck.EVAL_FILE
        fields = ["step", "level", *CRITERIA_METRICS, "unstable", "peak_vs_pid_pct", "score"]
        new = not path.is_file()
        with open(path, "a", newline="") as f:
            writer = csv.DictWriter(f, fieldnames=fields)
            if new:
                writer.writeheader()
            for row in rows:
                writer.writerow({**row, "score": score})

    def _on_training_end(self) -> None:
        for env in self._envs.values():
            env.close()
        self._envs.clear()


class PeriodicCheckpointCallback(BaseCallback):
    """Save a resumable checkpoint every ``every_s`` seconds or ``every_steps`` transitions,
    whichever comes first, and at the end of training (see
    :mod:`myoexo.training.checkpoints`).

    A run without a resumable checkpoint yet gets its first one early: once
    ``learning_starts + first_after_steps`` transitions are collected or ``first_after_s``
    seconds have passed, whichever comes first (each only with its cadence on), so that a
    run killed early does not start over. A policy snapshot (no replay buffer) is also saved
    at every evaluated step. With a wall-time budget, the callback also ends the run once
    :meth:`wall_time_s` reaches it, with a resumable checkpoint that records that wall time
    (one clock for the budget and the checkpoints, so a resume sees the budget spent).

    Args:
        run_dir: Run folder.
        every_s: Wall time between checkpoints (0: off).
        every_steps: Transitions between checkpoints (0: off).
        wall_time_offset_s: Training wall time of the previous sessions of this run.
        evaluator: Its :attr:`~PaperMetricsEvalCallback.last_score` goes into each state.
        keep_replay: Replay buffers kept (newest checkpoints).
        first_after_steps: Transitions after ``learning_starts`` of the first checkpoint
            (0: off).
        first_after_s: Wall time of the first checkpoint (0: off).
        max_wall_time_s: The run's training wall-time budget, all sessions (0: none).
        provenance: What every checkpoint's state records so that its policy's env can be
            rebuilt from the checkpoint alone (``twin``, ``env_id``, ``algorithm``).
    """

    def __init__(
        self,
        run_dir: Path,
        every_s: float,
        every_steps: int = 0,
        wall_time_offset_s: float = 0.0,
        evaluator: PaperMetricsEvalCallback | None = None,
        keep_replay: int = ck.DEFAULT_KEEP_REPLAY,
        verbose: int = 0,
        first_after_steps: int = 0,
        first_after_s: float = 0.0,
        max_wall_time_s: float = 0.0,
        provenance: dict[str, Any] | None = None,
    ) -> None:
        super().__init__(verbose)
        self.run_dir = Path(run_dir)
        self.provenance = dict(provenance or {})
        self.max_wall_time_s = float(max_wall_time_s)
        #: The session ended because the wall-time budget was spent.
        self.budget_spent = False
        self.every_s = float(every_s)
        self.every_steps = int(every_steps)
        self.wall_time_offset_s = float(wall_time_offset_s)
        self.evaluator = evaluator
        self.keep_replay = int(keep_replay)
        self.first_after_steps = int(first_after_steps)
        self.first_after_s = float(first_after_s)
        self.last_checkpoint: Path | None = None
        self._t_start = 0.0
        self._t_last = 0.0
        self._step_last = 0  # step of the last checkpoint of any kind
        self._step_last_full = 0  # step of the last resumable checkpoint
        self._steps_at_start = 0
        self._first_pending = False
        self._first_step = 0

    def _on_training_start(self) -> None:
        self._t_start = self._t_last = time.monotonic()
        self._step_last = self._step_last_full = self._steps_at_start = self.num_timesteps
        self._first_pending = ck.latest_checkpoint(self.run_dir, with_replay=True) is None
        learning_starts = int(getattr(self.model, "learning_starts", 0))
        self._first_step = learning_starts + self.first_after_steps

    def wall_time_s(self) -> float:
        """Training wall time of the run so far, all sessions."""
        return self.wall_time_offset_s + time.monotonic() - self._t_start

    def _due(self, now: float) -> bool:
        """Whether a resumable checkpoint is due now."""
        use_time, use_steps = self.every_s > 0, self.every_steps > 0
        if self._first_pending:
            if use_time and self.first_after_s > 0 and now - self._t_start >= self.first_after_s:
                return True
            if use_steps and self.first_after_steps > 0 and self.num_timesteps >= self._first_step:
                return True
        due_time = use_time and now - self._t_last >= self.every_s
        due_steps = use_steps and self.num_timesteps - self._step_last_full >= self.every_steps
        return due_time or due_steps

    def _on_step(self) -> bool:
        if self.max_wall_time_s > 0 and self.wall_time_s() >= self.max_wall_time_s:
            self.budget_spent = True
            self.save(with_replay=True)
            return False
        if self._due(time.monotonic()):
            self.save(with_replay=True)
        elif (
            self.evaluator is not None
            and self.evaluator.last_eval_step == self.num_timesteps
            and self._step_last != self.num_timesteps
        ):
            self.save(with_replay=False)  # a policy snapshot for every evaluated step
        return True

    def save(self, with_replay: bool = True) -> Path:
        """Write a checkpoint now (resumable with the replay buffer, else a snapshot)."""
        ev = self.evaluator
        score = ev.last_score if ev is not None else None
        elapsed = time.monotonic() - self._t_start
        state = {
            "num_timesteps": int(self.num_timesteps),
            "n_updates": int(getattr(self.model, "_n_updates", 0)),
            "episodes": int(getattr(self.model, "_episode_num", 0)),
            "wall_time_s": round(self.wall_time_s(), 3),
            "session_env_steps_per_s": round(
                (self.num_timesteps - self._steps_at_start) / max(elapsed, 1e-9), 2
            ),
            "eval_score": score,
            "eval_step": ev.last_eval_step if ev is not None else None,
            "resumable": with_replay,
            "saved_utc": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
            **self.provenance,
        }
        self.last_checkpoint = ck.save_checkpoint(
            self.model, self.run_dir, state, with_replay, self.keep_replay
        )
        self._step_last = self.num_timesteps
        if with_replay:
            self._t_last = time.monotonic()
            self._step_last_full = self.num_timesteps
            self._first_pending = False
        if self.verbose:
            print(
                f"[checkpoint] step {state['num_timesteps']} updates {state['n_updates']} "
                f"wall {state['wall_time_s']:.0f} s -> {self.last_checkpoint.name}",
                flush=True,
            )
        return self.last_checkpoint

    def _on_training_end(self) -> None:
        if self._step_last_full != self.num_timesteps or self.last_checkpoint is None:
            last = ck.latest_checkpoint(self.run_dir, with_replay=True)
            if last is None or ck.step_of(last) != self.num_timesteps:
                self.save(with_replay=True)


class StopOnSignalCallback(BaseCallback):
    """End training at the next step once ``signals`` has received SIGTERM / SIGINT.

    SB3 then leaves ``learn`` as at its normal end: the update in progress completes (the
    flag is only read between env steps) and :class:`PeriodicCheckpointCallback` writes
    the final resumable checkpoint in its ``_on_training_end``. The transitions of the
    vector step that saw the flag are counted but not stored in the replay buffer (SB3
    stops before storing them): ``n_envs`` transitions.
    """

    def __init__(self, signals: StopSignals, verbose: int = 0) -> None:
        super().__init__(verbose)
        self.signals = signals

    def _on_step(self) -> bool:
        return self.signals.received is None
