"""Joint acceleration limits: the twist change every joint's motor can follow.

A twist within the base's own acceleration limits can still ask one joint
for more acceleration than its motor gives -- a powered caster swinging
through its unstable alignment (its wheel leading its steering axis), the
DDROT's turret when a strafe reverses. The drive then saturates and the base
leaves the commanded path. This stage scales the commanded twist change so
that no joint's rate changes by more than ``max_acceleration x dt`` in one
cycle, as HSR's base controller does for its offset-turret base.

The joint accelerations follow exactly from the kinematics. The joint rates
are linear in the twist at a configuration, ``q_dot = J(q) xi`` (``J`` is
``J_base_to_joint``, the exact inverse kinematics). The last cycle commanded
``q_dot_prev = J(q_prev) xi_prev``; this cycle, at the measured positions
``q``, a twist ``xi`` asks for ``J(q) xi``, so over the cycle

    q_ddot dt = J(q) xi - q_dot_prev
              = [J(q) xi_prev - q_dot_prev]  +  J(q) (xi - xi_prev)
              =        a (drift)             +        b (change)

-- the discrete form of ``q_ddot = J_dot(q, q_dot) xi + J(q) xi_dot``. The
drift ``a`` is what the configuration change alone asks for at an unchanged
twist (a swinging caster's steering rate grows with it: at speed v and caster
offset b, ``v^2 sin(2 alpha) / (2 b^2)``); ``b`` is linear in the twist change.

Candidates, in order of preference, each a scaling that keeps a direction:

1. ``xi = xi_prev + t (xi_target - xi_prev)``, the largest t in [0, 1] with
   ``|a_i + t b_i| <= c_i = max_acceleration_i dt`` for every joint i: the
   twist moves along the straight line towards the limited target (t = 1: the
   target passes unchanged);
2. when even t = 0 is too much (the drift alone exceeds a limit),
   ``xi = (1 - u) xi_prev``, the smallest u in [0, 1] that keeps every joint
   within its limit: the base slows down along its current direction of
   motion, which is what reduces the drift (quadratic in the speed);
3. when neither can (the configuration asks more of some joint than any
   scaling of the twist allows within one cycle): the candidate on either
   segment with the smallest worst ratio ``|q_ddot_i| / max_acceleration_i``;
   the drive saturates for that cycle, as little as the kinematics allow.

Each constraint ``|a_i + s b_i| <= c_i`` is an interval of s, so 1 and 2 are
interval intersections in closed form; 3 bisects on the ratio (rare cycles).
Joints without a limit (0 in the config) are left out. The joint speed
saturation (limits.saturate_joint_rates) comes after this stage.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

#: bisection steps of the least-violation case (the ratio to 2^-40 of its range)
_BISECTION_STEPS = 40


def _interval(a: float, b: float, c: float, lo: float, hi: float) -> tuple[float, float]:
    """The part of [lo, hi] where ``|a + s b| <= c`` (empty: lo > hi)."""
    if b == 0.0:
        return (lo, hi) if abs(a) <= c else (1.0, 0.0)
    s1, s2 = (-c - a) / b, (c - a) / b
    if s1 > s2:
        s1, s2 = s2, s1
    return max(lo, s1), min(hi, s2)


def _feasible(a, b, c, scale: float = 1.0) -> tuple[float, float]:
    """The s in [0, 1] with ``|a_i + s b_i| <= scale c_i`` for every i."""
    lo, hi = 0.0, 1.0
    for ai, bi, ci in zip(a, b, c):
        lo, hi = _interval(ai, bi, ci * scale, lo, hi)
        if lo > hi:
            break
    return lo, hi


class JointAccelerationLimit:
    """Scales the commanded twist change to the joints' acceleration limits.

    ``inverse(positions, twist)``: the exact inverse kinematics (joint rates
    [rad/s] in joint order, linear in the twist); ``max_acceleration``
    [rad/s^2] per joint, ``inf`` for a joint without a limit;
    ``max_velocity`` [rad/s] per joint (> 0).
    """

    def __init__(self, inverse, max_acceleration, max_velocity):
        self._inverse = inverse
        #: the joints' speed limits [rad/s], joint order
        self.max_velocity = tuple(float(v) for v in max_velocity)
        limits = np.array(max_acceleration, dtype=float)
        if limits.ndim != 1 or np.any(np.isnan(limits)) or np.any(limits <= 0):
            raise ValueError(f"JointAccelerationLimit max_acceleration must be numbers > 0 "
                             f"(inf: none), got {limits}")
        self.max_acceleration = limits
        #: the limited joints (indices in joint order)
        self._limited = [i for i, v in enumerate(limits.tolist()) if math.isfinite(v)]
        #: the last cycle's outcome: "target", "slowed", "saturated" (diagnostics, tests)
        self.last = "target"
        #: the uniform scale of the last cycle's target to the joint speed limits
        self.speed_scale = 1.0

    @classmethod
    def from_config(cls, model, values: Mapping) -> "JointAccelerationLimit | None":
        """The stage for ``model`` from the ``joints.NAME.max_acceleration``
        values (0: none); None when no joint has a limit."""
        limits = [values.get(f"joints.{j}.max_acceleration", 0.0) or math.inf
                  for j in model.joint_names]
        if all(math.isinf(v) for v in limits):
            return None
        return cls(model.kinematics.inverse, limits, model.max_joint_velocity)

    def accelerations(self, positions, twist, previous_rates, dt: float) -> np.ndarray:
        """The joint accelerations [rad/s^2] over a cycle of ``dt`` [s] in which
        the commanded rates go from ``previous_rates`` to those of ``twist``
        at ``positions``: ``(J(q) xi - q_dot_prev) / dt``."""
        return (self._inverse(positions, twist) - previous_rates) / dt

    def limit(self, positions, twist, previous_twist, previous_rates, dt: float) -> np.ndarray:
        """The twist to command this cycle (base_link, [m/s, m/s, rad/s]).

        ``positions`` [rad]: the measured joints; ``twist``: the limited target
        of this cycle; ``previous_twist`` and ``previous_rates`` [rad/s]: what
        the last cycle commanded (after the joint speed saturation). Returns
        ``twist`` itself when every joint is within its limits.

        The joint speed limits are part of the same intervals (``|q_dot_i| <=
        max_velocity_i`` is affine along each candidate too), and the target is
        first scaled uniformly to them, as the saturation after this stage
        would: so the twist chosen keeps every joint within its speed *and*
        acceleration limits whenever that is possible, and the saturation that
        follows has nothing left to do. :attr:`speed_scale` is that first
        scaling (the controller reports it as its saturation).
        """
        if not dt > 0.0:
            self.last, self.speed_scale = "target", 1.0
            return previous_twist.copy()
        base = self._inverse(positions, previous_twist)
        rates = self._inverse(positions, twist)
        base_l, rates_l = base.tolist(), rates.tolist()
        prev_l = np.asarray(previous_rates, dtype=float).tolist()
        vmax = self.max_velocity
        worst = max(abs(r) / v for r, v in zip(rates_l, vmax))
        self.speed_scale = 1.0 if worst <= 1.0 else 1.0 / worst
        if self.speed_scale < 1.0:
            twist = twist * self.speed_scale
            rates_l = [r * self.speed_scale for r in rates_l]
        lim = self.max_acceleration.tolist()
        idx = self._limited
        # acceleration constraints |drift + s direction| <= cap, then the
        # speed constraints |base + s direction| <= max_velocity
        drift = [base_l[i] - prev_l[i] for i in idx] + base_l
        change = [rates_l[i] - base_l[i] for i in idx] + [r - b for r, b in zip(rates_l, base_l)]
        cap = [lim[i] * dt for i in idx] + list(vmax)
        # 1. along the line to the (speed-scaled) target
        lo, hi = _feasible(drift, change, cap)
        if lo <= hi:
            self.last = "target"
            if hi >= 1.0:
                return twist
            return previous_twist + (twist - previous_twist) * hi
        # 2. slowing down along the current motion: drift - u base
        slow = [-base_l[i] for i in idx] + [-b for b in base_l]
        lo, hi = _feasible(drift, slow, cap)
        if lo <= hi:
            self.last = "slowed"
            return previous_twist * (1.0 - lo)
        # 3. least violation: the smallest ratio at which either segment is
        # feasible (the speed limits scaled with it: the saturation after
        # this stage then cuts the speeds back)
        low, high = 1.0, min(self._worst(drift, change, cap, 0.0),
                             self._worst(drift, slow, cap, 1.0))

        def either(scale: float) -> bool:
            for direction in (change, slow):
                lo, hi = _feasible(drift, direction, cap, scale)
                if lo <= hi:
                    return True
            return False

        for _ in range(_BISECTION_STEPS):
            mid = 0.5 * (low + high)
            if either(mid):
                high = mid
            else:
                low = mid
        self.last = "saturated"
        lo, hi = _feasible(drift, change, cap, high)
        if lo <= hi:
            return previous_twist + (twist - previous_twist) * hi
        lo, hi = _feasible(drift, slow, cap, high)
        return previous_twist * (1.0 - lo)

    @staticmethod
    def _worst(a, b, c, s: float) -> float:
        """max_i |a_i + s b_i| / c_i."""
        return max((abs(ai + s * bi) / ci for ai, bi, ci in zip(a, b, c)), default=0.0)
