"""Recording a running robot to MCAP (``holonomic-bringup --record run.mcap``).

A node in the bringup's process subscribes to the robot's topics with raw
(serialized CDR) subscriptions and writes every message unchanged, with the
ROS 2 message definitions as ``ros2msg`` schemas -- the layout rosbag2's MCAP
storage uses, so Foxglove, ``ros2 bag`` and the ``mcap`` tools open the file.
Each robot's validated configuration is stored as MCAP metadata
(``holonomic_robot``), so ``holonomic-plot`` can recompute per-wheel slip
residuals from the recorded joint states with the very same model.
"""

from __future__ import annotations

import os
import re
import time
from pathlib import Path
from typing import Iterable

import yaml
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

#: (relative topic, message type name) recorded for each robot
ROBOT_TOPICS = (
    ("cmd_vel", None),            # Twist or TwistStamped: filled in by the caller
    ("odom", "nav_msgs/msg/Odometry"),
    ("joint_states", "sensor_msgs/msg/JointState"),
    ("ground_truth/odom", "nav_msgs/msg/Odometry"),
    ("diagnostics", "diagnostic_msgs/msg/DiagnosticArray"),
    ("robot_description", "std_msgs/msg/String"),
)
GLOBAL_TOPICS = (("/tf", "tf2_msgs/msg/TFMessage"),)

_PRIMITIVES = {"bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16",
               "int32", "uint32", "int64", "uint64", "string", "wstring"}
_SEPARATOR = "=" * 80


def _msg_file(package: str, name: str) -> Path:
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        path = Path(prefix) / "share" / package / "msg" / f"{name}.msg"
        if path.is_file():
            return path
    raise FileNotFoundError(f"no definition of {package}/msg/{name} in AMENT_PREFIX_PATH")


def _field_types(text: str, package: str) -> list[tuple[str, str]]:
    """(package, name) of every non-primitive field type in a .msg text."""
    found = []
    for line in text.splitlines():
        parts = line.split("#", 1)[0].split()
        if len(parts) < 2:
            continue
        if "=" in parts[1] or (len(parts) > 2 and parts[2].startswith("=")):
            continue                                    # a constant: "uint8 OK = 0"
        base = re.sub(r"\[.*\]$", "", parts[0])
        base = re.sub(r"<=\d+$", "", base)
        if base in _PRIMITIVES:
            continue
        if base == "Header":
            found.append(("std_msgs", "Header"))
        elif "/" in base:
            pieces = base.split("/")
            found.append((pieces[0], pieces[-1]))
        else:
            found.append((package, base))
    return found


def message_definition(type_name: str) -> str:
    """The ``ros2msg`` schema text of ``pkg/msg/Type``: its .msg file, then
    every type it uses, each after a separator line and ``MSG: pkg/Type``."""
    package, _, name = type_name.split("/")
    main = _msg_file(package, name).read_text()
    seen, order, todo = set(), [], _field_types(main, package)
    while todo:
        dep = todo.pop(0)
        if dep in seen:
            continue
        seen.add(dep)
        text = _msg_file(*dep).read_text()
        order.append((dep, text))
        todo.extend(_field_types(text, dep[0]))
    parts = [main.rstrip("\n")]
    for (pkg, dep_name), text in order:
        parts.append(f"{_SEPARATOR}\nMSG: {pkg}/{dep_name}\n{text.rstrip(chr(10))}")
    return "\n".join(parts) + "\n"


def _message_class(type_name: str):
    import importlib
    package, _, name = type_name.split("/")
    return getattr(importlib.import_module(f"{package}.msg"), name)


class McapRecorder:
    """Writes the topics of one or more robots to ``path`` from ``node``.

    ``robots``: ``(namespace, config_values, cmd_vel_stamped)`` per robot.
    Call :meth:`close` to finish the file (its index and summary).
    """

    def __init__(self, node, path: str | os.PathLike,
                 robots: Iterable[tuple[str, dict, bool]]):
        from mcap.writer import Writer
        self.node = node
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = open(self.path, "wb")
        self._writer = Writer(self._file)
        self._writer.start(profile="ros2", library="holonomic_bringup")
        self._schemas: dict[str, int] = {}
        self._subs = []
        self.count = 0
        topics = list(GLOBAL_TOPICS)
        for namespace, values, stamped in robots:
            prefix = "/" + namespace.strip("/") if namespace.strip("/") else ""
            for rel, type_name in ROBOT_TOPICS:
                if type_name is None:
                    type_name = ("geometry_msgs/msg/TwistStamped" if stamped
                                 else "geometry_msgs/msg/Twist")
                topics.append((f"{prefix}/{rel}", type_name))
            self._writer.add_metadata("holonomic_robot", {
                "namespace": prefix or "/",
                "config": yaml.safe_dump({"base_controller": {"ros__parameters": {
                    k: list(v) if isinstance(v, tuple) else v for k, v in values.items()}}}),
            })
        for topic, type_name in topics:
            self._add(topic, type_name)

    def _add(self, topic: str, type_name: str) -> None:
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                type_name, "ros2msg", message_definition(type_name).encode())
        channel = self._writer.register_channel(topic, "cdr", self._schemas[type_name])
        # robot_description is latched (transient local); the rest as published
        durable = topic.endswith("robot_description")
        qos = QoSProfile(depth=1 if durable else 100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if durable
                         else DurabilityPolicy.VOLATILE)

        def write(data: bytes, channel=channel) -> None:
            now = time.time_ns()
            self._writer.add_message(channel, log_time=now, data=data, publish_time=now)
            self.count += 1

        self._subs.append(self.node.create_subscription(
            _message_class(type_name), topic, write, qos, raw=True))

    def close(self) -> None:
        """Stop recording and finish the file (idempotent)."""
        for sub in self._subs:
            self.node.destroy_subscription(sub)
        self._subs = []
        if not self._file.closed:
            self._writer.finish()
            self._file.close()
