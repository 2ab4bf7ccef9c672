"""Torque distribution of a powered-caster vehicle (Holmberg & Khatib,
eq. 14): the joint torques that produce a base wrench, the force-side dual of
the slip-minimising estimator C# (:mod:`pcv_base.estimators`). The
operational-space controller computes the wrench from the dynamics
(:mod:`pcv_base.dynamics`, whose :meth:`PcvDynamics.torque_distribution
<pcv_base.dynamics.PcvDynamics.torque_distribution>` calls this) and
distributes it here.
"""

from __future__ import annotations

import numpy as np


def torque_distribution(kin, positions: np.ndarray, force: np.ndarray) -> np.ndarray:
    """Joint torques ``Gamma' = C#^T F`` [N m] (eq. 14) that produce the
    base wrench ``F = (fx [N], fy [N], tz [N m])`` in base_link at the joint
    ``positions`` [rad] of ``kin`` (a PoweredCasterKinematics) while
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
