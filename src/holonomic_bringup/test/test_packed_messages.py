"""The node's 1 kHz messages packed into the middleware's own serialization
(holonomic_bringup.packed_messages): what a subscriber deserializes is the
message the numbers describe, for each message the node publishes every
cycle, and the plain mode publishes the same message. No ROS graph needed:
rclpy's serializer is the middleware's (Fast DDS CDR)."""

from __future__ import annotations

import math

import numpy as np
from geometry_msgs.msg import TransformStamped
from nav_msgs.msg import Odometry
from rclpy.serialization import deserialize_message
from sensor_msgs.msg import JointState
from tf2_msgs.msg import TFMessage

from holonomic_bringup import packed_messages
from holonomic_bringup.base_controller_node import (_ODOM_PATHS, _TRUTH_PATHS,
                                                    _odometry_template, _odometry_values)
from holonomic_bringup.packed_messages import PackedMessage


class _Publisher:
    """Records what is published."""

    def __init__(self):
        self.sent = []

    def publish(self, msg):
        self.sent.append(msg)


def _received(out: PackedMessage, publisher: _Publisher, msg_type):
    """The last published message as a subscriber gets it."""
    sent = publisher.sent[-1]
    assert isinstance(sent, bytes) == out.packed
    return deserialize_message(sent, msg_type) if out.packed else sent


def test_odometry_carries_pose_twist_and_both_covariances_in_the_6x6_layout():
    publisher = _Publisher()
    out = PackedMessage(publisher, _odometry_template("odom", "base_link"), _ODOM_PATHS)
    assert out.packed, out.why_plain
    pose_cov = [float(k) for k in range(1, 10)]           # 3x3 row-major: 1..9
    twist_cov = [float(k) for k in range(11, 20)]
    out.publish(_odometry_values(12, 345_000_000, (1.5, -2.25, 0.5), pose_cov,
                                 (0.3, -0.1, 0.7), twist_cov))
    msg = _received(out, publisher, Odometry)
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (12, 345_000_000)
    assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
    p = msg.pose.pose
    assert (p.position.x, p.position.y, p.position.z) == (1.5, -2.25, 0.0)
    # yaw 0.5 rad about z: (0, 0, sin 0.25, cos 0.25)
    assert (p.orientation.x, p.orientation.y) == (0.0, 0.0)
    assert (p.orientation.z, p.orientation.w) == (math.sin(0.25), math.cos(0.25))
    t = msg.twist.twist
    assert (t.linear.x, t.linear.y, t.linear.z, t.angular.x, t.angular.y, t.angular.z) == \
        (0.3, -0.1, 0.0, 0.0, 0.0, 0.7)
    # REP 103 6x6 (x, y, z, roll, pitch, yaw), row-major: the 3x3 (x, y, yaw)
    # entries at rows/columns 0, 1, 5; the locked z, roll, pitch variances
    # (1e-9) on the diagonal at 14, 21, 28; zeros elsewhere
    for covariance, first in ((msg.pose.covariance, 1.0), (msg.twist.covariance, 11.0)):
        expected = np.zeros(36)
        expected[[0, 1, 5, 6, 7, 11, 30, 31, 35]] = np.arange(first, first + 9)
        expected[[14, 21, 28]] = 1e-9
        assert np.array_equal(covariance, expected)


def test_ground_truth_is_an_odometry_without_covariance():
    publisher = _Publisher()
    out = PackedMessage(publisher, _odometry_template("world", "robot_1/base_link", False),
                        _TRUTH_PATHS)
    assert out.packed, out.why_plain
    out.publish(_odometry_values(3, 7, (-4.0, 2.0, -math.pi / 2), (), (1.0, 2.0, 3.0), ()))
    msg = _received(out, publisher, Odometry)
    assert msg.child_frame_id == "robot_1/base_link"
    assert (msg.pose.pose.position.x, msg.pose.pose.position.y) == (-4.0, 2.0)
    # yaw -pi/2: (0, 0, -sin(pi/4), cos(pi/4))
    assert (msg.pose.pose.orientation.z, msg.pose.pose.orientation.w) == \
        (math.sin(-math.pi / 4), math.cos(-math.pi / 4))
    assert msg.twist.twist.angular.z == 3.0
    assert not np.any(msg.pose.covariance) and not np.any(msg.twist.covariance)


def test_joint_states_with_and_without_efforts_and_odd_names():
    for efforts in (False, True):
        publisher = _Publisher()
        # names of odd lengths: the serializer pads after each string
        template = JointState(name=["a", "left_wheel_joint", "turret"],
                              position=[0.0] * 3, velocity=[0.0] * 3)
        fields = ["position", "velocity"]
        if efforts:
            template.effort = [0.0] * 3
            fields.append("effort")
        out = PackedMessage(publisher, template, ("header.stamp.sec", "header.stamp.nanosec",
                                                  *(f"{f}[{i}]" for f in fields
                                                    for i in range(3))))
        assert out.packed, out.why_plain
        out.publish([5, 999_999_999, 1.0, -2.0, 3.5, 0.1, 0.2, -0.3,
                     *((7.0, 8.0, -9.0) if efforts else ())])
        msg = _received(out, publisher, JointState)
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == (5, 999_999_999)
        assert list(msg.name) == ["a", "left_wheel_joint", "turret"]
        assert list(msg.position) == [1.0, -2.0, 3.5]
        assert list(msg.velocity) == [0.1, 0.2, -0.3]
        assert list(msg.effort) == ([7.0, 8.0, -9.0] if efforts else [])


def test_a_tf_message_of_several_transforms():
    publisher = _Publisher()
    transforms = []
    for parent, child in (("odom", "base_link"), ("base_link", "turret_link")):
        tf = TransformStamped()
        tf.header.frame_id, tf.child_frame_id = parent, child
        transforms.append(tf)
    paths = [f"transforms[{k}].{p}" for k in (0, 1) for p in (
        "header.stamp.sec", "header.stamp.nanosec", "transform.translation.x",
        "transform.translation.y", "transform.translation.z", "transform.rotation.x",
        "transform.rotation.y", "transform.rotation.z", "transform.rotation.w")]
    out = PackedMessage(publisher, TFMessage(transforms=transforms), tuple(paths))
    assert out.packed, out.why_plain
    out.publish([1, 2, 0.1, 0.2, 0.3, 0.0, 0.0, 0.6, 0.8,
                 1, 2, -1.0, 0.0, 0.25, 0.5, 0.5, 0.5, 0.5])
    msg = _received(out, publisher, TFMessage)
    assert [(t.header.frame_id, t.child_frame_id) for t in msg.transforms] == \
        [("odom", "base_link"), ("base_link", "turret_link")]
    second = msg.transforms[1].transform
    assert (second.translation.x, second.translation.z) == (-1.0, 0.25)
    assert (second.rotation.x, second.rotation.w) == (0.5, 0.5)
    assert msg.transforms[0].transform.rotation.z == 0.6


def test_a_middleware_that_does_not_match_gets_the_same_message_plainly(monkeypatch):
    # the self-check finds the packed bytes decode to something else
    monkeypatch.setattr(packed_messages, "deserialize_message", lambda data, t: t())
    publisher = _Publisher()
    out = PackedMessage(publisher, _odometry_template("odom", "base_link"), _ODOM_PATHS)
    assert not out.packed
    assert out.why_plain == "packed bytes differ from the middleware's serialization"
    out.publish(_odometry_values(12, 345, (1.5, -2.25, 0.5), [1.0] * 9,
                                 (0.3, -0.1, 0.7), [2.0] * 9))
    msg = publisher.sent[-1]
    assert isinstance(msg, Odometry)
    assert (msg.header.stamp.sec, msg.pose.pose.position.y, msg.twist.twist.angular.z) == \
        (12, -2.25, 0.7)
    assert (msg.pose.covariance[7], msg.pose.covariance[14], msg.twist.covariance[35]) == \
        (1.0, 1e-9, 2.0)
