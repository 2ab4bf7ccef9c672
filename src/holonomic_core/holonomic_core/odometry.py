"""Dead reckoning from joint encoders, with a pose covariance that grows.

The pose is integrated from *encoder displacements*, not from time x rate:
the joint displacement ``dq`` over a cycle maps through the (linear-in-rates)
forward kinematics, evaluated at the mid-point configuration, to a body
displacement ``(dx, dy, dtheta)``, which is composed exactly on SE(2) as a
constant-twist arc. Consequences a user relies on: a stalled loop (200 ms
between reads) integrates the motion that really happened, and a clock that
jumps backwards cannot produce a pose jump (time is only used to report the
velocity).

Twist: a least-squares line through the last readings within a time window
(``twist_window``, using their stamps), per joint; its slope is the joint
rate, mapped through the forward kinematics at the window's mean
configuration. Why a line fit: it is exact at constant speed (no bias), uses
the true, jittered sample times (a Savitzky-Golay filter assumes a uniform
grid), has a known delay (half the window on a ramp) and a finite memory (a
glitch leaves after one window), and has nothing to tune but the window. A
Kalman filter would need a process-noise model of the robot's accelerations.
Over one cycle it is the plain difference of two readings.

Covariance (see :class:`OdometryNoise`): each increment adds variance that
grows with the distance and angle it covers and with the contact slip the
estimator could not explain (squared residual x time),
propagated through the pose composition's Jacobian. The coefficients come
from ``holonomic-odometry-experiment --calibrate`` (ground truth in the
simulator, or whatever reference a user has on their floor).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from holonomic_core import hot_path
from holonomic_core.se2 import compose_arc, rotate, wrap_angle


@dataclass(frozen=True)
class OdometryNoise:
    """Odometry error model (the defaults: the XR4000's profile for its
    default floor, ``holonomic-odometry-experiment --calibrate`` on the drive
    model, checked on kinds of motion it was not fitted on, the command in
    config/xr4000.yaml; see docs/odometry_experiment.md).

    Per increment that moves the base by ``dist`` [m] and turns it by
    ``dtheta`` [rad] while the estimator leaves ``rho`` [m/s] of contact
    velocity unexplained (RMS over the wheel units) for ``dt`` [s]:

    * position variance, isotropic in x, y [m^2]:
      ``linear_variance_per_meter * dist + slip_position_gain * rho^2 * dt
      + slip4_position_gain * rho^4 * dt``;
    * heading variance [rad^2]: ``angular_variance_per_radian * |dtheta| +
      angular_variance_per_meter * dist + slip_heading_gain * rho^2 * dt
      + slip4_heading_gain * rho^4 * dt``.

    The slip terms are those of a velocity error of std ~rho with a
    correlation time: ``slip_position_gain`` [s] (twice the correlation
    time, times the squared ratio of twist error to residual),
    ``slip_heading_gain`` [s/m^2]. They make the covariance scale with the
    slip level (sigma ~ rho), which a term linear in rho does not.

    The rho^4 terms (``slip4_position_gain`` [s^3/m^2],
    ``slip4_heading_gain`` [s^3/m^4]): the share of the slip that no
    residual shows grows with the slip. Tyres that grip yield to the
    wheels' fight (conflict slip), which lies in the residual's space and
    which C# ignores: a large residual with a small error. Tyres that slide
    also slip *together*, along a rigid motion the fit takes for the base's:
    an error the residual only hints at (the explanation the data fit; the
    calibration measures only the outcome). So the error's variance grows
    faster than rho^2: a variance ~ rho^2 sized for the slippery floor
    over-covers the nominal one, one sized for the nominal floor
    under-covers the slippery one, while one ~ rho^4 covers both (on the
    XR4000's drive model the calibration, given both terms, puts all the
    weight on rho^4; docs/odometry_experiment.md).

    Latency, a term that does not accumulate: a reading older than its
    stamp (a delay its driver does not know of: a drive's filter, a reading
    stamped when it arrived rather than when it was sampled) puts the
    published pose where the base was a time
    ``tau`` before the stamp, off from the true pose by ``tau * u`` with
    ``u = (R(yaw) (vx, vy), wz)`` the current twist in odom. With ``tau``
    unknown but of variance ``latency_variance`` [s^2] (its mean square: a
    fixed delay is a variance of delay^2), the published pose covariance is
    the accumulated one plus ``latency_variance * u u^T`` (rank one, along
    the motion). On a good floor this is most of the heading error: it
    follows the turn rate and comes back when the base stops turning, which
    a random walk, growing for ever, cannot describe (the accumulated terms
    either over-cover the good floor or under-cover the slippery one).

    Twist covariance, diagonal (vx, vy, wz) [(m/s)^2, (m/s)^2, (rad/s)^2]:
    ``twist_variance + twist_slip_gain * rho^2 + twist_lag_gain * (a lag)^2``
    per axis, with ``a`` the estimated acceleration of that axis and ``lag``
    the filter's delay (half the twist window): a line fit lags a ramp by
    ``a * lag``. ``twist_slip_gain`` is [-] for vx, vy and [1/m^2] for wz;
    ``twist_lag_gain`` is [-].
    """

    linear_variance_per_meter: float = 8.26e-07
    angular_variance_per_radian: float = 1.57e-06
    angular_variance_per_meter: float = 2.28e-06
    slip_position_gain: float = 8.14e-09
    slip_heading_gain: float = 0.644
    twist_variance: tuple[float, float, float] = (2.22e-06, 1.89e-06, 1.22e-06)
    twist_slip_gain: tuple[float, float, float] = (0.378, 0.237, 44.2)
    twist_lag_gain: tuple[float, float, float] = (0.543, 0.571, 0.684)
    latency_variance: float = 0.0
    slip4_position_gain: float = 1.41e-10
    slip4_heading_gain: float = 2.56e-06


class Odometry:
    """Integrates joint encoder readings into the pose of base_link in odom.

    ``model`` is a :class:`holonomic_core.model.RobotModel`; ``estimator`` is
    one of holonomic_core.kinematics.ESTIMATORS; ``twist_window`` [s] is the
    span of readings the twist's line fit uses (0: the last two readings).
    """

    def __init__(self, model, estimator: str = "slip_min", noise: OdometryNoise | None = None,
                 twist_window: float = 0.0):
        if not (math.isfinite(twist_window) and twist_window >= 0.0):
            raise ValueError(f"twist_window must be a finite number >= 0 s, got {twist_window}")
        self.model = model
        self.estimator = estimator
        self.noise = noise or OdometryNoise()
        self.twist_window = float(twist_window)
        # the compiled increment (hot_path) where the kinematics have one for
        # this estimator; None: the pure-Python arithmetic below
        hot = hot_path.module()
        self._hot = hot
        self._kernel = model.kinematics.hot_path_geometry(estimator) if hot is not None else None
        n = self.noise
        self._noise_terms = np.array([n.linear_variance_per_meter, n.angular_variance_per_radian,
                                      n.angular_variance_per_meter, n.slip_position_gain,
                                      n.slip_heading_gain, n.slip4_position_gain,
                                      n.slip4_heading_gain], dtype=float)
        self._twist_terms = np.array(tuple(n.twist_variance) + tuple(n.twist_slip_gain)
                                     + tuple(n.twist_lag_gain), dtype=float)
        self.reset()

    def reset(self, pose=(0.0, 0.0, 0.0)) -> None:
        """Set the pose [m, m, rad] and zero the covariance and the twist.

        The next reading becomes the new encoder reference, so a reset during
        motion neither jumps nor loses the motion after it.
        """
        self.pose = np.array(pose, dtype=float)
        self.twist = np.zeros(3)
        #: [m/s, m/s, rad/s] the body twist over the last reading interval
        #: alone (no window, no lag): velocity feedback for the torque
        #: controller, where the window's delay would cost damping
        self.rate_twist = np.zeros(3)
        # upper triangle (p00, p01, p02, p11, p12, p22) as Python floats: the
        # per-cycle update is scalar; the matrix is built when read
        self._P = (0.0,) * 6
        self.residual = np.zeros(0)
        #: RMS over the wheel units of the contact residual [m/s], last cycle
        self.slip = 0.0
        self.distance = 0.0
        self._twist_var = tuple(float(v) for v in self.noise.twist_variance)
        self._last_positions: np.ndarray | None = None
        self._last_stamp: float | None = None
        # (stamp, positions, twist) of the readings in the twist window
        self._history: deque = deque()

    @property
    def pose_covariance(self) -> np.ndarray:
        """Covariance (3 x 3) of (x, y, yaw) in odom [m^2, m rad, rad^2]:
        the accumulated one plus the latency term of the current twist
        (:class:`OdometryNoise`)."""
        p00, p01, p02, p11, p12, p22 = self._P
        P = np.array([[p00, p01, p02], [p01, p11, p12], [p02, p12, p22]])
        lat = self.noise.latency_variance
        if lat > 0.0:
            vx, vy, wz = self.twist.tolist()
            u = np.array([*rotate(vx, vy, float(self.pose[2])), wz])
            P += lat * np.outer(u, u)
        return P

    @property
    def twist_covariance(self) -> np.ndarray:
        """Covariance (3 x 3, diagonal) of the reported twist in base_link
        [(m/s)^2, (m/s)^2, (rad/s)^2] (model in :class:`OdometryNoise`)."""
        return np.diag(self._twist_var)

    def set_pose(self, pose, covariance=None) -> None:
        """Jump to ``pose`` (x, y, yaw) [m, m, rad] with ``covariance`` (9
        values, the 3 x 3 of x, y, yaw row-major; None: zero) -- a pose from
        localization (set_pose). The encoder reference, the twist and the
        path length are kept: during motion the odometry goes on from the new
        pose without losing or repeating a displacement."""
        self.pose[:] = (float(pose[0]), float(pose[1]), wrap_angle(float(pose[2])))
        if covariance is None:
            self._P = (0.0,) * 6
        else:
            c = [float(v) for v in covariance]
            self._P = (c[0], c[1], c[2], c[4], c[5], c[8])

    def rebase(self) -> None:
        """Keep the pose; take the next reading as the new encoder reference
        (after an implausible reading, or a gap in which the joints moved
        unobserved)."""
        self._last_positions = None
        self._last_stamp = None
        self._history.clear()

    def update(self, positions: np.ndarray, stamp: float) -> bool:
        """Integrate the displacement since the last reading.

        ``positions`` [rad] in joint order, ``stamp`` [s]. Returns False when
        nothing was integrated (first reading, or non-finite positions, which
        are skipped and do not become the reference).
        """
        if self._kernel is not None and self._last_positions is not None:
            dt = stamp - self._last_stamp
            if dt > 0.0:
                return self._update_compiled(positions, stamp, dt)
        # one reduction: any nan or +-inf makes the sum non-finite
        if not math.isfinite(float(np.add.reduce(positions))):
            return False
        if self._last_positions is None:
            self._last_positions = np.array(positions, dtype=float)
            self._last_stamp = stamp
            self._history.clear()
            self._history.append((stamp, self._last_positions, self.twist))
            return False
        dt = stamp - self._last_stamp
        disp = self._increment(positions, dt)
        self._last_positions = np.array(positions, dtype=float)
        self._last_stamp = stamp
        if dt > 0.0:
            self._update_twist(disp, dt)
        elif dt < 0.0:
            # the clock went back: the window's stamps mean nothing any more
            self._history.clear()
            self._history.append((stamp, self._last_positions, self.twist))
        return True

    def _update_compiled(self, positions: np.ndarray, stamp: float, dt: float) -> bool:
        """:meth:`update` for an increment with dt > 0 on the compiled path:
        the check, the estimate and :meth:`_integrate` in one call."""
        kind, geometry = self._kernel
        step = self._hot.odometry_step(kind, geometry, self._last_positions, positions, dt,
                                       self.pose, self._P, self._noise_terms)
        if step is None:            # a non-finite position: skipped, not the reference
            return False
        (self.rate_twist, self.residual, disp, self.slip, self._P, dist,
         self._last_positions) = step
        self.distance += dist
        self._last_stamp = stamp
        self._update_twist(disp, dt)
        return True

    def _increment(self, positions: np.ndarray, dt: float) -> np.ndarray:
        """The pure-Python increment: estimate, then compose; returns the
        body displacement (dx, dy, dtheta) [m, m, rad]."""
        dq = positions - self._last_positions
        mid = self._last_positions + 0.5 * dq
        slip2 = slip2_dt = 0.0
        if dt > 0.0:
            # Fit the mean rates, not the displacement: slip_min and pinv are
            # linear in the joint motion, but the robust estimator's
            # thresholds are speeds [m/s]. The displacement is rate x dt.
            rate_twist, residual = self.model.kinematics.estimate(mid, dq / dt, self.estimator)
            disp = rate_twist * dt
            self.rate_twist = rate_twist
            self.residual = residual
            self.slip = (math.sqrt(float(np.dot(residual, residual)) / residual.size)
                         if residual.size else 0.0)
            slip2 = self.slip * self.slip
            slip2_dt = slip2 * dt
        else:
            # a repeated or backward stamp: no rate, but the motion is real
            disp = self.model.kinematics.forward(mid, dq, self.estimator)
        self._integrate(disp, slip2_dt, slip2_dt * slip2)
        return disp

    def _update_twist(self, disp: np.ndarray, dt: float) -> None:
        """Line fit through the readings of the last ``twist_window`` s."""
        history = self._history
        stamp, positions = self._last_stamp, self._last_positions
        # the readings within the window before this one, at least the last
        while len(history) > 1 and stamp - history[0][0] > self.twist_window + 1e-9:
            history.popleft()
        if self._kernel is not None:
            # compiled: the fit, the acceleration and the variances below, one call
            kind, geometry = self._kernel
            twist, self._twist_var = self._hot.twist_update(
                kind, geometry, history, stamp, positions, disp, dt, self._twist_terms,
                self.slip * self.slip, 0.5 * self.twist_window)
            history.append((stamp, positions, twist))
            self.twist = twist
            return
        if len(history) == 1:
            twist = disp / dt          # the line through two readings
        else:
            t = np.array([h[0] for h in history] + [stamp])
            q = np.array([h[1] for h in history] + [positions])
            tc = t - t.mean()
            qm = q.mean(axis=0)
            rates = tc @ (q - qm) / float(tc @ tc)
            twist = self.model.kinematics.forward(qm, rates, self.estimator)
        # acceleration over the window, for the lag term of the covariance
        t0, _, twist0 = history[0]
        accel = (twist - twist0) / (stamp - t0)
        history.append((stamp, positions, twist))
        self.twist = twist
        n = self.noise
        lag = 0.5 * self.twist_window
        rho2 = self.slip * self.slip
        self._twist_var = tuple(
            float(base + gain * rho2 + lag_gain * (a * lag) ** 2)
            for base, gain, lag_gain, a in zip(n.twist_variance, n.twist_slip_gain,
                                               n.twist_lag_gain, accel.tolist()))

    def _integrate(self, disp: np.ndarray, slip2_dt: float, slip4_dt: float) -> None:
        """Compose the displacement; grow the covariance (slip2_dt: rho^2 dt
        [m^2/s], slip4_dt: rho^4 dt [m^4/s^3])."""
        dx, dy, dth = disp.tolist()
        x, y, heading = self.pose.tolist()
        wx, wy = compose_arc((x, y, heading), dx, dy, dth)
        self.pose[:] = (x + wx, y + wy, wrap_angle(heading + dth))
        # Covariance: P' = F P F^T + G Q G^T, F = d(pose')/d(pose), G maps
        # body-frame increment noise to the odom frame.
        dist = math.hypot(dx, dy)
        self.distance += dist
        n = self.noise
        var_lin = (n.linear_variance_per_meter * dist + n.slip_position_gain * slip2_dt
                   + n.slip4_position_gain * slip4_dt)
        var_ang = (n.angular_variance_per_radian * abs(dth) + n.angular_variance_per_meter * dist
                   + n.slip_heading_gain * slip2_dt + n.slip4_heading_gain * slip4_dt)
        # (no shortcut when the step adds no noise: F P F^T still swings the
        # heading variance already accumulated into the position)
        # P' = F P F^T + G Q G^T with F = [[1, 0, -wy], [0, 1, wx], [0, 0, 1]]
        # (the world displacement depends on the heading) and G the rotation
        # to odom; Q = diag(var_lin, var_lin, var_ang) is isotropic in x, y,
        # so G Q G^T = Q. Written out: 3x3 numpy products cost more than the
        # rest of the control cycle.
        a, b = -wy, wx
        p00, p01, p02, p11, p12, p22 = self._P
        self._P = (p00 + 2.0 * a * p02 + a * a * p22 + var_lin,
                   p01 + a * p12 + b * p02 + a * b * p22,
                   p02 + a * p22,
                   p11 + 2.0 * b * p12 + b * b * p22 + var_lin,
                   p12 + b * p22,
                   p22 + var_ang)
