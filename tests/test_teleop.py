"""holonomic-teleop: the key logic alone, then the real program in a
pseudo-terminal, publishing to this process and driving a simulated HAMR."""

from __future__ import annotations

import time

import numpy as np
import pytest
from geometry_msgs.msg import Twist, TwistStamped

from holonomic_bringup.teleop import TeleopState
from holonomic_testing.ros_probe import Bringup, Probe, Teleop, relative_pose, wait_until


def state(timeout=0.7):
    return TeleopState(speed=0.5, turn=1.0, max_speed=2.0, max_turn=6.0, key_timeout=timeout)


def test_keys_build_the_twist_of_the_teleop_twist_keyboard_layout():
    s = state()
    expected = {"i": (0.5, 0, 0), ",": (-0.5, 0, 0), "j": (0, 0, 1.0), "l": (0, 0, -1.0),
                "u": (0.5, 0, 1.0), "J": (0, 0.5, 0), "L": (0, -0.5, 0), "U": (0.5, 0.5, 0),
                ">": (-0.5, -0.5, 0), "M": (-0.5, 0.5, 0)}
    for key, twist in expected.items():
        s.key(key, now=0.0)
        assert s.twist(0.1) == pytest.approx(twist), key
    s.key(" ", now=0.2)
    assert s.twist(0.2) == (0, 0, 0)


def test_a_held_key_drives_and_a_released_one_stops_after_the_timeout():
    s = state(timeout=0.7)
    s.key("J", now=10.0)
    assert s.twist(10.6)[1] == pytest.approx(0.5)
    assert s.twist(10.8) == (0, 0, 0)
    latched = state(timeout=0.0)
    latched.key("I", now=0.0)
    assert latched.twist(100.0)[0] == pytest.approx(0.5)


def test_speed_keys_scale_and_stop_at_the_caps():
    s = state()
    assert s.key("q", 0.0).startswith("speed 0.55")
    s.key("x", 0.0)
    assert s.speed == pytest.approx(0.495) and s.turn == pytest.approx(1.1)
    for _ in range(100):
        s.key("q", 0.0)
    assert (s.speed, s.turn) == (2.0, 6.0)
    assert s.key("\x03", 0.0) == "quit" and s.twist(0.0) == (0, 0, 0)


def test_shift_a_arms_and_d_disarms_and_both_stop_the_motion():
    s = state()
    s.key("I", 0.0)
    assert s.key("A", 0.1) == "arm" and s.twist(0.1) == (0, 0, 0)
    s.key("I", 0.2)
    assert s.key("d", 0.3) == "disarm" and s.twist(0.3) == (0, 0, 0)
    assert s.key("D", 0.4) == "disarm"
    assert s.key("a", 0.5) is None      # lower-case a: no accidental arming


def test_s_presses_the_emergency_stop_and_shift_r_releases_it():
    s = state()
    s.key("I", 0.0)
    assert s.key("s", 0.1) == "estop" and s.twist(0.1) == (0, 0, 0)
    assert s.key("S", 0.2) == "estop"
    assert s.key("R", 0.3) == "release"
    assert s.key("r", 0.4) is None      # lower-case r: no accidental release


@pytest.fixture
def listen(ros):
    """Factory: record the messages of a topic on the test's node."""
    subs = []

    def make(msg_type, topic):
        got = []
        subs.append(ros.create_subscription(msg_type, topic, got.append, 50))
        return got

    yield make
    for sub in subs:
        ros.destroy_subscription(sub)


def test_keys_in_a_terminal_publish_cmd_vel_and_ctrl_c_stops(listen):
    got = listen(Twist, "/tele1/cmd_vel")
    teleop = Teleop("--namespace", "tele1")
    try:
        wait_until(lambda: got, 20, "teleop to publish")
        teleop.hold("J", 0.5)
        wait_until(lambda: got[-1].linear.y == pytest.approx(0.5), 5, "a strafe command")
        assert got[-1].linear.x == 0 and got[-1].angular.z == 0
        teleop.press("q")
        teleop.hold("I", 0.4)
        wait_until(lambda: got[-1].linear.x == pytest.approx(0.55), 5, "faster forward")
        teleop.press(" ")
        wait_until(lambda: got[-1].linear.x == 0 and got[-1].linear.y == 0, 5, "stop")
        teleop.hold("U", 0.3)
        teleop.press("\x03")            # Ctrl-C as a key in raw mode
        assert teleop.proc.wait(10) == 0
        time.sleep(0.2)
        assert got[-1].linear.x == 0 and got[-1].linear.y == 0   # last word: stop
        assert b"holonomic" in teleop.output.lower() or b"strafe" in teleop.output
    finally:
        teleop.stop()


def test_stamped_mode_publishes_twiststamped_with_a_fresh_stamp(listen, ros):
    got = listen(TwistStamped, "/tele2/cmd_vel")
    teleop = Teleop("--namespace", "tele2", "--stamped")
    try:
        wait_until(lambda: got, 20, "teleop to publish")
        teleop.hold("L", 0.4)
        wait_until(lambda: got[-1].twist.linear.y == pytest.approx(-0.5), 5, "strafe right")
        msg = got[-1]
        now = ros.get_clock().now().nanoseconds * 1e-9
        assert abs(now - (msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)) < 1.0
        assert msg.header.frame_id == "base_link"
    finally:
        assert teleop.stop() == 0


def controller_state(probe) -> str | None:
    """The motors' state the robot's diagnostics report, or None before any."""
    diag = probe.diagnostics
    if diag is None:
        return None
    return next((kv.value for s in diag.status for kv in s.values
                 if kv.key == "controller_state"), None)


def test_arm_keys_reach_the_robot_and_the_screen_says_who_listens(ros, tmp_path):
    teleop = Teleop("--namespace", "tele4")
    robot = None
    probe = Probe(ros, "tele4")
    try:
        # no robot yet: said after the discovery grace period (3 s)
        wait_until(lambda: (teleop.drain(), b"nothing subscribes to /tele4/cmd_vel"
                            in teleop.output)[1], 20, "the no-subscriber warning")
        assert b"A (Shift-a) : arm the motors" in teleop.output
        robot = Bringup(["hamr", "--namespace", "tele4"], tmp_path / "bringup.log")
        probe.wait_ready()
        wait_until(lambda: (teleop.drain(), b"/tele4/cmd_vel: a robot listens"
                            in teleop.output)[1], 20, "the robot to be seen")
        wait_until(lambda: controller_state(probe) == "disarmed", 10, "disarmed diagnostics")
        # moving disarmed motors: the screen says why not. Teleop knows the
        # motors' state from its own diagnostics subscription, which can match
        # the robot's publisher a diagnostics period after the probe's did:
        # keep pressing, as a user would, until it knows
        wait_until(lambda: (teleop.hold("i", 0.3), teleop.drain(),
                            b"motors DISARMED: the robot will not move (press A to arm)"
                            in teleop.output)[2], 10, "the disarmed hint")
        teleop.press("A")
        wait_until(lambda: controller_state(probe) == "armed", 10, "the motors to arm")
        teleop.press("d")
        wait_until(lambda: controller_state(probe) == "disarmed", 10, "the motors to disarm")
        wait_until(lambda: (teleop.drain(), b"disarm: " in teleop.output)[1], 5, "the answer")
        # the e-stop key: quick stop, arming refused until R, R does not arm
        teleop.press("A")
        wait_until(lambda: controller_state(probe) == "armed", 10, "the motors to arm")
        teleop.press("s")
        wait_until(lambda: controller_state(probe) == "disarmed", 10, "the e-stop to disarm")
        teleop.press("A")
        wait_until(lambda: (teleop.drain(), b"release the emergency stop first"
                            in teleop.output)[1], 10, "arming refused")
        teleop.press("R")
        wait_until(lambda: (teleop.drain(), b"emergency stop released" in teleop.output)[1],
                   5, "the release line")
        time.sleep(1.5)
        assert controller_state(probe) == "disarmed"
        teleop.press("A")
        wait_until(lambda: controller_state(probe) == "armed", 10, "arming after the release")
    finally:
        assert teleop.stop() == 0
        probe.close()
        if robot is not None:
            assert robot.stop() == 0, robot.log()


def test_holding_the_strafe_key_moves_the_simulated_hamr_sideways(ros, tmp_path):
    robot = Bringup(["hamr", "--namespace", "tele3", "--enable"], tmp_path / "bringup.log")
    probe = Probe(ros, "tele3")
    teleop = Teleop("--namespace", "tele3", "--speed", "0.4")
    try:
        probe.wait_ready()
        start = probe.latest_truth().pose
        teleop.hold("J", 2.5)
        wait_until(lambda: np.linalg.norm(probe.latest_truth().twist) < 0.01, 5,
                   "the base to stop after the key is released")
        moved = relative_pose(start, probe.latest_truth().pose)
        # 0.4 m/s left while the key is held (2.5 s) and for the 0.7 s key
        # timeout after it: 3.2 s x 0.4 = 1.28 m less the ramps (~0.1 m);
        # no forward motion, heading kept
        assert 1.0 < moved[1] < 1.35, moved
        assert abs(moved[0]) < 0.05 and abs(moved[2]) < 0.05, moved
    finally:
        assert teleop.stop() == 0
        probe.close()
        assert robot.stop() == 0, robot.log()
