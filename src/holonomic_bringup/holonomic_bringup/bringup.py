"""``holonomic-bringup ROBOT``: start the whole stack for one robot.

A pure-Python launcher (``ros2 launch`` is not available from PyPI): it
validates the configuration, sets a safe DDS discovery default and runs the
base controller node -- which owns the driver, so with ``--driver sim`` the
pybullet stand-in runs inside it -- until SIGINT/SIGTERM, then stops and
disarms the motors and exits 0.
"""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path

from holonomic_bringup.process_guard import install_signal_handlers
from holonomic_bringup.ros_names import namespace
from holonomic_core.command_line import ArgumentParser, ShowDefaults


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    from holonomic_core.driver import driver_names

    parser = ArgumentParser(
        prog="holonomic-bringup", formatter_class=ShowDefaults,
        description="Start the base controller, its driver (simulator or motor drives) "
                    "and its topics for one robot. Motors start disarmed unless --enable.")
    parser.add_argument("robot", help="a config name from config/ (hamr, xr4000, comr3) "
                                      "or a path to a robot YAML")
    parser.add_argument("--driver", choices=driver_names(),
                        help="driver backend (default: the config's `driver`, normally sim)")
    parser.add_argument("--sim-drives", action="store_true",
                        help="with --driver odrive_can or cia402: run that CAN driver against "
                             "emulated drives on a virtual bus whose motors are the "
                             "simulator's joints (check a robot's CAN YAML before the hardware)")
    parser.add_argument("--gui", action="store_true",
                        help="show the pybullet GUI (sim and --sim-drives only)")
    parser.add_argument("--namespace", type=namespace, default="",
                        help="ROS namespace of the robot's node, topics and frames")
    parser.add_argument("--params-file", action="append", default=[], metavar="FILE",
                        help="extra ROS 2 params file(s) overriding the robot config")
    parser.add_argument("--enable", action="store_true",
                        help="arm the motors at start (default: disarmed until ~/enable)")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="NAME:=VALUE",
                        help="override one parameter, e.g. -p cmd_timeout:=1.0")
    parser.add_argument("--fleet", type=int, metavar="N",
                        help="run N robots (namespaces robot1..robotN) in one simulated world")
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="record cmd_vel, odom, /tf, joint_states, ground_truth/odom, "
                             "diagnostics and robot_description to an MCAP file "
                             "(Foxglove, ros2 bag, holonomic-plot)")
    fox = parser.add_argument_group(
        "Foxglove", "a Foxglove WebSocket server in this process (docs/foxglove.md). The "
                    "protocol has no authentication: anyone who reaches the port sees the robot.")
    fox.add_argument("--foxglove", nargs="?", type=int, const=8765, metavar="PORT",
                     help="serve the robot live to Foxglove on PORT (default 8765): URDF, "
                          "every link's transform, paths, twists, slip, diagnostics")
    fox.add_argument("--foxglove-host", default="127.0.0.1", metavar="ADDR",
                     help="address to listen on (default 127.0.0.1: this machine only; "
                          "0.0.0.0 serves every network the robot is on)")
    fox.add_argument("--foxglove-allow-control", action="store_true",
                     help="let Foxglove clients publish cmd_vel (geometry_msgs/Twist JSON). "
                          "Default: read-only (no client publishing, services or parameters)")
    args = parser.parse_args(argv)
    check_args(parser, args)
    return args


def check_args(parser: argparse.ArgumentParser, args: argparse.Namespace) -> None:
    """What argparse cannot check alone; exits 2 with one line (parser.error)."""
    import yaml

    from holonomic_core.config import read_params_file
    from holonomic_core.schema import ConfigError

    for item in args.param:
        name, _, value = item.partition(":=")
        if ":=" not in item or not name:
            parser.error(f"-p expects NAME:=VALUE (e.g. -p cmd_timeout:=1.0), got {item!r}")
        try:    # rcl reads the value as YAML; a malformed one would stop rclpy.init
            yaml.safe_load(value)
        except yaml.YAMLError:
            parser.error(f"-p {name}: the value {value!r} is not valid YAML "
                         "(a number, true/false, a string or a [list])")
    for path in args.params_file:
        if not Path(path).is_file():
            parser.error(f"--params-file: no such file: {path}")
        try:
            read_params_file(Path(path))
        except ConfigError as exc:
            parser.error(f"--params-file {path}: expected {exc.allowed}")
    if args.record:
        if not args.record.endswith(".mcap"):
            parser.error(f"--record wants a FILE.mcap, got {args.record!r}")
        folder = Path(args.record).absolute().parent
        try:
            folder.mkdir(parents=True, exist_ok=True)
        except OSError as exc:
            parser.error(f"--record: cannot create the folder {str(folder)!r}: {exc.strerror}")
        if not os.access(folder, os.W_OK):
            parser.error(f"--record: the folder {str(folder)!r} is not writable")
    if args.gui and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        parser.error("--gui needs a display (DISPLAY is not set); run headless without --gui")


def start_foxglove(args: argparse.Namespace):
    """The Foxglove bridge the arguments ask for, listening; None without
    --foxglove. Raises SystemExit(2) with one line when it cannot start."""
    if args.foxglove is None:
        if args.foxglove_allow_control or args.foxglove_host != "127.0.0.1":
            raise SystemExit("holonomic-bringup: --foxglove-host and --foxglove-allow-control "
                             "need --foxglove")
        return None
    if not 1 <= args.foxglove <= 65535:
        raise SystemExit(f"holonomic-bringup: --foxglove PORT must be 1..65535, "
                         f"got {args.foxglove}")
    from holonomic_bringup.foxglove_bridge import BridgeError, FoxgloveBridge
    try:
        return FoxgloveBridge(args.foxglove_host, args.foxglove,
                              allow_control=args.foxglove_allow_control)
    except BridgeError as exc:
        raise SystemExit(f"holonomic-bringup: {exc}") from None


def ros_arguments(args: argparse.Namespace) -> list[str]:
    """The ``--ros-args`` for the base controller node."""
    from holonomic_core.config import resolve_config

    ros = ["--ros-args", "-p", f"robot_config:={resolve_config(args.robot)}"]
    if args.namespace:
        ns = args.namespace     # absolute, checked by ros_names.namespace
        ros += ["-r", f"__ns:={ns}"]
        # every frame of the robot under its namespace too (a -p frame_prefix
        # given below wins: later overrides replace earlier ones)
        ros += ["-p", f"frame_prefix:={ns.strip('/')}/"]
    if args.driver:
        ros += ["-p", f"driver:={args.driver}"]
    if args.sim_drives:
        ros += ["-p", "sim_drives:=true"]
    if args.gui:
        ros += ["-p", "sim.gui:=true"]
    if args.enable:
        ros += ["-p", "enable_on_start:=true"]
    for path in args.params_file:
        ros += ["--params-file", path]
    for item in args.param:
        ros += ["-p", item]
    return ros


def main(argv: list[str] | None = None) -> int:
    # First: from here on SIGINT/SIGTERM request the normal shutdown (motors
    # stopped and disarmed, exit 0), whatever is being set up when they come.
    install_signal_handlers()
    args = parse_args(argv)
    # DDS must not multicast on the network interface unless the user asks for it.
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    from holonomic_core.schema import ConfigError
    try:
        ros = ros_arguments(args)
    except ConfigError as exc:
        print(f"holonomic-bringup: {exc}", file=sys.stderr)
        return 2
    from holonomic_bringup.base_controller_node import main as node_main
    from holonomic_core.driver import emulated_drive_names
    if args.sim_drives and args.driver not in emulated_drive_names():
        print("holonomic-bringup: --sim-drives needs "
              + " or ".join(f"--driver {name}" for name in emulated_drive_names())
              + f" (got {args.driver or 'the config default'})", file=sys.stderr)
        return 2
    if args.fleet is not None:
        problem = ("N must be between 1 and 100" if not 1 <= args.fleet <= 100 else
                   "is simulation only (--driver sim)" if args.driver not in (None, "sim") else
                   "puts each robot in its own namespace (no --namespace)" if args.namespace else
                   "takes -p overrides, not --params-file" if args.params_file else
                   "runs headless (no --gui)" if args.gui else None)
        if problem:
            print(f"holonomic-bringup: --fleet {problem}", file=sys.stderr)
            return 2
    # Before any driver opens: a port in use stops here, with nothing moved.
    try:
        bridge = start_foxglove(args)
    except SystemExit as exc:
        print(exc, file=sys.stderr)
        return 2
    try:
        if args.fleet is not None:
            from holonomic_bringup.fleet import run_fleet
            return run_fleet(args.robot, args.fleet, args.param, args.enable, args.record,
                             foxglove=bridge)
        return node_main(["holonomic-bringup"] + ros, record=args.record, foxglove=bridge)
    finally:
        if bridge is not None:
            if bridge.cost() is not None:       # it ran: say what it cost
                print(bridge.cost(), file=sys.stderr)
            bridge.close()


if __name__ == "__main__":
    sys.exit(main())
