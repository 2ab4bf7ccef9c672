"""The swerve base's physical body (``body.*``) and URDF
(:mod:`holonomic_core.description`).

A chassis box (base_link's own body) and one steering yoke and wheel per
module, the wheel's axle straight under the steering axis (no caster
offset). Masses [kg] and sizes [m] are parameters; inertias follow from the
solid shapes.
"""

from __future__ import annotations

import math
from typing import Mapping

from holonomic_core.description import (Description, Inertia, box, inertial, joint_limits,
                                        joint_xml, robot_xml, shape, visual_and_collision,
                                        wheel_shapes)
from holonomic_core.schema import ConfigError, ParamSpec


class SwerveDescription(Description):
    """Body and URDF of a swerve base."""

    @classmethod
    def param_specs(cls, params: Mapping[str, object]) -> list[ParamSpec]:
        return [
            ParamSpec("body.chassis.mass", "double", "Mass of the chassis with payload [kg].",
                      default=60.0, minimum=0.0, exclusive_minimum=True, maximum=1e4),
            ParamSpec("body.chassis.length", "double", "Chassis box length along x [m].",
                      default=0.5, minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec("body.chassis.width", "double", "Chassis box width along y [m].",
                      default=0.5, minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec("body.chassis.height", "double", "Chassis box height [m].",
                      default=0.1, minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec("body.yoke.mass", "double", "Mass of one module's steering yoke [kg].",
                      default=1.0, minimum=0.0, exclusive_minimum=True, maximum=1e3),
            ParamSpec("body.yoke.height", "double",
                      "Drop from the chassis bottom to the wheel axle [m].",
                      default=0.04, minimum=0.0, exclusive_minimum=True, maximum=10.0),
            ParamSpec("body.wheel.mass", "double", "Mass of one wheel [kg].",
                      default=0.5, minimum=0.0, exclusive_minimum=True, maximum=1e3),
            ParamSpec("body.wheel.width", "double", "Width of a wheel [m].",
                      default=0.03, minimum=0.0, exclusive_minimum=True, maximum=10.0),
        ]

    @classmethod
    def check(cls, kinematics, values: Mapping[str, object]) -> None:
        # a wheel turning about its own contact point sweeps a disc of radius
        # hypot(r, w/2): two modules' discs must not intersect
        w = values["body.wheel.width"]
        swept = [math.hypot(m.wheel_radius, w / 2) for m in kinematics.modules]
        for i, mi in enumerate(kinematics.modules):
            for j in range(i + 1, len(kinematics.modules)):
                mj = kinematics.modules[j]
                dist = math.hypot(mi.x - mj.x, mi.y - mj.y)
                if dist <= swept[i] + swept[j]:
                    raise ConfigError(f"swerve.{mj.name}.x", mj.x,
                                      f"steering axes of {mi.name} and {mj.name} more than "
                                      f"{swept[i] + swept[j]:.3f} m apart (the wheels' swept "
                                      f"discs overlap at {dist:.3f} m)")

    @classmethod
    def base_height(cls, model) -> float:
        """Height [m] of the chassis box's centre above the floor (and base_link)."""
        p = model.params
        return (float(model.kinematics.r.max()) + p["body.yoke.height"]
                + p["body.chassis.height"] / 2)

    @classmethod
    def urdf(cls, model) -> str:
        """URDF of a swerve base.

        ``base_link`` (root, origin on the floor) carries the chassis box, its
        centre at :meth:`base_height`. Module ``NAME``: ``NAME_steer_joint``
        (axis +z, at the steering axis on the chassis bottom) carries
        ``NAME_yoke``, whose x axis is the wheel's rolling heading;
        ``NAME_wheel_joint`` (axis +y, positive rolls forward) sits straight
        below it, carrying ``NAME_wheel``. Wheels of different radii hang
        from yokes of different lengths so that all touch a flat floor; the
        wheels are the only bodies that touch the floor.
        """
        k, p = model.kinematics, model.params
        length, width, h_c = (p["body.chassis.length"], p["body.chassis.width"],
                              p["body.chassis.height"])
        m_c, m_y = p["body.chassis.mass"], p["body.yoke.mass"]
        m_w, w_w = p["body.wheel.mass"], p["body.wheel.width"]
        height = cls.base_height(model)
        parts = ['<link name="base_link">'
                 + inertial(m_c, Inertia.box(m_c, length, width, h_c), (0, 0, height))
                 + visual_and_collision(box(length, width, h_c), (0, 0, height), material="body")
                 + "</link>"]
        for module in k.modules:
            r = module.wheel_radius
            drop = height - h_c / 2 - r              # steering joint to wheel axle [m]
            yoke, wheel = f"{module.name}_yoke", f"{module.name}_wheel"
            arm = (0.02, w_w + 0.02, max(drop, 0.01))   # visual only: it must not touch
            parts.append(f'<link name="{yoke}">'
                         + inertial(m_y, Inertia.box(m_y, *arm), (0, 0, -drop / 2))
                         + shape("visual", box(*arm), (0, 0, -drop / 2), material="top")
                         + "</link>")
            effort, velocity = joint_limits(model, module.steer_joint)
            parts.append(joint_xml(module.steer_joint, "continuous", "base_link", yoke,
                                   (module.x, module.y, height - h_c / 2), (0, 0, 1),
                                   effort, velocity))
            parts.append(f'<link name="{wheel}">' + inertial(m_w, Inertia.cylinder_y(m_w, r, w_w))
                         + wheel_shapes(r, w_w) + "</link>")
            effort, velocity = joint_limits(model, module.wheel_joint)
            parts.append(joint_xml(module.wheel_joint, "continuous", yoke, wheel,
                                   (0, 0, -drop), (0, 1, 0), effort, velocity))
        return robot_xml(model.name, parts)
