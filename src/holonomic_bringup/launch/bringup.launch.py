"""ros2 launch holonomic_bringup bringup.launch.py robot:=hamr [driver:=sim]
[namespace:=NS] [params_file:=FILE] [enable:=false]

The full-ROS equivalent of ``holonomic-bringup ROBOT``: the base controller
node (which owns the driver, so with driver:=sim the simulator runs inside
it), with the same arguments and the same namespace and frame-prefix rules.
Recording: ``ros2 bag record -s mcap ...`` on a full install, or
``holonomic-bringup --record``. DDS discovery stays on this machine
(ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST) unless a range is exported.
"""

import os

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

ARGUMENTS = (
    ("robot", "hamr", "config name (hamr, xr4000, comr3) or a robot YAML path"),
    ("driver", "", "driver backend: sim, mock, odrive_can, cia402 (default: the config's)"),
    ("namespace", "", "namespace of the robot's node, topics and frames"),
    ("params_file", "", "extra ROS 2 params file overriding the robot config"),
    ("enable", "false", "arm the motors at start"),
)


def _node(context):
    arg = {name: LaunchConfiguration(name).perform(context) for name, _, _ in ARGUMENTS}
    ns = arg["namespace"].strip("/")
    params = {"robot_config": arg["robot"]}
    if arg["driver"]:
        params["driver"] = arg["driver"]
    if ns:
        params["frame_prefix"] = f"{ns}/"
    if arg["enable"].lower() in ("true", "1", "yes"):
        params["enable_on_start"] = True
    parameters = [params] + ([arg["params_file"]] if arg["params_file"] else [])
    return [Node(package="holonomic_bringup", executable="base_controller",
                 name="base_controller", namespace=ns, parameters=parameters,
                 output="screen", emulate_tty=True, additional_env=discovery_env(os.environ))]


def discovery_env(environ) -> dict:
    """DDS stays on this machine unless the user exported a discovery range
    (e.g. SUBNET for a robot driven from another machine): the same default
    the holonomic-* programs apply."""
    if environ.get("ROS_AUTOMATIC_DISCOVERY_RANGE"):
        return {}
    return {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}


def generate_launch_description():
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, default, text in ARGUMENTS] + [OpaqueFunction(function=_node)])
