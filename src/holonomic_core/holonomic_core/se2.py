"""Planar poses (SE(2)): the one place every pose operation is written.

A pose is ``(x, y, yaw)`` [m, m, rad]: the position of a frame's origin and
its heading (CCW from the x axis, REP 103), both in a parent frame (``odom``,
the simulator's world). Angles returned are wrapped to [-pi, pi].

* :func:`compose` ``a * b``: the pose ``b``, given in frame ``a``, in ``a``'s parent;
* :func:`relative_pose` ``a^-1 * b``: the pose ``b`` seen from frame ``a``;
* :func:`rotate`: a planar vector turned by an angle;
* :func:`compose_arc` / :func:`integrate_arc`: the exact motion under a
  constant body twist (the odometry's and the torque reference's integration);
  :func:`arc_between` the inverse (the constant twist that joins two poses);
* :func:`yaw_of_quaternion` / :func:`quaternion_of_yaw`: to and from
  ``(x, y, z, w)`` quaternions (ROS messages, pybullet).
"""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(angle: float) -> float:
    """``angle`` [rad] wrapped to [-pi, pi]."""
    return math.remainder(angle, 2.0 * math.pi)


def wrap_angles(angles) -> np.ndarray:
    """Element-wise wrap of an array of angles [rad] to [-pi, pi)."""
    return np.remainder(np.asarray(angles, float) + math.pi, 2.0 * math.pi) - math.pi


def rotate(x: float, y: float, angle: float) -> tuple[float, float]:
    """The planar vector ``(x, y)`` turned CCW by ``angle`` [rad]."""
    c, s = math.cos(angle), math.sin(angle)
    return c * x - s * y, s * x + c * y


def compose(a, b) -> np.ndarray:
    """``a * b``: pose ``b`` (given in frame ``a``) expressed in ``a``'s parent frame."""
    dx, dy = rotate(b[0], b[1], a[2])
    return np.array([a[0] + dx, a[1] + dy, wrap_angle(a[2] + b[2])])


def relative_pose(start, end) -> np.ndarray:
    """``start^-1 * end``: pose ``end`` expressed in the frame of ``start``
    (both in the same parent frame)."""
    dx, dy = rotate(end[0] - start[0], end[1] - start[1], -start[2])
    return np.array([dx, dy, wrap_angle(end[2] - start[2])])


def relative_poses(starts, ends) -> np.ndarray:
    """Row-wise :func:`relative_pose` of two (k x 3) arrays of poses; the
    headings wrapped to [-pi, pi) as by :func:`wrap_angles`."""
    starts, ends = np.asarray(starts, float), np.asarray(ends, float)
    d = ends - starts
    c, s = np.cos(starts[:, 2]), np.sin(starts[:, 2])
    return np.column_stack((c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1],
                            wrap_angles(d[:, 2])))


def _arc_factors(dtheta: float) -> tuple[float, float]:
    """sin(t)/t and (1 - cos t)/t at t = ``dtheta`` [rad]: a constant body
    twist that turns by t moves the origin by [[a, -b], [b, a]] (dx, dy)."""
    if abs(dtheta) < 1e-6:
        # series of sin(t)/t and (1 - cos t)/t to 2nd order
        return 1.0 - dtheta * dtheta / 6.0, 0.5 * dtheta
    return math.sin(dtheta) / dtheta, (1.0 - math.cos(dtheta)) / dtheta


def compose_arc(pose, dx: float, dy: float, dtheta: float) -> tuple[float, float]:
    """World-frame displacement [m] of a constant-twist arc.

    The body moves by ``(dx, dy, dtheta)`` [m, m, rad] integrated as a
    constant body twist (the body-frame chord of an arc), starting at heading
    ``pose[2]``. Returns the displacement of the origin in the parent frame.
    """
    a, b = _arc_factors(dtheta)
    bx = a * dx - b * dy
    by = b * dx + a * dy
    return rotate(bx, by, pose[2])


def integrate_arc(pose, dx: float, dy: float, dtheta: float) -> tuple[float, float, float]:
    """The pose [m, m, rad] reached from ``pose`` by the constant-twist arc
    ``(dx, dy, dtheta)`` (body frame, see :func:`compose_arc`)."""
    wx, wy = compose_arc(pose, dx, dy, dtheta)
    return pose[0] + wx, pose[1] + wy, wrap_angle(pose[2] + dtheta)


def arc_between(start, end) -> np.ndarray:
    """The inverse of :func:`integrate_arc`: the body-frame ``(dx, dy,
    dtheta)`` [m, m, rad] whose constant-twist arc takes ``start`` to ``end``
    (the SE(2) logarithm of ``start^-1 end``; divided by the time between
    the two poses it is the mean body twist [m/s, m/s, rad/s] of the motion,
    whatever the sampling in between). ``dtheta`` is the heading change
    wrapped to [-pi, pi]."""
    x, y, dtheta = relative_pose(start, end)
    a, b = _arc_factors(dtheta)
    det = a * a + b * b
    return np.array([(a * x + b * y) / det, (a * y - b * x) / det, dtheta])


def yaw_of_quaternion(q) -> float:
    """Yaw [rad] (rotation about z, REP 103) of the unit quaternion ``q`` = (x, y, z, w)."""
    x, y, z, w = q
    return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def quaternion_of_yaw(yaw: float) -> tuple[float, float, float, float]:
    """The quaternion (x, y, z, w) of a rotation by ``yaw`` [rad] about z."""
    return 0.0, 0.0, math.sin(0.5 * yaw), math.cos(0.5 * yaw)
