"""The knee exoskeleton: load the MJCF fragment, fit it to the leg, close the strap loop.

:func:`exo_spec` reads ``myoexo/assets/exo_knee.xml`` and rewrites its positions, axes,
ranges, springs, friction, masses and inertias from :class:`~myoexo.model.params.TwinParams`
and the :class:`~myoexo.model.geometry.ExoGeometry` fitted to the human knee. The result is
attached to the thigh body by ``ModelBuilder.attach_spec``; :func:`strap_to_shank` then adds
the site on the tibia and the soft weld that closes the loop (the strap).

Every exo body frame has the thigh frame's orientation at the reference pose, so a body's
position is the difference of two thigh-frame points of the geometry.
"""

from __future__ import annotations

from collections.abc import Callable
from importlib import resources

import mujoco
import numpy as np

from myoexo.model.geometry import ExoGeometry
from myoexo.model.joint_torque import CoupledJointTorque, EqualityJointTorque
from myoexo.model.params import TwinParams

__all__ = [
    "COUPLING_JOINTS",
    "CUFF_SENSORS",
    "EXO_ACTUATOR",
    "EXO_JOINT",
    "EXO_JOINTS",
    "EXO_SENSORS",
    "STRAP_EQUALITY",
    "STRAP_SITES",
    "exo_fragment_path",
    "exo_spec",
    "strap_knee_torque",
    "strap_to_shank",
]

#: Actuated exo hinge (rad; 0 = extended, flexion positive).
EXO_JOINT = "exo_knee"
#: Exo torque motor (last actuator of the twin; actuator force in Nm).
EXO_ACTUATOR = "exo_motor"
#: Passive coupling joints (paper: slide + 2 pins; myoexo adds two soft-tissue pins at
#: the shank cuff that follow the tibia's coupled ab/adduction and axial rotation).
COUPLING_JOINTS: tuple[str, ...] = (
    "exo_thigh_slide",
    "exo_thigh_pin",
    "exo_shank_pin",
    "exo_shank_abduction",
    "exo_shank_axial",
)
#: All exo joints, in tree order.
EXO_JOINTS: tuple[str, ...] = ("exo_thigh_slide", "exo_thigh_pin", EXO_JOINT, *COUPLING_JOINTS[2:])
#: Cuff force/torque sensors (3-D, in the cuff site frames) -> unit suffix of their readings
#: (``n``: N, ``nm``: Nm); the env observes each as ``<sensor>_<unit>``.
CUFF_SENSORS: dict[str, str] = {
    "thigh_cuff_force": "n",
    "thigh_cuff_torque": "nm",
    "shank_cuff_force": "n",
    "shank_cuff_torque": "nm",
}
#: All exo sensors.
EXO_SENSORS: tuple[str, ...] = ("exo_knee_pos", "exo_knee_vel", "exo_motor_torque", *CUFF_SENSORS)
#: Weld equality of the shank strap and its two sites (cuff side, tibia side).
STRAP_EQUALITY = "shank_strap"
STRAP_SITES: tuple[str, str] = ("exo_shank_strap", "tibia_strap")


def strap_knee_torque(model: mujoco.MjModel) -> EqualityJointTorque:
    """The torque the shank strap transmits to the human knee, along its coupled motion (Nm,
    flexion positive): the interaction torque the envs, the criteria and the reward read
    (``myoexo.envs``: ``interaction_torque_nm`` is its magnitude). Call it with the data and
    the knee angle its constraint forces were computed at."""
    from myoexo.model.leg import KNEE_JOINT

    return EqualityJointTorque(model, STRAP_EQUALITY, CoupledJointTorque(model, KNEE_JOINT))


def exo_fragment_path() -> str:
    """Absolute path of the exo MJCF fragment shipped with myoexo."""
    return str(resources.files("myoexo") / "assets" / "exo_knee.xml")


def _range_rad(range_deg: tuple[float, float]) -> np.ndarray:
    return np.radians(np.asarray(range_deg, dtype=float))


def _soft_joint(
    spec: mujoco.MjSpec,
    name: str,
    axis: np.ndarray,
    joint_range: np.ndarray,
    stiffness: float,
    damping: float,
    armature: float | None = None,
) -> mujoco.MjsJoint:
    """Set a coupling joint's axis, range, soft-tissue spring/damper (SI units: N/m or
    Nm/rad, N s/m or Nm s/rad) and, if given, armature (kg m^2), and return it."""
    joint = spec.joint(name)
    joint.axis = axis
    joint.range = joint_range
    joint.stiffness = np.array([stiffness, 0.0, 0.0])
    joint.damping = np.array([damping, 0.0, 0.0])
    if armature is not None:
        joint.armature = armature
    return joint


def _rod_inertia(mass_kg: float, length_m: float, radius_m: float) -> np.ndarray:
    """Principal inertia (kg m^2) of a rod along the body y axis (x, y, z order)."""
    transverse = mass_kg * (length_m**2 / 12.0 + radius_m**2 / 4.0)
    return np.array([transverse, 0.5 * mass_kg * radius_m**2, transverse])


def _shell_inertia(mass_kg: float, radius_m: float, height_m: float) -> np.ndarray:
    """Principal inertia (kg m^2) of a thin cylindrical shell along y (x, y, z order)."""
    transverse = mass_kg * (radius_m**2 / 2.0 + height_m**2 / 12.0)
    return np.array([transverse, mass_kg * radius_m**2, transverse])


def exo_spec(params: TwinParams, geometry: ExoGeometry) -> mujoco.MjSpec:
    """Load the exo fragment and fit it to ``geometry`` and ``params``.

    Args:
        params: Twin parameters (ranges, springs, friction, masses, motor limit).
        geometry: Exo layout in the thigh frame (from :func:`~myoexo.model.geometry.exo_geometry`).

    Returns:
        The exo spec, ready to be attached at the origin of the thigh body.
    """
    spec = mujoco.MjSpec.from_file(exo_fragment_path())
    g = geometry
    bar_radius_m = 0.012

    cuff = spec.body("exo_thigh_cuff")
    cuff.pos = g.thigh_cuff_m
    cuff.mass = params.thigh_cuff_mass_kg
    cuff.inertia = _shell_inertia(
        params.thigh_cuff_mass_kg, params.cuff_radius_m, params.cuff_height_m
    )
    cuff.ipos = np.zeros(3)
    shell = spec.geom("exo_thigh_cuff_shell")
    shell.size = np.array([params.cuff_radius_m, params.cuff_height_m / 2.0, 0.0])

    thigh_link = spec.body("exo_thigh_link")
    thigh_link.pos = g.thigh_pin_m - g.thigh_cuff_m
    thigh_bar = g.exo_knee_m - g.thigh_pin_m
    thigh_len = float(np.linalg.norm(thigh_bar))
    # Upper exo: bar plus motor and gearbox at the hinge; centre of mass 2/3 down the bar.
    thigh_link.mass = params.exo_thigh_mass_kg
    thigh_link.ipos = thigh_bar * (2.0 / 3.0)
    thigh_link.inertia = _rod_inertia(params.exo_thigh_mass_kg, thigh_len, bar_radius_m)
    spec.geom("exo_thigh_bar").fromto = np.concatenate([np.zeros(3), thigh_bar])
    spec.geom("exo_thigh_pin_housing").quat = _quat_z_to(g.knee_axis)

    slide = spec.joint("exo_thigh_slide")
    slide.axis = g.slide_axis
    slide.range = np.asarray(params.thigh_slide_range_m, dtype=float)
    slide.frictionloss = params.slide_frictionloss_n
    slide.damping = np.array([params.thigh_slide_damping_n_s_m, 0.0, 0.0])
    slide.stiffness = np.array([params.thigh_slide_stiffness_n_m, 0.0, 0.0])
    pin_spring = (
        params.pin_stiffness_nm_rad,
        params.pin_damping_nm_s_rad,
        params.pin_armature_kg_m2,
    )
    _soft_joint(
        spec, "exo_thigh_pin", g.knee_axis, _range_rad(params.thigh_pin_range_deg), *pin_spring
    )

    shank_link = spec.body("exo_shank_link")
    shank_link.pos = g.exo_knee_m - g.thigh_pin_m
    shank_bar = g.shank_pin_m - g.exo_knee_m
    shank_len = float(np.linalg.norm(shank_bar))
    shank_link.mass = params.exo_shank_mass_kg
    shank_link.ipos = shank_bar * 0.5
    shank_link.inertia = _rod_inertia(params.exo_shank_mass_kg, shank_len, bar_radius_m)
    spec.geom("exo_shank_bar").fromto = np.concatenate([np.zeros(3), shank_bar])
    spec.geom("exo_motor_housing").quat = _quat_z_to(g.knee_axis)

    knee = spec.joint(EXO_JOINT)
    knee.axis = g.knee_axis
    knee.range = _range_rad(params.exo_knee_range_deg)
    knee.damping = np.array([params.exo_knee_damping_nm_s_rad, 0.0, 0.0])
    knee.armature = params.exo_knee_armature_kg_m2

    shank_cuff = spec.body("exo_shank_cuff")
    shank_cuff.pos = g.shank_cuff_m - g.exo_knee_m
    shank_cuff.mass = params.shank_cuff_mass_kg
    shank_cuff.ipos = np.zeros(3)
    shank_cuff.inertia = _shell_inertia(
        params.shank_cuff_mass_kg, params.cuff_radius_m, params.cuff_height_m
    )
    spec.geom("exo_shank_cuff_shell").size = np.array(
        [params.cuff_radius_m, params.cuff_height_m / 2.0, 0.0]
    )
    bracket = spec.geom("exo_shank_cuff_bracket")
    bracket.pos = (g.shank_pin_m - g.shank_cuff_m) * 0.85
    shank_pin = _soft_joint(
        spec, "exo_shank_pin", g.knee_axis, _range_rad(params.shank_pin_range_deg), *pin_spring
    )
    shank_pin.pos = g.shank_pin_m - g.shank_cuff_m
    rotation_spring = (params.shank_rotation_stiffness_nm_rad, params.coupling_damping_nm_s_rad)
    abduction = _soft_joint(
        spec,
        "exo_shank_abduction",
        g.abduction_axis,
        _range_rad(params.shank_abduction_range_deg),
        *rotation_spring,
    )
    abduction.pos = g.tibia_origin_m - g.shank_cuff_m
    _soft_joint(
        spec,
        "exo_shank_axial",
        g.axial_axis,
        _range_rad(params.shank_axial_range_deg),
        *rotation_spring,
    )

    motor = spec.actuator(EXO_ACTUATOR)
    gain = np.zeros(len(motor.gainprm))
    gain[0] = params.motor_limit_nm
    motor.gainprm = gain
    motor.gear = np.array([1.0, 0, 0, 0, 0, 0])
    motor.forcerange = np.array([-params.motor_limit_nm, params.motor_limit_nm])
    return spec


def _quat_z_to(direction: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) rotating the z axis onto ``direction``."""
    z = np.array([0.0, 0.0, 1.0])
    d = np.asarray(direction, dtype=float) / np.linalg.norm(direction)
    cross = np.cross(z, d)
    w = 1.0 + float(np.dot(z, d))
    if w < 1e-9:  # opposite: half turn about x
        return np.array([0.0, 1.0, 0.0, 0.0])
    quat = np.concatenate([[w], cross])
    return quat / np.linalg.norm(quat)


def strap_to_shank(
    params: TwinParams, geometry: ExoGeometry
) -> Callable[[mujoco.MjSpec], mujoco.MjSpec]:
    """Return a ``ModelBuilder`` transform that straps the shank cuff to the shank.

    Adds the site ``tibia_strap`` on the shank body where the cuff's ``exo_shank_strap``
    site is at the reference pose, and a site-to-site weld between them whose
    ``solref``/``solimp`` (``params.strap_solref``/``strap_solimp``) model the soft tissue
    under the strap. With the thigh cuff rigid on the thigh (the exo's root), this weld
    closes the human-exo loop.

    Args:
        params: Twin parameters.
        geometry: Exo layout (shank cuff centre and tibia origin, thigh frame).

    Returns:
        A function ``spec -> spec`` that edits the spec in place and returns it.
    """

    def transform(spec: mujoco.MjSpec) -> mujoco.MjSpec:
        shank = spec.body(params.shank_body)
        site = shank.add_site()
        site.name = STRAP_SITES[1]
        site.pos = geometry.shank_cuff_m - geometry.tibia_origin_m
        site.group = 3
        site.size = np.array([0.01, 0.0, 0.0])
        eq = spec.add_equality()
        eq.name = STRAP_EQUALITY
        eq.type = mujoco.mjtEq.mjEQ_WELD
        eq.objtype = mujoco.mjtObj.mjOBJ_SITE
        eq.name1, eq.name2 = STRAP_SITES
        data = np.zeros(len(eq.data))
        data[6] = 1.0  # relative quaternion (unused for sites) kept valid
        data[10] = 1.0  # torquescale: the strap resists rotation like translation (per m)
        eq.data = data
        eq.solref = np.asarray(params.strap_solref, dtype=float)
        eq.solimp = np.asarray(params.strap_solimp, dtype=float)
        return spec

    return transform
