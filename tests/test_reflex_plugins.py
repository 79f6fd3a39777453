"""Reflex models as plug-ins (myoexo.spasticity.registry): the registry's API, the built-in
models' torch twins, and a model the user defines in a module of their own (the docs'
example, docs/examples/velocity_reflex.py) running everywhere a reflex name is taken:
gymnasium.make, SpasticityWrapper, the clinical tests, the evaluation and the CLI."""

from __future__ import annotations

import dataclasses
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import torch

from myoexo.spasticity import (
    ReflexModel,
    SpasticityStage,
    SpasticityWrapper,
    get_reflex,
    reflex_names,
    register_reflex,
    resolve_reflex,
    sample_subject,
)
from myoexo.spasticity.registry import _REGISTRY

EXAMPLES = Path(__file__).resolve().parents[1] / "docs" / "examples"


def _example(name: str):
    """A docs' example module, imported as a user's script would (it registers itself)."""
    import importlib

    sys.path.insert(0, str(EXAMPLES))
    try:
        yield importlib.import_module(name)
    finally:
        sys.path.remove(str(EXAMPLES))


@pytest.fixture(scope="module")
def velocity_reflex():
    yield from _example("velocity_reflex")


@pytest.fixture
def scratch_registry():
    """Names registered inside a test are removed after it."""
    before = dict(_REGISTRY)
    yield
    _REGISTRY.clear()
    _REGISTRY.update(before)


def test_the_registry_holds_the_builtins_and_takes_a_variant_under_a_new_name(scratch_registry):
    assert {"stretch", "uniform", "persistent"} <= set(reflex_names())
    slow = dataclasses.replace(get_reflex("stretch"), delay_s=0.04)
    assert register_reflex("stretch_40ms", slow) is slow
    assert get_reflex("stretch_40ms") is slow and "stretch_40ms" in reflex_names()
    # a registered model registered again under another name is the same model
    register_reflex("also_stretch", get_reflex("stretch"))
    assert get_reflex("also_stretch") is get_reflex("stretch")
    assert SpasticityStage(reflex="stretch_40ms").reflex.delay_s == 0.04
    with pytest.raises(ValueError, match="already registered"):
        register_reflex("stretch", slow)
    register_reflex("stretch_40ms", slow)  # the same model again: no error
    with pytest.raises(ValueError, match="without"):
        register_reflex("bad name", slow)
    with pytest.raises(TypeError, match="ReflexModel"):
        register_reflex("not_a_model", object())  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"registered: .*persistent.*stretch.*uniform"):
        resolve_reflex("clonus")


@pytest.mark.parametrize("name", ["stretch", "uniform", "persistent"])
def test_each_builtin_torch_twin_agrees_with_its_numpy_step_and_has_gradients(name):
    model = get_reflex(name)
    dt = 0.01
    for level in (1, 3):
        subject = sample_subject(level, np.random.default_rng(level))
        c = model.subject_constants(level, subject, None, dt)
        memory = model.initial_memory()
        params = {
            f.name: torch.tensor(getattr(subject, f.name), dtype=torch.float64, requires_grad=True)
            for f in dataclasses.fields(subject)
        }
        mem_t = tuple(torch.tensor(m, dtype=torch.float64) for m in memory)
        for theta, vel in ((80.0, -3.0), (30.0, -2.0), (10.0, 0.5), (60.0, 2.5)):
            flex, ext, memory = model.step(c, memory, theta, vel)
            th = torch.tensor(theta, dtype=torch.float64)
            v = torch.tensor(vel, dtype=torch.float64)
            flex_t, ext_t, mem_t = model.step_torch(level, params, mem_t, th, v, dt)
            assert float(flex_t.detach()) == pytest.approx(flex, abs=1e-12)
            assert float(ext_t.detach()) == pytest.approx(ext, abs=1e-12)
            assert [float(m.detach()) for m in mem_t] == pytest.approx(list(memory), abs=1e-12)
        (flex_t + ext_t).backward()
        assert params["s_theta"].grad is not None or params["s_v"].grad is not None


def test_a_user_model_runs_in_gym_make_the_wrapper_and_the_stage(velocity_reflex, walk_env_factory):
    import gymnasium as gym

    import myoexo  # noqa: F401

    model = get_reflex("velocity_example")
    assert isinstance(model, ReflexModel) and model == velocity_reflex.VelocityReflex()
    env = gym.make("MyoExoKnee-v2", reflex="velocity_example")
    stage = env.unwrapped.spasticity
    assert stage.reflex is model and stage.reflex_name == "velocity_example"
    env.reset(seed=0)
    flex, ext = [], []
    for _ in range(40):  # a fast extension: the flexors answer, the extensors stay quiet
        _, _, _, _, info = env.step(np.array([-1.0], np.float32))
        flex.append(stage.last_flexor_excitation)
        ext.append(stage.last_extensor_excitation)
    assert stage.delay_steps == 3  # 30 ms at 100 Hz
    assert max(flex) > 0.1 and max(ext) < 0.02  # at rest both are at the sigmoid tail
    assert info["sc_total"] == pytest.approx(
        stage.last_flexor_excitation + stage.last_extensor_excitation
    )
    other = gym.make("MyoExoKnee-v2")
    other.reset(seed=0)
    for _ in range(40):
        _, _, _, _, info_stretch = other.step(np.array([-1.0], np.float32))
    assert info_stretch["knee_angle_deg"] != info["knee_angle_deg"]  # another twin
    env.close()
    other.close()

    walk = walk_env_factory(level=1, reflex="velocity_example")  # a SpasticityWrapper
    walk.reset(seed=0)
    walk.step(walk.action_space.sample() * 0)
    assert isinstance(walk, SpasticityWrapper) and walk.spasticity.reflex is model
    walk.close()

    variant = dataclasses.replace(model, gains=(0.0, 0.0, 0.0, 0.0))
    with pytest.raises(ValueError, match="four values"):
        dataclasses.replace(model, gains=(2.0, 0.0, 0.0, 0.0))
    silent = SpasticityStage(level=2, reflex=variant, subject_noise=False)
    assert silent.reflex_name == "VelocityReflex (custom)"


def test_a_user_model_runs_in_the_clinical_tests_and_the_evaluation(velocity_reflex):
    from myoexo.clinical.tardieu import TardieuParams, run_tardieu
    from myoexo.control import PID
    from myoexo.evaluation.engine import evaluate_controller

    table = run_tardieu(TardieuParams(levels=(2,)), reflex="velocity_example").table()
    assert list(table["reflex"]) == ["velocity_example"]
    assert table["fast_peak_nm"].iloc[0] > table["slow_peak_nm"].iloc[0]  # velocity-dependent

    from myoexo.envs import make_env

    env = make_env(2, reflex="velocity_example")
    pid = PID.from_env(env)
    env.close()
    rows, _ = evaluate_controller(
        pid, 2, 1, episode_duration_s=1.0, env_kwargs={"reflex": "velocity_example"}
    )
    assert len(rows) == 1 and math.isfinite(rows["final_error_deg"].iloc[0])


def _cli(*args: str, env_plugins: str | None = None) -> subprocess.CompletedProcess:
    env = dict(os.environ)
    env["PYTHONPATH"] = os.pathsep.join([str(EXAMPLES), env.get("PYTHONPATH", "")])
    env.pop("MYOEXO_PLUGINS", None)
    if env_plugins:
        env["MYOEXO_PLUGINS"] = env_plugins
    return subprocess.run(
        [sys.executable, "-m", "myoexo.cli", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=600,
    )


def test_an_unknown_reflex_on_the_command_line_lists_the_registered_ones():
    out = _cli("clinic", "tardieu", "--reflex", "clonus", "--levels", "1")
    assert out.returncode == 2
    assert (
        "clonus" in out.stderr
        and "persistent, spindle, spindle_tone, spindle_tsrt, stretch, tsrt, uniform" in out.stderr
    )


@pytest.mark.slow
def test_a_user_model_evaluates_through_the_cli_in_worker_processes(tmp_path):
    out = _cli(
        "--plugin", "velocity_reflex",
        "evaluate", "--controllers", "pid", "--levels", "2", "--subjects", "2",
        "--workers", "2", "--episode-duration-s", "1", "--reflex", "velocity_example",
        "--out", str(tmp_path / "eval"), "--no-progress",
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    import json

    config = json.loads((tmp_path / "eval" / "config.json").read_text())
    assert config["config"]["twin"]["reflex"] == "velocity_example"
    assert config["config"]["twin"]["reflex_parameters"]["class"].endswith("VelocityReflex")
    # the same through the environment variable, for tools that start myoexo themselves
    again = _cli(
        "clinic", "tardieu", "--reflex", "velocity_example", "--levels", "1",
        env_plugins="velocity_reflex",
    )  # fmt: skip
    assert again.returncode == 0, again.stderr
    assert "velocity_example" in again.stdout


def test_a_user_model_reaches_the_training_and_distillation_envs(velocity_reflex):
    from myoexo.envs.options import TwinOptions
    from myoexo.studies.distill import DistillConfig, EnvPool
    from myoexo.training import get_preset
    from myoexo.training.train import make_vec_env

    preset = get_preset("cpu", n_envs=1, reflex="velocity_example", episode_duration_s="0.1")
    venv = make_vec_env(preset)
    assert [s.reflex_name for s in venv.get_attr("spasticity")] == ["velocity_example"]
    venv.close()
    config = DistillConfig(twin=TwinOptions(reflex="velocity_example"))
    pool = EnvPool(config.twin)
    for perturbed in (False, True):
        stage = pool.get(2, perturbed).unwrapped.spasticity
        assert stage.reflex is get_reflex("velocity_example")
    pool.close()


@pytest.fixture(scope="module")
def spindle_reflex():
    """The docs' example of a model on the muscles' own state."""
    yield from _example("spindle_reflex")
    _REGISTRY.pop("spindle_example", None)


def test_the_sensory_record_is_mujocos_muscle_state():
    """Normalised fibre length and lengthening speed by MuJoCo's own muscle normalisation;
    knee extension lengthens the hamstrings and gastrocnemii and shortens the quadriceps."""
    import gymnasium as gym

    import myoexo  # noqa: F401

    env = gym.make("MyoExoKnee-v0")
    try:
        base = env.unwrapped
        stage = base.spasticity
        env.reset(seed=0)
        env.step(np.array([-1.0], np.float32))
        records = []
        for _ in range(10):  # a fast extension
            env.step(np.array([-1.0], np.float32))
            records.append(stage._sensors.read(base.data, 0.0, 0.0))
    finally:
        env.close()
    r = records[-1]
    nf = r.n_flexors
    assert nf == len(stage.flexors) and len(r.fibre_length) == len(stage.muscles)
    assert ((r.fibre_length > 0.2) & (r.fibre_length < 2.0)).all()
    assert (r.lengthening_speed[:nf] > 0.0).all()  # the paper's flexors: stretched
    quadriceps = [i for i, m in enumerate(stage.muscles) if m.startswith(("vas", "recfem"))]
    assert len(quadriceps) == 4 and (r.lengthening_speed[quadriceps] < 0.0).all()
    assert (r.force_n >= 0.0).all()
    # MuJoCo's own normalisation: at a range's ends the normalised length is the range's
    model = base.model
    ids = stage.actuator_ids
    lr, rng = model.actuator_lengthrange[ids], model.actuator_gainprm[ids, 0:2]
    sensors = stage._sensors
    np.testing.assert_allclose(lr[:, 0] / sensors.optimal_length_m + sensors._offset, rng[:, 0])
    np.testing.assert_allclose(lr[:, 1] / sensors.optimal_length_m + sensors._offset, rng[:, 1])


def test_a_model_on_the_muscles_own_state_runs_as_a_plug_in(spindle_reflex):
    """Written on the sensory record: one excitation per muscle, from the delayed record."""
    import gymnasium as gym

    import myoexo  # noqa: F401

    model = get_reflex("spindle_example")
    env = gym.make("MyoExoKnee-v2", reflex="spindle_example")
    try:
        stage = env.unwrapped.spasticity
        assert stage.reflex is model
        env.reset(seed=0)
        quadriceps = [i for i, m in enumerate(stage.muscles) if m.startswith(("vas", "recfem"))]
        flex, quad = [], []
        for _ in range(40):  # a fast extension: the stretched muscles answer, each its own
            env.step(np.array([-1.0], np.float32))
            flex.append(stage.last_flexor_excitation)
            quad.append(stage.last_excitations[quadriceps].max())
        assert stage.delay_steps == 3  # 30 ms at 100 Hz
        assert max(flex) > 0.1 and max(quad) < 0.1 * max(flex)  # the shortened quadriceps
        # the excitation is the model's of the record delay_steps old
        record = stage.delay_line.state()[0]
        assert all(r is not None for r in record)
    finally:
        env.close()
    with pytest.raises(NotImplementedError, match="excite"):
        model.step(None, (), 0.0, 0.0)
