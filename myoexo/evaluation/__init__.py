"""The paper's evaluation protocol: metrics, the paired multi-subject runner, figures and the
Markdown report (``myoexo evaluate``, ``myoexo report``).

    from myoexo.evaluation import EvaluationConfig, evaluate

    run = evaluate(EvaluationConfig(controllers=("pid", "sac"), subjects=100), "results/eval")
    run.table.groupby(["controller", "level"]).peak_interaction_torque_nm.mean()
"""

from myoexo.evaluation.metrics import EpisodeMetrics, episode_metrics
from myoexo.evaluation.runner import (
    EvaluationConfig,
    EvaluationRun,
    evaluate,
    evaluate_controller,
    load_table,
    load_traces,
    run_episode,
    subject_seed,
)

__all__ = [
    "EpisodeMetrics",
    "EvaluationConfig",
    "EvaluationRun",
    "episode_metrics",
    "evaluate",
    "evaluate_controller",
    "load_table",
    "load_traces",
    "run_episode",
    "subject_seed",
]
