"""The passive knee: Riener and Edrich's measured moment built into the model as springs,
the knee damped at its own value, the muscles' passive fibres off at the knee only, and the
healthy pendulum it gives."""

from __future__ import annotations

import dataclasses
import math

import mujoco
import numpy as np
import pytest

from myoexo.clinical.pendulum import (
    FREED_EXO_RANGE_DEG,
    HEALTHY_FIRST_SWING_VELOCITY_SUPINE_RAD_S,
    RECLINED,
    SUPINE,
    run_pendulum,
)
from myoexo.model import KNEE_JOINT, TwinParams, build_model, pose_twin
from myoexo.model.joint_torque import CoupledJointTorque
from myoexo.model.passive_knee import (
    KNEE_MUSCLES,
    KNEE_SPRING_TENDONS,
    RIENER_EDRICH_1999,
    knee_springs,
)

#: Kim, Chon, Park and Choi 1996: healthy adults' relaxation index, mean and SD.
KIM_RELAXATION_INDEX = (1.678, 0.090)
#: The same adults' second-swing velocity, rad/s.
KIM_SECOND_SWING_RAD_S = (3.076, 0.551)


def _relaxed_knee_moment_nm(model: mujoco.MjModel, knee_deg: float) -> float:
    """The knee's passive moment (Nm, flexing positive) with every muscle at rest: the
    muscles' passive forces and the springs, along the coupled knee motion."""
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=knee_deg)
    data.act[:] = 0.0
    mujoco.mj_forward(model, data)
    knee = CoupledJointTorque(model, KNEE_JOINT)
    qadr = model.jnt_qposadr[model.joint(KNEE_JOINT).id]
    return knee.torque_at(float(data.qpos[qadr]), data.qfrc_actuator + data.qfrc_spring)


@pytest.mark.parametrize("hip_deg", [40.0, 90.0])
def test_springs_fit_the_published_moment(hip_deg: float) -> None:
    springs = knee_springs(hip_deg)
    knee_deg = np.linspace(0.0, 120.0, 121)
    error = springs.moment_nm(knee_deg) - RIENER_EDRICH_1999.moment_nm(knee_deg, hip_deg)
    assert np.abs(error).max() < 0.25
    assert springs.max_error_nm == pytest.approx(np.abs(error).max(), abs=0.05)


@pytest.mark.parametrize("hip_deg", [40.0, 90.0])
def test_model_knee_carries_the_published_moment(hip_deg: float) -> None:
    model, _ = build_model(TwinParams(hip_flexion_deg=hip_deg, scene=False))
    for knee_deg in (5.0, 30.0, 60.0, 100.0):
        measured = _relaxed_knee_moment_nm(model, knee_deg)
        published = float(RIENER_EDRICH_1999.moment_nm(knee_deg, hip_deg))
        assert measured == pytest.approx(published, abs=0.3), knee_deg


def test_the_moment_depends_on_the_hip() -> None:
    # hip flexion stretches the hamstrings: more flexing moment near extension
    seated = float(RIENER_EDRICH_1999.moment_nm(10.0, 90.0))
    reclined = float(RIENER_EDRICH_1999.moment_nm(10.0, 40.0))
    assert seated > reclined + 15.0


def test_knee_muscles_are_the_muscles_with_a_knee_moment_arm() -> None:
    model, _ = build_model(TwinParams(scene=False))
    data = mujoco.MjData(model)
    pose_twin(model, data, knee_angle_deg=45.0)
    moment = np.zeros((model.nu, model.nv))
    mujoco.mju_sparse2dense(
        moment, data.actuator_moment, data.moment_rownnz, data.moment_rowadr, data.moment_colind
    )
    dof = model.jnt_dofadr[model.joint(KNEE_JOINT).id]
    crossing = {
        model.actuator(i).name
        for i in range(model.nu)
        if model.actuator_dyntype[i] == mujoco.mjtDyn.mjDYN_MUSCLE and abs(moment[i, dof]) > 1e-6
    }
    assert crossing == set(KNEE_MUSCLES)


def test_knee_muscles_keep_their_active_force_and_lose_their_passive_one() -> None:
    new, _ = build_model(TwinParams(scene=False))
    old, _ = build_model(TwinParams.of_version(2, scene=False))
    for name in KNEE_MUSCLES:
        a, b = new.actuator(name).id, old.actuator(name).id
        assert new.actuator_biasprm[a, 7] < 1e-5 < old.actuator_biasprm[b, 7]
        np.testing.assert_array_equal(new.actuator_gainprm[a, :7], old.actuator_gainprm[b, :7])
    soleus = new.actuator("soleus_r").id
    assert new.actuator_biasprm[soleus, 7] == old.actuator_biasprm[old.actuator("soleus_r").id, 7]


def test_knee_flexion_is_damped_at_its_own_value() -> None:
    model, _ = build_model(TwinParams(knee_damping_nm_s_rad=0.25, scene=False))
    knee = CoupledJointTorque(model, KNEE_JOINT)
    assert model.dof_damping[model.jnt_dofadr[model.joint(KNEE_JOINT).id]] == 0.25
    assert np.all(model.dof_damping[knee.dependent_dofs] == 0.0)
    for name in KNEE_SPRING_TENDONS:
        assert model.tendon(name).id >= 0


def test_earlier_twins_keep_the_muscles_passive_knee() -> None:
    model, _ = build_model(TwinParams.of_version(2, scene=False))
    names = {model.tendon(i).name for i in range(model.ntendon)}
    assert not names & set(KNEE_SPRING_TENDONS)
    assert model.dof_damping[model.jnt_dofadr[model.joint(KNEE_JOINT).id]] == 0.5


def test_unknown_passive_knee_is_refused() -> None:
    with pytest.raises(ValueError, match="passive_knee = 'rigid'; accepted"):
        TwinParams(passive_knee="rigid")
    with pytest.raises(ValueError, match="knee_damping_nm_s_rad must be >= 0"):
        TwinParams(knee_damping_nm_s_rad=-0.1)


def test_healthy_pendulum_relaxation_index_is_kims() -> None:
    params = dataclasses.replace(RECLINED, levels=(0,))
    twin = TwinParams(exo_knee_range_deg=FREED_EXO_RANGE_DEG)
    row = run_pendulum(params, twin=twin).summary.iloc[0]
    mean, sd = KIM_RELAXATION_INDEX
    assert abs(row["relaxation_index"] - mean) <= 2.0 * sd
    # the earlier twin's passive knee, too stiff and too damped, stays below the range
    earlier = TwinParams.of_version(2, exo_knee_range_deg=FREED_EXO_RANGE_DEG)
    old = run_pendulum(params, twin=earlier)
    assert old.summary.iloc[0]["relaxation_index"] < mean - 2.0 * sd
    assert math.isfinite(row["second_peak_velocity_deg_s"])


def test_healthy_supine_pendulum_lies_within_kims_two_sd() -> None:
    """Kim et al. tested healthy adults supine: in that posture (hip extended, the hamstrings
    slack) the freed twin's index and both swing velocities lie within 2 SD; reclined at hip
    40 deg the stretched hamstrings pull the released shank faster than their first swing."""
    twin = TwinParams(exo_knee_range_deg=FREED_EXO_RANGE_DEG)
    supine = run_pendulum(dataclasses.replace(SUPINE, levels=(0,)), twin=twin).summary.iloc[0]
    assert supine["release_deg"] < 2.0
    for value, (mean, sd) in (
        (supine["relaxation_index"], KIM_RELAXATION_INDEX),
        (math.radians(supine["peak_velocity_deg_s"]), HEALTHY_FIRST_SWING_VELOCITY_SUPINE_RAD_S),
        (math.radians(supine["second_peak_velocity_deg_s"]), KIM_SECOND_SWING_RAD_S),
    ):
        assert abs(value - mean) <= 2.0 * sd, (value, mean, sd)
    reclined = run_pendulum(dataclasses.replace(RECLINED, levels=(0,)), twin=twin).summary
    mean, sd = HEALTHY_FIRST_SWING_VELOCITY_SUPINE_RAD_S
    assert math.radians(reclined.iloc[0]["peak_velocity_deg_s"]) > mean + 2.0 * sd
