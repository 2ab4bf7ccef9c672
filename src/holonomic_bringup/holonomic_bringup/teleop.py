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
    A (Shift-a) : arm the motors        d : disarm them      (the controller's ~/enable)
    s or S : EMERGENCY STOP             R (Shift-r) : release it (emergency_stop; arm again with A)

The command is published at ``--rate`` Hz. A movement key holds its command
for ``--key-timeout`` seconds (longer than the terminal's key-repeat delay),
so holding a key drives and releasing it stops -- even if the robot's
``cmd_timeout`` is long. ``--key-timeout 0`` latches each command until the
next key. On exit (Ctrl-C, SIGTERM, end of input) a zero twist is sent.
The screen says when nothing subscribes to the topic (no robot with that
namespace on this ROS_DOMAIN_ID) and when a movement key meets disarmed motors.
"""

from __future__ import annotations

import math
import os
import threading
import select
import sys
import termios
import time
import tty

from holonomic_bringup.process_guard import STOP, install_signal_handlers
from holonomic_bringup.ros_names import namespace
from holonomic_core.command_line import ArgumentParser, ShowDefaults, number

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
#: key -> arm (True) / disarm (False); arming takes Shift, a deliberate key
ENABLE_KEYS = {"A": True, "d": False, "D": False}
#: key -> press (True) / release (False) the emergency stop; release takes Shift
ESTOP_KEYS = {"s": True, "S": True, "R": False}
#: seconds after start before an absent subscriber is reported (DDS discovery
#: can take up to about 2.5 s)
DISCOVERY_GRACE = 3.0
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
        when something changed, "quit" to stop, "arm"/"disarm" to call the
        controller's ~/enable, None otherwise."""
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
        if ch in ENABLE_KEYS:
            self.motion = (0, 0, 0)
            return "arm" if ENABLE_KEYS[ch] else "disarm"
        if ch in ESTOP_KEYS:
            self.motion = (0, 0, 0)
            return "estop" if ESTOP_KEYS[ch] else "release"
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
    p = ArgumentParser(prog="holonomic-teleop", description=HELP, formatter_class=ShowDefaults)
    positive = number(0.0, strict_low=True)
    p.add_argument("--topic", default="cmd_vel", help="topic (relative to the namespace)")
    p.add_argument("--namespace", type=namespace, default="", help="robot namespace, e.g. robot1")
    p.add_argument("--stamped", action="store_true",
                   help="publish geometry_msgs/TwistStamped (for cmd_vel_stamped: true)")
    p.add_argument("--frame-id", default="base_link", help="header frame of --stamped")
    p.add_argument("--speed", type=positive, default=0.5, help="start linear speed [m/s]")
    p.add_argument("--turn", type=positive, default=1.0, help="start turn rate [rad/s]")
    p.add_argument("--max-speed", type=positive, default=2.0, help="cap of q/w [m/s]")
    p.add_argument("--max-turn", type=positive, default=6.0, help="cap of q/e [rad/s]")
    p.add_argument("--rate", type=number(0.0, 1000.0, strict_low=True), default=20.0,
                   help="publish rate [Hz]")
    p.add_argument("--key-timeout", type=number(0.0), default=0.7,
                   help="seconds a movement key holds its command (0: until the next key)")
    args = p.parse_args(argv)
    if args.speed > args.max_speed or args.turn > args.max_turn:
        p.error(f"--speed/--turn ({args.speed:g}, {args.turn:g}) must not exceed "
                f"--max-speed/--max-turn ({args.max_speed:g}, {args.max_turn:g})")
    return args


class RobotLink:
    """What teleop knows of the robot: who subscribes to its topic, the motors'
    state from ``diagnostics``, and the ``~/enable`` service."""

    def __init__(self, node, ns: str, pub, write):
        from diagnostic_msgs.msg import DiagnosticArray
        from std_srvs.srv import SetBool

        self._pub, self._write = pub, write
        self._request = SetBool.Request
        self.state = "unknown"
        self._enable = node.create_client(SetBool, f"{ns}/base_controller/enable")
        from std_msgs.msg import Bool

        from holonomic_bringup.safety_inputs import ESTOP_QOS, ESTOP_TOPIC
        # latched while teleop runs: a controller started later sees it too
        self._bool = Bool
        self._estop = node.create_publisher(Bool, f"{ns}/{ESTOP_TOPIC}", ESTOP_QOS)
        node.create_subscription(DiagnosticArray, f"{ns}/diagnostics", self._on_diag, 10)
        self._listened: bool | None = None

    def _on_diag(self, msg) -> None:
        for status in msg.status:
            for kv in status.values:
                if kv.key == "controller_state":
                    self.state = kv.value

    def check_listener(self, started: float, now: float) -> None:
        """Say when the topic gains or loses its subscriber (after the grace)."""
        listened = self._pub.get_subscription_count() > 0
        if now - started < DISCOVERY_GRACE and not listened:
            return
        if listened != self._listened:
            self._listened = listened
            self._write(f"{self._pub.topic_name}: a robot listens" if listened else
                        f"WARNING: nothing subscribes to {self._pub.topic_name}: is "
                        "holonomic-bringup running with this --namespace and ROS_DOMAIN_ID="
                        f"{os.environ.get('ROS_DOMAIN_ID', '0')}?")

    def moving_while_disarmed(self) -> bool:
        return self.state in ("disarmed", "fault")

    def estop(self, pressed: bool) -> None:
        """Press or release the emergency stop (emergency_stop)."""
        self._estop.publish(self._bool(data=pressed))
        self._write(f"EMERGENCY STOP pressed ({self._estop.topic_name}): R releases it"
                    if pressed else f"emergency stop released ({self._estop.topic_name}): "
                    "the motors stay disarmed, A arms them")

    def enable(self, on: bool) -> None:
        """Call ~/enable; the answer is written when it comes."""
        if not self._enable.service_is_ready():
            self._write(f"{self._enable.srv_name} is not available: no robot to "
                        f"{'arm' if on else 'disarm'}")
            return
        future = self._enable.call_async(self._request(data=on))
        future.add_done_callback(lambda f: self._write(
            f"{'arm' if on else 'disarm'}: {f.result().message}" if f.result() is not None
            else f"{'arm' if on else 'disarm'}: no answer"))


def main(argv: list[str] | None = None) -> int:
    install_signal_handlers()
    args = parse_args(argv)
    if not sys.stdin.isatty():
        print("holonomic-teleop: needs a terminal on stdin (keyboard input)", file=sys.stderr)
        return 2
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy
    from geometry_msgs.msg import Twist, TwistStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node("teleop", namespace=args.namespace or None)
    msg_type = TwistStamped if args.stamped else Twist
    pub = node.create_publisher(msg_type, args.topic, 10)
    state = TeleopState(args.speed, args.turn, args.max_speed, args.max_turn, args.key_timeout)
    out = sys.stdout
    out_lock = threading.Lock()

    def write(line: str) -> None:     # raw mode: every line needs its own \r
        with out_lock:
            out.write(line + "\r\n")
            out.flush()

    link = RobotLink(node, args.namespace, pub, write)
    # service answers and diagnostics arrive on an executor of their own
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    spinning = threading.Event()
    spinning.set()

    def spin():
        while spinning.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)

    spinner = threading.Thread(target=spin, daemon=True)
    spinner.start()

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
    write(HELP.replace("\n", "\r\n") + f"publishing {pub.topic_name} "
          f"({msg_type.__name__}) at {args.rate:g} Hz")
    period = 1.0 / args.rate
    started = next_pub = time.monotonic()
    hinted = -math.inf
    try:
        tty.setraw(fd)   # every key at once, Ctrl-C as a key (restored below)
        while not STOP.is_set():
            now = time.monotonic()
            ready, _, _ = select.select([fd], [], [], max(0.0, next_pub - now))
            if ready:
                data = os.read(fd, 32)
                if not data:            # end of input
                    break
                keys = data.decode(errors="ignore")
                statuses = [state.key(ch, time.monotonic()) for ch in keys]
                if "quit" in statuses:
                    break
                for status in filter(None, statuses):
                    if status in ("arm", "disarm"):
                        link.enable(status == "arm")
                    elif status in ("estop", "release"):
                        link.estop(status == "estop")
                    else:
                        write(status)
                if any(ch in MOVE_KEYS for ch in keys) and link.moving_while_disarmed() \
                        and time.monotonic() - hinted > 3.0:
                    hinted = time.monotonic()
                    write(f"motors {link.state.upper()}: the robot will not move "
                          "(press A to arm)")
            now = time.monotonic()
            if now >= next_pub:
                publish(state.twist(now))
                link.check_listener(started, now)
                next_pub = max(next_pub + period, now)
    finally:
        termios.tcsetattr(fd, termios.TCSADRAIN, saved)
        for _ in range(3):
            publish((0.0, 0.0, 0.0))
            time.sleep(0.02)
        spinning.clear()
        spinner.join(1.0)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
