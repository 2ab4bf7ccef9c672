"""A client's view of one running robot, for scripts, the demo and tests.

Publishes ``cmd_vel``, records ``odom`` and ``ground_truth/odom`` (pose in
odom, body twist in base_link) and the latest ``diagnostics``, and calls the
controller's ``~/enable`` and ``~/reset_odometry``. It does not spin: add its
node to an executor spinning in another thread.
"""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import Twist
from nav_msgs.msg import Odometry
from std_srvs.srv import SetBool, Trigger

from holonomic_core.se2 import yaw_of_quaternion


def wait_until(predicate, timeout: float, what: str, period: float = 0.02):
    """Poll ``predicate`` until truthy and return it; TimeoutError after ``timeout`` s."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = predicate()
        if value:
            return value
        time.sleep(period)
    raise TimeoutError(f"timed out after {timeout:g} s waiting for {what}")


def yaw_of(q) -> float:
    """Yaw [rad] of a quaternion message (geometry_msgs/Quaternion)."""
    return yaw_of_quaternion((q.x, q.y, q.z, q.w))


@dataclass(frozen=True)
class Sample:
    """Pose (x, y, yaw) [m, m, rad] in odom and body twist (vx, vy, wz) at
    receive time ``t`` (time.monotonic, s); ``stamp``: the message's header
    stamp [s] (the time of the readings the estimate is from)."""

    t: float
    pose: np.ndarray
    twist: np.ndarray
    stamp: float = float("nan")


def _sample(msg: Odometry) -> Sample:
    p, tw = msg.pose.pose, msg.twist.twist
    return Sample(time.monotonic(),
                  np.array([p.position.x, p.position.y, yaw_of(p.orientation)]),
                  np.array([tw.linear.x, tw.linear.y, tw.angular.z]),
                  msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)


class RobotClient:
    """Topics and services of the robot in namespace ``ns``, on ``node``."""

    def __init__(self, node, ns: str = "", controller: str = "base_controller"):
        prefix = f"/{ns.strip('/')}" if ns.strip("/") else ""
        self.node = node
        self._lock = threading.Lock()
        self.odom: list[Sample] = []
        self.truth: list[Sample] = []
        self.odom_msgs: list[Odometry] = []
        self.diagnostics: DiagnosticArray | None = None
        self.cmd_pub = node.create_publisher(Twist, f"{prefix}/cmd_vel", 10)
        self._subs = [
            node.create_subscription(Odometry, f"{prefix}/odom", self._on_odom, 50),
            node.create_subscription(Odometry, f"{prefix}/ground_truth/odom", self._on_truth, 50),
            node.create_subscription(DiagnosticArray, f"{prefix}/diagnostics",
                                     self._on_diag, 10),
        ]
        self.enable_client = node.create_client(SetBool, f"{prefix}/{controller}/enable")
        self.reset_client = node.create_client(Trigger, f"{prefix}/{controller}/reset_odometry")

    def close(self) -> None:
        for sub in self._subs:
            self.node.destroy_subscription(sub)
        self.node.destroy_publisher(self.cmd_pub)
        self.node.destroy_client(self.enable_client)
        self.node.destroy_client(self.reset_client)

    def _on_odom(self, msg: Odometry) -> None:
        with self._lock:
            self.odom.append(_sample(msg))
            self.odom_msgs = self.odom_msgs[-10:] + [msg]

    def _on_truth(self, msg: Odometry) -> None:
        with self._lock:
            self.truth.append(_sample(msg))

    def _on_diag(self, msg: DiagnosticArray) -> None:
        self.diagnostics = msg

    # -- commands and services -----------------------------------------------------
    def wait_ready(self, timeout: float = 30.0, ground_truth: bool = True) -> None:
        """Wait until the robot publishes odom (and ground truth) and listens on cmd_vel."""
        wait_until(lambda: self.odom and (self.truth or not ground_truth) and
                   self.cmd_pub.get_subscription_count() > 0, timeout,
                   "the robot to publish odom and subscribe cmd_vel")

    def call(self, client, request, timeout: float = 10.0):
        wait_until(client.service_is_ready, timeout, f"service {client.srv_name}")
        future = client.call_async(request)
        return wait_until(lambda: future.result() if future.done() else None, timeout,
                          f"the answer of {client.srv_name}")

    def enable(self, on: bool = True):
        """Arm (True) or disarm the motors; returns the SetBool response."""
        return self.call(self.enable_client, SetBool.Request(data=on))

    def reset_odometry(self):
        return self.call(self.reset_client, Trigger.Request())

    def publish(self, vx: float = 0.0, vy: float = 0.0, wz: float = 0.0) -> None:
        """One cmd_vel: (vx, vy, wz) [m/s, m/s, rad/s] in base_link."""
        msg = Twist()
        msg.linear.x, msg.linear.y, msg.angular.z = float(vx), float(vy), float(wz)
        self.cmd_pub.publish(msg)

    def drive(self, twist, seconds: float, rate: float = 20.0) -> None:
        """Publish the body ``twist`` at ``rate`` [Hz] for ``seconds`` (wall time)."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.publish(*twist)
            time.sleep(1.0 / rate)

    # -- recorded state ------------------------------------------------------------
    def latest_truth(self) -> Sample:
        with self._lock:
            return self.truth[-1]

    def latest_odom(self) -> Sample:
        with self._lock:
            return self.odom[-1]

    def truth_since(self, t0: float) -> list[Sample]:
        with self._lock:
            return [s for s in self.truth if s.t >= t0]

    def odom_since(self, t0: float) -> list[Sample]:
        with self._lock:
            return [s for s in self.odom if s.t >= t0]

    def wait_at_rest(self, timeout: float = 5.0, speed: float = 0.005) -> None:
        """Command zero until ground truth shows the base at rest."""
        def still():
            self.publish()
            s = self.latest_truth()
            return np.linalg.norm(s.twist[:2]) < speed and abs(s.twist[2]) < 5 * speed
        wait_until(still, timeout, "the base to come to rest", period=0.05)
