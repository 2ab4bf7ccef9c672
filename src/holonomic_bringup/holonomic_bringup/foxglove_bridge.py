"""Foxglove WebSocket bridge: the robot live in Foxglove, no ROS install needed.

``holonomic-bringup ROBOT --foxglove [PORT]`` starts a Foxglove WebSocket
server (``foxglove-sdk``, subprotocol ``foxglove.sdk.v1``) in the bringup's
process. It is fed by the controller, not by ROS: the node hands it a
:class:`RobotSnapshot` (plain numbers) at its publish rate and the diagnostics
once a second, each a single reference assignment in the control loop's
thread. The bridge's own thread encodes and sends at :data:`SEND_RATE`, so
the control loop never waits for a client, and a slow or vanished client
only loses its own messages (the SDK drops the oldest queued ones).

Channels of one robot (relative to its namespace, like its ROS topics; see
docs/foxglove.md for the table):

* ``/tf`` (``foxglove.FrameTransforms``): odom -> base_link, every link of
  the URDF placed from the measured joint positions
  (:mod:`holonomic_core.link_transforms`), and in simulation
  odom -> ``base_link_ground_truth``;
* ``robot_description`` (``std_msgs/msg/String`` as JSON): the URDF, which
  Foxglove's 3D panel loads from that topic name;
* ``path/odom``, ``path/ground_truth`` (``foxglove.PosesInFrame`` in odom);
* ``odom``, ``ground_truth/odom`` (``nav_msgs/msg/Odometry`` as JSON),
  ``twist_command`` (``geometry_msgs/msg/Twist``: the twist the controller
  tracks, after the limits), ``joint_states`` (``sensor_msgs/msg/JointState``),
  ``slip_residual`` (each caster's contact-velocity residual [m/s]),
  ``controller_state`` (armed, fault, emergency stop, stale command, saturation) and
  ``diagnostics`` (``diagnostic_msgs/msg/DiagnosticArray`` as JSON).

The JSON channels keep the ROS field names, so one Foxglove layout plots the
live bridge and an MCAP recording of the ROS topics alike.

Access: the protocol has no authentication. The server listens on
127.0.0.1 unless told otherwise, and is read-only -- no client publishing,
no services, no parameters -- unless ``allow_control``: then, and only then,
a client may publish ``geometry_msgs/Twist`` JSON on the robot's
``cmd_vel`` (Foxglove's Teleop panel does), which goes through the same
``set_command`` as ROS commands (limits, command timeout, arming).
"""

from __future__ import annotations

import json
import math
import sys
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Callable, Sequence

import foxglove
from foxglove.channels import FrameTransformsChannel, PosesInFrameChannel
from foxglove.messages import (FrameTransform, FrameTransforms, Pose, PosesInFrame, Quaternion,
                               Timestamp, Vector3)
from foxglove.websocket import Capability

from holonomic_core.link_transforms import LinkTree
from holonomic_core.se2 import quaternion_of_yaw, wrap_angle

#: the Foxglove app's default port
DEFAULT_PORT = 8765
#: rate [Hz] at which the bridge sends the latest state to clients
SEND_RATE = 30.0
#: the URDF is sent again this often [s] (and at once to a new subscriber)
DESCRIPTION_PERIOD = 5.0
#: a path gets a new pose after this distance [m] or turn [rad] ...
PATH_STEP = (0.01, math.radians(2.0))
#: ... keeps at most this many poses, and is sent at this rate [Hz]
PATH_LENGTH = 2000
PATH_RATE = 5.0
#: suffix of the frame that carries the simulator's ground-truth pose
GROUND_TRUTH_SUFFIX = "_ground_truth"

Planar = tuple[float, float, float]


class BridgeError(RuntimeError):
    """The server could not start (port in use, bad address)."""


@dataclass(frozen=True)
class RobotSnapshot:
    """One robot's state at one instant, handed over by the control loop.

    Poses are (x [m], y [m], yaw [rad]) of base_link in odom; twists
    (vx [m/s], vy [m/s], wz [rad/s]) in base_link; covariances 3x3 over
    (x, y, yaw) as nested tuples; joints in the model's ``joint_names`` order
    [rad, rad/s].
    """

    stamp_ns: int
    pose: Planar
    pose_covariance: tuple
    twist: Planar
    twist_covariance: tuple
    twist_command: Planar
    joint_positions: tuple[float, ...]
    joint_velocities: tuple[float, ...]
    slip_residual: tuple[float, ...]
    state: str
    fault: str | None
    stale: bool
    saturation: float
    truth_pose: Planar | None = None
    truth_twist: Planar | None = None
    estop: str | None = None        #: why the emergency stop is pressed; None: released


@dataclass(frozen=True)
class DiagnosticEntry:
    """One diagnostic_msgs/DiagnosticStatus: level 0 OK, 1 WARN, 2 ERROR, 3 STALE."""

    name: str
    level: int
    message: str
    hardware_id: str
    values: tuple[tuple[str, str], ...]


@dataclass(frozen=True)
class RobotDescription:
    """What the bridge needs to know about one robot, fixed at start.

    ``namespace``: "" or "/robot1" (channel prefix); ``frame_prefix``: "" or
    "robot1/" (prefix of every frame, as on /tf); ``urdf``: its description.
    """

    namespace: str
    frame_prefix: str
    odom_frame: str
    base_frame: str
    urdf: str
    joint_names: tuple[str, ...]
    caster_names: tuple[str, ...] = ()
    has_ground_truth: bool = False      # simulation: serve the true pose, twist, path
    command_sink: Callable[[Planar], None] | None = field(default=None, compare=False)


def _yaw_quaternion(yaw: float) -> dict:
    return dict(zip("xyzw", quaternion_of_yaw(yaw)))


def _stamp(ns: int) -> dict:
    sec, nsec = divmod(ns, 1_000_000_000)
    return {"sec": sec, "nsec": nsec}


def _twist(t: Planar) -> dict:
    return {"linear": {"x": t[0], "y": t[1], "z": 0.0},
            "angular": {"x": 0.0, "y": 0.0, "z": t[2]}}


def _covariance6(cov3) -> list[float]:
    """3x3 (x, y, yaw) covariance into ROS's row-major 6x6 (x y z roll pitch yaw)."""
    full = [0.0] * 36
    index = (0, 1, 5)
    for a, ia in enumerate(index):
        for b, ib in enumerate(index):
            full[ia * 6 + ib] = float(cov3[a][b])
    return full


def odometry_message(stamp_ns: int, odom_frame: str, base_frame: str, pose: Planar,
                     twist: Planar, pose_cov=None, twist_cov=None) -> dict:
    """A nav_msgs/msg/Odometry as a JSON-able dict (Foxglove's field names for time)."""
    zero = ((0.0,) * 3,) * 3
    return {
        "header": {"stamp": _stamp(stamp_ns), "frame_id": odom_frame},
        "child_frame_id": base_frame,
        "pose": {"pose": {"position": {"x": pose[0], "y": pose[1], "z": 0.0},
                          "orientation": _yaw_quaternion(pose[2])},
                 "covariance": _covariance6(pose_cov if pose_cov is not None else zero)},
        "twist": {"twist": _twist(twist),
                  "covariance": _covariance6(twist_cov if twist_cov is not None else zero)},
    }


def _json_schema(properties: dict) -> bytes:
    return json.dumps({"type": "object", "properties": properties}).encode()


_NUMBER = {"type": "number"}
_VECTOR3 = {"type": "object", "properties": {"x": _NUMBER, "y": _NUMBER, "z": _NUMBER}}
_TWIST = {"linear": _VECTOR3, "angular": _VECTOR3}
_TIME = {"type": "object", "properties": {"sec": {"type": "integer"},
                                          "nsec": {"type": "integer"}}}
_HEADER = {"type": "object", "properties": {"stamp": _TIME, "frame_id": {"type": "string"}}}
_POSE_COV = {"type": "object", "properties": {
    "pose": {"type": "object", "properties": {
        "position": _VECTOR3,
        "orientation": {"type": "object", "properties": {
            k: _NUMBER for k in "xyzw"}}}},
    "covariance": {"type": "array", "items": _NUMBER}}}
_TWIST_COV = {"type": "object", "properties": {
    "twist": {"type": "object", "properties": _TWIST},
    "covariance": {"type": "array", "items": _NUMBER}}}
_ARRAY = {"type": "array", "items": _NUMBER}

#: schema name -> JSON schema of the JSON channels (the ROS message's fields)
JSON_SCHEMAS = {
    "std_msgs/msg/String": _json_schema({"data": {"type": "string"}}),
    "nav_msgs/msg/Odometry": _json_schema({"header": _HEADER,
                                           "child_frame_id": {"type": "string"},
                                           "pose": _POSE_COV, "twist": _TWIST_COV}),
    "geometry_msgs/msg/Twist": _json_schema(_TWIST),
    "sensor_msgs/msg/JointState": _json_schema({
        "header": _HEADER, "name": {"type": "array", "items": {"type": "string"}},
        "position": _ARRAY, "velocity": _ARRAY}),
    "diagnostic_msgs/msg/DiagnosticArray": _json_schema({"header": _HEADER, "status": {
        "type": "array", "items": {"type": "object", "properties": {
            "level": {"type": "integer"}, "name": {"type": "string"},
            "message": {"type": "string"}, "hardware_id": {"type": "string"},
            "values": {"type": "array", "items": {"type": "object", "properties": {
                "key": {"type": "string"}, "value": {"type": "string"}}}}}}}}),
    "holonomic/ControllerState": _json_schema({
        "state": {"type": "string"}, "armed": {"type": "boolean"},
        "fault": {"type": "string"}, "stale_command": {"type": "boolean"},
        "saturation": _NUMBER, "estop": {"type": "string"}}),
}


def parse_twist_json(data: bytes) -> Planar:
    """(vx, vy, wz) from a geometry_msgs Twist or TwistStamped as JSON.

    Raises ValueError on anything else (missing fields count as 0, as in a
    ROS message; a non-number is an error). Non-finite values are passed on:
    the controller rejects them and stops the base.
    """
    try:
        msg = json.loads(data)
        if isinstance(msg, dict) and "twist" in msg and "linear" not in msg:
            msg = msg["twist"]
        linear, angular = msg.get("linear", {}), msg.get("angular", {})
        values = (linear.get("x", 0.0), linear.get("y", 0.0), angular.get("z", 0.0))
    except (ValueError, AttributeError, TypeError) as exc:
        raise ValueError(f"not a geometry_msgs/Twist JSON: {exc}") from None
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in values):
        raise ValueError(f"not a geometry_msgs/Twist JSON: {values!r}")
    return tuple(float(v) for v in values)


class RobotFeed:
    """The loop's side of one robot: :meth:`offer` and :meth:`offer_diagnostics`
    store the latest value and return at once (any thread)."""

    def __init__(self, description: RobotDescription):
        self.description = description
        self._latest: RobotSnapshot | None = None
        self._diagnostics: tuple[int, tuple[DiagnosticEntry, ...]] | None = None

    def offer(self, **state) -> None:
        """The robot's state now: the fields of :class:`RobotSnapshot`."""
        self._latest = RobotSnapshot(**state)

    def offer_diagnostics(self, stamp_ns: int, entries: Sequence[tuple]) -> None:
        """Diagnostics at ``stamp_ns`` [ns]: the fields of :class:`DiagnosticEntry` each."""
        self._diagnostics = (stamp_ns, tuple(DiagnosticEntry(*e) for e in entries))

    def take(self):
        """(latest snapshot or None, latest diagnostics or None), each once."""
        snapshot, self._latest = self._latest, None
        diagnostics, self._diagnostics = self._diagnostics, None
        return snapshot, diagnostics


class _Listener:
    """foxglove ServerListener: re-send the URDF to new subscribers; route
    client messages on a robot's cmd_vel (only registered with allow_control)."""

    def __init__(self, bridge: "FoxgloveBridge"):
        self._bridge = bridge
        self._client_topics: dict[tuple[int, int], str] = {}

    def on_subscribe(self, client, channel) -> None:
        self._bridge.subscribed(channel.topic)

    def on_unsubscribe(self, client, channel) -> None:
        return None

    def on_client_advertise(self, client, channel) -> None:
        self._client_topics[(client.id, channel.id)] = channel.topic

    def on_client_unadvertise(self, client, client_channel_id: int) -> None:
        self._client_topics.pop((client.id, client_channel_id), None)

    def on_message_data(self, client, client_channel_id: int, data: bytes) -> None:
        topic = self._client_topics.get((client.id, client_channel_id))
        if topic is not None:
            self._bridge.client_message(topic, data)


class _RobotChannels:
    """The channels of one robot and what is sent on them."""

    def __init__(self, bridge: "FoxgloveBridge", feed: RobotFeed):
        self.feed = feed
        d = feed.description
        ctx = bridge.context
        self.prefix = d.namespace.rstrip("/")
        self.odom_frame = d.frame_prefix + d.odom_frame
        self.base_frame = d.frame_prefix + d.base_frame
        self.truth_frame = self.base_frame + GROUND_TRUTH_SUFFIX
        self.tree = LinkTree.from_urdf(d.urdf)
        self.joint_names = d.joint_names

        def json_channel(rel: str, schema: str):
            return foxglove.Channel(self.topic(rel), message_encoding="json", context=ctx,
                                    schema=foxglove.Schema(name=schema, encoding="jsonschema",
                                                           data=JSON_SCHEMAS[schema]))

        self.description = json_channel("robot_description", "std_msgs/msg/String")
        self.odom = json_channel("odom", "nav_msgs/msg/Odometry")
        self.truth = self.truth_path = None
        if d.has_ground_truth:
            self.truth = json_channel("ground_truth/odom", "nav_msgs/msg/Odometry")
            self.truth_path = PosesInFrameChannel(self.topic("path/ground_truth"), context=ctx)
        self.twist_command = json_channel("twist_command", "geometry_msgs/msg/Twist")
        self.joint_states = json_channel("joint_states", "sensor_msgs/msg/JointState")
        self.state = json_channel("controller_state", "holonomic/ControllerState")
        self.diagnostics = json_channel("diagnostics", "diagnostic_msgs/msg/DiagnosticArray")
        self.slip = None
        if d.caster_names:
            self.slip = foxglove.Channel(
                self.topic("slip_residual"), message_encoding="json", context=ctx,
                schema=foxglove.Schema(name="holonomic/SlipResidual", encoding="jsonschema",
                                       data=_json_schema({n: _NUMBER for n in d.caster_names})))
        self.odom_path = PosesInFrameChannel(self.topic("path/odom"), context=ctx)
        self._paths = {"odom": deque(maxlen=PATH_LENGTH), "truth": deque(maxlen=PATH_LENGTH)}
        self._last_path_pose: dict[str, Planar] = {}
        self._description_sent = -math.inf

    def topic(self, rel: str) -> str:
        return f"{self.prefix}/{rel}"

    # -- sending (bridge thread) ----------------------------------------------------
    def send_description(self, now: float, force: bool) -> None:
        if force or now - self._description_sent >= DESCRIPTION_PERIOD:
            self.description.log({"data": self.feed.description.urdf})
            self._description_sent = now

    def transforms(self, s: RobotSnapshot) -> list:
        """The FrameTransform messages of one snapshot."""
        sec, nsec = divmod(s.stamp_ns, 1_000_000_000)
        stamp = Timestamp(sec, nsec)
        prefix = self.feed.description.frame_prefix

        def planar(parent: str, child: str, pose: Planar):
            return FrameTransform(timestamp=stamp, parent_frame_id=parent, child_frame_id=child,
                                  translation=Vector3(x=pose[0], y=pose[1], z=0.0),
                                  rotation=Quaternion(**_yaw_quaternion(pose[2])))

        out = [planar(self.odom_frame, self.base_frame, s.pose)]
        if s.truth_pose is not None and self.truth is not None:
            out.append(planar(self.odom_frame, self.truth_frame, s.truth_pose))
        positions = dict(zip(self.joint_names, s.joint_positions))
        for link in self.tree.transforms(positions):
            (x, y, z), (qx, qy, qz, qw) = link.translation, link.rotation
            out.append(FrameTransform(timestamp=stamp, parent_frame_id=prefix + link.parent,
                                      child_frame_id=prefix + link.child,
                                      translation=Vector3(x=x, y=y, z=z),
                                      rotation=Quaternion(x=qx, y=qy, z=qz, w=qw)))
        return out

    def send_state(self, s: RobotSnapshot) -> None:
        t = s.stamp_ns
        self.odom.log(odometry_message(t, self.odom_frame, self.base_frame, s.pose, s.twist,
                                       s.pose_covariance, s.twist_covariance), log_time=t)
        if s.truth_pose is not None and self.truth is not None:
            self.truth.log(odometry_message(t, self.odom_frame, self.truth_frame, s.truth_pose,
                                            s.truth_twist or (0.0, 0.0, 0.0)), log_time=t)
        self.twist_command.log(_twist(s.twist_command), log_time=t)
        self.joint_states.log({"header": {"stamp": _stamp(t), "frame_id": ""},
                               "name": list(self.joint_names),
                               "position": list(s.joint_positions),
                               "velocity": list(s.joint_velocities)}, log_time=t)
        self.state.log({"state": s.state, "armed": s.state == "armed", "fault": s.fault or "",
                        "stale_command": s.stale, "saturation": s.saturation,
                        "estop": s.estop or ""}, log_time=t)
        if self.slip is not None:
            self.slip.log(dict(zip(self.feed.description.caster_names, s.slip_residual)),
                          log_time=t)
        self._grow_path("odom", s.pose)
        if s.truth_pose is not None and self.truth is not None:
            self._grow_path("truth", s.truth_pose)

    def _grow_path(self, which: str, pose: Planar) -> None:
        last = self._last_path_pose.get(which)
        if last is not None and math.hypot(pose[0] - last[0], pose[1] - last[1]) < PATH_STEP[0] \
                and abs(wrap_angle(pose[2] - last[2])) < PATH_STEP[1]:
            return
        self._last_path_pose[which] = pose
        self._paths[which].append(Pose(position=Vector3(x=pose[0], y=pose[1], z=0.0),
                                       orientation=Quaternion(**_yaw_quaternion(pose[2]))))

    def send_paths(self, stamp_ns: int) -> None:
        sec, nsec = divmod(stamp_ns, 1_000_000_000)
        for which, channel in (("odom", self.odom_path), ("truth", self.truth_path)):
            if channel is not None and self._paths[which]:
                channel.log(PosesInFrame(timestamp=Timestamp(sec, nsec), frame_id=self.odom_frame,
                                         poses=list(self._paths[which])), log_time=stamp_ns)

    def send_diagnostics(self, stamp_ns: int, entries: Sequence[DiagnosticEntry]) -> None:
        self.diagnostics.log({
            "header": {"stamp": _stamp(stamp_ns), "frame_id": ""},
            "status": [{"level": e.level, "name": e.name, "message": e.message,
                        "hardware_id": e.hardware_id,
                        "values": [{"key": k, "value": v} for k, v in e.values]}
                       for e in entries]}, log_time=stamp_ns)


class FoxgloveBridge:
    """A Foxglove WebSocket server for the robots of one process.

    ``host``/``port``: where to listen (port 0: any free port, see
    :attr:`port`). ``allow_control``: accept ``cmd_vel`` from clients (off:
    read-only). Raises :class:`BridgeError` when the server cannot start.
    Call :meth:`add_robot` for each robot, then :meth:`start`; :meth:`close`
    at the end.
    """

    def __init__(self, host: str = "127.0.0.1", port: int = DEFAULT_PORT,
                 allow_control: bool = False, name: str = "holonomic-bringup"):
        self.host = host
        self.allow_control = allow_control
        self.context = foxglove.Context()
        self._robots: list[_RobotChannels] = []
        self._resend_description: set[str] = set()     # topics, under _lock
        self._lock = threading.Lock()
        self._tf = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._warned_at = -math.inf
        # what sending costs, in this thread's CPU time [s] (tick_cpu: the last ticks)
        self._started: tuple[float, float] | None = None
        self._tick_cpu: deque[float] = deque(maxlen=3000)
        self._cpu_total = 0.0
        listener = _Listener(self)
        try:
            self._server = foxglove.start_server(
                name=name, host=host, port=port, context=self.context,
                server_listener=listener,
                capabilities=[Capability.ClientPublish] if allow_control else [],
                supported_encodings=["json"] if allow_control else None)
        except RuntimeError as exc:
            reason = str(exc).removeprefix("FoxgloveError: ")
            raise BridgeError(f"cannot serve Foxglove on {host}:{port}: {reason}") from None
        self.port = self._server.port

    def add_robot(self, description: RobotDescription) -> RobotFeed:
        """Advertise one robot's channels; returns the feed its loop offers to."""
        if self._tf is None:
            self._tf = FrameTransformsChannel("/tf", context=self.context)
        feed = RobotFeed(description)
        self._robots.append(_RobotChannels(self, feed))
        return feed

    def start(self) -> None:
        """Start sending (a daemon thread at SEND_RATE)."""
        self._thread = threading.Thread(target=self._run, name="foxglove_bridge", daemon=True)
        self._thread.start()

    def _run(self) -> None:
        period = 1.0 / SEND_RATE
        path_every = max(1, round(SEND_RATE / PATH_RATE))
        tick = 0
        deadline = time.monotonic()
        self._started = (time.monotonic(), time.thread_time())
        while not self._stop.is_set():
            deadline += period
            self._stop.wait(max(0.0, deadline - time.monotonic()))
            if time.monotonic() - deadline > 1.0:    # fell far behind: do not catch up
                deadline = time.monotonic()
            tick += 1
            cpu = time.thread_time()
            try:
                self._send(tick % path_every == 0)
            except Exception as exc:   # a bridge fault must never reach the robot
                self._warn(f"foxglove bridge: {exc!r}")
            self._tick_cpu.append(time.thread_time() - cpu)
            self._cpu_total = time.thread_time() - self._started[1]

    def _send(self, paths: bool) -> None:
        now = time.monotonic()
        with self._lock:
            resend, self._resend_description = self._resend_description, set()
        transforms, stamp = [], 0
        for robot in self._robots:
            robot.send_description(now, robot.description.topic() in resend)
            snapshot, diagnostics = robot.feed.take()
            if diagnostics is not None:
                robot.send_diagnostics(*diagnostics)
            if snapshot is None:
                continue
            stamp = max(stamp, snapshot.stamp_ns)
            transforms += robot.transforms(snapshot)
            robot.send_state(snapshot)
            if paths:
                robot.send_paths(snapshot.stamp_ns)
        if transforms:
            self._tf.log(FrameTransforms(transforms=transforms), log_time=stamp)

    def subscribed(self, topic: str) -> None:
        """A client subscribed to ``topic`` (server thread): a robot
        description is sent again at the next tick, not in 5 s."""
        with self._lock:
            self._resend_description.add(topic)

    def client_message(self, topic: str, data: bytes) -> None:
        """A client's message on ``topic`` (server thread; only with
        allow_control): a Twist for a robot's cmd_vel, else ignored."""
        for robot in self._robots:
            sink = robot.feed.description.command_sink
            if sink is not None and topic.lstrip("/") == robot.topic("cmd_vel").lstrip("/"):
                try:
                    sink(parse_twist_json(data))
                except ValueError as exc:
                    self._warn(f"foxglove bridge: {topic}: {exc}")
                return

    def _warn(self, text: str) -> None:
        # throttled: a client flooding bad messages must not flood the log
        now = time.monotonic()
        if now - self._warned_at >= 1.0:
            self._warned_at = now
            print(text, file=sys.stderr)

    def cost(self) -> str | None:
        """One line: the sending thread's CPU use (its share of one core, and
        per tick p50/p99 [ms]) since :meth:`start` -- what the bridge takes
        from the process that runs the control loop. None before a first tick."""
        if self._started is None or not self._tick_cpu:
            return None
        ticks = sorted(self._tick_cpu)
        wall = time.monotonic() - self._started[0]
        return (f"Foxglove bridge: CPU {100.0 * self._cpu_total / wall:.2f} % of a core over "
                f"{wall:.0f} s; per tick p50 {1e3 * ticks[len(ticks) // 2]:.3f} ms, "
                f"p99 {1e3 * ticks[int(0.99 * (len(ticks) - 1))]:.3f} ms")

    def summary(self) -> str:
        """One line for the log: where, and what clients may do."""
        text = (f"Foxglove: ws://{self.host}:{self.port} "
                + ("(clients may publish cmd_vel)" if self.allow_control else "(read-only)"))
        if not self.host.startswith("127.") and self.host not in ("localhost", "::1"):
            text += ("; listening beyond this machine: anyone who reaches the port sees "
                     "the robot" + (" and can drive it" if self.allow_control else ""))
        return text

    def close(self) -> None:
        """Stop sending and stop the server (idempotent)."""
        self._stop.set()
        if self._thread is not None:
            self._thread.join(2.0)
            self._thread = None
        if self._server is not None:
            self._server.stop()
            self._server = None
