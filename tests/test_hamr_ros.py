"""The simulated HAMR end to end through real ROS nodes and topics.

holonomic-bringup runs as a subprocess (the simulator in it stands in for
the hardware); this process publishes cmd_vel and watches odom and
ground_truth/odom like any other ROS node would.
"""

import math
import signal
import time

import numpy as np
import pytest
from tf2_msgs.msg import TFMessage

from std_srvs.srv import Trigger

from holonomic_testing.ros_probe import Bringup, Probe, drive_script, wait_until


@pytest.fixture(scope="module")
def hamr(ros, tmp_path_factory):
    """One simulated HAMR for the module's tests, armed, on ideal motors:
    these tests time the controller (stops, tracking, odometry) to a few
    hundredths of a second, and the measured values in their comments are
    the ideal plant's (the drive model's lag is its own tests' subject)."""
    proc = Bringup(["hamr", "-p", "sim.ideal_motors:=true"],
                   tmp_path_factory.mktemp("hamr") / "bringup.log")
    probe = Probe(ros)
    try:
        probe.wait_ready()
        ok = probe.enable(True)
        assert ok.success, ok.message
        yield probe
    finally:
        probe.close()
        code = proc.stop(signal.SIGINT)
        assert code == 0, proc.log()


def mean_body_twist(samples):
    return np.mean([s.twist for s in samples], axis=0)


# forward, strafe at constant heading, diagonal, spin in place, and
# translate-while-rotating (a body-frame twist with all three components)
TWISTS = {
    "forward": (0.6, 0.0, 0.0),
    "strafe_left": (0.0, 0.4, 0.0),
    "diagonal": (0.35, -0.35, 0.0),
    "spin": (0.0, 0.0, 1.5),
    "translate_while_rotating": (0.3, 0.2, 0.6),
    "backward_strafe_rotate": (-0.3, -0.25, -0.8),
}


@pytest.mark.parametrize("name", list(TWISTS))
def test_base_moves_with_the_commanded_body_twist(hamr, name):
    cmd = np.array(TWISTS[name])
    hamr.wait_at_rest()
    hamr.drive(cmd, 2.5)          # transient: acceleration, the drive base turning
    t0 = time.monotonic()
    hamr.drive(cmd, 1.5)          # steady window
    achieved = mean_body_twist(hamr.truth_since(t0))
    # within 3 % of the commanded speed (translation and rotation separately)
    v_cmd, w_cmd = np.linalg.norm(cmd[:2]), abs(cmd[2])
    assert np.linalg.norm(achieved[:2] - cmd[:2]) <= 0.03 * max(v_cmd, 0.1), achieved
    assert abs(achieved[2] - cmd[2]) <= 0.03 * max(w_cmd, 0.3), achieved


def test_odometry_stays_within_0_2_percent_of_distance_over_20_s(hamr):
    script = [((0.6, 0.0, 0.0), 3.0), ((0.0, 0.4, 0.0), 3.0), ((0.3, 0.3, 0.5), 4.0),
              ((0.0, 0.0, -1.5), 2.0), ((-0.4, 0.2, 0.3), 4.0), ((0.5, -0.3, -0.4), 4.0)]
    distance, error, heading = drive_script(hamr, script)
    # 8.8 m as scripted, less the ramps and whatever a loaded machine drops
    # (7.8 m measured with two busy CPUs beside the test)
    assert distance > 6.0
    # measured (ideal motors, sim.ideal_motors:=true): 3.4 mm over 7.8 m
    # (0.044 %), heading 0.0018 rad; bounds ~5x that: a kinematic or
    # odometry error of a fraction of a percent fails
    assert error <= 0.002 * distance, (error, distance)
    # heading, measured over 11 runs of this script (alone, in the whole
    # file, with two busy loops beside, on the drive model, on Python 3.12):
    # 0.0003-0.0027 rad; on a machine loaded by other test sessions (the loop
    # process among other SCHED_FIFO loops) up to 0.0142 rad: the test's cmd_vel
    # arrives on the wall clock while the simulation steps with the loop, so a
    # starved machine changes the drive itself. Bound: under 2x the loaded
    # worst (the distance bound above still catches a fraction of a percent).
    assert heading < 0.025, heading



def test_stale_cmd_vel_stops_the_base(hamr):
    hamr.wait_at_rest()
    hamr.drive((0.5, 0.0, 0.0), 2.0)
    last_cmd = time.monotonic()
    start = hamr.latest_truth().pose
    # the publisher dies: after cmd_timeout (0.5 s) the base decelerates at
    # 2.0 m/s^2 (hamr.yaml) -- at rest 0.5 + 0.25 s after the last command
    wait_until(lambda: np.linalg.norm(hamr.latest_truth().twist) < 0.01, 3.0,
               "the base to stop after the command went stale")
    # measured 0.77 s (0.02 s of latency over the 0.75 s); 0.15 s of slack
    stopped_after = time.monotonic() - last_cmd
    assert stopped_after < 0.5 + 0.25 + 0.15, stopped_after
    # coasting distance: 0.5 m/s * 0.5 s + 0.5^2 / (2 * 2.0) = 0.3125 m
    # (measured 0.304 m): it held the command until the timeout, then braked
    travelled = np.linalg.norm(hamr.latest_truth().pose[:2] - start[:2])
    assert travelled == pytest.approx(0.3125, abs=0.03), travelled


def test_nan_commands_never_move_the_base_and_stop_a_moving_one(hamr):
    hamr.wait_at_rest()
    start = hamr.latest_truth().pose
    for _ in range(20):
        hamr.publish(math.nan, 0.3, 0.0)
        hamr.publish(0.2, math.inf, 0.0)
        time.sleep(0.05)
    assert np.linalg.norm(hamr.latest_truth().pose[:2] - start[:2]) < 0.005
    # moving at 0.5 m/s, a NaN command stops the base (it does not keep going
    # until the timeout on the last good command)
    hamr.drive((0.5, 0.0, 0.0), 1.5)
    hamr.publish(math.nan, 0.0, 0.0)
    t_nan = time.monotonic()
    at_nan = hamr.latest_truth().pose
    wait_until(lambda: np.linalg.norm(hamr.latest_truth().twist) < 0.01, 3.0,
               "the base to stop after a NaN command")
    # Braking starts at the next cycle: 0.5 m/s at 2.0 m/s^2 (hamr.yaml) is
    # 0.25 s, measured 0.27-0.29 s from the publish to a ground truth at rest. A
    # base that dropped the NaN but kept the last good command would only
    # stop after cmd_timeout + braking = 0.5 + 0.25 s (measured 0.73 s), so
    # anything under cmd_timeout proves the NaN itself stopped it.
    stop_time = time.monotonic() - t_nan
    assert stop_time < 0.5, stop_time
    # the same in distance (free of the machine's load): braking from 0.5 m/s
    # at 2.0 m/s^2 covers 0.5^2 / (2 * 2.0) = 0.06 m (measured 0.074 m);
    # holding the last good command until the timeout would add 0.5 m/s *
    # 0.5 s = 0.25 m
    braked = np.linalg.norm(hamr.latest_truth().pose[:2] - at_nan[:2])
    assert braked < 0.15, braked


def test_disarmed_base_ignores_cmd_vel_and_rearms(hamr):
    hamr.wait_at_rest()
    assert hamr.enable(False).success
    start = hamr.latest_truth().pose
    hamr.drive((0.5, 0.0, 0.0), 1.0)
    assert np.linalg.norm(hamr.latest_truth().pose[:2] - start[:2]) < 0.005
    assert hamr.enable(True).success
    hamr.drive((0.5, 0.0, 0.0), 1.0)
    assert np.linalg.norm(hamr.latest_truth().pose[:2] - start[:2]) > 0.2


def test_odometry_message_tf_joint_states_and_diagnostics(hamr, ros):
    from sensor_msgs.msg import JointState
    tf_msgs, joints = [], []
    subs = [ros.create_subscription(TFMessage, "/tf", tf_msgs.append, 10),
            ros.create_subscription(JointState, "joint_states", joints.append, 10)]
    try:
        wait_until(lambda: tf_msgs and joints and hamr.diagnostics, 10.0,
                   "/tf, joint_states and diagnostics")
        odom = hamr.odom_msgs[-1]
        assert (odom.header.frame_id, odom.child_frame_id) == ("odom", "base_link")
        cov = np.array(odom.pose.covariance).reshape(6, 6)
        assert np.allclose(cov, cov.T) and all(cov[i, i] > 0 for i in range(6))
        assert np.array(odom.twist.covariance).reshape(6, 6)[0, 0] > 0
        tf = tf_msgs[-1].transforms[0]
        assert (tf.header.frame_id, tf.child_frame_id) == ("odom", "base_link")
        assert type(tf_msgs[-1]).__module__.startswith("tf2_msgs.msg")
        assert list(joints[-1].name) == ["left_wheel_joint", "right_wheel_joint", "turret_joint"]
        assert len(joints[-1].position) == len(joints[-1].velocity) == 3
        names = {s.name for s in hamr.diagnostics.status}
        assert {"base_controller: driver", "base_controller: control loop",
                "base_controller: command", "base_controller: odometry"} <= names
        loop = next(s for s in hamr.diagnostics.status if s.name.endswith("control loop"))
        rate = float(next(kv.value for kv in loop.values if kv.key == "rate_hz"))
        assert rate == pytest.approx(200.0, rel=0.05)
        # the glitch policy's count (safety.glitch_policy drop): none on the simulator
        driver = next(s for s in hamr.diagnostics.status if s.name.endswith(": driver"))
        assert {kv.key: kv.value for kv in driver.values}["dropped_readings"] == "0"
    finally:
        for sub in subs:
            ros.destroy_subscription(sub)


def test_reset_odometry_service_zeroes_the_pose(hamr):
    hamr.drive((0.3, 0.0, 0.0), 0.5)
    answer = hamr.call(hamr.reset_client, Trigger.Request())
    assert answer.success
    hamr.wait_at_rest()
    assert np.linalg.norm(hamr.latest_odom().pose[:2]) < 0.2


def test_sigterm_while_moving_stops_the_motors_and_exits_zero(ros, start_bringup):
    proc = start_bringup("hamr", "--namespace", "shutdown_test", "--enable")
    probe = Probe(ros, "shutdown_test")
    try:
        probe.wait_ready()
        probe.drive((0.5, 0.0, 0.0), 1.0)
        assert np.linalg.norm(probe.latest_truth().twist[:2]) > 0.3
        assert proc.stop(signal.SIGTERM) == 0
        assert "motors stopped and disarmed" in proc.log()
    finally:
        probe.close()


def test_invalid_config_exits_with_a_message_naming_the_key(start_bringup, tmp_path):
    from holonomic_core.config import resolve_config
    bad = tmp_path / "bad.yaml"
    bad.write_text(resolve_config("hamr").read_text().replace(
        "wheel_radius: 0.0615", "wheel_radius: -0.0615"))
    proc = start_bringup(str(bad))
    code = proc.proc.wait(30)
    log = proc.log()
    assert code == 2
    assert "ddrot.wheel_radius" in log and "Traceback" not in log
