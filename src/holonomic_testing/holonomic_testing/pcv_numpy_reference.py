"""The PCV's torque-mode equations as main 7112ec2 computed them, in numpy:
Lambda and mu (:mod:`pcv_base.dynamics`), the C#^T F distribution
(:mod:`pcv_base.torque_distribution`, eq. 14) and the operational-space law
(:mod:`holonomic_core.torque`, eqs. 5 and 6). They were rewritten as scalar
arithmetic on floats (a numpy call on a 3-vector costs microseconds); this
copy, verbatim but for names, is the reference the rewrite is tested against
(``pcv_base/test/test_dynamics_reference.py``) and the baseline that
``bench/torque_law.py`` times it against. Not used by the product.
"""

from __future__ import annotations

import math

import numpy as np

from holonomic_core.se2 import compose, integrate_arc, relative_pose, rotate


def ref_caster_jacobians(dyn, i: int, phi: float):
    cas = dyn.kin.casters[i]
    sx, sy = cas.axis
    b, r, h = cas.caster_offset, cas.wheel_radius, cas.h
    cb, sb = math.cos(cas.beta), math.sin(cas.beta)
    c, s = math.cos(phi), math.sin(phi)
    steer = np.array([-s / b, c / b, h * (cb * c + sb * s) / b - 1.0])
    roll = np.array([c / r, s / r, h * (cb * s - sb * c) / r])
    d_steer = np.array([-c / b, -s / b, h * (sb * c - cb * s) / b])
    d_roll = np.array([-s / r, c / r, h * (cb * c + sb * s) / r])
    n_vec, d_n = np.array([-s, c]), np.array([-c, -s])

    def point(arm):
        px, py = sx - arm * c, sy - arm * s
        rows = np.array([[1.0, 0.0, -py], [0.0, 1.0, px]]) - arm * np.outer(n_vec, steer)
        d_rows = (np.array([[0.0, 0.0, arm * c], [0.0, 0.0, arm * s]])
                  - arm * (np.outer(d_n, steer) + np.outer(n_vec, d_steer)))
        return rows, d_rows

    yaw = np.array([0.0, 0.0, 1.0]) + steer
    fork_xy, d_fork_xy = point(0.5 * b)
    wheel_xy, d_wheel_xy = point(b)
    return (np.vstack([fork_xy, yaw]), np.vstack([wheel_xy, yaw, roll]),
            np.vstack([d_fork_xy, d_steer]), np.vstack([d_wheel_xy, d_steer, d_roll]))


def ref_terms(dyn, positions, twist=None):
    body = dyn.body
    fork_m = np.array([body.fork_mass, body.fork_mass, body.fork_inertia])
    wheel_m = np.array([body.wheel_mass, body.wheel_mass, body.wheel_inertia_yaw,
                        body.wheel_inertia_spin])
    chassis = np.diag([body.chassis_mass, body.chassis_mass, body.chassis_inertia])
    steer = np.asarray(positions, float)[0::2]
    lam = chassis.copy()
    mu = np.zeros(3)
    x_dot = None if twist is None else np.asarray(twist, float)
    if x_dot is not None:
        wz = x_dot[2]
        mu += chassis @ np.array([-wz * x_dot[1], wz * x_dot[0], 0.0])
    for i, phi in enumerate(steer):
        fork, wheel, d_fork, d_wheel = ref_caster_jacobians(dyn, i, float(phi))
        for J, dJ, masses in ((fork, d_fork, fork_m), (wheel, d_wheel, wheel_m)):
            lam += J.T @ (masses[:, None] * J)
            if x_dot is None:
                continue
            v = J @ x_dot
            phi_dot = v[2] - wz
            accel = (dJ * phi_dot) @ x_dot
            accel[0] -= wz * v[1]
            accel[1] += wz * v[0]
            mu += J.T @ (masses * accel)
    return lam, mu


def ref_torque_distribution(kin, positions, force):
    fx, fy, tz = (float(v) for v in force)
    phi = np.asarray(positions, float)[0::2]
    c, s = np.cos(phi), np.sin(phi)
    px, py = kin.sx - kin.b * c, kin.sy - kin.b * s
    n = len(kin.casters)
    cx, cy = px.mean(), py.mean()
    qx, qy = px - cx, py - cy
    nu = (tz - (cx * fy - cy * fx)) / float((qx * qx + qy * qy).sum())
    f_x, f_y = fx / n - nu * qy, fy / n + nu * qx
    out = np.empty(2 * n)
    out[0::2] = kin.b * (-s * f_x + c * f_y)
    out[1::2] = kin.r * (c * f_x + s * f_y)
    return out


class RefLaw:
    """OperationalSpaceController.step (eqs. 5, 6 and 14) as main 7112ec2
    computed it, on :func:`ref_terms` and :func:`ref_torque_distribution`;
    ``dyn``: the PcvDynamics whose geometry and body parameters it uses."""

    MAX_ERROR = (0.15, 0.15, 0.3)

    def __init__(self, dyn, kp, kv, max_efforts, pose):
        self.dyn, self.kp, self.kv = dyn, np.asarray(kp, float), np.asarray(kv, float)
        self.max_efforts = np.asarray(max_efforts, float)
        self.ref_pose, self.ref_twist = np.array(pose, dtype=float), np.zeros(3)

    def step(self, positions, pose, twist, reference_twist, dt):
        ref_twist = np.asarray(reference_twist, float)
        accel = (ref_twist - self.ref_twist) / dt
        mid = 0.5 * (ref_twist + self.ref_twist)
        self.ref_pose = np.array(integrate_arc(self.ref_pose, mid[0] * dt, mid[1] * dt,
                                               mid[2] * dt))
        self.ref_twist = ref_twist
        e_pose = -relative_pose(pose, self.ref_pose)
        rx, ry = rotate(self.ref_twist[0], self.ref_twist[1], self.ref_pose[2] - pose[2])
        e_twist = np.asarray(twist, float) - np.array([rx, ry, self.ref_twist[2]])
        if not all(abs(e) <= m for e, m in zip(e_pose, self.MAX_ERROR)):
            self.ref_pose = compose(pose, -np.clip(e_pose, -np.array(self.MAX_ERROR),
                                                   self.MAX_ERROR))
        e_pose = np.clip(e_pose, -np.array(self.MAX_ERROR), self.MAX_ERROR)
        f_star = -self.kp * e_pose - self.kv * e_twist + accel
        lam, mu = ref_terms(self.dyn, positions, twist)
        wrench = lam @ f_star + mu
        torques = ref_torque_distribution(self.dyn.kin, positions, wrench)
        worst = float(np.max(np.abs(torques) / self.max_efforts))
        if not math.isfinite(worst):
            return np.zeros_like(torques)
        return torques / worst if worst > 1.0 else torques
