"""The base controller's safety inputs over ROS: ``emergency_stop`` and
``set_pose``, and the ``emergency stop`` diagnostics status. A translation
only: the state machine is :mod:`holonomic_core.safety`, run in the control
loop (the messages reach it over the loop's control socket, as ``~/enable``
does).

``emergency_stop`` (std_msgs/Bool, true = pressed): subscribed twice, with
transient-local durability (a publisher that latches its state -- an e-stop
bridge, ``holonomic-ctl estop`` -- is heard by a controller started after
it) and with volatile durability (a publisher that does not latch would not
match a transient-local subscription and be silently ignored; a latching
one's messages then arrive twice, which changes nothing).

``set_pose`` (geometry_msgs/PoseWithCovarianceStamped, robot_localization's
set_pose): the odometry jumps to the pose with the (x, y, yaw) part of the
covariance. A pose that is not finite, a non-planar orientation or a
covariance that is not one is refused with a log line and moves nothing.
"""

from __future__ import annotations

import math
import time

from diagnostic_msgs.msg import DiagnosticStatus
from geometry_msgs.msg import PoseWithCovarianceStamped
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import Bool

from holonomic_core.safety import parse_covariance, parse_pose, planar_covariance

ESTOP_TOPIC = "emergency_stop"
SET_POSE_TOPIC = "set_pose"
#: the e-stop topic's QoS (publishers: use it to latch the state)
ESTOP_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.TRANSIENT_LOCAL)
_VOLATILE_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)


def pose_from_message(msg: PoseWithCovarianceStamped) -> tuple[tuple, tuple]:
    """((x, y, yaw), 9-value planar covariance) of a set_pose message;
    ValueError naming what is wrong."""
    p, q = msg.pose.pose.position, msg.pose.pose.orientation
    norm = math.sqrt(q.x * q.x + q.y * q.y + q.z * q.z + q.w * q.w)
    if not math.isfinite(norm) or norm < 1e-9:
        raise ValueError("orientation is not a quaternion")
    if math.hypot(q.x, q.y) > 1e-3 * norm:
        raise ValueError("orientation is not a rotation about z (the base is planar)")
    yaw = 2.0 * math.atan2(q.z, q.w)
    pose = parse_pose((p.x, p.y, yaw))
    return pose, parse_covariance(planar_covariance(msg.pose.covariance))


class SafetyInputs:
    """The subscriptions of one base controller node; ``link``: its loop
    link (``request_estop``, ``request_set_pose``)."""

    def __init__(self, node, link):
        self._node, self._link = node, link
        self._estop_source = node.resolve_topic_name(ESTOP_TOPIC)
        for qos in (ESTOP_QOS, _VOLATILE_QOS):
            node.create_subscription(Bool, ESTOP_TOPIC, self._on_estop, qos)
        node.create_subscription(PoseWithCovarianceStamped, SET_POSE_TOPIC, self._on_set_pose,
                                 QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        self._last_pressed: bool | None = None

    def _on_estop(self, msg: Bool) -> None:
        pressed = bool(msg.data)
        self._link.request_estop(pressed, self._estop_source, time.monotonic())
        if pressed != self._last_pressed:
            # rclpy: one call site, one severity
            if pressed:
                self._node.get_logger().error(f"{self._estop_source}: PRESSED: quick stop")
            else:
                self._node.get_logger().info(
                    f"{self._estop_source}: released (arm again with ~/enable)")
        self._last_pressed = pressed

    def _on_set_pose(self, msg: PoseWithCovarianceStamped) -> None:
        log = self._node.get_logger()
        try:
            pose, covariance = pose_from_message(msg)
        except ValueError as exc:
            log.error(f"set_pose refused: {exc}")
            return
        future = self._link.request_set_pose(pose, covariance)
        future.add_done_callback(lambda f: log.info(f"set_pose: {f.result()[1]}"))


def estop_diagnostic(status) -> tuple[bytes, str, dict[str, str]]:
    """(level, message, values) of the ``emergency stop`` status from a
    ControllerStatus: ERROR naming the source while pressed."""
    values = {"pressed": str(status.estop is not None), "holding": str(status.holding)}
    if status.estop is not None:
        values["source"] = status.estop
        return (DiagnosticStatus.ERROR, f"{status.estop}: motors quick-stopped, ~/enable refused until released",
                values)
    return DiagnosticStatus.OK, "released", values
