"""Kinematics of a swerve base: n >= 2 modules, each a driven wheel steered
about a vertical axis through its own contact point (caster offset b = 0).

Geometry (frames and joints as the powered caster's, docs/conventions.md).
Module ``i`` has its steering axis -- and so its wheel's contact point -- at
``p_i = (x_i, y_i)`` in base_link (configured as ``swerve.NAME.x, y`` or as
``h, beta``: ``p = h (cos beta, sin beta)``), a wheel of radius ``r_i`` and
two joints: ``NAME_steer_joint`` = phi_i, the wheel's rolling heading
relative to base_link x (CCW positive), and ``NAME_wheel_joint`` = omega_i
(positive rolls forward along that heading). With ``e_i = (cos phi_i, sin
phi_i)`` a rolling wheel that does not slip has the contact velocity of the
base's point there::

    v(p_i) = (vx - wz y_i, vy + wz x_i) = r_i omega_i e_i             (*)

(*) is two equations per module: along ``e_i`` it fixes the wheel rate, and
across it (``n_i . v(p_i) = 0``) it is a constraint the twist must meet --
a swerve module cannot move sideways before it has turned, which is why it
is not instantaneously holonomic (b = 0 turns the powered caster's
steering rate ``n . v / b`` into that constraint). So:

* the inverse (:meth:`SwerveKinematics.command`) is a law, not a map: turn
  each module towards ``v(p_i)`` and drive its wheel with the part of
  ``v(p_i)`` along its heading (:mod:`swerve_base.steering_law`);
* the odometry (:mod:`swerve_base.odometry_fit`) fits the rigid motion
  through the n measured velocity vectors ``r_i omega_i e_i`` (2n
  equations, 3 unknowns); the residual is the slip no rigid motion explains.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from holonomic_core.kinematics import BaseKinematics
from holonomic_core.schema import ConfigError, ParamSpec, number_or_none
from swerve_base import odometry_fit
from swerve_base.steering_law import drive_fraction, module_law

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")
#: two steering axes closer than this [m] count as coincident
MIN_MODULE_DISTANCE = 0.01
#: default gain k_s [1/s] of the steering heading error
STEERING_GAIN = 8.0
#: default speed [m/s] of a module below which it holds its heading
HOLD_SPEED = 0.01
#: default window [rad] of the wheels' wait for their modules (10 deg): full
#: speed within 2 deg of every module's heading, none beyond 10 deg
DRIVE_ALIGNMENT = math.radians(10.0)


@dataclass(frozen=True)
class Module:
    """Geometry of one swerve module: steering axis (= contact point) at
    ``(x, y)`` [m] in base_link, wheel radius [m] > 0."""

    name: str
    x: float
    y: float
    wheel_radius: float

    @property
    def steer_joint(self) -> str:
        return f"{self.name}_steer_joint"

    @property
    def wheel_joint(self) -> str:
        return f"{self.name}_wheel_joint"


class SwerveKinematics(BaseKinematics):
    """Swerve kinematics: the module command law and the least-squares odometry.

    Joint order: ``(m1_steer, m1_wheel, m2_steer, m2_wheel, ...)`` in the
    order of ``modules`` (the powered caster's). ``steering_gain`` k_s [1/s],
    ``hold_speed`` [m/s] and ``drive_alignment`` [rad] (the window of
    :func:`~swerve_base.steering_law.drive_fraction`):
    :mod:`swerve_base.steering_law`;
    ``steering_ranges``: per module ``(min, max)`` [rad] of its steering
    joint, or None (continuous).
    """

    kind = "swerve"

    def __init__(self, modules: Sequence[Module], steering_gain: float = STEERING_GAIN,
                 hold_speed: float = HOLD_SPEED,
                 steering_ranges: Sequence[tuple[float, float] | None] | None = None,
                 drive_alignment: float = DRIVE_ALIGNMENT):
        """Validate the geometry; raise :class:`ConfigError` naming the key."""
        modules = tuple(modules)
        if len(modules) < 2:
            raise ConfigError("swerve.modules", [m.name for m in modules],
                              "at least 2 modules (one steered wheel cannot hold a base's "
                              "3 degrees of freedom)")
        check_module_names([m.name for m in modules])
        for m in modules:
            if not (math.isfinite(m.wheel_radius) and m.wheel_radius > 0):
                raise ConfigError(f"swerve.{m.name}.wheel_radius", m.wheel_radius,
                                  "a finite number > 0")
            for axis, value in (("x", m.x), ("y", m.y)):
                if not math.isfinite(value):
                    raise ConfigError(f"swerve.{m.name}.{axis}", value, "a finite number")
        for i, mi in enumerate(modules):
            for mj in modules[i + 1:]:
                dist = math.hypot(mi.x - mj.x, mi.y - mj.y)
                if dist < MIN_MODULE_DISTANCE:
                    raise ConfigError(
                        f"swerve.{mj.name}.x", mj.x,
                        f"a steering axis at least {MIN_MODULE_DISTANCE:g} m from module "
                        f"{mi.name}'s (it is {dist:g} m: the modules coincide, and two "
                        "wheels on one point cannot tell a rotation about it)")
        if not (math.isfinite(steering_gain) and steering_gain > 0):
            raise ConfigError("swerve.steering_gain", steering_gain, "a finite number > 0")
        if not (math.isfinite(hold_speed) and hold_speed >= 0):
            raise ConfigError("swerve.hold_speed", hold_speed, "a finite number >= 0")
        if not (math.isfinite(drive_alignment) and 0.0 <= drive_alignment <= math.pi / 2):
            raise ConfigError("swerve.drive_alignment", drive_alignment,
                              "a number in [0, pi/2] (0: the wheels do not wait)")
        ranges = tuple(steering_ranges) if steering_ranges is not None else (None,) * len(modules)
        if len(ranges) != len(modules):
            raise ValueError(f"steering_ranges: one per module ({len(modules)}), "
                             f"got {len(ranges)}")
        for m, rng in zip(modules, ranges):
            if rng is not None and not rng[1] - rng[0] >= math.pi:
                raise ConfigError(f"joints.{m.steer_joint}.max_position", rng[1],
                                  f"at least pi above min_position ({rng[0]:g} rad): a module "
                                  "must reach one of every two opposite headings")
        self.modules = modules
        self.steering_gain = float(steering_gain)
        self.hold_speed = float(hold_speed)
        self.drive_alignment = float(drive_alignment)
        self.steering_ranges = ranges
        self._names = tuple(n for m in modules for n in (m.steer_joint, m.wheel_joint))
        self.sx = np.array([m.x for m in modules])
        self.sy = np.array([m.y for m in modules])
        self.r = np.array([m.wheel_radius for m in modules])
        #: per module (x [m], y [m], b = 0, r [m]): the contact geometry of
        #: the rigid fit, shared with the powered caster's estimators
        self.contact_geometry = tuple((float(m.x), float(m.y), 0.0, float(m.wheel_radius))
                                      for m in modules)

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def module_names(self) -> tuple[str, ...]:
        return tuple(m.name for m in self.modules)

    @property
    def caster_names(self) -> tuple[str, ...]:
        """The wheel units the per-unit slip residual is published for (the
        name the core's slip monitor and diagnostics read): the modules."""
        return self.module_names

    @property
    def steer_indices(self) -> slice:
        """Slice of the steering joints in joint arrays."""
        return slice(0, None, 2)

    @property
    def wheel_indices(self) -> slice:
        """Slice of the wheel joints in joint arrays."""
        return slice(1, None, 2)

    # -- the command law ------------------------------------------------------------
    def module_velocities(self, twist) -> np.ndarray:
        """Velocity (n x 2) [m/s] the twist (vx, vy, wz) gives each steering axis."""
        vx, vy, wz = (float(v) for v in twist)
        return np.column_stack((vx - wz * self.sy, vy + wz * self.sx))

    def command(self, positions: np.ndarray, twist: np.ndarray,
                twist_rate: np.ndarray | None = None) -> np.ndarray:
        """Steering and wheel rates [rad/s] towards ``twist`` (vx, vy, wz) at
        the measured steering angles ``positions`` [rad] (joint order), with
        the twist's rate (ax, ay, alpha) [m/s^2, m/s^2, rad/s^2] feeding the
        steering forward (None: a constant twist):
        :func:`swerve_base.steering_law.module_command` per module, every
        wheel then driving the fraction of :meth:`command_and_fraction`."""
        return self.command_and_fraction(positions, twist, twist_rate)[0]

    def command_and_fraction(self, positions: np.ndarray, twist: np.ndarray,
                             twist_rate: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """:meth:`command`'s rates and the fraction ``kappa`` of the twist the
        wheels drive while the modules turn
        (:func:`swerve_base.steering_law.drive_fraction` of the worst
        module's steering error)."""
        q = positions.tolist() if isinstance(positions, np.ndarray) else list(positions)
        vx, vy, wz = float(twist[0]), float(twist[1]), float(twist[2])
        ax, ay, alpha = (0.0, 0.0, 0.0) if twist_rate is None else (
            float(twist_rate[0]), float(twist_rate[1]), float(twist_rate[2]))
        out, worst = [], 0.0
        for i, (m, rng) in enumerate(zip(self.modules, self.steering_ranges)):
            steer, wheel, error = module_law(vx - wz * m.y, vy + wz * m.x,
                                             ax - alpha * m.y, ay + alpha * m.x,
                                             q[2 * i], m.wheel_radius, self.steering_gain,
                                             self.hold_speed, rng)
            out += (steer, wheel)
            worst = max(worst, error)
        rates = np.array(out)
        fraction = drive_fraction(worst, self.drive_alignment)
        if fraction < 1.0:
            rates[1::2] *= fraction
        return rates, fraction

    def inverse(self, positions: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """:meth:`command` for a constant twist: the rates towards ``twist``
        from the measured steering angles (a swerve has no exact inverse at a
        configuration whose modules do not point along the twist's field)."""
        return self.command(positions, twist, None)

    # -- odometry -------------------------------------------------------------------
    def forward(self, positions: np.ndarray, velocities: np.ndarray,
                estimator: str = "slip_min") -> np.ndarray:
        """Body twist (vx, vy, wz) [m/s, m/s, rad/s] of base_link from joint
        rates [rad/s] (:mod:`swerve_base.odometry_fit`)."""
        return self.estimate(positions, velocities, estimator)[0]

    def fit_residual(self, positions: np.ndarray, velocities: np.ndarray,
                     estimator: str = "slip_min") -> np.ndarray:
        """Per module the norm [m/s] of the velocity the rigid fit does not explain."""
        return self.estimate(positions, velocities, estimator)[1]

    def estimate(self, positions: np.ndarray, velocities: np.ndarray,
                 estimator: str = "slip_min") -> tuple[np.ndarray, np.ndarray]:
        """Twist and per-module residual from one fit (see BaseKinematics)."""
        return odometry_fit.estimate(self, np.asarray(positions, float),
                                     np.asarray(velocities, float), estimator)

    def wheel_velocity_matrix(self, positions: np.ndarray) -> np.ndarray:
        """``U`` (2n x 2n): joint rates -> measured module velocities; block
        ``[0 | r e]`` per module (the steering rate moves no contact point)."""
        phi = np.asarray(positions, float)[0::2]
        n = len(self.modules)
        out = np.zeros((2 * n, 2 * n))
        for i in range(n):
            out[2 * i:2 * i + 2, 2 * i + 1] = self.r[i] * np.array([math.cos(phi[i]),
                                                                    math.sin(phi[i])])
        return out

    def contact_jacobian(self, positions: np.ndarray | None = None) -> np.ndarray:
        """``C_p`` (2n x 3): twist -> module velocities, block ``[[1, 0, -y], [0, 1, x]]``."""
        n = len(self.modules)
        cp = np.zeros((2 * n, 3))
        cp[0::2, 0] = 1.0
        cp[1::2, 1] = 1.0
        cp[0::2, 2] = -self.sy
        cp[1::2, 2] = self.sx
        return cp

    def jacobian(self, positions: np.ndarray) -> np.ndarray:
        """``J_joint_to_base = C_p^+ U`` (3 x 2n): the least-squares estimator
        (the steering columns are zero)."""
        return np.linalg.pinv(self.contact_jacobian()) @ self.wheel_velocity_matrix(positions)

    # -- configuration ----------------------------------------------------------------
    @classmethod
    def param_specs(cls, params: Mapping[str, object]) -> list[ParamSpec]:
        specs = [
            ParamSpec("swerve.modules", "string_array",
                      "Module names, in joint order; module NAME has joints "
                      "NAME_steer_joint and NAME_wheel_joint.", min_length=2),
            ParamSpec("swerve.wheel_radius", "double",
                      "Wheel radius r [m] of every module (per-module override: "
                      "swerve.NAME.wheel_radius).", minimum=0.0, exclusive_minimum=True,
                      maximum=10.0),
            ParamSpec("swerve.steering_gain", "double",
                      "Gain k_s [1/s] of the steering command on the heading error "
                      "(steering rate = k_s error + the feed-forward of the twist's rate).",
                      default=STEERING_GAIN, minimum=0.0, exclusive_minimum=True,
                      maximum=1000.0),
            ParamSpec("swerve.hold_speed", "double",
                      "Module speed [m/s] below which a module holds its steering angle.",
                      default=HOLD_SPEED, minimum=0.0, maximum=10.0),
            ParamSpec("swerve.drive_alignment", "double",
                      "Steering error [rad] at which the wheels wait for their modules: "
                      "full speed while every module is within a fifth of it of its "
                      "heading, none beyond it, linear between (a wheel off its heading "
                      "slides sideways); 0: the wheels never wait.",
                      default=DRIVE_ALIGNMENT, minimum=0.0, maximum=math.pi / 2),
        ]
        names = params.get("swerve.modules")
        if isinstance(names, (list, tuple)) and all(isinstance(n, str) for n in names):
            check_module_names(list(names))
            shared_r = params.get("swerve.wheel_radius")
            for name in names:
                if f"swerve.{name}.h" in params or f"swerve.{name}.beta" in params:
                    specs += [
                        ParamSpec(f"swerve.{name}.h", "double",
                                  f"Distance [m] of module {name}'s steering axis from the "
                                  "base_link origin (or swerve.NAME.x, y).",
                                  minimum=0.0, maximum=100.0),
                        ParamSpec(f"swerve.{name}.beta", "double",
                                  f"Direction [rad] of module {name}'s steering axis from "
                                  "base_link x, CCW.", minimum=-10.0, maximum=10.0)]
                else:
                    specs += [
                        ParamSpec(f"swerve.{name}.x", "double",
                                  f"x [m] of module {name}'s steering axis in base_link "
                                  "(or swerve.NAME.h, beta).", minimum=-100.0, maximum=100.0),
                        ParamSpec(f"swerve.{name}.y", "double",
                                  f"y [m] of module {name}'s steering axis in base_link.",
                                  minimum=-100.0, maximum=100.0)]
                specs.append(ParamSpec(f"swerve.{name}.wheel_radius", "double",
                                       f"Wheel radius [m] of module {name} (default "
                                       "swerve.wheel_radius).", default=number_or_none(shared_r),
                                       minimum=0.0, exclusive_minimum=True, maximum=10.0))
        return specs

    @classmethod
    def from_params(cls, values: Mapping[str, object]) -> "SwerveKinematics":
        modules = []
        for name in values["swerve.modules"]:
            if f"swerve.{name}.h" in values:
                h, beta = values[f"swerve.{name}.h"], values[f"swerve.{name}.beta"]
                x, y = h * math.cos(beta), h * math.sin(beta)
            else:
                x, y = values[f"swerve.{name}.x"], values[f"swerve.{name}.y"]
            modules.append(Module(name, x, y, values[f"swerve.{name}.wheel_radius"]))
        return cls(modules, values["swerve.steering_gain"], values["swerve.hold_speed"],
                   drive_alignment=values["swerve.drive_alignment"])

    def with_joint_ranges(self, ranges) -> "SwerveKinematics":
        """A copy whose flip keeps each steering joint inside its range
        (``joints.NAME.min_position / max_position``, per joint in
        :attr:`joint_names` order; None: continuous)."""
        by_joint = dict(zip(self.joint_names, ranges))
        return type(self)(self.modules, self.steering_gain, self.hold_speed,
                          steering_ranges=[by_joint[m.steer_joint] for m in self.modules],
                          drive_alignment=self.drive_alignment)


def check_module_names(names: list[str]) -> None:
    """Module names become joint names and parameter keys: valid and unique."""
    for name in names:
        if not _NAME.match(name):
            raise ConfigError("swerve.modules", names,
                              f"module names usable in joint names ({name!r} is not: "
                              "letters, digits, '_', starting with a letter)")
        if names.count(name) > 1:
            raise ConfigError("swerve.modules", names,
                              f"unique module names ({name!r} twice would duplicate "
                              "the joint names)")
