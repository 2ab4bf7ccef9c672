"""Command limits that keep the direction of motion.

Two stages, both *uniform scalings*, never per-axis clipping (which bends the
path: a diagonal command clipped on x only turns into a more lateral one):

* :class:`TwistLimiter` -- per-axis speed, acceleration, deceleration and
  jerk limits and a limit on the translation speed (the norm of (vx, vy)) on
  the body twist, as ros2_controllers' ``SpeedLimiter`` has the per-axis ones,
  except that when any axis would exceed its limit the whole twist (or the
  whole change of twist, or of its acceleration) is scaled down, so a
  diagonal move ramps along the diagonal (docs/limits.md);
* :func:`saturate_joint_rates` -- when the inverse kinematics ask a joint for
  more than its speed limit, all joint rates are scaled by the same factor.
  The inverse kinematics are linear in the twist, so this is the same as
  scaling the twist: the base follows the commanded direction, slower.
"""

from __future__ import annotations

import math

import numpy as np

from holonomic_core import hot_path


class TwistLimiter:
    """Limits on a body twist (vx, vy, wz) applied by uniform scaling.

    ``max_velocity`` [m/s, m/s, rad/s], ``max_acceleration`` and
    ``max_deceleration`` [m/s^2, m/s^2, rad/s^2] (all > 0). Acceleration
    applies on an axis whose speed grows in magnitude, deceleration on one
    that slows down or reverses.

    ``max_speed`` [m/s] (> 0, or ``inf``: none) bounds the norm of (vx, vy),
    so that a diagonal is no faster than a straight line; ``max_jerk``
    [m/s^3, m/s^3, rad/s^3] (> 0, ``inf``: none on that axis) bounds how fast
    the twist's acceleration changes (see :meth:`limit_jerk`).
    """

    def __init__(self, max_velocity, max_acceleration, max_deceleration,
                 max_speed: float = math.inf, max_jerk=(math.inf, math.inf, math.inf)):
        self.max_velocity = np.array(max_velocity, dtype=float)
        self.max_acceleration = np.array(max_acceleration, dtype=float)
        self.max_deceleration = np.array(max_deceleration, dtype=float)
        self.max_jerk = np.array(max_jerk, dtype=float)
        self.max_speed = float(max_speed)
        for name, arr in (("max_velocity", self.max_velocity),
                          ("max_acceleration", self.max_acceleration),
                          ("max_deceleration", self.max_deceleration)):
            if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ValueError(f"TwistLimiter {name} must be 3 finite numbers > 0, got {arr}")
        if self.max_jerk.shape != (3,) or np.any(np.isnan(self.max_jerk)) \
                or np.any(self.max_jerk <= 0):
            raise ValueError(f"TwistLimiter max_jerk must be 3 numbers > 0 (inf: none), "
                             f"got {self.max_jerk}")
        if not self.max_speed > 0.0:
            raise ValueError(f"TwistLimiter max_speed must be > 0 (inf: none), "
                             f"got {self.max_speed}")
        # the per-cycle arithmetic runs on Python floats (numpy scalar access
        # costs more than the arithmetic on three numbers)
        self._vmax = tuple(self.max_velocity.tolist())
        self._amax = tuple(self.max_acceleration.tolist())
        self._dmax = tuple(self.max_deceleration.tolist())
        self._jmax = tuple(self.max_jerk.tolist())
        self._acc_bound = tuple(np.maximum(self.max_acceleration, self.max_deceleration).tolist())
        #: True when some axis has a jerk limit (else the acceleration limits alone)
        self.jerk_limited = bool(np.any(np.isfinite(self.max_jerk)))
        #: the compiled closed forms, or None for the pure-Python path (hot_path)
        self._hot = hot_path.module()
        self._limits = np.concatenate((self.max_velocity, self.max_acceleration,
                                       self.max_deceleration, [self.max_speed],
                                       self.max_jerk))

    def limit_velocity(self, twist: np.ndarray) -> tuple[np.ndarray, float]:
        """Scale ``twist`` so every axis is within its speed limit and the
        norm of (vx, vy) within ``max_speed``.

        Returns (limited twist, scale in (0, 1]).
        """
        scale = 1.0
        values = twist.tolist()
        for value, vmax in zip(values, self._vmax):
            mag = abs(value)
            if mag > vmax:
                scale = min(scale, vmax / mag)
        # the norm after the per-axis scaling (which bounds it: no overflow);
        # sqrt of the sum of squares, not math.hypot, so that the compiled
        # twin gives the same bits
        vx, vy = values[0] * scale, values[1] * scale
        speed = math.sqrt(vx * vx + vy * vy)
        if speed > self.max_speed:
            scale = scale * (self.max_speed / speed)
        return (twist * scale if scale < 1.0 else twist.copy()), scale

    def limit_acceleration(self, target: np.ndarray, previous: np.ndarray, dt: float) -> np.ndarray:
        """Move from ``previous`` towards ``target`` within one step of ``dt`` [s].

        The change is scaled uniformly so that each axis' change stays within
        its acceleration (growing speed) or deceleration (slowing or
        reversing) limit times ``dt``.
        """
        tgt, prev = target.tolist(), previous.tolist()
        scale = 1.0
        for i in range(3):
            change = abs(tgt[i] - prev[i])
            if change == 0.0:
                continue
            step = self._step_limit(i, tgt[i], prev[i]) * dt
            if change > step:
                scale = min(scale, step / change)
        if scale == 1.0:
            return np.array(tgt)
        return np.array([p + (g - p) * scale for g, p in zip(tgt, prev)])

    def _step_limit(self, i: int, tgt: float, prev: float) -> float:
        """Axis ``i``'s acceleration limit (speed growing) or deceleration
        limit (slowing down or reversing) for a change from prev to tgt."""
        growing = abs(tgt) > abs(prev) and tgt * prev >= 0.0
        return self._amax[i] if growing else self._dmax[i]

    def limit_jerk(self, target: np.ndarray, previous: np.ndarray, dt: float,
                   acceleration) -> np.ndarray:
        """One step of ``dt`` [s] from ``previous`` towards ``target`` under the
        acceleration *and* jerk limits, given the twist's ``acceleration``
        over the last step [m/s^2, m/s^2, rad/s^2].

        Two uniform scalings, each keeping a direction:

        1. the wanted acceleration is the velocity gap ``d = target -
           previous`` over ``dt``, scaled by one factor so that every axis
           stays within its acceleration (or deceleration) limit and within
           the acceleration from which it can still stop *on* the target
           under its jerk limit (:func:`jerk_arrival_bound`);
        2. the change from the last acceleration to that one is scaled by one
           factor so that no axis' acceleration changes by more than its jerk
           limit times ``dt``.

        From rest, or from a steady twist, the wanted acceleration stays
        parallel to ``d`` all the way, so the twist moves along the straight
        line to the target (the direction is kept) and reaches it without
        overshoot: the arrival bound is kept from step to step (the step
        after one within it can always reduce its acceleration by the jerk
        limit and still be within it; derivation in jerk_arrival_bound). A
        target changed in mid-ramp bends the path in twist space: the
        acceleration cannot turn at once.
        """
        if not dt > 0.0:
            return previous.copy()
        tgt, prev = target.tolist(), previous.tolist()
        # the last step's acceleration, as the limits could have made it (a
        # twist cut by the joint speed saturation drops faster than any limit)
        acc = [min(max(a, -lim), lim) for a, lim in zip(list(acceleration), self._acc_bound)]
        sigma = 1.0
        for i in range(3):
            change = abs(tgt[i] - prev[i])
            if change == 0.0:
                continue
            need = change / dt                       # acceleration to arrive in one step
            allowed = self._step_limit(i, tgt[i], prev[i])
            jerk = self._jmax[i] * dt               # acceleration change per step
            if jerk < math.inf:
                allowed = min(allowed, jerk_arrival_bound(need, jerk))
            if need > allowed:
                sigma = min(sigma, allowed / need)
        wanted = [(g - p) / dt * sigma for g, p in zip(tgt, prev)]
        kappa = 1.0
        for i in range(3):
            change = abs(wanted[i] - acc[i])
            jerk = self._jmax[i] * dt
            if change > jerk:
                kappa = min(kappa, jerk / change)
        if sigma == 1.0 and kappa == 1.0:
            return np.array(tgt)                     # arrives: exactly on the target
        return np.array([p + (a + (w - a) * kappa) * dt
                         for p, a, w in zip(prev, acc, wanted)])

    def limit(self, target: np.ndarray, previous: np.ndarray, dt: float,
              acceleration=None) -> np.ndarray:
        """Speed limits, then acceleration (and jerk) limits, on ``target``
        given the last output ``previous`` and, for the jerk limits, its
        ``acceleration`` over the last step (None: zero, from rest).

        Returns a new array (vx, vy, wz) [m/s, m/s, rad/s]; compiled when
        :mod:`holonomic_core.hot_path` selects it (the same numbers).
        """
        if acceleration is None:
            acceleration = _ZERO3
        if self._hot is not None:
            return self._hot.limit_twist(target, previous, dt, self._limits, acceleration)
        limited, _ = self.limit_velocity(target)
        if self.jerk_limited:
            return self.limit_jerk(limited, previous, dt, acceleration)
        return self.limit_acceleration(limited, previous, dt)


_ZERO3 = np.zeros(3)
#: gap / jerk above which jerk_arrival_bound uses the continuous bound (its
#: integer n, about sqrt(2 gap / jerk), stays exact in a float below this)
_EXACT_RATIO = 1e12


def jerk_arrival_bound(gap: float, jerk: float) -> float:
    """The largest acceleration a' (>= 0) from which a velocity ``gap``
    (expressed as the acceleration that closes it in one step, |d| / dt) can
    still be closed exactly, with a zero acceleration after it, when the
    acceleration may change by at most ``jerk`` (j dt) per step.

    After a step at a' the gap left is ``gap - a'``; from a' the acceleration
    must come down to 0 by at most ``jerk`` a step, which closes at least
    ``S(a') = sum_k max(a' - k jerk, 0)`` (k >= 1) more. So a' is allowed
    while ``F(a') = a' + S(a') <= gap``. F is piecewise linear and increasing,
    ``F(n jerk) = jerk n (n + 1) / 2``: with the n for which ``F(n jerk) <=
    gap < F((n + 1) jerk)``, ``F(a') = (n + 1) a' - jerk n (n + 1) / 2``, so
    ``a' = (gap + jerk n (n + 1) / 2) / (n + 1)``.

    The bound holds from step to step: if a' <= bound(gap) then
    ``gap - a' >= S(a') = F(a' - jerk)`` (for a' >= jerk), so ``a' - jerk <=
    bound(gap - a')`` -- the next step can reduce its acceleration by one
    jerk step and be within the bound again; and bound(gap) <= gap (F(a') >=
    a'), so no step passes the target.

    In continuous time this is the familiar ``a <= sqrt(2 j |d|)`` (the
    velocity a ramp from a down to 0 covers is a^2 / (2 j)).
    """
    if gap <= 0.0:
        return 0.0
    if not gap / jerk <= _EXACT_RATIO:
        # far from the target (or NaN, which passes through): the continuous
        # bound, which the exact one approaches there
        return math.sqrt(2.0 * gap * jerk)
    n = math.floor((math.sqrt(1.0 + 8.0 * gap / jerk) - 1.0) / 2.0)
    # the float square root can land one off the integer: correct it
    while n > 0 and jerk * n * (n + 1) / 2.0 > gap:
        n -= 1
    while jerk * (n + 1) * (n + 2) / 2.0 <= gap:
        n += 1
    return (gap + jerk * n * (n + 1) / 2.0) / (n + 1)


def saturate_joint_rates_pure(rates: np.ndarray,
                              max_rates: np.ndarray) -> tuple[np.ndarray, float]:
    """Scale all joint ``rates`` [rad/s] by one factor so none exceeds ``max_rates``.

    Returns (scaled rates, scale in (0, 1]); ``rates`` itself when nothing
    is scaled. Non-finite rates are a caller bug upstream (the twist is
    validated first); they give scale 0 and zero rates, never motion.
    The pure-Python reference of :func:`saturate_joint_rates`.
    """
    worst = 0.0
    for value, limit in zip(rates.tolist(), max_rates.tolist()):
        ratio = abs(value) / limit
        if not math.isfinite(ratio):
            return np.zeros_like(rates), 0.0
        if ratio > worst:
            worst = ratio
    if worst <= 1.0:
        return rates, 1.0
    scale = 1.0 / worst
    return rates * scale, scale


def joint_rate_saturation():
    """:func:`saturate_joint_rates_pure` or its compiled twin, as
    :mod:`holonomic_core.hot_path` selects now (a cycle object takes it once,
    when it is built: a dispatching wrapper's call would cost as much as the
    compiled arithmetic)."""
    hot = hot_path.module()
    return saturate_joint_rates_pure if hot is None else hot.saturate_joint_rates


#: the saturation selected when this module was imported
saturate_joint_rates = joint_rate_saturation()


def is_finite_twist(twist) -> bool:
    """True when all three components are finite numbers."""
    x, y, z = twist
    return math.isfinite(x) and math.isfinite(y) and math.isfinite(z)
