"""Kinematics of the differential drive with an offset turret (DDROT, HAMR).

Geometry (Costa & Yim, Fig. 5; frames and joints: docs/conventions.md):

* a differential drive with wheel radius ``r`` and half wheel separation ``a``;
* a turret -- ``base_link``, the payload platform -- whose vertical axis lies
  ``b`` ahead of the axle midpoint along the drive base's forward axis;
* joints ``left_wheel_joint``, ``right_wheel_joint`` (positive rolls the wheel
  forward) and ``turret_joint`` = phi, the turret's angle relative to the drive
  base (CCW positive, 0 when the drive base faces base_link x).

Derivation. Let the drive base move forward at ``v = r (wL + wR) / 2`` and turn
at ``wd = r (wR - wL) / (2 a)``. The turret axis is a point of the drive base,
``b`` ahead of the axle, so it moves at ``v`` along the drive base's forward
axis ``e`` plus ``b wd`` along ``e_perp``. In base_link the drive base's axes
are ``e = (cos phi, -sin phi)`` and ``e_perp = (sin phi, cos phi)``, and the
turret turns at ``wd + phi_dot``::

    vx = v cos(phi) + b wd sin(phi)
    vy = -v sin(phi) + b wd cos(phi)
    wz = wd + phi_dot

Relation to the printed eq. 1 of the paper. Its text says "s and c are
cos(theta_s) and sin(theta_s) respectively"; that is swapped: with s = cos the
rows do not describe a rigid body (tested). With s = sin(theta_s),
c = cos(theta_s) eq. 1 is exactly the model above in the paper's own frame:
its X is lateral to the *right* (= -vy), Y is forward (= vx), Phi is CCW
(= wz), wheel 1 is the right wheel, wheel 2 the left, and theta_s is the drive
base's angle relative to the turret (= -phi). ``paper_jacobian`` keeps the
printed form (with the s/c fix) so that the tests can check this mapping.

The inverse is closed form (the 3x3 Jacobian's determinant is ``r^2 b / (2a)``,
zero iff b = 0, which is why a DDROT with a centred turret is not holonomic).
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from holonomic_core import hot_path
from holonomic_core.kinematics import ESTIMATORS, BaseKinematics
from holonomic_core.schema import ConfigError, ParamSpec, number_or_none

LEFT_WHEEL = "left_wheel_joint"
RIGHT_WHEEL = "right_wheel_joint"
TURRET = "turret_joint"
#: the residual of an exactly determined fit (read-only, shared)
_NO_RESIDUAL = np.zeros(0)
_NO_RESIDUAL.flags.writeable = False


def _positive(name: str, description: str, default=None, maximum=100.0) -> ParamSpec:
    return ParamSpec(name, "double", description, default=default, minimum=0.0,
                     exclusive_minimum=True, maximum=maximum)


class OffsetTurretKinematics(BaseKinematics):
    """Exact DDROT kinematics; ``forward`` is the inverse of ``inverse``.

    Its Jacobian is square, so the three estimators all give the exact
    inverse (there is no redundancy to fit, and no slip to reject).
    """

    kind = "ddrot"

    def __init__(self, wheel_radius: float, half_wheel_separation: float, turret_offset: float,
                 left_wheel_radius: float | None = None, right_wheel_radius: float | None = None):
        """``wheel_radius`` r [m] > 0, ``half_wheel_separation`` a [m] > 0,
        ``turret_offset`` b [m] > 0 (b = 0 makes the base non-holonomic);
        ``left_wheel_radius`` / ``right_wheel_radius`` [m]: each wheel's own
        radius when they differ (worn tyres; default ``wheel_radius``)."""
        left = wheel_radius if left_wheel_radius is None else left_wheel_radius
        right = wheel_radius if right_wheel_radius is None else right_wheel_radius
        for key, value in (("ddrot.wheel_radius", wheel_radius),
                           ("ddrot.left_wheel_radius", left),
                           ("ddrot.right_wheel_radius", right),
                           ("ddrot.half_wheel_separation", half_wheel_separation),
                           ("ddrot.turret_offset", turret_offset)):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                extra = (" (b = 0 puts the turret axis on the axle midpoint: the base "
                         "cannot move sideways, it is not holonomic)"
                         if key == "ddrot.turret_offset" else "")
                raise ConfigError(key, value, "a finite number > 0" + extra)
        self.r_left = float(left)
        self.r_right = float(right)
        #: mean wheel radius [m] (the body's ride height)
        self.r = 0.5 * (self.r_left + self.r_right)
        self.a = float(half_wheel_separation)
        self.b = float(turret_offset)
        #: the compiled closed forms (hot_path), None for the pure-Python path
        self._hot = hot_path.module()
        self._hot_geometry = np.array([self.a, self.b, self.r_left, self.r_right])

    @property
    def joint_names(self) -> tuple[str, ...]:
        return (LEFT_WHEEL, RIGHT_WHEEL, TURRET)

    # -- kinematics -----------------------------------------------------------
    def inverse(self, positions: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """(wL, wR, phi_dot) [rad/s] for body twist (vx, vy, wz) at turret angle phi."""
        if self._hot is not None:
            return self._hot.inverse(hot_path.KIND_DDROT, positions, twist, self._hot_geometry)
        phi = positions[2]
        s, c = math.sin(phi), math.cos(phi)
        vx, vy, wz = twist[0], twist[1], twist[2]
        v = vx * c - vy * s                 # projection on the drive base's forward axis
        wd = (vx * s + vy * c) / self.b     # the turret axis swings on the lever b
        return np.array([(v - self.a * wd) / self.r_left,
                         (v + self.a * wd) / self.r_right,
                         wz - wd])

    def forward(self, positions: np.ndarray, velocities: np.ndarray,
                estimator: str = "slip_min") -> np.ndarray:
        """Body twist (vx, vy, wz) from (wL, wR, phi_dot); exact for every estimator."""
        if estimator not in ESTIMATORS:
            raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
        phi = positions[2]
        s, c = math.sin(phi), math.cos(phi)
        wl, wr, dphi = velocities[0], velocities[1], velocities[2]
        # each wheel's rim speed, then the unicycle of the drive base
        vl, vr = self.r_left * wl, self.r_right * wr
        v = 0.5 * (vl + vr)
        wd = 0.5 * (vr - vl) / self.a
        return np.array([v * c + self.b * wd * s,
                         -v * s + self.b * wd * c,
                         wd + dphi])

    def estimate(self, positions: np.ndarray, velocities: np.ndarray,
                 estimator: str = "slip_min") -> tuple[np.ndarray, np.ndarray]:
        """(twist, residual): exact, so the residual is always empty."""
        return self.forward(positions, velocities, estimator), _NO_RESIDUAL

    def hot_path_geometry(self, estimator: str = "slip_min") -> tuple[int, np.ndarray] | None:
        """The compiled forward kinematics serve every estimator (they are exact)."""
        return hot_path.KIND_DDROT, self._hot_geometry

    def jacobian(self, positions: np.ndarray) -> np.ndarray:
        """J_joint_to_base (3x3): twist = J @ (wL, wR, phi_dot)."""
        phi = positions[2]
        s, c = math.sin(phi), math.cos(phi)
        kl, kr = 0.5 * self.r_left / self.a, 0.5 * self.r_right / self.a
        return np.array([[kl * (self.a * c - self.b * s), kr * (self.a * c + self.b * s), 0.0],
                         [-kl * (self.a * s + self.b * c), kr * (self.b * c - self.a * s), 0.0],
                         [-kl, kr, 1.0]])

    def paper_jacobian(self, theta_s: float) -> np.ndarray:
        """Eq. 1 as printed, with s = sin, c = cos (the paper's frame, see module doc).

        Maps (theta_1 = right wheel, theta_2 = left wheel, theta_s) rates to
        (X lateral right, Y forward, Phi CCW).
        """
        r, a, b = self.r, self.a, self.b
        s, c = math.sin(theta_s), math.cos(theta_s)
        return np.array([[-r * (b * c + a * s) / (2 * a), r * (b * c - a * s) / (2 * a), 0.0],
                         [-r * (b * s - a * c) / (2 * a), r * (b * s + a * c) / (2 * a), 0.0],
                         [r / (2 * a), -r / (2 * a), -1.0]])

    # -- configuration ----------------------------------------------------------
    @classmethod
    def param_specs(cls, params: Mapping[str, object]) -> list[ParamSpec]:
        return [
            _positive("ddrot.wheel_radius", "Drive wheel radius r [m]."),
            _positive("ddrot.left_wheel_radius",
                      "Radius [m] of the left wheel when the two differ (default "
                      "ddrot.wheel_radius).", default=number_or_none(params.get(
                          "ddrot.wheel_radius"))),
            _positive("ddrot.right_wheel_radius",
                      "Radius [m] of the right wheel when the two differ (default "
                      "ddrot.wheel_radius).", default=number_or_none(params.get(
                          "ddrot.wheel_radius"))),
            _positive("ddrot.half_wheel_separation",
                      "Half the distance between the wheels' contact points, a [m]."),
            # minimum 0 inclusive: b = 0 reaches the constructor, whose error
            # explains why it is not allowed (the base is not holonomic)
            ParamSpec("ddrot.turret_offset", "double",
                      "Distance b [m] from the axle midpoint forward to the turret axis; "
                      "must be > 0 for holonomic motion.", minimum=0.0, maximum=100.0),
        ]

    @classmethod
    def from_params(cls, values: Mapping[str, object]) -> "OffsetTurretKinematics":
        kin = cls(values["ddrot.wheel_radius"], values["ddrot.half_wheel_separation"],
                  values["ddrot.turret_offset"], values["ddrot.left_wheel_radius"],
                  values["ddrot.right_wheel_radius"])
        return kin
