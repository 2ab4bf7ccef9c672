"""Internal force: the part of the wheels' contact forces that moves nothing.

ROS-free (numpy). The planar contact forces ``f = (f_1, ..., f_n)``, each
``f_i = (f_x, f_y)`` [N] in base_link at the contact point ``p_i`` [m], produce
the body wrench ``F = W f`` with the contact-to-body map

    W = [[1, 0, ..., 1, 0], [0, 1, ..., 0, 1], [-p_1y, p_1x, ..., -p_ny, p_nx]],

the transpose of the map ``p_dot = C_p x_dot`` from the body twist to the
contact-point velocities (Holmberg & Khatib, eq. 11; by duality ``F = C_p^T f``,
as eq. 9 is for the joints). Forces in the null space of ``W`` cancel: no net
force or moment on the base, only wheels pushing against each other -- the
actuator conflict the paper's C# (eq. 13) and its dual C#^T F (eq. 14) are
meant to avoid. The internal force is that component,

    f_int = (I - W^+ W) f,

and its size ``|f_int|`` [N]; ``W^+ W f`` is the least-squares (minimum-norm)
set of contact forces producing the same wrench, which is what ``C#^T F``
asks the wheels for.
"""

from __future__ import annotations

import numpy as np


def contact_to_body_map(positions: np.ndarray) -> np.ndarray:
    """``W`` (3 x 2n): planar contact forces at ``positions`` (n x 2, base_link
    [m]) to the body wrench (F_x [N], F_y [N], M_z [N m]) about base_link."""
    p = np.asarray(positions, float).reshape(-1, 2)
    n = len(p)
    w = np.zeros((3, 2 * n))
    w[0, 0::2] = 1.0
    w[1, 1::2] = 1.0
    w[2, 0::2] = -p[:, 1]
    w[2, 1::2] = p[:, 0]
    return w


def internal_force(positions: np.ndarray, forces: np.ndarray) -> np.ndarray:
    """``f_int = (I - W^+ W) f`` [N], n x 2: the component of the contact forces
    ``forces`` (n x 2, base_link) at ``positions`` (n x 2) in the null space of
    the contact-to-body map (no net force or moment on the base)."""
    f = np.asarray(forces, float).reshape(-1)
    if f.size == 0:
        return np.zeros((0, 2))
    w = contact_to_body_map(positions)
    return (f - np.linalg.pinv(w) @ (w @ f)).reshape(-1, 2)
