"""Plausibility checks of joint readings: what a driver cannot see itself.

A driver reports what its devices say. Some failures only show in the
numbers: an encoder glitch (a velocity spike of thousands of rad/s, a
position that jumps), a device that keeps answering with a frozen sample, or
a motor that cannot follow its command because it is saturated or blocked.
:class:`ReadingMonitor` checks every reading before odometry or control uses
it and returns a message naming the joint when one is implausible; the
controller then faults, stops the base and keeps the bad sample out of the
odometry -- or, for an isolated invalid value (a :class:`Glitch`), drops it
as ``safety.glitch_policy`` says (:mod:`holonomic_core.glitch_policy`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from holonomic_core import hot_path
from holonomic_core.glitch_policy import Glitch


@dataclass(frozen=True)
class MonitorLimits:
    """Thresholds of :class:`ReadingMonitor`.

    ``velocity_factor`` [-]: a measured joint speed above this multiple of the
    joint's speed limit is a glitch (position increments are held to the same
    bound over the time between samples: at least the period, or the last
    stall of the control loop); ``reading_timeout`` [s]: readings whose stamp
    has not advanced for this long are frozen; ``tracking_error`` [-]: a joint whose measured speed
    differs from its command by more than this fraction of its speed limit ...
    ``tracking_timeout`` [s]: ... for this long cannot follow (0 disables).
    """

    # no defaults here: the controller's ParamSpec schema (safety.*) has them
    velocity_factor: float
    reading_timeout: float
    tracking_error: float
    tracking_timeout: float


class ReadingMonitor:
    """Checks a stream of JointReadings; one per control cycle.

    ``joint_names`` and ``max_velocity`` [rad/s] in joint order;
    ``period`` [s]: the control period.
    """

    #: checks over which a stall of the caller's loop widens the glitch bound
    STALL_MEMORY = 4

    def __init__(self, joint_names, max_velocity, period: float, limits: MonitorLimits):
        self.joint_names = tuple(joint_names)
        self.max_velocity = np.asarray(max_velocity, float)
        self.period = float(period)
        self.limits = limits
        # per-cycle checks run on Python floats (cheaper than numpy on n <= 16)
        self._bound = (limits.velocity_factor * self.max_velocity).tolist()
        self._tracking_bound = (limits.tracking_error * self.max_velocity).tolist()
        # the compiled per-joint tests (hot_path); on a failure the loops
        # below find it again and word the message
        self._hot = hot_path.module()
        self._bound_array = limits.velocity_factor * self.max_velocity
        self.reset()

    def reset(self) -> None:
        """Forget the reference sample (after a fault is cleared, or re-arming)."""
        self._last_positions: list[float] | None = None
        self._last_stamp: float | None = None
        self._stamp_changed_at: float | None = None
        self._tracking_since: float | None = None
        self._last_check: float | None = None
        self._gaps: deque[float] = deque(maxlen=self.STALL_MEMORY)

    def check(self, reading, now: float, command: np.ndarray | None = None) -> str | None:
        """Return why ``reading`` is implausible, or None.

        ``now`` [s]: the controller's clock; ``command`` [rad/s]: the joint
        velocities the driver was last told to follow (None when disarmed).
        An implausible reading does not become the reference for the next one.
        """
        n = len(self.joint_names)
        if self._last_check is not None:
            self._gaps.append(now - self._last_check)
        self._last_check = now
        positions = np.asarray(reading.positions, float)
        velocities = np.asarray(reading.velocities, float)
        if positions.shape != (n,) or velocities.shape != (n,):
            return (f"driver returned {positions.shape[0] if positions.ndim else 0} positions and "
                    f"{velocities.shape[0] if velocities.ndim else 0} velocities for {n} joints")
        pos, vel = positions.tolist(), velocities.tolist()
        last = self._last_positions
        dt = None if last is None else reading.stamp - self._last_stamp
        checked = self._hot is not None and self._hot.reading_plausible(
            positions, velocities, self._bound_array,
            last if dt is not None and dt >= 0.0 else None,
            self._span(dt) if dt is not None and dt >= 0.0 else 0.0)
        if not checked:
            problem = self._check_joints(pos, vel, dt)
            if problem is not None:
                return problem
        if last is not None:
            if dt < 0.0:
                # the clock restarted (simulation reset): a new reference
                self._accept(pos, reading.stamp, now)
                return None
            if dt == 0.0:
                frozen = now - self._stamp_changed_at
                if self.limits.reading_timeout > 0.0 and frozen > self.limits.reading_timeout:
                    return f"joint readings stopped updating {frozen:.3f} s ago"
                return None
        problem = self._check_tracking(vel, now, command)
        self._accept(pos, reading.stamp, now)
        return problem

    def _span(self, dt: float) -> float:
        """The time [s] over which a position may move by bound x span."""
        # The bound holds over the time between the device's samples,
        # which the stamps understate when the host stamps samples late:
        # after a stall of this loop, a sample taken before the stall can
        # be stamped after it (e.g. a TPDO handled after the next SYNC),
        # and the next one, a catch-up cycle later, then carries the
        # whole stall's motion over a fraction of a period. So the span
        # is at least the period and the longest gap between the last
        # few checks (a stall widens the bound for STALL_MEMORY cycles).
        return max(dt, self.period, max(self._gaps, default=0.0))

    def _check_joints(self, pos: list, vel: list, dt: float | None) -> str | None:
        """The per-joint tests (finite, speed, position jump when ``dt`` >= 0);
        a failure is a :class:`Glitch` (the glitch policy may drop it)."""
        n = len(self.joint_names)
        isfinite = math.isfinite
        for i in range(n):
            if not isfinite(pos[i]):
                return Glitch(f"{self.joint_names[i]}: non-finite position reading ({pos[i]})",
                              self.joint_names[i])
            if not isfinite(vel[i]):
                return Glitch(f"{self.joint_names[i]}: non-finite velocity reading ({vel[i]})",
                              self.joint_names[i])
        bound = self._bound
        for i in range(n):
            if abs(vel[i]) > bound[i]:
                return Glitch(f"{self.joint_names[i]}: velocity reading {vel[i]:.4g} rad/s is "
                              f"over {self.limits.velocity_factor:g}x its limit "
                              f"({self.max_velocity[i]:g} rad/s): encoder glitch",
                              self.joint_names[i])
        if dt is not None and dt >= 0.0:
            span = self._span(dt)
            last = self._last_positions
            for i in range(n):
                jump = abs(pos[i] - last[i])
                if jump > bound[i] * span + 1e-6:
                    return Glitch(f"{self.joint_names[i]}: position jumped by {jump:.4g} rad "
                                  f"in {dt:.4g} s: encoder glitch", self.joint_names[i])
        return None

    def _accept(self, positions: list, stamp, now) -> None:
        self._last_positions = positions
        self._last_stamp = stamp
        self._stamp_changed_at = now

    def _check_tracking(self, velocities, now, command) -> str | None:
        if command is None or self.limits.tracking_timeout <= 0.0:
            self._tracking_since = None
            return None
        excess = [abs(c - v) - b
                  for c, v, b in zip(command.tolist(), velocities, self._tracking_bound)]
        worst = max(excess)
        if not worst > 0.0:
            self._tracking_since = None
            return None
        if self._tracking_since is None:
            self._tracking_since = now
            return None
        if now - self._tracking_since < self.limits.tracking_timeout:
            return None
        i = excess.index(worst)
        return (f"{self.joint_names[i]}: cannot follow its command ({command[i]:.3g} rad/s "
                f"commanded, {velocities[i]:.3g} rad/s measured for "
                f"{now - self._tracking_since:.2f} s): motor saturated or blocked")
