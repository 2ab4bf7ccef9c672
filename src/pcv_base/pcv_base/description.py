"""The powered-caster vehicle's physical body (``body.*``) and URDF
(:mod:`holonomic_core.description`).

A chassis box (base_link's own body) and one fork and wheel per caster.
Masses [kg] and sizes [m] are parameters; inertias follow from the solid
shapes (the dynamic model, :mod:`pcv_base.dynamics`, uses the same bodies).
"""

from __future__ import annotations

import math
from typing import Mapping

from holonomic_core.description import (Description, Inertia, box, inertial, joint_limits,
                                        joint_range, joint_xml, robot_xml, shape, visual_and_collision,
                                        wheel_shapes)
from holonomic_core.schema import ConfigError, ParamSpec


class PoweredCasterDescription(Description):
    """Body and URDF of a powered-caster vehicle."""

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
            ParamSpec("body.fork.mass", "double", "Mass of one caster fork [kg].",
                      default=0.8, minimum=0.0, exclusive_minimum=True, maximum=1e3),
            ParamSpec("body.fork.height", "double",
                      "Drop from the chassis bottom to the wheel axle [m].",
                      default=0.04, minimum=0.0, exclusive_minimum=True, maximum=10.0),
            ParamSpec("body.wheel.mass", "double", "Mass of one wheel [kg].",
                      default=0.5, minimum=0.0, exclusive_minimum=True, maximum=1e3),
            ParamSpec("body.wheel.width", "double", "Width of a wheel [m].",
                      default=0.03, minimum=0.0, exclusive_minimum=True, maximum=10.0),
        ]

    @classmethod
    def check(cls, kinematics, values: Mapping[str, object]) -> None:
        # The wheels' swept discs (plan view: a 2r x w rectangle at distance b
        # from the axis, turning about it) must not intersect (Holmberg &
        # Khatib, Sec. 2), or the simulated and the real wheels collide.
        w = values["body.wheel.width"]
        swept = [math.hypot(c.caster_offset + c.wheel_radius, w / 2) for c in kinematics.casters]
        for i, ci in enumerate(kinematics.casters):
            for j in range(i + 1, len(kinematics.casters)):
                cj = kinematics.casters[j]
                dist = math.dist(ci.axis, cj.axis)
                if dist <= swept[i] + swept[j]:
                    raise ConfigError(f"pcv.{cj.name}.h", cj.h,
                                      f"steering axes of {ci.name} and {cj.name} more than "
                                      f"{swept[i] + swept[j]:.3f} m apart (the wheels' swept "
                                      f"discs overlap at {dist:.3f} m)")

    @classmethod
    def base_height(cls, model) -> float:
        """Height [m] of the chassis box's centre above the floor (and base_link)."""
        p = model.params
        return (float(model.kinematics.r.max()) + p["body.fork.height"]
                + p["body.chassis.height"] / 2)

    @classmethod
    def urdf(cls, model) -> str:
        """URDF of a powered-caster vehicle.

        ``base_link`` (root, origin on the floor) carries the chassis box, its
        centre at :meth:`base_height`. Caster ``NAME``:
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
        height = cls.base_height(model)
        parts = ['<link name="base_link">'
                 + inertial(m_c, Inertia.box(m_c, length, width, h_c), (0, 0, height))
                 + visual_and_collision(box(length, width, h_c), (0, 0, height), material="body")
                 + "</link>"]
        for caster in k.casters:
            r, b = caster.wheel_radius, caster.caster_offset
            drop = height - h_c / 2 - r              # steering joint to wheel axle [m]
            fork, wheel = f"{caster.name}_fork", f"{caster.name}_wheel"
            arm = (max(b, 0.01), 0.01, drop)          # visual only: the fork must not touch
            parts.append(f'<link name="{fork}">'
                         + inertial(m_f, Inertia.box(m_f, *arm), (-b / 2, 0, -drop / 2))
                         + shape("visual", box(*arm), (-b / 2, 0, -drop / 2), material="top")
                         + "</link>")
            effort, velocity = joint_limits(model, caster.steer_joint)
            x, y = caster.axis
            parts.append(joint_xml(caster.steer_joint, "continuous", "base_link", fork,
                                (x, y, height - h_c / 2), (0, 0, 1), effort, velocity,
                                **joint_range(model, caster.steer_joint)))
            parts.append(f'<link name="{wheel}">' + inertial(m_w, Inertia.cylinder_y(m_w, r, w_w))
                         + wheel_shapes(r, w_w) + "</link>")
            effort, velocity = joint_limits(model, caster.wheel_joint)
            parts.append(joint_xml(caster.wheel_joint, "continuous", fork, wheel,
                                (-b, 0, -drop), (0, 1, 0), effort, velocity))
        return robot_xml(model.name, parts)
