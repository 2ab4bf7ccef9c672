"""The robot description: the physical body and the URDF, from the config.

One source of geometry: wheel radius, offsets and joint limits come from the
:class:`~holonomic_core.model.RobotModel` (``model.kinematics`` and the
``body.*`` parameters), so the simulated robot, the controller's published
``robot_description`` and the analysis cannot disagree. Each kinematic family
describes its body with a :class:`Description` (its ``holonomic.description``
entry point, :mod:`holonomic_core.plugins`): the ``body.*`` schema (masses
[kg], sizes [m]), the checks of the body against the geometry, and its URDF,
built from the XML helpers here.

Wheels are URDF cylinders rotated onto the y axis (``rpy="1.5708 0 0"``), to
be loaded with ``URDF_USE_IMPLICIT_CYLINDER`` so that they stay true
cylinders in Bullet. Every link has an ``<inertial>`` computed from its solid
shape.

Frames and joints follow docs/conventions.md and REP 120's footprint
convention: the root link ``base_link`` has its origin *on the floor*, under
the centre of the base, so that the planar odom -> base_link transform draws
the robot standing on the floor of the odom frame (rviz, Foxglove). The body
that carries the payload (turret disc, chassis box) is base_link's own
visual, collision and inertial, raised by :func:`base_height`. A physics
engine reports a base at its inertial frame, not at the URDF link origin:
the simulator converts.
"""

from __future__ import annotations

import abc
import math
from dataclasses import dataclass
from typing import Mapping
from xml.sax.saxutils import escape

from holonomic_core import plugins
from holonomic_core.schema import ParamSpec


class Description(abc.ABC):
    """The physical body of one kinematic family and its URDF."""

    #: links in contact with the floor that must carry no traction (support balls)
    frictionless_links: tuple[str, ...] = ()

    @classmethod
    @abc.abstractmethod
    def param_specs(cls, params: Mapping[str, object]) -> list[ParamSpec]:
        """Schema of the family's ``body.*`` keys: masses [kg], sizes [m]."""

    @classmethod
    def check(cls, kinematics, values: Mapping[str, object]) -> None:
        """Raise :class:`~holonomic_core.schema.ConfigError` where the body
        does not fit the geometry (wheels that would overlap, ...)."""

    @classmethod
    @abc.abstractmethod
    def urdf(cls, model) -> str:
        """URDF text of ``model`` (a RobotModel of this family)."""

    @classmethod
    @abc.abstractmethod
    def base_height(cls, model) -> float:
        """Height [m] of the base body's centre above the floor (base_link's origin)."""


def description_class(kind: str) -> type[Description] | None:
    """The description of kinematic family ``kind``, or None if none is installed."""
    if not plugins.provides("description", kind):
        return None
    return plugins.load("description", kind, "robot.kinematics")


def _of(model) -> type[Description]:
    cls = description_class(model.kind)
    if cls is None:
        raise NotImplementedError(f"no robot description for kinematics '{model.kind}'")
    return cls


def generate_urdf(model) -> str:
    """URDF text of ``model`` (a RobotModel)."""
    return _of(model).urdf(model)


def base_height(model) -> float:
    """Height [m] of the base body's centre (base_link's inertial origin) above
    the floor; base_link's own origin is on the floor."""
    return _of(model).base_height(model)


def frictionless_links(model) -> tuple[str, ...]:
    """Links whose floor contacts must not carry traction (support balls)."""
    return _of(model).frictionless_links


# -- URDF building blocks -----------------------------------------------------------
#: vertical clearance between stacked bodies [m]
GAP = 0.005
#: height [m] of the unloaded support ball above the floor
BALL_CLEARANCE = 0.004
#: width [m] of the wheels' collision cylinders (see wheel_shapes)
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


def inertial(mass: float, inertia: Inertia, xyz=(0, 0, 0)) -> str:
    """``<inertial>`` of ``mass`` [kg] with principal moments ``inertia`` at ``xyz`` [m]."""
    return (f'<inertial><origin xyz="{_xyz(xyz)}" rpy="0 0 0"/><mass value="{mass:.6g}"/>'
            f'<inertia ixx="{inertia.ixx:.6g}" ixy="0" ixz="0" iyy="{inertia.iyy:.6g}" '
            f'iyz="0" izz="{inertia.izz:.6g}"/></inertial>')


def shape(tag: str, geometry: str, xyz=(0, 0, 0), rpy=(0, 0, 0), material: str = "") -> str:
    """A ``<visual>`` or ``<collision>`` (``tag``) of ``geometry`` at ``xyz`` [m], ``rpy`` [rad]."""
    mat = f'<material name="{material}"/>' if material and tag == "visual" else ""
    return (f'<{tag}><origin xyz="{_xyz(xyz)}" rpy="{_xyz(rpy)}"/>'
            f'<geometry>{geometry}</geometry>{mat}</{tag}>')


def visual_and_collision(geometry: str, xyz=(0, 0, 0), rpy=(0, 0, 0), material: str = "") -> str:
    """The same ``geometry`` as visual and collision (see :func:`shape`)."""
    return shape("visual", geometry, xyz, rpy, material) + shape("collision", geometry, xyz, rpy)


def box(lx, ly, lz) -> str:
    """``<box>`` geometry of sides ``lx, ly, lz`` [m]."""
    return f'<box size="{_xyz((lx, ly, lz))}"/>'


def cylinder(radius, length) -> str:
    """``<cylinder>`` geometry (axis z) of ``radius`` and ``length`` [m]."""
    return f'<cylinder radius="{radius:.6g}" length="{length:.6g}"/>'


def sphere(radius) -> str:
    """``<sphere>`` geometry of ``radius`` [m]."""
    return f'<sphere radius="{radius:.6g}"/>'


def joint_xml(name, kind, parent, child, xyz, axis, effort, velocity,
              lower: float | None = None, upper: float | None = None) -> str:
    """A ``<joint>`` at ``xyz`` [m] about/along ``axis``, limits ``effort``
    [N m] and ``velocity`` [rad/s], no damping or friction; a ``continuous``
    ``kind`` with a range ``lower``/``upper`` [rad] becomes ``revolute``
    with those limits (a simulator stops the joint there: a hard stop)."""
    span = ""
    if lower is not None and upper is not None:
        kind = "revolute" if kind == "continuous" else kind
        span = f' lower="{lower:.9g}" upper="{upper:.9g}"'
    return (f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
            f'<child link="{child}"/><origin xyz="{_xyz(xyz)}" rpy="0 0 0"/>'
            f'<axis xyz="{_xyz(axis)}"/><limit{span} effort="{effort:.6g}" '
            f'velocity="{velocity:.6g}"/><dynamics damping="0" friction="0"/></joint>')


def wheel_shapes(radius: float, width: float) -> str:
    """Visual: the whole wheel. Collision: its tyre crown, _CROWN wide.

    A rigid flat cylinder on a rigid floor touches at one rim edge as soon as
    the base rolls by any angle, so the contact jumps by +-width/2 across the
    axle: with HAMR's 3 cm wheels that changes the effective track by up to
    9 % while strafing, and the heading odometry with it. A real
    tyre is crowned and compliant, its contact stays under the wheel centre;
    a thin implicit cylinder keeps the contact within +-_CROWN/2 of it.
    """
    rpy = (math.pi / 2, 0, 0)
    return (shape("visual", cylinder(radius, width), rpy=rpy, material="tyre")
            + shape("collision", cylinder(radius, min(width, _CROWN)), rpy=rpy))


_MATERIALS = ('<material name="body"><color rgba="0.85 0.55 0.15 1"/></material>'
              '<material name="top"><color rgba="0.25 0.3 0.35 1"/></material>'
              '<material name="tyre"><color rgba="0.1 0.1 0.1 1"/></material>')


def robot_xml(name: str, parts: list[str]) -> str:
    """The URDF document of robot ``name`` from its links and joints."""
    return (f'<?xml version="1.0"?>\n<robot name="{escape(name)}">' + _MATERIALS
            + "".join(parts) + "</robot>\n")


def joint_limits(model, joint: str) -> tuple[float, float]:
    """``(max_effort [N m], max_velocity [rad/s])`` of ``joint`` of ``model``."""
    lim = model.joint_limits[model.joint_names.index(joint)]
    return lim.max_effort, lim.max_velocity


def joint_range(model, joint: str) -> dict[str, float | None]:
    """``{"lower": min_position, "upper": max_position}`` [rad] of ``joint``
    of ``model`` (None, None: continuous), as :func:`joint_xml` takes them."""
    lim = model.joint_limits[model.joint_names.index(joint)]
    return {"lower": lim.min_position, "upper": lim.max_position}
