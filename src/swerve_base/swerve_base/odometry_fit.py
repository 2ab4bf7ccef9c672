"""Odometry of a swerve base: the rigid motion through the modules' measured
velocity vectors (:mod:`swerve_base.swerve` for the geometry).

Module i at ``p_i`` reports ``u_i = r_i omega_i e(phi_i)`` [m/s]. A rigid
twist ``x = (vx, vy, wz)`` gives ``C_p x`` there (2n equations, 3
unknowns); the least-squares ``x = C_p^+ u`` minimises the total slip in
m/s, the same weight for every module and both directions, and the residual
``u_i - (C_p x)_i`` is the slip of module i that no rigid motion explains.
This is the powered caster's slip-minimising fit with caster offset b = 0
(the contact point on the steering axis, the steering rate moving no
contact point), so the fit and the robust leave-one-out test are the ones
of :mod:`pcv_base.estimators`, called with the swerve's contact geometry
``(x_i, y_i, 0, r_i)``; their closed form costs O(n) with no matrix
inversion.

Estimators: ``slip_min`` (the fit above), ``robust`` (the fit without the
one module that alone disagrees: a wheel that spins or skids),
``pinv`` (the Moore-Penrose inverse of the wheel rows ``omega_i = e_i .
v(p_i) / r_i``: fits wheel rates, weighing module i by 1/r_i^2, and ignores
the sideways component, for comparison). The wheel rows alone lose rank
whenever the modules are parallel (driving straight, strafing): the motion
across the wheels is then unobservable from wheel rates, and with modules
almost parallel the plain inverse multiplies the encoders' noise by the
inverse of a near-zero singular value (kilometres of error on a straight
run). So its inverse is truncated: a direction whose singular value is below
``PINV_RCOND`` of the largest counts as unobservable and gets the
minimum-norm answer, no motion across parallel wheels, which is what the
rolling constraint says there.
"""

from __future__ import annotations

import math

import numpy as np

from holonomic_core.kinematics import ESTIMATORS
from pcv_base import estimators as rigid


#: relative singular value below which ``pinv`` treats a direction of the
#: twist as unobservable: modules within about 3 deg of parallel
PINV_RCOND = 0.05


def pinv(kin, positions, velocities):
    """Twist fitting the wheel rates [rad/s] in the least-squares sense,
    and the per-module velocity residual norms [m/s] it leaves."""
    phi = positions[0::2]
    c, s = np.cos(phi), np.sin(phi)
    rows = np.column_stack((c, s, kin.sx * s - kin.sy * c)) / kin.r[:, None]
    twist = np.linalg.pinv(rows, rcond=PINV_RCOND) @ velocities[1::2]
    vx, vy, wz = twist.tolist()
    u = kin.r * velocities[1::2]
    res = [math.hypot(ui * ci - (vx - wz * y), ui * si - (vy + wz * x))
           for ui, ci, si, x, y in zip(u.tolist(), c.tolist(), s.tolist(),
                                       kin.sx.tolist(), kin.sy.tolist())]
    return twist, np.array(res)


def estimate(kin, positions, velocities, estimator):
    """(twist [m/s, m/s, rad/s], per-module residual [m/s]) of the named
    estimator from joint ``positions`` [rad] and ``velocities`` [rad/s]."""
    if estimator == "slip_min":
        return rigid.slip_min(kin, positions, velocities)
    if estimator == "robust":
        return rigid.robust(kin, positions, velocities)
    if estimator == "pinv":
        return pinv(kin, positions, velocities)
    raise ValueError(f"estimator must be one of {ESTIMATORS}, got {estimator!r}")
