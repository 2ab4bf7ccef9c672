"""holonomic-ctl: arm, disarm, reset and inspect a running robot without
the ros2 CLI (which a pip-only install does not have).

    holonomic-ctl enable           [--namespace NS]   arm the motors (~/enable true)
    holonomic-ctl disable          [--namespace NS]   disarm them (~/enable false)
    holonomic-ctl reset-odometry   [--namespace NS]   odometry pose back to the origin
    holonomic-ctl unwind           [--namespace NS]   every ranged joint (steering, turret)
                                                      back to the middle of its range by
                                                      loops about the start; waits for the
                                                      end (any cmd_vel or disable cancels)
    holonomic-ctl estop            [--namespace NS]   press the emergency stop (emergency_stop
                                                      true, latched): the drives quick-stop
    holonomic-ctl release          [--namespace NS]   release it (the motors stay disarmed)
    holonomic-ctl set-pose X Y YAW [--namespace NS]   odometry jumps to (X, Y) [m], YAW [rad]
    holonomic-ctl status           [--namespace NS]   armed/disarmed, e-stop, fault and its cause,
                                                      loop rate, odometry pose, slip residuals

status reads what the base controller publishes (diagnostics, 1 Hz, and
odom); --json prints it as one JSON object. Exit status: 0 done,
1 the robot refused or did not answer within ``--timeout``, 2 bad arguments.
"""

from __future__ import annotations

import json
import math
import os
import sys
import threading

from holonomic_bringup.process_guard import install_signal_handlers
from holonomic_bringup.ros_names import namespace
from holonomic_core.command_line import ArgumentParser, ShowDefaults, number

PROG = "holonomic-ctl"
COMMANDS = ("enable", "disable", "reset-odometry", "estop", "release", "set-pose", "status",
            "unwind")
CONTROLLER = "base_controller"


def parse_args(argv: list[str] | None):
    p = ArgumentParser(prog=PROG, description=__doc__.split("\n\n")[0].replace("\n", " "),
                       epilog="\n\n".join(__doc__.split("\n\n")[1:]), formatter_class=ShowDefaults)
    p.add_argument("command", choices=COMMANDS, help="what to do")
    p.add_argument("pose", nargs="*", type=number(-1e6, 1e6), metavar="X Y YAW",
                   help="set-pose: the pose in odom [m, m, rad]")
    p.add_argument("--namespace", type=namespace, default="",
                   help="the robot's namespace, as given to holonomic-bringup (e.g. robot1)")
    p.add_argument("--timeout", type=number(0.0, 600.0, strict_low=True, unit="s"), default=10.0,
                   help="how long to wait for the robot [s]")
    p.add_argument("--json", action="store_true", help="status: print one JSON object")
    args = p.parse_args(argv)
    if args.json and args.command != "status":
        p.error("--json goes with status only")
    if args.command == "set-pose" and len(args.pose) != 3:
        p.error(f"set-pose needs X Y YAW (3 numbers), got {len(args.pose)}")
    if args.command != "set-pose" and args.pose:
        p.error(f"{args.command} takes no numbers (only set-pose X Y YAW does)")
    return args


# -- the status report (ROS-free: plain dicts in, text out) ------------------------
def status_from_diagnostics(statuses: list[dict], pose) -> dict:
    """The robot's state from its ``diagnostics`` statuses.

    ``statuses``: [{"name", "level", "message", "values": {key: text}}] as the
    base controller publishes them; ``pose``: (x, y, yaw) [m, m, rad] in odom
    or None. Returns the dict ``status --json`` prints.
    """
    by_name = {s["name"].split(": ", 1)[-1]: s for s in statuses}
    driver = by_name.get("driver", {}).get("values", {})
    loop = by_name.get("control loop", {}).get("values", {})
    odo = by_name.get("odometry", {}).get("values", {})
    command = by_name.get("command", {})
    prefix, suffix = "slip_residual_", "_m_s"
    return {
        "robot": next((s.get("hardware_id", "") for s in statuses if s.get("hardware_id")), ""),
        "state": driver.get("controller_state", "unknown"),
        "fault": driver.get("fault"),
        "loop_rate_hz": _float(loop.get("rate_hz")),
        "loop_period_p99_ms": _float(loop.get("period_p99_ms")),
        "pose": None if pose is None else {"x": pose[0], "y": pose[1], "yaw": pose[2]},
        "estimator": odo.get("estimator"),
        "distance_m": _float(odo.get("distance_m")),
        "slip_residual_m_s": {k[len(prefix):-len(suffix)]: _float(v) for k, v in odo.items()
                              if k.startswith(prefix) and k.endswith(suffix)},
        "command": command.get("message"),
        "unwind": command.get("values", {}).get("unwind"),
        "command_warning": command.get("level") == 1,
        "estop": by_name.get("emergency stop", {}).get("values", {}).get("source"),
    }


def _float(text):
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


def format_status(status: dict, ns: str) -> str:
    """``status_from_diagnostics`` as the lines ``holonomic-ctl status`` prints."""
    where = ns or "/"
    flag = f" --namespace {ns.strip('/')}" if ns else ""
    state = status["state"]
    motors = state.upper()
    if state == "disarmed" and status.get("estop"):
        motors += f"  (e-stop pressed: holonomic-ctl release{flag}, then enable)"
    elif state == "disarmed":
        motors += f"  (arm: holonomic-ctl enable{flag})"
    lines = [f"robot      {status['robot'] or '?'} at {where}",
             f"motors     {motors}",
             f"e-stop     {('PRESSED: ' + status['estop']) if status.get('estop') else 'released'}",
             f"fault      {status['fault'] or 'none'}"]
    if status["loop_rate_hz"] is not None:
        lines.append(f"loop       {status['loop_rate_hz']:.1f} Hz "
                     f"(p99 period {status['loop_period_p99_ms']:.2f} ms)")
    pose = status["pose"]
    if pose is not None:
        lines.append(f"odometry   x {pose['x']:+.3f} m  y {pose['y']:+.3f} m  "
                     f"yaw {math.degrees(pose['yaw']):+.1f} deg  "
                     f"({status['estimator']}, {status['distance_m'] or 0.0:.2f} m travelled)")
    if status["command"]:
        lines.append(f"command    {status['command']}"
                     + ("  [WARN]" if status["command_warning"] else ""))
    if status["slip_residual_m_s"]:
        lines.append("slip residual per caster [m/s]: " + "  ".join(
            f"{name} {value:.4f}" for name, value in status["slip_residual_m_s"].items()))
    return "\n".join(lines)


# -- ROS -----------------------------------------------------------------------------
def _call(node, srv_type, name: str, request, timeout: float):
    """Call a service; (response, None) or (None, why not)."""
    from holonomic_bringup.robot_client import wait_until

    client = node.create_client(srv_type, name)
    try:
        wait_until(client.service_is_ready, timeout, name)
    except TimeoutError:
        return None, (f"no robot answers at {name} within {timeout:g} s (is holonomic-bringup "
                      f"running with this --namespace and ROS_DOMAIN_ID="
                      f"{os.environ.get('ROS_DOMAIN_ID', '0')}?)")
    future = client.call_async(request)
    try:
        wait_until(future.done, timeout, name)
    except TimeoutError:
        return None, f"{name} did not answer within {timeout:g} s"
    return future.result(), None


def _status(node, ns: str, timeout: float):
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry

    from holonomic_bringup.robot_client import wait_until, yaw_of

    got: dict = {}
    node.create_subscription(DiagnosticArray, f"{ns}/diagnostics",
                             lambda m: got.setdefault("diag", m), 10)
    node.create_subscription(Odometry, f"{ns}/odom", lambda m: got.__setitem__("odom", m), 10)
    try:
        # diagnostics come at 1 Hz; odom does not while the driver has no reading
        wait_until(lambda: "diag" in got, timeout, "diagnostics")
        wait_until(lambda: "odom" in got, 1.5, "odom")
    except TimeoutError:
        if "diag" not in got:
            return None, (f"no diagnostics on {ns}/diagnostics within {timeout:g} s (is "
                          "holonomic-bringup running with this --namespace and ROS_DOMAIN_ID="
                          f"{os.environ.get('ROS_DOMAIN_ID', '0')}?)")
    statuses = [{"name": s.name, "level": int.from_bytes(s.level, "little")
                 if isinstance(s.level, bytes) else int(s.level),
                 "message": s.message, "hardware_id": s.hardware_id,
                 "values": {kv.key: kv.value for kv in s.values}}
                for s in got["diag"].status if s.name.startswith(CONTROLLER)]
    pose = None
    if "odom" in got:
        p = got["odom"].pose.pose
        pose = (p.position.x, p.position.y, yaw_of(p.orientation))
    return status_from_diagnostics(statuses, pose), None


def _await_unwind(node, ns: str, stall: float) -> tuple[bool, str]:
    """Wait until the robot's diagnostics say the unwind ended: (unwound, its
    last report). Gives up after ``stall`` [s] without diagnostics."""
    import time

    from diagnostic_msgs.msg import DiagnosticArray

    from holonomic_bringup.process_guard import STOP

    latest: dict = {}

    def on_diagnostics(msg) -> None:
        for s in msg.status:
            if s.name == f"{CONTROLLER}: command":
                latest["values"] = {kv.key: kv.value for kv in s.values}
                latest["at"] = time.monotonic()
    node.create_subscription(DiagnosticArray, f"{ns}/diagnostics", on_diagnostics, 10)
    start = time.monotonic()
    while not STOP.is_set():
        time.sleep(0.1)
        seen = latest.get("at", start)
        if time.monotonic() - seen > stall:
            return False, f"no diagnostics for {stall:g} s: the outcome is unknown"
        report = latest.get("values", {}).get("unwind")
        if "values" in latest and report is not None and not report.startswith("running"):
            return report.startswith("unwound"), report
    return False, "stopped waiting (the maneuver goes on: holonomic-ctl disable stops it)"


def main(argv: list[str] | None = None) -> int:
    install_signal_handlers()
    args = parse_args(argv)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions
    from std_srvs.srv import SetBool, Trigger

    from holonomic_bringup.process_guard import STOP

    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(f"holonomic_ctl_{os.getpid()}")
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    done = threading.Event()

    def spin():
        while not done.is_set() and not STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=spin, daemon=True)
    thread.start()
    ns = args.namespace
    service = f"{ns}/{CONTROLLER}"
    try:
        if args.command == "status":
            status, problem = _status(node, ns, args.timeout)
            if problem:
                print(f"{PROG}: {problem}", file=sys.stderr)
                return 1
            print(json.dumps(status) if args.json else format_status(status, ns))
            return 0
        if args.command in ("estop", "release", "set-pose"):
            from holonomic_bringup.safety_commands import estop, set_pose

            if args.command == "set-pose":
                ok, text = set_pose(node, ns, args.pose, args.timeout)
            else:
                ok, text = estop(node, ns, args.command == "estop", args.timeout)
            print(f"{args.command}: {text}" if ok else f"{PROG}: {text}",
                  file=sys.stdout if ok else sys.stderr)
            return 0 if ok else 1
        if args.command == "reset-odometry":
            response, problem = _call(node, Trigger, f"{service}/reset_odometry",
                                      Trigger.Request(), args.timeout)
        elif args.command == "unwind":
            response, problem = _call(node, Trigger, f"{service}/unwind", Trigger.Request(),
                                      args.timeout)
            if problem is None and response.success and response.message.startswith("unwinding"):
                print(f"unwind: {response.message}", flush=True)
                ok, report = _await_unwind(node, ns, max(args.timeout, 5.0))
                print(f"unwind: {report}", file=sys.stdout if ok else sys.stderr)
                return 0 if ok else 1
        else:
            response, problem = _call(node, SetBool, f"{service}/enable",
                                      SetBool.Request(data=args.command == "enable"),
                                      args.timeout)
        if problem:
            print(f"{PROG}: {problem}", file=sys.stderr)
            return 1
        print(f"{args.command}: {response.message}", file=sys.stdout if response.success
              else sys.stderr)
        return 0 if response.success else 1
    finally:
        done.set()
        thread.join(1.0)
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
