"""A student's fine-positioning layer (myoexo.policies.student.FinePositioner) and the command
that fits it (myoexo.studies.knee_estimator)."""

from __future__ import annotations

import itertools
import json
import math

import numpy as np
import pytest
from test_distill import _episode_obs  # the same fixed command sequence

from myoexo.envs.observation import OBS_SCALES
from myoexo.policies.actor import MLPActor
from myoexo.policies.student import (
    EXO_ANGLE_INDEX,
    EXO_VEL_INDEX,
    FRAME_DIM,
    KNEE_OFFSET_RANGE_DEG,
    TARGET_INDEX,
    FinePositioner,
    FinePositioning,
    StudentController,
    export_student_onnx,
    load_student,
    save_student,
)


def _mlp(in_dim: int, seed: int, reach: float = 1.0, last_scale: float = 1.0) -> MLPActor:
    rng = np.random.default_rng(seed)
    dims = [in_dim, 16, 1]
    weights = [
        (rng.normal(0, 1 / math.sqrt(i), (o, i)), rng.normal(0, 0.1, o))
        for i, o in itertools.pairwise(dims)
    ]
    weights[-1] = (weights[-1][0] * last_scale, weights[-1][1] * last_scale)
    return MLPActor(
        weights,
        activation="elu",
        obs_mean=np.zeros(in_dim),
        obs_var=np.ones(in_dim),
        action_low=-reach,
        action_high=reach,
    )


def _constant_estimator(offset_deg: float, in_dim: int = 4 * FRAME_DIM) -> MLPActor:
    """An estimator that returns *offset_deg* whatever it reads."""
    reach = KNEE_OFFSET_RANGE_DEG
    weights = [
        (np.zeros((4, in_dim)), np.zeros(4)),
        (np.zeros((1, 4)), np.array([math.atanh(offset_deg / reach)])),
    ]
    return MLPActor(weights, activation="elu", action_low=-reach, action_high=reach)


def _frame(exo_rad: float, target_rad: float, speed_deg_s: float = 0.0) -> np.ndarray:
    f = np.zeros(FRAME_DIM)
    f[EXO_ANGLE_INDEX], f[TARGET_INDEX] = exo_rad, target_rad
    f[EXO_VEL_INDEX] = math.radians(speed_deg_s) * OBS_SCALES["exo_vel_rad_s"]
    return f


@pytest.fixture(scope="module")
def env_exo():
    from myoexo.envs import make_env

    env = make_env(1, obs_preset="exo", episode_duration_s=0.5)
    yield env
    env.close()


def test_the_law_refuses_values_outside_their_range():
    with pytest.raises(ValueError, match=r"limit = 2.0 is outside \[0, 1\]"):
        FinePositioning(limit=2.0)
    with pytest.raises(ValueError, match="window_deg"):
        FinePositioning(window_deg=0.0)
    with pytest.raises(ValueError, match="gain_per_rad_s"):
        FinePositioning(gain_per_rad_s=-1.0)


def test_the_integral_runs_near_the_estimated_knee_and_stays_within_its_limit():
    law = FinePositioning(gain_per_rad_s=10.0, window_deg=1.5, limit=0.3, control_period_s=0.01)
    layer = FinePositioner(_constant_estimator(0.5), law)
    window = np.zeros(4 * FRAME_DIM)
    target = math.radians(60.0)
    # the encoder reads 0.9 deg short, the knee sits 0.5 deg beyond it: 0.4 deg to go
    exo = target - math.radians(0.9)
    assert layer.offset_deg(window) == pytest.approx(0.5, abs=1e-9)
    first = layer.step(window, _frame(exo, target))
    assert first == pytest.approx(10.0 * math.radians(0.4) * 0.01, rel=1e-9)
    # 3 deg from the estimated knee: outside the window, held
    assert layer.step(window, _frame(target - math.radians(3.5), target)) == first
    for _ in range(2000):
        value = layer.step(window, _frame(exo, target))
    assert value == pytest.approx(0.3)
    # past the target the integral runs back
    assert layer.step(window, _frame(target, target)) < 0.3
    layer.reset()
    assert layer.integral == 0.0


def test_the_integral_holds_while_the_encoder_turns_faster_than_the_speed_limit():
    """A knee that swings through the window (a limit cycle under latency) winds nothing up;
    without a speed limit (layers written before it) the integral runs at any speed."""
    target = math.radians(60.0)
    exo = target - math.radians(0.4)
    window = np.zeros(4 * FRAME_DIM)
    law = FinePositioning(speed_limit_deg_s=20.0)
    layer = FinePositioner(_constant_estimator(0.0), law)
    assert layer.step(window, _frame(exo, target, speed_deg_s=25.0)) == 0.0
    assert layer.step(window, _frame(exo, target, speed_deg_s=-25.0)) == 0.0
    assert layer.step(window, _frame(exo, target, speed_deg_s=15.0)) > 0.0
    anywhere = FinePositioner(_constant_estimator(0.0), FinePositioning(speed_limit_deg_s=None))
    assert anywhere.step(window, _frame(exo, target, speed_deg_s=500.0)) > 0.0
    with pytest.raises(ValueError, match="speed_limit_deg_s"):
        FinePositioning(speed_limit_deg_s=0.0)


def test_a_student_with_the_layer_keeps_it_through_its_files_and_its_onnx(tmp_path, env_exo):
    ort = pytest.importorskip("onnxruntime")
    n_frames, stride = 4, 2
    actor = _mlp(n_frames * FRAME_DIM, seed=0)
    estimator = _mlp(n_frames * FRAME_DIM, seed=1, reach=KNEE_OFFSET_RANGE_DEG, last_scale=0.05)
    # a wide window and a steep gain: the integral moves at every step of a short episode
    law = FinePositioning(gain_per_rad_s=40.0, window_deg=180.0, limit=0.5)
    raw = StudentController(actor, n_frames=n_frames, stride=stride)
    student = raw.with_fine(FinePositioner(estimator, law))
    episode = _episode_obs(env_exo, seed=3, steps=20)
    raw.reset()
    student.reset()
    plain = [float(raw.act(o)[0]) for o in episode]
    fine = [float(student.act(o)[0]) for o in episode]
    assert fine != pytest.approx(plain, abs=1e-3)
    assert fine[-1] == pytest.approx(np.clip(plain[-1] + student.fine.integral, -1, 1), abs=1e-6)
    twin = student.with_fine(student.fine)  # the same layer: its own integral
    twin.reset()
    assert twin.fine is not None and twin.fine.integral == 0.0 != student.fine.integral

    save_student(student, tmp_path / "s")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.json", "s.npz"]  # one controller
    with np.load(tmp_path / "s.npz") as arrays:
        assert {k for k in arrays.files if k.startswith("knee_layer")} == {
            "knee_layer0.weight", "knee_layer0.bias", "knee_layer1.weight", "knee_layer1.bias"
        }  # fmt: skip
    block = json.loads((tmp_path / "s.json").read_text())["student"]["fine_positioning"]
    assert block["law"] == law.__dict__
    assert block["estimator"]["action_high"] == [KNEE_OFFSET_RANGE_DEG]
    loaded = load_student(tmp_path / "s")
    assert loaded.fine is not None and loaded.fine.law == law
    loaded.reset()
    assert [float(loaded.act(o)[0]) for o in episode] == pytest.approx(fine, abs=1e-5)

    export_student_onnx(loaded, tmp_path / "s.onnx")
    sess = ort.InferenceSession(str(tmp_path / "s.onnx"), providers=["CPUExecutionProvider"])
    assert [i.name for i in sess.get_inputs()] == ["frame", "memory", "integral"]
    assert [o.name for o in sess.get_outputs()] == ["action", "memory_out", "integral_out"]
    memory, integral, worst = None, np.zeros((1, 1), np.float32), 0.0
    for obs, expected in zip(episode, fine, strict=True):
        frame = loaded.frame(obs).astype(np.float32)
        if memory is None:
            memory = loaded.initial_memory(frame)[None]
        action, memory, integral = sess.run(
            None, {"frame": frame[None], "memory": memory, "integral": integral}
        )
        worst = max(worst, abs(float(action[0, 0]) - expected))
    assert worst <= 1e-4


def test_a_layer_must_read_the_students_memory():
    actor = _mlp(4 * FRAME_DIM, seed=0)
    with pytest.raises(ValueError, match="knee estimator input"):
        StudentController(
            actor, n_frames=4, stride=2, fine=FinePositioner(_constant_estimator(0.0, 3))
        )


def test_the_fit_refuses_the_evaluation_root():
    from myoexo.studies.knee_estimator import KneeEstimatorSettings

    with pytest.raises(ValueError, match="evaluation"):
        KneeEstimatorSettings(root_seed=0)


def test_a_tiny_fit_labels_the_knee_offset_and_records_its_provenance(tmp_path):
    from myoexo.envs import make_env
    from myoexo.evaluation.config import subject_seed
    from myoexo.studies.knee_estimator import (
        KneeEstimatorSettings,
        collect,
        fit_knee_estimator,
    )

    raw = StudentController(_mlp(3 * FRAME_DIM, seed=2), n_frames=3, stride=1)
    settings = KneeEstimatorSettings(
        subjects=1, held_out=1, levels=(1,), perturbed=False, hidden=(8,), epochs=2
    )
    data, period_s = collect(raw, settings, log=lambda _: None)
    assert period_s == pytest.approx(0.01)
    assert data.held_out.sum() == data.held_out.size // 2  # one subject of two
    # the labels are the twin's knee minus the encoder, step by step, from the reset on
    env = make_env(1, obs_preset="exo")
    _, info = env.reset(seed=subject_seed(1, settings.subject_offset, settings.root_seed))
    env.close()
    assert data.offsets_deg[0] == pytest.approx(info["knee_angle_deg"] - info["exo_angle_deg"])
    assert np.ptp(data.offsets_deg) > 0.1  # the straps give as the motor pushes

    logged: list[str] = []
    student = fit_knee_estimator(raw, settings, FinePositioning(), "myoexo x", logged.append)
    assert student.actor is raw.actor and student.fine is not None
    meta = student.fine.estimator.metadata
    assert meta["command"] == "myoexo x" and meta["root_seed"] == 1
    assert meta["settings"]["subjects"] == 1 and "versions" in meta
    assert [r["level"] for r in meta["held_out_errors"]] == [1]
    assert any("held out, level 1 nominal" in line for line in logged)
    save_student(student, tmp_path / "fitted")
    again = load_student(tmp_path / "fitted")
    assert again.fine is not None
    assert again.fine.estimator.metadata["held_out_errors"] == meta["held_out_errors"]


def test_law_only_keeps_the_estimator_and_writes_the_law(tmp_path, capsys):
    """myoexo policy knee-estimator --law-only: the student's files get the new law, the
    estimator and the network stay, the command is recorded; a student without a layer is
    refused."""
    from myoexo.cli import main

    n_frames = 4
    estimator = _mlp(n_frames * FRAME_DIM, seed=1, reach=KNEE_OFFSET_RANGE_DEG)
    actor = _mlp(n_frames * FRAME_DIM, seed=0)
    old = FinePositioning(speed_limit_deg_s=None)
    save_student(
        StudentController(actor, n_frames=n_frames, stride=2, fine=FinePositioner(estimator, old)),
        tmp_path / "s",
    )
    save_student(StudentController(actor, n_frames=n_frames, stride=2), tmp_path / "plain")
    assert main(["policy", "knee-estimator", str(tmp_path / "s"), "--law-only",
                 "--speed-limit-deg-s", "10", "--gain-per-rad-s", "5"]) == 0  # fmt: skip
    again = load_student(tmp_path / "s")
    assert again.fine is not None
    assert again.fine.law == FinePositioning(gain_per_rad_s=5.0, speed_limit_deg_s=10.0)
    x = np.linspace(-1, 1, n_frames * FRAME_DIM)
    assert again.fine.offset_deg(x) == pytest.approx(float(estimator(x)[0]), abs=1e-5)
    assert again.actor(x) == pytest.approx(actor(x), abs=1e-5)
    assert again.fine.estimator.metadata["law_command"]  # the command line that ran
    assert main(["policy", "knee-estimator", str(tmp_path / "plain"), "--law-only"]) != 0
    assert "no fine-positioning layer" in capsys.readouterr().err


def test_the_shipped_knee_student_carries_its_layer_and_ends_at_the_target():
    """`student_knee`: `student_fine`'s recipe distilled again (five seeds) with a
    fine-positioning layer fitted on root 1; built on an env it runs at its default weight,
    and a full level-1 episode ends within 0.05 deg of the target, where the same network
    without its layer ends further off."""
    import myoexo
    from myoexo.control.policy import GentleController
    from myoexo.control.rollout import rollout
    from myoexo.envs import make_env

    stored = myoexo.load_policy("student_knee")
    assert stored.fine is not None and stored.gentleness_input
    meta = stored.fine.estimator.metadata
    assert meta["root_seed"] == 1 and meta["command"].startswith("myoexo policy knee-estimator")
    assert len(stored.metadata["distill_seeds"]) == 5
    env = make_env(1, obs_preset="exo")
    try:
        controller = myoexo.load_policy("student_knee", env)
        assert isinstance(controller, GentleController)
        with_layer = rollout(env, controller, seed=5)
        raw = GentleController(stored.with_fine(None), controller.gentleness)
        without = rollout(env, raw, seed=5)
    finally:
        env.close()
    end = abs(with_layer.signals["error_deg"][-1])
    assert not with_layer.unstable and end < 0.05
    assert end < abs(without.signals["error_deg"][-1])
