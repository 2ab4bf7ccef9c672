"""Dead reckoning from joint encoders, with a pose covariance that grows.

The pose is integrated from *encoder displacements*, not from time x rate:
the joint displacement ``dq`` over a cycle maps through the (linear-in-rates)
forward kinematics, evaluated at the mid-point configuration, to a body
displacement ``(dx, dy, dtheta)``, which is composed exactly on SE(2) as a
constant-twist arc. Consequences a user relies on: a stalled loop (200 ms
between reads) integrates the motion that really happened, and a clock that
jumps backwards cannot produce a pose jump (time is only used to report the
velocity).

Covariance: each increment adds variance proportional to the distance and
angle it covers (the classic odometry error model: errors accumulate with
travel, not with time), propagated through the pose composition's Jacobian.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np


#: contact-velocity residual [m/s] that doubles the odometry variances
SLIP_SCALE = 0.01


def wrap_angle(angle: float) -> float:
    """Angle wrapped to [-pi, pi] [rad]."""
    return math.remainder(angle, 2.0 * math.pi)


def compose_arc(pose, dx: float, dy: float, dtheta: float) -> tuple[float, float]:
    """World-frame displacement of a constant-twist arc.

    The body moves by ``(dx, dy, dtheta)`` integrated as a constant body
    twist (the body-frame chord of an arc), starting at heading ``pose[2]``.
    Returns the world (odom-frame) displacement of the origin.
    """
    if abs(dtheta) < 1e-6:
        # series of sin(t)/t and (1 - cos t)/t to 2nd order
        a = 1.0 - dtheta * dtheta / 6.0
        b = 0.5 * dtheta
    else:
        a = math.sin(dtheta) / dtheta
        b = (1.0 - math.cos(dtheta)) / dtheta
    bx = a * dx - b * dy
    by = b * dx + a * dy
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return c * bx - s * by, s * bx + c * by


@dataclass(frozen=True)
class OdometryNoise:
    """Odometry error model.

    ``linear_variance_per_meter`` [m^2/m]: position variance added per metre
    travelled, along and across the motion; ``angular_variance_per_radian``
    [rad^2/rad] and ``angular_variance_per_meter`` [rad^2/m]: heading variance
    per radian turned and per metre travelled; ``twist_variance``: diagonal of
    the reported twist covariance [(m/s)^2, (m/s)^2, (rad/s)^2].
    """

    linear_variance_per_meter: float = 4e-4
    angular_variance_per_radian: float = 1e-3
    angular_variance_per_meter: float = 4e-4
    twist_variance: tuple[float, float, float] = (4e-4, 4e-4, 1e-3)


class Odometry:
    """Integrates joint encoder readings into the pose of base_link in odom.

    ``model`` is a :class:`holonomic_core.model.RobotModel`; ``estimator`` is
    one of holonomic_core.kinematics.ESTIMATORS.
    """

    def __init__(self, model, estimator: str = "slip_min", noise: OdometryNoise | None = None):
        self.model = model
        self.estimator = estimator
        self.noise = noise or OdometryNoise()
        self._base_twist_cov = np.diag(self.noise.twist_variance).astype(float)
        self.reset()

    def reset(self, pose=(0.0, 0.0, 0.0)) -> None:
        """Set the pose [m, m, rad] and zero the covariance and the twist.

        The next reading becomes the new encoder reference, so a reset during
        motion neither jumps nor loses the motion after it.
        """
        self.pose = np.array(pose, dtype=float)
        self.twist = np.zeros(3)
        # upper triangle (p00, p01, p02, p11, p12, p22) as Python floats: the
        # per-cycle update is scalar; the matrix is built when read
        self._P = (0.0,) * 6
        self.residual = np.zeros(0)
        self.slip_factor = 1.0
        self.distance = 0.0
        self._last_positions: np.ndarray | None = None
        self._last_stamp: float | None = None

    @property
    def pose_covariance(self) -> np.ndarray:
        """Covariance (3 x 3) of (x, y, yaw) in odom [m^2, m rad, rad^2]."""
        p00, p01, p02, p11, p12, p22 = self._P
        return np.array([[p00, p01, p02], [p01, p11, p12], [p02, p12, p22]])

    @property
    def twist_covariance(self) -> np.ndarray:
        """Covariance (3 x 3) of the reported twist, scaled by the slip factor."""
        return self._base_twist_cov * self.slip_factor

    def rebase(self) -> None:
        """Keep the pose; take the next reading as the new encoder reference
        (after an implausible reading, or a gap in which the joints moved
        unobserved)."""
        self._last_positions = None
        self._last_stamp = None

    def update(self, positions: np.ndarray, stamp: float) -> bool:
        """Integrate the displacement since the last reading.

        ``positions`` [rad] in joint order, ``stamp`` [s]. Returns False when
        nothing was integrated (first reading, or non-finite positions, which
        are skipped and do not become the reference).
        """
        # one reduction: any nan or +-inf makes the sum non-finite
        if not math.isfinite(float(np.add.reduce(positions))):
            return False
        if self._last_positions is None:
            self._last_positions = np.array(positions, dtype=float)
            self._last_stamp = stamp
            return False
        dq = positions - self._last_positions
        mid = self._last_positions + 0.5 * dq
        # One fit of the displacement gives both; the fit is linear in the
        # joint motion, so the residual of dq over dt is the rate residual.
        disp, residual = self.model.kinematics.estimate(mid, dq, self.estimator)
        dt = stamp - self._last_stamp
        if dt > 0.0:
            self._update_slip(residual / dt)
        self._integrate(disp)
        if dt > 0.0:
            self.twist = disp / dt
        self._last_positions = np.array(positions, dtype=float)
        self._last_stamp = stamp
        return True

    def _integrate(self, disp: np.ndarray) -> None:
        dx, dy, dth = disp.tolist()
        x, y, heading = self.pose.tolist()
        wx, wy = compose_arc((x, y, heading), dx, dy, dth)
        self.pose[:] = (x + wx, y + wy, wrap_angle(heading + dth))
        # Covariance: P' = F P F^T + G Q G^T, F = d(pose')/d(pose), G maps
        # body-frame increment noise to the odom frame.
        dist = math.hypot(dx, dy)
        self.distance += dist
        n = self.noise
        var_lin = n.linear_variance_per_meter * dist
        var_ang = n.angular_variance_per_radian * abs(dth) + n.angular_variance_per_meter * dist
        if var_lin == 0.0 and var_ang == 0.0:
            return
        # P' = F P F^T + G Q G^T with F = [[1, 0, -wy], [0, 1, wx], [0, 0, 1]]
        # (the world displacement depends on the heading) and G the rotation
        # to odom; Q = diag(var_lin, var_lin, var_ang) is isotropic in x, y,
        # so G Q G^T = Q. Written out: 3x3 numpy products cost more than the
        # rest of the control cycle.
        k = self.slip_factor
        a, b = -wy, wx
        p00, p01, p02, p11, p12, p22 = self._P
        self._P = (p00 + 2.0 * a * p02 + a * a * p22 + k * var_lin,
                   p01 + a * p12 + b * p02 + a * b * p22,
                   p02 + a * p22,
                   p11 + 2.0 * b * p12 + b * b * p22 + k * var_lin,
                   p12 + b * p22,
                   p22 + k * var_ang)

    def _update_slip(self, residual: np.ndarray) -> None:
        """Scale the covariances by the slip the estimator could not explain.

        With residual norm rho [m/s] per wheel unit, the twist variance and the
        pose variance added by this increment are multiplied by
        ``slip_factor = 1 + (max rho / SLIP_SCALE)^2``: 1 cm/s of unexplained
        contact velocity doubles them. A square (DDROT) model has no residual.
        """
        self.residual = residual
        self.slip_factor = 1.0
        if residual.size:
            self.slip_factor = 1.0 + (max(residual.tolist()) / SLIP_SCALE) ** 2
