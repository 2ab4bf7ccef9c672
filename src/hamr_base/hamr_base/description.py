"""The DDROT's physical body (``body.*``) and URDF (:mod:`holonomic_core.description`).

A turret disc (base_link's own body) on a drive base box with two wheels and
two frictionless support balls standing in for the passive casters. Masses
[kg] and sizes [m] are parameters; inertias follow from the solid shapes.
"""

from __future__ import annotations

from typing import Mapping

from holonomic_core.description import (BALL_CLEARANCE, GAP, Description, Inertia, box,
                                        cylinder, inertial, joint_limits, joint_range, joint_xml,
                                        robot_xml, sphere, visual_and_collision,
                                        wheel_shapes)
from holonomic_core.schema import ConfigError, ParamSpec


def _positive(name: str, description: str, default: float, maximum=100.0) -> ParamSpec:
    return ParamSpec(name, "double", description, default=default, minimum=0.0,
                     exclusive_minimum=True, maximum=maximum)


class OffsetTurretDescription(Description):
    """Body and URDF of a differential drive with an offset turret."""

    frictionless_links = ("drive_base",)

    @classmethod
    def param_specs(cls, params: Mapping[str, object]) -> list[ParamSpec]:
        return [
            # masses [kg], lengths [m]; inertias follow from the solid shapes
            _positive("body.drive_base.mass", "Mass of the drive base [kg].", 14.0, 1e4),
            _positive("body.drive_base.length",
                      "Length of the drive base box along its forward axis [m].", 0.40),
            _positive("body.drive_base.width", "Width of the drive base box [m].", 0.26),
            _positive("body.drive_base.height", "Height of the drive base box [m].", 0.06),
            _positive("body.turret.mass", "Mass of the turret with its payload [kg].", 8.0, 1e4),
            _positive("body.turret.radius", "Radius of the turret disc [m].", 0.30),
            _positive("body.turret.height", "Thickness of the turret disc [m].", 0.04),
            _positive("body.wheel.mass", "Mass of one drive wheel [kg].", 0.6, 1e3),
            _positive("body.wheel.width", "Width of a drive wheel [m].", 0.03),
            _positive("body.support.radius",
                      "Radius of the frictionless support balls at the front and back of "
                      "the drive base (the passive casters) [m].", 0.02),
        ]

    @classmethod
    def check(cls, kinematics, values: Mapping[str, object]) -> None:
        if values["body.wheel.width"] >= 2 * kinematics.a:
            raise ConfigError("body.wheel.width", values["body.wheel.width"],
                              f"< 2 a = {2 * kinematics.a:g} m (the wheels would overlap)")
        if values["body.support.radius"] >= min(kinematics.r_left, kinematics.r_right):
            raise ConfigError("body.support.radius", values["body.support.radius"],
                              f"< wheel radius {kinematics.r:g} m")

    @classmethod
    def base_height(cls, model) -> float:
        """Height [m] of the turret disc's centre above the floor (and base_link)."""
        p = model.params
        r = model.kinematics.r
        return r + p["body.drive_base.height"] / 2 + GAP + p["body.turret.height"] / 2

    @classmethod
    def urdf(cls, model) -> str:
        """URDF of a differential drive with an offset turret.

        ``base_link`` (root) is the turret disc, origin on the turret axis on
        the floor, the disc at :meth:`base_height`. ``turret_joint`` (axis -z,
        so its angle is the turret's angle relative to the drive base, CCW
        positive) carries ``drive_base``, whose frame is on the turret axis at
        axle height with x along the drive base's forward axis; the axle
        midpoint is ``b`` behind the turret axis. The wheels roll forward for
        positive angles (axis +y). Two frictionless balls at the front and back
        of the drive base stand in for the passive casters.
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
        z_turret = cls.base_height(model)
        parts = [
            '<link name="base_link">'
            + inertial(m_t, Inertia.cylinder_z(m_t, r_t, h_t), (0, 0, z_turret))
            + visual_and_collision(cylinder(r_t, h_t), (0, 0, z_turret), material="top") + "</link>",
        ]
        # Drive base: box centred on the axle midpoint, plus the support balls at
        # its front and back ends. Only the ball on the side of the centre of mass
        # rests on the floor; the other one clears it by BALL_CLEARANCE and only
        # catches the base if it pitches. Two wheels and two touching balls would
        # be statically indeterminate: the rigid contact solver then lets a wheel
        # go light at random, and the base turns without its wheels knowing.
        ball_x = length / 2 - r_s
        m_w_total = 2 * m_w
        # from the axle
        com_x = (m_t * b + m_db * 0.0 + m_w_total * 0.0) / (m_t + m_db + m_w_total)
        front_z = r_s - r if com_x >= 0 else r_s - r + BALL_CLEARANCE
        back_z = r_s - r + BALL_CLEARANCE if com_x >= 0 else r_s - r
        parts.append(
            '<link name="drive_base">'
            + inertial(m_db, Inertia.box(m_db, length, width, h_db), (-b, 0, 0))
            + visual_and_collision(box(length, width, h_db), (-b, 0, 0), material="body")
            + visual_and_collision(sphere(r_s), (-b + ball_x, 0, front_z))
            + visual_and_collision(sphere(r_s), (-b - ball_x, 0, back_z))
            + "</link>")
        effort, velocity = joint_limits(model, "turret_joint")
        # axis -z: the URDF angle is phi itself, so the range carries over as is
        parts.append(joint_xml("turret_joint", "continuous", "base_link", "drive_base",
                            (0, 0, z_axle), (0, 0, -1), effort, velocity,
                            **joint_range(model, "turret_joint")))
        for side, y, r_side in (("left", a, k.r_left), ("right", -a, k.r_right)):
            link = f"{side}_wheel"
            parts.append(f'<link name="{link}">'
                         + inertial(m_w, Inertia.cylinder_y(m_w, r_side, w_w))
                         + wheel_shapes(r_side, w_w) + "</link>")
            effort, velocity = joint_limits(model, f"{side}_wheel_joint")
            # wheels of unequal radius (worn tyres): each axle at its own height
            parts.append(joint_xml(f"{side}_wheel_joint", "continuous", "drive_base", link,
                                (-b, y, r_side - r), (0, 1, 0), effort, velocity))
        return robot_xml(model.name, parts)
