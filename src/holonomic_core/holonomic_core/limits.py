"""Command limits that keep the direction of motion.

Two stages, both *uniform scalings*, never per-axis clipping (which bends the
path: a diagonal command clipped on x only turns into a more lateral one):

* :class:`TwistLimiter` -- per-axis speed, acceleration and deceleration
  limits on the body twist, as ros2_controllers' ``SpeedLimiter`` has them,
  except that when any axis would exceed its limit the whole twist (or the
  whole change of twist) is scaled down, so a diagonal move ramps along the
  diagonal;
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
    """Per-axis limits on a body twist (vx, vy, wz) applied by uniform scaling.

    ``max_velocity`` [m/s, m/s, rad/s], ``max_acceleration`` and
    ``max_deceleration`` [m/s^2, m/s^2, rad/s^2] (all > 0). Acceleration
    applies on an axis whose speed grows in magnitude, deceleration on one
    that slows down or reverses.
    """

    def __init__(self, max_velocity, max_acceleration, max_deceleration):
        self.max_velocity = np.array(max_velocity, dtype=float)
        self.max_acceleration = np.array(max_acceleration, dtype=float)
        self.max_deceleration = np.array(max_deceleration, dtype=float)
        for name, arr in (("max_velocity", self.max_velocity),
                          ("max_acceleration", self.max_acceleration),
                          ("max_deceleration", self.max_deceleration)):
            if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                raise ValueError(f"TwistLimiter {name} must be 3 finite numbers > 0, got {arr}")
        # the per-cycle arithmetic runs on Python floats (numpy scalar access
        # costs more than the arithmetic on three numbers)
        self._vmax = tuple(self.max_velocity.tolist())
        self._amax = tuple(self.max_acceleration.tolist())
        self._dmax = tuple(self.max_deceleration.tolist())
        #: the compiled closed forms, or None for the pure-Python path (hot_path)
        self._hot = hot_path.module()
        self._limits = np.concatenate((self.max_velocity, self.max_acceleration,
                                       self.max_deceleration))

    def limit_velocity(self, twist: np.ndarray) -> tuple[np.ndarray, float]:
        """Scale ``twist`` so every axis is within its speed limit.

        Returns (limited twist, scale in (0, 1]).
        """
        scale = 1.0
        for value, vmax in zip(twist.tolist(), self._vmax):
            mag = abs(value)
            if mag > vmax:
                scale = min(scale, vmax / mag)
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
            growing = abs(tgt[i]) > abs(prev[i]) and tgt[i] * prev[i] >= 0.0
            step = (self._amax[i] if growing else self._dmax[i]) * dt
            if change > step:
                scale = min(scale, step / change)
        if scale == 1.0:
            return np.array(tgt)
        return np.array([p + (g - p) * scale for g, p in zip(tgt, prev)])

    def limit(self, target: np.ndarray, previous: np.ndarray, dt: float) -> np.ndarray:
        """Speed limits, then acceleration limits, on ``target`` given the last output.

        Returns a new array (vx, vy, wz) [m/s, m/s, rad/s]; compiled when
        :mod:`holonomic_core.hot_path` selects it (the same numbers).
        """
        if self._hot is not None:
            return self._hot.limit_twist(target, previous, dt, self._limits)
        limited, _ = self.limit_velocity(target)
        return self.limit_acceleration(limited, previous, dt)


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
