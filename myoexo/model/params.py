"""Parameters of the human + knee-exoskeleton digital twin (one frozen dataclass).

Every number that shapes the twin lives in :class:`TwinParams`, with the paper's values as
defaults where the paper gives them (``paper.tex`` section "Human MS system with Exo
coupling"; docs/reference.md section 1) and documented, physically plausible choices elsewhere.

Conventions
-----------
* Angles are in degrees in this dataclass (``*_deg``) and converted to radians when the
  MuJoCo model is built; MuJoCo joints are in radians.
* Knee angles (human ``knee_angle_r`` and exo ``exo_knee``): 0 = full extension, flexion
  positive.
* Coupling joints are at 0 in the model's reference configuration (human knee extended),
  where the exo is assembled without strain.

Slide friction (paper: "linear friction coefficient eta = 0.97")
----------------------------------------------------------------
The paper gives the thigh slider an efficiency-like coefficient eta = 0.97 without units.
myoexo reads it as a transmission efficiency: the slider loses ``1 - eta`` (3 %) of the
nominal strap load it carries. MuJoCo models dry (Coulomb) joint friction with
``frictionloss``, so::

    frictionloss_N = (1 - eta) * nominal_strap_force_N
    nominal_strap_force_N = motor_limit_nm / thigh_cuff_distance_m

i.e. the force at the thigh cuff when the motor delivers its limit torque over the cuff's
lever arm (100 Nm / 0.2 m = 500 N, hence 15 N of slider friction). A small viscous
``thigh_slide_damping_n_s_m`` is added on top for numerical smoothness.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields
from typing import Any

__all__ = [
    "EARLIER_TWINS",
    "PASSIVE_KNEE_MODELS",
    "TWIN_VERSION",
    "TwinParams",
    "recorded_twin_version",
]

#: Version of the default twin's physics, recorded in every evaluation folder and result set
#: (``twin_version``); results without it were measured on version 1. CHANGELOG.md says what
#: each version changed. 2: the sagittal cuff pins are damped (``pin_damping_nm_s_rad``) and
#: carry an armature (``pin_armature_kg_m2``). 3: the passive knee is Riener and Edrich's
#: measured moment with a knee damping of its own (``passive_knee``,
#: ``knee_damping_nm_s_rad``; :mod:`myoexo.model.passive_knee`). 4: the exo drive brakes
#: before its end stops (``exo_stop_braking_fraction``, :mod:`myoexo.model.drive`).
TWIN_VERSION = 4

#: The fields that give an earlier twin version's physics (:meth:`TwinParams.of_version`), so
#: that a result or a policy of that version can be reproduced on the twin it was made on.
EARLIER_TWINS: dict[int, dict[str, float | str]] = {
    1: {
        "pin_damping_nm_s_rad": 1.0,
        "pin_armature_kg_m2": 0.001,
        "passive_knee": "muscles",
        "knee_damping_nm_s_rad": 0.5,
        "exo_stop_braking_fraction": 0.0,
    },
    2: {
        "passive_knee": "muscles",
        "knee_damping_nm_s_rad": 0.5,
        "exo_stop_braking_fraction": 0.0,
    },
    3: {"exo_stop_braking_fraction": 0.0},
}


#: The passive knee models (``TwinParams.passive_knee``): ``"muscles"``, the MyoSuite
#: muscles' passive fibres with MyoSuite's damping on every knee coordinate (twins 1-2);
#: ``"riener_edrich"``, :mod:`myoexo.model.passive_knee`.
PASSIVE_KNEE_MODELS: tuple[str, ...] = ("muscles", "riener_edrich")


def recorded_twin_version(record: Mapping[str, Any]) -> int:
    """The twin version a record (a result set's meta, an evaluation's config, a policy's
    metadata) was made on: its ``twin_version``, or 1 for a record made before versions."""
    return int(record.get("twin_version", 1))


def _check_range(name: str, value: tuple[float, float], *, contains_zero: bool) -> None:
    """Raise ``ValueError`` unless ``value`` is an increasing (lower, upper) pair."""
    if len(value) != 2 or not all(math.isfinite(float(v)) for v in value):
        raise ValueError(f"TwinParams.{name} must be a finite (lower, upper) pair, got {value!r}")
    lo, hi = float(value[0]), float(value[1])
    if not lo < hi:
        raise ValueError(
            f"TwinParams.{name} must satisfy lower < upper (a positive-width range), got {value!r}"
        )
    if contains_zero and not lo < 0.0 < hi:
        raise ValueError(
            f"TwinParams.{name} must contain 0 (the strain-free assembly pose) strictly "
            f"inside, got {value!r}"
        )


@dataclass(frozen=True)
class TwinParams:
    """All parameters of the seated human + knee-exoskeleton twin.

    Attributes:
        timestep_s: Physics timestep (s). 2 ms is stable and accurate with the 40 muscles
            and the soft strap equalities (see ``benchmarks/bench_physics.py``); the
            envs reach their control rate with a frame skip.
        hip_flexion_deg: Locked right-hip flexion (deg); 90 = thigh horizontal (paper).
        hip_adduction_deg: Locked right-hip adduction (deg).
        hip_rotation_deg: Locked right-hip rotation (deg).
        hip_lock_solref: ``solref`` (time constant s, damping ratio) of the joint
            equalities that lock the hip.
        hip_lock_solimp: ``solimp`` of the hip-lock equalities (stiff: the hip is fixed).
        hip_height_m: Height of the pelvis origin above the world origin (m); the subject
            sits facing +x with +z up. Visual only: the twin has no floor.
        passive_knee: Where the relaxed knee's passive moment comes from:
            ``"riener_edrich"`` (Riener and Edrich 1999's measured moment at the locked
            hip, built as springs; the knee muscles' passive fibres off;
            :mod:`myoexo.model.passive_knee`) or ``"muscles"`` (the MyoSuite muscles'
            passive fibres, twins 1-2).
        knee_damping_nm_s_rad: Viscous damping of the knee flexion (Nm s/rad). With
            ``"riener_edrich"`` it is the flexion's only damping (the knee's dependent
            coordinates are undamped); with ``"muscles"`` it is ``knee_angle_r``'s own,
            MyoSuite's 0.5 on every knee coordinate.
        thigh_body: Human body the thigh cuff is strapped to.
        shank_body: Human body the shank cuff is strapped to.
        exo_knee_range_deg: Exo knee hinge range (deg), paper [-15, 95].
        thigh_slide_range_m: Thigh cuff slider range (m), paper +-0.02.
        thigh_pin_range_deg: Thigh cuff pin ("crank") range (deg), paper +-15.
        shank_pin_range_deg: Shank cuff pin range (deg), paper +-15.
        shank_axial_range_deg: Shank cuff axial pin range (deg). Not in the paper: it
            leaves the tibia's coupled axial rotation (``knee_angle_rotation3_r``,
            ~15 deg over the flexion range) free; without it the knee is locked near
            extension (docs/reference.md section 1).
        shank_abduction_range_deg: Shank cuff ab/adduction pin range (deg). Not in the
            paper: it follows the tibia's coupled ab/adduction
            (``knee_angle_rotation2_r``, up to ~2 deg, i.e. ~7 mm sideways at the cuff),
            which the exo's sagittal joints cannot, so the strap is not preloaded.
        slide_efficiency: Slider efficiency eta (paper 0.97); see the module docstring for
            the mapping to MuJoCo ``frictionloss``.
        thigh_slide_damping_n_s_m: Viscous damping of the slider (N s/m).
        thigh_slide_stiffness_n_m: Soft-tissue stiffness of the slider (N/m) towards its
            strain-free position. The paper's coupling DOF "simulate the relative movement
            of the exoskeleton due to human soft tissue compliance"; cuff shear stiffness
            of tens of kN/m is typical of strapped thigh cuffs.
        pin_stiffness_nm_rad: Soft-tissue rotational stiffness of each sagittal cuff pin
            (Nm/rad) towards its strain-free angle.
        shank_rotation_stiffness_nm_rad: Rotational stiffness of the shank cuff's axial and
            ab/adduction pins (Nm/rad); small, so the tibia's coupled axial rotation and
            ab/adduction stay nearly free.
        pin_damping_nm_s_rad: Viscous damping of each sagittal cuff pin (Nm s/rad): the
            soft tissue under a cuff is viscoelastic. 20 Nm s/rad damps the pins' mode
            (``pin_stiffness_nm_rad`` against the lower exo's inertia about its hinge, about
            0.030 kg m^2 with the drive's armature) at a damping ratio of about 1.3, so the
            strap passes the motor's torque on without ringing (docs/twin.md, "Straps").
            With 1 Nm s/rad (ratio 0.06) a stiff encoder-feedback PID drove the pins into
            their stops and the strap torque to 900 Nm with a 100 Nm motor.
        pin_armature_kg_m2: Armature (numerical rotor inertia) of each sagittal cuff pin
            (kg m^2). The shank pin's spring on the 0.2 kg cuff alone (1.5e-3 kg m^2 about
            the pin) has ``omega h`` = 2.3 at the 2 ms timestep, past the explicit limit 2;
            with the pins damped, the strap weld and the pins then chattered at some
            perturbed twins (``tests/test_stability.py``). 4e-3 brings ``omega h`` to 1.3
            (1.0 at the perturbed twin's stiffest straps, whose armature scales with them):
            13 % of the lower exo's inertia about its hinge.
        coupling_damping_nm_s_rad: Viscous damping of the shank cuff's axial and
            ab/adduction pins (Nm s/rad).
        strap_solref: ``solref`` (time constant s, damping ratio) of the strap equality
            (weld) that closes the exo loop on the shank: soft tissue under the strap.
        strap_solimp: ``solimp`` (dmin, dmax, width m, midpoint, power) of the strap weld.
        thigh_cuff_distance_m: Distance of the thigh cuff centre above the knee axis,
            along the femur (m).
        shank_cuff_distance_m: Distance of the shank cuff centre below the knee, along the
            tibia's axial-rotation axis (m).
        exo_lateral_offset_m: Lateral distance of the exo bars and hinge from the knee's
            mid-plane (m).
        knee_axis_fit_range_deg: Human knee range over which the exo hinge is placed on
            the knee's mean (least-squares) flexion axis (deg).
        motor_limit_nm: Exo motor peak torque (Nm), paper 100; ctrl in [-1, 1] maps to
            [-motor_limit_nm, motor_limit_nm].
        exo_knee_damping_nm_s_rad: Viscous damping of the exo hinge (Nm s/rad).
        exo_knee_armature_kg_m2: Reflected rotor inertia of the exo drive (kg m^2).
        exo_stop_braking_fraction: The share of the motor's authority the drive's end-stop
            protection plans to brake with (:mod:`myoexo.model.drive`; 0: no protection,
            twins 1-3). 0.5 leaves the other half for the leg's own torques.
        exo_stop_contact_speed_rad_s: The speed at which the drive lets the exo hinge touch
            a stop, rad/s.
        thigh_cuff_mass_kg: Thigh cuff + strap mass (kg).
        exo_thigh_mass_kg: Upper exo frame (bar, motor and gearbox) mass (kg).
        exo_shank_mass_kg: Lower exo frame mass (kg).
        shank_cuff_mass_kg: Shank cuff + strap mass (kg).
        cuff_radius_m: Inner radius of the cuffs (m), for their inertia and visuals.
        cuff_height_m: Height of the cuffs along the limb (m).
        scene: Add the visual scene (floor, plinth under the thigh, lights, skybox; see
            :mod:`myoexo.model.scene`). Visual only: the dynamics are the same without it.
            The named cameras are there either way.
    """

    timestep_s: float = 0.002

    hip_flexion_deg: float = 90.0
    hip_adduction_deg: float = 0.0
    hip_rotation_deg: float = 0.0
    hip_lock_solref: tuple[float, float] = (0.005, 1.0)
    hip_lock_solimp: tuple[float, float, float, float, float] = (0.99, 0.999, 0.001, 0.5, 2.0)
    hip_height_m: float = 0.55

    passive_knee: str = "riener_edrich"
    knee_damping_nm_s_rad: float = 0.1

    thigh_body: str = "femur_r"
    shank_body: str = "tibia_r"

    exo_knee_range_deg: tuple[float, float] = (-15.0, 95.0)
    thigh_slide_range_m: tuple[float, float] = (-0.02, 0.02)
    thigh_pin_range_deg: tuple[float, float] = (-15.0, 15.0)
    shank_pin_range_deg: tuple[float, float] = (-15.0, 15.0)
    shank_abduction_range_deg: tuple[float, float] = (-5.0, 5.0)
    shank_axial_range_deg: tuple[float, float] = (-20.0, 20.0)

    slide_efficiency: float = 0.97
    thigh_slide_damping_n_s_m: float = 50.0
    thigh_slide_stiffness_n_m: float = 50_000.0
    pin_stiffness_nm_rad: float = 2_000.0
    shank_rotation_stiffness_nm_rad: float = 1.0
    pin_damping_nm_s_rad: float = 20.0
    pin_armature_kg_m2: float = 0.004
    coupling_damping_nm_s_rad: float = 1.0
    strap_solref: tuple[float, float] = (0.005, 1.0)
    strap_solimp: tuple[float, float, float, float, float] = (0.95, 0.99, 0.001, 0.5, 2.0)

    thigh_cuff_distance_m: float = 0.20
    shank_cuff_distance_m: float = 0.22
    exo_lateral_offset_m: float = 0.10
    knee_axis_fit_range_deg: tuple[float, float] = (0.0, 95.0)

    motor_limit_nm: float = 100.0
    exo_knee_damping_nm_s_rad: float = 0.5
    exo_knee_armature_kg_m2: float = 0.01
    exo_stop_braking_fraction: float = 0.5
    exo_stop_contact_speed_rad_s: float = 0.5

    thigh_cuff_mass_kg: float = 0.25
    exo_thigh_mass_kg: float = 1.0
    exo_shank_mass_kg: float = 0.6
    shank_cuff_mass_kg: float = 0.2
    cuff_radius_m: float = 0.065
    cuff_height_m: float = 0.06

    scene: bool = True

    def __post_init__(self) -> None:
        """Validate every field; raise ``ValueError`` naming the first bad one."""
        for name in (
            "exo_knee_range_deg",
            "thigh_slide_range_m",
            "thigh_pin_range_deg",
            "shank_pin_range_deg",
            "shank_abduction_range_deg",
            "shank_axial_range_deg",
        ):
            _check_range(name, getattr(self, name), contains_zero=True)
        _check_range("knee_axis_fit_range_deg", self.knee_axis_fit_range_deg, contains_zero=False)
        lo, hi = self.knee_axis_fit_range_deg
        if lo < 0.0 or hi > 120.0:
            raise ValueError(
                f"TwinParams.knee_axis_fit_range_deg must lie within the human knee range "
                f"[0, 120] deg, got {self.knee_axis_fit_range_deg!r}"
            )

        positive = (
            "timestep_s",
            "motor_limit_nm",
            "thigh_cuff_distance_m",
            "shank_cuff_distance_m",
            "exo_lateral_offset_m",
            "thigh_cuff_mass_kg",
            "exo_thigh_mass_kg",
            "exo_shank_mass_kg",
            "shank_cuff_mass_kg",
            "cuff_radius_m",
            "cuff_height_m",
        )
        for name in positive:
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ValueError(f"TwinParams.{name} must be > 0, got {value!r}")
        if self.timestep_s > 0.01:
            raise ValueError(
                f"TwinParams.timestep_s must be in (0, 0.01] s for the muscle dynamics, "
                f"got {self.timestep_s!r}"
            )

        non_negative = (
            "thigh_slide_damping_n_s_m",
            "thigh_slide_stiffness_n_m",
            "pin_stiffness_nm_rad",
            "pin_damping_nm_s_rad",
            "pin_armature_kg_m2",
            "shank_rotation_stiffness_nm_rad",
            "coupling_damping_nm_s_rad",
            "exo_knee_damping_nm_s_rad",
            "exo_knee_armature_kg_m2",
            "knee_damping_nm_s_rad",
            "exo_stop_contact_speed_rad_s",
        )
        for name in non_negative:
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f"TwinParams.{name} must be >= 0, got {value!r}")

        if not 0.0 <= self.exo_stop_braking_fraction <= 1.0:
            raise ValueError(
                f"TwinParams.exo_stop_braking_fraction must be in [0, 1], "
                f"got {self.exo_stop_braking_fraction!r}"
            )
        if not 0.0 < self.slide_efficiency <= 1.0:
            raise ValueError(
                f"TwinParams.slide_efficiency must be in (0, 1], got {self.slide_efficiency!r}"
            )
        if not 0.0 <= self.hip_flexion_deg <= 120.0:
            raise ValueError(
                f"TwinParams.hip_flexion_deg must be in [0, 120] deg (the model's hip range), "
                f"got {self.hip_flexion_deg!r}"
            )
        for name in ("hip_lock_solref", "strap_solref"):
            timeconst, dampratio = getattr(self, name)
            if not (timeconst > 0.0 and dampratio > 0.0):
                raise ValueError(
                    f"TwinParams.{name} must be (time constant > 0 s, damping ratio > 0), "
                    f"got {getattr(self, name)!r}"
                )
        for name in ("hip_lock_solimp", "strap_solimp"):
            dmin, dmax, width, mid, power = getattr(self, name)
            if not (0.0 < dmin <= dmax < 1.0 and width > 0.0 and 0.0 < mid < 1.0 and power >= 1):
                raise ValueError(
                    f"TwinParams.{name} must satisfy 0 < dmin <= dmax < 1, width > 0, "
                    f"0 < midpoint < 1, power >= 1, got {getattr(self, name)!r}"
                )
        if self.passive_knee not in PASSIVE_KNEE_MODELS:
            raise ValueError(
                f"TwinParams.passive_knee = {self.passive_knee!r}; accepted: "
                f"{list(PASSIVE_KNEE_MODELS)}"
            )
        for name in ("thigh_body", "shank_body"):
            if not isinstance(getattr(self, name), str) or not getattr(self, name):
                raise ValueError(f"TwinParams.{name} must be a non-empty body name")
        if not isinstance(self.scene, bool):
            raise ValueError(f"TwinParams.scene must be True or False, got {self.scene!r}")

    @property
    def misalignment_bound_deg(self) -> float:
        """How far the exo hinge may sit from the knee (deg): one sagittal cuff pin's range,
        the misalignment the coupling is built to absorb."""
        return min(
            max(abs(v) for v in self.thigh_pin_range_deg),
            max(abs(v) for v in self.shank_pin_range_deg),
        )

    @property
    def slide_frictionloss_n(self) -> float:
        """Coulomb friction of the thigh slider (N): ``(1 - eta) * nominal strap force``."""
        nominal_strap_force_n = self.motor_limit_nm / self.thigh_cuff_distance_m
        return (1.0 - self.slide_efficiency) * nominal_strap_force_n

    @classmethod
    def of_version(cls, version: int, **overrides: object) -> TwinParams:
        """The default parameters of twin *version* (:data:`TWIN_VERSION` or one of
        :data:`EARLIER_TWINS`), with *overrides* on top.

        Raises:
            ValueError: If *version* is neither.
        """
        if version == TWIN_VERSION:
            return cls(**overrides)  # type: ignore[arg-type]
        if version not in EARLIER_TWINS:
            raise ValueError(
                f"twin version {version!r} is unknown; known: "
                f"{sorted([*EARLIER_TWINS, TWIN_VERSION])}"
            )
        return cls(**{**EARLIER_TWINS[version], **overrides})  # type: ignore[arg-type]

    def as_dict(self) -> dict[str, object]:
        """Return the parameters as a plain ``dict`` (for logs and reports)."""
        return {f.name: getattr(self, f.name) for f in fields(self)}
