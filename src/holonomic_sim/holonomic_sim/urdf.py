"""URDF of a robot, generated from the same model the controller uses.

One source of geometry: wheel radius, offsets and joint limits come from the
:class:`~holonomic_core.model.RobotModel` (``model.kinematics`` and the
``body.*`` parameters), so the simulated robot and the controller cannot
disagree. Wheels are URDF cylinders rotated onto the y axis
(``rpy="1.5708 0 0"``), to be loaded with ``URDF_USE_IMPLICIT_CYLINDER`` so
that they stay true cylinders in Bullet. Every link has an ``<inertial>``
computed from its solid shape.

Frames and joints follow docs/conventions.md and REP 120's footprint convention: the
root link ``base_link`` has its origin *on the floor*, under the centre of the
base, so that the planar odom -> base_link transform draws the robot standing
on the floor of the odom frame (rviz, Foxglove). The body that carries the
payload (turret disc, chassis box) is base_link's own visual, collision and
inertial, raised by :func:`base_height`. pybullet reports a base at its
inertial frame, not at the URDF link origin: :mod:`holonomic_sim.world`
converts (``SimRobot.world_pose``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from xml.sax.saxutils import escape

#: vertical clearance between stacked bodies [m]
_GAP = 0.005
#: height [m] of the unloaded support ball above the floor
_BALL_CLEARANCE = 0.004
#: width [m] of the wheels' collision cylinders (see _wheel_shapes)
_CROWN = 0.002


@dataclass(frozen=True)
class Inertia:
    """Principal moments [kg m^2] of a solid about its centre, axes of its link."""

    ixx: float
    iyy: float
    izz: float

    @staticmethod
    def box(mass: float, lx: float, ly: float, lz: float) -> "Inertia":
        return Inertia(mass * (ly ** 2 + lz ** 2) / 12, mass * (lx ** 2 + lz ** 2) / 12,
                       mass * (lx ** 2 + ly ** 2) / 12)

    @staticmethod
    def cylinder_z(mass: float, radius: float, length: float) -> "Inertia":
        """Solid cylinder with its axis along z."""
        side = mass * (3 * radius ** 2 + length ** 2) / 12
        return Inertia(side, side, mass * radius ** 2 / 2)

    @staticmethod
    def cylinder_y(mass: float, radius: float, length: float) -> "Inertia":
        """Solid cylinder with its axis along y (a wheel on a y-axis joint)."""
        side = mass * (3 * radius ** 2 + length ** 2) / 12
        return Inertia(side, mass * radius ** 2 / 2, side)


def _xyz(v) -> str:
    return " ".join(f"{float(c):.6g}" for c in v)


def _inertial(mass: float, inertia: Inertia, xyz=(0, 0, 0)) -> str:
    return (f'<inertial><origin xyz="{_xyz(xyz)}" rpy="0 0 0"/><mass value="{mass:.6g}"/>'
            f'<inertia ixx="{inertia.ixx:.6g}" ixy="0" ixz="0" iyy="{inertia.iyy:.6g}" '
            f'iyz="0" izz="{inertia.izz:.6g}"/></inertial>')


def _shape(tag: str, geometry: str, xyz=(0, 0, 0), rpy=(0, 0, 0), material: str = "") -> str:
    mat = f'<material name="{material}"/>' if material and tag == "visual" else ""
    return (f'<{tag}><origin xyz="{_xyz(xyz)}" rpy="{_xyz(rpy)}"/>'
            f'<geometry>{geometry}</geometry>{mat}</{tag}>')


def _both(geometry: str, xyz=(0, 0, 0), rpy=(0, 0, 0), material: str = "") -> str:
    return _shape("visual", geometry, xyz, rpy, material) + _shape("collision", geometry, xyz, rpy)


def _box(lx, ly, lz) -> str:
    return f'<box size="{_xyz((lx, ly, lz))}"/>'


def _cylinder(radius, length) -> str:
    return f'<cylinder radius="{radius:.6g}" length="{length:.6g}"/>'


def _sphere(radius) -> str:
    return f'<sphere radius="{radius:.6g}"/>'


def _joint(name, kind, parent, child, xyz, axis, effort, velocity) -> str:
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{_xyz(xyz)}" rpy="0 0 0"/>'
            f'<axis xyz="{_xyz(axis)}"/><limit effort="{effort:.6g}" velocity="{velocity:.6g}"/>'
            f'<dynamics damping="0" friction="0"/></joint>')


def _wheel_shapes(radius: float, width: float) -> str:
    """Visual: the whole wheel. Collision: its tyre crown, _CROWN wide.

    A rigid flat cylinder on a rigid floor touches at one rim edge as soon as
    the base rolls by any angle, so the contact jumps by +-width/2 across the
    axle: with HAMR's 3 cm wheels that changed the effective track by up to
    9 % and the heading odometry with it (measured while strafing). A real
    tyre is crowned and compliant, its contact stays under the wheel centre;
    a thin implicit cylinder keeps the contact within +-_CROWN/2 of it.
    """
    rpy = (math.pi / 2, 0, 0)
    return (_shape("visual", _cylinder(radius, width), rpy=rpy, material="tyre")
            + _shape("collision", _cylinder(radius, min(width, _CROWN)), rpy=rpy))


_MATERIALS = ('<material name="body"><color rgba="0.85 0.55 0.15 1"/></material>'
              '<material name="top"><color rgba="0.25 0.3 0.35 1"/></material>'
              '<material name="tyre"><color rgba="0.1 0.1 0.1 1"/></material>')


def _robot(name: str, parts: list[str]) -> str:
    return (f'<?xml version="1.0"?>\n<robot name="{escape(name)}">' + _MATERIALS
            + "".join(parts) + "</robot>\n")


def _limits(model, joint: str):
    lim = model.joint_limits[model.joint_names.index(joint)]
    return lim.max_effort, lim.max_velocity


# -- DDROT ---------------------------------------------------------------------
def ddrot_base_height(model) -> float:
    """Height [m] of the turret disc's centre above the floor (and base_link)."""
    p = model.params
    r = model.kinematics.r
    return r + p["body.drive_base.height"] / 2 + _GAP + p["body.turret.height"] / 2


def ddrot_urdf(model) -> str:
    """URDF of a differential drive with an offset turret.

    ``base_link`` (root) is the turret disc, origin on the turret axis on the
    floor, the disc at :func:`ddrot_base_height`. ``turret_joint`` (axis -z, so its angle is the turret's angle relative to
    the drive base, CCW positive) carries ``drive_base``, whose frame is on
    the turret axis at axle height with x along the drive base's forward
    axis; the axle midpoint is ``b`` behind the turret axis. The wheels roll
    forward for positive angles (axis +y). Two frictionless balls at the front
    and back of the drive base stand in for the passive casters.
    """
    k, p = model.kinematics, model.params
    r, a, b = k.r, k.a, k.b
    length, width = p["body.drive_base.length"], p["body.drive_base.width"]
    h_db = p["body.drive_base.height"]
    m_db = p["body.drive_base.mass"]
    r_t, h_t, m_t = p["body.turret.radius"], p["body.turret.height"], p["body.turret.mass"]
    m_w, w_w = p["body.wheel.mass"], p["body.wheel.width"]
    r_s = p["body.support.radius"]
    z_axle = r                                   # axle height in base_link (on the floor)
    z_turret = ddrot_base_height(model)
    parts = [
        '<link name="base_link">'
        + _inertial(m_t, Inertia.cylinder_z(m_t, r_t, h_t), (0, 0, z_turret))
        + _both(_cylinder(r_t, h_t), (0, 0, z_turret), material="top") + "</link>",
    ]
    # Drive base: box centred on the axle midpoint, plus the support balls at
    # its front and back ends. Only the ball on the side of the centre of mass
    # rests on the floor; the other one clears it by _BALL_CLEARANCE and only
    # catches the base if it pitches. Two wheels and two touching balls would
    # be statically indeterminate: the rigid contact solver then lets a wheel
    # go light at random, and the base turns without its wheels knowing.
    ball_x = length / 2 - r_s
    m_w_total = 2 * m_w
    com_x = (m_t * b + m_db * 0.0 + m_w_total * 0.0) / (m_t + m_db + m_w_total)  # from the axle
    front_z = r_s - r if com_x >= 0 else r_s - r + _BALL_CLEARANCE
    back_z = r_s - r + _BALL_CLEARANCE if com_x >= 0 else r_s - r
    parts.append(
        '<link name="drive_base">'
        + _inertial(m_db, Inertia.box(m_db, length, width, h_db), (-b, 0, 0))
        + _both(_box(length, width, h_db), (-b, 0, 0), material="body")
        + _both(_sphere(r_s), (-b + ball_x, 0, front_z))
        + _both(_sphere(r_s), (-b - ball_x, 0, back_z))
        + "</link>")
    effort, velocity = _limits(model, "turret_joint")
    parts.append(_joint("turret_joint", "continuous", "base_link", "drive_base",
                        (0, 0, z_axle), (0, 0, -1), effort, velocity))
    for side, y, r_side in (("left", a, k.r_left), ("right", -a, k.r_right)):
        link = f"{side}_wheel"
        parts.append(f'<link name="{link}">'
                     + _inertial(m_w, Inertia.cylinder_y(m_w, r_side, w_w))
                     + _wheel_shapes(r_side, w_w) + "</link>")
        effort, velocity = _limits(model, f"{side}_wheel_joint")
        # wheels of unequal radius (worn tyres): each axle at its own height
        parts.append(_joint(f"{side}_wheel_joint", "continuous", "drive_base", link,
                            (-b, y, r_side - r), (0, 1, 0), effort, velocity))
    return _robot(model.name, parts)


# -- PCV -------------------------------------------------------------------------
def pcv_base_height(model) -> float:
    """Height [m] of the chassis box's centre above the floor (and base_link)."""
    p = model.params
    return float(model.kinematics.r.max()) + p["body.fork.height"] + p["body.chassis.height"] / 2


def pcv_urdf(model) -> str:
    """URDF of a powered-caster vehicle.

    ``base_link`` (root, origin on the floor) carries the chassis box, its
    centre at :func:`pcv_base_height`. Caster ``NAME``:
    ``NAME_steer_joint`` (axis +z, at the steering axis on the chassis bottom)
    carries ``NAME_fork``, whose x axis is the wheel's rolling heading;
    ``NAME_wheel_joint`` (axis +y, positive rolls forward) sits ``b`` behind
    the steering axis along the fork's -x and ``body.fork.height`` below the
    chassis, carrying ``NAME_wheel``. Wheels of different radii hang from
    forks of different lengths so that all contact points touch a flat floor.
    The wheels are the only bodies that touch the floor.
    """
    k, p = model.kinematics, model.params
    length, width, h_c = (p["body.chassis.length"], p["body.chassis.width"],
                          p["body.chassis.height"])
    m_c, m_f = p["body.chassis.mass"], p["body.fork.mass"]
    m_w, w_w = p["body.wheel.mass"], p["body.wheel.width"]
    height = pcv_base_height(model)
    parts = ['<link name="base_link">'
             + _inertial(m_c, Inertia.box(m_c, length, width, h_c), (0, 0, height))
             + _both(_box(length, width, h_c), (0, 0, height), material="body") + "</link>"]
    for caster in k.casters:
        r, b = caster.wheel_radius, caster.caster_offset
        drop = height - h_c / 2 - r              # steering joint to wheel axle [m]
        fork, wheel = f"{caster.name}_fork", f"{caster.name}_wheel"
        arm = (max(b, 0.01), 0.01, drop)          # visual only: the fork must not touch
        parts.append(f'<link name="{fork}">'
                     + _inertial(m_f, Inertia.box(m_f, *arm), (-b / 2, 0, -drop / 2))
                     + _shape("visual", _box(*arm), (-b / 2, 0, -drop / 2), material="top")
                     + "</link>")
        effort, velocity = _limits(model, caster.steer_joint)
        x, y = caster.axis
        parts.append(_joint(caster.steer_joint, "continuous", "base_link", fork,
                            (x, y, height - h_c / 2), (0, 0, 1), effort, velocity))
        parts.append(f'<link name="{wheel}">' + _inertial(m_w, Inertia.cylinder_y(m_w, r, w_w))
                     + _wheel_shapes(r, w_w) + "</link>")
        effort, velocity = _limits(model, caster.wheel_joint)
        parts.append(_joint(caster.wheel_joint, "continuous", fork, wheel,
                            (-b, 0, -drop), (0, 1, 0), effort, velocity))
    return _robot(model.name, parts)


#: kinematic family -> (URDF generator, base height, links in contact with
#: the floor that must be frictionless)
GENERATORS = {
    "ddrot": (ddrot_urdf, ddrot_base_height, ("drive_base",)),
    "pcv": (pcv_urdf, pcv_base_height, ()),
}


def generate_urdf(model) -> str:
    """URDF text of ``model`` (a RobotModel)."""
    try:
        return GENERATORS[model.kind][0](model)
    except KeyError:
        raise NotImplementedError(f"no URDF generator for kinematics '{model.kind}'") from None


def base_height(model) -> float:
    """Height [m] of the base body's centre (base_link's inertial origin) above
    the floor; base_link's own origin is on the floor."""
    return GENERATORS[model.kind][1](model)


def frictionless_links(model) -> tuple[str, ...]:
    """Links whose floor contacts must not carry traction (support balls)."""
    return GENERATORS[model.kind][2]
