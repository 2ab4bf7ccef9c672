"""Caster isotropy: Kim & Moon, "Isotropy analysis of caster wheeled
omnidirectional mobile robot with variable steering link offset" (2006).

Their kinematics of a fully actuated caster robot is ``A x_dot = B Theta``
(eq. 13) with the task vector ``x_dot = (v, L w)`` -- the characteristic
length ``L`` [m] gives the rotation column the units of the others -- and
``Z = B^-1 A`` (eq. 17) maps it to the joint rates. A configuration is
isotropic when ``Z^T Z`` is a multiple of the identity (eq. 18): every task
direction costs the same joint speed. The **isotropy index** is
``sigma_min(Z) / sigma_max(Z)`` (1 when isotropic, 0 at a singularity).

Mapping to this project's model (``pcv_base.powered_caster``). Kim & Moon put
the wheel centre at ``p_i = s_i - d u_i`` with ``u_i = -(cos phi_i, sin phi_i)``
and let the wheel roll along ``u_i``; our contact point is ``s_i - b e_i`` with
``e_i`` the rolling heading. So ``e_i = u_i``: **our steering angle is theirs
+ pi**, d is our caster offset b, and the rows of Z are the rows of our
constraint matrix C (eq. 7 of Holmberg & Khatib) with the rotation column
divided by L. Their eq. 8 has the opposite sign on the steering term (their
phi_dot is minus ours); a row's sign does not change ``Z^T Z``, so the
isotropy results do not depend on it. The reference point is base_link's
origin (the paper's is the triangle's centre O_b).

Departures from the printed equations (each checked numerically in
src/holonomic_analysis/test/test_analysis.py):

* eq. 4: the vertex vectors printed do not sum to zero (s3 = l/sqrt(3) (0, 1)
  with s1, s2 both at +1/2 in y). The fix that makes every later claim of the
  paper hold is s1 = l/sqrt(3) (-sqrt(3)/2, -1/2), s2 = l/sqrt(3) (sqrt(3)/2,
  -1/2), s3 = l/sqrt(3) (0, 1) -- an equilateral triangle, vertices numbered
  counter-clockwise. (Flipping s3 instead mirrors the triangle, and then the
  family that is isotropic for every d is (-2pi/3, 2pi/3), not the paper's
  (2pi/3, -2pi/3), and the third group's special offsets are not isotropic.)
* eq. 24: ``(u_i^t d q_i)^2`` is ``(u_i^t q_i)^2`` (C3 is the rotation
  diagonal of eq. 19).
* eq. 30 does not follow from eq. 29 with eqs. 11-12 as printed; we do not use
  it: C1 and C2 are evaluated from ``Z^T Z`` itself.
* Sec. IV.2 writes the always-isotropic family as ``(phi_1, phi_2 + 2pi/3,
  phi_3 - 2pi/3)``; it is ``(phi_1, phi_1 + 2pi/3, phi_1 - 2pi/3)``.
* The group-3 offsets ``d = sqrt(3)/4 |1 - mu|`` are in units of the side
  length l (the paper normalises l = 1).

Conditions. ``Z^T Z = [[M, m / L], [m^T / L, k / L^2]]`` with M (2 x 2), m
(2,), k from C. Isotropy needs ``M = sigma I`` (C1), ``m = 0`` (C2) and
``k / L^2 = sigma`` (C3). C1 and C2 do not involve L, so they pick the
isotropic steering angles, and C3 then gives the isotropic characteristic
length ``L = sqrt(k / sigma)``, ``sigma = trace(M) / 2``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: index above which a configuration counts as isotropic
ISOTROPIC = 1.0 - 1e-6


def to_paper_angles(steer) -> np.ndarray:
    """Our steering angles [rad] -> Kim & Moon's phi_i (wrapped to (-pi, pi])."""
    return _wrap(np.asarray(steer, float) - math.pi)


def from_paper_angles(phi) -> np.ndarray:
    """Kim & Moon's phi_i [rad] -> our steering angles (wrapped to (-pi, pi])."""
    return _wrap(np.asarray(phi, float) + math.pi)


def _wrap(angle):
    return math.pi - np.mod(math.pi - np.asarray(angle, float), 2.0 * math.pi)


def paper_robot(offset: float, wheel_radius: float, side: float = 1.0):
    """The paper's robot: three identical casters at the vertices of an
    equilateral triangle of side ``side`` [m] (eq. 4, corrected: see the
    module doc), caster offset d = ``offset`` [m], wheel radius r [m].

    Returns the :class:`PoweredCasterKinematics`.
    """
    from pcv_base.powered_caster import Caster, PoweredCasterKinematics
    h = side / math.sqrt(3.0)
    betas = (math.radians(210.0), math.radians(-30.0), math.radians(90.0))
    return PoweredCasterKinematics([Caster(f"c{i + 1}", h, beta, wheel_radius, offset)
                                    for i, beta in enumerate(betas)])


def _gram(kin, steer) -> tuple[np.ndarray, np.ndarray, float]:
    """(M, m, k) of ``Z^T Z`` at the steering angles ``steer`` (see module doc)."""
    positions = np.zeros(2 * len(kin.casters))
    positions[0::2] = steer
    C = kin.constraint_matrix(positions)
    G = C.T @ C
    return G[:2, :2], G[:2, 2], float(G[2, 2])


def _index(M, m, k, lengths) -> np.ndarray:
    """Isotropy index for each characteristic length in ``lengths`` [m]."""
    t = 1.0 / np.atleast_1d(np.asarray(lengths, float))
    G = np.zeros((len(t), 3, 3))
    G[:, :2, :2] = M
    G[:, :2, 2] = G[:, 2, :2] = m[None, :] * t[:, None]
    G[:, 2, 2] = k * t * t
    ev = np.linalg.eigvalsh(G)
    return np.sqrt(np.maximum(ev[:, 0], 0.0) / ev[:, -1])


@dataclass(frozen=True)
class Isotropy:
    """Isotropy of one configuration.

    ``index``: sigma_min/sigma_max of Z at ``length``, the characteristic
    length L [m] that maximises it; ``c1``, ``c2``: how far C1 and C2 are from
    holding (relative to sigma; both 0 at an isotropic configuration);
    ``isotropic_length``: C3's L = sqrt(k / sigma) (the maximiser when the
    configuration is isotropic).
    """

    index: float
    length: float
    c1: float
    c2: float
    isotropic_length: float

    @property
    def isotropic(self) -> bool:
        return self.index >= ISOTROPIC


def isotropy(kin, steer) -> Isotropy:
    """Isotropy index of the PCV ``kin`` at steering angles ``steer`` [rad,
    our convention], maximised over the characteristic length."""
    steer = np.asarray(steer, float)
    if steer.shape != (len(kin.casters),) or not np.all(np.isfinite(steer)):
        raise ValueError(f"need {len(kin.casters)} finite steering angles, got {steer.tolist()}")
    M, m, k = _gram(kin, steer)
    sigma = 0.5 * float(np.trace(M))
    natural = math.sqrt(k / sigma)
    # The index is a smooth function of log L with one hump: a coarse scan
    # over six decades around C3's length, then golden-section refinement.
    logs = np.log(natural) + np.linspace(-3 * math.log(10), 3 * math.log(10), 121)
    best = int(np.argmax(_index(M, m, k, np.exp(logs))))
    lo, hi = logs[max(best - 1, 0)], logs[min(best + 1, len(logs) - 1)]

    def f(g):
        return float(_index(M, m, k, [math.exp(g)])[0])

    ratio = (math.sqrt(5.0) - 1.0) / 2.0
    a, b = hi - ratio * (hi - lo), lo + ratio * (hi - lo)
    fa, fb = f(a), f(b)
    for _ in range(50):
        if fa < fb:
            lo, a, fa = a, b, fb
            b = lo + ratio * (hi - lo)
            fb = f(b)
        else:
            hi, b, fb = b, a, fa
            a = hi - ratio * (hi - lo)
            fa = f(a)
    length = math.exp(0.5 * (lo + hi))
    c1 = float(np.linalg.norm(M - sigma * np.eye(2)) / sigma)
    c2 = float(np.linalg.norm(m) / (sigma * natural))
    return Isotropy(float(_index(M, m, k, [length])[0]), length, c1, c2, natural)


# -- the search for isotropic configurations --------------------------------------------
def _residuals(kin, angles: np.ndarray) -> np.ndarray:
    """C1 and C2 residuals (B x 4, relative to sigma) at a batch of steering
    configurations (B x n). Zero exactly at the isotropic configurations."""
    rows_s, rows_w = [], []
    for i, cas in enumerate(kin.casters):
        phi = angles[:, i]
        s, c = np.sin(phi), np.cos(phi)
        b, r, h = cas.caster_offset, cas.wheel_radius, cas.h
        rows_s.append(np.stack([-s / b, c / b, h * np.cos(cas.beta - phi) / b - 1.0], axis=1))
        rows_w.append(np.stack([c / r, s / r, h * np.sin(phi - cas.beta) / r], axis=1))
    C = np.stack(rows_s + rows_w, axis=1)            # B x 2n x 3
    G = np.einsum("bki,bkj->bij", C, C)
    sigma = 0.5 * (G[:, 0, 0] + G[:, 1, 1])
    scale_m = sigma * np.sqrt(G[:, 2, 2] / sigma)
    return np.stack([(G[:, 0, 0] - G[:, 1, 1]) / (2 * sigma), G[:, 0, 1] / sigma,
                     G[:, 0, 2] / scale_m, G[:, 1, 2] / scale_m], axis=1)


def _refine(kin, start: np.ndarray, iterations: int = 60) -> tuple[np.ndarray, np.ndarray]:
    """Levenberg-Marquardt on the C1/C2 residuals, batched over starts (B x n)."""
    x = start.copy()
    n = x.shape[1]
    lam = np.full(len(x), 1e-3)
    h = 1e-7
    res = _residuals(kin, x)
    cost = (res ** 2).sum(axis=1)
    for _ in range(iterations):
        unit = np.eye(n) * h
        J = np.stack([(_residuals(kin, x + unit[j]) - _residuals(kin, x - unit[j])) / (2 * h)
                      for j in range(n)], axis=2)                         # B x 4 x n
        JtJ = np.einsum("bki,bkj->bij", J, J)
        g = np.einsum("bki,bk->bi", J, res)
        step = -np.linalg.solve(JtJ + lam[:, None, None] * np.eye(n), g[:, :, None])[:, :, 0]
        trial = x + step
        res_t = _residuals(kin, trial)
        cost_t = (res_t ** 2).sum(axis=1)
        better = cost_t < cost
        x[better], res[better], cost[better] = trial[better], res_t[better], cost_t[better]
        lam = np.where(better, lam * 0.3, lam * 10.0)
    return x, cost


@dataclass(frozen=True)
class IsotropicSet:
    """Isotropic steering configurations found by :func:`isotropic_configurations`.

    ``kind``: "family" -- ``(phi_1, phi_1 + offsets[0], phi_1 + offsets[1], ...)``
    is isotropic for every phi_1 -- or "point" -- the single configuration
    ``angles``. Angles [rad] in our convention; ``length``: the isotropic
    characteristic length [m] (for a family: at ``angles``).
    """

    kind: str
    angles: tuple[float, ...]
    offsets: tuple[float, ...]
    length: float


def isotropic_configurations(kin, grid: int = 36, tol: float = 1e-9) -> list[IsotropicSet]:
    """All isotropic steering configurations of a PCV, by search.

    Scans a ``grid``^n lattice of steering angles for small C1/C2 residuals,
    refines the best candidates with Levenberg-Marquardt, and groups the
    solutions: one that stays isotropic when every caster turns by the same
    angle belongs to a family, listed once by its steering offsets. Meant for
    n = 3 (the paper's robot; n = 4 works with a coarser grid).
    """
    n = len(kin.casters)
    axis = np.linspace(-math.pi, math.pi, grid, endpoint=False)
    lattice = np.stack(np.meshgrid(*([axis] * n), indexing="ij"), axis=-1).reshape(-1, n)
    cost = (_residuals(kin, lattice) ** 2).sum(axis=1)
    starts = lattice[np.argsort(cost)[:max(200, 4 * grid)]]
    found, fcost = _refine(kin, starts)
    solutions = _wrap(found[fcost < tol])
    sets: list[IsotropicSet] = []
    shifts = np.linspace(0.0, 2.0 * math.pi, 13)[1:-1]

    def same(a, b):
        return np.max(np.abs(_wrap(a - b))) < 1e-4

    for sol in solutions:
        offsets = _wrap(sol[1:] - sol[0])
        moved = sol[None, :] + shifts[:, None]
        is_family = bool(np.all((_residuals(kin, moved) ** 2).sum(axis=1) < tol))
        if is_family:
            if any(s.kind == "family" and same(np.array(s.offsets), offsets) for s in sets):
                continue
            anchor = np.concatenate([[0.0], offsets])
            sets.append(IsotropicSet("family", tuple(map(float, anchor)),
                                     tuple(map(float, offsets)), isotropy(kin, anchor).length))
        else:
            if any(s.kind == "point" and same(np.array(s.angles), sol) for s in sets):
                continue
            sets.append(IsotropicSet("point", tuple(map(float, sol)), tuple(map(float, offsets)),
                                     isotropy(kin, sol).length))
    # points lying on a family found later are not separate results
    fams = [s for s in sets if s.kind == "family"]
    return fams + [s for s in sets if s.kind == "point"
                   and not any(same(np.array(f.offsets), np.array(s.offsets)) for f in fams)]
