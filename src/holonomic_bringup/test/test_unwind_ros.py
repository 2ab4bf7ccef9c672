"""A user with casters whose cables allow 1.5 turns: driving round winds
them to the end of their range, diagnostics WARN naming the steering joints,
and `holonomic-ctl unwind` brings them back to the middle with the base back
where it started (the ROS route: ~/unwind through the loop process)."""

from __future__ import annotations

import math
import re
import shutil
import subprocess
import time

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


def test_casters_wound_to_their_range_warn_and_unwind_back_home(ros, tmp_path):
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
        start = probe.latest_truth().pose
        done = ctl("unwind", "--namespace", "unw1")
        assert done.returncode == 0, done.stdout + done.stderr
        assert "unwinding: " in done.stdout and "unwound:" in done.stdout, done.stdout
        offsets = [float(v) for v in re.findall(r"([+-]\d+\.\d) deg from the middle", done.stdout)]
        assert len(offsets) == 4 and all(abs(v) < 5.0 for v in offsets), done.stdout
        time.sleep(0.5)
        end_pose = probe.latest_truth().pose
        assert math.hypot(end_pose[0] - start[0], end_pose[1] - start[1]) < 0.01
        assert abs(math.degrees(end_pose[2] - start[2])) < 1.0
        # nothing left to unwind: a clear answer, exit 0
        again = ctl("unwind", "--namespace", "unw1")
        assert again.returncode == 0 and "nothing to unwind" in again.stdout, again.stdout
    finally:
        probe.close()
        assert robot.stop() == 0, robot.log()
