"""The base controller node: a thin ROS shell around holonomic_core.

Parameters -> a validated RobotConfig; the driver and the BaseController run
in the robot's control loop process (:mod:`loop_host`, docs/realtime.md),
which this node starts through a :class:`~loop_client.LoopClient`. Messages
in -> the loop's command pipe and request socket; the loop's state records
(every ``publish_rate`` cycle) -> odometry, /tf, joint states (and, with the
simulator, ground truth and /clock), published from the client's reader
thread; its status (``BaseController.status``, once a second) ->
diagnostics. A loop that ends or hangs is reported as an ERROR. The robot's URDF
(the one the simulator is built from) is latched on ``robot_description``;
with ``publish_link_tf`` every link's transform (from the measured joint
positions) goes on /tf too. :meth:`BaseControllerNode.attach_foxglove` hands
the same state to a Foxglove bridge (``--foxglove``). :func:`run_robots` is
the one runner of ``holonomic-bringup``, for a robot and for ``--fleet``.

The robot's YAML is named by the ``robot_config`` parameter (a config name or
a path); every key of it can be overridden with ROS parameters
(``--ros-args -p cmd_timeout:=1.0`` or ``--params-file``). Without
``robot_config`` the node takes its whole configuration from the ROS
parameter overrides (``ros2 run ... --ros-args --params-file config/hamr.yaml``).
"""

from __future__ import annotations

import gc
import math
import sys
import time

import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry as OdometryMsg
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage

from holonomic_core.command_stamp import stamped_command_age
from holonomic_core.config import config_from_flat, read_params_file, resolve_config
from holonomic_core.controller import ControllerState
from holonomic_core.description import generate_urdf
from holonomic_core.limits import is_finite_twist
from holonomic_core.link_transforms import LinkTree
from holonomic_core.schema import ConfigError, ParamSpec
from holonomic_core.se2 import quaternion_of_yaw
from holonomic_bringup import loop_wire as wire
from holonomic_bringup.loop_client import LoopClient, LoopLost
from holonomic_bringup.packed_messages import PackedMessage
from holonomic_bringup.safety_inputs import SafetyInputs, estop_diagnostic
from holonomic_bringup.process_guard import (STOP, InstanceConflict, InstanceLock,
                                             install_signal_handlers)

NODE_NAME = "base_controller"
#: parameters that are not part of the robot config
_NOT_CONFIG = ("robot_config", "use_sim_time", "start_type_description_service")

_PARAM_TYPES = {
    "double": ParameterType.PARAMETER_DOUBLE,
    "int": ParameterType.PARAMETER_INTEGER,
    "bool": ParameterType.PARAMETER_BOOL,
    "string": ParameterType.PARAMETER_STRING,
    "double_array": ParameterType.PARAMETER_DOUBLE_ARRAY,
    "string_array": ParameterType.PARAMETER_STRING_ARRAY,
}
#: twist covariance entries of the planar components (x, y, yaw) in a 6x6
_PLANAR = (0, 1, 5)
#: where a 3x3 (x, y, yaw) covariance, row-major, goes in a 6x6 row-major one
_PLANAR_IN_6X6 = tuple(a * 6 + b for a in _PLANAR for b in _PLANAR)
#: the numbers of an odometry message that change (_odometry_values)
_ODOM_PATHS = ("header.stamp.sec", "header.stamp.nanosec", "pose.pose.position.x",
               "pose.pose.position.y", "pose.pose.orientation.z", "pose.pose.orientation.w",
               *(f"pose.covariance[{i}]" for i in _PLANAR_IN_6X6),
               "twist.twist.linear.x", "twist.twist.linear.y", "twist.twist.angular.z",
               *(f"twist.covariance[{i}]" for i in _PLANAR_IN_6X6))
#: ground truth: an odometry message without covariances
_TRUTH_PATHS = tuple(p for p in _ODOM_PATHS if "covariance" not in p)
#: variance of the components a planar base does not move in (z, roll, pitch)
_PLANAR_LOCKED_VARIANCE = 1e-9
_SERVICE_TIMEOUT = 2.0  # [s] for the loop to execute a request
#: a state record's state index -> the state (loop_host writes the index)
_STATES = tuple(ControllerState)


def descriptor(spec: ParamSpec) -> ParameterDescriptor:
    """ROS parameter descriptor (type, description, range, read-only) of a spec."""
    text = spec.description
    if spec.choices:
        text += f" One of: {', '.join(spec.choices)}."
    desc = ParameterDescriptor(name=spec.name, type=_PARAM_TYPES[spec.type],
                               description=text, read_only=spec.read_only,
                               additional_constraints=f"allowed: {spec.allowed()}")
    if spec.minimum is not None and spec.maximum is not None:
        if spec.type == "double":
            desc.floating_point_range = [FloatingPointRange(
                from_value=float(spec.minimum), to_value=float(spec.maximum), step=0.0)]
        elif spec.type == "int":
            desc.integer_range = [IntegerRange(
                from_value=int(spec.minimum), to_value=int(spec.maximum), step=1)]
    return desc


def _stamp_parts(seconds: float) -> tuple[int, int]:
    """A time [s] as a builtin_interfaces/Time's (sec, nanosec)."""
    sec = math.floor(seconds)
    return int(sec), min(int((seconds - sec) * 1e9), 999_999_999)


def _odometry_template(frame_id: str, child_frame_id: str,
                       covariance: bool = True) -> OdometryMsg:
    """An Odometry in ``frame_id`` of ``child_frame_id``; with ``covariance``
    the planar base's fixed numbers, the locked variances (z, roll, pitch) on
    both covariances' diagonals (ground truth: none). Everything
    :data:`_ODOM_PATHS` names is zero."""
    msg = OdometryMsg()
    msg.header.frame_id, msg.child_frame_id = frame_id, child_frame_id
    for cov in (msg.pose.covariance, msg.twist.covariance) if covariance else ():
        for i in (2, 3, 4):
            cov[i * 7] = _PLANAR_LOCKED_VARIANCE
    return msg


def _odometry_values(sec: int, nanosec: int, pose, pose_cov9, twist, twist_cov9) -> list:
    """The numbers of :data:`_ODOM_PATHS`: ``pose`` (x, y, yaw) [m, m, rad]
    and ``twist`` (vx, vy, wz) [m/s, m/s, rad/s], their 3x3 covariances
    row-major (9 numbers each)."""
    _, _, qz, qw = quaternion_of_yaw(pose[2])
    return [sec, nanosec, pose[0], pose[1], qz, qw, *pose_cov9,
            twist[0], twist[1], twist[2], *twist_cov9]


def _transform_paths(prefix: str) -> tuple[str, ...]:
    """The numbers of a TransformStamped at ``prefix`` (a link's, from the URDF)."""
    return (f"{prefix}.header.stamp.sec", f"{prefix}.header.stamp.nanosec",
            *(f"{prefix}.transform.translation.{a}" for a in "xyz"),
            *(f"{prefix}.transform.rotation.{a}" for a in "xyzw"))


class BaseControllerNode(Node):
    """See the module docstring. Raises ConfigError (clean message) on bad config."""

    def __init__(self, start_loop: bool = True, publish_clock: bool = True, **kwargs):
        """``start_loop``: start this robot's own control loop (see
        :mod:`loop_client`); False when the caller runs one loop for several
        nodes (the fleet) and hands each its link with :meth:`attach`.
        ``publish_clock``: publish /clock with the simulator (the fleet: its
        first robot only)."""
        # every override (command line, params files, ``parameter_overrides``)
        # declared, so that the node can read them through the public API
        kwargs.setdefault("automatically_declare_parameters_from_overrides", True)
        super().__init__(NODE_NAME, **kwargs)
        self._logged_fault: str | None = None
        self._publish_clock = publish_clock
        self._instance_lock: InstanceLock | None = None
        self.loop: LoopClient | None = None     # this node's own loop (start_loop)
        self.link = None
        self._status = None            # the latest ControllerStatus
        self._latest = None            # the latest StateRecord
        self._lost_logged = False
        try:
            self._configure()
            if start_loop:
                values = self.config.values
                self.loop = LoopClient([self.loop_setup()], process=values["loop.process"],
                                       watchdog_timeout=values["loop.watchdog_timeout"])
                self.loop.start()
                self.attach(self.loop.links[0])
        except BaseException:
            if self.loop is not None:
                self.loop.stop()
            if self._instance_lock is not None:
                self._instance_lock.release()
            raise

    def _configure(self) -> None:
        self.config, self._flat = self._load_config()
        self._declare_config_parameters()
        # After the configuration is known valid (a bad config says so, exit
        # 2) and before the driver exists: a second controller must not even
        # open the motors' bus (raises InstanceConflict).
        self._instance_lock = InstanceLock(self.get_fully_qualified_name())
        ctrl = self.config.controller
        prefix = self.config.values["frame_prefix"]
        self._odom_frame, self._base_frame = prefix + ctrl.odom_frame, prefix + ctrl.base_frame
        self._publish_tf = ctrl.publish_tf
        self._foxglove = None   # a foxglove_bridge.RobotFeed, see attach_foxglove

    def loop_setup(self) -> tuple[dict, str, object]:
        """What a :class:`LoopClient` needs to run this robot: its flat
        config (file + overrides), the config's source, the robot model."""
        return dict(self._flat), self.config.source, self.config.model

    def attach(self, link) -> None:
        """Connect to this robot's control loop (a started ``RobotLink``):
        create the topics and services and start publishing its state."""
        model, ctrl = self.config.model, self.config.controller
        self.link = link
        self._sim = bool(link.info["sim"])
        # Simulated time is reported on an epoch = the wall clock at start, so
        # sim stamps and the stamps of nodes on system time agree while the
        # simulator runs in real time.
        self._epoch = time.time() if self._sim else 0.0
        self._make_interfaces(link.info)
        for level, text in link.early_logs:
            self._on_loop_log(level, text)
        link.on_log = self._on_loop_log
        link.on_status = self._on_status
        link.on_lost = self._on_lost
        link.on_record = self._on_record
        where = "its own process" if self.loop is None or self.loop.process else "a thread"
        self.get_logger().info(
            f"{model.name} ({model.kind}) on driver '{ctrl.driver}' at {ctrl.control_rate:g} Hz "
            f"(control loop in {where}); "
            f"motors {'arming' if ctrl.enable_on_start else 'DISARMED (call ~/enable)'}")

    # -- configuration ------------------------------------------------------------
    def _load_config(self):
        """The robot config (file + the ROS parameter overrides) and its flat dict."""
        declared = self.get_parameters_by_prefix("")
        source_param = declared.get("robot_config")
        source = source_param.value if source_param is not None else ""
        if source_param is not None:
            # re-declared below with its read-only descriptor
            self.undeclare_parameter("robot_config")
        self.declare_parameter("robot_config", source or "", ParameterDescriptor(
            type=ParameterType.PARAMETER_STRING, read_only=True,
            description="Robot config: a name from config/ (hamr, xr4000, comr3) or a YAML "
                        "path. Empty: take the whole configuration from parameter overrides."))
        overrides = {name: p.value for name, p in declared.items()
                     if name not in _NOT_CONFIG and not name.startswith("qos_overrides.")}
        if source:
            path = resolve_config(source)
            flat = read_params_file(path)
        else:
            path, flat = "<parameters>", {}
            if not overrides:
                raise ConfigError("robot_config", "", "a config name (hamr, xr4000, comr3) or a "
                                  "YAML path: --ros-args -p robot_config:=hamr, or the whole "
                                  "configuration through --ros-args --params-file FILE")
        flat.update(overrides)
        return config_from_flat(flat, str(path)), flat

    def _declare_config_parameters(self) -> None:
        for spec in self.config.specs:
            value = self.config.values[spec.name]
            if isinstance(value, tuple):
                value = list(value)
            if self.has_parameter(spec.name):     # an override, declared without a schema
                self.undeclare_parameter(spec.name)
            if value is None:       # an optional key left unset: typed, without a value
                value = Parameter.Type(_PARAM_TYPES[spec.type])
            self.declare_parameter(spec.name, value, descriptor(spec), ignore_override=True)
        names = {spec.name for spec in self.config.specs}
        for name in self._flat:
            # keys of the backends not in use (``sim.*`` on a real robot):
            # allowed in the config, not parameters of this node
            if name not in names and self.has_parameter(name) and name not in _NOT_CONFIG:
                self.undeclare_parameter(name)

    # -- ROS interfaces -------------------------------------------------------------
    def _make_interfaces(self, info) -> None:
        ctrl, model = self.config.controller, self.config.model
        # Only the latest command matters: a queue of one, so that a flood of
        # commands never builds a backlog (of memory or of stale motion).
        cmd_qos = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
        if ctrl.cmd_vel_stamped:
            self.create_subscription(TwistStamped, "cmd_vel", self._on_cmd_vel_stamped, cmd_qos)
        else:
            self.create_subscription(Twist, "cmd_vel", self._on_cmd_vel, cmd_qos)
        self.odom_pub = self.create_publisher(OdometryMsg, "odom", 10)
        self.tf_pub = self.create_publisher(TFMessage, "/tf", 100)
        self.joint_pub = self.create_publisher(JointState, "joint_states", 10)
        self.diag_pub = self.create_publisher(DiagnosticArray, "diagnostics", 10)
        self.gt_pub = self.create_publisher(OdometryMsg, "ground_truth/odom", 10) \
            if info["ground_truth"] else None
        self.clock_pub = self.create_publisher(Clock, "/clock", 10) \
            if self._sim and self._publish_clock else None
        # The URDF the simulator uses, latched, for rviz (robot_state_publisher
        # is not needed for the base's own frames: odom -> base_link is on /tf).
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.description_pub = self.create_publisher(String, "robot_description", latched)
        self.urdf = generate_urdf(self.config.model)
        self.description_pub.publish(String(data=self.urdf))
        self.create_service(Trigger, "~/reset_odometry", self._on_reset_odometry)
        self.create_service(Trigger, "~/unwind", self._on_unwind)
        self.create_service(SetBool, "~/enable", self._on_enable)
        # emergency_stop and set_pose (holonomic_bringup.safety_inputs)
        self._safety_inputs = SafetyInputs(self, self.link)

        # Every cycle's messages have a fixed layout (names, frames, array
        # lengths): serialized once, each publish writes only the numbers
        # (packed_messages: 40 % less of the node's CPU per cycle, docs/realtime.md).
        self._odom_out = PackedMessage(
            self.odom_pub, _odometry_template(self._odom_frame, self._base_frame), _ODOM_PATHS)
        self._truth_out = None if self.gt_pub is None else PackedMessage(
            self.gt_pub, _odometry_template(self._odom_frame, self._base_frame, False),
            _TRUTH_PATHS)
        # /tf: odom -> base_link (publish_tf), then with publish_link_tf
        # parent -> child of every URDF joint
        transforms, paths = [], []
        if self._publish_tf:
            transforms.append(TransformStamped())
            transforms[-1].header.frame_id = self._odom_frame
            transforms[-1].child_frame_id = self._base_frame
            paths += [f"transforms[0].{path}" for path in (
                "header.stamp.sec", "header.stamp.nanosec", "transform.translation.x",
                "transform.translation.y", "transform.rotation.z", "transform.rotation.w")]
        self._link_tree = LinkTree.from_urdf(self.urdf) if ctrl.publish_link_tf else None
        if self._link_tree is not None:
            prefix = self.config.values["frame_prefix"]
            for joint in self._link_tree.joints:
                paths += _transform_paths(f"transforms[{len(transforms)}]")
                transforms.append(TransformStamped())
                transforms[-1].header.frame_id = prefix + joint.parent
                transforms[-1].child_frame_id = prefix + joint.child
        self._tf_out = PackedMessage(self.tf_pub, TFMessage(transforms=transforms),
                                     tuple(paths)) if transforms else None
        # joint states: with efforts, or (a driver that reports none) without
        n = len(model.joint_names)
        names = ("position", "velocity", "effort")
        self._joints_out = []
        for fields in (names[:2], names):
            joints = JointState(name=list(model.joint_names))
            for name in fields:
                setattr(joints, name, [0.0] * n)
            self._joints_out.append(PackedMessage(self.joint_pub, joints, (
                "header.stamp.sec", "header.stamp.nanosec",
                *(f"{name}[{i}]" for name in fields for i in range(n)))))
        for out in (self._odom_out, self._truth_out, self._tf_out, *self._joints_out):
            if out is not None and not out.packed:
                self.get_logger().warn(f"publishing {out.type_name} as messages (slower): "
                                       f"{out.why_plain}", once=True)

    def _on_cmd_vel(self, msg: Twist) -> None:
        self._accept((msg.linear.x, msg.linear.y, msg.angular.z), None)

    def _on_cmd_vel_stamped(self, msg: TwistStamped) -> None:
        twist = msg.twist
        received = None
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if stamp > 0.0:  # an all-zero stamp means "unstamped": use the arrival time
            age, problem = stamped_command_age(self.get_clock().now().nanoseconds * 1e-9, stamp,
                                               self.config.controller.cmd_timeout)
            if problem is not None:
                self.get_logger().warn(problem, throttle_duration_sec=1.0)
                return
            received = time.monotonic() - age
        self._accept((twist.linear.x, twist.linear.y, twist.angular.z), received)

    def _accept(self, twist, received) -> None:
        """Hand a command to the loop; the loop's controller validates it
        again (and counts); here only what the user should read in the log."""
        try:
            values = tuple(float(v) for v in (twist[0], twist[1], twist[2]))
            malformed = any(isinstance(v, bool) for v in (twist[0], twist[1], twist[2]))
        except (TypeError, ValueError, OverflowError, IndexError, KeyError):
            values, malformed = (math.nan,) * 3, True
        if malformed:
            values = (math.nan,) * 3
        self.link.send_command(values, time.monotonic() if received is None else received)
        if not is_finite_twist(values):
            what = "malformed" if malformed else "non-finite"
            self.get_logger().warn(f"{what} command {repr(twist)[:80]} rejected; stopping the "
                                   "base", throttle_duration_sec=1.0)
            return
        state = self._state()
        if any(values) and state is not ControllerState.ARMED:
            fault = self._status.fault if self._status is not None else None
            self.get_logger().warn(
                f"cmd_vel received while the motors are {state.value.upper()}"
                f"{f' ({fault})' if fault else ''}: the base does not move (arm with "
                "`holonomic-ctl enable` or the ~/enable service)",
                throttle_duration_sec=5.0)

    def _state(self) -> ControllerState:
        """The controller's state as last reported by the loop."""
        if self.loop_lost() is not None:
            return ControllerState.FAULT
        record, status = self._latest, self._status
        if record is not None:
            return _STATES[record.state_index]
        return status.state if status is not None else ControllerState.DISARMED

    def loop_lost(self) -> str | None:
        """Why this robot's control loop is not running (None while it runs)."""
        return None if self.link is None else self.link.client.lost

    def _wait(self, future):
        try:
            return future.result(timeout=_SERVICE_TIMEOUT)
        except Exception:  # the loop is stopped or stuck
            return False, "the control loop did not answer within 2 s"

    def _on_enable(self, request, response):
        response.success, response.message = self._wait(self.link.request_enable(request.data))
        self.get_logger().info(f"~/enable {request.data}: {response.message}")
        return response

    def _on_reset_odometry(self, request, response):
        response.success, response.message = self._wait(self.link.request_reset_odometry())
        return response

    def _on_unwind(self, request, response):
        # answers once the maneuver starts; diagnostics report its progress
        response.success, response.message = self._wait(self.link.request_unwind())
        self.get_logger().info(f"~/unwind: {response.message}")
        return response

    # -- from the loop (the loop client's reader thread) ----------------------------
    def _on_record(self, record) -> None:
        self._latest = record
        if self._sim:
            stamp = _stamp_parts(self._epoch + record.stamp)
            if self.clock_pub is not None and record.flags & wire.CLOCK:
                self.clock_pub.publish(Clock(clock=TimeMsg(sec=stamp[0], nanosec=stamp[1])))
        else:
            # map the driver's monotonic stamp onto ROS time
            now = self.get_clock().now().nanoseconds * 1e-9
            stamp = _stamp_parts(now - (time.monotonic() - record.stamp))
        if record.flags & wire.PUBLISH:
            self._publish_state(stamp, record)

    def _on_loop_log(self, level: str, text: str) -> None:
        log = self.get_logger()
        if level == "error":
            log.error(text, throttle_duration_sec=1.0)
        elif level == "warn":
            log.warn(text)
        else:
            log.info(text)

    def _publish_state(self, stamp: tuple[int, int], record) -> None:
        """Odometry, /tf, joint states (and ground truth) of one state record
        at ``stamp`` (sec, nanosec)."""
        sec, nanosec = stamp
        # the record's numbers as Python floats, once (layout: loop_wire)
        values, layout = record.data.tolist(), record.layout
        pose = values[layout.pose]
        self._odom_out.publish(_odometry_values(
            sec, nanosec, pose, values[layout.pose_cov], values[layout.twist],
            values[layout.twist_cov]))
        if self._tf_out is not None:
            tf_values = []
            if self._publish_tf:
                _, _, qz, qw = quaternion_of_yaw(pose[2])
                tf_values += (sec, nanosec, pose[0], pose[1], qz, qw)
            if self._link_tree is not None:
                tf_values += self._link_values(sec, nanosec, values[layout.positions])
            self._tf_out.publish(tf_values)
        efforts = values[layout.efforts]
        with_efforts = not all(math.isnan(e) for e in efforts)
        self._joints_out[with_efforts].publish(
            [sec, nanosec, *values[layout.positions], *values[layout.velocities],
             *(efforts if with_efforts else ())])
        if self._truth_out is not None and values[layout.truth_valid]:
            truth = values[layout.truth_pose]
            self._truth_out.publish(_odometry_values(
                sec, nanosec, truth, (), values[layout.truth_twist], ()))
        if self._foxglove is not None:
            self._offer_foxglove(sec * 1_000_000_000 + nanosec, record)

    def _link_values(self, sec: int, nanosec: int, positions: list) -> list:
        """publish_link_tf: the numbers of parent -> child of every URDF joint
        at ``positions`` [rad] (_transform_paths' order)."""
        links = self._link_tree.transforms(dict(zip(self.config.model.joint_names, positions)))
        out = []
        for link in links:
            out += (sec, nanosec, *link.translation, *link.rotation)
        return out

    # -- Foxglove -------------------------------------------------------------------
    def attach_foxglove(self, bridge) -> None:
        """Serve this robot on a ``foxglove_bridge.FoxgloveBridge``; with its
        ``allow_control``, client Twists on cmd_vel go to :meth:`_accept`."""
        from holonomic_bringup.foxglove_bridge import RobotDescription

        ctrl = self.config.controller
        namespace = self.get_namespace()
        self._foxglove = bridge.add_robot(RobotDescription(
            namespace="" if namespace == "/" else namespace,
            frame_prefix=self.config.values["frame_prefix"], odom_frame=ctrl.odom_frame,
            base_frame=ctrl.base_frame, urdf=self.urdf,
            joint_names=tuple(self.config.model.joint_names),
            caster_names=tuple(self._unit_names()), has_ground_truth=self.gt_pub is not None,
            command_sink=(lambda twist: self._accept(twist, None))
            if bridge.allow_control else None))

    def _offer_foxglove(self, stamp_ns: int, record) -> None:
        # the reader thread's whole cost: copy plain numbers, hand over a reference
        status = self._status
        truth_pose, truth_twist = record.truth_pose, record.truth_twist
        self._foxglove.offer(
            stamp_ns=stamp_ns,
            pose=tuple(record.pose.tolist()),
            pose_covariance=tuple(record.pose_covariance.tolist()),
            twist=tuple(record.twist.tolist()),
            twist_covariance=tuple(record.twist_covariance.tolist()),
            twist_command=tuple(record.twist_command.tolist()),
            joint_positions=tuple(record.positions.tolist()),
            joint_velocities=tuple(record.velocities.tolist()),
            slip_residual=tuple(record.residual.tolist()),
            state=_STATES[record.state_index].value,
            fault=status.fault if status is not None else None, stale=record.stale,
            saturation=record.saturation,
            truth_pose=None if truth_pose is None else tuple(truth_pose.tolist()),
            truth_twist=None if truth_twist is None else tuple(truth_twist.tolist()),
            estop=status.estop if status is not None else None)

    # -- diagnostics ------------------------------------------------------------------
    def _on_status(self, status, loop: dict) -> None:
        """The loop's status (once a second): diagnostics."""
        self._status = status
        if status.fault and status.fault != self._logged_fault:
            # once per fault: the cause belongs in the log, not only in diagnostics
            self.get_logger().error(f"motors stopped: {status.fault}")
        self._logged_fault = status.fault
        period_ms = 1e3 / self.config.controller.control_rate
        loop_level = DiagnosticStatus.OK if loop["period_p99_ms"] <= 2.0 * period_ms \
            else DiagnosticStatus.WARN
        statuses = [
            self._driver_status(status),
            self._status_msg(f"{NODE_NAME}: control loop", loop_level,
                             f"{loop['rate_hz']:.1f} Hz, p99 period {loop['period_p99_ms']:.2f} ms",
                             {k: f"{v:.3f}" if isinstance(v, float) else str(v)
                              for k, v in loop.items()}),
            self._command_status(status),
            self._odometry_status(status),
            self._status_msg(f"{NODE_NAME}: emergency stop", *estop_diagnostic(status)),
        ]
        if status.drift_findings is not None:
            # its own status: a geometry that drifted is not a slip event
            findings = status.drift_findings
            statuses.append(self._status_msg(
                f"{NODE_NAME}: calibration",
                DiagnosticStatus.WARN if findings else DiagnosticStatus.OK,
                findings[0] if findings else
                "configured geometry consistent with the motion" if status.drift_judged else
                "not enough motion yet to judge the geometry", dict(status.drift_values)))
        self._publish_diagnostics(statuses)

    def _on_lost(self, reason: str) -> None:
        """The loop ended or hung (once a second while it is down): ERROR."""
        if not self._lost_logged:
            self.get_logger().error(f"motors stopped: {reason}")
            self._lost_logged = True
        driver = self.config.controller.driver
        how = ("the simulation stopped with it" if self._sim else
               "the drives' own watchdogs stop the motors")
        values = {"controller_state": ControllerState.FAULT.value, "fault": reason,
                  "backend": driver}
        self._publish_diagnostics([
            self._status_msg(f"{NODE_NAME}: driver", DiagnosticStatus.ERROR,
                             f"{reason}; {how}", values),
            self._status_msg(f"{NODE_NAME}: control loop", DiagnosticStatus.ERROR, reason,
                             {"rate_hz": "0.000"}),
        ])

    def _publish_diagnostics(self, statuses) -> None:
        now = self.get_clock().now().to_msg()
        for status in statuses:
            status.hardware_id = self.config.model.name
        self.diag_pub.publish(DiagnosticArray(header=Header(stamp=now), status=statuses))
        if self._foxglove is not None:
            self._foxglove.offer_diagnostics(now.sec * 1_000_000_000 + now.nanosec, [
                (s.name, ord(s.level), s.message, s.hardware_id,
                 tuple((kv.key, kv.value) for kv in s.values)) for s in statuses])

    def _driver_status(self, status) -> DiagnosticStatus:
        level = DiagnosticStatus.ERROR if status.state is ControllerState.FAULT \
            else DiagnosticStatus.OK
        values = dict(status.driver)
        values["controller_state"] = status.state.value
        values["driver_errors"] = str(status.driver_errors)
        values["implausible_readings"] = str(status.implausible_readings)
        values["dropped_readings"] = str(status.dropped_readings)
        if status.last_dropped:
            values["last_dropped"] = status.last_dropped
        if status.fault:
            values["fault"] = status.fault
        return self._status_msg(f"{NODE_NAME}: driver", level, status.fault or
                                f"{self.config.controller.driver} {status.state.value}", values)

    def _command_status(self, status) -> DiagnosticStatus:
        age = status.command_age
        values = {
            "command_age_s": f"{age:.3f}" if math.isfinite(age) else "none",
            "stale": str(status.stale), "timeouts": str(status.timeouts),
            "rejected_commands": str(status.rejected_commands),
            "saturation_scale": f"{status.saturation:.3f}",
            "twist_command": " ".join(f"{v:.3f}" for v in status.twist_command),
            "commands_while_disarmed": str(status.commands_while_disarmed),
        }
        if status.range_limited:
            values["range_limited_joints"] = " ".join(status.range_limited)
        if status.unwind is not None:
            values["unwind"] = status.unwind
        # WARN while commands arrive that the disarmed motors cannot follow
        # (within the last 2 diagnostics periods)
        if status.commanded_while_disarmed:
            return self._status_msg(f"{NODE_NAME}: command", DiagnosticStatus.WARN,
                                    f"commands received while {status.state.value}: not moving "
                                    "(holonomic-ctl enable)", values)
        if status.range_limited:
            # the motion would wind a joint past its range: slowed, or stopped
            return self._status_msg(
                f"{NODE_NAME}: command", DiagnosticStatus.WARN,
                "slowed to stop at the end of the range of " + ", ".join(status.range_limited)
                + " (motions that turn it back are accepted; holonomic-ctl unwind)", values)
        if status.unwinding:
            return self._status_msg(f"{NODE_NAME}: command", DiagnosticStatus.OK,
                                    f"unwinding ({status.unwind})", values)
        return self._status_msg(f"{NODE_NAME}: command", DiagnosticStatus.OK,
                                "stale: stopping" if status.stale else "tracking", values)

    def _odometry_status(self, status) -> DiagnosticStatus:
        values = {"estimator": status.estimator, "distance_m": f"{status.distance:.3f}"}
        for name, value in zip(self._unit_names(), status.residual):
            values[f"slip_residual_{name}_m_s"] = f"{value:.4f}"
        # a caster above the threshold for a while: WARN naming it
        level, message = DiagnosticStatus.OK, f"{status.estimator}, {status.distance:.2f} m"
        if status.slipping:
            level = DiagnosticStatus.WARN
            message = "slipping: " + ", ".join(
                f"caster {name} residual above {status.slip_threshold:g} m/s for {seconds:.1f} s"
                for name, seconds in status.slipping)
            values["slipping_casters"] = " ".join(name for name, _ in status.slipping)
        return self._status_msg(f"{NODE_NAME}: odometry", level, message, values)

    def _unit_names(self):
        kin = self.config.model.kinematics
        return getattr(kin, "caster_names", ())

    @staticmethod
    def _status_msg(name, level, message, values) -> DiagnosticStatus:
        return DiagnosticStatus(level=level, name=name, message=message,
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def shutdown(self) -> None:
        """Stop the loop (it stops and disarms the motors, closes the driver)."""
        if self.loop is not None:
            self.loop.stop()
        if self._instance_lock is not None:
            self._instance_lock.release()


def main(argv: list[str] | None = None, record: str | None = None, foxglove=None) -> int:
    """Run the node until SIGINT/SIGTERM; exit 0 after stopping the motors.

    ``record``: an MCAP file to record the robot's topics to; ``foxglove``: a
    listening ``foxglove_bridge.FoxgloveBridge`` to serve the robot on (the
    caller closes it). Exit 2 with a
    one-line message on an invalid configuration, 3 when the same controller
    already runs (same namespace and ROS domain).
    """
    install_signal_handlers()   # before anything slow: a signal at any moment
    argv = sys.argv if argv is None else argv
    # Our own signal handling: rclpy's would shut the context down before we
    # have stopped the motors.
    try:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
    except rclpy_implementation.RCLError as exc:   # malformed --ros-args or params file
        print(f"{NODE_NAME}: invalid ROS arguments: {str(exc).splitlines()[0]}", file=sys.stderr)
        return 2
    if STOP.is_set():
        rclpy.try_shutdown()
        return 0
    return run_robots([{}], record=record, foxglove=foxglove, prog=NODE_NAME)


def switch_interval(control_rate: float) -> float:
    """The interpreter's thread switch interval [s] for a node whose loop
    runs at ``control_rate`` [Hz]: a fifth of a period, at most 0.5 ms. The
    reader thread publishes every cycle and the executor thread runs the
    cmd_vel callback: each must get the interpreter lock back from the
    other well within a period (Python's default is 5 ms)."""
    return min(5e-4, 0.2 / control_rate)


def run_robots(robots: list[dict], record: str | None = None, foxglove=None,
               prog: str = NODE_NAME, shared_world: bool = False, label=None) -> int:
    """The runner of ``holonomic-bringup``, for one robot and for a fleet:
    a node per robot (``robots``: the keyword arguments of each
    :class:`BaseControllerNode`, e.g. ``namespace`` and ``cli_args``), one
    control loop for all of them (``shared_world``: the fleet's one
    simulation), the executor, recorder and Foxglove bridge, until
    SIGINT/SIGTERM. rclpy is initialised by the caller and shut down here.
    Exit codes as :func:`main`."""
    nodes: list[BaseControllerNode] = []
    client: LoopClient | None = None
    executor = SingleThreadedExecutor()
    recorder = None
    try:
        for k, kwargs in enumerate(robots):
            where = f"{kwargs['namespace']}: " if len(robots) > 1 else ""
            try:
                nodes.append(BaseControllerNode(start_loop=False, publish_clock=k == 0,
                                                **kwargs))
            except ConfigError as exc:
                print(f"{prog}: {where}configuration error: {exc}", file=sys.stderr)
                return 2
            except InstanceConflict as exc:
                print(f"{prog}: {where}refusing to start: {exc}", file=sys.stderr)
                return 3
            except rclpy_implementation.RCLError as exc:   # a malformed -p of the fleet
                print(f"{prog}: {where}invalid ROS arguments: {str(exc).splitlines()[0]}",
                      file=sys.stderr)
                return 2
        first = nodes[0].config.values
        if shared_world and (first["driver"] != "sim" or first["sim.gui"]):
            print(f"{prog}: --fleet is simulation only and runs headless (driver sim, "
                  "no sim.gui)", file=sys.stderr)
            return 2
        client = LoopClient([n.loop_setup() for n in nodes], process=first["loop.process"],
                            shared_world=shared_world,
                            watchdog_timeout=first["loop.watchdog_timeout"])
        try:
            client.start()
        except ConfigError as exc:
            print(f"{prog}: configuration error: {exc}", file=sys.stderr)
            return 2
        except LoopLost as exc:
            print(f"{prog}: {exc}", file=sys.stderr)
            return 1
        for node, link in zip(nodes, client.links):
            node.attach(link)
            executor.add_node(node)
        sys.setswitchinterval(switch_interval(nodes[0].config.controller.control_rate))
        # Everything built so far lives for the whole run: out of the garbage
        # collector's way, so that its full collections stay short.
        gc.freeze()
        if record:
            from holonomic_bringup.recorder import McapRecorder
            try:
                recorder = McapRecorder(nodes[0], record, [
                    (n.get_namespace(), dict(n.config.values),
                     n.config.controller.cmd_vel_stamped) for n in nodes])
            except OSError as exc:
                print(f"{prog}: cannot record to {record}: {exc}", file=sys.stderr)
                return 2
            nodes[0].get_logger().info(f"recording to {record}")
        if foxglove is not None:
            for node in nodes:
                node.attach_foxglove(foxglove)
            foxglove.start()
            nodes[0].get_logger().info(foxglove.summary())
        if label is not None:
            nodes[0].get_logger().info(label(nodes))
        while not STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    finally:
        if client is not None:
            client.stop()
        for node in nodes:
            node.shutdown()
        if nodes and client is not None:
            nodes[0].get_logger().info(
                ("fleet: " if len(nodes) > 1 else "") + "motors stopped and disarmed; exiting")
        if recorder is not None:
            recorder.close()
            nodes[0].get_logger().info(f"wrote {recorder.count} messages to {record}")
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
