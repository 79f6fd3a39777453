"""The gentleness setting: the env's ``gentleness=`` (a weight observed last and pricing
the interaction torque's peak and square in the reward), the twin record's option, the
``SPEC@W`` controller spec and the controller that appends the weight."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import myoexo  # noqa: F401  (registers the ids)
from myoexo.control.policy import CallableController, GentleController
from myoexo.control.specs import parse_controller_spec, spec_gentleness
from myoexo.envs.options import TwinOptions
from myoexo.envs.sensors import read_sensors

PEAK_PRICE = 400.0  # the documented default gentle_peak_weight
SQUARE_PRICE = 0.1  # the documented default gentle_torque_weight
SCALE_NM = 100.0


def _episode(gentleness, seed=4, steps=60, command=-0.8):
    env = gym.make("MyoExoKnee-v1", gentleness=gentleness, episode_duration_s=1.0)
    obs, info = env.reset(seed=seed)
    out = [(obs, None, info)]
    for _ in range(steps):
        obs, reward, _, _, info = env.step(np.array([command], np.float32))
        out.append((obs, reward, info))
    env.close()
    return out


def test_weight_is_the_last_observation_and_the_rest_is_unchanged():
    plain = _episode(None)
    gentle = _episode(0.7)
    for (o_plain, _, i_plain), (o_gentle, _, i_gentle) in zip(plain, gentle, strict=True):
        assert o_gentle.shape == (o_plain.size + 1,)
        assert o_gentle[-1] == np.float32(0.7)
        np.testing.assert_array_equal(o_gentle[:-1], o_plain)  # same subject, same physics
        assert i_gentle["gentleness"] == 0.7
        assert i_plain["gentleness"] is None


def test_weight_zero_is_the_studys_reward():
    for (_, r_plain, _), (_, r_zero, _) in zip(_episode(None), _episode(0.0), strict=True):
        assert r_plain == r_zero


def test_gentle_term_prices_the_peak_rises_and_the_square():
    weight = 0.6
    plain, gentle = _episode(None), _episode(weight)
    peak = gentle[0][2]["interaction_torque_nm"]
    total_rise = 0.0
    for (_, r_plain, _), (_, r_gentle, info) in zip(plain[1:], gentle[1:], strict=True):
        tau = info["interaction_torque_nm"]
        rise = max(0.0, tau - peak)
        total_rise += rise
        expected = PEAK_PRICE * rise / SCALE_NM + SQUARE_PRICE * (tau / SCALE_NM) ** 2
        assert info["rwd_dict"]["gentle"] == pytest.approx(expected, rel=1e-9, abs=1e-12)
        assert r_gentle == pytest.approx(r_plain - weight * expected, rel=1e-9, abs=1e-9)
        peak = max(peak, tau)
    taus = [info["interaction_torque_nm"] for _, _, info in gentle]
    assert total_rise == pytest.approx(max(taus) - taus[0], rel=1e-9)  # rises sum to the peak
    assert total_rise > 10.0  # a full-effort start raises the peak well above the reset's


def test_random_weight_is_drawn_per_reset_from_the_env_stream():
    env = gym.make("MyoExoKnee-v1", gentleness="random")
    weights = []
    for seed in (1, 2, 3):
        obs, info = env.reset(seed=seed)
        weights.append(info["gentleness"])
        assert obs[-1] == np.float32(info["gentleness"])
        assert 0.0 <= info["gentleness"] <= 1.0
    assert len(set(weights)) == 3
    _, info = env.reset(seed=2)
    assert info["gentleness"] == weights[1]  # same seed, same weight
    plain = gym.make("MyoExoKnee-v1")
    _, plain_info = plain.reset(seed=2)
    assert plain_info["subject"] == info["subject"]  # the draw leaves the subjects alone


@pytest.mark.parametrize("bad", [-0.1, 1.5, "gentle", float("nan"), True])
def test_bad_weight_is_refused_with_the_range(bad):
    with pytest.raises(ValueError, match=r"gentleness = .* is outside \[0, 1\]"):
        gym.make("MyoExoKnee-v1", gentleness=bad)


def test_twin_record_carries_the_option():
    twin = TwinOptions.from_overrides(["gentleness=random"])
    assert twin.env_kwargs() == {"gentleness": "random"}
    assert TwinOptions.from_dict(twin.to_dict()) == twin
    assert TwinOptions(gentleness="0.50").env_kwargs() == {"gentleness": 0.5}
    assert "gentleness=random" in twin.describe()
    assert twin.dynamics() == TwinOptions().dynamics()  # a learning signal, not dynamics
    with pytest.raises(ValueError, match="outside"):
        TwinOptions(gentleness="2")


def test_controller_appends_the_weight():
    seen = []

    def fn(obs):
        seen.append(obs)
        return [0.0]

    env = gym.make("MyoExoKnee-v1")
    obs, info = env.reset(seed=0)
    controller = GentleController(CallableController(fn), 0.25)
    controller.reset(0)
    controller.act(obs, read_sensors(info, controller.sensors))
    assert seen[0].size == obs.size + 1 and seen[0][-1] == np.float32(0.25)
    np.testing.assert_array_equal(seen[0][:-1], obs)
    with pytest.raises(ValueError, match="outside"):
        GentleController(CallableController(fn), 1.2)


def test_spec_weight_suffix():
    with pytest.raises(ValueError, match="only a policy takes a gentleness weight"):
        parse_controller_spec("pid@0.5")
    with pytest.raises(ValueError, match="outside"):
        parse_controller_spec("sac@1.5")
    spec = parse_controller_spec("sac@0.3")
    assert spec.label == "sac@0.3" and spec.gentleness == 0.3
    with pytest.raises(ValueError, match="not trained with a gentleness weight"):
        spec_gentleness(spec)  # the shipped policy was trained on the study's reward
    assert spec_gentleness(parse_controller_spec("sac")) is None


# ----------------------------------------------------------------------------- the study
def _hand_made_gentle_actor(tmp_path):
    """A one-layer actor on the full observation plus the weight: u = tanh(-3 e + 0.6 g)
    (e: the knee error in rad; a larger weight pushes less toward extension)."""
    from myoexo.envs.observation import DEFAULT_OBS_KEYS
    from myoexo.policies.actor import MLPActor, save_actor

    env = gym.make("MyoExoKnee-v1")
    size = env.observation_space.shape[0] + 1
    w = np.zeros((1, size))
    w[0, list(DEFAULT_OBS_KEYS).index("error_rad")] = -3.0
    w[0, -1] = 0.6
    meta = {"twin": TwinOptions(gentleness="random").to_dict(), "obs_preset": "full"}
    actor = MLPActor([(w, np.zeros(1))], metadata=meta)
    probe = np.random.default_rng(0).normal(size=(3, size))
    actor.metadata["reference"] = {
        "observations": probe.tolist(),
        "actions": np.tanh(probe @ w.T).tolist(),  # the law, computed here
    }
    stem = tmp_path / "gentle_actor"
    save_actor(actor, stem)
    return actor, f"{stem}.npz"


def test_gentleness_study_chooses_and_records_a_default(tmp_path):
    import json

    from myoexo.runtime.fields import Execution
    from myoexo.studies.gentleness import (
        GentlenessConfig,
        choose_default,
        run_gentleness,
        weight_key,
    )
    from myoexo.training.export import read_gentleness_record

    _, spec = _hand_made_gentle_actor(tmp_path)
    with pytest.raises(ValueError, match="records no default weight"):
        spec_gentleness(parse_controller_spec(spec))
    config = GentlenessConfig(
        policy=spec,
        weights=(0.0, 1.0),
        subjects=2,
        levels=(1,),
        out=tmp_path / "g",
        classical=False,
    )
    record = run_gentleness(config, execution=Execution(workers=1, progress=False))
    import pandas as pd

    table = pd.read_csv(tmp_path / "g" / "gentleness.csv")
    assert sorted(table.weight) == [0.0, 1.0]
    fast, gentle = (table[table.weight == w].iloc[0] for w in (0.0, 1.0))
    assert gentle.sac_peak_nm < fast.sac_peak_nm  # the bias toward flexion lowers the peak
    assert record["default_gentleness"] == choose_default(table)
    best = min((weight_key(rows), w) for w, rows in table.groupby("weight"))[1]
    assert record["default_gentleness"] == best
    written = json.loads((tmp_path / "g" / "gentleness.json").read_text())
    assert written["root_seed"] == 1 and written == record
    assert read_gentleness_record(tmp_path / "g") == record
    assert (tmp_path / "g" / "gentleness.png").stat().st_size > 0
    with pytest.raises(ValueError, match="evaluation"):
        GentlenessConfig(policy=spec, root_seed=0)


def test_dominance_asks_for_every_measure_at_equal_accuracy():
    import pandas as pd

    from myoexo.studies.gentleness import dominance, level_verdicts

    weights = pd.DataFrame(
        {
            "weight": [0.0, 1.0],
            "level": [1, 1],
            "sac_abs_final_error_deg": [0.5, 3.0],
            "sac_settling_time_s": [0.8, 2.0],
            "sac_peak_nm": [90.0, 50.0],
            "sac_rms_nm": [40.0, 20.0],
        }
    )
    classical = pd.DataFrame(
        {
            "level": [1, 1, 1],
            "controller": ["fast", "gentle", "accurate_gentle"],
            "abs_final_error_deg": [0.9, 3.5, 0.2],
            "settling_time_s": [1.0, 2.5, 2.5],
            "peak_interaction_torque_nm": [95.0, 60.0, 55.0],
            "rms_interaction_torque_nm": [45.0, 25.0, 25.0],
        }
    )
    table = dominance(weights, classical).set_index("controller")
    assert table.loc["fast", "matched_by"] == "0"  # both within the 1-deg bound
    assert table.loc["gentle", "matched_by"] == "1"  # 3.0 deg beats its 3.5
    assert table.loc["accurate_gentle", "matched_by"] == ""  # 0 too rough, 1 too inaccurate
    (verdict,) = level_verdicts(table.reset_index()).to_dict(orient="records")
    assert verdict["matched"] == 1 and verdict["classical"] == 3 and not verdict["every_one"]
    assert verdict["matched_by_no_weight"] == "accurate_gentle"


def test_a_controller_that_never_settles_is_slower_than_one_that_does(tmp_path):
    import pandas as pd

    from myoexo.studies.gentleness import dominance, recount, write_record

    weights = pd.DataFrame(
        {
            "weight": [0.0, 1.0],
            "level": [0, 0],
            "sac_abs_final_error_deg": [0.2, 0.3],
            "sac_settling_time_s": [0.6, float("nan")],  # weight 1 never settles
            "sac_peak_nm": [44.0, 43.0],
            "sac_rms_nm": [18.0, 17.0],
        }
    )
    classical = pd.DataFrame(
        {
            "level": [0, 0],
            "controller": ["never_settles", "settles"],
            "abs_final_error_deg": [5.7, 0.2],
            "settling_time_s": [float("nan"), 1.0],
            "peak_interaction_torque_nm": [112.0, 100.0],
            "rms_interaction_torque_nm": [95.0, 65.0],
        }
    )
    table = dominance(weights, classical).set_index("controller")
    # a NaN mean settling time (no episode settled) loses to any finite one, ties with NaN
    assert table.loc["never_settles", "matched_by"] == "0 1"
    assert table.loc["settles", "matched_by"] == "0"

    # a finished study's files, counted again from themselves
    for column in ("pid_settling_time_s", "pid_peak_nm", "pid_rms_nm"):
        weights[column] = 1.0
    for column in ("peak_reduction_pct", "rms_reduction_pct"):
        weights[column] = 0.0
    weights["pass"] = True
    record = {"policy": "p", "default_gentleness": 0.0, "subjects": 2, "root_seed": 1}
    write_record(tmp_path, record, weights, classical, figure=False)
    stale = pd.read_csv(tmp_path / "dominance.csv")
    stale["matched_by"] = ""  # as an older count might have left it
    stale.to_csv(tmp_path / "dominance.csv", index=False)
    recounted = recount(tmp_path)
    assert recounted["against_classical"][0]["matched"] == 2
    assert "recounted_with" in recounted and recounted["policy"] == "p"
    fresh = pd.read_csv(tmp_path / "dominance.csv").set_index("controller")
    assert fresh.loc["never_settles", "matched_by"] == "0 1"
    verdict_row = (tmp_path / "gentleness.md").read_text().splitlines()[-1].split("|")
    assert [cell.strip() for cell in verdict_row[1:6]] == ["0", "0", "2", "2", "True"]


def test_the_default_is_never_a_weight_that_does_not_settle_at_some_level():
    import pandas as pd

    from myoexo.studies.gentleness import choose_default

    # weight 0 has the larger reductions but settles in no episode at level 1
    rows = [
        (0.0, 0, 0.5, 0.6, 60.0, 60.0),
        (0.0, 1, 0.5, float("nan"), 60.0, 60.0),
        (1.0, 0, 0.5, 0.9, 20.0, 20.0),
        (1.0, 1, 0.5, 0.9, 20.0, 20.0),
    ]
    table = pd.DataFrame(
        rows,
        columns=[
            "weight", "level", "sac_abs_final_error_deg", "settling_ratio",
            "peak_reduction_pct", "rms_reduction_pct",
        ],
    )  # fmt: skip
    assert choose_default(table) == 1.0
    assert choose_default(table.fillna(0.8)) == 0.0  # settled: its reductions win


def test_onnx_takes_the_weight_as_its_own_input(tmp_path):
    onnxruntime = pytest.importorskip("onnxruntime")
    from myoexo.training.export import export_onnx

    actor, _ = _hand_made_gentle_actor(tmp_path)
    path = export_onnx(actor, tmp_path / "g.onnx")
    session = onnxruntime.InferenceSession(str(path))
    names = [i.name for i in session.get_inputs()]
    assert names == ["obs", "gentleness"]
    env = gym.make("MyoExoKnee-v1")
    obs, info = env.reset(seed=1)
    for weight in (0.0, 0.8):
        (onnx_action,) = session.run(
            None,
            {"obs": obs[None].astype(np.float32), "gentleness": np.array([[weight]], np.float32)},
        )
        controller = GentleController(actor, weight)
        action = controller.act(obs, read_sensors(info, controller.sensors))
        np.testing.assert_allclose(onnx_action[0], action, rtol=1e-5, atol=1e-6)
