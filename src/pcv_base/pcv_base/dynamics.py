"""Operational-space dynamics of a powered-caster vehicle (Holmberg & Khatib,
Sec. 3): ``Lambda(q) x_ddot + mu(q, x_dot) = F``.

``x_dot`` = (vx, vy, wz) is the body twist of base_link in base_link and
``x_ddot`` its time derivative *in body components*; ``F`` = (fx, fy, tz)
[N, N, N m] the wrench at base_link's origin in base_link, produced by the
actuated joint torques as ``F = C^T Gamma'`` (eq. 9).

Each caster is the paper's 3-DOF "manipulator" (steer phi, roll rho, twist
sigma at the contact) whose joint rates follow the base twist through
``q_dot_i = G_i x_dot`` (eq. 2). Rather than forming the joint-space mass
matrix A_i of that chain and its coriolis vector b_i symbolically (the paper
used AUTOLEV), we sum the same kinetic energy body by body, which is what
``G_i^T A_i G_i`` and ``G_i^T (A_i G_i_dot x_dot + b_i)`` expand to for a chain
whose bodies are the fork and the wheel:

* every body's planar velocity (its centre of mass's velocity and its yaw
  rate) and the wheel's spin are linear in the base twist, ``V_b = J_b(phi) x_dot``
  (J_b is built from the rows of G_i: the steering rate moves the fork and
  the wheel about the steering axis, the rolling rate spins the wheel);
* ``Lambda = sum_b J_b^T M_b J_b`` (the augmented object: the chassis's own
  ``diag(m, m, I)`` plus every caster's bodies, eq. 4);
* ``mu = sum_b J_b^T M_b (J_b_dot x_dot + Omega(wz) J_b x_dot)``: the
  derivative of the body velocities -- ``J_b_dot = dJ_b/dphi phi_dot`` with
  ``phi_dot = C_steer x_dot`` (the paper's ``G_dot``, derived in
  ``_caster_jacobians``) -- plus the rotation of the
  base frame (``Omega(wz) v = wz k x v`` on the linear parts), since x_ddot
  is a body-frame derivative.

The gyroscopic moment of a spinning wheel turning about the vertical acts
about a horizontal axis: the floor and the fork take it, and it does no work
in the plane, so it is not in ``mu``. Masses and inertias are those of the
simulator's URDF (``body.*``: chassis box, fork box with its centre half-way
along the offset, wheel cylinder), so the model and pybullet describe the
same robot.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pcv_base.torque_distribution import torque_distribution


@dataclass(frozen=True)
class BodyParams:
    """Masses [kg] and yaw / spin inertias [kg m^2] of the PCV's bodies."""

    chassis_mass: float
    chassis_inertia: float          # about the vertical through base_link's origin
    fork_mass: float
    fork_inertia: float             # about the vertical through the fork's centre
    wheel_mass: float
    wheel_inertia_yaw: float        # about a diameter (the vertical)
    wheel_inertia_spin: float       # about the axle

    @classmethod
    def from_model(cls, model) -> "BodyParams":
        """The inertias the simulator's URDF gives the same bodies
        (pcv_base.description: solid box, box, cylinder)."""
        p, k = model.params, model.kinematics
        m_c, m_f, m_w = p["body.chassis.mass"], p["body.fork.mass"], p["body.wheel.mass"]
        length, width = p["body.chassis.length"], p["body.chassis.width"]
        w_w = p["body.wheel.width"]
        # one radius and offset per robot for the bodies' inertias: casters
        # that differ by calibration (a percent of radius, a millimetre of
        # offset) change them by a few percent, well inside the model's
        # accuracy; casters of different designs are rejected
        r, b = float(np.mean(k.r)), float(np.mean(k.b))
        if np.ptp(k.r) > 0.1 * r or np.ptp(k.b) > 0.5 * b:
            raise ValueError("the dynamic model assumes casters of one design (wheel radii "
                             "within 10 % and caster offsets within 50 % of each other)")
        arm = max(b, 0.01)
        return cls(chassis_mass=m_c, chassis_inertia=m_c * (length ** 2 + width ** 2) / 12,
                   fork_mass=m_f, fork_inertia=m_f * (arm ** 2 + 0.01 ** 2) / 12,
                   wheel_mass=m_w, wheel_inertia_yaw=m_w * (3 * r ** 2 + w_w ** 2) / 12,
                   wheel_inertia_spin=m_w * r ** 2 / 2)


class PcvDynamics:
    """Lambda(q) and mu(q, x_dot) of one PCV (``kin``: PoweredCasterKinematics)."""

    def __init__(self, kin, body: BodyParams):
        self.kin = kin
        self.body = body
        n = len(kin.casters)
        # M_b per body row block: fork (m, m, I), wheel (m, m, I_yaw, I_spin)
        self._fork_m = np.array([body.fork_mass, body.fork_mass, body.fork_inertia])
        self._wheel_m = np.array([body.wheel_mass, body.wheel_mass, body.wheel_inertia_yaw,
                                  body.wheel_inertia_spin])
        self._chassis = np.diag([body.chassis_mass, body.chassis_mass, body.chassis_inertia])
        self._n = n

    @classmethod
    def from_model(cls, model) -> "PcvDynamics":
        return cls(model.kinematics, BodyParams.from_model(model))

    # -- body Jacobians --------------------------------------------------------------
    def _caster_jacobians(self, i: int, phi: float):
        """(J_fork 3x3, J_wheel 4x3, dJ_fork/dphi, dJ_wheel/dphi): body
        velocities per unit base twist, and their derivatives.

        Rows: fork centre (vx, vy) and yaw rate; wheel centre (vx, vy), yaw
        rate and spin rate rho_dot (all in base_link components). With
        c = cos phi, s = sin phi, n = (-s, c), the steering row S and rolling
        row R of G (eq. 2), a point ``arm`` behind the steering axis at
        (sx - arm c, sy - arm s) moves at
        ``[[1, 0, -py], [0, 1, px]] - arm n S``; the derivatives follow from
        d(c, s)/dphi = (-s, c): dS = (-c/b, -s/b, h (sb c - cb s)/b),
        dR = (-s/r, c/r, h (cb c + sb s)/r), dn = (-c, -s), d(px, py) =
        arm (s, -c).
        """
        cas = self.kin.casters[i]
        sx, sy = cas.axis
        b, r, h = cas.caster_offset, cas.wheel_radius, cas.h
        cb, sb = math.cos(cas.beta), math.sin(cas.beta)
        c, s = math.cos(phi), math.sin(phi)
        # steering and rolling rows of the constraint matrix (eq. 7 / G rows 1-2)
        steer = np.array([-s / b, c / b, h * (cb * c + sb * s) / b - 1.0])
        roll = np.array([c / r, s / r, h * (cb * s - sb * c) / r])
        d_steer = np.array([-c / b, -s / b, h * (sb * c - cb * s) / b])
        d_roll = np.array([-s / r, c / r, h * (cb * c + sb * s) / r])
        n_vec, d_n = np.array([-s, c]), np.array([-c, -s])

        def point(arm):
            # base velocity at the point plus the fork's turn about the
            # steering axis, which moves it by -arm phi_dot n
            px, py = sx - arm * c, sy - arm * s
            rows = np.array([[1.0, 0.0, -py], [0.0, 1.0, px]]) - arm * np.outer(n_vec, steer)
            d_rows = (np.array([[0.0, 0.0, arm * c], [0.0, 0.0, arm * s]])
                      - arm * (np.outer(d_n, steer) + np.outer(n_vec, d_steer)))
            return rows, d_rows

        yaw = np.array([0.0, 0.0, 1.0]) + steer          # wz + phi_dot
        fork_xy, d_fork_xy = point(0.5 * b)
        wheel_xy, d_wheel_xy = point(b)
        return (np.vstack([fork_xy, yaw]), np.vstack([wheel_xy, yaw, roll]),
                np.vstack([d_fork_xy, d_steer]), np.vstack([d_wheel_xy, d_steer, d_roll]))

    # -- the operational-space terms ----------------------------------------------------
    def terms(self, positions, twist=None) -> tuple[np.ndarray, np.ndarray]:
        """(Lambda (3 x 3) [kg, kg m, kg m^2], mu (3,) [N, N, N m]) at the joint
        ``positions`` and base ``twist`` (mu = 0 without a twist), from one
        pass over the casters' body Jacobians."""
        steer = np.asarray(positions, float)[0::2]
        lam = self._chassis.copy()
        mu = np.zeros(3)
        x_dot = None if twist is None else np.asarray(twist, float)
        if x_dot is not None:
            wz = x_dot[2]
            # the chassis: its centre is base_link's origin
            mu += self._chassis @ np.array([-wz * x_dot[1], wz * x_dot[0], 0.0])
        for i, phi in enumerate(steer):
            fork, wheel, d_fork, d_wheel = self._caster_jacobians(i, float(phi))
            for J, dJ, masses in ((fork, d_fork, self._fork_m), (wheel, d_wheel, self._wheel_m)):
                lam += J.T @ (masses[:, None] * J)
                if x_dot is None:
                    continue
                v = J @ x_dot
                phi_dot = v[2] - wz                      # the yaw row is wz + phi_dot
                accel = (dJ * phi_dot) @ x_dot           # G_dot x_dot
                accel[0] -= wz * v[1]                    # the base frame turns: wz k x v
                accel[1] += wz * v[0]
                mu += J.T @ (masses * accel)
        return lam, mu

    def mass_matrix(self, positions) -> np.ndarray:
        """Lambda (3 x 3) [kg, kg m, kg m^2] at the joint ``positions``."""
        return self.terms(positions)[0]

    def bias(self, positions, twist) -> np.ndarray:
        """mu (3,) [N, N, N m]: centripetal and coriolis wrench at ``twist``."""
        return self.terms(positions, twist)[1]

    def acceleration(self, positions, twist, wrench) -> np.ndarray:
        """x_ddot (body components) produced by ``wrench`` F at ``twist``."""
        lam, mu = self.terms(positions, twist)
        return np.linalg.solve(lam, np.asarray(wrench, float) - mu)

    def torque_distribution(self, positions, wrench) -> np.ndarray:
        """Joint torques [N m] ``Gamma' = C#^T F`` (eq. 14, in
        :mod:`pcv_base.torque_distribution`) that produce ``wrench`` F (fx [N],
        fy [N], tz [N m], base_link) at the joint ``positions`` [rad] with the
        least contact forces."""
        return torque_distribution(self.kin, positions, wrench)
