"""Odometry estimators of a powered-caster vehicle: the base twist from
measured joint rates (Holmberg & Khatib, eq. 13), for
:class:`pcv_base.powered_caster.PoweredCasterKinematics` (geometry and
joint order there; ``kin`` below is one of those).

The estimators (``PoweredCasterKinematics.forward`` / ``estimate`` choose one):

* ``slip_min``: the paper's ``C# = C_p^+ C_q^-1`` (eq. 13): map the joint rates
  to sensed contact velocities with ``C_q^-1`` and fit the rigid-body velocity
  field to them in the least-squares sense -- it minimises the total contact
  slip, in m/s, the same for every wheel and both directions;
* ``pinv``: the Moore-Penrose inverse of ``C``, for comparison: it fits joint
  rates, which weighs lateral slip by 1/b^2 and rolling slip by 1/r^2;
* ``robust``: ``slip_min``, except when the slip is one contact that
  disagrees with all the others (a wheel that spins or skids alone): then that
  caster is left out. See :func:`robust`.

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

import numpy as np

from holonomic_core.kinematics import ESTIMATORS

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


def rigid_fit(kin, positions, velocities):
    """The slip_min fit in scalar math, with what the robust test needs
    (``positions`` [rad], ``velocities`` [rad/s]: numpy arrays in joint order).

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
    for i, (sx, sy, b, r) in enumerate(kin.contact_geometry):
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


def slip_min(kin, positions, velocities):
    """C# = C_p^+ C_q^-1 (eq. 13) by the closed-form rigid fit: the twist
    (vx, vy, wz) [m/s, m/s, rad/s] of base_link and the per-caster contact
    residual norms [m/s]."""
    twist, res, _, _ = rigid_fit(kin, positions, velocities)
    return np.array(twist), np.array([math.hypot(rx, ry) for _, _, rx, ry in res])


def pinv(kin, positions, velocities):
    """The Moore-Penrose inverse of C (for comparison): the twist that fits
    the joint rates [rad/s] in the least-squares sense, and the per-caster
    contact residual norms [m/s] that twist leaves."""
    C = kin.constraint_matrix(positions)
    twist = np.linalg.lstsq(C, velocities, rcond=None)[0]
    fitted, res, _, _ = rigid_fit(kin, positions, velocities)
    # residual of pinv's twist: the slip_min residual minus the rigid
    # field of the two twists' difference
    dvx, dvy, dwz = (twist - np.array(fitted)).tolist()
    return twist, np.array([math.hypot(rx - (dvx - dwz * y), ry - (dvy + dwz * x))
                            for x, y, rx, ry in res])


def estimate(kin, positions, velocities, estimator):
    """(twist [m/s, m/s, rad/s], per-caster residual [m/s]) of the named
    estimator (one of ``holonomic_core.kinematics.ESTIMATORS``) from joint
    ``positions`` [rad] and ``velocities`` [rad/s] (numpy arrays in the
    kinematics' joint order)."""
    if estimator == "slip_min":
        return slip_min(kin, positions, velocities)
    if estimator == "robust":
        return robust(kin, positions, velocities)
    if estimator == "pinv":
        return pinv(kin, positions, velocities)
    raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")


def robust(kin, positions, velocities):
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
    (tx, ty, wz), res, (cx, cy), D = rigid_fit(kin, positions, velocities)
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
