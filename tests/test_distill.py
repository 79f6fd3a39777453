"""The deployable student controller (myoexo.policies.student) and its DAgger distillation
(myoexo.studies.distill)."""

from __future__ import annotations

import itertools
import json
import math
from pathlib import Path

import numpy as np
import pytest

from myoexo.control.protocol import Controller
from myoexo.policies.actor import MLPActor
from myoexo.policies.student import (
    EXO_PRESET_KEYS,
    FORBIDDEN_KEYS,
    FRAME_DIM,
    FRAME_KEYS,
    StudentController,
    export_student_onnx,
    frame_indices,
    load_student,
    save_student,
    stack_frames,
)


def _random_student(n_frames: int = 4, stride: int = 2, seed: int = 0) -> StudentController:
    rng = np.random.default_rng(seed)
    dims = [n_frames * FRAME_DIM, 16, 16, 1]
    weights = [
        (rng.normal(0, 1 / math.sqrt(i), (o, i)), rng.normal(0, 0.1, o))
        for i, o in itertools.pairwise(dims)
    ]
    actor = MLPActor(
        weights,
        activation="elu",
        obs_mean=rng.normal(0, 0.1, dims[0]),
        obs_var=rng.uniform(0.5, 2.0, dims[0]),
    )
    return StudentController(actor, n_frames=n_frames, stride=stride)


@pytest.fixture(scope="module")
def env_exo():
    from myoexo.envs import make_env

    env = make_env(1, obs_preset="exo", episode_duration_s=0.5)
    yield env
    env.close()


@pytest.fixture(scope="module")
def env_full():
    from myoexo.envs import make_env

    env = make_env(1, episode_duration_s=0.5)
    yield env
    env.close()


def _episode_obs(env, seed: int, steps: int = 30) -> list[np.ndarray]:
    """Observations of an episode driven by a fixed command sequence."""
    obs, _ = env.reset(seed=seed)
    out = [obs]
    for k in range(steps):
        obs, *_ = env.step(np.array([-0.5 * math.sin(0.2 * k)], np.float32))
        out.append(obs)
    return out


def test_student_is_a_controller_and_reads_no_forbidden_key():
    student = _random_student()
    assert isinstance(student, Controller)
    assert student.obs_preset == "exo"
    assert not set(student.required_obs_keys) & set(FORBIDDEN_KEYS)
    assert EXO_PRESET_KEYS[:-1] == FRAME_KEYS and EXO_PRESET_KEYS[-1] == "time_frac"


def test_frame_layout_matches_the_env(env_exo, env_full):
    """The exo preset is the frame keys + time_frac; the full preset holds the same values
    at frame_indices(obs_keys)."""
    assert tuple(env_exo.unwrapped.obs_keys) == EXO_PRESET_KEYS
    a = _episode_obs(env_exo, seed=5, steps=5)
    b = _episode_obs(env_full, seed=5, steps=5)
    idx = frame_indices(env_full.unwrapped.obs_keys)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x[:FRAME_DIM], y[idx])


def test_reset_clears_memory(env_exo):
    student = _random_student()
    obs = _episode_obs(env_exo, seed=3, steps=12)
    assert student.memory is None
    first = [student.act(o) for o in obs]
    assert student.memory is not None
    window = student.last_window  # the last decision's input, the memory stacked
    assert window is not None
    np.testing.assert_array_equal(
        window, stack_frames(student.memory, student.n_frames, student.stride)
    )
    student.reset(seed=1)
    assert student.memory is None and student.last_window is None
    again = [student.act(o) for o in obs]
    np.testing.assert_array_equal(np.concatenate(first), np.concatenate(again))
    # the memory matters: the same last observation after another history acts differently
    student.reset()
    student.act(obs[0])
    other = student.act(obs[-1])
    assert not np.array_equal(other, first[-1])


def test_never_reads_forbidden_keys(env_exo, env_full):
    """Human-knee, muscle, strap and clock entries NaN (or a sensor record of NaN, or none):
    it still acts, and exactly as from the exo sensors alone."""
    from myoexo.envs.sensors import KneeAngleMeasurements

    nan_record = KneeAngleMeasurements(*[math.nan] * 7)
    exo_obs = _episode_obs(env_exo, seed=9, steps=15)
    full_obs = _episode_obs(env_full, seed=9, steps=15)
    keys = list(env_full.unwrapped.obs_keys)
    idx = set(frame_indices(keys).tolist())
    a = _random_student()
    b = _random_student().bind(env_full)
    for xe, xf in zip(exo_obs, full_obs, strict=True):
        xe = xe.copy()
        xe[-1] = np.nan  # time_frac
        xf = xf.copy()
        xf[[i for i in range(xf.size) if i not in idx]] = np.nan  # knee, muscles, clock ...
        ua = a.act(xe, nan_record)
        ub = b.act(xf)
        assert np.isfinite(ua).all() and ua.shape == (1,) and ua.dtype == np.float32
        np.testing.assert_array_equal(ua, ub)


def test_the_smoothness_term_makes_the_students_command_change_less_between_steps():
    """With labels that jitter from step to step around a slow trend, the student trained
    with the temporal smoothness term changes its command less between consecutive steps
    of an episode than the one trained on imitation alone, and still follows the trend."""
    from myoexo.studies.distill import DistillConfig, Episodes, train_student

    rng = np.random.default_rng(0)
    lengths = [200, 200]
    n = sum(lengths)
    t = np.concatenate([np.arange(k) for k in lengths]) / 200.0
    frames = rng.normal(size=(n, FRAME_DIM)).astype(np.float32)
    frames[:, 0] = t  # the trend is readable from the frame
    trend = 0.8 * t - 0.4
    labels = (trend + 0.3 * np.where(np.arange(n) % 2, 1.0, -1.0)).astype(np.float32)
    data = Episodes(frames, labels, np.array([0, lengths[0]]), np.zeros(n, np.int32))
    changes, errors = {}, {}
    for weight in (0.0, 5.0):
        config = DistillConfig(
            n_frames=1, hidden=(32,), batch_size=64, lr=3e-3, smoothness_weight=weight
        )
        student, _ = train_student(config, data, 40, None, seed=0, log=lambda _: None)
        command = np.array([student.actor.act(frames[i].astype(np.float64))[0] for i in range(n)])
        within = np.ones(n - 1, bool)
        within[lengths[0] - 1] = False  # the step across the two episodes
        changes[weight] = float(np.mean(np.abs(np.diff(command))[within]))
        errors[weight] = float(np.mean(np.abs(command - trend)))
    assert changes[5.0] < 0.5 * changes[0.0], changes
    assert errors[5.0] < 0.15, errors


def test_the_absolute_smoothness_term_damps_jitter_and_keeps_a_sharp_step():
    """Labels that step from 0.5 to -0.5 halfway through each episode, with an alternating
    jitter of 0.05 (both readable from the frame): the absolute smoothness term (the
    command's total variation per step) removes the jitter and keeps the step's height; the
    squared term removes as little jitter only at a weight that also shrinks the step."""
    from myoexo.studies.distill import DistillConfig, Episodes, train_student

    lengths = [200, 200]
    n = sum(lengths)
    t = np.concatenate([np.arange(k) for k in lengths]) / 200.0
    alternating = np.where(np.arange(n) % 2, 1.0, -1.0)
    frames = np.zeros((n, FRAME_DIM), np.float32)
    frames[:, 0] = t
    frames[:, 1] = np.where(t < 0.5, 1.0, -1.0)
    frames[:, 2] = alternating
    labels = (0.5 * frames[:, 1] + 0.05 * alternating).astype(np.float32)
    data = Episodes(frames, labels, np.array([0, lengths[0]]), np.zeros(n, np.int32))
    mid = lengths[0] // 2
    steady = np.ones(n - 1, bool)
    steady[[mid - 1, lengths[0] - 1, lengths[0] + mid - 1]] = False  # the steps, the seam
    jitter, height = {}, {}
    for norm, weight in (("squared", 0.0), ("absolute", 0.2), ("squared", 5.0)):
        config = DistillConfig(
            n_frames=1, hidden=(32,), batch_size=64, lr=3e-3, smoothness_weight=weight,
            smoothness_norm=norm,
        )  # fmt: skip
        student, _ = train_student(config, data, 60, None, seed=0, log=lambda _: None)
        command = np.array([student.actor.act(f.astype(np.float64))[0] for f in frames])
        jitter[norm, weight] = float(np.mean(np.abs(np.diff(command))[steady]))
        height[norm, weight] = float(command[mid - 1] - command[mid])
    assert jitter["squared", 0.0] > 0.05, jitter  # imitation alone follows the jitter
    assert jitter["absolute", 0.2] < 0.1 * jitter["squared", 0.0], jitter
    assert height["absolute", 0.2] > 0.9, height
    assert jitter["squared", 5.0] > jitter["absolute", 0.2] and height["squared", 5.0] < 0.8, (
        jitter,
        height,
    )


def test_an_output_reach_above_one_lets_the_student_hold_the_motors_limit(tmp_path, env_exo):
    """With a tanh head the command approaches the teacher's saturated label and never
    reaches it; a head spanning [-1.1, 1.1] (clipped to the motor's range) commands the limit
    exactly where the label does and keeps the labels inside the range."""
    from myoexo.studies.distill import DistillConfig, Episodes, train_student

    rng = np.random.default_rng(1)
    n = 600
    frames = rng.normal(size=(n, FRAME_DIM)).astype(np.float32)
    labels = np.clip(1.6 * frames[:, 0], -1.0, 1.0).astype(np.float32)  # saturates often
    data = Episodes(frames, labels, np.array([0]), np.zeros(n, np.int32))
    saturated = np.abs(labels) >= 1.0
    inside = ~saturated
    reached, errors = {}, {}
    for reach in (1.0, 1.1):
        config = DistillConfig(n_frames=1, hidden=(32,), batch_size=64, lr=3e-3, output_reach=reach)
        student, _ = train_student(config, data, 60, None, seed=0, log=lambda _: None)
        assert student.actor.action_high[0] == pytest.approx(reach)
        command = np.array(
            [np.clip(student.actor.act(f.astype(np.float64))[0], -1.0, 1.0) for f in frames]
        )
        reached[reach] = float(np.mean(np.abs(command[saturated]) == 1.0))
        errors[reach] = float(np.mean(np.abs(command[inside] - labels[inside])))
    assert reached[1.0] == 0.0 and reached[1.1] > 0.5, reached
    assert errors[1.1] < 0.1, errors
    # the stored student and its ONNX file keep the reach and the clip
    save_student(student, tmp_path / "s")
    loaded = load_student(tmp_path / "s")
    assert loaded.actor.action_high[0] == pytest.approx(1.1)
    student.bind_obs_keys(EXO_PRESET_KEYS)
    episodes = [_episode_obs(env_exo, seed=s, steps=10) for s in (0, 1)]
    assert _onnx_parity(student, episodes, tmp_path / "s.onnx") <= 1e-5
    with pytest.raises(ValueError, match="output_reach"):
        DistillConfig(output_reach=0.9)


def test_a_label_at_the_limit_pulls_the_command_to_the_margin_beyond_it():
    """A label at the motor's limit costs nothing at or beyond ``limit + margin`` and pulls a
    command short of it by the distance left; a label inside the range is met exactly."""
    import torch

    from myoexo.runtime.fields import FieldError
    from myoexo.studies.distill import DistillConfig, imitation_error

    target = torch.tensor([-1.0, -1.0, -1.0, 1.0, 1.0, 0.3, 0.3])
    pred = torch.tensor([-1.0, -1.05, -1.2, 1.12, 0.9, 0.4, 0.2])
    np.testing.assert_allclose(
        imitation_error(pred, target).numpy(), [0, 0, 0, 0, -0.1, 0.1, -0.1], atol=1e-6
    )
    np.testing.assert_allclose(
        imitation_error(pred, target, 0.1).numpy(),
        [0.1, 0.05, 0, 0, -0.2, 0.1, -0.1],
        atol=1e-6,
    )
    with pytest.raises(FieldError, match=r"limit_margin = 0.2 must be below output_reach - 1"):
        DistillConfig(output_reach=1.1, limit_margin=0.2)


def test_frame_indices_refuses_unknown_layouts():
    with pytest.raises(ValueError, match="lacks"):
        frame_indices(["exo_angle_rad", "time_frac"])
    with pytest.raises(ValueError, match="unknown size"):
        frame_indices(["coupling_qpos", *FRAME_KEYS])


def test_training_stacks_equal_the_controller_memory():
    """Episodes.stack_index builds exactly the input the controller's memory gives."""
    from myoexo.studies.distill import Episodes

    rng = np.random.default_rng(0)
    lengths = [7, 12]
    frames = rng.normal(size=(sum(lengths), FRAME_DIM)).astype(np.float32)
    data = Episodes(
        frames, np.zeros(len(frames), np.float32), np.array([0, 7]), np.zeros(19, np.int32)
    )
    student = _random_student(n_frames=3, stride=2)
    index = data.stack_index(3, 2)
    row = 0
    for n in lengths:
        student.reset()
        for _ in range(n):
            x = student.push(frames[row].astype(np.float64))
            np.testing.assert_array_equal(x, frames[index[row]].reshape(-1).astype(np.float64))
            row += 1
    mem = np.arange(5 * 2).reshape(5, 2)
    np.testing.assert_array_equal(stack_frames(mem, 3, 2), [8, 9, 4, 5, 0, 1])


@pytest.mark.parametrize(("n_frames", "stride"), [(1, 1), (3, 2)])
def test_an_input_push_returned_is_not_changed_by_later_pushes(n_frames, stride):
    """The memory shifts in place: what push returned before stays as it was."""
    student = _random_student(n_frames=n_frames, stride=stride)
    frames = np.random.default_rng(1).normal(size=(6, FRAME_DIM))
    inputs = [student.push(f) for f in frames]
    kept = [x.copy() for x in inputs]
    student.push(frames[0] + 1.0)
    for x, y in zip(inputs, kept, strict=True):
        np.testing.assert_array_equal(x, y)
    np.testing.assert_array_equal(inputs[-1][:FRAME_DIM], frames[-1])  # the newest frame first


def test_save_load_roundtrip(tmp_path, env_exo):
    student = _random_student()
    student.metadata["note"] = "x"
    save_student(student, tmp_path / "s")
    loaded = load_student(tmp_path / "s")
    assert loaded.n_frames == student.n_frames and loaded.stride == student.stride
    assert loaded.metadata["note"] == "x"
    doc = json.loads((tmp_path / "s.json").read_text())
    assert doc["student"]["frame_keys"] == list(FRAME_KEYS)
    assert doc["obs_preset"] == "exo"
    for o in _episode_obs(env_exo, seed=2, steps=5):
        np.testing.assert_allclose(loaded.act(o), student.act(o), atol=1e-5)


def _onnx_parity(student: StudentController, episodes: list[list[np.ndarray]], path) -> float:
    ort = pytest.importorskip("onnxruntime")
    export_student_onnx(student, path)
    sess = ort.InferenceSession(str(path), providers=["CPUExecutionProvider"])
    worst = 0.0
    for obs_seq in episodes:
        student.reset()
        memory = None
        for obs in obs_seq:
            frame = student.frame(obs).astype(np.float32)
            if memory is None:
                memory = student.initial_memory(frame)[None]
            action, memory = sess.run(None, {"frame": frame[None], "memory": memory})
            expected = student.act(obs)
            worst = max(worst, float(np.max(np.abs(action[0] - expected))))
    return worst


def test_onnx_parity(tmp_path, env_exo):
    student = _random_student(n_frames=4, stride=2)
    episodes = [_episode_obs(env_exo, seed=s, steps=25) for s in (0, 1)]
    assert _onnx_parity(student, episodes, tmp_path / "s.onnx") <= 1e-5


def test_tiny_dagger_run_and_resume(tmp_path):
    from myoexo.envs.options import TwinOptions
    from myoexo.studies.distill import DistillConfig, Episodes, distill

    cfg = DistillConfig(
        rounds=1,
        episodes_per_round=2,
        levels=(0, 2),
        robust_fraction=0.5,
        n_frames=3,
        stride=1,
        hidden=(8,),
        epochs_first=1,
        epochs=1,
        selection_subjects=1,
        twin=TwinOptions().replace(episode_duration_s=0.2),
    )
    run = tmp_path / "run"
    hist = distill(cfg, run, log=lambda m: None)
    assert [h["round"] for h in hist["rounds"]] == [0]
    assert hist["rounds"][0]["beta"] == 1.0
    n0 = Episodes.load(run / "dataset.npz").size
    assert n0 == 2 * 20
    with pytest.raises(ValueError, match="resume"):
        distill(cfg, run, log=lambda m: None)
    hist = distill(cfg, run, resume=True, rounds=2, log=lambda m: None)
    assert [h["round"] for h in hist["rounds"]] == [0, 1]
    assert hist["rounds"][1]["beta"] == 0.5
    assert Episodes.load(run / "dataset.npz").size == 2 * n0
    student = load_student(run / "student")
    assert student.n_frames == 3
    meta = json.loads((run / "student_round_01.json").read_text())
    assert meta["selection_root_seed"] == 1 and meta["teacher"] == "sac"
    # nothing to do: a resume with every round done changes nothing
    again = distill(cfg, run, resume=True, log=lambda m: None)
    assert len(again["rounds"]) == 2
    # a kill after round 1's data was saved but before its student: the resume drops that
    # round's samples and runs the round again
    labels = Episodes.load(run / "dataset.npz").labels.copy()
    for suffix in (".npz", ".json"):
        (run / f"student_round_01{suffix}").unlink()
    again = distill(cfg, run, resume=True, log=lambda m: None)
    assert [h["round"] for h in again["rounds"]] == [0, 1]
    redone = Episodes.load(run / "dataset.npz")
    assert redone.size == 2 * n0 and list(redone.starts) == [0, 20, 40, 60]
    np.testing.assert_array_equal(redone.labels[:n0], labels[:n0])


def test_distill_refuses_the_evaluation_root():
    from myoexo.studies.distill import DistillConfig

    with pytest.raises(ValueError, match="evaluation root"):
        DistillConfig(root_seed=0)


def test_every_distill_setting_is_an_option_of_its_own_name(tmp_path, capsys):
    import argparse

    from myoexo.cli import main
    from myoexo.envs.options import TwinOptions, twin_from_args
    from myoexo.runtime.fields import FieldError, flag_of, from_options, option_fields
    from myoexo.studies import distill as D

    parser = argparse.ArgumentParser()
    D.add_arguments(parser)
    flags = {s for a in parser._actions for s in a.option_strings}
    assert {flag_of(f) for f in option_fields(D.DistillConfig)} <= flags
    args = parser.parse_args(
        [
            "--episodes-per-round", "4", "--fine-width-rad", "0.01", "--hidden", "32", "32",
            "--action-noise-std", "0.1", "--teacher-guard", "--lr", "1e-4",
            "--episode-duration-s", "0.5",
        ]
    )  # fmt: skip
    config = from_options(D.DistillConfig, args, twin=twin_from_args(args))
    assert config == D.DistillConfig(
        episodes_per_round=4,
        fine_width_rad=0.01,
        hidden=(32, 32),
        action_noise_std=0.1,
        teacher_guard=True,
        lr=1e-4,
        twin=TwinOptions().replace(episode_duration_s=0.5),
    )
    assert from_options(D.DistillConfig, parser.parse_args([])) == D.DistillConfig()
    with pytest.raises(FieldError, match="robust_fraction"):
        D.DistillConfig(robust_fraction=1.5)
    with pytest.raises(FieldError, match="subject_offset"):
        D.DistillConfig(subject_offset=2, selection_subjects=8)
    # a resume keeps the run's settings: only --rounds may be given
    assert main(["policy", "distill", "--resume", str(tmp_path), "--lr", "1e-4"]) == 2
    assert "drop --lr" in capsys.readouterr().err
    assert main(["policy", "distill", "--run-dir", str(tmp_path), "--n-frames", "0"]) == 2
    assert "--n-frames = 0 must be >= 1" in capsys.readouterr().err


def test_teacher_labels_from_the_true_state():
    """On a perturbed twin the teacher's input is the exact state, not the sensed one."""
    from myoexo.envs import make_env
    from myoexo.studies.distill import true_full_observation

    env = make_env(0, robustness=True, episode_duration_s=0.2)
    nominal = make_env(0, episode_duration_s=0.2)
    try:
        obs, info = env.reset(seed=4)
        for _ in range(3):
            obs, *_, info = env.step(np.array([0.1], np.float32))
        truth = true_full_observation(env, info)
        assert not np.allclose(truth, obs)  # the sensed obs is noisy and late
        obs_n, info_n = nominal.reset(seed=4)
        np.testing.assert_allclose(true_full_observation(nominal, info_n), obs_n, atol=1e-6)
        for _ in range(3):
            obs_n, *_, info_n = nominal.step(np.array([0.1], np.float32))
        np.testing.assert_allclose(true_full_observation(nominal, info_n), obs_n, atol=1e-6)
    finally:
        env.close()
        nominal.close()


def test_shipped_student_loads_and_acts(env_exo, tmp_path):
    import myoexo
    from myoexo.policies.student import StudentController

    student = myoexo.load_policy("student_exo")
    assert isinstance(student, StudentController)
    assert student.obs_preset == "exo"
    assert student.metadata.get("teacher") == "sac"
    # its provenance names its teacher's seeds; a student distilled from another seed set
    # than the shipped teacher's says so in its model card
    teacher = myoexo.load_policy("sac").metadata
    provenance = student.metadata["teacher_provenance"]
    assert provenance["training_seeds"] and "ship_seed" in provenance
    if (provenance["training_seeds"], provenance["ship_seed"]) != (
        teacher["training_seeds"],
        teacher["ship_seed"],
    ):
        card = Path(myoexo.__file__).parent / "policies" / "MODEL_CARD_student_exo.md"
        assert "has not been re-distilled" in " ".join(card.read_text().split())
    assert int(student.metadata.get("selection_root_seed")) == 1
    # one of at least three distillation seeds, chosen by the seed rule
    from myoexo.studies.distill import SHIP_RULE

    assert len(student.metadata["distill_seeds"]) >= 3
    assert student.metadata["ship_seed"] in student.metadata["distill_seeds"]
    assert student.metadata["ship_rule"] == SHIP_RULE
    for o in _episode_obs(env_exo, seed=0, steps=10):
        a = student.act(o)
        assert a.shape == (1,) and np.isfinite(a).all() and -1 <= a[0] <= 1
    # the shipped controller exported whole (memory included) matches numpy on an episode
    episodes = [_episode_obs(env_exo, seed=s, steps=40) for s in (3, 4)]
    assert _onnx_parity(student, episodes, tmp_path / "student.onnx") <= 1e-5


def test_wrong_layout_is_refused(env_full):
    """An exo-layout student given a full-preset observation says so instead of acting."""
    obs, _ = env_full.reset(seed=0)
    with pytest.raises(ValueError, match="obs_preset"):
        _random_student().act(obs)


def test_expert_fine_term_acts_only_near_the_target():
    import myoexo
    from myoexo.studies.distill import Expert

    teacher = myoexo.load_policy("sac")
    rng = np.random.default_rng(0)
    x = rng.normal(0, 0.3, (3, teacher.obs_dim))
    plain, fine = Expert(teacher), Expert(teacher, fine_gain=20.0, fine_width_rad=0.02)
    for xi in x:
        np.testing.assert_array_equal(plain(xi), np.clip(teacher(xi), -1, 1))
        xi[5] = 0.5  # 29 deg from the target: the term vanishes
        np.testing.assert_allclose(fine(xi), plain(xi), atol=1e-6)
        xi[5] = 0.01  # knee 0.6 deg too flexed: push towards extension (negative)
        assert fine(xi)[0] < plain(xi)[0] or plain(xi)[0] == -1.0


def test_evaluation_engine_runs_the_student():
    """evaluate_controller builds the exo-preset env from the controller's obs_preset."""
    from myoexo.evaluation.engine import evaluate_controller

    table, results = evaluate_controller(
        _random_student(), level=0, subjects=1, root_seed=1, episode_duration_s=0.3
    )
    assert len(table) == 1 and results[0].n_steps == 30
    assert np.isfinite(table["abs_final_error_deg"]).all()


def test_a_distillation_folder_in_use_is_refused(tmp_path, lock_holder):
    """Like every run folder, a distillation's is locked: a second writer stops at once,
    naming the holder, and writes nothing."""
    from myoexo.runtime.lifecycle import LOCK_FILE, FolderInUseError
    from myoexo.studies.distill import DistillConfig, distill

    folder = tmp_path / "busy"
    folder.mkdir()
    with lock_holder(folder) as holder:
        with pytest.raises(FolderInUseError, match=f"in use by pid {holder.pid}"):
            distill(DistillConfig(rounds=1), folder, log=lambda m: None)
        assert sorted(p.name for p in folder.iterdir()) == [LOCK_FILE]


def test_expert_with_the_stall_guard_pushes_only_after_a_stall():
    """With teacher_guard the labels are guard:sac's on the true knee error: unchanged for
    the first 2 s and near the target; past 17 deg after 2 s the label is pushed towards
    the target, more at each step, and a reset disengages it."""
    import myoexo
    from myoexo.control.guard import StallGuardConfig
    from myoexo.studies.distill import Expert

    teacher = myoexo.load_policy("sac")
    plain, guarded = Expert(teacher), Expert(teacher, guard=StallGuardConfig())
    x = np.random.default_rng(1).normal(0, 0.3, teacher.obs_dim)
    x[5] = np.radians(40.0)  # knee 40 deg too flexed: the guard's integral extends (negative)
    guarded.reset(0)
    steps = round(2.0 / 0.01)
    for _ in range(steps):
        np.testing.assert_array_equal(guarded(x), plain(x))
    labels = [float(guarded(x)[0]) for _ in range(5)]
    base = float(plain(x)[0])
    assert all(b < a for a, b in zip([base, *labels], labels, strict=False)) or base == -1.0
    guarded.reset(0)
    np.testing.assert_array_equal(guarded(x), plain(x))
    x[5] = np.radians(5.0)  # near the target: never engages
    for _ in range(steps + 10):
        np.testing.assert_array_equal(guarded(x), plain(x))


def test_ship_students_picks_a_typical_seed_and_groups_the_copies(tmp_path):
    """Three tiny seeds: the shipped student is the closest_seed of their selection errors,
    carries the seeds and the rule, and the seed copies are one controller for evaluate."""
    import pandas as pd

    from myoexo.control.specs import parse_controller_spec
    from myoexo.envs.options import TwinOptions
    from myoexo.studies.distill import SHIP_RULE, DistillConfig, distill, ship_students
    from myoexo.training.seeds import closest_seed

    runs = []
    for seed in (0, 1, 2):
        cfg = DistillConfig(
            rounds=1, episodes_per_round=2, levels=(0, 2), n_frames=2, stride=1, hidden=(4,),
            epochs_first=1, selection_subjects=1, seed=seed,
            twin=TwinOptions().replace(episode_duration_s=0.1),
        )  # fmt: skip
        distill(cfg, tmp_path / f"s{seed}", log=lambda m: None)
        runs.append(tmp_path / f"s{seed}")
    with pytest.raises(ValueError, match=">= 2"):
        ship_students(runs[:1], log=lambda m: None)
    with pytest.raises(ValueError, match="two runs of distillation seed 0"):
        ship_students([runs[0], runs[0]], log=lambda m: None)
    chosen = ship_students(
        runs, stem=tmp_path / "shipped", seed_copies=tmp_path / "copies", log=lambda m: None
    )
    rows = [
        {"seed": s, "level": k, "e": v}
        for s, run in enumerate(runs)
        for k, v in load_student(run / "student").metadata["selection_scores"].items()
        if k != "score"
    ]
    expected = closest_seed(pd.DataFrame(rows), metrics=("e",))
    shipped = load_student(tmp_path / "shipped")
    assert shipped.metadata["ship_seed"] == chosen.metadata["ship_seed"] == expected
    assert shipped.metadata["distill_seeds"] == [0, 1, 2]
    assert shipped.metadata["ship_rule"] == SHIP_RULE
    assert "seed_group" not in shipped.metadata  # the copies are a group, the shipped one not
    copies = sorted((tmp_path / "copies").glob("*.npz"))
    assert [p.stem for p in copies] == [f"student_3seeds-seed_{s}-round_00" for s in (0, 1, 2)]
    assert {parse_controller_spec(str(p)).seed_group for p in copies} == {"student_3seeds"}


def test_ship_students_takes_the_default_weight_of_a_gentleness_record(tmp_path):
    """`--ship --gentleness-record DIR`: every student written (the shipped one and the seed
    copies) runs at the record's default weight, not its teacher's; students without a
    gentleness input refuse a record."""
    import json

    from myoexo.control.specs import parse_controller_spec, spec_gentleness
    from myoexo.envs.options import TwinOptions
    from myoexo.studies.distill import DistillConfig, distill, ship_students

    def tiny(seed: int, gentle: bool) -> Path:
        cfg = DistillConfig(
            rounds=1, episodes_per_round=2, levels=(0,), n_frames=2, stride=1, hidden=(4,),
            epochs_first=1, selection_subjects=1, seed=seed, teacher="residual",
            gentleness_input=gentle, twin=TwinOptions().replace(episode_duration_s=0.1),
        )  # fmt: skip
        run = tmp_path / f"{'g' if gentle else 'p'}{seed}"
        distill(cfg, run, log=lambda m: None)
        return run

    record = tmp_path / "record"
    record.mkdir()
    (record / "gentleness.json").write_text(json.dumps({"default_gentleness": 0.5, "root_seed": 1}))
    gentle = [tiny(s, True) for s in (0, 1)]
    teacher_default = load_student(gentle[0] / "student").metadata["default_gentleness"]
    assert teacher_default != 0.5
    chosen = ship_students(
        gentle, stem=tmp_path / "shipped", seed_copies=tmp_path / "copies",
        log=lambda m: None, gentleness_record=record,
    )  # fmt: skip
    assert chosen.metadata["default_gentleness"] == 0.5
    assert load_student(tmp_path / "shipped").metadata["gentleness_record"]["root_seed"] == 1
    for copy in sorted((tmp_path / "copies").glob("*.npz")):
        assert spec_gentleness(parse_controller_spec(str(copy))) == 0.5
    with pytest.raises(ValueError, match="no gentleness record"):
        ship_students(gentle, log=lambda m: None, gentleness_record=tmp_path)
    plain = [tiny(s, False) for s in (0, 1)]
    with pytest.raises(ValueError, match="not trained with a gentleness weight"):
        ship_students(plain, log=lambda m: None, gentleness_record=record)


def test_a_residual_teacher_labels_what_it_commands_on_its_base():
    """`--teacher residual`: the expert runs the shipped residual policy on its base (the
    minimum-jerk PID, reading its sensors from the step's info) at its default weight, so its
    labels along an episode it drives are the commands `myoexo.load_policy("residual", env)`
    gives on the same episode."""
    import myoexo
    from myoexo.control.rollout import rollout
    from myoexo.envs import make_env
    from myoexo.studies.distill import Expert, collect_episode, load_teacher, teacher_controller

    env = make_env(1, episode_duration_s=0.5)
    try:
        actor = load_teacher("residual")
        assert teacher_controller("sac", load_teacher("sac"), env) is None  # a plain actor
        expert = Expert(actor, controller=teacher_controller("residual", actor, env))
        rng = np.random.default_rng(0)
        _, labels, _ = collect_episode(env, expert, None, 7, 1.0, rng)
        commands = rollout(env, myoexo.load_policy("residual", env), seed=7).signals["command"]
    finally:
        env.close()
    assert labels.size == 50
    applied = np.asarray(commands, np.float32)[1:]  # the signals start with the reset's record
    np.testing.assert_allclose(labels, applied[: labels.size], atol=1e-6)
    with pytest.raises(ValueError, match="needs the step's info"):
        expert(np.zeros(actor.obs_dim - 1))


def _weighted_student(n_frames: int = 4, stride: int = 2, seed: int = 0) -> StudentController:
    """A random student that takes the gentleness weight as its last input."""
    rng = np.random.default_rng(seed)
    dims = [n_frames * FRAME_DIM + 1, 16, 16, 1]
    weights = [
        (rng.normal(0, 1 / math.sqrt(i), (o, i)), rng.normal(0, 0.1, o))
        for i, o in itertools.pairwise(dims)
    ]
    weights[0][0][:, -1] = 3.0  # the weight moves the command
    actor = MLPActor(
        weights, activation="elu", obs_mean=np.zeros(dims[0]), obs_var=np.ones(dims[0])
    )
    return StudentController(actor, n_frames=n_frames, stride=stride, gentleness_input=True)


def test_a_student_reads_its_gentleness_weight_last_and_keeps_it_through_its_files(
    tmp_path, env_exo
):
    student = _weighted_student()
    obs = _episode_obs(env_exo, seed=0, steps=3)
    actions = {}
    for w in (0.0, 1.0):
        student.reset()
        actions[w] = [float(student.act(np.append(o, w))[0]) for o in obs]
    assert actions[0.0] != actions[1.0]
    with pytest.raises(ValueError, match="observation of size 18"):
        student.act(obs[0])  # the weight is missing
    save_student(student, tmp_path / "w")
    assert json.loads((tmp_path / "w.json").read_text())["student"]["gentleness_input"] is True
    loaded = load_student(tmp_path / "w")
    assert loaded.gentleness_input
    loaded.reset()
    assert [float(loaded.act(np.append(o, 1.0))[0]) for o in obs] == pytest.approx(
        actions[1.0], abs=1e-5
    )


def test_onnx_parity_with_the_gentleness_weight_as_an_input(tmp_path, env_exo):
    ort = pytest.importorskip("onnxruntime")
    student = _weighted_student()
    export_student_onnx(student, tmp_path / "w.onnx")
    sess = ort.InferenceSession(str(tmp_path / "w.onnx"), providers=["CPUExecutionProvider"])
    assert [i.name for i in sess.get_inputs()] == ["frame", "memory", "gentleness"]
    worst = 0.0
    for w in (0.0, 0.4, 1.0):
        student.reset()
        memory = None
        for obs in _episode_obs(env_exo, seed=1, steps=12):
            frame = student.frame(np.append(obs, w)).astype(np.float32)
            if memory is None:
                memory = student.initial_memory(frame)[None]
            weight = np.array([[w]], np.float32)
            action, memory = sess.run(
                None, {"frame": frame[None], "memory": memory, "gentleness": weight}
            )
            worst = max(worst, float(np.max(np.abs(action[0] - student.act(np.append(obs, w))))))
    assert worst <= 1e-5


def test_a_tiny_distillation_from_the_residual_teacher_with_a_weight_input(tmp_path):
    """`--teacher residual --gentleness-input`: each episode's weight is drawn and stored
    with its steps; the student records the teacher's default weight and runs, as any
    gentleness-trained policy, behind a GentleController (`STUDENT.npz@W`)."""
    from myoexo.control.policy import GentleController
    from myoexo.control.specs import build_controller, parse_controller_spec
    from myoexo.envs import make_env
    from myoexo.envs.options import TwinOptions
    from myoexo.studies.distill import DistillConfig, Episodes, distill, load_teacher

    short = TwinOptions().replace(episode_duration_s=0.2)
    tiny = dict(rounds=2, episodes_per_round=3, levels=(1,), n_frames=3, stride=1, hidden=(8,))
    tiny.update(epochs_first=1, epochs=1, selection_subjects=1, twin=short)
    with pytest.raises(ValueError, match="not trained over the gentleness range"):
        distill(DistillConfig(gentleness_input=True, **tiny), tmp_path / "sac", log=print)
    cfg = DistillConfig(teacher="residual", gentleness_input=True, **tiny)
    distill(cfg, tmp_path / "run", log=lambda m: None)
    data = Episodes.load(tmp_path / "run" / "dataset.npz")
    per_episode = data.weights[data.starts]
    assert len(set(per_episode.tolist())) == per_episode.size  # one draw per episode
    assert np.all((per_episode >= 0.0) & (per_episode <= 1.0))
    student = load_student(tmp_path / "run" / "student")
    teacher_weight = load_teacher("residual").metadata["default_gentleness"]
    assert student.gentleness_input
    assert student.metadata["default_gentleness"] == teacher_weight
    env = make_env(1, obs_preset="exo")
    try:
        at_default = build_controller(
            parse_controller_spec(str(tmp_path / "run" / "student.npz")), env
        )
        at_half = build_controller(
            parse_controller_spec(str(tmp_path / "run" / "student.npz") + "@0.5"), env
        )
    finally:
        env.close()
    assert isinstance(at_default, GentleController)
    assert at_default.gentleness == teacher_weight
    assert isinstance(at_half, GentleController) and at_half.gentleness == 0.5


def test_the_shipped_fine_student_takes_its_weight_and_reaches_the_target_smoothly():
    """`student_fine`: distilled from `residual` on today's twin with the smoothness and
    fine-positioning terms (five seeds, its round chosen over the weight range, one seed
    shipped by the seed rule, its default weight from a gentleness record of the selection
    root); built on an env it runs at that weight, and a full 8-s level-1 episode ends within
    1 deg (its goal) with a command whose total variation is below the paper's PID's on the
    same subject."""
    import myoexo
    from myoexo.control import PID
    from myoexo.control.policy import GentleController
    from myoexo.control.rollout import Rollout, rollout
    from myoexo.envs import make_env
    from myoexo.envs.options import TwinOptions
    from myoexo.model import TWIN_VERSION

    stored = myoexo.load_policy("student_fine")
    meta = stored.metadata
    assert stored.gentleness_input and meta["teacher"] == "residual"
    assert meta["ship_seed"] in meta["distill_seeds"] and len(meta["distill_seeds"]) == 5
    assert meta["twin_version"] == TWIN_VERSION and meta["selection_root_seed"] == 1
    assert meta["twin"]["reflex"] == TwinOptions().reflex
    config = meta["distill_config"]
    assert config["smoothness_weight"] == 10.0 and config["fine_gain"] == 10.0
    assert len(config["selection_weights"]) > 1
    record = meta["gentleness_record"]
    assert record["root_seed"] == 1 and meta["default_gentleness"] == record["default_gentleness"]
    for retired in ("student_residual", "student_smooth"):
        with pytest.raises(FileNotFoundError, match="student_fine"):
            myoexo.load_policy(retired)
    env = make_env(1, obs_preset="exo")
    try:
        controller = myoexo.load_policy("student_fine", env)
        assert isinstance(controller, GentleController)
        assert controller.gentleness == meta["default_gentleness"]
        with pytest.raises(ValueError, match="gentleness weight last"):
            obs, _ = env.reset(seed=0)
            stored.reset()
            stored.act(obs)
        episode = rollout(env, controller, seed=5)
        pid = rollout(env, PID.from_env(env), seed=5)
    finally:
        env.close()
    assert not episode.unstable
    assert abs(episode.signals["error_deg"][-1]) < 1.0

    def total_variation(run: Rollout) -> float:
        return float(np.abs(np.diff(run.signals["command"])).sum())

    assert total_variation(episode) < total_variation(pid)


def test_reselect_scores_every_round_again_over_the_weight_range(tmp_path):
    """`--reselect DIR --selection-weights W...`: without retraining, every round of a
    finished weight-input run is scored again as the mean of its scores at each weight; the
    best of those rounds becomes the run's student, the earlier scores and settings stay in
    the history, and only the selection settings may change."""
    import dataclasses

    from myoexo.envs.options import TwinOptions
    from myoexo.runtime.fields import FieldError
    from myoexo.studies.distill import (
        DistillConfig,
        EnvPool,
        distill,
        load_teacher,
        main,
        reselect,
        selection_scores,
        teacher_controller,
    )

    short = TwinOptions().replace(episode_duration_s=0.3)
    cfg = DistillConfig(
        rounds=2, episodes_per_round=2, levels=(1,), n_frames=2, stride=1, hidden=(4,),
        epochs_first=1, epochs=1, selection_subjects=1, teacher="residual",
        gentleness_input=True, twin=short,
    )  # fmt: skip
    with pytest.raises(FieldError, match="selection_weights"):
        dataclasses.replace(cfg, gentleness_input=False, selection_weights=(0.0,))
    run = tmp_path / "run"
    first = distill(cfg, run, log=lambda m: None)
    before = [h["selection"] for h in first["rounds"]]
    with pytest.raises(ValueError, match="only"):
        reselect(run, log=lambda m: None, seed=3)
    with pytest.raises(ValueError, match="drop --seed"):
        main(["--reselect", str(run), "--seed", "3"])
    hist = reselect(run, log=lambda m: None, selection_weights=(0.0, 1.0))
    assert [h["selection_before"] for h in hist["rounds"]] == before
    assert list(hist["reselected"]["from"]["selection_weights"]) == []
    saved = json.loads((run / "config.json").read_text())["config"]
    assert saved["selection_weights"] == [0.0, 1.0]
    envs = EnvPool(short)
    try:
        teacher = teacher_controller("residual", load_teacher("residual"), envs.get(1, False))
        for h in hist["rounds"]:
            student = load_student(run / f"student_round_{h['round']:02d}")
            per_weight = [
                selection_scores(
                    student, dataclasses.replace(cfg, selection_weights=(w,)), envs, None
                )
                for w in (0.0, 1.0)
            ]
            for key in ("L1", "L1p"):
                assert h["selection"][key] == pytest.approx(
                    (per_weight[0][key] + per_weight[1][key]) / 2
                )
            assert student.metadata["selection_scores"] == h["selection"]
        # none given: the teacher's default weight, as before
        default = selection_scores(student, cfg, envs, teacher.gentleness)
        assert default == pytest.approx(hist["rounds"][-1]["selection_before"])
    finally:
        envs.close()
    best = min(hist["rounds"], key=lambda h: h["selection"]["score"])["round"]
    assert hist["best_round"] == best
    chosen = load_student(run / "student")
    assert chosen.metadata["round"] == best
    assert chosen.metadata["distill_config"]["selection_weights"] == [0.0, 1.0]


def test_an_exported_actor_teaches_by_the_path_of_its_npz(tmp_path, monkeypatch):
    """`--teacher STEM.npz` (relative or absolute, with or without `@W`): the exported actor
    itself, on its base at its weight, as the shipped one of the same files would teach."""
    import shutil

    from myoexo.envs import make_env
    from myoexo.policies import shipped_path
    from myoexo.studies.distill import load_teacher, teacher_controller

    stem = shipped_path("residual")
    for suffix in (".npz", ".json"):
        shutil.copy(stem.with_suffix(suffix), tmp_path / f"teacher{suffix}")
    monkeypatch.chdir(tmp_path)
    shipped = load_teacher("residual")
    for name in ("teacher.npz", str(tmp_path / "teacher.npz"), "teacher.npz@0.5"):
        actor = load_teacher(name)
        assert actor.metadata == shipped.metadata
        obs = np.zeros(actor.obs_dim)
        np.testing.assert_array_equal(actor(obs), shipped(obs))
    env = make_env(1, episode_duration_s=0.5)
    try:
        assert teacher_controller("teacher.npz@0.5", load_teacher("teacher.npz"), env) is not None
    finally:
        env.close()
    with pytest.raises(FileNotFoundError):
        load_teacher("missing.npz")
