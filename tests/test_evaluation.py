"""The evaluation protocol on the twin: paired table, worker-count invariance, resume after a
kill, clean refusal of bad arguments, SB3 model files, the report, and the PID's pattern."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time

import numpy as np
import pandas as pd
import pytest

from myoexo.cli import main as cli_main
from myoexo.envs import make_env
from myoexo.envs.options import TwinOptions
from myoexo.evaluation import EvaluationConfig, evaluate, load_traces, subject_seed
from myoexo.evaluation.engine import resolve_controllers
from myoexo.evaluation.report import write_report
from myoexo.evaluation.storage import TRACE_CHANNELS

SHORT_S = 2.0  # episode length of the machinery tests (the PID pattern test runs the full 8 s)
CONFIG = EvaluationConfig(
    controllers=("pid", "pid:feedback=exo"),
    levels=(0, 3),
    subjects=3,
    twin=TwinOptions().replace(episode_duration_s=SHORT_S),
    chunk_size=2,
)


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    out = tmp_path_factory.mktemp("evaluation") / "ref"
    run = evaluate(CONFIG, out, workers=1, progress=False)
    return out, run


def test_subject_seeds_are_paired_and_distinct():
    seeds = {(lv, i): subject_seed(lv, i) for lv in range(4) for i in range(50)}
    assert len(set(seeds.values())) == len(seeds)
    assert subject_seed(2, 7) == subject_seed(2, 7) != subject_seed(2, 7, root_seed=1)
    with pytest.raises(ValueError):
        subject_seed(-1, 0)


def test_table_is_tidy_and_paired(reference):
    out, run = reference
    table = run.table
    assert len(table) == 2 * 2 * 3 and run.computed == 12
    for col in (
        "controller",
        "level",
        "subject",
        "seed",
        "subject_s_theta",
        "subject_k",
        "final_error_deg",
        "settling_time_s",
        "rms_interaction_torque_nm",
        "peak_interaction_torque_nm",
        "command_rms",
        "command_smoothness",
    ):
        assert col in table.columns, col
    # the same person for both controllers: same seed and same drawn parameters
    by = table.set_index(["controller", "level", "subject"]).sort_index()
    a, b = by.loc["pid"], by.loc["pid:feedback=exo"]
    pd.testing.assert_series_equal(a["seed"], b["seed"])
    pd.testing.assert_series_equal(a["subject_s_v"], b["subject_s_v"])
    assert (table["subject_s_v"][table.level == 0] == 0).all()  # level 0: no spasticity
    # parquet and csv hold the same table
    pq = pd.read_parquet(out / "episodes.parquet")
    csv = pd.read_csv(out / "episodes.csv")
    pd.testing.assert_frame_equal(pq, table, check_exact=True)
    np.testing.assert_allclose(csv["peak_interaction_torque_nm"], pq["peak_interaction_torque_nm"])
    tr = load_traces(out, "pid", 3)
    n = int(SHORT_S / 0.01) // CONFIG.trace_stride + 1
    assert tr["knee_angle_deg"].shape == (3, n) and tr["knee_angle_deg"].dtype == np.float32
    assert set(tr.data) == set(TRACE_CHANNELS)
    assert tr.time_s[-1] == pytest.approx(SHORT_S)


def test_same_table_for_one_and_two_workers(reference, tmp_path):
    _, run = reference
    run2 = evaluate(CONFIG, tmp_path / "w2", workers=2, progress=False)
    pd.testing.assert_frame_equal(run2.table, run.table, check_exact=True)


def test_resume_after_a_killed_run_loses_and_recomputes_nothing(reference, tmp_path):
    _, ref = reference
    out = tmp_path / "killed"
    cmd = [sys.executable, "-m", "myoexo.cli", "evaluate", "--controllers", *CONFIG.controllers]
    cmd += ["--levels", *map(str, CONFIG.levels), "--subjects", str(CONFIG.subjects)]
    cmd += ["--episode-duration-s", str(SHORT_S), "--chunk-size", "1", "--workers", "1"]
    cmd += ["--out", str(out), "--no-progress"]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.monotonic() + 120
    while not list(out.glob("traces/*/L*/0*.npz")) and time.monotonic() < deadline:
        assert proc.poll() is None, "the run ended before it could be killed"
        time.sleep(0.02)
    os.kill(proc.pid, signal.SIGKILL)
    proc.wait()
    done = len(list(out.glob("traces/*/L*/0*.npz")))
    assert 0 < done < 12
    assert not (out / "episodes.parquet").exists()  # killed before the table was written

    config = EvaluationConfig(**{**CONFIG.__dict__, "chunk_size": 1})
    run = evaluate(config, out, workers=1, progress=False)
    assert run.computed == 12 - done  # finished episodes were kept, not recomputed
    pd.testing.assert_frame_equal(run.table, ref.table, check_exact=True)
    assert not list(out.rglob(".tmp-*"))


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--levels", "0", "4"], "argument --levels: invalid choice: 4"),
        (["--subjects", "0"], "--subjects = 0 must be >= 1"),
        (["--controllers", "GARBAGE"], "cannot load"),
        (["--controllers", "missing.zip"], "does not exist"),
        (["--controllers", "lqr"], "unknown controller"),
    ],
)
def test_bad_arguments_give_a_clear_error_and_write_nothing(tmp_path, capsys, args, message):
    garbage = tmp_path / "garbage.zip"
    garbage.write_bytes(b"not a model")
    args = [str(garbage) if a == "GARBAGE" else a for a in args]
    args = [str(tmp_path / a) if a == "missing.zip" else a for a in args]
    out = tmp_path / "out"
    try:
        status = cli_main(["evaluate", *args, "--out", str(out), "--no-progress"])
    except SystemExit as stop:  # a mistake argparse itself finds
        status = stop.code
    assert status == 2
    (line,) = capsys.readouterr().err.strip().splitlines()
    assert line.startswith("myoexo evaluate: error: ") and message in line
    assert not out.exists()


def test_a_different_run_in_the_same_folder_is_refused(reference):
    out, _ = reference
    other = EvaluationConfig(**{**CONFIG.__dict__, "root_seed": 1})
    before = sorted(p.name for p in out.rglob("*"))
    with pytest.raises(ValueError, match="other settings"):
        evaluate(other, out, workers=1, progress=False)
    assert sorted(p.name for p in out.rglob("*")) == before


def test_missing_shipped_policy_is_skipped_with_a_message(monkeypatch):
    import myoexo.policies

    def unavailable(name="sac"):
        raise FileNotFoundError("no policy file")

    monkeypatch.setattr(myoexo.policies, "load_policy", unavailable)
    messages = []
    specs, skipped = resolve_controllers(["pid", "sac"], log=messages.append)
    assert [s.label for s in specs] == ["pid"] and "sac" in skipped
    assert "no policy file" in messages[0]
    with pytest.raises(ValueError, match="no controller left"):
        resolve_controllers(["sac"], log=messages.append)


def test_an_sb3_model_file_is_evaluated(tmp_path):
    from stable_baselines3 import SAC

    env = make_env(0)
    model = SAC("MlpPolicy", env, buffer_size=1, policy_kwargs={"net_arch": [16, 16]}, seed=0)
    env.close()
    path = tmp_path / "tiny_sac.zip"
    model.save(path)
    config = EvaluationConfig(
        controllers=(str(path),),
        levels=(0,),
        subjects=1,
        twin=TwinOptions().replace(episode_duration_s=0.5),
    )
    run = evaluate(config, tmp_path / "out", workers=1, progress=False)
    assert run.table.controller.tolist() == ["tiny_sac"]
    assert np.isfinite(run.table.peak_interaction_torque_nm).all()


def test_report_writes_figures_and_the_comparison(reference, tmp_path, capsys):
    out, _ = reference
    path = write_report(out, tmp_path / "report")
    text = path.read_text()
    for section in ("## Summary", "## Next to the paper", "## Reductions against the PID"):
        assert section in text
    assert "9.3" in text and "11.45" in text  # the paper's level-3 PID and SAC final errors
    assert "`pid:feedback=exo` vs `pid`" in text
    for name in ("fig3_pid", "fig4_comparison", "fig5_rms_vs_settling", "fig6_peak_torque"):
        png = tmp_path / "report" / "figures" / f"{name}.png"
        assert png.stat().st_size > 10_000 and f"({png.relative_to(path.parent)})" in text
    summary = pd.read_csv(tmp_path / "report" / "summary.csv")
    assert len(summary) == 4
    assert "## Tail risk" in text and "(the study's aggregation)" in text
    risk = pd.read_csv(tmp_path / "report" / "tail_risk.csv")
    assert len(risk) == 4 and {"worst_subject", "catastrophic", "p99_abs_final_error_deg"} <= set(
        risk.columns
    )
    assert cli_main(["report", str(tmp_path / "nothing")]) == 2
    assert "not an evaluation folder" in capsys.readouterr().err


@pytest.mark.slow
def test_pid_on_the_twin_follows_the_papers_pattern():
    """Full 8 s episodes, 3 subjects per level. Paper: overshoot at levels 0 and 1, final
    error 6.3 deg at level 2 and 9.3 deg at level 3.

    The calibrated stretch reflex (``myoexo twin calibrate``, fitted on 40 subjects per level
    and checked on 200) reproduces it: the PID overshoots and reaches the target at levels 0-1;
    at levels 2-3 the flexors' reflex, whose threshold lies inside the motion, stops the knee
    short of the target against the saturated 100 Nm motor, further at level 3. The bounds
    are loose (3 subjects; the subject spread of the final error is ~3-4 deg).
    """
    from myoexo.control import PID
    from myoexo.evaluation import evaluate_controller

    env = make_env(0)
    pid = PID.from_env(env)
    env.close()
    stats = {}
    for level in range(4):
        table, _ = evaluate_controller(pid, level, 3, label="pid")
        assert not table.unstable.any()
        stats[level] = table[
            [
                "final_error_deg",
                "target_overshoot_deg",
                "settling_time_s",
                "peak_interaction_torque_nm",
            ]
        ].mean()
    print("\nPID on the twin, mean of 3 subjects:\n" + pd.DataFrame(stats).T.to_string())
    for level in (0, 1):  # reaches the target, after an overshoot
        assert abs(stats[level].final_error_deg) < 1.0
        assert stats[level].target_overshoot_deg > 1.0
    assert stats[2].final_error_deg > 2.0  # stops short (paper 6.3 deg)
    assert stats[3].final_error_deg > stats[2].final_error_deg  # further short (paper 9.3)
    overshoot = [stats[lvl].target_overshoot_deg for lvl in range(4)]
    assert overshoot[0] > overshoot[3]  # the reflex damps the overshoot
    # the strap's torque on the knee (the interaction torque): on the scale of the study's
    # 100 Nm motor at every level. (On twin version 1 the level-0 peak was the highest: the
    # undamped strap rang as the overshoot was braked; tests/test_straps.py bounds it now.)
    peak = [stats[lvl].peak_interaction_torque_nm for lvl in range(4)]
    assert all(90.0 < p < 130.0 for p in peak), peak
