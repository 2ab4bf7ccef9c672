"""Mobility ellipsoid, speed polytope and theoretical holonomicity.

Costa & Yim, "Designing for Uniform Mobility Using Holonomicity", Sec. II-V,
VII, for any base of this project (DDROT or PCV) at one configuration.

Twists ``x = (vx, vy, wz)`` are in base_link [m/s, m/s, rad/s]. The inverse
kinematics is linear in the twist, ``q_dot = J_base_to_joint(q) x`` (n x 3):
for the DDROT the inverse of the paper's eq. 1, for the PCV the constraint
matrix C of Holmberg & Khatib (a rigid, no-slip base moves its joints only
along C's range). With the joint speed limits ``q_max`` (W = diag(1/q_max)):

* the **speed polytope** ``P = {x : |J_base_to_joint x|_i <= q_max_i}``: every
  twist the base can hold within the limits -- for the DDROT exactly the image
  of the box of joint speeds under the paper's Jacobian;
* the **mobility ellipsoid** ``E = {x : |W J_base_to_joint x|_2 <= 1}``: the
  image of the unit ball of normalised joint speeds ``q_dot_i / q_max_i``. With
  unit limits this is the paper's ME (the image of the unit ball through eq. 1);
  E is inscribed in P.

The paper reads both through *projections* ("shadows": the twists reachable
when the third component is free) and *intersections* (the third component
held at 0, e.g. ``wz = 0``: translation at constant heading).

Theoretical holonomicity (docs/conventions.md): ``H_hat`` = slowest / fastest
translation speed at constant heading over all directions, within the joint
speed limits -- the radii of the ``wz = 0`` intersection of P. The paper's
eq. 3 uses the min/max radius of the ME; we use P, because the joint speed
limits, not a unit ball, are what bound a real base (for the contract's
"within the joint speed limits"), and P's radii are exact: the smallest is the
distance to the nearest constraint line, the largest a vertex.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from holonomic_analysis import rolling

#: names of the twist components, in order
AXES = ("vx", "vy", "wz")
#: labels for plots
AXIS_LABELS = ("vx forward [m/s]", "vy left [m/s]", "wz [rad/s]")


def configuration(model, steer: Sequence[float] | None = None,
                  turret: float | None = None) -> np.ndarray:
    """Joint positions [rad] (joint_names order) for an analysis.

    ``steer``: the PCV's steering angles (one per caster, rad, the joints'
    convention: the wheel's rolling heading in base_link); ``turret``: the
    DDROT's turret angle (rad). Unset angles are 0; wheel angles do not matter.
    """
    positions = np.zeros(len(model.joint_names))
    if model.kind == "pcv":
        n = len(model.joint_names) // 2
        if turret is not None:
            raise ValueError("--turret is for a DDROT; a PCV takes --steer")
        if steer is not None:
            if len(steer) != n:
                raise ValueError(f"{model.name} has {n} casters: give {n} steering angles, "
                                 f"got {len(steer)}")
            positions[0::2] = steer
    elif hasattr(model.kinematics, "steer_indices"):
        steer_idx = np.arange(len(positions))[model.kinematics.steer_indices]
        if turret is not None:
            raise ValueError(f"--turret is for a DDROT; {model.name} takes --steer")
        if steer is not None:
            if len(steer) != len(steer_idx):
                raise ValueError(f"{model.name} has {len(steer_idx)} steered wheels: give "
                                 f"{len(steer_idx)} steering angles, got {len(steer)}")
            positions[steer_idx] = steer
    else:
        if steer is not None:
            raise ValueError("--steer is for a PCV; a DDROT takes --turret")
        if turret is not None:
            positions[model.joint_names.index("turret_joint")] = turret
    if not np.all(np.isfinite(positions)):
        raise ValueError("joint angles must be finite")
    return positions


def base_to_joint(model, positions) -> np.ndarray:
    """``J_base_to_joint`` (n x 3): joint rates [rad/s] per unit body twist.

    Built from the model's own inverse kinematics (linear in the twist), so the
    analysis and the controller cannot disagree.
    """
    positions = np.asarray(positions, float)
    return np.column_stack([model.inverse(positions, e) for e in np.eye(3)])


def _vertices(N: np.ndarray) -> np.ndarray:
    """Vertices of ``{y : |N y|_inf <= 1}`` (N: m x k, k = 2 or 3, rank k).

    Every k of the 2m facet planes ``+-N_i y = 1`` that meet in one point give
    a candidate; the feasible ones are the vertices (m <= 16 here, so at most
    C(32, 3) = 4960 small solves).
    """
    m, k = N.shape
    planes = np.vstack([N, -N])
    scale = np.linalg.norm(planes, axis=1).max()
    found = []
    for combo in itertools.combinations(range(2 * m), k):
        M = planes[list(combo)]
        if abs(np.linalg.det(M)) < 1e-12 * scale ** k:
            continue
        y = np.linalg.solve(M, np.ones(k))
        if np.max(np.abs(N @ y)) <= 1.0 + 1e-9:
            found.append(y)
    if not found:
        raise ValueError("the speed polytope is unbounded or empty (singular kinematics)")
    pts = np.array(found)
    # duplicates: a vertex where more than k facets meet
    key = np.round(pts / max(np.abs(pts).max(), 1e-12), 9)
    _, idx = np.unique(key, axis=0, return_index=True)
    return pts[np.sort(idx)]


def _ordered(points: np.ndarray) -> np.ndarray:
    """The convex hull of 2-D ``points``, counter-clockwise (monotone chain)."""
    pts = sorted(map(tuple, np.round(points, 12)))
    if len(pts) < 3:
        return np.array(pts)

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    lower, upper = [], []
    for p in pts:
        while len(lower) >= 2 and cross(lower[-2], lower[-1], p) <= 0:
            lower.pop()
        lower.append(p)
    for p in reversed(pts):
        while len(upper) >= 2 and cross(upper[-2], upper[-1], p) <= 0:
            upper.pop()
        upper.append(p)
    return np.array(lower[:-1] + upper[:-1])


@dataclass(frozen=True)
class SpeedSet:
    """The speed polytope P and mobility ellipsoid E at one configuration.

    ``J_base_to_joint`` (n x 3) and ``limits`` (n,) [rad/s]; see the module doc.
    """

    J_base_to_joint: np.ndarray
    limits: np.ndarray

    @classmethod
    def of(cls, model, positions) -> "SpeedSet":
        return cls(base_to_joint(model, positions), model.max_joint_velocity)

    @property
    def normalized(self) -> np.ndarray:
        """``W J_base_to_joint``: normalised joint speeds per unit twist."""
        return self.J_base_to_joint / self.limits[:, None]

    # -- the polytope ----------------------------------------------------------------
    def ray_speed(self, direction) -> float:
        """Largest s with ``s * direction`` in P (direction: a twist, any length)."""
        u = np.asarray(direction, float)
        u = u / np.linalg.norm(u)
        worst = np.max(np.abs(self.normalized @ u))
        return math.inf if worst == 0.0 else float(1.0 / worst)

    def vertices(self) -> np.ndarray:
        """Vertices of P (k x 3) in twist space."""
        return _vertices(self.normalized)

    def intersection(self, axes: tuple[int, int]) -> np.ndarray:
        """P cut by the plane where the third component is 0: the polygon
        (counter-clockwise, k x 2) in the coordinates ``axes``."""
        return _ordered(_vertices(self.normalized[:, list(axes)]))

    def shadow(self, axes: tuple[int, int]) -> np.ndarray:
        """P projected on the plane ``axes`` (third component free): polygon."""
        return _ordered(self.vertices()[:, list(axes)])

    def max_component(self, axis: int, held: int) -> float:
        """Largest component ``axis`` of a twist in P with component ``held``
        at 0 and the third one free (e.g. the fastest lateral speed when the
        base may turn while it moves: axis 1, held 0)."""
        free = 3 - axis - held
        pts = _vertices(self.normalized[:, [axis, free]])
        return float(pts[:, 0].max())

    # -- the ellipsoid ---------------------------------------------------------------
    @property
    def ellipsoid_shape(self) -> np.ndarray:
        """S (3 x 3) with ``E = {x : x^T S^-1 x <= 1}``: S = (N^T N)^-1."""
        N = self.normalized
        return np.linalg.inv(N.T @ N)

    def ellipse(self, axes: tuple[int, int], kind: str = "shadow", points: int = 181) -> np.ndarray:
        """Outline (points x 2) of E's shadow on, or intersection with, the
        plane ``axes``."""
        S = self.ellipsoid_shape
        idx = list(axes)
        if kind == "shadow":
            shape = S[np.ix_(idx, idx)]
        elif kind == "intersection":
            shape = np.linalg.inv(np.linalg.inv(S)[np.ix_(idx, idx)])
        else:
            raise ValueError(f"kind must be 'shadow' or 'intersection', got {kind!r}")
        t = np.linspace(0.0, 2.0 * math.pi, points)
        return (np.linalg.cholesky(shape) @ np.vstack([np.cos(t), np.sin(t)])).T

    def orientation_bias(self) -> float:
        """Skew of the ellipsoid's lateral-rotation projection [rad/m]: the
        rotation rate by which the middle of its wz range moves per m/s of
        lateral speed (S_vy,wz / S_vy,vy). 0 for a base whose rotational
        mobility does not depend on the direction of travel; 1/b for the DDROT
        (moving sideways swings the drive base about the turret at v/b)."""
        S = self.ellipsoid_shape
        return float(S[1, 2] / S[1, 1])

    # -- the paper's numbers -----------------------------------------------------------
    def holonomicity(self) -> tuple[float, float, float]:
        """``(H_hat, slowest, fastest)``: translation speeds [m/s] at constant
        heading over all directions, and their ratio."""
        N2 = self.normalized[:, :2]
        norms = np.linalg.norm(N2, axis=1)
        slowest = float(1.0 / norms.max())      # distance to the nearest facet line
        fastest = float(np.linalg.norm(_vertices(N2), axis=1).max())
        return slowest / fastest, slowest, fastest

    def max_speeds(self) -> dict[str, float]:
        """The contract's ``max_speed`` [m/s, rad/s], plus the forward speed
        at constant heading. "forward"/"lateral" let the base turn while it
        moves (the shadow); "..._constant_heading" hold wz = 0; "rotation" is
        the turn rate in place."""
        return max_speeds_of(self)


def max_speeds_of(speed_set) -> dict[str, float]:
    """The ``max_speed`` entries of any speed set with ``max_component`` and
    ``ray_speed`` (:class:`SpeedSet`, :class:`rolling.RollingConstraints`)."""
    return {
        "forward": speed_set.max_component(0, held=1),
        "forward_constant_heading": speed_set.ray_speed((1.0, 0.0, 0.0)),
        "lateral": speed_set.max_component(1, held=0),
        "lateral_constant_heading": speed_set.ray_speed((0.0, 1.0, 0.0)),
        "rotation": speed_set.ray_speed((0.0, 0.0, 1.0)),
    }


def sigma_ratio(model, positions) -> float:
    """sigma_min / sigma_max of ``J_joint_to_base`` (SI units) at ``positions``:
    the DDROT's exact Jacobian, the PCV's slip-minimising C#."""
    s = np.linalg.svd(model.jacobian(positions), compute_uv=False)
    return float(s[-1] / s[0])


#: the max_speed entries that are translation speeds (capped by a speed norm)
TRANSLATIONS = ("forward", "forward_constant_heading", "lateral", "lateral_constant_heading")


def capped(speeds: Mapping[str, float], h_hat: float, slowest: float, fastest: float,
           max_speed: float) -> tuple[dict, float, float, float]:
    """The speeds and H_hat once the commanded translation speed, the norm of
    (vx, vy), is limited to ``max_speed`` [m/s] (``limits.linear.max_speed``;
    inf: none). The norm limit is a circle in the (vx, vy) plane: every
    direction's speed becomes min(its joint-limited speed, max_speed), so the
    slowest and the fastest constant-heading speeds are capped alike and H_hat
    = min(slowest, cap) / min(fastest, cap) rises towards 1 as the cap comes
    down to the slowest direction (a base limited below every direction's
    joint limit is equally fast in every direction). Rotation is not capped."""
    if not max_speed < fastest:
        return dict(speeds), h_hat, slowest, fastest
    out = {k: (min(v, max_speed) if k in TRANSLATIONS else v) for k, v in speeds.items()}
    slow, fast = min(slowest, max_speed), max_speed
    return out, (slow / fast if h_hat > 0.0 else 0.0), slow, fast


def analyze(model, positions, max_speed: float = math.inf) -> dict:
    """The numbers of ``holonomic-analyze --json`` for one configuration;
    ``max_speed`` [m/s]: the config's limit on the norm of (vx, vy), which
    caps the translation speeds and H_hat (:func:`capped`). A base whose
    wheels must turn before they roll in a new direction:
    :func:`analyze_rolling`."""
    if rolling.applies(model.kinematics, positions):
        return analyze_rolling(model, positions, max_speed)
    speeds = SpeedSet.of(model, positions)
    h_hat, slowest, fastest = speeds.holonomicity()
    max_speeds, h_hat, slowest, fastest = capped(speeds.max_speeds(), h_hat, slowest,
                                                 fastest, max_speed)
    S = speeds.ellipsoid_shape
    return {
        "robot": model.name,
        "kinematics": model.kind,
        "configuration": dict(zip(model.joint_names, map(float, positions))),
        "H_hat": h_hat,
        "sigma_ratio": sigma_ratio(model, positions),
        "max_speed": max_speeds,
        "constant_heading_speed": {"slowest": slowest, "fastest": fastest},
        "speed_limit": None if math.isinf(max_speed) else float(max_speed),
        "orientation_bias": speeds.orientation_bias(),
        "ellipsoid_semi_axes": [float(v) for v in np.sqrt(np.linalg.eigvalsh(S))[::-1]],
    }


def analyze_rolling(model, positions, max_speed: float = math.inf) -> dict:
    """:func:`analyze` for a base with rolling constraints
    (:mod:`holonomic_analysis.rolling`, docs/analysis.md "Swerve"): H_hat,
    max_speed, orientation_bias and ellipsoid_semi_axes with reorientation
    allowed (the steady-state speeds); sigma_ratio and ``instantaneous`` at
    the configuration itself."""
    rc = rolling.RollingConstraints(model.kinematics, positions, model.max_joint_velocity)
    h_hat, slowest, fastest = rc.holonomicity()
    max_speeds, h_hat, slowest, fastest = capped(max_speeds_of(rc), h_hat, slowest,
                                                 fastest, max_speed)
    instantaneous = rc.instantaneous()
    if instantaneous["translation"] is not None and math.isfinite(max_speed):
        instantaneous["translation"]["speed"] = min(instantaneous["translation"]["speed"],
                                                    float(max_speed))
    S = rc.ellipsoid_shape()
    return {
        "robot": model.name,
        "kinematics": model.kind,
        "configuration": dict(zip(model.joint_names, map(float, positions))),
        "H_hat": h_hat,
        "sigma_ratio": rc.sigma_ratio(),
        "max_speed": max_speeds,
        "constant_heading_speed": {"slowest": slowest, "fastest": fastest},
        "speed_limit": None if math.isinf(max_speed) else float(max_speed),
        # 0 (not a rounding's -0.000) for a geometry symmetric about base_link x
        "orientation_bias": float(S[1, 2] / S[1, 1]) if abs(S[1, 2]) > 1e-12 * S[1, 1] else 0.0,
        "ellipsoid_semi_axes": [float(v) for v in np.sqrt(np.linalg.eigvalsh(S))[::-1]],
        "instantaneous": instantaneous,
    }


def parse_sweep(text: str) -> tuple[str, np.ndarray]:
    """``KEY=START:STOP:N`` -> (key, N values from START to STOP)."""
    key, sep, spec = text.partition("=")
    parts = spec.split(":")
    if not sep or not key or len(parts) != 3:
        raise ValueError(f"--sweep wants KEY=START:STOP:N, got {text!r}")
    try:
        start, stop, count = float(parts[0]), float(parts[1]), int(parts[2])
    except ValueError:
        raise ValueError(f"--sweep wants numbers in KEY=START:STOP:N, got {text!r}") from None
    if count < 2 or not (math.isfinite(start) and math.isfinite(stop)):
        raise ValueError(f"--sweep wants finite START, STOP and N >= 2, got {text!r}")
    return key.strip(), np.linspace(start, stop, count)


def sweep(load, key: str, values: Sequence[float], overrides: Mapping[str, object],
          positions_of, max_speed: float = math.inf) -> list[dict]:
    """``analyze`` for each value of the flat config ``key``.

    ``load(overrides)`` builds a model; ``positions_of(model)`` its
    configuration. A value the config schema rejects raises its ConfigError.
    """
    rows = []
    for value in values:
        model = load({**overrides, key: float(value)})
        row = analyze(model, positions_of(model), max_speed)
        row["value"] = float(value)
        rows.append(row)
    return rows
