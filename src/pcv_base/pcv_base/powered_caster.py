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

Estimators of the twist from measured joint rates (``forward``):

* ``slip_min``: the paper's ``C# = C_p^+ C_q^-1`` (eq. 13): map the joint rates
  to sensed contact velocities with ``C_q^-1`` and fit the rigid-body velocity
  field to them in the least-squares sense -- it minimises the total contact
  slip, in m/s, the same for every wheel and both directions;
* ``pinv``: the Moore-Penrose inverse of ``C``, for comparison: it fits joint
  rates, which weighs lateral slip by 1/b^2 and rolling slip by 1/r^2;
* ``robust``: ``slip_min``, except when the slip is one contact that
  disagrees with all the others (a wheel that spins or skids alone): then that
  caster is left out. See :meth:`PoweredCasterKinematics._robust`.

What the residual can tell apart. The sensed contact velocities are ``u =
C_p x + s`` (slip ``s``, 2n entries); the fit sees only the residual ``(I -
H) s`` with ``H = C_p C_p^+``, in the (2n - 3)-dimensional space orthogonal to
the rigid-body motions. That space is also the space of *internal* forces
(``C_p^T f = 0``: no net force, no net torque on the base), so actuator-conflict
slip -- each contact yielding in proportion to the internal force the casters
push on each other with -- lies in it entirely, and C# ignores it exactly
(``C_p^+ s = 0``); it is why the paper chose C#. A single contact's burst
``s = E_i d`` (2 rows of caster i) leaves a residual in the 2-dimensional
subspace ``(I - H) E_i``, and leaving caster i out explains it completely.

* 4 or more casters (2n - 3 >= 5): the subspaces of two casters meet only at
  zero, so one outlier is located uniquely; disagreement spread over all
  contacts is not confined to any of them.
* 3 casters (3-dimensional residual, planes of 2): one outlier is located,
  except along the lines where two casters' planes meet (then either caster
  could be the culprit; the estimator keeps slip_min). Two simultaneous
  outliers cannot be told apart from conflict.
* 2 casters (4 equations, 3 unknowns, one redundant): the residual is one
  number; both casters explain it equally, and so does conflict. An outlier
  is detected but cannot be located: ``robust`` is ``slip_min``.

What no residual can tell apart: conflict slip produced by *one* lagging
caster, ``s = (I - H) E_i d``, gives the same sensed velocities as a burst
``E_i d`` of that caster on a different rigid motion (``u = C_p (x - C_p^+ E_i
d) + E_i d``). Grip decides between them: a tyre that grips yields by
millimetres per second (micro-slip, a few % of its speed), a wheel that spins
or skids departs by tenths of a metre per second. So a caster is rejected
only when its disagreement with the others exceeds ``ROBUST_OUTLIER_SLIP``.

The least-squares fit of a planar rigid velocity field has a closed form (its
normal equations decouple about the weighted centroid of the contact points),
so the estimators cost O(n) arithmetic with no matrix inversion per cycle.
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from holonomic_core import hot_path
from holonomic_core.kinematics import ESTIMATORS, BaseKinematics
from holonomic_core.schema import ConfigError, ParamSpec, number_or_none

#: why the caster offset must be > 0, for the error messages
_ZERO_OFFSET = ("b = 0 makes a caster a steered wheel that cannot move sideways without "
                "first turning: the base would not be holonomic")

#: disagreement [m/s] of one caster with the rigid motion of the others above
#: which the robust estimator calls it a burst (a gripping tyre's micro-slip
#: stays at a few cm/s even at 1 m/s; a wheel that spins or skids is far off)
ROBUST_OUTLIER_SLIP = 0.1
#: at most this fraction of the residual energy (sum of squared contact
#: residuals) may remain when the suspected caster is left out: the others
#: must agree on one rigid motion (for spread conflict on 4 casters the
#: fraction is Beta(3/2, 1)-distributed, below 0.05 in 1 % of cycles per caster)
ROBUST_CONCENTRATION = 0.05
#: ... and it must explain more than any other caster would, by this much
#: [m/s] (as a root of residual energy): with 3 casters the residuals that
#: two casters can explain meet along a line, and near it either could be the
#: culprit (a relative margin fails there: the runner-up often explains 99 %)
ROBUST_UNIQUENESS = 0.03

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
        # The control cycle's paths (inverse, the slip_min fit) run on Python
        # floats: for n <= 8 casters a loop of scalar math costs a third of
        # the same work as a dozen numpy calls on length-n arrays.
        self._geometry = tuple((float(c.axis[0]), float(c.axis[1]), float(c.caster_offset),
                                float(c.wheel_radius)) for c in casters)
        #: the compiled closed forms (hot_path), None for the pure-Python path
        self._hot = hot_path.module() if len(casters) <= hot_path.MAX_CASTERS else None
        self._hot_geometry = np.array(self._geometry, dtype=float).ravel()

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
        for i, (sx, sy, b, r) in enumerate(self._geometry):
            phi = q[2 * i]
            c, s = cos(phi), sin(phi)
            vsx = vx - wz * sy
            vsy = vy + wz * sx
            out.append((c * vsy - s * vsx) / b - wz)
            out.append((c * vsx + s * vsy) / r)
        return np.array(out)

    def forward(self, positions: np.ndarray, velocities: np.ndarray,
                estimator: str = "slip_min") -> np.ndarray:
        """Body twist (vx, vy, wz) from joint rates with the chosen estimator."""
        return self._estimate(np.asarray(positions, float), np.asarray(velocities, float),
                              estimator)[0]

    def fit_residual(self, positions: np.ndarray, velocities: np.ndarray,
                     estimator: str = "slip_min") -> np.ndarray:
        """Per caster, the norm [m/s] of the contact-velocity slip the chosen
        estimator's twist does not explain (0 for consistent joint rates)."""
        return self._estimate(np.asarray(positions, float), np.asarray(velocities, float),
                              estimator)[1]

    def estimate(self, positions: np.ndarray, velocities: np.ndarray,
                 estimator: str = "slip_min") -> tuple[np.ndarray, np.ndarray]:
        """Twist and per-caster residual from one fit (see BaseKinematics)."""
        if self._hot is not None and estimator == "slip_min":
            return self._hot.estimate(hot_path.KIND_PCV, positions, velocities,
                                      self._hot_geometry)
        return self._estimate(np.asarray(positions, float), np.asarray(velocities, float),
                              estimator)

    def hot_path_geometry(self, estimator: str = "slip_min") -> tuple[int, np.ndarray] | None:
        """The compiled form covers the slip_min fit (robust and pinv stay in Python)."""
        if estimator != "slip_min" or len(self.casters) > hot_path.MAX_CASTERS:
            return None
        return hot_path.KIND_PCV, self._hot_geometry

    def _fit(self, positions, velocities):
        """The slip_min fit in scalar math, with what the robust test needs.

        Returns the twist (vx, vy, wz) of base_link, the per-caster contact
        residuals ``[(x, y, rx, ry)]`` (contact point [m] and the sensed
        contact velocity minus the fitted one [m/s]), the contact centroid
        ``(cx, cy)`` [m] and ``D = sum |p_i - c|^2`` [m^2]. About the
        centroid the normal equations of the rigid fit decouple: the
        translation there is the mean contact velocity and ``wz = sum q x u /
        D`` with ``q = p - c`` -- O(n), no matrix inversion.
        """
        q, v = positions.tolist(), velocities.tolist()
        cos, sin = math.cos, math.sin
        pts = []
        sum_x = sum_y = sum_u = sum_w = 0.0
        for i, (sx, sy, b, r) in enumerate(self._geometry):
            phi = q[2 * i]
            c, s = cos(phi), sin(phi)
            dphi, drho = v[2 * i], v[2 * i + 1]
            x, y = sx - b * c, sy - b * s
            u = -b * s * dphi + r * c * drho
            w = b * c * dphi + r * s * drho
            pts.append((x, y, u, w))
            sum_x += x
            sum_y += y
            sum_u += u
            sum_w += w
        n = len(pts)
        cx, cy, mu, mw = sum_x / n, sum_y / n, sum_u / n, sum_w / n
        num = den = 0.0
        for x, y, u, w in pts:
            qx, qy = x - cx, y - cy
            num += qx * w - qy * u
            den += qx * qx + qy * qy
        wz = num / den if den > 1e-12 * n else 0.0
        tx, ty = mu + wz * cy, mw - wz * cx
        res = [(x, y, u - (tx - wz * y), w - (ty + wz * x)) for x, y, u, w in pts]
        return (tx, ty, wz), res, (cx, cy), den

    def _slip_min(self, positions, velocities):
        twist, res, _, _ = self._fit(positions, velocities)
        return np.array(twist), np.array([math.hypot(rx, ry) for _, _, rx, ry in res])

    def _estimate(self, positions, velocities, estimator):
        if estimator == "slip_min":
            return self._slip_min(positions, velocities)
        if estimator == "robust":
            return self._robust(positions, velocities)
        if estimator == "pinv":
            C = self.constraint_matrix(positions)
            twist = np.linalg.lstsq(C, velocities, rcond=None)[0]
            fitted, res, _, _ = self._fit(positions, velocities)
            # residual of pinv's twist: the slip_min residual minus the rigid
            # field of the two twists' difference
            dvx, dvy, dwz = (twist - np.array(fitted)).tolist()
            return twist, np.array([math.hypot(rx - (dvx - dwz * y), ry - (dvy + dwz * x))
                                    for x, y, rx, ry in res])
        raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")

    def _robust(self, positions, velocities):
        """slip_min, or the fit without the one caster that alone disagrees.

        Leave-one-caster-out in closed form (regression deletion formulas on
        the 2 rows of caster i): with the hat block ``H_ii = I/n + t t^T / D``
        (``t = k x q_i``), the caster's disagreement with the rigid motion of
        the others is ``d_i = (I - H_ii)^-1 r_i`` (r_i its residual in the full
        fit), leaving it out lowers the residual energy by ``r_i . d_i``, and
        moves the fit by ``-d_i / n`` (translation at the centroid) and
        ``-(t . d_i) / D`` (rotation). Caster i* with the largest drop is
        rejected when (a) the others then agree on a rigid motion (at most
        ROBUST_CONCENTRATION of the energy left), (b) it explains more than any
        other caster by ROBUST_UNIQUENESS^2 and (c) ``|d_i*|`` exceeds
        ROBUST_OUTLIER_SLIP (a burst, not a gripping tyre's conflict slip).
        Otherwise this is slip_min exactly. ``I - H_ii`` is singular with 2
        casters (the other caster alone cannot fix a twist): no rejection.
        """
        (tx, ty, wz), res, (cx, cy), D = self._fit(positions, velocities)
        n = len(res)
        rss = sum(rx * rx + ry * ry for _, _, rx, ry in res)
        a = 1.0 - 1.0 / n
        drops = []
        for x, y, rx, ry in res:
            tqx, tqy = -(y - cy), x - cx
            t2 = tqx * tqx + tqy * tqy
            den = D * a - t2
            if n < 3 or den <= 1e-9 * D:
                drops.append(None)
                continue
            # (a I - t t^T / D)^-1 r = r / a + t (t . r) / (a den)   (Sherman-Morrison)
            k = (tqx * rx + tqy * ry) / (a * den)
            dx, dy = rx / a + k * tqx, ry / a + k * tqy
            drops.append((rx * dx + ry * dy, dx, dy, tqx, tqy))
        ranked = sorted((d[0], i) for i, d in enumerate(drops) if d is not None)
        best = None
        if len(ranked) >= 2 and rss > 0.0:
            drop, i = ranked[-1]
            second = ranked[-2][0]
            _, dx, dy, tqx, tqy = drops[i]
            if (rss - drop <= ROBUST_CONCENTRATION * rss
                    and drop - second >= ROBUST_UNIQUENESS ** 2
                    and math.hypot(dx, dy) > ROBUST_OUTLIER_SLIP):
                best = (i, dx, dy, tqx, tqy)
        if best is None:
            return (np.array((tx, ty, wz)),
                    np.array([math.hypot(rx, ry) for _, _, rx, ry in res]))
        i, dx, dy, tqx, tqy = best
        # centroid translation and rotation move by -d/n and -(t . d)/D
        dwz = -(tqx * dx + tqy * dy) / D
        dtx, dty = -dx / n + dwz * cy, -dy / n - dwz * cx    # at base_link's origin
        residual = [math.hypot(rx - (dtx - dwz * y), ry - (dty + dwz * x))
                    for x, y, rx, ry in res]
        return np.array((tx + dtx, ty + dty, wz + dwz)), np.array(residual)

    def jacobian(self, positions: np.ndarray) -> np.ndarray:
        """``C# = C_p^+ C_q^-1`` (3 x 2n): the slip-minimising estimator (eq. 13)."""
        positions = np.asarray(positions, float)
        return np.linalg.pinv(self.contact_jacobian(positions)) @ self.joint_to_contact(positions)

    def torque_distribution(self, positions: np.ndarray, force: np.ndarray) -> np.ndarray:
        """Joint torques ``Gamma' = C#^T F`` [N m] (eq. 14) that produce the
        base wrench ``F = (fx [N], fy [N], tz [N m])`` in base_link while
        minimising the contact forces in the least-squares sense.

        Dual of ``slip_min``: power balance ``Gamma'.q_dot = F.x_dot`` with
        ``q_dot = C x_dot`` gives ``C^T Gamma' = F``, which C#^T satisfies
        because C# C = I.

        Closed form (no pseudo-inverse per cycle): ``C_p^+T F`` is the
        smallest set of contact forces f_i with sum f_i = (fx, fy) and
        sum p_i x f_i = tz; Lagrange's conditions give f_i = (fx, fy)/n +
        nu k x q_i about the contact centroid c (q_i = p_i - c) with
        nu = (tz - c x (fx, fy)) / sum |q_i|^2. Then Gamma' = C_q^-T f:
        steering torque b n_i . f_i, wheel torque r e_i . f_i.
        """
        fx, fy, tz = (float(v) for v in force)
        phi = np.asarray(positions, float)[0::2]
        c, s = np.cos(phi), np.sin(phi)
        px, py = self.sx - self.b * c, self.sy - self.b * s
        n = len(self.casters)
        cx, cy = px.mean(), py.mean()
        qx, qy = px - cx, py - cy
        nu = (tz - (cx * fy - cy * fx)) / float((qx * qx + qy * qy).sum())
        f_x, f_y = fx / n - nu * qy, fy / n + nu * qx
        out = np.empty(2 * n)
        out[0::2] = self.b * (-s * f_x + c * f_y)
        out[1::2] = self.r * (c * f_x + s * f_y)
        return out

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
            ParamSpec("body.chassis.mass", "double", "Mass of the chassis with payload [kg].",
                      default=60.0, minimum=0.0, exclusive_minimum=True, maximum=1e4),
            ParamSpec("body.chassis.length", "double", "Chassis box length along x [m].",
                      default=0.5, minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec("body.chassis.width", "double", "Chassis box width along y [m].",
                      default=0.5, minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec("body.chassis.height", "double", "Chassis box height [m].",
                      default=0.1, minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec("body.fork.mass", "double", "Mass of one caster fork [kg].",
                      default=0.8, minimum=0.0, exclusive_minimum=True, maximum=1e3),
            ParamSpec("body.fork.height", "double",
                      "Drop from the chassis bottom to the wheel axle [m].",
                      default=0.04, minimum=0.0, exclusive_minimum=True, maximum=10.0),
            ParamSpec("body.wheel.mass", "double", "Mass of one wheel [kg].",
                      default=0.5, minimum=0.0, exclusive_minimum=True, maximum=1e3),
            ParamSpec("body.wheel.width", "double", "Width of a wheel [m].",
                      default=0.03, minimum=0.0, exclusive_minimum=True, maximum=10.0),
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
        kin = cls(casters)
        # The wheels' swept discs (plan view: a 2r x w rectangle at distance b
        # from the axis, turning about it) must not intersect (Holmberg &
        # Khatib, Sec. 2), or the simulated and the real wheels collide.
        w = values["body.wheel.width"]
        swept = [math.hypot(c.caster_offset + c.wheel_radius, w / 2) for c in kin.casters]
        for i, ci in enumerate(kin.casters):
            for j in range(i + 1, len(kin.casters)):
                cj = kin.casters[j]
                dist = math.dist(ci.axis, cj.axis)
                if dist <= swept[i] + swept[j]:
                    raise ConfigError(f"pcv.{cj.name}.h", cj.h,
                                      f"steering axes of {ci.name} and {cj.name} more than "
                                      f"{swept[i] + swept[j]:.3f} m apart (the wheels' swept "
                                      f"discs overlap at {dist:.3f} m)")
        return kin


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
