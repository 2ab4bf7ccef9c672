"""Kinematics of a powered-caster vehicle (PCV): n >= 2 actively steered and
driven offset casters (Holmberg & Khatib, "Development of a holonomic mobile
robot for mobile manipulation tasks"; Nomadic XR4000, PR2, Kim & Moon's COMR).

Geometry (frames and joints: docs/conventions.md). Caster ``i`` has its steering axis at
``s_i = h_i (cos beta_i, sin beta_i)`` in base_link, a wheel of radius ``r_i``
whose ground contact trails the axis by the caster offset ``b_i > 0``, and two
joints: ``<name>_steer_joint`` = phi_i, the wheel's rolling heading relative
to base_link x (CCW positive), and ``<name>_wheel_joint`` = rho_i (positive
rolls forward along that heading). With ``e_i = (cos phi_i, sin phi_i)`` and
``n_i = (-sin phi_i, cos phi_i)`` the contact point is ``p_i = s_i - b_i e_i``.

Derivation. A base twist ``x_dot = (vx, vy, wz)`` moves the base's point at
``p`` with ``v(p) = (vx - wz p_y, vy + wz p_x)``. Relative to the base, the
fork turns at phi_dot about ``s``, which moves its point at the contact by
``-b phi_dot n``; the wheel rolls, which moves its material point at the
contact by ``-r rho_dot e``. Ideal rolling (no slip) makes the wheel's contact
point still on the floor::

    v(p_i) = r_i rho_dot_i e_i + b_i phi_dot_i n_i                         (*)

* ``C_p`` (2n x 3) maps the base twist to the contact velocities ``p_dot_i =
  v(p_i)``: block ``[[1, 0, -p_iy], [0, 1, p_ix]]`` (the paper's eq. 11);
* ``C_q`` (2n x 2n, block diagonal, invertible for b, r > 0) maps contact
  velocities to joint rates ``q_dot_i = (phi_dot_i, rho_dot_i)``: by (*),
  ``C_q_i^-1 = [b n | r e]`` and ``C_q_i = [[-sin phi / b, cos phi / b],
  [cos phi / r, sin phi / r]]`` (eq. 10);
* ``C = C_q C_p`` is the constraint matrix of eq. 7, which comes out exactly as
  printed: ``phi_dot = (-s vx + c vy)/b + (h cos(beta - phi)/b - 1) wz`` and
  ``rho_dot = (c vx + s vy)/r + h sin(phi - beta)/r wz``. The tests check the
  printed form, the product, and a numeric differentiation of the rigid-body
  motion against each other.

The estimators of the twist from measured joint rates (``slip_min`` = C#,
``pinv``, ``robust``) are in :mod:`pcv_base.estimators`; the torque
distribution C#^T F (eq. 14) is in :mod:`pcv_base.torque_distribution`,
beside the dynamics.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from holonomic_core import hot_path
from holonomic_core.kinematics import BaseKinematics
from holonomic_core.schema import ConfigError, ParamSpec, number_or_none
from pcv_base.estimators import estimate

#: why the caster offset must be > 0, for the error messages
_ZERO_OFFSET = ("b = 0 makes a caster a steered wheel that cannot move sideways without "
                "first turning: the base would not be holonomic")

_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


@dataclass(frozen=True)
class Caster:
    """Geometry of one powered caster.

    ``h`` [m] and ``beta`` [rad]: the steering axis at (h cos beta, h sin beta)
    in base_link; ``wheel_radius`` r [m] > 0; ``caster_offset`` b [m] > 0, the
    horizontal distance by which the contact point trails the steering axis.
    """

    name: str
    h: float
    beta: float
    wheel_radius: float
    caster_offset: float

    @property
    def axis(self) -> tuple[float, float]:
        """Steering axis position (x, y) [m] in base_link."""
        return (self.h * math.cos(self.beta), self.h * math.sin(self.beta))

    @property
    def steer_joint(self) -> str:
        return f"{self.name}_steer_joint"

    @property
    def wheel_joint(self) -> str:
        return f"{self.name}_wheel_joint"


class PoweredCasterKinematics(BaseKinematics):
    """Exact PCV kinematics with the three odometry estimators.

    Joint order: ``(c1_steer, c1_wheel, c2_steer, c2_wheel, ...)`` in the
    order of ``casters`` -- the paper's ``q'_i = (phi_dot_i, rho_dot_i)``.
    """

    kind = "pcv"

    def __init__(self, casters: Sequence[Caster]):
        """Validate the geometry; raise :class:`ConfigError` naming the key."""
        casters = tuple(casters)
        if len(casters) < 2:
            raise ConfigError("pcv.casters", [c.name for c in casters],
                              "at least 2 casters (one caster cannot hold a base's "
                              "3 degrees of freedom)")
        check_caster_names([c.name for c in casters])
        for c in casters:
            for key, value in (("wheel_radius", c.wheel_radius),
                               ("caster_offset", c.caster_offset)):
                if not (math.isfinite(value) and value > 0):
                    extra = f" ({_ZERO_OFFSET})" if key == "caster_offset" else ""
                    raise ConfigError(f"pcv.{c.name}.{key}", value, "a finite number > 0" + extra)
            if not (math.isfinite(c.h) and c.h >= 0 and math.isfinite(c.beta)):
                raise ConfigError(f"pcv.{c.name}.h", c.h, "a finite number >= 0")
        # Two contact points that can coincide make C_p rank-deficient at some
        # steering angles (and the wheels collide): the circles on which the
        # contact points move must be apart.
        for i, ci in enumerate(casters):
            for cj in casters[i + 1:]:
                dist = math.dist(ci.axis, cj.axis)
                if dist <= ci.caster_offset + cj.caster_offset:
                    raise ConfigError(
                        f"pcv.{cj.name}.h", cj.h,
                        f"a steering axis more than b_{ci.name} + b_{cj.name} = "
                        f"{ci.caster_offset + cj.caster_offset:g} m from caster {ci.name}'s "
                        f"(it is {dist:g} m: the steering axes (nearly) coincide)")
        self.casters = casters
        self._names = tuple(n for c in casters for n in (c.steer_joint, c.wheel_joint))
        self.sx = np.array([c.axis[0] for c in casters])
        self.sy = np.array([c.axis[1] for c in casters])
        self.r = np.array([c.wheel_radius for c in casters])
        self.b = np.array([c.caster_offset for c in casters])
        #: per caster (sx [m], sy [m], b [m], r [m]) as Python floats: the
        #: control cycle's paths (inverse, the slip_min fit) run on them, since
        #: for n <= 8 casters a loop of scalar math costs a third of the same
        #: work as a dozen numpy calls on length-n arrays.
        self.contact_geometry = tuple((float(c.axis[0]), float(c.axis[1]),
                                       float(c.caster_offset), float(c.wheel_radius))
                                      for c in casters)
        #: the compiled closed forms (hot_path), None for the pure-Python path
        self._hot = hot_path.module() if len(casters) <= hot_path.MAX_CASTERS else None
        self._hot_geometry = np.array(self.contact_geometry, dtype=float).ravel()

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self._names

    @property
    def caster_names(self) -> tuple[str, ...]:
        return tuple(c.name for c in self.casters)

    @property
    def steer_indices(self) -> slice:
        """Slice of the steering joints in joint arrays."""
        return slice(0, None, 2)

    @property
    def wheel_indices(self) -> slice:
        """Slice of the wheel joints in joint arrays."""
        return slice(1, None, 2)

    # -- geometry at a configuration ----------------------------------------------
    def contact_points(self, positions: np.ndarray) -> np.ndarray:
        """Contact points p_i = s_i - b_i e_i (n x 2) [m] in base_link."""
        phi = np.asarray(positions, float)[0::2]
        return np.column_stack((self.sx - self.b * np.cos(phi), self.sy - self.b * np.sin(phi)))

    def contact_jacobian(self, positions: np.ndarray) -> np.ndarray:
        """``C_p`` (2n x 3): base twist -> contact-point velocities (eq. 11)."""
        p = self.contact_points(positions)
        n = len(self.casters)
        cp = np.zeros((2 * n, 3))
        cp[0::2, 0] = 1.0
        cp[1::2, 1] = 1.0
        cp[0::2, 2] = -p[:, 1]
        cp[1::2, 2] = p[:, 0]
        return cp

    def joint_to_contact(self, positions: np.ndarray) -> np.ndarray:
        """``C_q^-1`` (2n x 2n, block diagonal): joint rates -> sensed contact
        velocities (eq. 10 inverted); block ``[b n | r e]`` per caster."""
        phi = np.asarray(positions, float)[0::2]
        c, s = np.cos(phi), np.sin(phi)
        n = len(self.casters)
        out = np.zeros((2 * n, 2 * n))
        for i in range(n):
            out[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[-self.b[i] * s[i], self.r[i] * c[i]],
                                                     [self.b[i] * c[i], self.r[i] * s[i]]]
        return out

    def contact_to_joint(self, positions: np.ndarray) -> np.ndarray:
        """``C_q`` (2n x 2n, block diagonal): contact velocities -> joint rates (eq. 10)."""
        phi = np.asarray(positions, float)[0::2]
        c, s = np.cos(phi), np.sin(phi)
        n = len(self.casters)
        out = np.zeros((2 * n, 2 * n))
        for i in range(n):
            out[2 * i:2 * i + 2, 2 * i:2 * i + 2] = [[-s[i] / self.b[i], c[i] / self.b[i]],
                                                     [c[i] / self.r[i], s[i] / self.r[i]]]
        return out

    def constraint_matrix(self, positions: np.ndarray) -> np.ndarray:
        """``C`` (2n x 3), eq. 7 as printed: rows (phi_dot_i, rho_dot_i) per caster."""
        phi = np.asarray(positions, float)[0::2]
        out = np.zeros((2 * len(self.casters), 3))
        for i, cas in enumerate(self.casters):
            sp, cp_ = math.sin(phi[i]), math.cos(phi[i])
            sb, cb = math.sin(cas.beta), math.cos(cas.beta)
            b, r, h = cas.caster_offset, cas.wheel_radius, cas.h
            out[2 * i] = [-sp / b, cp_ / b, h * (cb * cp_ + sb * sp) / b - 1.0]
            out[2 * i + 1] = [cp_ / r, sp / r, h * (cb * sp - sb * cp_) / r]
        return out

    # -- kinematics ---------------------------------------------------------------
    def inverse(self, positions: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """Steering and wheel rates [rad/s] for body twist (vx, vy, wz) at the
        current steering angles: ``C @ twist``, written per caster.

        The steering rate is commanded directly (an offset caster is not a
        swerve module): phi_dot = n . v(s) / b - wz, rho_dot = e . v(s) / r,
        with v(s) the base's velocity at the steering axis.
        """
        if self._hot is not None:
            return self._hot.inverse(hot_path.KIND_PCV, positions, twist, self._hot_geometry)
        q = positions.tolist() if isinstance(positions, np.ndarray) else list(positions)
        vx, vy, wz = float(twist[0]), float(twist[1]), float(twist[2])
        out = []
        cos, sin = math.cos, math.sin
        for i, (sx, sy, b, r) in enumerate(self.contact_geometry):
            phi = q[2 * i]
            c, s = cos(phi), sin(phi)
            vsx = vx - wz * sy
            vsy = vy + wz * sx
            out.append((c * vsy - s * vsx) / b - wz)
            out.append((c * vsx + s * vsy) / r)
        return np.array(out)

    def forward(self, positions: np.ndarray, velocities: np.ndarray,
                estimator: str = "slip_min") -> np.ndarray:
        """Body twist (vx, vy, wz) [m/s, m/s, rad/s] of base_link from joint rates
        [rad/s] with the chosen estimator (:mod:`pcv_base.estimators`)."""
        return estimate(self, np.asarray(positions, float), np.asarray(velocities, float),
                        estimator)[0]

    def fit_residual(self, positions: np.ndarray, velocities: np.ndarray,
                     estimator: str = "slip_min") -> np.ndarray:
        """Per caster, the norm [m/s] of the contact-velocity slip the chosen
        estimator's twist does not explain (0 for consistent joint rates)."""
        return estimate(self, np.asarray(positions, float), np.asarray(velocities, float),
                        estimator)[1]

    def estimate(self, positions: np.ndarray, velocities: np.ndarray,
                 estimator: str = "slip_min") -> tuple[np.ndarray, np.ndarray]:
        """Twist and per-caster residual from one fit (see BaseKinematics)."""
        if self._hot is not None and estimator == "slip_min":
            return self._hot.estimate(hot_path.KIND_PCV, positions, velocities,
                                      self._hot_geometry)
        return estimate(self, np.asarray(positions, float), np.asarray(velocities, float),
                        estimator)

    def hot_path_geometry(self, estimator: str = "slip_min") -> tuple[int, np.ndarray] | None:
        """The compiled form covers the slip_min fit (robust and pinv stay in Python)."""
        if estimator != "slip_min" or len(self.casters) > hot_path.MAX_CASTERS:
            return None
        return hot_path.KIND_PCV, self._hot_geometry

    def jacobian(self, positions: np.ndarray) -> np.ndarray:
        """``C# = C_p^+ C_q^-1`` (3 x 2n): the slip-minimising estimator (eq. 13)."""
        positions = np.asarray(positions, float)
        return np.linalg.pinv(self.contact_jacobian(positions)) @ self.joint_to_contact(positions)

    # -- configuration ------------------------------------------------------------
    @classmethod
    def param_specs(cls, params: Mapping[str, object]) -> list[ParamSpec]:
        specs = [
            ParamSpec("pcv.casters", "string_array",
                      "Caster names, in joint order; caster NAME has joints "
                      "NAME_steer_joint and NAME_wheel_joint.", min_length=2),
            ParamSpec("pcv.wheel_radius", "double",
                      "Wheel radius r [m] of every caster (per-caster override: "
                      "pcv.NAME.wheel_radius).", minimum=0.0, exclusive_minimum=True,
                      maximum=10.0),
            # minimum 0 inclusive: b = 0 reaches the constructor, whose error
            # says why it is not allowed
            ParamSpec("pcv.caster_offset", "double",
                      "Caster offset b [m] of every caster: horizontal distance from the "
                      "steering axis back to the wheel's contact point (per-caster "
                      "override: pcv.NAME.caster_offset).", minimum=0.0, maximum=10.0),
        ]
        names = params.get("pcv.casters")
        if isinstance(names, (list, tuple)) and all(isinstance(n, str) for n in names):
            check_caster_names(list(names))
            shared_r = params.get("pcv.wheel_radius")
            shared_b = params.get("pcv.caster_offset")
            for name in names:
                specs += [
                    ParamSpec(f"pcv.{name}.h", "double",
                              f"Distance [m] of caster {name}'s steering axis from the "
                              "base_link origin.", minimum=0.0, maximum=100.0),
                    ParamSpec(f"pcv.{name}.beta", "double",
                              f"Direction [rad] of caster {name}'s steering axis from "
                              "base_link x, CCW.", minimum=-10.0, maximum=10.0),
                    ParamSpec(f"pcv.{name}.wheel_radius", "double",
                              f"Wheel radius [m] of caster {name} (default pcv.wheel_radius).",
                              default=number_or_none(shared_r), minimum=0.0,
                              exclusive_minimum=True, maximum=10.0),
                    ParamSpec(f"pcv.{name}.caster_offset", "double",
                              f"Caster offset [m] of caster {name} (default "
                              "pcv.caster_offset).", default=number_or_none(shared_b),
                              minimum=0.0, maximum=10.0),
                ]
        return specs

    @classmethod
    def from_params(cls, values: Mapping[str, object]) -> "PoweredCasterKinematics":
        if values["pcv.caster_offset"] <= 0:
            raise ConfigError("pcv.caster_offset", values["pcv.caster_offset"],
                              f"a number > 0 ({_ZERO_OFFSET})")
        casters = [Caster(name, values[f"pcv.{name}.h"], values[f"pcv.{name}.beta"],
                          values[f"pcv.{name}.wheel_radius"], values[f"pcv.{name}.caster_offset"])
                   for name in values["pcv.casters"]]
        return cls(casters)


def check_caster_names(names: list[str]) -> None:
    """Caster names become joint names and parameter keys: valid and unique."""
    for name in names:
        if not _NAME.match(name):
            raise ConfigError("pcv.casters", names,
                              f"caster names usable in joint names ({name!r} is not: "
                              "letters, digits, '_', starting with a letter)")
        if names.count(name) > 1:
            raise ConfigError("pcv.casters", names,
                              f"unique caster names ({name!r} twice would duplicate "
                              "the joint names)")
