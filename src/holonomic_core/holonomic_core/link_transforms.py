"""Forward kinematics of a URDF tree: every link's transform from joint positions.

What robot_state_publisher does on a full ROS install, ROS-free: the URDF's
joints (``fixed``, ``continuous``, ``revolute``, ``prismatic``) are parsed once
into a :class:`LinkTree`; :meth:`LinkTree.transforms` then maps measured joint
positions to one parent -> child transform per joint. The node's
``publish_link_tf`` and the Foxglove bridge both use it, so rviz and Foxglove
place the wheels, the turret and the casters from the same numbers.

Conventions (URDF): a joint's transform parent -> child is its ``<origin>``
(translation ``xyz`` [m], then fixed-axis roll-pitch-yaw ``rpy`` [rad]) followed
by the joint motion along/about its unit ``<axis>`` (in the child frame):
a rotation by ``q`` [rad] for revolute/continuous joints, a translation by
``q`` [m] for prismatic ones. Quaternions are ``(x, y, z, w)``.
"""

from __future__ import annotations

import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Mapping

#: joint types that move with a joint position
MOVING_TYPES = ("continuous", "revolute", "prismatic")
_KNOWN_TYPES = MOVING_TYPES + ("fixed",)

Vector3 = tuple[float, float, float]
Quaternion = tuple[float, float, float, float]


def quaternion_multiply(a: Quaternion, b: Quaternion) -> Quaternion:
    """Hamilton product ``a * b`` (rotate by ``b``, then by ``a``)."""
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by,
            aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw,
            aw * bw - ax * bx - ay * by - az * bz)


def rotate(q: Quaternion, v: Vector3) -> Vector3:
    """The vector ``v`` rotated by the unit quaternion ``q``."""
    x, y, z, w = q
    # v + 2 w (u x v) + 2 u x (u x v), u = (x, y, z)
    tx = 2.0 * (y * v[2] - z * v[1])
    ty = 2.0 * (z * v[0] - x * v[2])
    tz = 2.0 * (x * v[1] - y * v[0])
    return (v[0] + w * tx + (y * tz - z * ty),
            v[1] + w * ty + (z * tx - x * tz),
            v[2] + w * tz + (x * ty - y * tx))


def quaternion_from_rpy(roll: float, pitch: float, yaw: float) -> Quaternion:
    """URDF/REP 103 fixed-axis roll, pitch, yaw [rad] -> quaternion (Rz Ry Rx)."""
    cr, sr = math.cos(0.5 * roll), math.sin(0.5 * roll)
    cp, sp = math.cos(0.5 * pitch), math.sin(0.5 * pitch)
    cy, sy = math.cos(0.5 * yaw), math.sin(0.5 * yaw)
    return (sr * cp * cy - cr * sp * sy,
            cr * sp * cy + sr * cp * sy,
            cr * cp * sy - sr * sp * cy,
            cr * cp * cy + sr * sp * sy)


def axis_angle(axis: Vector3, angle: float) -> Quaternion:
    """Rotation by ``angle`` [rad] about the unit vector ``axis``."""
    s = math.sin(0.5 * angle)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(0.5 * angle))


@dataclass(frozen=True)
class LinkTransform:
    """Pose of ``child`` in ``parent``: translation [m], rotation (x, y, z, w)."""

    parent: str
    child: str
    translation: Vector3
    rotation: Quaternion


@dataclass(frozen=True)
class UrdfJoint:
    """One joint of the tree (see the module docstring for the conventions)."""

    name: str
    type: str
    parent: str
    child: str
    xyz: Vector3
    rotation: Quaternion    # of the <origin>
    axis: Vector3           # unit, in the child frame

    def transform(self, position: float = 0.0) -> LinkTransform:
        """parent -> child at joint position ``position`` [rad or m]."""
        if self.type == "prismatic":
            offset = rotate(self.rotation, tuple(a * position for a in self.axis))
            xyz = tuple(o + d for o, d in zip(self.xyz, offset))
            return LinkTransform(self.parent, self.child, xyz, self.rotation)
        if self.type == "fixed":
            return LinkTransform(self.parent, self.child, self.xyz, self.rotation)
        return LinkTransform(self.parent, self.child, self.xyz,
                             quaternion_multiply(self.rotation, axis_angle(self.axis, position)))


def _floats(text: str | None, default: Vector3) -> Vector3:
    if text is None:
        return default
    values = tuple(float(v) for v in text.split())
    if len(values) != 3:
        raise ValueError(f"expected 3 numbers, got {text!r}")
    return values


class LinkTree:
    """The joints of a URDF, parsed once; maps joint positions to link transforms."""

    def __init__(self, joints: tuple[UrdfJoint, ...], root: str):
        self.joints = joints
        #: the link that is no joint's child (base_link for our robots)
        self.root = root
        #: names of the joints that take a position, in URDF order
        self.moving_joint_names = tuple(j.name for j in joints if j.type in MOVING_TYPES)

    @classmethod
    def from_urdf(cls, text: str) -> "LinkTree":
        """Parse a URDF document. Raises ValueError on an unknown joint type,
        a zero axis, or a tree without exactly one root."""
        robot = ET.fromstring(text)
        links = [link.get("name") for link in robot.findall("link")]
        joints = []
        for element in robot.findall("joint"):
            kind = element.get("type")
            if kind not in _KNOWN_TYPES:
                raise ValueError(f"joint {element.get('name')!r}: unsupported type {kind!r}")
            origin = element.find("origin")
            xyz = _floats(origin.get("xyz") if origin is not None else None, (0.0, 0.0, 0.0))
            rpy = _floats(origin.get("rpy") if origin is not None else None, (0.0, 0.0, 0.0))
            axis_el = element.find("axis")
            axis = _floats(axis_el.get("xyz") if axis_el is not None else None, (1.0, 0.0, 0.0))
            norm = math.sqrt(sum(a * a for a in axis))
            if kind != "fixed" and norm == 0.0:
                raise ValueError(f"joint {element.get('name')!r}: zero axis")
            joints.append(UrdfJoint(
                name=element.get("name"), type=kind,
                parent=element.find("parent").get("link"),
                child=element.find("child").get("link"), xyz=xyz,
                rotation=quaternion_from_rpy(*rpy),
                axis=tuple(a / norm for a in axis) if norm else axis))
        children = {j.child for j in joints}
        roots = [name for name in links if name not in children]
        if len(roots) != 1:
            raise ValueError(f"a URDF tree has one root link, found {roots}")
        return cls(tuple(joints), roots[0])

    def transforms(self, positions: Mapping[str, float]) -> list[LinkTransform]:
        """parent -> child of every joint, moving joints at ``positions``
        (joint name -> rad or m). Raises KeyError naming a missing joint."""
        out = []
        for joint in self.joints:
            if joint.type == "fixed":
                out.append(joint.transform())
            else:
                out.append(joint.transform(float(positions[joint.name])))
        return out

    def poses_in_root(self, positions: Mapping[str, float]) -> dict[str, LinkTransform]:
        """Every link's pose in the root link (root -> link), from :meth:`transforms`."""
        by_child = {t.child: t for t in self.transforms(positions)}
        poses = {self.root: LinkTransform(self.root, self.root, (0.0, 0.0, 0.0),
                                          (0.0, 0.0, 0.0, 1.0))}

        def pose(link: str) -> LinkTransform:
            if link not in poses:
                local = by_child[link]
                up = pose(local.parent)
                shift = rotate(up.rotation, local.translation)
                poses[link] = LinkTransform(
                    self.root, link, tuple(a + b for a, b in zip(up.translation, shift)),
                    quaternion_multiply(up.rotation, local.rotation))
            return poses[link]

        for link in by_child:
            pose(link)
        return poses
