"""holonomic-ctl: a pip-only user arms, drives, resets and inspects a running
robot without the ros2 CLI; a controller that gets commands while disarmed
says so (log and diagnostics); casters wound to the end of their range say so
and `holonomic-ctl unwind` brings them back to the middle, the base home."""

from __future__ import annotations

import json
import math
import re
import shutil
import subprocess
import time

import pytest

from holonomic_bringup.ctl import format_status, status_from_diagnostics
from holonomic_testing.ros_probe import Bringup, Probe, wait_until


CASTERS = ("front_left", "rear_left", "rear_right", "front_right")


def ctl(*args: str, timeout: float = 90.0) -> subprocess.CompletedProcess:
    exe = shutil.which("holonomic-ctl")
    assert exe, "holonomic-ctl is not on PATH: run the tests with `make test`"
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=timeout)


def command_status(probe):
    diag = probe.diagnostics
    return None if diag is None else next(
        (s for s in diag.status if s.name.endswith(": command")), None)


def test_status_report_of_a_pcv_from_its_diagnostics():
    # The statuses as the base controller publishes them (names, keys), values made up.
    statuses = [
        {"name": "base_controller: driver", "level": 2, "message": "drive front_left: timeout",
         "hardware_id": "xr4000",
         "values": {"controller_state": "fault", "fault": "drive front_left: timeout"}},
        {"name": "base_controller: control loop", "level": 0, "message": "",
         "values": {"rate_hz": "199.800", "period_p99_ms": "5.400"}},
        {"name": "base_controller: odometry", "level": 0, "message": "",
         "values": {"estimator": "slip_min", "distance_m": "1.250",
                    "slip_residual_front_left_m_s": "0.0012",
                    "slip_residual_rear_left_m_s": "0.0003"}},
        {"name": "base_controller: command", "level": 1,
         "message": "commands received while fault: not moving", "values": {}},
    ]
    status = status_from_diagnostics(statuses, (1.0, -0.5, 0.5))
    assert status["state"] == "fault" and status["fault"] == "drive front_left: timeout"
    assert status["loop_rate_hz"] == 199.8 and status["robot"] == "xr4000"
    assert status["slip_residual_m_s"] == {"front_left": 0.0012, "rear_left": 0.0003}
    text = format_status(status, "/r1")
    assert "motors     FAULT" in text and "fault      drive front_left: timeout" in text
    # yaw 0.5 rad = 28.6 deg
    assert "x +1.000 m  y -0.500 m  yaw +28.6 deg" in text
    assert "front_left 0.0012  rear_left 0.0003" in text and "[WARN]" in text


def test_ctl_arms_resets_and_reports_a_running_robot(ros, tmp_path):
    robot = Bringup(["xr4000", "--namespace", "ctl1"], tmp_path / "bringup.log")
    probe = Probe(ros, "ctl1")
    try:
        probe.wait_ready()
        status = ctl("status", "--namespace", "ctl1")
        assert status.returncode == 0, status.stderr
        assert "motors     DISARMED  (arm: holonomic-ctl enable --namespace ctl1)" in status.stdout
        assert "fault      none" in status.stdout and " Hz (p99 period" in status.stdout
        for caster in ("front_left", "rear_left", "rear_right", "front_right"):
            assert f"{caster} 0.0" in status.stdout, status.stdout

        # commands while disarmed: the base stays, the controller says why
        probe.drive((0.3, 0.0, 0.0), 1.5)
        wait_until(lambda: command_status(probe) is not None
                   and command_status(probe).level == b"\x01", 10, "a WARN in diagnostics")
        assert "not moving" in command_status(probe).message
        wait_until(lambda: "while the motors are DISARMED" in robot.log(), 10, "the log line")

        enabled = ctl("enable", "--namespace", "ctl1")
        assert enabled.returncode == 0, enabled.stderr
        probe.drive((0.3, 0.0, 0.0), 1.5)
        probe.wait_at_rest()
        report = json.loads(ctl("status", "--namespace", "ctl1", "--json").stdout)
        assert report["state"] == "armed" and report["pose"]["x"] > 0.2, report
        assert set(report["slip_residual_m_s"]) == {"front_left", "rear_left", "rear_right",
                                                    "front_right"}

        assert ctl("reset-odometry", "--namespace", "ctl1").returncode == 0
        report = json.loads(ctl("status", "--namespace", "ctl1", "--json").stdout)
        # a fresh odom message after the reset: the pose is back at the origin
        assert report["pose"]["x"] == pytest.approx(0.0, abs=1e-3), report

        disabled = ctl("disable", "--namespace", "ctl1")
        assert disabled.returncode == 0, disabled.stderr
        wait_until(lambda: json.loads(ctl("status", "--namespace", "ctl1", "--json").stdout)
                   ["state"] == "disarmed", 20, "the motors to disarm")
    finally:
        probe.close()
        assert robot.stop() == 0, robot.log()


def test_ctl_says_when_no_robot_answers():
    proc = ctl("enable", "--namespace", "nobody_here", "--timeout", "1")
    assert proc.returncode == 1
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "no robot answers at /nobody_here/base_controller/enable" \
        in lines[0], proc.stderr


def test_casters_wound_to_their_range_warn_and_unwind_back_home(ros, tmp_path):
    # casters whose cables allow 1.5 turns; the ROS route: ~/unwind through the loop process
    ranges = [f"joints.{c}_steer_joint.{end}_position:={sign * 3 * math.pi}"
              for c in CASTERS for end, sign in (("min", -1), ("max", 1))]
    args = ["xr4000", "--namespace", "unw1", "--enable"]
    for item in ranges:
        args += ["-p", item]
    robot = Bringup(args, tmp_path / "bringup.log")
    probe = Probe(ros, "unw1")
    try:
        probe.wait_ready()
        # a circle of 0.2 m at constant heading: the casters follow the direction
        # of travel, one turn per 3.1 s; after 1.5 turns they are at their range
        end = time.monotonic() + 8.0
        t0 = time.monotonic()
        while time.monotonic() < end:
            a = 2.0 * (time.monotonic() - t0)
            probe.publish(0.4 * math.cos(a), 0.4 * math.sin(a), 0.0)
            time.sleep(0.05)
            status = command_status(probe)
            if status is not None and status.level == b"\x01" and "range" in status.message:
                break
        wait_until(lambda: command_status(probe) is not None
                   and "end of the range of" in command_status(probe).message, 10,
                   "a WARN naming the steering joints")
        assert command_status(probe).level == b"\x01"
        assert "front_left_steer_joint" in command_status(probe).message
        probe.wait_at_rest()
        start, odom_start = probe.latest_truth().pose, probe.latest_odom().pose
        done = ctl("unwind", "--namespace", "unw1")
        assert done.returncode == 0, done.stdout + done.stderr
        assert "unwinding: " in done.stdout and "unwound:" in done.stdout, done.stdout
        offsets = [float(v) for v in re.findall(r"([+-]\d+\.\d) deg from the middle", done.stdout)]
        assert len(offsets) == 4 and all(abs(v) < 5.0 for v in offsets), done.stdout
        time.sleep(0.5)
        end_pose, odom_end = probe.latest_truth().pose, probe.latest_odom().pose
        # the base is home by ground truth (the odometry's drift over the loop included)
        assert math.hypot(end_pose[0] - start[0], end_pose[1] - start[1]) < 0.01, \
            (done.stdout, "truth", start, end_pose, "odometry", odom_start, odom_end)
        assert abs(math.degrees(end_pose[2] - start[2])) < 1.0
        # nothing left to unwind: a clear answer, exit 0
        again = ctl("unwind", "--namespace", "unw1")
        assert again.returncode == 0 and "nothing to unwind" in again.stdout, again.stdout
    finally:
        probe.close()
        assert robot.stop() == 0, robot.log()
