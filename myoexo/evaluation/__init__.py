"""The paper's evaluation protocol: metrics, the paired multi-subject engine, figures and the
Markdown report (``myoexo evaluate``, ``myoexo report``).

    from myoexo.evaluation import EvaluationConfig, evaluate

    run = evaluate(EvaluationConfig(controllers=("pid", "sac"), subjects=100), "results/eval")
    run.table.groupby(["controller", "level"]).peak_interaction_torque_nm.mean()

Modules: :mod:`.config` (what a run is, subject seeds, ``config.json``), :mod:`.engine`
(episodes, chunks), :mod:`.backends` (in-process, worker processes) and :mod:`.ray_backend`
(the chunks as Ray tasks, on a cluster: ``docs/cluster.md``), :mod:`.runner` (a whole run:
:func:`evaluate`), :mod:`.storage` (chunk, table and trace files),
:mod:`.metrics`, :mod:`.stats` (summaries, intervals, bootstraps, the tail),
:mod:`.criteria` (the acceptance criteria and the verdicts), :mod:`.paper` (the study's
numbers), :mod:`.figures`, :mod:`.report`, :mod:`.results` (result sets and their tables).
"""

from myoexo.evaluation.backends import available_cores
from myoexo.evaluation.config import EvaluationConfig, load_config, subject_seed
from myoexo.evaluation.engine import EpisodeResult, evaluate_controller, run_episode
from myoexo.evaluation.metrics import EpisodeMetrics, episode_metrics
from myoexo.evaluation.runner import EvaluationRun, evaluate
from myoexo.evaluation.storage import Traces, load_table, load_traces

__all__ = [
    "EpisodeMetrics",
    "EpisodeResult",
    "EvaluationConfig",
    "EvaluationRun",
    "Traces",
    "available_cores",
    "episode_metrics",
    "evaluate",
    "evaluate_controller",
    "load_config",
    "load_table",
    "load_traces",
    "run_episode",
    "subject_seed",
]
