"""The SE(2) module: every pose operation, against values derived by hand."""

from __future__ import annotations

import math

import numpy as np
import pytest

from holonomic_core import se2

PI = math.pi


@pytest.mark.parametrize("angle,wrapped", [
    (0.0, 0.0), (3 * PI / 2, -PI / 2), (-3 * PI / 2, PI / 2), (7 * PI, PI), (2 * PI + 0.1, 0.1),
    (-0.1 - 4 * PI, -0.1)])
def test_wrap_angle_maps_into_minus_pi_pi(angle, wrapped):
    assert abs(se2.wrap_angle(angle)) <= PI
    assert math.cos(se2.wrap_angle(angle) - wrapped) == pytest.approx(1.0, abs=1e-12)
    assert se2.wrap_angle(angle) == pytest.approx(wrapped, abs=1e-12) or \
        abs(wrapped) == pytest.approx(PI)


def test_wrap_angles_is_the_elementwise_wrap():
    # pi + 0.5 -> -pi + 0.5; -pi - 0.5 -> pi - 0.5; 4 pi + 1 -> 1
    out = se2.wrap_angles([PI + 0.5, -PI - 0.5, 4 * PI + 1.0, 0.25])
    assert out == pytest.approx([-PI + 0.5, PI - 0.5, 1.0, 0.25], abs=1e-12)


def test_rotate_turns_counter_clockwise():
    # (1, 0) by +90 deg -> (0, 1); (1, 2) by 180 deg -> (-1, -2)
    assert se2.rotate(1.0, 0.0, PI / 2) == pytest.approx((0.0, 1.0), abs=1e-15)
    assert se2.rotate(1.0, 2.0, PI) == pytest.approx((-1.0, -2.0), abs=1e-15)


def test_compose_puts_a_body_pose_into_the_parent_frame():
    # a frame at (1, 2) heading +90 deg; a point 1 m ahead of it (its +x) is
    # at (1, 3) in the parent, heading 90 + 90 = 180 deg
    assert se2.compose((1.0, 2.0, PI / 2), (1.0, 0.0, PI / 2)) == \
        pytest.approx([1.0, 3.0, PI], abs=1e-12)
    # headings wrap: 170 + 20 deg = -170 deg
    assert se2.compose((0.0, 0.0, math.radians(170)), (0.0, 0.0, math.radians(20)))[2] == \
        pytest.approx(math.radians(-170), abs=1e-12)


def test_relative_pose_is_the_inverse_of_compose():
    # seen from (1, 2, +90 deg), the point (1, 3) heading 180 deg is 1 m
    # ahead (+x), turned by +90 deg
    assert se2.relative_pose((1.0, 2.0, PI / 2), (1.0, 3.0, PI)) == \
        pytest.approx([1.0, 0.0, PI / 2], abs=1e-12)
    # and (2, 2) is on its right: y = -1
    assert se2.relative_pose((1.0, 2.0, PI / 2), (2.0, 2.0, PI / 2)) == \
        pytest.approx([0.0, -1.0, 0.0], abs=1e-12)
    rng = np.random.default_rng(7)
    for _ in range(100):
        a, b = rng.uniform(-5, 5, 3), rng.uniform(-5, 5, 3)
        assert se2.relative_pose(a, se2.compose(a, b)) == \
            pytest.approx([b[0], b[1], se2.wrap_angle(b[2])], abs=1e-9)


def test_relative_poses_is_relative_pose_row_by_row():
    rng = np.random.default_rng(3)
    starts, ends = rng.uniform(-4, 4, (20, 3)), rng.uniform(-4, 4, (20, 3))
    rows = se2.relative_poses(starts, ends)
    for s, e, row in zip(starts, ends, rows):
        assert row == pytest.approx(se2.relative_pose(s, e), abs=1e-12)


def test_the_exact_arc_ends_on_the_circle():
    # a quarter circle of radius R = v / w: from heading 0, forward 0.5 m/s
    # turning at pi/2 rad/s for 1 s ends at (R, R, pi/2), R = 0.5 / (pi/2)
    r = 0.5 / (PI / 2)
    assert se2.integrate_arc((0.0, 0.0, 0.0), 0.5, 0.0, PI / 2) == \
        pytest.approx((r, r, PI / 2), abs=1e-12)
    # the same arc started heading +90 deg from (1, 1): turned by 90 deg
    assert se2.integrate_arc((1.0, 1.0, PI / 2), 0.5, 0.0, PI / 2) == \
        pytest.approx((1.0 - r, 1.0 + r, PI), abs=1e-12)
    # no turn: a straight chord (the series branch): (0.3, -0.2) turned by 30 deg
    c, s = math.cos(PI / 6), math.sin(PI / 6)
    assert se2.compose_arc((0.0, 0.0, PI / 6), 0.3, -0.2, 0.0) == \
        pytest.approx((0.3 * c + 0.2 * s, 0.3 * s - 0.2 * c), abs=1e-15)
    # the series and the closed form agree where they meet (|dtheta| = 1e-6);
    # the closed form's (1 - cos t) / t loses digits there: measured 4.4e-11
    near = se2.compose_arc((0.0, 0.0, 0.0), 1.0, 0.5, 1.0000001e-6)
    series = se2.compose_arc((0.0, 0.0, 0.0), 1.0, 0.5, 0.9999999e-6)
    assert near == pytest.approx(series, abs=1e-10)


def test_yaw_of_a_quaternion_and_back():
    # rotation by 120 deg about z: (0, 0, sin 60, cos 60)
    q = (0.0, 0.0, math.sin(PI / 3), math.cos(PI / 3))
    assert se2.quaternion_of_yaw(2 * PI / 3) == pytest.approx(q, abs=1e-15)
    assert se2.yaw_of_quaternion(q) == pytest.approx(2 * PI / 3, abs=1e-12)
    # -q is the same rotation (w < 0): the yaw stays in [-pi, pi]
    assert se2.yaw_of_quaternion(tuple(-v for v in q)) == pytest.approx(2 * PI / 3, abs=1e-12)
    # a roll of 90 deg (about x) has no yaw: (sin 45, 0, 0, cos 45)
    assert se2.yaw_of_quaternion((math.sin(PI / 4), 0.0, 0.0, math.cos(PI / 4))) == \
        pytest.approx(0.0, abs=1e-12)


def test_arc_between_inverts_the_constant_twist_arc():
    # By hand: from (1, 2) heading +y (pi/2), a quarter circle of radius 1
    # turning left (v = 1 m/s, w = 1 rad/s for pi/2 s) goes round the centre
    # (1, 2) + 1 m to the left = (0, 2) and ends at (0, 3) heading -x (pi):
    # the arc is (pi/2 m along the body's x, 0, pi/2 rad).
    assert se2.arc_between((1.0, 2.0, math.pi / 2), (0.0, 3.0, math.pi)) == pytest.approx(
        (math.pi / 2, 0.0, math.pi / 2))
    # no turn (the series branch): the body-frame displacement itself; here
    # heading pi/2, so world +x is the body's -y
    assert se2.arc_between((0.0, 0.0, math.pi / 2), (0.5, 0.0, math.pi / 2)) == pytest.approx(
        (0.0, -0.5, 0.0))
    # integrate_arc of the result comes back to the end pose
    start, arc = (0.3, -1.2, 2.5), (0.4, -0.7, -1.1)
    end = se2.integrate_arc(start, *arc)
    assert se2.arc_between(start, end) == pytest.approx(arc)


def test_the_small_angle_arc_keeps_the_chord_to_the_last_digit():
    """Below 1e-6 rad the arc uses the series of sin(t)/t and (1 - cos t)/t.
    For t = 9e-7 rad and 1 m forward, the chord is (sin t / t, 2 sin^2(t/2)
    / t) -- written without the cancellation of 1 - cos t -- i.e. x = 1 -
    1.35e-13 m: the series must give it to a few 1e-16 m (a wrong t^2
    coefficient is off by 2e-14 m or more)."""
    t = 9e-7
    x, y = se2.compose_arc((0.0, 0.0, 0.0), 1.0, 0.0, t)
    assert abs(x - math.sin(t) / t) < 1e-15
    # (b = t/2: the series drops t^3 / 24 = 3e-20 m)
    assert abs(y - 2.0 * math.sin(0.5 * t) ** 2 / t) < 1e-19


def test_a_sideways_arc_a_start_off_the_diagonal_and_a_rolled_yaw():
    """By hand: 1 m to the left while turning a quarter turn (constant
    twist) is an arc of radius 2/pi about (-2/pi, 0): it ends at (-2/pi,
    2/pi). From (1, 2) heading 0, 1 m forward ends at (2, 2). A rotation of
    roll 0.4 rad then yaw 0.7 rad (q = q_z(0.7) q_x(0.4)) has yaw 0.7 rad."""
    x, y = se2.compose_arc((0.0, 0.0, 0.0), 0.0, 1.0, math.pi / 2)
    assert x == pytest.approx(-2 / math.pi, abs=1e-15) and y == pytest.approx(2 / math.pi)
    assert se2.integrate_arc((1.0, 2.0, 0.0), 1.0, 0.0, 0.0) == pytest.approx((2.0, 2.0, 0.0))
    c, s = math.cos(0.35), math.sin(0.35)           # half of the yaw
    cr, sr = math.cos(0.2), math.sin(0.2)           # half of the roll
    q = (c * sr, s * sr, s * cr, c * cr)            # (x, y, z, w) of q_z q_x
    assert se2.yaw_of_quaternion(q) == pytest.approx(0.7, abs=1e-12)
