"""Static analysis of a base whose wheels roll only along their heading and
must be steered before they roll in a new direction (a swerve: steered
wheels without caster offset), docs/analysis.md "Swerve".

The family's kinematics expose its rolling constraints at a configuration
``q`` (the hook this module reads; no family is named here)::

    C_p x = U(q) q_dot                                               (R)

``C_p`` (2m x 3): the twist ``x = (vx, vy, wz)`` -> the velocities of the m
wheel units' contact points; ``U(q)`` (2m x n): joint rates -> the contact
velocities the joints produce (``contact_jacobian()``,
``wheel_velocity_matrix(q)``). When ``U`` has full row rank every twist has
joint rates (the powered caster: :mod:`holonomic_analysis.mobility`'s linear
map applies). When it does not -- a steered wheel without offset produces a
contact velocity only along its heading ``e_i``, ``U_i = [0 | r_i e_i]`` --
(R) is also a constraint on the twist:

* **instantaneous mobility** at ``q``: the twists (R) admits,
  ``K(q) = null((I - U U^+) C_p)``. For a swerve, row i is
  ``(-sin phi_i, cos phi_i, x_i cos phi_i + y_i sin phi_i) x = 0`` (no
  sideways velocity at module i): the line through module i across its
  wheel (the axle line) must hold the instantaneous centre of rotation.
  Each row is non-zero, so ``dim K <= 2``: a swerve is never
  instantaneously holonomic. ``dim K = 2`` only when every axle line is one
  line (the modules collinear, every wheel across that line: a differential
  drive); ``1`` when the axle lines meet in one point (the ICR; parallel
  lines: a translation along the common heading); ``0`` otherwise (locked
  until the modules turn). On ``K`` the joint rates are ``U^+ C_p x``
  (steering rates 0: the modules keep their angles in base_link), and the
  mobility ellipsoid is the image on ``K`` of the unit ball of normalised
  joint speeds.
* **with reorientation** (the steady state of a move: the steering joints
  point every module along its contact velocity first): unit i produces any
  contact velocity up to ``R_i = ||U_i diag(q_max)||`` (``r_i
  omega_max_i``), so the base holds the twists
  ``S = {x : |C_i x| <= R_i for every unit}`` -- the intersection of
  elliptic cylinders, convex. At ``wz = 0`` every unit moves at the base's
  speed: ``S`` is the disc ``|v| <= min_i R_i``, the same top speed in
  every direction.
"""

from __future__ import annotations

import math

import numpy as np

#: relative tolerance of the rank decisions: singular values below it count
#: as 0, so that headings within about 1 mrad of a common field (angles typed
#: to three decimals, an encoder's resolution) count as on it
RANK_TOL = 1e-3


def applies(kinematics, positions) -> bool:
    """True when ``kinematics`` exposes its rolling constraints (R) and its
    joints cannot produce every contact velocity (``U`` rank deficient): the
    twist is then constrained by the configuration."""
    if not (hasattr(kinematics, "contact_jacobian")
            and hasattr(kinematics, "wheel_velocity_matrix")):
        return False
    U = kinematics.wheel_velocity_matrix(positions)
    return _rank(U) < U.shape[0]


def _rank(M: np.ndarray) -> int:
    s = np.linalg.svd(M, compute_uv=False)
    return int(np.sum(s > RANK_TOL * max(s.max(initial=0.0), 1.0)))


def _null_space(M: np.ndarray) -> np.ndarray:
    """Orthonormal basis (3 x d) of ``{x : M x = 0}``."""
    _, s, vt = np.linalg.svd(M)
    rank = int(np.sum(s > RANK_TOL * max(s.max(initial=0.0), 1.0)))
    basis = vt[rank:].T
    basis[np.abs(basis) < 1e-12] = 0.0
    for j in range(basis.shape[1]):         # a fixed sign: the first non-zero entry > 0
        k = int(np.argmax(np.abs(basis[:, j]) > RANK_TOL))
        if basis[k, j] < 0:
            basis[:, j] = -basis[:, j]
    return basis


class RollingConstraints:
    """(R) of one configuration, with the joint speed limits ``limits`` (n,) [rad/s]."""

    def __init__(self, kinematics, positions, limits):
        positions = np.asarray(positions, float)
        self.Cp = np.asarray(kinematics.contact_jacobian(positions), float)
        self.U = np.asarray(kinematics.wheel_velocity_matrix(positions), float)
        self.limits = np.asarray(limits, float)
        self.U_pinv = np.linalg.pinv(self.U)
        #: rows of the constraint on the twist: the part of C_p x no joint produces
        self.constraint = (np.eye(len(self.U)) - self.U @ self.U_pinv) @ self.Cp
        #: orthonormal basis (3 x d) of the instantaneous mobility K
        self.basis = _null_space(self.constraint)

    @property
    def dimension(self) -> int:
        return self.basis.shape[1]

    # -- at the configuration --------------------------------------------------------
    def joint_rates(self, twist) -> np.ndarray:
        """Joint rates [rad/s] of a twist in K: ``U^+ C_p x``."""
        return self.U_pinv @ (self.Cp @ np.asarray(twist, float))

    def no_slip_jacobian(self) -> np.ndarray:
        """``J_joint_to_base`` (3 x n) on the joint rates (R) admits:
        ``x = B (U^+ C_p B)^+ q_dot``; rank ``dim K``."""
        if self.dimension == 0:
            return np.zeros((3, len(self.limits)))
        B = self.basis
        return B @ np.linalg.pinv(self.U_pinv @ self.Cp @ B)

    def sigma_ratio(self) -> float:
        """sigma_min / sigma_max of :meth:`no_slip_jacobian` (3 singular
        values): 0 unless K is 3-D, which a steered wheel without offset
        never allows."""
        s = np.linalg.svd(self.no_slip_jacobian(), compute_uv=False)
        return 0.0 if s[0] == 0.0 else float(s[-1] / s[0])

    def ellipsoid_semi_axes(self) -> list[float]:
        """Semi-axes (3, largest first, 0 across K) of the mobility ellipsoid
        on K: ``{x = B y : |W U^+ C_p B y| <= 1}``, W = diag(1/q_max)."""
        axes = [0.0, 0.0, 0.0]
        if self.dimension:
            N = (self.U_pinv @ self.Cp @ self.basis) / self.limits[:, None]
            s = np.linalg.svd(N, compute_uv=False)
            for i, v in enumerate(sorted((1.0 / v if v > 0 else math.inf for v in s),
                                         reverse=True)):
                axes[i] = float(v)
        return axes

    def instantaneous(self) -> dict:
        """The configuration's own numbers: K's dimension and basis, its
        ellipsoid, the one translation it may allow (direction [rad] in
        base_link and top speed [m/s] within the joint limits) and H_hat at
        the configuration (0: at most one direction of translation)."""
        translations = _null_space(np.vstack([self.constraint, [0.0, 0.0, 1.0]]))
        out = {"mobility_dimension": self.dimension,
               "mobility_basis": [[float(v) for v in col] for col in self.basis.T],
               "ellipsoid_semi_axes": self.ellipsoid_semi_axes(),
               "translation": None, "H_hat": 0.0}
        if translations.shape[1] == 1:
            t = translations[:, 0]
            rates = np.abs(self.joint_rates(t)) / self.limits
            out["translation"] = {"direction": float(math.atan2(t[1], t[0])),
                                  "speed": float(1.0 / rates.max())}
        return out

    # -- with reorientation ----------------------------------------------------------
    def unit_speed_limits(self) -> np.ndarray:
        """``R_i`` [m/s]: the largest contact speed unit i's joints produce
        within their limits, ``||U_i diag(q_max)||_2``."""
        m = len(self.U) // 2
        scaled = self.U * self.limits[None, :]
        return np.array([np.linalg.norm(scaled[2 * i:2 * i + 2], 2) for i in range(m)])

    def _blocks(self):
        return [self.Cp[2 * i:2 * i + 2] for i in range(len(self.Cp) // 2)]

    def ray_speed(self, direction) -> float:
        """Largest s with ``s * direction`` in S (direction: a twist)."""
        u = np.asarray(direction, float)
        u = u / np.linalg.norm(u)
        worst = max(np.linalg.norm(C @ u) / R
                    for C, R in zip(self._blocks(), self.unit_speed_limits()))
        return math.inf if worst == 0.0 else float(1.0 / worst)

    def max_component(self, axis: int, held: int) -> float:
        """Largest component ``axis`` of a twist in S with ``held`` at 0 and
        the third component free: ``g(w) = max {t : (t, w) in S}`` is concave
        (S is convex); a grid over w, then golden-section refinement."""
        free = 3 - axis - held
        blocks = [(C[:, axis], C[:, free], R)
                  for C, R in zip(self._blocks(), self.unit_speed_limits())]

        def g(w: float) -> float:
            low, high = -math.inf, math.inf
            for a, f, R in blocks:
                aa, af, ff = a @ a, a @ f, f @ f
                if aa == 0.0:
                    if ff * w * w > R * R:
                        return -math.inf
                    continue
                disc = af * af * w * w - aa * (ff * w * w - R * R)
                if disc < 0.0:
                    return -math.inf
                root = math.sqrt(disc)
                low, high = max(low, (-af * w - root) / aa), min(high, (-af * w + root) / aa)
            return high if low <= high else -math.inf

        span = self.ray_speed(np.eye(3)[free])
        span = 1.0 if not math.isfinite(span) else span
        grid = np.linspace(-span, span, 401)
        values = [g(w) for w in grid]
        k = int(np.argmax(values))
        lo, hi = grid[max(k - 1, 0)], grid[min(k + 1, len(grid) - 1)]
        ratio = (math.sqrt(5.0) - 1.0) / 2.0
        for _ in range(60):
            m1, m2 = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
            if g(m1) < g(m2):
                lo = m1
            else:
                hi = m2
        return float(max(values[k], g(0.5 * (lo + hi))))

    def holonomicity(self) -> tuple[float, float, float]:
        """``(H_hat, slowest, fastest)`` at constant heading with
        reorientation: S at ``wz = 0`` is the disc of radius min R_i."""
        speed = float(self.unit_speed_limits().min())
        return (1.0 if speed > 0 else 0.0), speed, speed

    def ellipsoid_shape(self) -> np.ndarray:
        """S_E (3 x 3), ``E = {x : x^T S_E^-1 x <= 1}``: the image of the unit
        ball of normalised unit speeds ``sum_i |C_i x|^2 / R_i^2 <= 1``."""
        N = np.vstack([C / R for C, R in zip(self._blocks(), self.unit_speed_limits())])
        return np.linalg.inv(N.T @ N)
