"""Unwinding: the maneuver that brings every ranged joint back to the middle
of its range while the base keeps its heading and ends where it started.

Why a translation. Neither family can turn these joints with the base at
rest. A powered caster's steering rate is ``phi_dot = v sin(alpha - phi) / b
+ (...) wz`` (the PCV family's kinematics, eq. 7 of Holmberg & Khatib): with ``wz = 0`` and the
base translating at speed ``v`` in the direction ``alpha`` (base_link), the
steering angle tends to ``alpha`` (``alpha - phi`` decays; ``phi = alpha + pi``
is the unstable twin). The DDROT's turret rate is ``phi_dot = wz - wd`` with
``wd = v sin(alpha + phi) / b`` (the DDROT family's kinematics): at constant
heading the turret angle tends to ``-alpha``. In both, a *follower joint*
``j`` settles at ``q_j = sigma_j alpha + c_j (mod 2 pi)``, ``sigma_j = +-1``,
with the decay ``d(delta)/ds = -sin(delta) / b_j`` per metre travelled
(``tan(delta/2)`` falls by ``e`` every ``b_j``). Turning the direction of
travel by an angle ``A`` (unwrapped, several turns if need be) turns the
joint by ``sigma_j A``. :func:`follower_joints` finds ``sigma_j``, ``c_j`` and
``b_j`` from the model's own inverse kinematics, so any family whose ranged
joints follow the travel direction is served (a joint that does not -- a
swerve module's steering, which turns at rest -- is left alone and named).

The path (constant heading, odom frame) is made of *loops* through the
start ``P0``. One loop: an out leg from ``P0`` in the direction ``a`` (the
direction the joints point to, turned by LEAD towards the middle), a fillet
of radius ``rho``, the big circle of radius ``R`` about ``P0`` (sense ``s =
+-1``, as many extra full turns as needed), a fillet, and an in leg back to
``P0`` in the direction ``e``. The fillets are tangent to a leg and inside
the big circle, ``sin(delta) = rho / (R - rho)``, so the path is smooth and
closed; along it the direction of travel turns by ``s (pi + 2 delta +
span)`` with the big circle's polar span ``span = (s (e - a + pi) - 2
delta) mod 2 pi``, plus ``s 2 pi`` per extra turn (:func:`loop_turn`). A
joint that needs a turn ``N = sigma (middle - q)`` of the direction of
travel gets one loop of the sense of ``N`` ending in the direction ``e`` at
which the joints sit at their middle; when ``|N|`` is less than one loop's
turn, a figure of eight: a loop one way to a direction between, then one the
other way. :func:`plan_unwind` takes the shortest of these that never drives
a joint past its range (a joint turns monotonically within a loop, so the
loops' ends bound it) and refuses, saying why, when none does (joints wound
by different turns, which a translation turns alike; or a joint at the end
of a narrow range less than ``pi + 2 delta`` from its middle).

Sizes (``b`` the largest follower length: the caster offset, the DDROT's
turret offset): ``rho = max(1.5 b, R_MIN)``, ``R = 4 rho`` (``delta`` = 19.5
deg). On a fillet the joint lags the direction of travel by ``asin(b /
rho)`` = 42 deg; the in leg of ``(R - rho) cos(delta)`` = 4.2 b removes it to
``2 atan(tan(21 deg) e^-4.2)`` = 1 deg. Footprint: base_link stays within
``R = 6 b`` of the start (0.98 m for HAMR, b = 0.164 m; 0.20 m for the
XR4000, whose 5 cm smallest fillet sets it). A loop's length is ``2 (R -
rho) cos(delta) + 2 rho (pi / 2 + delta) + R (span + 2 pi k)``, at the
maneuver's speed ``v = min(0.25 m/s, half the linear speed limits, 0.4 rho
x the slowest ranged joint's speed limit)`` (on a fillet the joint turns at
``v / rho``); the duration is the length over ``v`` plus the ramps, the
final approach and the settling (:attr:`UnwindPlan.duration`). The plan
states both; the simulator tests (test_unwind_sim.py of the simulator package) check them.

:class:`UnwindManeuver` runs the path closed loop on the odometry, once per
control cycle: it projects the pose on the path, commands the tangent speed
(slowing to stop at ``P0``: ``min(v, sqrt(2 a d), 3 d)``, ``d`` the path
left), a lateral pull onto the path and a heading hold, so that the base
ends within millimetres of the start pose as the odometry measures it; it
ends only once the base has stayed there for SETTLE (at rest, not passing
through), so the motors' lag does not carry it on after the end. It can be
cancelled (a new command, disarm, a fault) and gives up when it
makes no progress for STALL_TIME or takes more than twice its planned time.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holonomic_core.se2 import rotate, wrap_angle

#: [m] smallest fillet radius (position control at the scale of centimetres)
R_MIN = 0.05
#: fillet radius over the joints' follower length b; big circle over fillet
FILLET, RING = 1.5, 4.0
#: [m/s] top speed of the maneuver
SPEED = 0.25
#: [rad] the joints count as unwound within this of the middle of their range
TOLERANCE = math.radians(2.0)
#: [rad] how far the out leg turns the joints towards the middle of their range
#: (a joint at the end of its range is not pushed past it by the path's corrections)
LEAD = math.radians(10.0)
#: [s] no progress along the path for this long: the maneuver gives up
STALL_TIME = 3.0
#: [1/s] gains: lateral pull onto the path, heading hold, final approach
LATERAL_GAIN, HEADING_GAIN, APPROACH_GAIN = 3.0, 3.0, 3.0
#: [m/s^2] deceleration towards the end of the path
END_DECELERATION = 0.5
#: [m], [rad] the base has arrived: distance to the start, heading error
ARRIVED, ARRIVED_YAW = 0.002, math.radians(0.2)
#: [s] the base must stay arrived this long (it has come to rest there, not
#: passed through on its way) before the maneuver ends
SETTLE = 0.3
#: [m] this near the start on the last leg the base is settling: no stall rule
SETTLING = 0.02


class UnwindError(ValueError):
    """The joints cannot be unwound from here (the message says why)."""


@dataclass(frozen=True)
class FollowerJoint:
    """A ranged joint that follows the direction of travel at constant heading.

    ``index``: its place in the model's joint arrays; ``sigma`` (+-1) and
    ``offset`` [rad]: it settles at ``q = sigma alpha + offset`` (mod 2 pi) for
    a translation in the direction ``alpha`` (base_link); ``length`` [m]: its
    decay length ``b`` (the caster or turret offset); ``lower``/``upper``/
    ``middle``: its range [rad]."""

    index: int
    name: str
    sigma: int
    offset: float
    length: float
    lower: float
    upper: float

    @property
    def middle(self) -> float:
        return 0.5 * (self.lower + self.upper)

    def direction(self, position: float) -> float:
        """The travel direction alpha [rad] (base_link) the joint at
        ``position`` is aligned with."""
        return wrap_angle(self.sigma * (position - self.offset))


def _rate(model, positions, index: int, alpha: float) -> float:
    """Joint ``index``'s rate [rad/s] for a unit-speed translation in the
    direction ``alpha`` (base_link) at ``positions``."""
    return float(model.inverse(positions, np.array([math.cos(alpha), math.sin(alpha), 0.0]))[index])


def _stable_direction(model, positions, index: int) -> tuple[float, float] | None:
    """The direction of travel at which joint ``index`` is at rest and
    returns there when disturbed, and its restoring rate ``-d rate/d q``
    [1/m]; None when its rate does not depend on the direction."""
    a, b = _rate(model, positions, index, 0.0), _rate(model, positions, index, math.pi / 2)
    if math.hypot(a, b) < 1e-9:
        return None
    # a cos(alpha) + b sin(alpha) = 0 at alpha0 and alpha0 + pi
    eps = 1e-6
    for alpha in (math.atan2(-a, b), math.atan2(-a, b) + math.pi):
        shifted = positions.copy()
        shifted[index] += eps
        slope = (_rate(model, shifted, index, alpha) - _rate(model, positions, index, alpha)) / eps
        if slope < 0.0:
            return wrap_angle(alpha), -slope
    return None


def follower_joints(model, positions) -> tuple[list[FollowerJoint], list[str]]:
    """The ranged joints of ``model`` that follow the travel direction (from
    its inverse kinematics at ``positions`` [rad]), and the names of the
    ranged joints that do not."""
    positions = np.asarray(positions, float)
    found, others = [], []
    for i, (name, lim) in enumerate(zip(model.joint_names, model.joint_limits)):
        if not lim.ranged:
            continue
        here = _stable_direction(model, positions, i)
        turned = positions.copy()
        turned[i] += 0.1
        there = _stable_direction(model, turned, i)
        if here is None or there is None:
            others.append(name)
            continue
        ratio = wrap_angle(there[0] - here[0]) / 0.1
        if abs(abs(ratio) - 1.0) > 0.05:
            others.append(name)
            continue
        sigma = 1 if ratio > 0 else -1
        found.append(FollowerJoint(i, name, sigma,
                                   wrap_angle(positions[i] - sigma * here[0]), 1.0 / here[1],
                                   lim.min_position, lim.max_position))
    return found, others


# -- the path ------------------------------------------------------------------------
@dataclass(frozen=True)
class Line:
    """A straight segment from ``start`` (x, y) [m] in direction ``heading`` [rad]."""

    start: tuple[float, float]
    heading: float
    length: float

    def point(self, s: float) -> tuple[float, float]:
        return (self.start[0] + s * math.cos(self.heading),
                self.start[1] + s * math.sin(self.heading))

    def tangent(self, s: float) -> float:
        return self.heading

    def project(self, p, s_guess: float) -> float:
        return (p[0] - self.start[0]) * math.cos(self.heading) + \
            (p[1] - self.start[1]) * math.sin(self.heading)


@dataclass(frozen=True)
class Arc:
    """A circular arc about ``centre`` (x, y) [m] of ``radius`` [m] from the
    polar angle ``angle0`` [rad], turning by ``sense`` (+1 CCW) over
    ``length`` [m] (may loop several times)."""

    centre: tuple[float, float]
    radius: float
    angle0: float
    sense: int
    length: float

    def _angle(self, s: float) -> float:
        return self.angle0 + self.sense * s / self.radius

    def point(self, s: float) -> tuple[float, float]:
        a = self._angle(s)
        return (self.centre[0] + self.radius * math.cos(a),
                self.centre[1] + self.radius * math.sin(a))

    def tangent(self, s: float) -> float:
        return self._angle(s) + self.sense * math.pi / 2

    def project(self, p, s_guess: float) -> float:
        # the polar angle of p, unwrapped next to the guess (loops)
        a = math.atan2(p[1] - self.centre[1], p[0] - self.centre[0])
        return s_guess + self.sense * wrap_angle(a - self._angle(s_guess)) * self.radius


@dataclass(frozen=True)
class UnwindPlan:
    """A planned unwind: the start pose (x, y, yaw) [m, m, rad] in odom, the
    path's segments, its speed [m/s], and what it does."""

    start: tuple[float, float, float]
    segments: tuple
    speed: float
    loops: int                        #: loops about the start
    fillet: float                     #: [m] fillet radius
    radius: float                     #: [m] radius of the big circle about the start
    footprint: float                  #: [m] farthest distance of base_link from the start
    joints: tuple[FollowerJoint, ...]
    expected: tuple[float, ...]       #: [rad] each follower joint's final position
    start_positions: tuple[float, ...]  #: [rad] each follower joint's position at the start

    @property
    def length(self) -> float:
        """[m] path length."""
        return sum(seg.length for seg in self.segments)

    @property
    def duration(self) -> float:
        """[s] expected duration: the path at speed, plus the ramps and the
        final approach (the speed over END_DECELERATION, 3 / APPROACH_GAIN)
        and the settling at the start (SETTLE)."""
        return (self.length / self.speed + self.speed / END_DECELERATION + 3.0 / APPROACH_GAIN
                + SETTLE)

    def describe(self) -> str:
        turns = ", ".join(f"{j.name} {q:+.2f} -> {e:+.2f} rad"
                          for j, q, e in zip(self.joints, self.start_positions, self.expected))
        return (f"unwinding: {self.loops} loop(s) of radius {self.radius:.2f} m about the start "
                f"(within {self.footprint:.2f} m of it), {self.length:.2f} m at "
                f"{self.speed:.2f} m/s, about {self.duration:.0f} s ({turns})")


def loop_turn(sense: int, start: float, end: float, delta: float) -> float:
    """The smallest turn [rad] (signed, ``sense``) of the direction of travel
    in one loop (:func:`loop_segments`) that leaves the start in the
    direction ``start`` and comes back in the direction ``end`` (rad, any
    frame): ``sense (pi + 2 delta + span)``, ``span`` the big arc's polar
    span; each extra full loop adds ``sense 2 pi``."""
    span = (sense * (end - start + math.pi) - 2.0 * delta) % (2.0 * math.pi)
    return sense * (math.pi + 2.0 * delta + span)


def loop_segments(origin, start: float, end: float, sense: int, extra: int,
                  fillet: float, radius: float) -> tuple:
    """One loop through ``origin`` (x, y) [m], odom directions ``start`` (out)
    and ``end`` (back in) [rad], ``sense`` +1 CCW / -1 CW, ``extra`` full
    loops more on the big circle: an out leg, a fillet of radius ``fillet``,
    the big circle of ``radius`` about the origin, a fillet, the in leg (the
    module docstring's loop)."""
    x0, y0 = origin
    ring = radius - fillet
    delta = math.asin(fillet / ring)
    leg = ring * math.cos(delta)
    w1, w2 = start, end + math.pi                 # the legs, from the origin outwards
    span = (sense * (w2 - w1) - 2.0 * delta) % (2.0 * math.pi)
    c1 = (x0 + ring * math.cos(w1 + sense * delta), y0 + ring * math.sin(w1 + sense * delta))
    c2 = (x0 + ring * math.cos(w2 - sense * delta), y0 + ring * math.sin(w2 - sense * delta))
    corner = fillet * (math.pi / 2 + delta)
    return (Line((x0, y0), w1, leg),
            Arc(c1, fillet, w1 - sense * math.pi / 2, sense, corner),
            Arc((x0, y0), radius, w1 + sense * delta, sense,
                radius * (span + 2.0 * math.pi * extra)),
            Arc(c2, fillet, w2 - sense * delta, sense, corner),
            Line((x0 + leg * math.cos(w2), y0 + leg * math.sin(w2)), end, leg))


def plan_unwind(model, positions, pose, max_speed=(math.inf, math.inf)) -> UnwindPlan | None:
    """The loops that bring every follower joint of ``model`` from joint
    ``positions`` [rad] to the middle of its range, starting and ending at
    ``pose`` (x, y, yaw) [m, m, rad] in odom; ``max_speed`` (vx, vy) [m/s]:
    the twist limits. None when every ranged joint is already within
    TOLERANCE of its middle. Raises :class:`UnwindError` when there is no
    ranged joint to unwind, or a plan would leave one off its middle (joints
    wound by different turns: one translation turns them all alike)."""
    positions = np.asarray(positions, float)
    joints, others = follower_joints(model, positions)
    if not joints:
        raise UnwindError("no ranged joint that follows the direction of travel"
                          + (f" ({', '.join(others)} turn at rest)" if others else
                             " (every joint is continuous: nothing to unwind)"))
    if all(abs(positions[j.index] - j.middle) <= TOLERANCE for j in joints):
        return None
    b = max(j.length for j in joints)
    fillet = max(FILLET * b, R_MIN)
    radius = RING * fillet
    delta = math.asin(fillet / (radius - fillet))
    slowest = min(model.joint_limits[j.index].max_velocity for j in joints)
    speed = min(SPEED, 0.5 * min(max_speed), 0.4 * fillet * slowest)
    ref = joints[0]
    # the out leg turns the joints a little towards the middle first: a joint
    # at the end of its range must not be pushed the width of a hair past it
    # by the path's corrections (the range guard would stop the base)
    q = positions[ref.index]
    lead = ref.sigma * math.copysign(LEAD, ref.middle - q)
    start = wrap_angle(ref.direction(q) + lead)
    final = ref.direction(ref.middle)
    # the direction's turn the reference joint needs after that (unwrapped)
    need = ref.sigma * (ref.middle - q) - lead
    plans = []
    # one loop of the sense of the need, with extra loops ...
    sense = 1 if need > 0 else -1
    first = loop_turn(sense, start, final, delta)
    extra = round((need - first) / (2.0 * math.pi) * sense)
    if extra >= 0:
        plans.append([(sense, start, final, extra)])
    # ... or a figure of eight (a need smaller than one loop's turn): a loop
    # one way to a direction between, then one the other way
    for sense in (1, -1):
        for k in range(12):
            middle = start + k * math.pi / 6
            turn1 = loop_turn(sense, start, middle, delta)
            turn2 = need - turn1
            least = loop_turn(-sense, middle, final, delta)
            extra2 = round((turn2 - least) / (2.0 * math.pi) * -sense)
            if extra2 >= 0:
                plans.append([(sense, start, middle, 0), (-sense, middle, final, extra2)])
    x0, y0, yaw = (float(v) for v in pose)

    def segments_of(loops):
        return tuple(seg for sense, a, e, extra in loops
                     for seg in loop_segments((x0, y0), a + yaw, e + yaw, sense, extra,
                                              fillet, radius))

    swings = [wrap_angle(start - j.direction(positions[j.index])) for j in joints]

    def joint_path(loops):
        """Each follower joint's position after the lead and after each loop."""
        out, turned = [], 0.0
        for sense, a, e, extra in [(0, 0.0, 0.0, 0)] + loops:
            if sense:
                turned += loop_turn(sense, a, e, delta) + sense * 2.0 * math.pi * extra
            out.append([positions[j.index] + j.sigma * (w + turned)
                        for j, w in zip(joints, swings)])
        return out

    def inside(loops):
        # a joint turns monotonically within a loop: its ends bound it
        return all(j.lower - 1e-9 <= q <= j.upper + 1e-9 or
                   abs(q - j.middle) < abs(q0 - j.middle)     # already outside: coming back
                   for qs in joint_path(loops)
                   for j, q, q0 in zip(joints, qs, (positions[j.index] for j in joints)))

    valid = [ls for ls in plans if inside(ls)]
    if not valid:
        raise UnwindError(
            "every way round would drive a joint past its range (a loop turns the joints by at "
            f"least {math.degrees(math.pi + 2 * delta):.0f} deg: a joint nearer its middle "
            "than that at the end of a narrow range cannot be unwound by loops)")
    loops = min(valid, key=lambda ls: sum(seg.length for seg in segments_of(ls)))
    ends = [float(q) for q in joint_path(loops)[-1]]
    worst = max(abs(e - j.middle) for e, j in zip(ends, joints))
    if worst > math.radians(5.0):
        wound = ", ".join(f"{j.name} {positions[j.index]:+.2f} rad" for j in joints)
        raise UnwindError(f"no translation brings every ranged joint to its middle ({wound}): "
                          "joints wound by different turns turn together in a translation")
    count = sum(1 + extra for _, _, _, extra in loops)
    return UnwindPlan((x0, y0, yaw), segments_of(loops), speed, count, fillet, radius,
                      radius, tuple(joints), tuple(ends),
                      tuple(float(positions[j.index]) for j in joints))


class UnwindManeuver:
    """Runs an :class:`UnwindPlan` closed loop on the odometry.

    :meth:`target` (once a control cycle, loop thread) gives the body twist
    (vx, vy, wz) [m/s, m/s, rad/s] to command, or None when the maneuver is
    over; :attr:`result` then says how it ended. :meth:`cancel` may be
    called from any thread.
    """

    def __init__(self, plan: UnwindPlan, now: float):
        self.plan = plan
        self._segment = 0
        self._s = 0.0                      # along the current segment [m]
        self._started = now
        self._progress_at = (0.0, now)     # (path done [m], clock [s]) of the last progress
        self._arrived_at: float | None = None  # clock [s] since when the base is arrived
        self._cancel: str | None = None
        self._result: tuple[bool, str] | None = None

    @property
    def result(self) -> tuple[bool, str] | None:
        """None while it runs; then (success, text)."""
        if self._result is None and self._cancel is not None:
            return False, f"unwind cancelled: {self._cancel}"
        return self._result

    def cancel(self, reason: str) -> None:
        """Stop the maneuver (any thread): no more twist from it, the base
        ramps to rest under the limits."""
        if self._result is None and self._cancel is None:
            self._cancel = reason

    def progress(self) -> float:
        """Path done [m]."""
        segs = self.plan.segments
        return sum(seg.length for seg in segs[:self._segment]) + max(0.0, self._s)

    def status(self) -> str:
        if self.result is not None:
            return self.result[1]
        return (f"running: {self.progress():.2f} of {self.plan.length:.2f} m "
                f"({self.plan.loops} loop(s))")

    def _finish(self, success: bool, text: str) -> None:
        self._result = (success, text)

    def target(self, pose, positions, now: float):
        """The twist for this cycle at odometry ``pose`` (x, y, yaw) and joint
        ``positions``, or None (then see :attr:`result`)."""
        if self.result is not None:
            return None
        plan = self.plan
        if now - self._started > 2.0 * plan.duration + 10.0:
            self._finish(False, f"unwind gave up after {now - self._started:.0f} s "
                                f"(planned {plan.duration:.0f} s)")
            return None
        p = (float(pose[0]), float(pose[1]))
        segs = plan.segments
        # follow the projection along the path, moving on at each segment's end
        while True:
            seg = segs[self._segment]
            self._s = seg.project(p, self._s)
            if self._s < seg.length or self._segment == len(segs) - 1:
                break
            self._segment += 1
            self._s = 0.0
        seg = segs[self._segment]
        s = min(max(self._s, 0.0), seg.length)
        done = self.progress()
        x0, y0, yaw0 = plan.start
        yaw_error = wrap_angle(yaw0 - float(pose[2]))
        left = plan.length - done
        end_distance = math.hypot(p[0] - x0, p[1] - y0)
        last = self._segment == len(segs) - 1
        settling = last and end_distance <= SETTLING
        if done > self._progress_at[0] + 0.001 or settling:
            self._progress_at = (done, now)
        elif now - self._progress_at[1] > STALL_TIME:
            self._finish(False, f"unwind stalled at {done:.2f} of {plan.length:.2f} m "
                                "(a joint at its range, or the base blocked)")
            return None
        arrived = last and (left <= ARRIVED or self._s >= seg.length) \
            and end_distance <= ARRIVED and abs(yaw_error) <= ARRIVED_YAW
        if not arrived:
            self._arrived_at = None
        elif self._arrived_at is None:
            self._arrived_at = now
        elif now - self._arrived_at >= SETTLE:
            final = [float(positions[j.index]) - j.middle for j in plan.joints]
            self._finish(True, "unwound: " + ", ".join(
                f"{j.name} {math.degrees(e):+.1f} deg from the middle"
                for j, e in zip(plan.joints, final))
                + f"; the base {1000.0 * end_distance:.1f} mm and "
                  f"{math.degrees(abs(yaw_error)):.2f} deg from its start (odometry)")
            return None
        heading = seg.tangent(s)
        ref = seg.point(s)
        ex, ey = p[0] - ref[0], p[1] - ref[1]
        lateral = -math.sin(heading) * ex + math.cos(heading) * ey
        if last:
            left = max(0.0, seg.length - self._s)
        speed = min(plan.speed, math.sqrt(2.0 * END_DECELERATION * left), APPROACH_GAIN * left)
        # the pull onto the path scales with the speed near the end, so that
        # the direction of travel (which the joints follow) stays the path's
        pull = -LATERAL_GAIN * lateral * min(1.0, speed / plan.speed + 0.2)
        pull = max(-0.5 * plan.speed, min(0.5 * plan.speed, pull))
        if last and self._s > seg.length:
            speed = -APPROACH_GAIN * (self._s - seg.length)     # past the start: back up
        vx_w = speed * math.cos(heading) - pull * math.sin(heading)
        vy_w = speed * math.sin(heading) + pull * math.cos(heading)
        vx, vy = rotate(vx_w, vy_w, -float(pose[2]))
        wz = max(-1.0, min(1.0, HEADING_GAIN * yaw_error))
        return np.array([vx, vy, wz])


def begin(model, positions, pose, max_speed, now: float
          ) -> tuple[UnwindManeuver | None, tuple[bool, str]]:
    """Plan and start an unwind (see :func:`plan_unwind`): the maneuver (None
    when there is nothing to do or it cannot be done) and the answer to the
    request, ``(success, text)``."""
    if positions is None:
        return None, (False, "no joint reading yet")
    try:
        plan = plan_unwind(model, positions, pose, max_speed)
    except UnwindError as exc:
        return None, (False, f"cannot unwind: {exc}")
    if plan is None:
        return None, (True, "nothing to unwind: every ranged joint is within "
                            f"{math.degrees(TOLERANCE):g} deg of the middle of its range")
    return UnwindManeuver(plan, now), (True, plan.describe())
