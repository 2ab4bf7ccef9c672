"""Publish cmd_vel as fast as asked, from its own process (the flood test).

Usage: python -m holonomic_testing.flood_publisher TOPIC RATE_HZ SECONDS FINAL_VX FINAL_VY FINAL_WZ
Publishes alternating hostile-but-finite twists at RATE_HZ for SECONDS, prints
"final command" (so a test waits for the end of the flood, not for a time: the
start-up alone takes seconds on a loaded machine), then the final twist for
3 s at 20 Hz (which must win), and prints the achieved rate.
"""

import sys
import time

import rclpy
from geometry_msgs.msg import Twist
from rclpy.qos import QoSProfile, ReliabilityPolicy


def main() -> int:
    topic, rate, seconds = sys.argv[1], float(sys.argv[2]), float(sys.argv[3])
    final = [float(v) for v in sys.argv[4:7]]
    rclpy.init()
    node = rclpy.create_node("flood_publisher")
    pub = node.create_publisher(Twist, topic,
                                QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE))
    deadline = time.monotonic() + 10.0
    while pub.get_subscription_count() == 0 and time.monotonic() < deadline:
        time.sleep(0.05)
    msgs = []
    for sign in (1.0, -1.0):
        m = Twist()
        m.linear.x, m.linear.y, m.angular.z = 5.0 * sign, -3.0 * sign, 40.0 * sign
        msgs.append(m)
    period = 1.0 / rate
    start = time.monotonic()
    sent = 0
    while True:
        now = time.monotonic()
        if now - start >= seconds:
            break
        # pace by the clock: catch up after a scheduling gap instead of drifting
        due = int((now - start) / period) + 1
        while sent < due:
            pub.publish(msgs[sent & 1])
            sent += 1
    last = Twist()
    last.linear.x, last.linear.y, last.angular.z = final
    elapsed = time.monotonic() - start
    print("final command", flush=True)
    for _ in range(60):            # then 3 s of the final command at 20 Hz
        pub.publish(last)
        time.sleep(0.05)
    print(f"sent {sent} messages in {elapsed:.2f} s: {sent / elapsed:.0f} Hz", flush=True)
    node.destroy_node()
    rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
