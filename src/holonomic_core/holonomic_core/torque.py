"""Dynamically decoupled torque control (Holmberg & Khatib, Sec. 4).

``F = Lambda F* + mu`` (eq. 5) with the PD law on a reference trajectory
``F* = -Kp (x - x_d) - Kv (x_dot - x_dot_d) + x_ddot_d`` (eq. 6), and the joint
torques ``Gamma' = C#^T F`` (eq. 14): the dual of the slip-minimising
estimator, which spreads the tractive effort over the wheels so that the
contact forces are as even as possible. The velocity feedback ``x_dot`` is
the slip-minimising odometry's twist, the position feedback its pose.

The reference is the commanded twist after the controller's limits (so it
never asks for more than the base may do), integrated on SE(2) into a
reference pose: ``x_d``, ``x_dot_d`` and ``x_ddot_d`` (the change of the
limited twist over the cycle). Errors are expressed in base_link. When the
base cannot follow (held, pushed, saturated), the reference is pulled back to
within ``max_error`` of the measured pose instead of running away; a base
that stays far off its joint-rate reference trips the reading monitor's
tracking check as in velocity mode. The reference restarts at the measured
pose on every arming.
"""

from __future__ import annotations

import math

import numpy as np

from holonomic_core import plugins
from holonomic_core.se2 import compose, integrate_arc, rotate, wrap_angle
from holonomic_core.schema import ConfigError

#: largest position / heading error the reference may run ahead [m, rad]
MAX_ERROR = (0.15, 0.15, 0.3)


def dynamics_for(model):
    """The dynamic model of ``model`` (its family's ``holonomic.dynamics`` entry
    point) or ConfigError if its family has none."""
    if not plugins.provides("dynamics", model.kind):
        raise ConfigError("control_mode", "torque",
                          f"'velocity' for kinematics '{model.kind}' (torque mode needs a "
                          f"dynamic model; families with one: {list(plugins.names('dynamics'))})")
    dynamics = plugins.load("dynamics", model.kind, "control_mode")
    try:
        return dynamics.from_model(model)
    except ValueError as exc:
        raise ConfigError("control_mode", "torque", f"'velocity' for this robot ({exc})") from exc


class OperationalSpaceController:
    """Eqs. 5, 6 and 14 for one base; ``step`` once per control cycle.

    ``kp`` [1/s^2] and ``kv`` [1/s]: per-axis gains of the unit-mass system;
    ``max_efforts`` [N m]: joint torque limits (the torques are scaled
    together to respect them, keeping the wrench's direction).
    """

    def __init__(self, model, kp, kv, max_efforts, dynamics=None, distribution: str = "slip_min"):
        self.model = model
        self.dynamics = dynamics if dynamics is not None else dynamics_for(model)
        self.kp = np.asarray(kp, float)
        self.kv = np.asarray(kv, float)
        # per-axis gains as floats for the cycle (a scalar gain applies to all axes)
        self._kp = tuple(np.broadcast_to(self.kp, 3).tolist())
        self._kv = tuple(np.broadcast_to(self.kv, 3).tolist())
        self.max_efforts = np.asarray(max_efforts, float)
        if distribution not in ("slip_min", "pinv"):
            raise ValueError(f"distribution must be 'slip_min' or 'pinv', got {distribution!r}")
        #: C#^T (slip_min, the paper's) or pinv(C)^T (for comparison)
        self.distribution = distribution
        self.ref_pose = np.zeros(3)
        self.ref_twist = np.zeros(3)
        self.wrench = np.zeros(3)

    def reset(self, pose) -> None:
        """Restart the reference at rest at ``pose`` (odom) [m, m, rad]."""
        self.ref_pose = np.array(pose, dtype=float)
        self.ref_twist = np.zeros(3)

    def errors(self, pose, twist) -> tuple[np.ndarray, np.ndarray]:
        """(pose error, twist error) of the base against the reference, in
        base_link [m, m, rad] and [m/s, m/s, rad/s]."""
        e_pose, e_twist = self._errors(pose, twist)
        return np.array(e_pose), np.array(e_twist)

    def _errors(self, pose, twist) -> tuple[tuple, tuple]:
        """:meth:`errors` as tuples of floats (the cycle works on scalars: a
        numpy call on a 3-vector costs microseconds, the arithmetic nanoseconds)."""
        px, py, pth = (float(v) for v in pose)
        rx, ry, rth = self.ref_pose.tolist()
        # the base's offset from the reference, along the base's own axes:
        # -relative_pose(pose, ref_pose)
        dx, dy = rotate(rx - px, ry - py, -pth)
        e_pose = (-dx, -dy, -wrap_angle(rth - pth))
        # the reference twist, turned into the actual base frame
        vx, vy, wz = self.ref_twist.tolist()
        tx, ty = rotate(vx, vy, rth - pth)
        x_dot = tuple(float(v) for v in twist)
        return e_pose, (x_dot[0] - tx, x_dot[1] - ty, x_dot[2] - wz)

    def step(self, positions, pose, twist, reference_twist, dt: float,
             reference_acceleration=None) -> np.ndarray:
        """Joint torques [N m] for this cycle.

        ``positions``: joint positions; ``pose`` (odom) and ``twist`` (base
        link): the odometry's estimate; ``reference_twist``: the limited
        commanded body twist; ``reference_acceleration``: its body-frame
        derivative if known (a trajectory), else taken from the twist's change.
        """
        ref = tuple(float(v) for v in reference_twist)
        prev = self.ref_twist.tolist()
        if reference_acceleration is None:
            accel = tuple((r - p) / dt for r, p in zip(ref, prev))
        else:
            accel = tuple(float(v) for v in reference_acceleration)
        # advance the reference pose by the reference twist over the cycle
        mid = [0.5 * (r + p) for r, p in zip(ref, prev)]
        self.ref_pose = np.array(integrate_arc(self.ref_pose.tolist(), mid[0] * dt, mid[1] * dt,
                                               mid[2] * dt))
        self.ref_twist = np.array(ref)
        return self._torques(positions, pose, twist, accel)

    def track(self, positions, pose, twist, ref_pose, ref_twist, ref_acceleration) -> np.ndarray:
        """Joint torques [N m] to follow a trajectory sample: the reference
        pose (odom), twist and body-frame acceleration given directly (a
        precise move), instead of integrated from commands."""
        self.ref_pose = np.array(ref_pose, dtype=float)
        self.ref_twist = np.array(ref_twist, dtype=float)
        return self._torques(positions, pose, twist,
                             tuple(float(v) for v in ref_acceleration))

    def _torques(self, positions, pose, twist, accel) -> np.ndarray:
        e_pose, e_twist = self._errors(pose, twist)
        self._limit_reference(pose, e_pose)
        # F* = -Kp (x - x_d) - Kv (x_dot - x_dot_d) + x_ddot_d (eq. 6), the
        # position error clipped to MAX_ERROR (NaN passes through min/max)
        f_star = np.array([-kp * min(max(e, -m), m) - kv * et + a for kp, kv, e, m, et, a
                           in zip(self._kp, self._kv, e_pose, MAX_ERROR, e_twist, accel)])
        lam, mu = self.dynamics.terms(positions, twist)
        self.wrench = lam @ f_star + mu                                      # eq. 5
        return self.distribute(positions, self.wrench)

    def distribute(self, positions, wrench) -> np.ndarray:
        """Joint torques producing ``wrench`` (F = C^T Gamma'), scaled into
        the torque limits."""
        if self.distribution == "slip_min":
            torques = self.dynamics.torque_distribution(positions, wrench)      # C#^T F
        else:
            kin = self.model.kinematics
            torques = np.linalg.pinv(kin.constraint_matrix(positions)).T @ wrench
        # numpy's max, not Python's: a NaN anywhere makes it NaN (zero torques)
        worst = float(np.max(np.abs(torques) / self.max_efforts))
        if not math.isfinite(worst):
            return np.zeros_like(torques)
        return torques / worst if worst > 1.0 else torques

    def _limit_reference(self, pose, e_pose) -> None:
        """Pull the reference to within MAX_ERROR of the measured pose."""
        if all(abs(e) <= m for e, m in zip(e_pose, MAX_ERROR)):
            return
        # ref = pose - R(theta) e (position), theta - e_theta (heading), e
        # clipped to MAX_ERROR
        self.ref_pose = compose(pose, [-min(max(e, -m), m) for e, m in zip(e_pose, MAX_ERROR)])
