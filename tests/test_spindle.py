"""The ``"spindle"`` reflex: each muscle answers the stretch of its own fibres, so the same
knee angle stretches the hamstrings seated and leaves them slack reclined."""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np
import pytest

from myoexo.model import TwinParams, build_model, pose_twin
from myoexo.spasticity import (
    LEVELS,
    SPASTIC_FLEXORS,
    SPASTIC_MUSCLES,
    MuscleSensors,
    SpasticityStage,
    StageHost,
    get_reflex,
    reflex_names,
)
from myoexo.spasticity.reflex import CALIBRATION, StretchReflex, stretch_constants, stretch_terms
from myoexo.spasticity.spindle import SpindleReflex, SpindleTSRTReflex, spindle_geometry
from myoexo.spasticity.tsrt import TSRT_CALIBRATION, TSRTReflex, tsrt_constants, tsrt_terms

HAMSTRINGS = ("semimem_r", "semiten_r", "bflh_r")


@pytest.fixture(scope="module")
def seated() -> tuple[mujoco.MjModel, object]:
    model, _ = build_model(TwinParams(scene=False))
    return model, spindle_geometry(TwinParams(scene=False))


def _record(model: mujoco.MjModel, knee_deg: float):
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=knee_deg)
    mujoco.mj_forward(model, data)
    ids = np.array([model.actuator(n).id for n in SPASTIC_MUSCLES])
    return MuscleSensors(model, ids, len(SPASTIC_FLEXORS)).read(data, knee_deg, 0.0)


def test_geometry_signs_and_lines(seated) -> None:
    _, geometry = seated
    slope = dict(zip(geometry.muscles, geometry.slope_per_rad, strict=True))
    for name in (*HAMSTRINGS, "bfsh_r", "grac_r", "gaslat_r", "gasmed_r"):
        assert slope[name] < 0.0, name  # knee extension lengthens the flexors (and gracilis)
    for name in ("vasmed_r", "vaslat_r", "vasint_r", "recfem_r"):
        assert slope[name] > 0.0, name
    assert max(geometry.rms_error) < 0.02  # a line is close over 0-90 deg


def test_seated_fibre_lengths_read_as_the_knee_angle(seated) -> None:
    model, geometry = seated
    for knee_deg in (20.0, 45.0, 70.0):
        theta = geometry.equivalent_knee_deg(_record(model, knee_deg).fibre_length)
        assert np.abs(theta - knee_deg).max() < 15.0, (knee_deg, theta)


def test_the_reclined_hip_slackens_the_hamstrings_and_stretches_rectus_femoris(seated) -> None:
    _, geometry = seated
    reclined, _ = build_model(TwinParams(hip_flexion_deg=40.0, scene=False))
    record = _record(reclined, 10.0)
    theta = dict(
        zip(SPASTIC_MUSCLES, geometry.equivalent_knee_deg(record.fibre_length), strict=True)
    )
    for name in HAMSTRINGS:
        assert theta[name] > 10.0 + 30.0, name  # as slack as a knee 30+ deg more flexed
    assert theta["recfem_r"] > 10.0 + 30.0  # rectus femoris crosses the hip too
    assert abs(theta["bfsh_r"] - 10.0) < 15.0  # a one-joint muscle does not care


@pytest.mark.parametrize(
    ("reflex_class", "calibration", "constants_of", "terms"),
    [
        (SpindleReflex, CALIBRATION, stretch_constants, stretch_terms),
        (SpindleTSRTReflex, TSRT_CALIBRATION, tsrt_constants, tsrt_terms),
    ],
    ids=["spindle", "spindle_tsrt"],
)
def test_the_excitation_is_the_knee_reflex_on_each_muscles_state(
    seated, reflex_class, calibration, constants_of, terms
) -> None:
    """excite equals the knee-angle reflex's terms (``"stretch"``'s for ``"spindle"``,
    ``"tsrt"``'s for ``"spindle_tsrt"``) evaluated at each muscle's equivalent knee angle
    and speed, the flexor term for the muscles extension lengthens and the extensor term
    for the others."""
    model, geometry = seated
    reflex = reflex_class(calibration=calibration, geometry=geometry)
    rng = np.random.default_rng(0)
    for level in (1, 2, 3):
        subject = LEVELS[level]
        constants = reflex.subject_constants(level, subject, None, 0.01)
        knee_constants = constants_of(subject, calibration[level])
        for knee_deg in (10.0, 50.0, 85.0):
            record = _record(model, knee_deg)._replace(
                lengthening_speed=rng.normal(0.0, 1.5, len(SPASTIC_MUSCLES))
            )
            got, memory = reflex.excite(constants, (), record)
            assert memory == ()
            theta = geometry.equivalent_knee_deg(record.fibre_length)
            vel = geometry.equivalent_knee_velocity_rad_s(record.lengthening_speed)
            flex, ext = terms(theta, vel, knee_constants, np.tanh)
            expected = np.where(np.asarray(geometry.slope_per_rad) < 0.0, flex, ext)
            np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12)


def test_it_excites_each_muscle_on_its_own_stretch(seated) -> None:
    model, geometry = seated
    reflex = SpindleReflex(calibration=CALIBRATION, geometry=geometry)
    stage = SpasticityStage(3, subject_noise=False, reflex=reflex)
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=10.0)
    mujoco.mj_forward(model, data)
    host = StageHost(model, data, 0.01)
    stage.reset(host)
    ctrl = stage.apply(host, np.zeros(model.nu))
    exc = stage.last_excitations
    assert exc.shape == (len(SPASTIC_MUSCLES),)
    assert len(set(np.round(exc, 6))) > 2  # per muscle, not one value per group
    assert np.isfinite(ctrl).all()
    # seated near extension the stretched hamstrings fire more than the slack vasti
    by_name = dict(zip(SPASTIC_MUSCLES, exc, strict=True))
    assert min(by_name[n] for n in HAMSTRINGS) > max(by_name[n] for n in ("vasmed_r", "vasint_r"))


@pytest.mark.parametrize(
    ("name", "reflex_class", "knee_class"),
    [("spindle", SpindleReflex, StretchReflex), ("spindle_tsrt", SpindleTSRTReflex, TSRTReflex)],
)
def test_registered_and_reads_only_the_record(name, reflex_class, knee_class) -> None:
    assert name in reflex_names()
    model = get_reflex(name)
    assert isinstance(model, reflex_class) and isinstance(model, knee_class)
    with pytest.raises(NotImplementedError, match="SensoryRecord"):
        model.step((), (), 10.0, 0.0)
    assert dataclasses.replace(model, delay_s=0.03).delay_s == 0.03


def test_a_refit_that_differs_in_the_last_digits_records_the_same_parameters():
    """A policy's recorded reflex parameters match today's within floating-point noise (a
    re-fit of the same geometry on another MuJoCo build), not a real change."""
    import copy

    from myoexo.spasticity.registry import reflex_parameter_changes, reflex_parameters

    recorded = copy.deepcopy(reflex_parameters("spindle"))
    assert reflex_parameter_changes(recorded, "spindle") == []
    slopes = recorded["geometry"]["slope_per_rad"]
    slopes[2] *= 1.0 + 1e-14
    assert reflex_parameter_changes(recorded, "spindle") == []
    slopes[2] *= 1.001
    (change,) = reflex_parameter_changes(recorded, "spindle")
    assert change.startswith("geometry.slope_per_rad:")


# ----------------------------------------------------------------------------- spindle_tsrt
def test_spindle_tsrt_fires_on_a_fast_stretch_of_the_hamstrings_only_where_stretched(
    seated,
) -> None:
    """A fast extension (hamstrings lengthening at 3 rad/s of knee motion) excites the
    hamstrings seated, where they are long, and hardly reclined, where the hip slackens
    them: the dynamic threshold is a fibre length."""
    model, geometry = seated
    reflex = SpindleTSRTReflex(calibration=TSRT_CALIBRATION, geometry=geometry)
    constants = reflex.subject_constants(2, LEVELS[2], None, 0.01)
    ham = [SPASTIC_MUSCLES.index(n) for n in HAMSTRINGS]
    reclined, _ = build_model(TwinParams(hip_flexion_deg=40.0, scene=False))
    fired = {}
    for name, m in (("seated", model), ("reclined", reclined)):
        record = _record(m, 30.0)
        speed = -3.0 * np.asarray(geometry.slope_per_rad)  # knee extending at 3 rad/s
        at_rest, _ = reflex.excite(constants, (), record)
        fast, _ = reflex.excite(constants, (), record._replace(lengthening_speed=speed))
        fired[name] = float(np.mean(np.asarray(fast)[ham] - np.asarray(at_rest)[ham]))
    assert fired["seated"] > 0.1
    assert fired["reclined"] < 0.25 * fired["seated"], fired
