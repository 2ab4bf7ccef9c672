"""Joint position ranges: the schema keys and the guard that keeps every
ranged joint inside its range.

Steering joints of powered casters and the DDROT's turret often carry
cables or a limited slip ring: ``joints.NAME.min_position`` /
``max_position`` [rad] give such a joint its range (both absent: the joint
is continuous). Wheel joints roll without end and take no range.

:class:`JointRangeGuard` runs once per control cycle, after the twist
limiter and the joint-rate saturation. The joint rates are linear in the
twist at the measured joint positions (``q_dot = A(q) x``), so scaling the
twist by ``s`` scales every joint rate by ``s``: the base keeps its direction
and only slows down. For each ranged joint moving towards an end of its
range, with ``d`` [rad] left to that end, the guard takes the largest ``s``
that still lets the joint stop in time:

* for one more cycle (the horizon ``h``, the next decision plus the
  reading's age) it keeps moving at ``s |q_dot|``;
* then the twist limiter brings the base to rest in ``s T``, ``T = max_i
  |x_i| / d_i`` (``d_i`` the per-axis deceleration limits, the same uniform
  ramp the limiter makes), during which the joint travels ``s^2 |q_dot| T / 2``;
  where a joint has its own deceleration limit ``a``, it needs at least
  ``s^2 q_dot^2 / (2 a)``.

So ``s |q_dot| h + s^2 K <= d`` with ``K = max(|q_dot| T / 2, q_dot^2 / (2 a))``,
whose root is ``s = (-|q_dot| h + sqrt(q_dot^2 h^2 + 4 K d)) / (2 K)``. The
twist is scaled by the smallest ``s`` of all joints (never above 1). A joint
moving away from the end it is near (or back into its range after an
overshoot) is never slowed. As the joint nears its end ``d`` and with it
``s`` fall to zero: the motion that would wind the joint further stops, and
the joint stops at its end.
"""

from __future__ import annotations

import math
from typing import Mapping

import numpy as np

from holonomic_core.schema import ConfigError, ParamSpec

#: [rad] largest |min_position|, |max_position|: three turns either way
RANGE_LIMIT = 6.0 * math.pi
#: [rad] narrowest range: room for the stopping distance and for the unwind
#: maneuver's tolerance around the middle
MIN_SPAN = 0.5


def range_specs(joint: str) -> list[ParamSpec]:
    """Schema of ``joints.<joint>.min_position`` / ``max_position``."""
    return [
        ParamSpec(f"joints.{joint}.{end}_position", "double",
                  f"{word} end of {joint}'s range [rad] (steering or turret joints with "
                  "cables: the controller slows any motion so that the joint stops at its "
                  "range, holonomic-ctl unwind brings it back to the middle); unset with "
                  f"{other}_position unset: continuous.",
                  minimum=-RANGE_LIMIT, maximum=RANGE_LIMIT, optional=True)
        for end, word, other in (("min", "Lower", "max"), ("max", "Upper", "min"))]


def checked_range(joint: str, values: Mapping[str, object]) -> tuple[float | None, float | None]:
    """``(min_position, max_position)`` of ``joint`` from validated flat
    ``values``: both None (continuous) or a valid range; raises
    :class:`ConfigError` naming the key otherwise."""
    low = values.get(f"joints.{joint}.min_position")
    high = values.get(f"joints.{joint}.max_position")
    if low is None and high is None:
        return None, None
    if joint.endswith("wheel_joint"):
        key = f"joints.{joint}.{'min' if low is not None else 'max'}_position"
        raise ConfigError(key, low if low is not None else high,
                          "unset (a wheel joint rolls without end: it is continuous)")
    if low is None or high is None:
        missing = "min" if low is None else "max"
        raise ConfigError(f"joints.{joint}.{missing}_position", "<missing>",
                          f"a number: a range needs both ends (or neither: continuous)")
    if high - low < MIN_SPAN:
        raise ConfigError(f"joints.{joint}.max_position", high,
                          f"at least min_position + {MIN_SPAN:g} rad = {low + MIN_SPAN:g} "
                          "(a narrower range leaves no room to stop and to unwind)")
    return float(low), float(high)


class JointRangeGuard:
    """Scales the commanded twist so that no ranged joint passes its range.

    ``names``: every joint (the model's order); ``lower`` / ``upper`` [rad]:
    per joint, NaN for a continuous joint; ``base_deceleration``: the twist
    limiter's per-axis deceleration limits (vx, vy, wz) [m/s^2, m/s^2,
    rad/s^2]; ``joint_deceleration`` [rad/s^2]: per joint (inf: no limit of
    its own), default none; ``horizon`` [s]: how long a command lasts before
    the next decision can change it (a cycle, plus the reading's age).
    """

    def __init__(self, names, lower, upper, base_deceleration, horizon: float,
                 joint_deceleration=None):
        lower, upper = np.asarray(lower, float), np.asarray(upper, float)
        self.names = tuple(names)
        self.indices = [i for i in range(len(self.names)) if not math.isnan(lower[i])]
        self.lower = lower
        self.upper = upper
        decel = np.asarray(base_deceleration, float)
        if decel.shape != (3,) or np.any(decel <= 0) or not np.all(np.isfinite(decel)):
            raise ValueError(f"base_deceleration must be 3 numbers > 0, got {decel}")
        self._base_decel = tuple(decel.tolist())
        self._joint_decel = (np.full(len(self.names), math.inf) if joint_deceleration is None
                             else np.asarray(joint_deceleration, float)).tolist()
        self.horizon = float(horizon)
        self._bounds = [(i, float(lower[i]), float(upper[i])) for i in self.indices]
        #: per ranged joint: the clock time [s] it was last slowed (-inf: never)
        self._last_limited = {self.names[i]: -math.inf for i in self.indices}

    @classmethod
    def from_model(cls, model, base_deceleration, horizon: float,
                   joint_deceleration=None) -> "JointRangeGuard | None":
        """The guard of ``model``'s ranged joints, None when all are continuous;
        ``joint_deceleration`` [rad/s^2] per joint (None: unbounded)."""
        limits = model.joint_limits
        if not any(j.ranged for j in limits):
            return None
        nan = math.nan
        return cls(model.joint_names,
                   [nan if j.min_position is None else j.min_position for j in limits],
                   [nan if j.max_position is None else j.max_position for j in limits],
                   base_deceleration, horizon, joint_deceleration)

    def stop_time(self, twist) -> float:
        """[s] the twist limiter needs to bring ``twist`` to rest."""
        return max(abs(v) / d for v, d in zip(twist, self._base_decel))

    def scale(self, positions, rates, twist, now: float) -> float:
        """Factor in [0, 1] for the cycle's ``twist`` (vx, vy, wz) and its
        joint ``rates`` [rad/s] at joint ``positions`` [rad]: 1 when no
        ranged joint needs slowing. Records which joints were slowed at
        clock time ``now`` [s] (see :meth:`limited`)."""
        q, qd = positions.tolist(), rates.tolist()
        stop = self.stop_time(twist.tolist())
        scale = 1.0
        for i, low, high in self._bounds:
            rate = qd[i]
            if rate > 0.0:
                left = high - q[i]
            elif rate < 0.0:
                left = q[i] - low
            else:
                continue
            speed = abs(rate)
            allowed = self._allowed_scale(speed, max(left, 0.0), stop, self._joint_decel[i])
            if allowed < 1.0:
                self._last_limited[self.names[i]] = now
                scale = min(scale, allowed)
        return scale

    def _allowed_scale(self, speed: float, left: float, stop: float, decel: float) -> float:
        """Largest s <= 1 with s speed h + s^2 K <= left (module docstring)."""
        k = 0.5 * speed * stop
        if decel < math.inf:
            k = max(k, 0.5 * speed * speed / decel)
        linear = speed * self.horizon
        if linear + k <= left:
            return 1.0
        if k <= 0.0:
            return left / linear
        return (-linear + math.sqrt(linear * linear + 4.0 * k * left)) / (2.0 * k)

    def limited(self, now: float, within: float) -> tuple[str, ...]:
        """The joints slowed at their range in the ``within`` [s] before ``now``."""
        return tuple(name for name, t in self._last_limited.items() if now - t <= within)

    def reset(self) -> None:
        """Forget which joints were slowed (after arming)."""
        for name in self._last_limited:
            self._last_limited[name] = -math.inf
