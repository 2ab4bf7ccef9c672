"""The base controller's core: one control cycle, ROS-free.

Each :meth:`BaseController.step` (called by the fixed-rate loop thread):

1. applies pending requests (arm, disarm, reset odometry) -- driver calls
   only ever happen in the loop thread;
2. reads the driver, checks the reading (an isolated invalid one may be
   dropped: :mod:`holonomic_core.glitch_policy`) and integrates odometry;
3. picks the target twist: the latest command, or zero when disarmed, when
   the command is stale (older than ``cmd_timeout``) or when it was
   rejected as non-finite;
4. limits it (speeds and the speed norm, acceleration, deceleration, jerk,
   then the joints' accelerations: direction-preserving; docs/limits.md),
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
from typing import Any, Callable, Mapping

import numpy as np

from holonomic_core.config import RobotConfig
from holonomic_core.drift_watch import DriftWatch
from holonomic_core.glitch_policy import GlitchPolicy
from holonomic_core.driver import Driver, DriverError, DriverFault, DriverState, JointReading
from holonomic_core.joint_acceleration import JointAccelerationLimit
from holonomic_core.joint_range import JointRangeGuard
from holonomic_core.limits import TwistLimiter, is_finite_twist, joint_rate_saturation
from holonomic_core.monitor import ReadingMonitor
from holonomic_core.odometry import Odometry
from holonomic_core.safety import safety_from_values
from holonomic_core.se2 import relative_pose
from holonomic_core.slip_monitor import SlipMonitor
from holonomic_core.torque import OperationalSpaceController
from holonomic_core import unwind


class ControllerState(enum.Enum):
    DISARMED = "disarmed"
    ARMED = "armed"
    FAULT = "fault"


@dataclasses.dataclass(frozen=True)
class ControllerStatus:
    """What the controller reports about itself (:meth:`BaseController.status`):
    plain values, picklable, taken in the loop thread between two cycles.

    Rates [m/s, m/s, rad/s] in base_link, times [s], distance [m].
    """

    state: ControllerState
    fault: str | None
    driver: Mapping[str, str]            #: the driver's own key/value status
    cycles: int
    driver_errors: int
    implausible_readings: int
    timeouts: int
    rejected_commands: int
    commands_while_disarmed: int
    commanded_while_disarmed: bool       #: a non-zero command in the last 2 s while not armed
    command_age: float                   #: [s], inf without a command
    stale: bool
    saturation: float
    twist_command: tuple[float, float, float]
    estimator: str
    distance: float                      #: odometry path length [m]
    residual: tuple[float, ...]          #: per caster [m/s]
    slipping: tuple[tuple[str, float], ...]   #: (caster, seconds above the threshold)
    slip_threshold: float                #: [m/s]
    drift_findings: tuple[str, ...] | None    #: None: no drift watch for this robot
    drift_judged: bool                   #: the drift watch has enough motion to judge
    drift_values: Mapping[str, str]
    dropped_readings: int = 0            #: invalid readings dropped (safety.glitch_policy)
    last_dropped: str | None = None      #: why the last one was
    #: joints slowed at their position range in the last 2 s
    range_limited: tuple[str, ...] = ()
    #: the unwind maneuver: running (progress) or how the last one ended; None: none yet
    unwind: str | None = None
    unwinding: bool = False              #: the unwind maneuver is running
    estop: str | None = None             #: why the emergency stop is pressed; None: released
    holding: bool = False                #: disarmed, drives holding zero velocity (disarm_mode hold)


#: how far back a command while disarmed makes the status say so [s]
DISARMED_COMMAND_WINDOW = 2.0

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
        self.limiter = TwistLimiter(c.max_velocity, c.max_acceleration, c.max_deceleration,
                                    c.max_speed, c.max_jerk)
        #: joints.*.max_acceleration (None: no joint has one)
        self.joint_acceleration = JointAccelerationLimit.from_config(self.model, config.values)
        # (twist_command, a copy of it, the one before): the last step's twist
        # acceleration for the jerk limits, valid while twist_command is that
        # very array, unchanged (every reset assigns or zeroes it)
        self._twist_memory: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self.odometry = Odometry(self.model, c.estimator, c.noise, c.twist_window)
        self.slip_monitor = SlipMonitor(getattr(self.model.kinematics, "caster_names", ()),
                                        c.slip)
        self.monitor = ReadingMonitor(self.model.joint_names, self.model.max_joint_velocity,
                                      self.dt, c.monitor)
        self.glitches = GlitchPolicy(c.glitch)
        self._clock = clock
        self._max_rates = self.model.max_joint_velocity
        # compiled or pure, as the limiter, kinematics and odometry (hot_path)
        self._saturate = joint_rate_saturation()
        #: keeps ranged joints inside their range (None: all continuous)
        # with joint acceleration limits, a joint brakes no harder than its own
        self.range_guard = JointRangeGuard.from_model(
            self.model, c.max_deceleration, 2.0 * self.dt,
            None if self.joint_acceleration is None else self.joint_acceleration.max_acceleration)
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
        #: the unwind maneuver running or last run (request_unwind)
        self.maneuver: unwind.UnwindManeuver | None = None
        self._requests: list[tuple[str, Any, concurrent.futures.Future]] = []
        self._requests_lock = threading.Lock()
        # outputs of the last cycle, read by the ROS shell in the loop thread
        self.reading: JointReading | None = None
        self.twist_command = np.zeros(3)
        self.joint_command = np.zeros(n)
        self.saturation = 1.0
        self.stale = True
        self.fault: str | None = None
        #: the emergency-stop input and what disarming does (holonomic_core.safety)
        self.estop, self.disarm_policy = safety_from_values(config.values)
        #: why the e-stop is pressed (None: released), as of the last cycle
        self.estop_reason: str | None = None
        #: clock time [s] a hold began (disarm_mode hold); None: not holding
        self._holding_since: float | None = None
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
        self.cancel_unwind("a new cmd_vel")
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

    def request_estop(self, pressed: bool, source: str = "emergency_stop",
                      stamp: float | None = None) -> None:
        """One message of the emergency-stop input (any thread): pressed or
        released, from ``source``, received at ``stamp`` [s, this clock].
        The next cycle quick-stops the drives; a release re-arms nothing."""
        self.estop.update(pressed, source, self._clock() if stamp is None else stamp)

    def request_set_pose(self, pose, covariance=None) -> concurrent.futures.Future:
        """Ask the loop to set the odometry pose (x, y, yaw) [m, m, rad] and
        its covariance (9 values, 3 x 3 row-major; None: zero). Safe during
        motion: the odometry goes on from the new pose."""
        return self._request("set_pose", (tuple(pose), covariance))

    def request_reset_odometry(self) -> concurrent.futures.Future:
        """Ask the loop to reset the odometry pose to the origin."""
        return self._request("reset_odometry", None)

    def request_unwind(self) -> concurrent.futures.Future:
        """Ask the loop to start the unwind maneuver (:mod:`holonomic_core.unwind`):
        every ranged joint back to the middle of its range, the base back at
        its pose. The future resolves to ``(success, plan or why not)`` once
        it starts; :meth:`status` reports its progress and how it ended."""
        return self._request("unwind", None)

    def cancel_unwind(self, reason: str) -> None:
        """Cancel a running unwind maneuver (any thread): the base ramps to rest
        under the limits; its status says why (e-stop, a new command, ...)."""
        if self.maneuver is not None:
            self.maneuver.cancel(reason)

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
        return (ControllerState.ARMED if self.driver.armed and self._holding_since is None
                else ControllerState.DISARMED)

    def command_age(self) -> float:
        """Seconds since the last command (inf if none)."""
        cmd = self._command
        return math.inf if cmd is None else self._clock() - cmd[1]

    def status(self) -> ControllerStatus:
        """A snapshot of the state, counters, command and odometry health
        (the loop thread, between cycles: diagnostics are built from it)."""
        c, odo = self.counters, self.odometry
        reading = self.reading
        return ControllerStatus(
            state=self.state, fault=self.fault, driver=dict(self.driver.status()),
            cycles=c["cycles"], driver_errors=c["driver_errors"],
            implausible_readings=c["implausible_readings"], timeouts=c["timeouts"],
            rejected_commands=c["rejected_commands"],
            commands_while_disarmed=c["commands_while_disarmed"],
            commanded_while_disarmed=self.commanded_while_disarmed(DISARMED_COMMAND_WINDOW),
            command_age=self.command_age(), stale=self.stale,
            saturation=float(self.saturation),
            twist_command=tuple(float(v) for v in self.twist_command),
            estimator=odo.estimator, distance=float(odo.distance),
            residual=tuple(float(v) for v in np.asarray(odo.residual)),
            slipping=tuple(self.slip_monitor.slipping(reading.stamp))
            if reading is not None else (),
            slip_threshold=self.slip_monitor.limits.threshold,
            drift_findings=None if self.drift is None else tuple(self.drift.findings()),
            drift_judged=self.drift is not None and self.drift.error is not None,
            drift_values={} if self.drift is None else dict(self.drift.values()),
            dropped_readings=self.glitches.dropped, last_dropped=self.glitches.last,
            range_limited=() if self.range_guard is None else
            self.range_guard.limited(self._clock(), DISARMED_COMMAND_WINDOW),
            unwind=None if self.maneuver is None else self.maneuver.status(),
            unwinding=self.maneuver is not None and self.maneuver.result is None,
            estop=self.estop_reason, holding=self._holding_since is not None)

    # -- the cycle (loop thread) ----------------------------------------------------
    def step(self, take_command: Callable[[], None] | None = None) -> bool:
        """Run one control cycle. Returns False if the driver failed this cycle.

        ``take_command()``: called after the reading, immediately before the
        command is used (and on a disarmed cycle), so that a loop receiving
        commands from elsewhere (the control loop process's command pipe) hands
        over the newest (:meth:`set_command`) as late as the cycle allows,
        at a fixed point of every cycle. Not called on a cycle whose reading
        failed or was implausible (the caller then takes the command itself);
        called on one whose invalid reading was dropped (safety.glitch_policy:
        that cycle commands from the last good reading)."""
        self.counters["cycles"] += 1
        self._check_estop()
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
        if problem is None:
            self.glitches.good()
        elif self.fault is None:
            # None: dropped (safety.glitch_policy), else the fault's message
            problem = self.glitches.judge(problem, self._clock())
            if problem is None:
                if self.reading is None:
                    return False                # nothing good to command from yet
                # the odometry keeps its last good reading as the reference: the
                # next good one integrates the whole motion since then, as one
                # arc; this cycle commands from the last good reading
                reading = None
        if problem is not None:
            # keep the bad sample out of the odometry: the next good reading
            # becomes its new reference (the pose is kept)
            self.odometry.rebase()
            if self.fault is None or self.driver.armed:
                self.counters["implausible_readings"] += 1
                self._on_fault(DriverFault(problem))
            return False
        if reading is None:
            reading = self.reading
        else:
            self.reading = reading
            if self.odometry.update(reading.positions, reading.stamp):
                self.slip_monitor.update(self.odometry.residual, reading.stamp)
            if self.drift is not None:
                self.drift.update(reading.stamp, reading.positions)
        if take_command is not None:
            take_command()

        if not self.driver.armed:
            self.twist_command[:] = 0.0
            self.joint_command[:] = 0.0
            self.saturation = 1.0
            return True

        if self._holding_since is not None and self._hold_over():
            return True
        holding = self._holding_since is not None
        maneuver = None if self.maneuver is None or holding else self.maneuver.target(
            self.odometry.pose, reading.positions, self._clock())
        sample = None if maneuver is not None or holding else self._trajectory_sample()
        if holding:
            target = _ZERO3          # disarmed, holding: to rest and stay there
        elif maneuver is not None:
            target = maneuver
        elif sample is None:
            target = self._target()
        else:
            # velocity mode follows the sample by feed-forward twist plus a
            # proportional pull onto the reference pose (in base_link)
            pull = TRAJECTORY_GAIN * relative_pose(self.odometry.pose, sample[0])
            target = np.asarray(sample[1], float) + pull
        twist = self.limiter.limit(target, self.twist_command, self.dt, self._twist_acceleration())
        if self.joint_acceleration is not None:
            twist = self.joint_acceleration.limit(reading.positions, twist, self.twist_command,
                                                  self.joint_command, self.dt)
        # the twist's rate since the last cycle feeds a steered wheel's turn forward
        rates, follow = self.model.kinematics.command_and_fraction(
            reading.positions, twist, (twist - self.twist_command) / self.dt)
        rates, scale = self._saturate(rates, self._max_rates)
        # a family whose wheels wait for their steering drives that fraction
        scale = scale * follow
        if self.range_guard is not None:
            # slow down (direction kept) so that no ranged joint passes its range
            keep = self.range_guard.scale(reading.positions, rates, twist * scale, self._clock())
            if keep < 1.0:
                rates, scale = rates * keep, scale * keep
        try:
            if self.torque is None:
                self.driver.write_velocities(rates)
            elif sample is None:
                # the reference is the limited, saturated twist; the monitor
                # checks the joints against its joint rates as in velocity mode
                # feedback from the last interval's twist: the published,
                # windowed one lags by half its window, and with the 30 ms
                # window that lag triples the XR4000's slip in torque mode
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
        before = self.twist_command
        self.twist_command = twist * scale if scale < 1.0 else twist
        self._twist_memory = (self.twist_command, self.twist_command.copy(), before.copy())
        self.joint_command = rates
        self.saturation = scale if self.joint_acceleration is None \
            else scale * self.joint_acceleration.speed_scale
        return True

    def _twist_acceleration(self) -> np.ndarray | None:
        """The last step's twist acceleration [m/s^2, m/s^2, rad/s^2] for the
        jerk limits; None (from rest) after anything reset the command."""
        memory = self._twist_memory
        if memory is None or memory[0] is not self.twist_command \
                or not np.array_equal(memory[1], self.twist_command):
            return None
        return (memory[1] - memory[2]) / self.dt

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
                elif kind == "unwind":
                    result = self._start_unwind()
                elif kind == "set_pose":
                    self.odometry.set_pose(*arg)
                    x, y, yaw = arg[0]
                    result = (True, f"odometry set to x {x:g} m, y {y:g} m, yaw {yaw:g} rad")
                else:
                    self.odometry.reset()
                    self.slip_monitor.reset()
                    result = (True, "odometry reset to the origin")
            except DriverError as exc:
                self._on_fault(exc)
                result = (False, f"driver error: {exc}")
            future.set_result(result)

    def _start_unwind(self) -> tuple[bool, str]:
        if not self.driver.armed:
            return False, f"cannot unwind: the motors are {self.state.value} (holonomic-ctl enable)"
        reading = self.reading
        maneuver, result = unwind.begin(self.model, None if reading is None else reading.positions,
                                        self.odometry.pose, self.config.controller.max_velocity[:2],
                                        self._clock())
        if maneuver is not None:
            # the commands before it are not resumed after it
            self._command = (_ZERO3, self._clock())
            self._trajectory = None
            self.maneuver = maneuver
        return result

    def _arm(self) -> tuple[bool, str]:
        if self.estop_reason is not None:
            return False, f"refused: {self.estop_reason}; release the emergency stop first"
        if self.driver.armed and self._holding_since is None:
            return True, "already armed"
        self._holding_since = None
        # A fault is cleared only if the driver answers again, plausibly.
        reading = self.driver.read()
        self.monitor.reset()
        self.glitches.reset()
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
        self.cancel_unwind("motors re-armed")
        self.twist_command = np.zeros(3)
        if self.torque is not None:
            self.torque.reset(self.odometry.pose)
        return True, "motors armed"

    def _disarm(self) -> tuple[bool, str]:
        self._trajectory = None
        self.cancel_unwind("motors disarmed")
        policy = self.disarm_policy
        if policy.holds and self.driver.armed and self._holding_since is None:
            # to rest under the deceleration limits, then zero velocity
            self._holding_since = self._clock()
            self._command = None
            until = (f"for {policy.hold_time:g} s" if policy.hold_time > 0.0
                     else "until disarmed again")
            return True, f"motors disarmed; holding the base at rest {until}"
        self._holding_since = None
        self.driver.deactivate()
        self.twist_command = np.zeros(3)
        return True, "motors disarmed"

    def _hold_over(self) -> bool:
        """End a hold whose safety.hold_time has run (idle the drives)."""
        if not self.disarm_policy.hold_over(self._holding_since, self._clock()):
            return False
        self._holding_since = None
        try:
            self.driver.deactivate()
        except DriverError as exc:
            self._on_fault(exc)
        self.twist_command = np.zeros(3)
        self.joint_command[:] = 0.0
        return True

    def _check_estop(self) -> None:
        """Quick-stop and disarm when the e-stop is (or becomes) pressed."""
        reason = self.estop.reason(self._clock())
        self.estop_reason = reason
        if reason is None or not self.driver.armed:
            return
        self._holding_since = None
        self._trajectory = None
        self.cancel_unwind(f"emergency stop: {reason}")
        self._command = None
        self.twist_command = np.zeros(3)
        self.joint_command[:] = 0.0
        try:
            self.driver.quick_stop()
        except DriverError as exc:
            self._on_fault(exc)

    def _on_fault(self, exc: DriverError) -> None:
        self.counters["driver_errors"] += 1
        self.raise_fault(str(exc))

    def raise_fault(self, reason: str) -> None:
        """Fault and stop: zero the joints and disarm the motors. For the
        cycle's own checks and for callers outside it (an exception in the
        loop); loop thread only, as :meth:`step`."""
        # The first failure is the cause; what follows while disarmed (the
        # same device still silent, ...) is its consequence.
        if self.fault is None:
            self.fault = reason
        self.twist_command = np.zeros(3)
        self._trajectory = None
        self.cancel_unwind(f"fault: {reason}")
        self._holding_since = None
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
