"""The base controller's core: one control cycle, ROS-free.

Each :meth:`BaseController.step` (called by the fixed-rate loop thread):

1. applies pending requests (arm, disarm, reset odometry) -- driver calls
   only ever happen in the loop thread;
2. reads the driver and integrates odometry;
3. picks the target twist: the latest command, or zero when disarmed, when
   the command is stale (older than ``cmd_timeout``) or when it was
   rejected as non-finite;
4. limits it (speed, acceleration, deceleration: direction-preserving),
   maps it through the exact inverse kinematics at the measured joint
   positions, scales the joint rates uniformly to their speed limits, and
   writes them.

ROS callbacks only call :meth:`set_command` and the ``request_*`` methods,
which store a value and return; they never touch the driver.
"""

from __future__ import annotations

import concurrent.futures
import dataclasses
import enum
import math
import numbers
import threading
import time
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

import numpy as np

from holonomic_core.drift_watch import DRIFT_SPECS, DriftWatch
from holonomic_core.driver import (DRIVER_REGISTRY, Driver, DriverError, DriverFault,
                                   DriverState, JointReading, driver_class,
                                   sim_drives_driver)
from holonomic_core.kinematics import ESTIMATORS
from holonomic_core.limits import TwistLimiter, is_finite_twist, saturate_joint_rates
from holonomic_core.model import (RobotModel, build_model, check_no_unknown, read_params_file,
                                  resolve_config)
from holonomic_core.monitor import MonitorLimits, ReadingMonitor
from holonomic_core.odometry import Odometry, OdometryNoise, wrap_angle
from holonomic_core.schema import ConfigError, ParamSpec, validate
from holonomic_core.slip_monitor import SlipLimits, SlipMonitor
from holonomic_core.torque import OperationalSpaceController, dynamics_for

_AXES = (("linear.x", "m/s", "m/s^2"), ("linear.y", "m/s", "m/s^2"),
         ("angular.z", "rad/s", "rad/s^2"))


def _limit_specs() -> list[ParamSpec]:
    specs = []
    for axis, vel_unit, acc_unit in _AXES:
        specs += [
            ParamSpec(f"limits.{axis}.max_velocity", "double",
                      f"Speed limit of the commanded twist's {axis} [{vel_unit}].",
                      minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec(f"limits.{axis}.max_acceleration", "double",
                      f"Acceleration limit on {axis} when speeding up [{acc_unit}].",
                      minimum=0.0, exclusive_minimum=True, maximum=1000.0),
            ParamSpec(f"limits.{axis}.max_deceleration", "double",
                      f"Deceleration limit on {axis} when slowing down or stopping "
                      f"(also after a command timeout) [{acc_unit}].",
                      minimum=0.0, exclusive_minimum=True, maximum=1000.0),
        ]
    return specs


CONTROLLER_SPECS: list[ParamSpec] = [
    ParamSpec("driver", "string", "Driver backend: " + ", ".join(sorted(DRIVER_REGISTRY)) + ".",
              default="sim", choices=tuple(sorted(DRIVER_REGISTRY))),
    ParamSpec("sim_drives", "bool",
              "Run the CAN backend (odrive_can, cia402) against emulated drives whose motors "
              "are the simulator's joints (holonomic-bringup --sim-drives).", default=False),
    ParamSpec("control_rate", "double", "Rate of the control loop [Hz].",
              default=200.0, minimum=1.0, maximum=1000.0),
    ParamSpec("publish_rate", "double",
              "Rate of odom, /tf and joint_states [Hz]; at most control_rate.",
              default=50.0, minimum=0.1, maximum=1000.0),
    ParamSpec("cmd_timeout", "double",
              "Age [s] after which the last cmd_vel is stale and the base stops "
              "under the deceleration limits; 0 disables the timeout.",
              default=0.5, minimum=0.0, maximum=60.0),
    ParamSpec("control_mode", "string",
              "velocity: joint velocity commands from the exact inverse kinematics (every "
              "robot); torque: dynamically decoupled operational-space control, F = Lambda F* "
              "+ mu, joint torques C#^T F (Holmberg & Khatib; PCV on a driver with torque "
              "mode).", default="velocity", choices=("velocity", "torque")),
    ParamSpec("torque.kp", "double_array",
              "Torque mode: position gains of the unit-mass system for (x, y, yaw) [1/s^2].",
              default=(36.0, 36.0, 36.0), minimum=0.0, maximum=1e4, min_length=3),
    ParamSpec("torque.kv", "double_array",
              "Torque mode: velocity gains for (x, y, yaw) [1/s] (2 sqrt(kp): critically "
              "damped).", default=(12.0, 12.0, 12.0), minimum=0.0, maximum=1e3, min_length=3),
    ParamSpec("estimator", "string",
              "Odometry estimator: slip_min (C# = Cp+ Cq^-1), robust (slip_min, except that "
              "one caster alone disagreeing by more than 0.1 m/s is left out) or pinv.",
              default="slip_min", choices=ESTIMATORS),
    ParamSpec("odom_frame", "string", "Frame of the odometry (REP 105).", default="odom"),
    ParamSpec("base_frame", "string", "Frame of the base (REP 105).", default="base_link"),
    ParamSpec("frame_prefix", "string",
              "Prefix of odom_frame and base_frame, e.g. 'robot1/' for one robot of several "
              "(holonomic-bringup --namespace NS sets 'NS/').", default=""),
    ParamSpec("publish_tf", "bool", "Publish odom -> base_link on /tf.", default=True),
    ParamSpec("publish_link_tf", "bool",
              "Also publish every URDF link's transform on /tf, from the measured joint "
              "positions (wheels, turret, casters), for rviz where no robot_state_publisher "
              "runs (a pip-only install). Off by default: on a full ROS install "
              "robot_state_publisher does this from joint_states.", default=False),
    ParamSpec("cmd_vel_stamped", "bool",
              "Subscribe cmd_vel as geometry_msgs/TwistStamped instead of Twist.", default=False),
    ParamSpec("enable_on_start", "bool",
              "Arm the motors at start. Default false: motors start disarmed and "
              "~/enable arms them.", default=False),
    # defaults: the XR4000's all-floor profile on the drive model (config/xr4000.yaml):
    # holonomic-odometry-experiment --robot xr4000 --seeds 5 --duration 40 --condition
    # drives-nominal --condition drives-uneven --condition drives-slippery --condition
    # drives-worn --calibrate (docs/odometry_experiment.md)
    ParamSpec("odometry.twist_window", "double",
              "Span of the encoder readings whose least-squares line gives the published "
              "twist [s]; it lags a ramp by half of it; 0: the last two readings.",
              default=0.03, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.linear_variance_per_meter", "double",
              "Position variance added per metre travelled [m^2/m].",
              default=0.0, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.angular_variance_per_radian", "double",
              "Heading variance added per radian turned [rad^2/rad].",
              default=5.26e-6, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.angular_variance_per_meter", "double",
              "Heading variance added per metre travelled [rad^2/m].",
              default=0.0, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.slip_position_gain", "double",
              "Position variance added per squared RMS contact residual the estimator could "
              "not explain, per second [s] (m^2 per (m/s)^2 s).",
              default=0.327, minimum=0.0, maximum=1e4),
    ParamSpec("odometry.slip_heading_gain", "double",
              "Heading variance added per squared RMS contact residual, per second [s/m^2] "
              "(rad^2 per (m/s)^2 s).", default=2.18, minimum=0.0, maximum=1e6),
    ParamSpec("odometry.twist_variance", "double_array",
              "Variances of the reported twist (vx, vy, wz) without slip or acceleration "
              "[(m/s)^2, (m/s)^2, (rad/s)^2].",
              default=(8.39e-6, 5.71e-6, 3.77e-5), minimum=0.0, maximum=100.0, min_length=3),
    ParamSpec("odometry.twist_slip_gain", "double_array",
              "Twist variance (vx, vy, wz) added per (m/s)^2 of squared RMS contact residual "
              "[-, -, 1/m^2].", default=(0.268, 0.254, 6.97), minimum=0.0, maximum=1e4,
              min_length=3),
    ParamSpec("odometry.twist_lag_gain", "double_array",
              "Twist variance (vx, vy, wz) added per squared lag error of the axis, "
              "(acceleration x half the twist window)^2 [-].", default=(1.23, 1.27, 1.9),
              minimum=0.0, maximum=1e4, min_length=3),
    ParamSpec("diagnostics.slip_threshold", "double",
              "Odometry residual of one caster above which it counts as slipping [m/s].",
              default=0.05, minimum=0.0, exclusive_minimum=True, maximum=10.0),
    ParamSpec("diagnostics.slip_duration", "double",
              "How long a caster must stay above diagnostics.slip_threshold before the "
              "odometry diagnostics WARN, naming it [s].",
              default=1.0, minimum=0.0, maximum=600.0),
    ParamSpec("safety.velocity_factor", "double",
              "A measured joint speed above this multiple of the joint's speed limit is an "
              "encoder glitch: the controller faults and stops the base [-].",
              default=3.0, minimum=1.5, maximum=1000.0),
    ParamSpec("safety.reading_timeout", "double",
              "Joint readings whose stamp has not advanced for this long are frozen: "
              "fault and stop [s].", default=0.05, minimum=0.001, maximum=10.0),
    ParamSpec("safety.tracking_error", "double",
              "A joint whose measured speed differs from its command by more than this "
              "fraction of its speed limit, for safety.tracking_timeout, cannot follow "
              "(saturated or blocked): fault and stop [-].",
              default=0.3, minimum=0.01, maximum=100.0),
    ParamSpec("safety.tracking_timeout", "double",
              "How long a joint may miss its command by safety.tracking_error before the "
              "controller faults [s]; 0 disables the check.",
              default=0.5, minimum=0.0, maximum=60.0),
] + _limit_specs() + DRIFT_SPECS


@dataclass(frozen=True)
class ControllerConfig:
    """Validated settings of the base controller (units in CONTROLLER_SPECS)."""

    driver: str
    control_rate: float
    publish_rate: float
    cmd_timeout: float
    estimator: str
    odom_frame: str
    base_frame: str
    publish_tf: bool
    publish_link_tf: bool
    cmd_vel_stamped: bool
    enable_on_start: bool
    control_mode: str
    torque_kp: tuple[float, float, float]
    torque_kv: tuple[float, float, float]
    max_velocity: tuple[float, float, float]
    max_acceleration: tuple[float, float, float]
    max_deceleration: tuple[float, float, float]
    noise: OdometryNoise
    twist_window: float
    monitor: MonitorLimits
    slip: SlipLimits

    @classmethod
    def from_values(cls, v: Mapping[str, Any]) -> "ControllerConfig":
        if v["publish_rate"] > v["control_rate"]:
            raise ConfigError("publish_rate", v["publish_rate"],
                              f"<= control_rate ({v['control_rate']:g} Hz)")
        for key in ("odometry.twist_variance", "odometry.twist_slip_gain",
                    "odometry.twist_lag_gain"):
            if len(v[key]) != 3:
                raise ConfigError(key, v[key], "exactly 3 values (vx, vy, wz)")
        for key in ("torque.kp", "torque.kv"):
            if len(v[key]) != 3:
                raise ConfigError(key, v[key], "exactly 3 gains (x, y, yaw)")
        axes = [a for a, _, _ in _AXES]
        return cls(
            driver=v["driver"], control_rate=v["control_rate"], publish_rate=v["publish_rate"],
            cmd_timeout=v["cmd_timeout"], estimator=v["estimator"],
            odom_frame=v["odom_frame"], base_frame=v["base_frame"],
            publish_tf=v["publish_tf"], publish_link_tf=v["publish_link_tf"],
            cmd_vel_stamped=v["cmd_vel_stamped"],
            enable_on_start=v["enable_on_start"], control_mode=v["control_mode"],
            torque_kp=tuple(v["torque.kp"]), torque_kv=tuple(v["torque.kv"]),
            max_velocity=tuple(v[f"limits.{a}.max_velocity"] for a in axes),
            max_acceleration=tuple(v[f"limits.{a}.max_acceleration"] for a in axes),
            max_deceleration=tuple(v[f"limits.{a}.max_deceleration"] for a in axes),
            noise=OdometryNoise(v["odometry.linear_variance_per_meter"],
                                v["odometry.angular_variance_per_radian"],
                                v["odometry.angular_variance_per_meter"],
                                v["odometry.slip_position_gain"],
                                v["odometry.slip_heading_gain"],
                                tuple(v["odometry.twist_variance"]),
                                tuple(v["odometry.twist_slip_gain"]),
                                tuple(v["odometry.twist_lag_gain"])),
            twist_window=v["odometry.twist_window"],
            slip=SlipLimits(v["diagnostics.slip_threshold"], v["diagnostics.slip_duration"]),
            monitor=MonitorLimits(v["safety.velocity_factor"], v["safety.reading_timeout"],
                                  v["safety.tracking_error"], v["safety.tracking_timeout"]),
        )


@dataclass(frozen=True)
class RobotConfig:
    """Everything needed to run one robot, validated.

    ``specs``: every parameter's schema (the ROS node declares them);
    ``values``: every validated value by flat key.
    """

    model: RobotModel
    controller: ControllerConfig
    driver_class: type
    specs: tuple[ParamSpec, ...]
    values: Mapping[str, Any] = field(repr=False)
    source: str = ""


def config_from_flat(flat: Mapping[str, Any], source: str = "") -> RobotConfig:
    """Validate a flat parameter dict (file + overrides) into a RobotConfig."""
    model, model_specs = build_model(flat)
    values = dict(model.params)
    values.update(validate(CONTROLLER_SPECS, flat))
    controller = ControllerConfig.from_values(values)
    dcls = driver_class(controller.driver)
    if values["sim_drives"]:
        dcls = sim_drives_driver(dcls)
    if controller.control_mode == "torque":
        if not dcls.supports_effort:
            raise ConfigError("control_mode", "torque",
                              f"'velocity' with driver '{controller.driver}' (it has no torque "
                              "mode; the sim driver has)")
        dynamics_for(model)      # a family without a dynamic model says so here
    dspecs = dcls.param_specs(model)
    values.update(validate(dspecs, flat))
    # Keys of the backends not in use (e.g. `sim.*` on a real robot) are
    # allowed in the file; anything else unknown is a typo.
    others = tuple(f"{name}." for name in DRIVER_REGISTRY if name != controller.driver)
    specs = tuple(model_specs + CONTROLLER_SPECS + dspecs)
    check_no_unknown(list(specs), flat, ignore_prefixes=others)
    return RobotConfig(model, controller, dcls, specs, values, source)


def load_config(source, overrides: Mapping[str, Any] | None = None) -> RobotConfig:
    """Load and validate a robot config (a name from config/ or a YAML path).

    ``overrides``: flat keys applied over the file (e.g. ``{"driver": "mock"}``).
    Raises :class:`ConfigError` naming the first bad key.
    """
    path = resolve_config(source)
    flat = read_params_file(path)
    flat.update(overrides or {})
    return config_from_flat(flat, str(path))


class ControllerState(enum.Enum):
    DISARMED = "disarmed"
    ARMED = "armed"
    FAULT = "fault"


_ZERO3 = np.zeros(3)
#: gain [1/s] of velocity mode's pull onto a followed trajectory's pose
TRAJECTORY_GAIN = 4.0


class BaseController:
    """One robot's control cycle: driver in, odometry and joint commands out.

    ``clock`` [s] (monotonic) times command age; injectable for tests.
    Thread-safety: :meth:`set_command` and the ``request_*`` methods may be
    called from any thread; :meth:`step` from the loop thread only.
    """

    def __init__(self, config: RobotConfig, driver: Driver,
                 clock: Callable[[], float] = time.monotonic):
        self.config = config
        self.model = config.model
        c = config.controller
        self.driver = driver
        self.dt = 1.0 / c.control_rate
        self.cmd_timeout = c.cmd_timeout
        self.limiter = TwistLimiter(c.max_velocity, c.max_acceleration, c.max_deceleration)
        self.odometry = Odometry(self.model, c.estimator, c.noise, c.twist_window)
        self.slip_monitor = SlipMonitor(getattr(self.model.kinematics, "caster_names", ()),
                                        c.slip)
        self.monitor = ReadingMonitor(self.model.joint_names, self.model.max_joint_velocity,
                                      self.dt, c.monitor)
        self._clock = clock
        self._max_rates = self.model.max_joint_velocity
        corrections = self.model.zero_corrections
        self._zero_corrections = corrections if corrections.any() else None
        #: the calibration drift watch (None where it does not apply)
        self.drift = DriftWatch.from_config(self.model, config.values)
        #: the torque-mode law (None in velocity mode)
        self.torque = (OperationalSpaceController(
            self.model, c.torque_kp, c.torque_kv,
            [j.max_effort for j in self.model.joint_limits])
            if c.control_mode == "torque" else None)
        n = len(self.model.joint_names)
        # (twist, receive time); replaced atomically by set_command
        self._command: tuple[np.ndarray, float] | None = None
        # (trajectory, start time) while following one (see follow)
        self._trajectory: tuple[Callable, float | None] | None = None
        self._requests: list[tuple[str, Any, concurrent.futures.Future]] = []
        self._requests_lock = threading.Lock()
        # outputs of the last cycle, read by the ROS shell in the loop thread
        self.reading: JointReading | None = None
        self.twist_command = np.zeros(3)
        self.joint_command = np.zeros(n)
        self.saturation = 1.0
        self.stale = True
        self.fault: str | None = None
        self.counters = {"rejected_commands": 0, "timeouts": 0, "driver_errors": 0,
                         "implausible_readings": 0, "cycles": 0, "commands_while_disarmed": 0}
        #: clock time [s] of the last non-zero command received while the
        #: motors were not armed (-inf: none): the base cannot follow it
        self.last_command_while_disarmed = -math.inf

    # -- inputs (any thread) -------------------------------------------------------
    def set_command(self, twist, received: float | None = None) -> str | None:
        """Store the latest command (vx, vy, wz) [m/s, m/s, rad/s] in base_link.

        A non-finite component rejects the command *and* stops the base (the
        publisher is broken; its last good command is not trusted either).
        Returns None when accepted, else the reason it was rejected.
        """
        now = self._clock() if received is None else received
        try:
            parts = (twist[0], twist[1], twist[2])
            # fast path for plain floats (every ROS message); the ABC check
            # (numpy scalars, ints; never bools) only for the rest
            if all(type(v) is float for v in parts) or all(
                    isinstance(v, numbers.Real) and not isinstance(v, bool) for v in parts):
                values = np.array([float(v) for v in parts])
            else:
                values = None
        except (TypeError, ValueError, OverflowError, IndexError, KeyError):
            values = None
        if values is None or not is_finite_twist(values.tolist()):
            self.counters["rejected_commands"] += 1
            self._command = (_ZERO3, now)
            what = "non-finite" if values is not None else "malformed"
            return f"{what} command {repr(twist)[:80]} rejected; stopping the base"
        self._command = (values, now)
        if values.any() and self.state is not ControllerState.ARMED:
            self.counters["commands_while_disarmed"] += 1
            self.last_command_while_disarmed = now
        return None

    def commanded_while_disarmed(self, within: float) -> bool:
        """True when a non-zero command arrived in the last ``within`` seconds
        while the motors were disarmed or faulted (it moves nothing)."""
        return self._clock() - self.last_command_while_disarmed <= within

    def request_enable(self, enable: bool) -> concurrent.futures.Future:
        """Ask the loop to arm (True) or disarm (False) the motors.

        The future resolves to ``(success, message)`` after the next cycle.
        """
        return self._request("enable", bool(enable))

    def request_reset_odometry(self) -> concurrent.futures.Future:
        """Ask the loop to reset the odometry pose to the origin."""
        return self._request("reset_odometry", None)

    def _request(self, kind: str, arg: Any) -> concurrent.futures.Future:
        future: concurrent.futures.Future = concurrent.futures.Future()
        with self._requests_lock:
            self._requests.append((kind, arg, future))
        return future

    # -- state ------------------------------------------------------------------
    @property
    def state(self) -> ControllerState:
        if self.fault is not None:
            return ControllerState.FAULT
        return ControllerState.ARMED if self.driver.armed else ControllerState.DISARMED

    def command_age(self) -> float:
        """Seconds since the last command (inf if none)."""
        cmd = self._command
        return math.inf if cmd is None else self._clock() - cmd[1]

    # -- the cycle (loop thread) ----------------------------------------------------
    def step(self) -> bool:
        """Run one control cycle. Returns False if the driver failed this cycle."""
        self.counters["cycles"] += 1
        self._process_requests()
        try:
            reading = self.driver.read()
        except DriverError as exc:
            self._on_fault(exc)
            return False
        if self._zero_corrections is not None:
            # encoder zeros (joints.*.zero_correction): odometry, inverse
            # kinematics and joint_states all see kinematic angles
            reading = dataclasses.replace(reading,
                                          positions=reading.positions + self._zero_corrections)
        problem = self.monitor.check(reading, self._clock(),
                                     self.joint_command if self.driver.armed else None)
        if problem is not None:
            # keep the bad sample out of the odometry: the next good reading
            # becomes its new reference (the pose is kept)
            self.odometry.rebase()
            if self.fault is None or self.driver.armed:
                self.counters["implausible_readings"] += 1
                self._on_fault(DriverFault(problem))
            return False
        self.reading = reading
        if self.odometry.update(reading.positions, reading.stamp):
            self.slip_monitor.update(self.odometry.residual, reading.stamp)
        if self.drift is not None:
            self.drift.update(reading.stamp, reading.positions)

        if not self.driver.armed:
            self.twist_command[:] = 0.0
            self.joint_command[:] = 0.0
            self.saturation = 1.0
            return True

        sample = self._trajectory_sample()
        if sample is None:
            target = self._target()
        else:
            # velocity mode follows the sample by feed-forward twist plus a
            # proportional pull onto the reference pose (in base_link)
            pose = self.odometry.pose
            c, s = math.cos(pose[2]), math.sin(pose[2])
            dx, dy = sample[0][0] - pose[0], sample[0][1] - pose[1]
            pull = TRAJECTORY_GAIN * np.array([c * dx + s * dy, -s * dx + c * dy,
                                               wrap_angle(sample[0][2] - pose[2])])
            target = np.asarray(sample[1], float) + pull
        twist = self.limiter.limit(target, self.twist_command, self.dt)
        rates = self.model.kinematics.inverse(reading.positions, twist)
        rates, scale = saturate_joint_rates(rates, self._max_rates)
        try:
            if self.torque is None:
                self.driver.write_velocities(rates)
            elif sample is None:
                # the reference is the limited, saturated twist; the monitor
                # checks the joints against its joint rates as in velocity mode
                # feedback from the last interval's twist: the published,
                # windowed one lags by half its window (measured: 3x the
                # XR4000's slip in torque mode with the 30 ms window)
                efforts = self.torque.step(reading.positions, self.odometry.pose,
                                           self.odometry.rate_twist, twist * scale, self.dt)
                self.driver.write_efforts(efforts)
            else:
                efforts = self.torque.track(reading.positions, self.odometry.pose,
                                            self.odometry.rate_twist, *sample)
                self.driver.write_efforts(efforts)
        except DriverError as exc:
            self._on_fault(exc)
            return False
        # The limiter continues from what was really commanded.
        self.twist_command = twist * scale if scale < 1.0 else twist
        self.joint_command = rates
        self.saturation = scale
        return True

    def follow(self, trajectory: Callable[[float], tuple | None]) -> None:
        """Follow a trajectory (a precise move) instead of ``cmd_vel``.

        ``trajectory(t)`` for t [s] since the next cycle returns ``(pose,
        twist, acceleration)`` -- the reference pose in odom [m, m, rad], its
        body twist and body-frame acceleration in base_link -- or None when it
        is over (then the base is commanded to rest). Torque mode tracks it
        with the decoupled PD law; velocity mode with feed-forward twist plus
        a proportional pull (TRAJECTORY_GAIN) onto the pose. The limits and
        checks stay in force. Any thread.
        """
        self._trajectory = (trajectory, None)

    def _trajectory_sample(self):
        active = self._trajectory
        if active is None:
            return None
        trajectory, start = active
        now = self._clock()
        if start is None:
            start = now
            self._trajectory = (trajectory, start)
        sample = trajectory(now - start)
        if sample is None:
            self._trajectory = None
            self._command = (_ZERO3, now)
            if self.torque is not None:
                self.torque.reset(self.odometry.pose)
        return sample

    def _target(self) -> np.ndarray:
        cmd = self._command
        if cmd is None:
            self.stale = True
            return _ZERO3
        twist, received = cmd
        stale = self.cmd_timeout > 0.0 and self._clock() - received > self.cmd_timeout
        if stale and not self.stale:
            self.counters["timeouts"] += 1
        self.stale = stale
        return _ZERO3 if stale else twist

    def _process_requests(self) -> None:
        if not self._requests:
            return
        with self._requests_lock:
            pending, self._requests = self._requests, []
        for kind, arg, future in pending:
            try:
                if kind == "enable":
                    result = self._arm() if arg else self._disarm()
                else:
                    self.odometry.reset()
                    self.slip_monitor.reset()
                    result = (True, "odometry reset to the origin")
            except DriverError as exc:
                self._on_fault(exc)
                result = (False, f"driver error: {exc}")
            future.set_result(result)

    def _arm(self) -> tuple[bool, str]:
        if self.driver.armed:
            return True, "already armed"
        # A fault is cleared only if the driver answers again, plausibly.
        reading = self.driver.read()
        self.monitor.reset()
        problem = self.monitor.check(reading, self._clock())
        if problem is not None:
            raise DriverFault(problem)
        self.odometry.rebase()
        self.fault = None
        if self.driver.state is DriverState.INACTIVE:
            self.driver.activate()
        # Start from rest and ignore commands (and trajectories) sent before arming.
        self._command = None
        self._trajectory = None
        self.twist_command = np.zeros(3)
        if self.torque is not None:
            self.torque.reset(self.odometry.pose)
        return True, "motors armed"

    def _disarm(self) -> tuple[bool, str]:
        self.driver.deactivate()
        self.twist_command = np.zeros(3)
        self._trajectory = None
        return True, "motors disarmed"

    def _on_fault(self, exc: DriverError) -> None:
        self.counters["driver_errors"] += 1
        # The first failure is the cause; what follows while disarmed (the
        # same device still silent, ...) is its consequence.
        if self.fault is None:
            self.fault = str(exc)
        self.twist_command = np.zeros(3)
        self._trajectory = None
        self.joint_command[:] = 0.0
        try:
            self.driver.deactivate()
        except DriverError:
            pass  # already reported: the fault itself

    def shutdown(self) -> None:
        """Stop and disarm the motors, then close the driver (any thread, loop stopped)."""
        try:
            self.driver.deactivate()
        finally:
            self.driver.close()
