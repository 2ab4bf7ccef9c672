"""Properties of the one twist limiter (speed norm, per-axis speeds,
accelerations, jerk), over generated commands (hypothesis, derandomized).

Each property is what a user relies on: the direction of the command is
kept, zero stays zero, a command within every limit passes unchanged, every
limit is respected, and the jerk-limited command reaches a constant target
without overshoot. Both paths (pure and compiled) are exercised: the limiter
built here uses whichever hot_path selects, and test_hot_path checks they are
bitwise equal."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from holonomic_core.limits import TwistLimiter, jerk_arrival_bound

DT = 0.005
VMAX = (1.2, 0.8, 3.0)
AMAX = (1.0, 0.7, 6.0)
DMAX = (2.0, 1.5, 9.0)
SPEED = 1.0
JERK = (5.0, 4.0, 40.0)

PLAIN = TwistLimiter(VMAX, AMAX, DMAX, max_speed=SPEED)
JERKY = TwistLimiter(VMAX, AMAX, DMAX, max_speed=SPEED, max_jerk=JERK)

# sub-nanometre components are zero (their squares underflow the checks' dot products)
component = st.floats(-3.0, 3.0, allow_nan=False).map(lambda v: 0.0 if abs(v) < 1e-9 else v)
twists = st.tuples(component, component, component).map(np.array)
SETTINGS = settings(max_examples=400, derandomize=True, deadline=None)


def within(limiter, twist, tol=1e-12):
    return (np.all(np.abs(twist) <= np.array(VMAX) + tol)
            and math.hypot(twist[0], twist[1]) <= SPEED + tol)


@SETTINGS
@given(twists)
def test_the_speed_limits_keep_the_direction_and_bound_norm_and_axes(target):
    limited, scale = PLAIN.limit_velocity(target)
    # one scale for all axes: limited = scale x target
    assert np.allclose(limited, scale * target, rtol=0, atol=1e-15)
    assert 0.0 < scale <= 1.0
    assert within(PLAIN, limited)
    # and as large as the tightest limit allows: some limit is reached
    if scale < 1.0:
        reached = [abs(v) / m for v, m in zip(limited, VMAX)]
        reached.append(math.hypot(limited[0], limited[1]) / SPEED)
        assert max(reached) == pytest.approx(1.0, abs=1e-12)


def test_a_diagonal_is_no_faster_than_a_straight_line():
    # 0.8 m/s on x and on y is within both axes' limits, but its norm is
    # 0.8 sqrt(2) = 1.131 m/s > 1.0: scaled by 1 / 1.131 to (0.707, 0.707)
    limited, scale = PLAIN.limit_velocity(np.array([0.8, 0.8, 0.0]))
    assert scale == pytest.approx(1.0 / (0.8 * math.sqrt(2.0)))
    assert limited == pytest.approx([math.sqrt(0.5), math.sqrt(0.5), 0.0])


@pytest.mark.parametrize("limiter", [PLAIN, JERKY], ids=["accel", "jerk"])
def test_zero_stays_zero(limiter):
    zero = np.zeros(3)
    for _ in range(10):
        out = limiter.limit(zero, zero, DT, zero)
        assert np.array_equal(out, zero) and not np.signbit(out).any() or np.all(out == 0.0)


@SETTINGS
@given(twists, twists)
def test_every_step_respects_the_speed_and_acceleration_limits(target, previous):
    previous, _ = PLAIN.limit_velocity(previous)
    out = PLAIN.limit(target, previous, DT)
    assert within(PLAIN, out, 1e-9)
    step = np.abs(out - previous)
    assert np.all(step <= np.maximum(AMAX, DMAX) * DT + 1e-12)
    # the change is along the (speed-limited) target's line from previous
    wanted = PLAIN.limit_velocity(target)[0] - previous
    if np.any(wanted):
        k = np.dot(out - previous, wanted) / np.dot(wanted, wanted)
        assert np.allclose(out - previous, k * wanted, atol=1e-12) and -1e-12 <= k <= 1 + 1e-12


@SETTINGS
@given(twists, st.floats(0.0, 1.0), st.floats(0.0, 1.0))
def test_a_command_within_every_limit_passes_unchanged(previous, fraction, jerk_fraction):
    # inside the speed limits (a limited twist can land one ulp above a limit)
    previous = PLAIN.limit_velocity(previous)[0] * 0.999
    # a change of at most the smaller of the acceleration limits (times dt),
    # in a direction that the norm limit accepts: previous scaled towards 0
    change = -previous * min(1.0, fraction * min(AMAX) * DT / max(np.abs(previous).max(), 1e-9))
    target = previous + change
    assert np.array_equal(PLAIN.limit(target, previous, DT), target)
    # with jerk limits: a change whose acceleration is within one jerk step
    # of the last one, and small enough to stop after it (|d| <= j dt^2)
    small = change * min(1.0, jerk_fraction * min(JERK) * DT * DT
                         / max(np.abs(change).max(), 1e-300))
    acceleration = small / DT
    assert np.array_equal(JERKY.limit(previous + small, previous, DT, acceleration),
                          previous + small)


def ramp(limiter, target, previous, steps):
    """Run the limiter on a constant target; the twists and accelerations."""
    out, acc = [previous], [np.zeros(3)]
    for _ in range(steps):
        nxt = limiter.limit(target, out[-1], DT, acc[-1])
        acc.append((nxt - out[-1]) / DT)
        out.append(nxt)
    return np.array(out), np.array(acc)


@settings(max_examples=150, derandomize=True, deadline=None)
@given(twists, twists)
def test_the_jerk_limited_command_reaches_the_target_along_its_line_without_overshoot(
        target, previous):
    previous, _ = JERKY.limit_velocity(previous)
    goal, _ = JERKY.limit_velocity(target)
    # the slowest axis: 2.4 m/s at 0.7 m/s^2 with 4 m/s^3 takes 3.6 s: 1000 steps do
    out, acc = ramp(JERKY, target, previous, 1000)
    assert np.array_equal(out[-1], goal)                  # reached, exactly
    assert np.all(acc[-1] == 0.0)                         # and stopped accelerating
    gap = goal - previous
    progress = (out - previous) @ gap / max(gap @ gap, 1e-300)
    # on the straight line from previous to the goal (the direction of the
    # change is kept), moving one way, never past the goal
    assert np.allclose(out - previous, np.outer(progress, gap), atol=1e-9)
    assert np.all(np.diff(progress) >= -1e-12) and progress.max() <= 1.0 + 1e-12
    # every limit respected on every step
    assert all(within(JERKY, o, 1e-9) for o in out)
    assert np.all(np.abs(acc) <= np.maximum(AMAX, DMAX) + 1e-9)
    assert np.all(np.abs(np.diff(acc, axis=0)) <= np.array(JERK) * DT + 1e-7)


def test_a_jerk_limit_lengthens_a_stop_by_the_ramp_of_the_deceleration():
    # 1.0 m/s on x, stop: deceleration 2 m/s^2 reached after 2 / 5 = 0.4 s of
    # ramp, so the stop takes about v / d + d / j = 0.5 + 0.4 = 0.9 s (0.5 s
    # without the jerk limit) and the distance v^2 / (2 d) + v d / (2 j) =
    # 0.25 + 0.2 = 0.45 m (0.25 m) -- what a command timeout then costs
    start = np.array([1.0, 0.0, 0.0])
    out, _ = ramp(JERKY, np.zeros(3), start, 400)
    stopped = int(np.argmax(np.all(out == 0.0, axis=1)))
    assert stopped * DT == pytest.approx(0.9, abs=0.02)
    assert out[:stopped, 0].sum() * DT == pytest.approx(0.45, abs=0.01)
    plain, _ = ramp(PLAIN, np.zeros(3), start, 400)
    assert int(np.argmax(np.all(plain == 0.0, axis=1))) * DT == pytest.approx(0.5, abs=0.006)


@pytest.mark.parametrize("gap,jerk,want", [
    (0.0, 1.0, 0.0),
    # n = 0: gap below one jerk step: one step closes it, a' = gap
    (0.5, 1.0, 0.5),
    # gap = jerk n (n + 1) / 2 for n = 2: a' = 2 jerk (then jerk, then 0)
    (3.0, 1.0, 2.0),
    # n = 2 (3 <= 4 < 6): a' = (4 + 3) / 3
    (4.0, 1.0, 7.0 / 3.0),
])
def test_the_arrival_bound_by_hand(gap, jerk, want):
    assert jerk_arrival_bound(gap, jerk) == pytest.approx(want)


@pytest.mark.parametrize("bad", [dict(max_speed=0.0), dict(max_speed=-1.0),
                                 dict(max_jerk=(1.0, 0.0, 1.0)),
                                 dict(max_jerk=(1.0, math.nan, 1.0))])
def test_limits_that_are_not_positive_are_refused(bad):
    with pytest.raises(ValueError, match="TwistLimiter max_"):
        TwistLimiter(VMAX, AMAX, DMAX, **bad)
