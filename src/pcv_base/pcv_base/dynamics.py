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

from holonomic_core import hot_path
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
    """Lambda(q) and mu(q, x_dot) of one PCV (``kin``: PoweredCasterKinematics).

    The terms run once per torque-mode cycle (1 kHz on the XR4000), on 3-vectors
    and 3x3 matrices: they are written as scalar arithmetic on Python floats,
    which costs a fraction of the same work as numpy calls on arrays that
    small (numpy's per-call overhead is a few microseconds whatever the size).
    :meth:`terms` has a compiled twin (``holonomic_core._hot_path.pcv_terms``,
    the same operations in the same order: bitwise the same numbers), used
    as the kinematics' closed forms are (``HOLONOMIC_HOT_PATH``, read here).
    """

    def __init__(self, kin, body: BodyParams):
        self.kin = kin
        self.body = body
        # M_b per body row: fork (m, m, I), wheel (m, m, I_yaw, I_spin)
        self._fork_m = (body.fork_mass, body.fork_mass, body.fork_inertia)
        self._wheel_m = (body.wheel_mass, body.wheel_mass, body.wheel_inertia_yaw,
                         body.wheel_inertia_spin)
        #: per caster (sx, sy [m], b, r [m], h [m], cos beta, sin beta) as floats
        self._geometry = tuple((float(c.axis[0]), float(c.axis[1]), float(c.caster_offset),
                                float(c.wheel_radius), float(c.h), math.cos(c.beta),
                                math.sin(c.beta)) for c in kin.casters)
        #: the compiled terms (hot_path) and their inputs; None: the pure path
        self._hot = hot_path.module()
        self._hot_geometry = np.array(self._geometry, dtype=float).ravel()
        self._hot_masses = np.array((body.chassis_mass, body.chassis_inertia,
                                     *self._fork_m, *self._wheel_m), dtype=float)

    @classmethod
    def from_model(cls, model) -> "PcvDynamics":
        return cls(model.kinematics, BodyParams.from_model(model))

    # -- body Jacobians --------------------------------------------------------------
    def _caster_rows(self, i: int, phi: float):
        """(J_fork, J_wheel, dJ_fork/dphi, dJ_wheel/dphi) of caster ``i`` at
        steering angle ``phi`` [rad], as tuples of rows (3-tuples of floats):
        body velocities per unit base twist, and their derivatives.

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
        sx, sy, b, r, h, cb, sb = self._geometry[i]
        c, s = math.cos(phi), math.sin(phi)
        # steering and rolling rows of the constraint matrix (eq. 7 / G rows 1-2)
        s0, s1, s2 = steer = (-s / b, c / b, h * (cb * c + sb * s) / b - 1.0)
        roll = (c / r, s / r, h * (cb * s - sb * c) / r)
        d0, d1, d2 = d_steer = (-c / b, -s / b, h * (sb * c - cb * s) / b)
        d_roll = (-s / r, c / r, h * (cb * c + sb * s) / r)

        def point(arm):
            # base velocity at the point plus the fork's turn about the
            # steering axis, which moves it by -arm phi_dot n, n = (-s, c);
            # the derivative: d[[1, 0, -py], [0, 1, px]] = [[0, 0, arm c],
            # [0, 0, arm s]] minus arm (dn S + n dS), dn = (-c, -s)
            px, py = sx - arm * c, sy - arm * s
            ac, as_ = arm * c, arm * s
            rows = ((1.0 + as_ * s0, as_ * s1, -py + as_ * s2),
                    (-ac * s0, 1.0 - ac * s1, px - ac * s2))
            d_rows = ((ac * s0 + as_ * d0, ac * s1 + as_ * d1, ac + ac * s2 + as_ * d2),
                      (as_ * s0 - ac * d0, as_ * s1 - ac * d1, as_ + as_ * s2 - ac * d2))
            return rows, d_rows

        yaw = (s0, s1, 1.0 + s2)                         # wz + phi_dot
        fork_xy, d_fork_xy = point(0.5 * b)
        wheel_xy, d_wheel_xy = point(b)
        return (fork_xy + (yaw,), wheel_xy + (yaw, roll),
                d_fork_xy + (d_steer,), d_wheel_xy + (d_steer, d_roll))

    def _caster_jacobians(self, i: int, phi: float):
        """:meth:`_caster_rows` as arrays (J_fork 3x3, J_wheel 4x3, dJ_fork/dphi,
        dJ_wheel/dphi)."""
        return tuple(np.array(rows) for rows in self._caster_rows(i, phi))

    # -- the operational-space terms ----------------------------------------------------
    def terms(self, positions, twist=None) -> tuple[np.ndarray, np.ndarray]:
        """(Lambda (3 x 3) [kg, kg m, kg m^2], mu (3,) [N, N, N m]) at the joint
        ``positions`` and base ``twist`` (mu = 0 without a twist), from one
        pass over the casters' body Jacobians.

        Per body row j (a 3-vector of J_b) with mass or inertia m:
        ``Lambda += m j j^T`` and ``mu += m a j`` where ``a = phi_dot (dj . x_dot)``
        (G_dot x_dot) plus, on the linear rows, the base frame's turn
        ``wz k x v`` (``v = J_b x_dot``).
        """
        if self._hot is not None:
            return self._hot.pcv_terms(positions, twist, self._hot_geometry, self._hot_masses)
        return self._terms_pure(positions, twist)

    def _terms_pure(self, positions, twist=None) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`terms` in Python: the reference of the compiled twin."""
        body = self.body
        m_c, i_c = body.chassis_mass, body.chassis_inertia
        l00, l01, l02, l11, l12, l22 = m_c, 0.0, 0.0, m_c, 0.0, i_c
        mu0 = mu1 = mu2 = 0.0
        moving = twist is not None
        if moving:
            vx, vy, wz = (float(v) for v in twist)
            # the chassis: its centre is base_link's origin
            mu0, mu1 = m_c * (-wz * vy), m_c * (wz * vx)
        fork_m, wheel_m = self._fork_m, self._wheel_m
        for i, phi in enumerate(positions[0::2]):
            fork, wheel, d_fork, d_wheel = self._caster_rows(i, float(phi))
            for J, dJ, masses in ((fork, d_fork, fork_m), (wheel, d_wheel, wheel_m)):
                if moving:
                    # the body's velocity v = J x_dot, and phi_dot = S x_dot
                    # (the yaw row is wz + phi_dot)
                    v = [j0 * vx + j1 * vy + j2 * wz for j0, j1, j2 in J]
                    phi_dot = v[2] - wz
                    accel = [phi_dot * (d0 * vx + d1 * vy + d2 * wz) for d0, d1, d2 in dJ]
                    accel[0] -= wz * v[1]                # the base frame turns: wz k x v
                    accel[1] += wz * v[0]
                else:
                    accel = (0.0, 0.0, 0.0, 0.0)
                for (j0, j1, j2), m, a in zip(J, masses, accel):
                    w0, w1, w2 = m * j0, m * j1, m * j2
                    l00 += w0 * j0
                    l01 += w0 * j1
                    l02 += w0 * j2
                    l11 += w1 * j1
                    l12 += w1 * j2
                    l22 += w2 * j2
                    mu0 += w0 * a
                    mu1 += w1 * a
                    mu2 += w2 * a
        lam = np.array(((l00, l01, l02), (l01, l11, l12), (l02, l12, l22)))
        return lam, np.array((mu0, mu1, mu2))

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
