"""No selection leakage: policies are never reported on the subjects that selected them."""

from __future__ import annotations

import pytest

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


def _policy_files() -> list[str]:
    """Every shipped policy by name and by its own file (the exported actor's ``.npz``)."""
    from myoexo.policies import shipped_path

    names = sorted(SHIPPED_POLICIES)
    return names + [str(shipped_path(n).with_suffix(".npz")) for n in names]


@pytest.mark.parametrize("policy", _policy_files())
def test_an_evaluation_on_the_selection_root_is_refused_through_the_real_files(
    policy, tmp_path, capsys
):
    """`myoexo evaluate` of a shipped policy (by name, or its own .npz file) on the root that
    selected it exits 2 naming the root, and writes nothing; on the evaluation root it
    resolves. (A `model.zip` chosen by `myoexo policy select` is refused the same way:
    tests/test_twin_options.py runs it through the console script.)"""
    from myoexo.cli import main

    out = tmp_path / "out"
    argv = ["evaluate", "--controllers", policy, "--levels", "0", "--subjects", "1"]
    assert main([*argv, "--seed", str(SELECTION_ROOT_SEED), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert f"selected on the subjects of root seed {SELECTION_ROOT_SEED}" in err
    assert not out.exists()
    chosen, skipped = resolve_controllers([policy], root_seed=EVALUATION_ROOT_SEED)
    assert len(chosen) == 1 and not skipped


def test_a_selection_run_may_not_use_the_evaluation_root_and_makes_no_result_set(tmp_path):
    from myoexo.evaluation.results import collect
    from myoexo.evaluation.runner import evaluate

    with pytest.raises(ValueError, match="that is the evaluation root"):
        EvaluationConfig(selection=True, root_seed=EVALUATION_ROOT_SEED)
    from myoexo.envs.options import TwinOptions

    config = EvaluationConfig(
        controllers=("pid", "sac"),
        levels=(0,),
        subjects=1,
        root_seed=SELECTION_ROOT_SEED,
        selection=True,  # may run `sac` on the root that selected it: a picking step
        twin=TwinOptions(task=(("episode_duration_s", 0.2),)),
    )
    evaluate(config, tmp_path / "picking", workers=1, progress=False)
    with pytest.raises(ValueError, match="evaluation root 0 only"):
        collect(tmp_path / "picking", tmp_path / "set")
    assert not (tmp_path / "set").exists()


# ------------------------------------------------------------- fitting and choosing refused
def test_the_subject_roots_are_distinct_and_their_streams_disjoint():
    import itertools

    from myoexo.evaluation.config import SUBJECT_ROOTS, subject_seed

    assert sorted(SUBJECT_ROOTS) == ["calibration", "evaluation", "recovery", "selection"]
    assert len(set(SUBJECT_ROOTS.values())) == len(SUBJECT_ROOTS)
    seeds = {
        name: {subject_seed(level, i, root) for level in range(4) for i in range(300)}
        for name, root in SUBJECT_ROOTS.items()
    }
    assert all(len(s) == 1200 for s in seeds.values())
    for a, b in itertools.combinations(seeds, 2):
        assert not (seeds[a] & seeds[b]), (a, b)


@pytest.mark.parametrize(
    "argv",
    [
        ["twin", "calibrate", "--seed", "0", "--subjects", "2", "--verify-subjects", "2"],
        ["twin", "calibrate", "--reflex", "persistent", "--seed", "0"],
        ["policy", "select", "RUN", "--root-seed", "0"],
    ],
)
def test_fitting_or_choosing_on_the_evaluation_root_is_refused_on_the_command_line(
    argv, tmp_path, capsys
):
    from myoexo.cli import main

    argv = [str(tmp_path / "run") if a == "RUN" else a for a in argv]
    before = sorted(tmp_path.rglob("*"))
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "that is the evaluation root" in err and err.count("\n") == 1
    assert sorted(tmp_path.rglob("*")) == before  # nothing written


def test_fitting_or_choosing_on_the_evaluation_root_is_refused_in_the_api(tmp_path):
    from myoexo.spasticity import get_reflex
    from myoexo.studies.calibrate import calibrate, fit_threshold_shift
    from myoexo.studies.distill import DistillConfig
    from myoexo.training.callbacks import SmallEvalSpec
    from myoexo.training.seeds import per_seed_table
    from myoexo.training.select import SelectionConfig, select_checkpoint

    for call in (
        lambda: calibrate(subjects=2, verify_subjects=2, root_seed=0),
        lambda: fit_threshold_shift(2, 6.3, get_reflex("stretch"), 2, root_seed=0),
        lambda: select_checkpoint(tmp_path, root_seed=0),
        lambda: per_seed_table(tmp_path, SelectionConfig(1, last=1, top=1, root_seed=0)),
        lambda: SmallEvalSpec(root_seed=0),
        lambda: DistillConfig(root_seed=0),
    ):
        with pytest.raises(ValueError, match="that is the evaluation root"):
            call()


def test_the_fitted_reflex_values_record_their_root():
    from myoexo.evaluation.config import CALIBRATION_ROOT_SEED
    from myoexo.spasticity import CALIBRATION, PERSISTENT, UNCALIBRATED
    from myoexo.spasticity.tsrt import TSRT_CALIBRATION

    # the shipped calibrations are fitted on the calibration root; the persistent gains are
    # chosen, not fitted, and say so
    assert CALIBRATION.root_seed == CALIBRATION_ROOT_SEED == TSRT_CALIBRATION.root_seed
    assert PERSISTENT.root_seed is None and PERSISTENT.note.startswith("chosen, not fitted")
    assert UNCALIBRATED.root_seed is None
