"""The running stack under hostile conditions at the process level: signals
at any moment, a second instance, stamped commands from the wrong time, and
a flood of cmd_vel from another process."""

import math
import os
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from rclpy.qos import QoSProfile, ReliabilityPolicy

from holonomic_testing.ros_probe import Probe, wait_until

STARTED = "on driver"                      # the node's start-up log line
STOPPED = "motors stopped and disarmed"


@pytest.mark.parametrize("sig, after, delay", [
    (signal.SIGINT, None, 0.0), (signal.SIGINT, None, 0.03), (signal.SIGTERM, None, 0.2),
    (signal.SIGINT, None, 0.5),
    (signal.SIGINT, STARTED, 0.0), (signal.SIGTERM, STARTED, 0.3), (signal.SIGINT, STARTED, 2.0)])
def test_a_signal_at_any_moment_stops_disarms_and_exits(start_bringup, sig, after, delay):
    """Armed at start (--enable) and signalled ``delay`` seconds after the
    process started (``after`` None: somewhere in its start-up, wherever the
    machine's load puts it) or after it logged ``after`` (the driver exists:
    the motors are arming or running). The motors are stopped and disarmed
    before the process ends.

    The one window our code cannot cover is the Python interpreter's own
    start-up (site packages, ~50 ms after the wrapper's exec): a signal there
    ends the process before any of the stack exists -- no driver, no motors,
    and no output at all.
    """
    namespace = f"sig{int(sig)}{'s' if after else 'p'}{int(delay * 100)}"
    proc = start_bringup("hamr", "--enable", "--namespace", namespace,
                         "-p", "cmd_timeout:=0.0")
    if after is not None:
        wait_until(lambda: after in proc.log() or proc.proc.poll() is not None, 60.0,
                   f"the node to log {after!r}")
        assert after in proc.log(), proc.log()
    time.sleep(delay)                  # the moment of the signal (the scenario, not a wait)
    code = proc.stop(sig, timeout=30.0)
    log = proc.log()
    if STARTED in log:           # the driver existed: it was stopped and disarmed
        assert code == 0 and STOPPED in log, log
        assert "Traceback" not in log, log
    else:
        # our handlers ran (clean exit 0), or the signal came before any of
        # our code ran: killed by it, with nothing printed
        assert code == 0 or (code == -sig and not log.strip()), (code, log)


def test_a_second_controller_on_the_same_namespace_and_domain_is_refused(ros, start_bringup):
    first = start_bringup("hamr", "--driver", "mock", "--namespace", "twin")
    probe = Probe(ros, "twin")
    try:
        probe.wait_ready(ground_truth=False)
        second = start_bringup("hamr", "--driver", "mock", "--namespace", "twin")
        assert second.proc.wait(30) == 3
        assert "already running" in second.log() and "Traceback" not in second.log()
        # the first one is unaffected, and another namespace is fine
        assert first.proc.poll() is None
        other = start_bringup("hamr", "--driver", "mock", "--namespace", "twin2")
        Probe(ros, "twin2").wait_ready(ground_truth=False)
        assert other.proc.poll() is None
    finally:
        probe.close()


def _stamped(node_clock, offset, vx):
    msg = TwistStamped()
    t = node_clock.now().nanoseconds * 1e-9 + offset
    msg.header.stamp.sec = int(math.floor(t))
    msg.header.stamp.nanosec = int((t - math.floor(t)) * 1e9)
    msg.twist.linear.x = vx
    return msg


def test_stamped_commands_from_the_future_or_the_past_are_rejected(ros, start_bringup):
    from nav_msgs.msg import Odometry
    start_bringup("hamr", "--driver", "mock", "--namespace", "stamped", "--enable",
                  "-p", "cmd_vel_stamped:=true")
    # (not the Probe: its Twist publisher would clash with TwistStamped on the topic)
    odom = []
    sub = ros.create_subscription(Odometry, "/stamped/odom", odom.append, 10)
    pub = ros.create_publisher(TwistStamped, "/stamped/cmd_vel",
                               QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
    try:
        wait_until(lambda: odom and pub.get_subscription_count() > 0, 30.0,
                   "odom and the stamped cmd_vel subscriber")

        def speed_after(offset):
            end = time.monotonic() + 1.0
            while time.monotonic() < end:
                pub.publish(_stamped(ros.get_clock(), offset, 0.4))
                time.sleep(0.05)
            return odom[-1].twist.twist.linear.x

        # the window of ages is [-0.1 s, cmd_timeout = 0.5 s] (command_stamp.py)
        assert abs(speed_after(+5.0)) < 1e-6        # 5 s in the future
        assert abs(speed_after(-10.0)) < 1e-6       # 10 s old (> cmd_timeout)
        assert abs(speed_after(+0.3)) < 1e-6        # 0.3 s ahead: past the tolerance
        assert speed_after(0.0) == pytest.approx(0.4, abs=0.02)
        # inside the window: 0.2 s old (each one, published every 50 ms,
        # fresh for another 0.3 s) and 50 ms ahead (a clock offset)
        assert speed_after(-0.2) == pytest.approx(0.4, abs=0.02)
        assert speed_after(+0.05) == pytest.approx(0.4, abs=0.02)
    finally:
        ros.destroy_publisher(pub)
        ros.destroy_subscription(sub)


def _rss_kib(pid: int) -> int:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1])
    raise RuntimeError("no VmRSS")


@pytest.mark.slow
def test_a_10_khz_cmd_vel_flood_for_30_s_keeps_the_loop_rate_and_memory(ros, start_bringup):
    proc = start_bringup("hamr", "--driver", "mock", "--namespace", "flood", "--enable")
    probe = Probe(ros, "flood")
    try:
        probe.wait_ready(ground_truth=False)
        time.sleep(2.0)
        rss_start = _rss_kib(proc.proc.pid)
        flood = subprocess.Popen(
            [sys.executable, "-m", "holonomic_testing.flood_publisher",
             "/flood/cmd_vel", "10000", "30", "0.3", "-0.2", "0.5"],
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, env=dict(os.environ))
        rates, rss = [], []
        t_end = time.monotonic() + 30.0
        while time.monotonic() < t_end:
            time.sleep(1.0)
            loop = next((s for s in probe.diagnostics.status
                         if s.name.endswith("control loop")), None)
            if loop is not None:
                rates.append(float(next(kv.value for kv in loop.values if kv.key == "rate_hz")))
            rss.append(_rss_kib(proc.proc.pid))
        # the latest command wins: after the flood, its final twist (sent
        # for 3 s) is what the base does. The flood ends 30 s after the
        # publisher's own start-up, which takes seconds on a loaded machine
        # (a 4 s wait from the test's own 30 s can miss the final command):
        # wait for its word.
        deadline, said = time.monotonic() + 60.0, []
        while "final command" not in said:
            wait_until(lambda: select.select([flood.stdout], [], [], 0.0)[0],
                       deadline - time.monotonic(), "the end of the flood")
            said.append(flood.stdout.readline())
            assert said[-1], f"the flood publisher ended early: {said}"
            said[-1] = said[-1].strip()
        wait_until(lambda: np.allclose(probe.latest_odom().twist, [0.3, -0.2, 0.5], atol=0.02),
                   4.0, "the final command to win")
        out, _ = flood.communicate(timeout=30)
        assert flood.returncode == 0, out
        sent_rate = float(out.split(":")[-1].split()[0])
        assert sent_rate > 8000, out               # the flood really happened
        # the loop kept its 200 Hz (diagnostics' rate over the last second);
        # 170 Hz: 178-198 Hz measured in fresh-clone CI runs, the flood
        # publisher and the node's 10 kHz callbacks taking CPU beside the loop
        assert min(rates[3:]) > 170.0, rates
        # memory does not grow with the number of messages (300 000 of them)
        assert max(rss) - rss_start < 20 * 1024, (rss_start, rss)
    finally:
        probe.close()
    assert proc.stop(signal.SIGINT) == 0
