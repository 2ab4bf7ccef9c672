"""The safety inputs over ROS, as a user drives them: emergency_stop (latched,
heartbeat), holonomic-ctl estop|release|set-pose, set_pose during motion."""

from __future__ import annotations

import json
import math
import shutil
import subprocess

import pytest
from std_msgs.msg import Bool
from tf2_msgs.msg import TFMessage

from holonomic_bringup.safety_inputs import ESTOP_QOS
from holonomic_testing.ros_probe import Bringup, Probe, wait_until


def ctl(*args: str, timeout: float = 60.0) -> subprocess.CompletedProcess:
    exe = shutil.which("holonomic-ctl")
    assert exe, "holonomic-ctl is not on PATH: run the tests with `make test`"
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=timeout)


def estop_status(probe):
    diag = probe.diagnostics
    return None if diag is None else next(
        (s for s in diag.status if s.name.endswith(": emergency stop")), None)


def test_latched_estop_stops_refuses_enable_and_release_does_not_rearm(ros, tmp_path):
    # pressed and latched BEFORE the controller starts: it must see it
    pub = ros.create_publisher(Bool, "/es1/emergency_stop", ESTOP_QOS)
    pub.publish(Bool(data=True))
    robot = Bringup(["hamr", "--namespace", "es1", "--enable"], tmp_path / "bringup.log")
    probe = Probe(ros, "es1")
    try:
        probe.wait_ready()
        wait_until(lambda: estop_status(probe) is not None and estop_status(probe).level == b"\x02",
                   20, "the e-stop ERROR in diagnostics")
        assert "pressed by /es1/emergency_stop" in estop_status(probe).message
        # --enable at start was refused, and so is ~/enable
        assert probe.enable(True).success is False
        report = json.loads(ctl("status", "--namespace", "es1", "--json").stdout)
        assert report["state"] == "disarmed" and "emergency_stop" in report["estop"]
        # release (ctl): diagnostics OK, the motors stay disarmed
        released = ctl("release", "--namespace", "es1")
        assert released.returncode == 0, released.stderr
        pub.publish(Bool(data=False))        # the latched publisher agrees
        probe.drive((0.3, 0.0, 0.0), 1.0)
        report = json.loads(ctl("status", "--namespace", "es1", "--json").stdout)
        assert report["state"] == "disarmed" and report["estop"] is None, report
        assert probe.latest_truth().pose[0] == pytest.approx(0.0, abs=2e-3)
        # armed by hand, moving: estop from the CLI brakes the base to rest
        assert probe.enable(True).success
        probe.drive((0.5, 0.0, 0.0), 1.5)
        assert probe.latest_truth().twist[0] > 0.3
        pressed = ctl("estop", "--namespace", "es1")
        assert pressed.returncode == 0, pressed.stderr
        probe.wait_at_rest()
        assert probe.enable(True).success is False
        pub.publish(Bool(data=False))
    finally:
        ros.destroy_publisher(pub)
        probe.close()
        assert robot.stop() == 0, robot.log()


def test_estop_heartbeat_timeout_quick_stops(ros, tmp_path):
    robot = Bringup(["hamr", "--namespace", "es2", "--driver", "mock",
                     "-p", "safety.estop_timeout:=0.5"], tmp_path / "bringup.log")
    probe = Probe(ros, "es2")
    pub = ros.create_publisher(Bool, "/es2/emergency_stop", ESTOP_QOS)
    try:
        probe.wait_ready(ground_truth=False)
        # no 'released' heard yet: arming is refused
        assert probe.enable(True).success is False
        pub.publish(Bool(data=False))
        wait_until(lambda: probe.enable(True).success, 10, "arming after a release")
        for _ in range(25):                  # a 10 Hz heartbeat for 2.5 s: stays armed
            pub.publish(Bool(data=False))
            probe.drive((0.2, 0.0, 0.0), 0.1)
        # (diagnostics of the last second; a holonomic-ctl status would take
        # longer to start than the heartbeat allows)
        driver = next(s for s in probe.diagnostics.status if s.name.endswith(": driver"))
        assert {kv.key: kv.value for kv in driver.values}["controller_state"] == "armed"
        assert estop_status(probe).level == b"\x00"
        # the heartbeat stops: pressed within 0.5 s, diagnostics say why
        wait_until(lambda: estop_status(probe) is not None
                   and "heartbeat lost" in estop_status(probe).message, 10, "the timeout")
        assert probe.enable(True).success is False
    finally:
        ros.destroy_publisher(pub)
        probe.close()
        assert robot.stop() == 0, robot.log()


def test_set_pose_during_motion_moves_odom_and_tf_together(ros, tmp_path):
    robot = Bringup(["hamr", "--namespace", "sp1", "--enable"], tmp_path / "bringup.log")
    probe = Probe(ros, "sp1")
    tfs = []
    ros.create_subscription(TFMessage, "/tf", lambda m: tfs.append(m), 100)
    try:
        probe.wait_ready()
        probe.drive((0.3, 0.0, 0.0), 1.0)
        done = ctl("set-pose", "3", "-1", "1.5707963", "--namespace", "sp1")
        assert done.returncode == 0, done.stderr
        probe.drive((0.3, 0.0, 0.0), 1.0)
        odom = probe.latest_odom().pose
        # 1 s more at 0.3 m/s along the new heading (+y) from (3, -1)
        assert odom[0] == pytest.approx(3.0, abs=0.02)
        assert -1.0 + 0.2 < odom[1] < -1.0 + 0.4
        assert odom[2] == pytest.approx(math.pi / 2, abs=0.02)
        # /tf's odom -> base_link at the same stamps as odom: the same pose
        last = probe.odom_msgs[-1]
        match = [t.transform for m in tfs for t in m.transforms
                 if t.child_frame_id.endswith("base_link") and t.header.stamp == last.header.stamp]
        assert match, "no /tf at odom's stamp"
        assert match[-1].translation.x == pytest.approx(last.pose.pose.position.x, abs=1e-9)
        assert match[-1].translation.y == pytest.approx(last.pose.pose.position.y, abs=1e-9)
        # bad input moves nothing
        bad = ctl("set-pose", "1", "nan", "0", "--namespace", "sp1")
        assert bad.returncode == 2 and len(bad.stderr.strip().splitlines()) == 1
    finally:
        probe.close()
        assert robot.stop() == 0, robot.log()
