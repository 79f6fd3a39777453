"""The ``"spindle_tone"`` reflex: ``"spindle_tsrt"`` plus a broad tone on each flexor's own
fibre length and a phasic scale per level."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path
from types import MappingProxyType

import mujoco
import numpy as np
import pytest

from myoexo.model import TwinParams, build_model, pose_twin
from myoexo.spasticity import LEVELS, SPASTIC_FLEXORS, SPASTIC_MUSCLES, MuscleSensors
from myoexo.spasticity.registry import get_reflex
from myoexo.spasticity.spindle import SPINDLE_TSRT_CALIBRATION, SpindleTSRTReflex, spindle_geometry
from myoexo.spasticity.spindle_tone import (
    SpindleToneReflex,
    ToneCalibration,
    ToneIndividual,
    ToneLevel,
)
from myoexo.studies.joint_fit import calibrate_tsrt

HAMSTRINGS = ("semimem_r", "semiten_r", "bflh_r")
ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def geometry():
    return spindle_geometry(TwinParams(scene=False))


def _record(model: mujoco.MjModel, knee_deg: float, speed: np.ndarray | None = None):
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=knee_deg)
    mujoco.mj_forward(model, data)
    ids = np.array([model.actuator(n).id for n in SPASTIC_MUSCLES])
    record = MuscleSensors(model, ids, len(SPASTIC_FLEXORS)).read(data, knee_deg, 0.0)
    return record if speed is None else record._replace(lengthening_speed=speed)


def _tone(level: int, tone: float, scale: float = 1.0) -> ToneCalibration:
    levels = {lv: ToneLevel.from_tsrt(c) for lv, c in SPINDLE_TSRT_CALIBRATION.levels.items()}
    levels[level] = dataclasses.replace(levels[level], flexor_tone=tone, phasic_scale=scale)
    return ToneCalibration(levels=MappingProxyType(levels))


def test_without_tone_it_is_spindle_tsrt_bit_for_bit(geometry) -> None:
    model, _ = build_model(TwinParams(scene=False))
    plain = SpindleTSRTReflex(calibration=SPINDLE_TSRT_CALIBRATION, geometry=geometry)
    toned = SpindleToneReflex(
        calibration=ToneCalibration.from_tsrt(SPINDLE_TSRT_CALIBRATION), geometry=geometry
    )
    speed = -2.0 * np.asarray(geometry.slope_per_rad)
    for level in (1, 2, 3):
        a = plain.subject_constants(level, LEVELS[level], None, 0.01)
        b = toned.subject_constants(level, LEVELS[level], None, 0.01)
        for knee_deg in (5.0, 40.0, 80.0):
            record = _record(model, knee_deg, speed)
            ea, _ = plain.excite(a, (), record)
            eb, _ = toned.excite(b, (), record)
            np.testing.assert_array_equal(np.asarray(ea), np.asarray(eb))


def test_the_tone_rises_as_a_flexor_lengthens_and_spares_the_extensors(geometry) -> None:
    model, _ = build_model(TwinParams(scene=False))
    without = SpindleToneReflex(calibration=_tone(3, 0.0), geometry=geometry)
    toned = SpindleToneReflex(calibration=_tone(3, 0.4), geometry=geometry)
    c0 = without.subject_constants(3, LEVELS[3], None, 0.01)
    c1 = toned.subject_constants(3, LEVELS[3], None, 0.01)
    flexor = np.asarray(geometry.slope_per_rad) < 0.0
    added = {}
    for knee_deg in (10.0, 45.0, 85.0):
        record = _record(model, knee_deg)
        added[knee_deg] = np.asarray(toned.excite(c1, (), record)[0]) - np.asarray(
            without.excite(c0, (), record)[0]
        )
        assert np.all(added[knee_deg][~flexor] == 0.0)
        assert np.all(added[knee_deg][flexor] > 0.0)
        assert np.all(added[knee_deg][flexor] < 0.4)
    # extension lengthens the flexors: more tone at 10 deg than at 85
    assert np.all(added[10.0][flexor] > added[45.0][flexor])
    assert np.all(added[45.0][flexor] > added[85.0][flexor])
    # the tone is gentle: at most tone / (2 width) per deg over the seated range
    slope = (added[10.0][flexor] - added[85.0][flexor]) / 75.0
    assert np.all(slope <= 0.4 / (2 * toned.tone_width_deg) + 1e-9)


def test_the_reclined_hip_takes_the_hamstrings_tone_away(geometry) -> None:
    seated, _ = build_model(TwinParams(scene=False))
    reclined, _ = build_model(TwinParams(hip_flexion_deg=40.0, scene=False))
    toned = SpindleToneReflex(calibration=_tone(3, 0.4), geometry=geometry)
    without = SpindleToneReflex(calibration=_tone(3, 0.0), geometry=geometry)
    c1 = toned.subject_constants(3, LEVELS[3], None, 0.01)
    c0 = without.subject_constants(3, LEVELS[3], None, 0.01)
    ham = [SPASTIC_MUSCLES.index(n) for n in HAMSTRINGS]

    def tone(model: mujoco.MjModel) -> float:
        record = _record(model, 10.0)
        e1 = np.asarray(toned.excite(c1, (), record)[0])
        e0 = np.asarray(without.excite(c0, (), record)[0])
        return float(np.mean((e1 - e0)[ham]))

    assert tone(reclined) < 0.6 * tone(seated)


def test_the_phasic_scale_scales_the_velocity_term_only(geometry) -> None:
    model, _ = build_model(TwinParams(scene=False))
    full = SpindleToneReflex(calibration=_tone(2, 0.0, 1.0), geometry=geometry)
    half = SpindleToneReflex(calibration=_tone(2, 0.0, 0.5), geometry=geometry)
    cf = full.subject_constants(2, LEVELS[2], None, 0.01)
    ch = half.subject_constants(2, LEVELS[2], None, 0.01)
    speed = -3.0 * np.asarray(geometry.slope_per_rad)
    rest, fast = _record(model, 30.0), _record(model, 30.0, speed)
    # at rest the velocity term is nearly off: the tonic term is the same
    np.testing.assert_allclose(
        full.excite(cf, (), rest)[0], half.excite(ch, (), rest)[0], rtol=1e-3
    )
    phasic_full = np.asarray(full.excite(cf, (), fast)[0]) - np.asarray(
        full.excite(cf, (), rest)[0]
    )
    phasic_half = np.asarray(half.excite(ch, (), fast)[0]) - np.asarray(
        half.excite(ch, (), rest)[0]
    )
    assert phasic_full.max() > 0.05
    np.testing.assert_allclose(phasic_half, 0.5 * phasic_full, atol=1e-6)


def test_the_background_tone_adds_its_excitation_to_every_muscle_at_any_state(geometry) -> None:
    """The background tone is the same constant on flexors and extensors, stretched or not,
    at rest or moving: it closes no loop."""
    model, _ = build_model(TwinParams(scene=False))
    levels = {lv: ToneLevel.from_tsrt(c) for lv, c in SPINDLE_TSRT_CALIBRATION.levels.items()}
    records = [_record(model, angle) for angle in (10.0, 45.0, 80.0)]
    records.append(_record(model, 30.0, -2.0 * np.asarray(geometry.slope_per_rad)))
    excitation = {}
    for tone in (0.0, 0.07):
        level = dataclasses.replace(levels[3], background_tone=tone)
        reflex = SpindleToneReflex(
            calibration=ToneCalibration(levels=MappingProxyType({**levels, 3: level})),
            geometry=geometry,
        )
        c = reflex.subject_constants(3, LEVELS[3], None, 0.01)
        excitation[tone] = [np.asarray(reflex.excite(c, (), r)[0]) for r in records]
    for plain, toned in zip(excitation[0.0], excitation[0.07], strict=True):
        assert toned.shape == (len(SPASTIC_MUSCLES),)
        np.testing.assert_allclose(toned - plain, 0.07, atol=1e-12)


@pytest.mark.parametrize(
    ("changes", "message"),
    [
        ({"flexor_tone": 1.5}, r"ToneLevel.flexor_tone = 1.5 .*\[0(\.0)?, 1(\.0)?\]"),
        ({"phasic_scale": -0.1}, r"ToneLevel.phasic_scale = -0.1 .*\[0(\.0)?, 2(\.0)?\]"),
        ({"background_tone": 0.6}, r"ToneLevel.background_tone = 0.6 .*\[0(\.0)?, 0.5\]"),
        (
            {"phasic_threshold_offset_deg": 250.0},
            r"ToneLevel.phasic_threshold_offset_deg = 250.0 .*\[-100(\.0)?, 200(\.0)?\] deg",
        ),
    ],
)
def test_bad_tone_parameters_are_refused_with_their_range(changes, message) -> None:
    with pytest.raises(ValueError, match=message):
        ToneLevel(**changes)


def test_the_calibration_round_trips_and_takes_tone_levels_only() -> None:
    calibration = _tone(2, 0.12, 0.5)
    assert ToneCalibration.from_dict(calibration.to_dict()) == calibration
    with pytest.raises(ValueError, match="must be a ToneLevel"):
        ToneCalibration(levels=MappingProxyType({2: SPINDLE_TSRT_CALIBRATION[2]}))


def test_the_joint_fit_refuses_another_models_start() -> None:
    assert isinstance(get_reflex("spindle_tone"), SpindleToneReflex)
    with pytest.raises(ValueError, match="takes a ToneCalibration"):
        calibrate_tsrt(start=SPINDLE_TSRT_CALIBRATION, reflex="spindle_tone", sweeps=0)


def test_the_fit_reads_its_start_file_and_refuses_one_without_levels(tmp_path, capsys) -> None:
    """``--start`` names the JSON the search starts from; a file without a calibration's
    ``levels`` is refused with one line, before any candidate is measured."""
    from myoexo import cli

    bad = tmp_path / "start.json"
    bad.write_text('{"note": "no levels"}')
    args = ["twin", "calibrate", "--reflex", "spindle_tone", "--start", str(bad), "--sweeps", "0"]
    assert cli.main(args) == 2
    err = capsys.readouterr().err
    assert f"--start {bad}: expected a calibration's JSON with its 'levels'" in err
    # the committed start reads back as the model's kind of calibration
    doc = ROOT / "docs" / "studies" / "calibration_spindle_tone" / "start.json"
    start = ToneCalibration.from_dict(json.loads(doc.read_text()))
    assert start[2].phasic_scale == 0.5 and start[3].flexor_tone > 0.0


def test_the_phasic_threshold_offset_keeps_the_catch_with_the_static_threshold_out(
    geometry,
) -> None:
    """With the flexors' static threshold beyond full extension, a fast extension at 30 deg
    hardly excites the hamstrings; an offset that puts the dynamic threshold back inside the
    range restores the phasic burst, and leaves the excitation at rest as it was."""
    model, _ = build_model(TwinParams(scene=False))
    levels = {lv: ToneLevel.from_tsrt(c) for lv, c in SPINDLE_TSRT_CALIBRATION.levels.items()}
    out = dataclasses.replace(levels[2], flexor_threshold_shift_deg=-10.0)
    ham = [SPASTIC_MUSCLES.index(n) for n in HAMSTRINGS]
    speed = -3.0 * np.asarray(geometry.slope_per_rad)  # the knee extending at 3 rad/s
    rest, fast = _record(model, 30.0), _record(model, 30.0, speed)
    burst, at_rest = {}, {}
    for offset in (0.0, 60.0):
        level = dataclasses.replace(out, phasic_threshold_offset_deg=offset)
        reflex = SpindleToneReflex(
            calibration=ToneCalibration(levels=MappingProxyType({**levels, 2: level})),
            geometry=geometry,
        )
        c = reflex.subject_constants(2, LEVELS[2], None, 0.01)
        e_rest = np.asarray(reflex.excite(c, (), rest)[0])
        burst[offset] = float(np.mean((np.asarray(reflex.excite(c, (), fast)[0]) - e_rest)[ham]))
        at_rest[offset] = e_rest
    assert burst[0.0] < 0.02 and burst[60.0] > 0.1, burst
    np.testing.assert_allclose(at_rest[0.0], at_rest[60.0], atol=1e-3)


def test_each_subject_draws_its_own_tones_without_moving_the_resets_stream() -> None:
    """A subject's flexor and background tones are the level's times its own factors (10 %
    SD); the nominal subject (``None``) keeps the level's; the reset's generator draws the
    same afterwards as if no factor had been drawn."""
    reflex = get_reflex("spindle_tone")
    level = dataclasses.replace(reflex.calibration[2], flexor_tone=0.3, background_tone=0.05)
    levels = {**reflex.calibration.levels, 2: level}
    model = dataclasses.replace(
        reflex, calibration=ToneCalibration(levels=MappingProxyType(levels))
    )
    rng = np.random.default_rng(11)
    individuals = [model.draw_individual(rng, 0.1) for _ in range(200)]
    assert rng.standard_normal() == np.random.default_rng(11).standard_normal()
    factors = np.array(individuals)
    assert np.all(factors >= 0.0)
    assert abs(factors.mean() - 1.0) < 0.03 and 0.07 < factors.std() < 0.13
    assert abs(np.corrcoef(factors.T)[0, 1]) < 0.25  # two factors of their own
    own = ToneIndividual(1.2, 0.5)
    c = model.subject_constants(2, LEVELS[2], own, 0.01)
    nominal = model.subject_constants(2, LEVELS[2], None, 0.01)
    flexors = nominal.tone > 0.0
    np.testing.assert_allclose(nominal.tone[flexors], 0.3)
    np.testing.assert_allclose(c.tone[flexors], 0.36)
    assert np.all(c.tone[~flexors] == 0.0)
    assert nominal.background_tone == 0.05 and c.background_tone == pytest.approx(0.025)


def test_the_excitation_is_the_documented_formula(geometry) -> None:
    """``excite`` (the expanded kernel) equals the module docstring's formula, term by term,
    at random fibre lengths and speeds, with a tone, a dynamic-threshold offset and a
    background tone."""
    levels = {lv: ToneLevel.from_tsrt(c) for lv, c in SPINDLE_TSRT_CALIBRATION.levels.items()}
    level = dataclasses.replace(
        levels[2],
        flexor_tone=0.3,
        phasic_scale=0.7,
        phasic_threshold_offset_deg=20.0,
        background_tone=0.04,
    )
    reflex = SpindleToneReflex(
        calibration=ToneCalibration(levels=MappingProxyType({**levels, 2: level})),
        geometry=geometry,
    )
    c = reflex.subject_constants(2, LEVELS[2], ToneIndividual(1.1, 0.9), 0.01)
    t = c.tsrt
    rng = np.random.default_rng(3)
    model, _ = build_model(TwinParams(scene=False))
    for knee_deg in (5.0, 35.0, 70.0):
        record = _record(model, knee_deg, rng.normal(0.0, 1.0, len(SPASTIC_MUSCLES)))
        theta = record.fibre_length * t.deg_per_length + t.theta_offset_deg
        vel = record.lengthening_speed * t.inv_slope
        side = t.side
        beyond = theta - t.threshold_deg
        static = 1.0 + side * np.tanh(t.half_k * beyond)
        stretch = np.maximum(side * vel, 0.0)
        offset = np.where(side < 0.0, 20.0, 0.0)
        dynamic = 1.0 + side * np.tanh(
            t.half_k * (beyond - offset + side * t.mu_deg_s_rad * stretch)
        )
        gate = 0.5 * (1.0 + side * np.tanh(t.half_k_v * (vel - t.v_threshold_rad_s)))
        tone = c.tone * 0.5 * (1.0 - np.tanh((theta - 45.0) / 30.0))
        expected = 0.5 * (t.s_theta * static + t.s_v * gate * dynamic) + tone + 0.04 * 0.9
        got, memory = reflex.excite(c, (), record)
        assert memory == ()
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)
