"""``holonomic-bringup ROBOT --fleet N``: N simulated robots in one world.

Every robot is a full base controller node in its own namespace (``robot1``
... ``robotN``: topics, services, the node and the frames ``robotK/odom``,
``robotK/base_link``), commanded on its own ``robotK/cmd_vel``. They share
one pybullet world -- the robots can collide -- stepped by one fixed-rate
loop: physics once per control period, then each robot's control cycle.
One robot's failure (a fault, an exception in its cycle) stops that robot
only. The first robot publishes ``/clock``.
"""

from __future__ import annotations

import gc
import sys

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter
from rclpy.signals import SignalHandlerOptions

from holonomic_core.config import load_config, resolve_config
from holonomic_core.loop import ControlLoop
from holonomic_core.schema import ConfigError
from holonomic_bringup.process_guard import STOP, InstanceConflict

#: distance [m] between neighbouring robots' start poses, along world y
SPACING = 2.0


def _value(text: str):
    import yaml
    return yaml.safe_load(text)


def start_poses(count: int, spacing: float = SPACING) -> list[tuple[float, float, float]]:
    """Start poses (x, y, yaw) in the world: a row along y centred on 0."""
    return [(0.0, spacing * (k - (count - 1) / 2.0), 0.0) for k in range(count)]


def run_fleet(robot: str, count: int, params: list[str], enable: bool,
              record: str | None = None, foxglove=None) -> int:
    """Run the fleet until SIGINT/SIGTERM; exit code as holonomic-bringup.

    ``foxglove``: a listening Foxglove bridge that serves every robot (each
    under its namespace); the caller closes it."""
    from holonomic_bringup.base_controller_node import BaseControllerNode
    from holonomic_sim.world import SimWorld

    overrides = {}
    for item in params:
        name, _, text = item.partition(":=")
        overrides[name] = _value(text)
    try:
        path = str(resolve_config(robot))
        cfg = load_config(path, {**overrides, "driver": "sim"})
    except ConfigError as exc:
        print(f"holonomic-bringup: {exc}", file=sys.stderr)
        return 2
    if cfg.values["sim.gui"]:
        print("holonomic-bringup: --fleet runs headless (sim.gui is not supported)",
              file=sys.stderr)
        return 2
    rclpy.init(args=None, signal_handler_options=SignalHandlerOptions.NO)
    world = SimWorld(cfg.values["sim.physics_rate"])
    nodes: list[BaseControllerNode] = []
    executor = SingleThreadedExecutor()
    loop = None
    recorder = None
    try:
        for k, pose in enumerate(start_poses(count), start=1):
            ns = f"robot{k}"
            node_params = [Parameter("robot_config", value=path),
                           Parameter("driver", value="sim"),
                           Parameter("frame_prefix", value=f"{ns}/"),
                           Parameter("sim.start_pose", value=list(pose))]
            if enable:
                node_params.append(Parameter("enable_on_start", value=True))
            node_params += [Parameter(name, value=value) for name, value in overrides.items()]
            try:
                node = BaseControllerNode(world=world, start_loop=False, namespace=ns,
                                          parameter_overrides=node_params)
            except ConfigError as exc:
                print(f"holonomic-bringup: {ns}: configuration error: {exc}", file=sys.stderr)
                return 2
            except InstanceConflict as exc:
                print(f"holonomic-bringup: {ns}: refusing to start: {exc}", file=sys.stderr)
                return 3
            if nodes:
                node.clock_pub = None
            nodes.append(node)
            executor.add_node(node)
        world.settle()
        # as base_controller_node.main(): the GIL back to the loop sooner,
        # and the long-lived objects out of the garbage collector's way
        sys.setswitchinterval(min(5e-4, 0.2 / cfg.controller.control_rate))
        gc.freeze()
        substeps = round(cfg.values["sim.physics_rate"] / cfg.controller.control_rate)

        def cycle() -> None:
            world.step(substeps)
            for node in nodes:
                try:
                    node.control_cycle()
                except Exception as exc:   # this robot stops; the others go on
                    node._on_loop_error(exc)

        loop = ControlLoop(1.0 / cfg.controller.control_rate, cycle, name="fleet_loop")
        loop.start()
        if record:
            from holonomic_bringup.recorder import McapRecorder
            try:
                recorder = McapRecorder(nodes[0], record, [
                    (n.get_namespace(), dict(n.config.values),
                     n.config.controller.cmd_vel_stamped) for n in nodes])
            except OSError as exc:
                print(f"holonomic-bringup: cannot record to {record}: {exc}", file=sys.stderr)
                return 2
        if foxglove is not None:
            for node in nodes:
                node.attach_foxglove(foxglove)
            foxglove.start()
            nodes[0].get_logger().info(foxglove.summary())
        nodes[0].get_logger().info(
            f"fleet of {count} {cfg.model.name} in one simulated world: namespaces "
            + ", ".join(n.get_namespace() for n in nodes))
        while not STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    finally:
        if loop is not None:
            loop.stop()
        for node in nodes:
            node.shutdown()
        if recorder is not None:
            recorder.close()
        if nodes:
            nodes[0].get_logger().info("fleet: motors stopped and disarmed; exiting")
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        world.close()
        rclpy.try_shutdown()
    return 0
