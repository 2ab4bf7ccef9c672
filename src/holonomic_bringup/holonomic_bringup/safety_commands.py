"""``holonomic-ctl estop|release|set-pose``: publish one safety input to a
running base controller and confirm that it took effect (the e-stop in its
``diagnostics``, the pose in its ``odom``).

With ``safety.estop_timeout`` set the controller expects a *stream* of
"released" messages: one ``holonomic-ctl release`` lets it arm only within
that timeout; a heartbeat source (the e-stop's bridge) must keep publishing.
"""

from __future__ import annotations

import math
import time

from holonomic_bringup.safety_inputs import ESTOP_QOS, ESTOP_TOPIC, SET_POSE_TOPIC

#: how close [m, rad] odom must come to a set pose to confirm it (the base
#: may be moving: 1 m/s for the 20 ms between two odom messages)
POSE_TOLERANCE = 0.05


def _wait_for_subscriber(publisher, timeout: float) -> bool:
    deadline = time.monotonic() + timeout
    while publisher.get_subscription_count() == 0:
        if time.monotonic() > deadline:
            return False
        time.sleep(0.02)
    return True


def _no_robot(topic: str, timeout: float) -> str:
    import os
    return (f"no robot subscribes to {topic} within {timeout:g} s (is holonomic-bringup "
            f"running with this --namespace and ROS_DOMAIN_ID="
            f"{os.environ.get('ROS_DOMAIN_ID', '0')}?)")


def estop(node, ns: str, pressed: bool, timeout: float) -> tuple[bool, str]:
    """Press (True) or release the e-stop; (confirmed, text)."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import Bool

    topic = f"{ns}/{ESTOP_TOPIC}"
    publisher = node.create_publisher(Bool, topic, ESTOP_QOS)
    seen: dict = {}

    def on_diagnostics(msg) -> None:
        for s in msg.status:
            if s.name.endswith(": emergency stop"):
                values = {kv.key: kv.value for kv in s.values}
                seen["pressed"] = values.get("pressed") == "True"
                seen["message"] = s.message
    node.create_subscription(DiagnosticArray, f"{ns}/diagnostics", on_diagnostics, 10)
    if not _wait_for_subscriber(publisher, timeout):
        return False, _no_robot(topic, timeout)
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        # again every 0.2 s (a heartbeat controller wants fresh releases)
        # until diagnostics (1 Hz) show the new state
        publisher.publish(Bool(data=pressed))
        if seen.get("pressed") is pressed:
            return True, seen["message"] + ("" if pressed else
                                            " (the motors stay disarmed: holonomic-ctl enable)")
        time.sleep(0.2)
    return False, (f"{topic}: sent, but {ns}/diagnostics did not show it "
                   f"{'pressed' if pressed else 'released'} within {timeout:g} s")


def set_pose(node, ns: str, pose, timeout: float) -> tuple[bool, str]:
    """Set the odometry pose (x, y, yaw) [m, m, rad] with zero covariance;
    (confirmed, text)."""
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    from holonomic_bringup.robot_client import yaw_of
    from holonomic_core.se2 import quaternion_of_yaw, wrap_angle

    x, y, yaw = (float(v) for v in pose)
    topic = f"{ns}/{SET_POSE_TOPIC}"
    publisher = node.create_publisher(PoseWithCovarianceStamped, topic,
                                      QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
    got: dict = {}

    def on_odom(msg) -> None:
        p = msg.pose.pose
        if (math.hypot(p.position.x - x, p.position.y - y) < POSE_TOLERANCE
                and abs(wrap_angle(yaw_of(p.orientation) - yaw)) < POSE_TOLERANCE):
            got["pose"] = (p.position.x, p.position.y, yaw_of(p.orientation))
    node.create_subscription(Odometry, f"{ns}/odom", on_odom, 10)
    if not _wait_for_subscriber(publisher, timeout):
        return False, _no_robot(topic, timeout)
    msg = PoseWithCovarianceStamped()
    msg.header.frame_id = "odom"
    msg.header.stamp = node.get_clock().now().to_msg()
    msg.pose.pose.position.x, msg.pose.pose.position.y = x, y
    _, _, qz, qw = quaternion_of_yaw(yaw)
    msg.pose.pose.orientation.z, msg.pose.pose.orientation.w = qz, qw
    publisher.publish(msg)
    deadline = time.monotonic() + timeout
    while "pose" not in got:
        if time.monotonic() > deadline:
            return False, f"{topic}: sent, but {ns}/odom did not reach it within {timeout:g} s"
        time.sleep(0.02)
    px, py, pyaw = got["pose"]
    return True, f"odometry at x {px:+.3f} m  y {py:+.3f} m  yaw {pyaw:+.3f} rad"
