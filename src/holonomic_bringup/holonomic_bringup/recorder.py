"""Recording a running robot to MCAP (``holonomic-bringup --record run.mcap``).

A node in the bringup's process subscribes to the robot's topics with raw
(serialized CDR) subscriptions and writes every message unchanged, with the
ROS 2 message definitions as ``ros2msg`` schemas and each channel's
publishers' QoS as ``offered_qos_profiles`` metadata -- the layout rosbag2's
MCAP storage uses, so Foxglove, ``ros2 bag`` (which re-latches
``robot_description`` from that metadata) and the ``mcap`` tools open the file.
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


def _duration(nanoseconds: int) -> dict:
    """An rmw_time_t as rosbag2 writes it (``{sec, nsec}``); rclpy reports an
    unset (infinite) duration as 2**63 - 1 ns = RMW_DURATION_INFINITE."""
    return {"sec": nanoseconds // 1_000_000_000, "nsec": nanoseconds % 1_000_000_000}


def offered_qos_yaml(profiles) -> str:
    """rosbag2's ``offered_qos_profiles`` text (rosbag2_storage's qos.cpp,
    metadata version 9): a YAML list with one mapping per publisher -- history,
    depth, reliability, durability, deadline, lifespan, liveliness,
    liveliness_lease_duration, avoid_ros_namespace_conventions -- policies as
    rmw's lower-case names (``keep_last``, ``transient_local``...).
    ``profiles``: rclpy QoSProfiles (e.g. ``TopicEndpointInfo.qos_profile``)."""
    return yaml.safe_dump([{
        "history": p.history.name.lower(),
        "depth": int(p.depth),
        "reliability": p.reliability.name.lower(),
        "durability": p.durability.name.lower(),
        "deadline": _duration(p.deadline.nanoseconds),
        "lifespan": _duration(p.lifespan.nanoseconds),
        "liveliness": p.liveliness.name.lower(),
        "liveliness_lease_duration": _duration(p.liveliness_lease_duration.nanoseconds),
        "avoid_ros_namespace_conventions": bool(p.avoid_ros_namespace_conventions),
    } for p in profiles], sort_keys=False, default_flow_style=False)


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
        # robot_description is latched (transient local); the rest as published
        durable = topic.endswith("robot_description")
        qos = QoSProfile(depth=1 if durable else 100, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL if durable
                         else DurabilityPolicy.VOLATILE)
        channel: list[int] = []

        def write(data: bytes) -> None:
            if not channel:
                # Registered at the first message, like rosbag2 registers a
                # topic once it has discovered its publishers: their offered
                # QoS goes into the channel's metadata, from which `ros2 bag
                # play` chooses its own (and re-latches robot_description).
                profiles = [info.qos_profile for info in
                            self.node.get_publishers_info_by_topic(topic)]
                channel.append(self._writer.register_channel(
                    topic, "cdr", self._schemas[type_name],
                    metadata={"offered_qos_profiles": offered_qos_yaml(profiles)}))
            now = time.time_ns()
            self._writer.add_message(channel[0], log_time=now, data=data, publish_time=now)
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
