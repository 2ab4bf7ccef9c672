"""``holonomic-teleop``: keyboard teleop in a terminal, publishing ``cmd_vel``.

teleop_twist_keyboard's layout, plus its holonomic (Shift) layout for
strafing and diagonals at constant heading::

    Moving around:          Holonomic (Shift), constant heading:
       u    i    o             U    I    O
       j    k    l             J    K    L
       m    ,    .             M    <    >

    i / ,   forward / backward          J / L   strafe left / right
    j / l   turn left / right           U O M > diagonals
    u o m . forward/backward + turn     I / <   forward / backward

    q / z : all speeds x1.1 / x0.9      w / x : linear only     e / c : turn only
    space or k or K : stop              Ctrl-C : stop and quit

The command is published at ``--rate`` Hz. A movement key holds its command
for ``--key-timeout`` seconds (longer than the terminal's key-repeat delay),
so holding a key drives and releasing it stops -- even if the robot's
``cmd_timeout`` is long. ``--key-timeout 0`` latches each command until the
next key. On exit (Ctrl-C, SIGTERM, end of input) a zero twist is sent.
"""

from __future__ import annotations

import argparse
import math
import os
import select
import sys
import termios
import time
import tty

from holonomic_bringup.process_guard import STOP, install_signal_handlers

#: key -> (forward, lateral, turn) as multiples of (speed, speed, turn)
MOVE_KEYS = {
    "i": (1, 0, 0), "o": (1, 0, -1), "j": (0, 0, 1), "l": (0, 0, -1),
    "u": (1, 0, 1), ",": (-1, 0, 0), ".": (-1, 0, 1), "m": (-1, 0, -1),
    # holonomic layout (Shift): translate at constant heading
    "I": (1, 0, 0), "O": (1, -1, 0), "J": (0, 1, 0), "L": (0, -1, 0),
    "U": (1, 1, 0), "<": (-1, 0, 0), ">": (-1, -1, 0), "M": (-1, 1, 0),
}
#: key -> (linear factor, angular factor)
SPEED_KEYS = {"q": (1.1, 1.1), "z": (0.9, 0.9), "w": (1.1, 1.0), "x": (0.9, 1.0),
              "e": (1.0, 1.1), "c": (1.0, 0.9)}
STOP_KEYS = {" ", "k", "K"}
#: Ctrl-C and Ctrl-D arrive as characters in raw mode
QUIT_KEYS = {"\x03", "\x04"}

HELP = __doc__.split("::", 1)[1].split("The command is published")[0]


class TeleopState:
    """The command the keys have built: pure logic, no terminal or ROS."""

    def __init__(self, speed: float, turn: float, max_speed: float, max_turn: float,
                 key_timeout: float):
        self.speed, self.turn = speed, turn
        self.max_speed, self.max_turn = max_speed, max_turn
        self.key_timeout = key_timeout
        self.motion = (0, 0, 0)
        self.last_key = -math.inf

    def key(self, ch: str, now: float) -> str | None:
        """Apply one key at time ``now`` [s]; returns a status line to show
        when something changed, "quit" to stop, None otherwise."""
        if ch in QUIT_KEYS:
            self.motion = (0, 0, 0)
            return "quit"
        if ch in MOVE_KEYS:
            self.motion = MOVE_KEYS[ch]
            self.last_key = now
            return None
        if ch in STOP_KEYS:
            self.motion = (0, 0, 0)
            return "stop"
        if ch in SPEED_KEYS:
            lin, ang = SPEED_KEYS[ch]
            self.speed = min(self.max_speed, self.speed * lin)
            self.turn = min(self.max_turn, self.turn * ang)
            return f"speed {self.speed:.2f} m/s  turn {self.turn:.2f} rad/s"
        return None

    def twist(self, now: float) -> tuple[float, float, float]:
        """(vx, vy, wz) to publish at ``now`` [m/s, m/s, rad/s]."""
        if self.key_timeout > 0 and now - self.last_key > self.key_timeout:
            self.motion = (0, 0, 0)
        fwd, lat, rot = self.motion
        return (fwd * self.speed, lat * self.speed, rot * self.turn)


def parse_args(argv):
    p = argparse.ArgumentParser(prog="holonomic-teleop", description=HELP,
                                formatter_class=argparse.RawDescriptionHelpFormatter)
    p.add_argument("--topic", default="cmd_vel", help="topic (relative; default cmd_vel)")
    p.add_argument("--namespace", default="", help="robot namespace, e.g. robot1")
    p.add_argument("--stamped", action="store_true",
                   help="publish geometry_msgs/TwistStamped (for cmd_vel_stamped: true)")
    p.add_argument("--frame-id", default="base_link", help="header frame of --stamped")
    p.add_argument("--speed", type=float, default=0.5, help="start linear speed [m/s]")
    p.add_argument("--turn", type=float, default=1.0, help="start turn rate [rad/s]")
    p.add_argument("--max-speed", type=float, default=2.0, help="cap of q/w [m/s]")
    p.add_argument("--max-turn", type=float, default=6.0, help="cap of q/e [rad/s]")
    p.add_argument("--rate", type=float, default=20.0, help="publish rate [Hz]")
    p.add_argument("--key-timeout", type=float, default=0.7,
                   help="seconds a movement key holds its command (0: until the next key)")
    args = p.parse_args(argv)
    for name in ("speed", "turn", "max_speed", "max_turn", "rate"):
        value = getattr(args, name)
        if not (math.isfinite(value) and value > 0):
            p.error(f"--{name.replace('_', '-')} must be a positive number, got {value}")
    if not (math.isfinite(args.key_timeout) and args.key_timeout >= 0):
        p.error("--key-timeout must be >= 0")
    return args


def main(argv: list[str] | None = None) -> int:
    install_signal_handlers()
    args = parse_args(argv)
    if not sys.stdin.isatty():
        print("holonomic-teleop: needs a terminal on stdin (keyboard input)", file=sys.stderr)
        return 2
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy
    from geometry_msgs.msg import Twist, TwistStamped
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("teleop", namespace=args.namespace or None)
    msg_type = TwistStamped if args.stamped else Twist
    pub = node.create_publisher(msg_type, args.topic, 10)
    state = TeleopState(args.speed, args.turn, args.max_speed, args.max_turn, args.key_timeout)

    def publish(twist):
        if args.stamped:
            msg = TwistStamped()
            msg.header.stamp = node.get_clock().now().to_msg()
            msg.header.frame_id = args.frame_id
            body = msg.twist
        else:
            msg = body = Twist()
        body.linear.x, body.linear.y, body.angular.z = (float(v) for v in twist)
        pub.publish(msg)

    fd = sys.stdin.fileno()
    saved = termios.tcgetattr(fd)
    out = sys.stdout
    out.write(HELP.replace("\n", "\r\n") + f"\r\npublishing {pub.topic_name} "
              f"({msg_type.__name__}) at {args.rate:g} Hz\r\n")
    out.flush()
    period = 1.0 / args.rate
    next_pub = time.monotonic()
    try:
        tty.setraw(fd)   # every key at once, Ctrl-C as a key (restored below)
        while not STOP.is_set():
            now = time.monotonic()
            ready, _, _ = select.select([fd], [], [], max(0.0, next_pub - now))
            if ready:
                data = os.read(fd, 32)
                if not data:            # end of input
                    break
                statuses = [state.key(ch, time.monotonic())
                            for ch in data.decode(errors="ignore")]
                if "quit" in statuses:
                    break
                for status in filter(None, statuses):
                    out.write(status + "\r\n")
                out.flush()
            now = time.monotonic()
            if now >= next_pub:
                publish(state.twist(now))
                next_pub = max(next_pub + period, now)
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        for _ in range(3):
            publish((0.0, 0.0, 0.0))
            time.sleep(0.02)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
