"""The base controller node: a thin ROS shell around holonomic_core.

Parameters -> a validated RobotConfig -> driver + BaseController; messages in
-> ``BaseController.set_command``; the control loop thread runs
``BaseController.step`` at ``control_rate`` and publishes odometry, /tf,
joint states, diagnostics (and, with the simulator, ground truth and /clock)
from the same thread, decimated to ``publish_rate`` / 1 Hz. The robot's URDF
(the one the simulator is built from) is latched on ``robot_description``;
with ``publish_link_tf`` every link's transform (from the measured joint
positions) goes on /tf too. :meth:`BaseControllerNode.attach_foxglove` hands
the same state to a Foxglove bridge (``--foxglove``).

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

import numpy as np
import rclpy
from builtin_interfaces.msg import Time as TimeMsg
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TransformStamped, Twist, TwistStamped
from nav_msgs.msg import Odometry as OdometryMsg
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, ParameterType
from rclpy.executors import SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import Header, String
from std_srvs.srv import SetBool, Trigger
from tf2_msgs.msg import TFMessage

from holonomic_core.config import config_from_flat, read_params_file, resolve_config
from holonomic_core.controller import BaseController, ControllerState
from holonomic_core.description import generate_urdf
from holonomic_core.driver import DriverError
from holonomic_core.link_transforms import LinkTree
from holonomic_core.loop import ControlLoop
from holonomic_core.schema import ConfigError, ParamSpec
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
#: variance of the components a planar base does not move in (z, roll, pitch)
_PLANAR_LOCKED_VARIANCE = 1e-9
_SERVICE_TIMEOUT = 2.0  # [s] for the loop to execute a request


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


def _stamp(seconds: float) -> TimeMsg:
    sec = math.floor(seconds)
    return TimeMsg(sec=int(sec), nanosec=min(int((seconds - sec) * 1e9), 999_999_999))


def _yaw_quaternion(msg_orientation, yaw: float) -> None:
    msg_orientation.x = 0.0
    msg_orientation.y = 0.0
    msg_orientation.z = math.sin(0.5 * yaw)
    msg_orientation.w = math.cos(0.5 * yaw)


def _fill_covariance(target, cov3: np.ndarray) -> None:
    """Write a 3x3 (x, y, yaw) covariance into a 6x6 row-major ROS array."""
    full = [0.0] * 36
    for i in (2, 3, 4):
        full[i * 7] = _PLANAR_LOCKED_VARIANCE
    for a, ia in enumerate(_PLANAR):
        for b, ib in enumerate(_PLANAR):
            full[ia * 6 + ib] = float(cov3[a, b])
    target[:] = full


class BaseControllerNode(Node):
    """See the module docstring. Raises ConfigError (clean message) on bad config."""

    def __init__(self, world=None, start_loop: bool = True, **kwargs):
        """``world``: a shared simulated world (a fleet in one simulation; the
        ``sim`` driver then does not step it). ``start_loop``: False when the
        caller runs :meth:`control_cycle` itself (the fleet's one loop)."""
        super().__init__(NODE_NAME, **kwargs)
        self._logged_fault: str | None = None
        self._world = world
        self._start_loop = start_loop
        self._instance_lock: InstanceLock | None = None
        try:
            self._configure()
        except BaseException:
            if self._instance_lock is not None:
                self._instance_lock.release()
            raise

    def _configure(self) -> None:
        self.declare_parameter("robot_config", "", ParameterDescriptor(
            type=ParameterType.PARAMETER_STRING, read_only=True,
            description="Robot config: a name from config/ (hamr, xr4000, comr3) or a YAML "
                        "path. Empty: take the whole configuration from parameter overrides."))
        self.config = self._load_config()
        model, ctrl = self.config.model, self.config.controller
        self._declare_config_parameters()

        # After the configuration is known valid (a bad config says so, exit
        # 2) and before the driver exists: a second controller must not even
        # open the motors' bus (raises InstanceConflict).
        self._instance_lock = InstanceLock(self.get_fully_qualified_name())

        # driver + core
        extra = {"world": self._world} if self._world is not None else {}
        self.driver = self.config.driver_class(model, self.config.values, ctrl.control_rate,
                                               **extra)
        try:
            self.driver.configure()
        except DriverError as exc:
            self.driver.close()
            raise ConfigError("driver", ctrl.driver, f"a backend that configures ({exc})") from exc
        self.controller = BaseController(self.config, self.driver)
        self._sim = self.driver.sim_time() is not None
        # Simulated time is reported on an epoch = the wall clock at start, so
        # sim stamps and the stamps of nodes on system time agree while the
        # simulator runs in real time.
        self._epoch = time.time() if self._sim else 0.0

        prefix = self.config.values["frame_prefix"]
        self._odom_frame, self._base_frame = prefix + ctrl.odom_frame, prefix + ctrl.base_frame
        self._publish_tf = ctrl.publish_tf
        self._foxglove = None   # a foxglove_bridge.RobotFeed, see attach_foxglove
        self._publish_every = max(1, round(ctrl.control_rate / ctrl.publish_rate))
        self._clock_every = max(1, round(ctrl.control_rate / 250.0))
        self._diag_every = max(1, round(ctrl.control_rate))
        self._cycle = 0

        self._make_interfaces()
        self.loop = ControlLoop(1.0 / ctrl.control_rate, self.control_cycle,
                                on_error=self._on_loop_error, name=f"{NODE_NAME}_loop")
        self._loop_errors = 0
        if ctrl.enable_on_start:
            self.controller.request_enable(True)
        if self._start_loop:
            self.loop.start()
        self.get_logger().info(
            f"{model.name} ({model.kind}) on driver '{ctrl.driver}' at {ctrl.control_rate:g} Hz; "
            f"motors {'arming' if ctrl.enable_on_start else 'DISARMED (call ~/enable)'}")

    # -- configuration ------------------------------------------------------------
    def _load_config(self):
        source = self.get_parameter("robot_config").value
        # rclpy has no public accessor for the overrides it parsed from the
        # command line / params files: _parameter_overrides is that dict.
        overrides = {name: p.value for name, p in self._parameter_overrides.items()
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
        return config_from_flat(flat, str(path))

    def _declare_config_parameters(self) -> None:
        for spec in self.config.specs:
            value = self.config.values[spec.name]
            if isinstance(value, tuple):
                value = list(value)
            self.declare_parameter(spec.name, value, descriptor(spec), ignore_override=True)

    # -- ROS interfaces -------------------------------------------------------------
    def _make_interfaces(self) -> None:
        ctrl = self.config.controller
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
            if self.driver.ground_truth() is not None else None
        self.clock_pub = self.create_publisher(Clock, "/clock", 10) if self._sim else None
        # The URDF the simulator uses, latched, for rviz (robot_state_publisher
        # is not needed for the base's own frames: odom -> base_link is on /tf).
        latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                             durability=DurabilityPolicy.TRANSIENT_LOCAL)
        self.description_pub = self.create_publisher(String, "robot_description", latched)
        self.urdf = generate_urdf(self.config.model)
        self.description_pub.publish(String(data=self.urdf))
        self.create_service(Trigger, "~/reset_odometry", self._on_reset_odometry)
        self.create_service(SetBool, "~/enable", self._on_enable)

        self._odom_msg = OdometryMsg()
        self._odom_msg.header.frame_id = self._odom_frame
        self._odom_msg.child_frame_id = self._base_frame
        self._tf = TransformStamped()
        self._tf.header.frame_id = self._odom_frame
        self._tf.child_frame_id = self._base_frame
        # publish_link_tf: one TransformStamped per URDF joint, reused each cycle
        self._link_tree = LinkTree.from_urdf(self.urdf) if ctrl.publish_link_tf else None
        self._link_tfs = []
        if self._link_tree is not None:
            prefix = self.config.values["frame_prefix"]
            for joint in self._link_tree.joints:
                tf = TransformStamped()
                tf.header.frame_id = prefix + joint.parent
                tf.child_frame_id = prefix + joint.child
                self._link_tfs.append(tf)
        self._joint_msg = JointState()
        self._joint_msg.name = list(self.config.model.joint_names)

    def _on_cmd_vel(self, msg: Twist) -> None:
        self._accept((msg.linear.x, msg.linear.y, msg.angular.z), None)

    def _on_cmd_vel_stamped(self, msg: TwistStamped) -> None:
        twist = msg.twist
        received = None
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        if stamp > 0.0:  # an all-zero stamp means "unstamped": use the arrival time
            age = self.get_clock().now().nanoseconds * 1e-9 - stamp
            timeout = self.controller.cmd_timeout
            if age < -0.1 or (timeout > 0.0 and age > timeout):
                self.get_logger().warn(
                    f"cmd_vel stamped {age:+.3f} s from now rejected (allowed: -0.1 s to "
                    f"cmd_timeout={timeout:g} s old)", throttle_duration_sec=1.0)
                return
            received = time.monotonic() - max(age, 0.0)
        self._accept((twist.linear.x, twist.linear.y, twist.angular.z), received)

    def _accept(self, twist, received) -> None:
        ignored = self.controller.counters["commands_while_disarmed"]
        error = self.controller.set_command(twist, received)
        if error:
            self.get_logger().warn(error, throttle_duration_sec=1.0)
        elif self.controller.counters["commands_while_disarmed"] != ignored:
            fault = self.controller.fault
            self.get_logger().warn(
                f"cmd_vel received while the motors are {self.controller.state.value.upper()}"
                f"{f' ({fault})' if fault else ''}: the base does not move (arm with "
                "`holonomic-ctl enable` or the ~/enable service)",
                throttle_duration_sec=5.0)

    def _wait(self, future):
        try:
            return future.result(timeout=_SERVICE_TIMEOUT)
        except Exception:  # the loop is stopped or stuck
            return False, "the control loop did not answer within 2 s"

    def _on_enable(self, request, response):
        response.success, response.message = self._wait(
            self.controller.request_enable(request.data))
        self.get_logger().info(f"~/enable {request.data}: {response.message}")
        return response

    def _on_reset_odometry(self, request, response):
        response.success, response.message = self._wait(
            self.controller.request_reset_odometry())
        return response

    # -- the loop thread ----------------------------------------------------------
    def control_cycle(self) -> None:
        controller = self.controller
        controller.step()
        self._loop_errors = 0
        self._cycle += 1
        reading = controller.reading
        if reading is None:
            if self._cycle % self._diag_every == 0:
                self._publish_diagnostics()
            return
        if self._sim:
            stamp = _stamp(self._epoch + reading.stamp)
            if self.clock_pub is not None and self._cycle % self._clock_every == 0:
                self.clock_pub.publish(Clock(clock=stamp))
        else:
            # map the driver's monotonic stamp onto ROS time
            now = self.get_clock().now().nanoseconds * 1e-9
            stamp = _stamp(now - (time.monotonic() - reading.stamp))
        if self._cycle % self._publish_every == 0:
            self._publish_state(stamp, reading)
        if self._cycle % self._diag_every == 0:
            self._publish_diagnostics()

    def _publish_state(self, stamp: TimeMsg, reading) -> None:
        odo = self.controller.odometry
        x, y, yaw = (float(v) for v in odo.pose)
        msg = self._odom_msg
        msg.header.stamp = stamp
        msg.pose.pose.position.x = x
        msg.pose.pose.position.y = y
        _yaw_quaternion(msg.pose.pose.orientation, yaw)
        _fill_covariance(msg.pose.covariance, odo.pose_covariance)
        msg.twist.twist.linear.x = float(odo.twist[0])
        msg.twist.twist.linear.y = float(odo.twist[1])
        msg.twist.twist.angular.z = float(odo.twist[2])
        _fill_covariance(msg.twist.covariance, odo.twist_covariance)
        self.odom_pub.publish(msg)
        transforms = []
        if self._publish_tf:
            tf = self._tf
            tf.header.stamp = stamp
            tf.transform.translation.x = x
            tf.transform.translation.y = y
            _yaw_quaternion(tf.transform.rotation, yaw)
            transforms.append(tf)
        if self._link_tree is not None:
            transforms += self._link_transforms(stamp, reading.positions)
        if transforms:
            self.tf_pub.publish(TFMessage(transforms=transforms))
        joints = self._joint_msg
        joints.header.stamp = stamp
        joints.position = reading.positions.tolist()
        joints.velocity = reading.velocities.tolist()
        joints.effort = [] if np.all(np.isnan(reading.efforts)) else reading.efforts.tolist()
        self.joint_pub.publish(joints)
        truth = self.driver.ground_truth() if self.gt_pub is not None else None
        if truth is not None:
            self._publish_ground_truth(stamp, truth)
        if self._foxglove is not None:
            self._offer_foxglove(stamp, reading, truth)

    def _link_transforms(self, stamp: TimeMsg, positions) -> list[TransformStamped]:
        """publish_link_tf: parent -> child of every URDF joint at ``positions`` [rad]."""
        links = self._link_tree.transforms(dict(zip(self.config.model.joint_names,
                                                    positions.tolist())))
        for tf, link in zip(self._link_tfs, links):
            tf.header.stamp = stamp
            t, q = tf.transform.translation, tf.transform.rotation
            t.x, t.y, t.z = link.translation
            q.x, q.y, q.z, q.w = link.rotation
        return self._link_tfs

    def _publish_ground_truth(self, stamp: TimeMsg, truth) -> None:
        msg = OdometryMsg()
        msg.header.stamp = stamp
        msg.header.frame_id = self._odom_frame
        msg.child_frame_id = self._base_frame
        msg.pose.pose.position.x = float(truth.pose[0])
        msg.pose.pose.position.y = float(truth.pose[1])
        _yaw_quaternion(msg.pose.pose.orientation, float(truth.pose[2]))
        msg.twist.twist.linear.x = float(truth.twist[0])
        msg.twist.twist.linear.y = float(truth.twist[1])
        msg.twist.twist.angular.z = float(truth.twist[2])
        self.gt_pub.publish(msg)

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

    def _offer_foxglove(self, stamp: TimeMsg, reading, truth) -> None:
        # the loop's whole cost: copy plain numbers and hand over a reference
        c, odo = self.controller, self.controller.odometry
        self._foxglove.offer(
            stamp_ns=stamp.sec * 1_000_000_000 + stamp.nanosec,
            pose=tuple(odo.pose.tolist()), pose_covariance=tuple(odo.pose_covariance.tolist()),
            twist=tuple(odo.twist.tolist()),
            twist_covariance=tuple(odo.twist_covariance.tolist()),
            twist_command=tuple(c.twist_command.tolist()),
            joint_positions=tuple(reading.positions.tolist()),
            joint_velocities=tuple(reading.velocities.tolist()),
            slip_residual=tuple(np.asarray(odo.residual).tolist()),
            state=c.state.value, fault=c.fault, stale=c.stale, saturation=float(c.saturation),
            truth_pose=None if truth is None else tuple(truth.pose.tolist()),
            truth_twist=None if truth is None else tuple(truth.twist.tolist()))

    def _publish_diagnostics(self) -> None:
        c = self.controller
        robot = self.config.model.name
        state = c.state
        now = self.get_clock().now().to_msg()
        level_driver = DiagnosticStatus.ERROR if state is ControllerState.FAULT else DiagnosticStatus.OK
        driver_values = dict(self.driver.status())
        driver_values["controller_state"] = state.value
        driver_values["driver_errors"] = str(c.counters["driver_errors"])
        driver_values["implausible_readings"] = str(c.counters["implausible_readings"])
        if c.fault:
            driver_values["fault"] = c.fault
        if c.fault and c.fault != self._logged_fault:
            # once per fault: the cause belongs in the log, not only in diagnostics
            self.get_logger().error(f"motors stopped: {c.fault}")
        self._logged_fault = c.fault
        loop = self.loop.stats.summary()
        period_ms = 1e3 / self.config.controller.control_rate
        loop_level = DiagnosticStatus.OK if loop["period_p99_ms"] <= 2.0 * period_ms \
            else DiagnosticStatus.WARN
        age = c.command_age()
        cmd_values = {
            "command_age_s": f"{age:.3f}" if math.isfinite(age) else "none",
            "stale": str(c.stale), "timeouts": str(c.counters["timeouts"]),
            "rejected_commands": str(c.counters["rejected_commands"]),
            "saturation_scale": f"{c.saturation:.3f}",
            "twist_command": " ".join(f"{v:.3f}" for v in c.twist_command),
        }
        odo = c.odometry
        odo_values = {"estimator": odo.estimator, "distance_m": f"{odo.distance:.3f}"}
        for name, value in zip(self._unit_names(), odo.residual):
            odo_values[f"slip_residual_{name}_m_s"] = f"{value:.4f}"
        # a caster above the threshold for a while: WARN naming it
        slipping = c.slip_monitor.slipping(c.reading.stamp) if c.reading is not None else []
        limits = c.slip_monitor.limits
        odo_level, odo_message = DiagnosticStatus.OK, f"{odo.estimator}, {odo.distance:.2f} m"
        if slipping:
            odo_level = DiagnosticStatus.WARN
            odo_message = "slipping: " + ", ".join(
                f"caster {name} residual above {limits.threshold:g} m/s for {seconds:.1f} s"
                for name, seconds in slipping)
            odo_values["slipping_casters"] = " ".join(name for name, _ in slipping)
        statuses = [
            self._status(f"{NODE_NAME}: driver", level_driver,
                         c.fault or f"{self.config.controller.driver} {state.value}", driver_values),
            self._status(f"{NODE_NAME}: control loop", loop_level,
                         f"{loop['rate_hz']:.1f} Hz, p99 period {loop['period_p99_ms']:.2f} ms",
                         {k: f"{v:.3f}" if isinstance(v, float) else str(v) for k, v in loop.items()}),
            self._command_status(cmd_values),
            self._status(f"{NODE_NAME}: odometry", odo_level, odo_message, odo_values),
        ]
        if c.drift is not None:
            # its own status: a geometry that drifted is not a slip event
            findings = c.drift.findings()
            statuses.append(self._status(
                f"{NODE_NAME}: calibration",
                DiagnosticStatus.WARN if findings else DiagnosticStatus.OK,
                findings[0] if findings else
                "not enough motion yet to judge the geometry" if c.drift.error is None else
                "configured geometry consistent with the motion",
                c.drift.values()))
        for status in statuses:
            status.hardware_id = robot
        self.diag_pub.publish(DiagnosticArray(header=Header(stamp=now), status=statuses))
        if self._foxglove is not None:
            self._foxglove.offer_diagnostics(now.sec * 1_000_000_000 + now.nanosec, [
                (s.name, ord(s.level), s.message, s.hardware_id,
                 tuple((kv.key, kv.value) for kv in s.values)) for s in statuses])

    def _command_status(self, values) -> DiagnosticStatus:
        c = self.controller
        values["commands_while_disarmed"] = str(c.counters["commands_while_disarmed"])
        # WARN while commands arrive that the disarmed motors cannot follow
        # (within the last 2 diagnostics periods)
        if c.commanded_while_disarmed(2.0):
            return self._status(f"{NODE_NAME}: command", DiagnosticStatus.WARN,
                                f"commands received while {c.state.value}: not moving "
                                "(holonomic-ctl enable)", values)
        return self._status(f"{NODE_NAME}: command", DiagnosticStatus.OK,
                            "stale: stopping" if c.stale else "tracking", values)

    def _unit_names(self):
        kin = self.config.model.kinematics
        return getattr(kin, "caster_names", ())

    @staticmethod
    def _status(name, level, message, values) -> DiagnosticStatus:
        return DiagnosticStatus(level=level, name=name, message=message,
                                values=[KeyValue(key=k, value=v) for k, v in values.items()])

    def _on_loop_error(self, exc: BaseException) -> bool:
        """An unexpected exception in the cycle: stop the motors, keep the loop.

        After 50 consecutive failures the loop stops; the motors stay off.
        """
        self._loop_errors += 1
        self.get_logger().error(f"control cycle failed: {exc!r}; stopping the motors",
                                throttle_duration_sec=1.0)
        try:
            self.driver.deactivate()
        except DriverError:
            pass
        self.controller.fault = f"internal error: {exc!r}"
        return self._loop_errors < 50

    def shutdown(self) -> None:
        """Stop the loop, stop and disarm the motors, close the driver."""
        self.loop.stop()
        self.controller.shutdown()
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
    # The control loop thread shares the GIL with the executor's callbacks. By
    # default a thread that wants the GIL waits up to 5 ms -- a whole 200 Hz
    # period -- while a flood of cmd_vel callbacks holds it; 0.5 ms bounds
    # the loop's extra jitter at a tenth of a period.
    sys.setswitchinterval(5e-4)
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
    try:
        node = BaseControllerNode()
    except ConfigError as exc:
        print(f"{NODE_NAME}: configuration error: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 2
    except InstanceConflict as exc:
        print(f"{NODE_NAME}: refusing to start: {exc}", file=sys.stderr)
        rclpy.try_shutdown()
        return 3
    # At high control rates the loop must get the GIL back sooner than 0.5 ms.
    sys.setswitchinterval(min(5e-4, 0.2 * node.loop.period))
    # Everything built so far lives for the whole run: out of the garbage
    # collector's way, so that its full collections stay short.
    gc.freeze()
    executor = SingleThreadedExecutor()
    executor.add_node(node)
    recorder = None
    try:
        if record:
            from holonomic_bringup.recorder import McapRecorder
            try:
                recorder = McapRecorder(node, record, [(node.get_namespace(),
                                                        dict(node.config.values),
                                                        node.config.controller.cmd_vel_stamped)])
            except OSError as exc:
                print(f"{NODE_NAME}: cannot record to {record}: {exc}", file=sys.stderr)
                return 2
            node.get_logger().info(f"recording to {record}")
        if foxglove is not None:
            node.attach_foxglove(foxglove)
            foxglove.start()
            node.get_logger().info(foxglove.summary())
        while not STOP.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    finally:
        node.shutdown()
        node.get_logger().info("motors stopped and disarmed; exiting")
        if recorder is not None:
            recorder.close()
            node.get_logger().info(f"wrote {recorder.count} messages to {record}")
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
