"""Torque distribution of a powered-caster vehicle (Holmberg & Khatib,
eq. 14): the joint torques that produce a base wrench, the force-side dual of
the slip-minimising estimator C# (:mod:`pcv_base.estimators`). The
operational-space controller computes the wrench from the dynamics
(:mod:`pcv_base.dynamics`, whose :meth:`PcvDynamics.torque_distribution
<pcv_base.dynamics.PcvDynamics.torque_distribution>` calls this) and
distributes it here.
"""

from __future__ import annotations

import math

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
    geometry = kin.contact_geometry                  # (sx, sy, b, r) per caster
    n = len(geometry)
    # scalar arithmetic on floats: for a handful of casters this costs a
    # fraction of the same work as numpy calls on length-n arrays
    cs = [(math.cos(phi), math.sin(phi)) for phi in positions[0::2]]
    if len(positions) != 2 * n:
        raise ValueError(f"expected {2 * n} joint positions, got {len(positions)}")
    px = [sx - b * c for (sx, _, b, _), (c, _) in zip(geometry, cs)]
    py = [sy - b * s for (_, sy, b, _), (_, s) in zip(geometry, cs)]
    cx, cy = sum(px) / n, sum(py) / n
    qx, qy = [x - cx for x in px], [y - cy for y in py]
    nu = (tz - (cx * fy - cy * fx)) / sum(x * x + y * y for x, y in zip(qx, qy))
    fx_n, fy_n = fx / n, fy / n
    out = []
    for (_, _, b, r), (c, s), x, y in zip(geometry, cs, qx, qy):
        f_x, f_y = fx_n - nu * y, fy_n + nu * x
        out += (b * (-s * f_x + c * f_y), r * (c * f_x + s * f_y))
    return np.array(out)
