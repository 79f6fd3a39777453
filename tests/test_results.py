"""Result sets (myoexo.evaluation.results): an evaluation folder collected into small files,
rendered into the docs' and the README's results tables, and a check that fails when a
committed table differs from what its files give."""

from __future__ import annotations

import shutil
from pathlib import Path

import pandas as pd
import pytest

from myoexo.envs.options import TwinOptions
from myoexo.evaluation import EvaluationConfig, evaluate
from myoexo.evaluation.config import load_config
from myoexo.evaluation.results import (
    README_END,
    README_SET,
    README_START,
    RESULTS_DIR,
    collect,
    command_of,
    write_tables,
)

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def evaluation(tmp_path_factory):
    out = tmp_path_factory.mktemp("results") / "eval"
    config = EvaluationConfig(
        controllers=("pid", "sac"),
        levels=(1, 2),
        subjects=3,
        twin=TwinOptions().replace(episode_duration_s=0.5),
    )
    evaluate(config, out, workers=1, progress=False, log=lambda m: None)
    return out


def test_a_result_set_holds_the_tables_inputs_and_its_provenance(evaluation, tmp_path):
    dest = collect(evaluation, tmp_path / README_SET)
    meta = (dest / "meta.json").read_text()
    assert "myoexo evaluate --controllers pid sac --levels 1 2 --subjects 3" in meta
    assert '"root_seed": 0' in meta and '"reference": "pid"' in meta
    red = pd.read_csv(dest / "reductions.csv")
    assert list(red.controller) == ["sac", "sac"] and {"peak_reduction_pct_low"} <= set(red)
    heads = pd.read_csv(dest / "headline.csv", dtype={"levels": str})
    assert list(heads.scope) == ["study", "all"] and heads.levels.iloc[0] == "1, 2"
    assert command_of(load_config(evaluation)).endswith("--set episode_duration_s=0.5")


def test_tables_are_rendered_and_a_stale_one_is_caught(evaluation, tmp_path):
    root = tmp_path / "repo"
    collect(evaluation, root / RESULTS_DIR / README_SET)
    (root / "README.md").write_text(f"intro\n{README_START}\nold\n{README_END}\nrest\n")
    assert write_tables(root, check=True) == [f"{RESULTS_DIR}/{README_SET}/tables.md", "README.md"]
    assert write_tables(root) and write_tables(root, check=True) == []
    readme = (root / "README.md").read_text()
    assert readme.startswith("intro\n") and readme.endswith("rest\n") and "old" not in readme
    assert "| 2 |" in readme and "(the study's aggregation)" in readme
    tables = root / RESULTS_DIR / README_SET / "tables.md"
    tables.write_text(tables.read_text().replace("| 1 |", "| 1 (edited) |", 1))
    assert write_tables(root, check=True) == [f"{RESULTS_DIR}/{README_SET}/tables.md"]
    (root / "README.md").write_text("no markers\n")
    with pytest.raises(ValueError, match="lacks the markers"):
        write_tables(root, check=True)
    shutil.rmtree(root / RESULTS_DIR / README_SET)
    (root / RESULTS_DIR / "broken").mkdir()
    with pytest.raises(ValueError, match="is no result set"):
        write_tables(root, check=True)


def test_every_committed_results_table_is_what_its_files_give():
    """The docs' and the README's generated results tables (run `myoexo results tables`
    after `myoexo results collect` to refresh them)."""
    assert (REPO / RESULTS_DIR).is_dir(), "no committed result set"
    assert write_tables(REPO, check=True) == []
