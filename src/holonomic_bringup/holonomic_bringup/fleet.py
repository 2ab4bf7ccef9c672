"""``holonomic-bringup ROBOT --fleet N``: N simulated robots in one world.

Every robot is a full base controller node in its own namespace (``robot1``
... ``robotN``: topics, services, the node and the frames ``robotK/odom``,
``robotK/base_link``), commanded on its own ``robotK/cmd_vel``. They share
one pybullet world -- the robots can collide -- stepped by one fixed-rate
loop (in the control loop process, as for one robot): physics once per
control period, then each robot's control cycle. One robot's failure (a
fault, an exception in its cycle) stops that robot only. The first robot
publishes ``/clock``.
"""

from __future__ import annotations

import sys

import rclpy
from rclpy.signals import SignalHandlerOptions

from holonomic_core.config import resolve_config
from holonomic_core.schema import ConfigError

#: distance [m] between neighbouring robots' start poses, along world y
SPACING = 2.0


def start_poses(count: int, spacing: float = SPACING) -> list[tuple[float, float, float]]:
    """Start poses (x, y, yaw) in the world: a row along y centred on 0."""
    return [(0.0, spacing * (k - (count - 1) / 2.0), 0.0) for k in range(count)]


def fleet_arguments(path: str, count: int, params: list[str], enable: bool) -> list[dict]:
    """Each robot's node arguments: its namespace and its ``--ros-args``
    (rclpy parses the ``-p NAME:=VALUE`` overrides as for one robot; later
    ones win, so the user's come after the fleet's own)."""
    robots = []
    for k, pose in enumerate(start_poses(count), start=1):
        ns = f"robot{k}"
        args = ["--ros-args", "-p", f"robot_config:={path}", "-p", "driver:=sim",
                "-p", f"frame_prefix:={ns}/",
                "-p", "sim.start_pose:=[" + ", ".join(repr(float(v)) for v in pose) + "]"]
        if enable:
            args += ["-p", "enable_on_start:=true"]
        for item in params:
            args += ["-p", item]
        robots.append({"namespace": ns, "cli_args": args})
    return robots


def run_fleet(robot: str, count: int, params: list[str], enable: bool,
              record: str | None = None, foxglove=None) -> int:
    """Run the fleet until SIGINT/SIGTERM; exit code as holonomic-bringup.

    ``foxglove``: a listening Foxglove bridge that serves every robot (each
    under its namespace); the caller closes it."""
    from holonomic_bringup.base_controller_node import run_robots

    try:
        path = str(resolve_config(robot))
    except ConfigError as exc:
        print(f"holonomic-bringup: {exc}", file=sys.stderr)
        return 2
    # not sys.argv: its -p NAME:=VALUE are for the nodes (rcl would read them as
    # deprecated remap rules)
    rclpy.init(args=["holonomic-bringup"], signal_handler_options=SignalHandlerOptions.NO)
    return run_robots(
        fleet_arguments(path, count, params, enable), record=record, foxglove=foxglove,
        prog="holonomic-bringup", shared_world=True,
        label=lambda nodes: f"fleet of {count} {nodes[0].config.model.name} in one simulated "
                            "world: namespaces " + ", ".join(n.get_namespace() for n in nodes))
