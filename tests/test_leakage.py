"""No selection leakage: policies are never reported on the subjects that selected them."""

from __future__ import annotations

import pytest

from myoexo.control import specs
from myoexo.evaluation.config import EVALUATION_ROOT_SEED, SELECTION_ROOT_SEED, EvaluationConfig
from myoexo.evaluation.engine import resolve_controllers
from myoexo.policies import SHIPPED_POLICIES, load_policy
from myoexo.training.callbacks import SmallEvalSpec


def test_selection_and_evaluation_roots_differ_by_default():
    assert SELECTION_ROOT_SEED != EVALUATION_ROOT_SEED
    assert SmallEvalSpec().root_seed == SELECTION_ROOT_SEED
    assert EvaluationConfig().root_seed == EVALUATION_ROOT_SEED


@pytest.mark.parametrize("name", sorted(SHIPPED_POLICIES))
def test_shipped_policies_record_a_selection_root_other_than_the_evaluation(name):
    policy = load_policy(name)
    assert policy.selection_root_seed is not None
    assert policy.selection_root_seed != EVALUATION_ROOT_SEED


def test_an_evaluation_on_the_selection_root_is_refused(monkeypatch):
    class Chosen:
        def __init__(self) -> None:
            self.metadata = {"selection_root_seed": 5, "obs_preset": "full"}

    monkeypatch.setattr(specs, "load_shipped_policy", lambda name="sac": Chosen())
    import myoexo.evaluation.engine as engine

    monkeypatch.setattr(engine, "load_shipped_policy", lambda name="sac": Chosen())
    with pytest.raises(ValueError, match="selected on the subjects of root seed 5"):
        resolve_controllers(["sac"], root_seed=5)
    chosen, skipped = resolve_controllers(["sac"], root_seed=0)
    assert [s.label for s in chosen] == ["sac"] and not skipped
