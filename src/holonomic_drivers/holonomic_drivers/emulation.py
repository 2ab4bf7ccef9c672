"""Emulated motor drives on python-can's virtual bus, for tests and dry runs.

Each emulated device opens its own ``virtual`` bus on a channel shared with
the driver under test, obeys its protocol, integrates the commanded speed
into its encoder position and can be told to fail. Two ways to run them:

* by hand: ``device.poll(now)`` handles the frames that reached it,
  ``device.tick(now)`` advances its motor and sends what is due (heartbeat,
  encoder messages); ``now`` is wall-clock time (``time.time()``), the
  clock of python-can's frame timestamps;
* in the background: ``EmulatorThread(devices)`` does both every
  millisecond (a context manager).

Each device drives a *motor* (constructor argument ``motor=``), anything with
this interface, all on the motor shaft in SI units::

    command_velocity(rad_per_s)    velocity setpoint of the drive's loop
    command_torque(newton_metre)   torque setpoint (torque control)
    position() -> rad              shaft angle (what the encoder measures)
    velocity() -> rad/s            shaft speed
    advance(dt)                    let dt seconds pass

The device calls ``command_*`` with what its protocol state asks for (an
idle or disabled drive commands zero speed) and ``advance`` as time passes.
The default, :class:`IdealMotor`, is ideal: in velocity control the speed
follows the setpoint within ``max_acceleration``; an idle or disabled motor
stops at the same rate; in torque control it is a free inertia. With
``holonomic-bringup --sim-drives`` the motor is a simulated joint instead
(:mod:`holonomic_sim.joint_motor`).

The emulated CiA 402 drive (built on canopen's LocalNode from the drive's
EDS) is in :mod:`holonomic_drivers.emulated_cia402`; ``EmulatorThread``
runs it too.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from typing import Protocol

import can

from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers.odrive_protocol import AxisState, Cmd, ControlMode


TWO_PI = 2.0 * math.pi


def _approach(value: float, target: float, step: float) -> float:
    return target if abs(target - value) <= step else value + math.copysign(step, target - value)


class Motor(Protocol):
    """What an emulated drive drives: motor shaft, SI units."""

    def command_velocity(self, rad_per_s: float) -> None:
        """Follow this speed [rad/s] (as the drive's velocity loop does)."""

    def command_torque(self, newton_metre: float) -> None:
        """Apply this torque [N m] (torque control)."""

    def position(self) -> float:
        """Shaft angle [rad]."""

    def velocity(self) -> float:
        """Shaft speed [rad/s]."""

    def advance(self, dt: float) -> None:
        """Move on by ``dt`` [s] under the last command."""


class IdealMotor:
    """The default motor of an emulated drive (motor shaft, SI units).

    Velocity control: the speed ramps to the setpoint at ``max_acceleration``
    [rad/s^2]. Torque control: a free rotor of ``inertia`` [kg m^2]
    accelerates at torque / inertia (no friction, no limit). Position
    integrates the speed exactly over each step (trapezoid).
    """

    def __init__(self, max_acceleration: float = 200.0 * TWO_PI, inertia: float = 1e-4):
        self.max_acceleration = float(max_acceleration)
        self.inertia = float(inertia)
        self._position = 0.0
        self._velocity = 0.0
        self._target_velocity = 0.0
        self._torque: float | None = None

    def command_velocity(self, rad_per_s: float) -> None:
        self._target_velocity, self._torque = float(rad_per_s), None

    def command_torque(self, newton_metre: float) -> None:
        self._torque = float(newton_metre)

    def position(self) -> float:
        return self._position

    def velocity(self) -> float:
        return self._velocity

    def advance(self, dt: float) -> None:
        if dt <= 0.0:
            return
        start = self._velocity
        if self._torque is None:
            self._velocity = _approach(self._velocity, self._target_velocity,
                                       self.max_acceleration * dt)
        else:
            self._velocity += self._torque / self.inertia * dt
        self._position += 0.5 * (start + self._velocity) * dt


class EmulatedDevice:
    """Common part: own bus, failure switch, the motor."""

    def __init__(self, channel: str, max_acceleration: float, motor=None):
        """``max_acceleration`` [motor rev/s^2] of the default :class:`IdealMotor`;
        ``motor``: another motor (see the module docstring)."""
        # the device stamps what it sends (preserve_timestamps): a real drive
        # answers within a fraction of a millisecond, whenever this emulator's
        # thread gets to run on a busy test machine
        self.bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
        self.motor = motor if motor is not None else IdealMotor(max_acceleration * TWO_PI)
        #: no frame at all leaves the device (unplugged, dead CPU)
        self.silent = False
        self._last_tick: float | None = None
        self._lock = threading.RLock()

    @property
    def position_rev(self) -> float:
        """Motor shaft position [rev]."""
        return self.motor.position() / TWO_PI

    @property
    def velocity_rev_per_s(self) -> float:
        """Motor shaft speed [rev/s]."""
        return self.motor.velocity() / TWO_PI

    def poll(self, now: float) -> None:
        """Handle every frame waiting on the device's bus.

        The motor is advanced to each frame's send time first (``now`` is on
        the wall clock, like python-can's timestamps), so that a drive
        sampling on SYNC samples when the SYNC was sent.
        """
        with self._lock:
            while (msg := self.bus.recv(timeout=0.0)) is not None:
                at = min(msg.timestamp or now, now)
                self._advance(at)
                if not self.silent:
                    self.handle(msg, at)

    def tick(self, now: float) -> None:
        """Advance the motor to ``now`` [s, wall clock] and send what is due."""
        with self._lock:
            self._advance(now)
            if not self.silent:
                self.cyclic(now)

    def _advance(self, now: float) -> None:
        if self._last_tick is not None and now <= self._last_tick:
            return
        dt = 0.0 if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        self.command_motor(now)
        self.motor.advance(dt)

    def send(self, arbitration_id: int, data: bytes, at: float | None = None) -> None:
        """Send a frame stamped ``at`` [s, wall clock] (default: now)."""
        self.bus.send(can.Message(arbitration_id=arbitration_id, data=data,
                                  is_extended_id=False,
                                  timestamp=time.time() if at is None else at))

    def close(self) -> None:
        self.bus.shutdown()

    # -- protocol hooks -------------------------------------------------------------
    def handle(self, msg: can.Message, now: float) -> None:
        raise NotImplementedError

    def command_motor(self, now: float) -> None:
        """Give the motor what the drive's state asks for at ``now``."""
        raise NotImplementedError

    def cyclic(self, now: float) -> None:
        pass


class EmulatedOdriveAxis(EmulatedDevice):
    """One ODrive axis speaking CANSimple, in the message layout and error
    bits of ``firmware`` ("0.6" or "0.5").

    Failure injection: ``silent``; ``encoder_period`` (make it long: the
    axis answers late); ``inject_error(bits)`` -- a condition that disarms
    the axis and persists until ``clear_condition()``; after that a
    Clear_Errors from the host clears the latched error.

    The axis watchdog (``enable_watchdog``, ``watchdog_timeout`` [s]), as
    each firmware line has it:

    * 0.5 (its open source: can_simple.cpp feeds the addressed axis on every
      frame, main.cpp checks every axis in every state): any frame to the
      axis feeds it; when it expires, WATCHDOG_TIMER_EXPIRED is latched even
      in IDLE;
    * 0.6 (closed source): Set_Input_Vel and Set_Axis_State feed it
      (ODrive's can_watchdog example), here Set_Input_Torque too; it
      disarms an axis in closed-loop control.

    Firmware 0.6 also answers Get_Version (``version``) and, given
    ``endpoints`` (an :class:`~holonomic_drivers.odrive_endpoints.EndpointFile`),
    RxSdo reads and writes of the two watchdog endpoints by their ids; a
    write is confirmed from firmware 0.6.11 on, as ODrive's examples say.
    Unknown ids get no answer. ``watchdog_expired`` is (fed at, detected at)
    [s, wall clock] of the last expiry.
    """

    def __init__(self, node_id: int, channel: str, heartbeat_period: float = 0.1,
                 encoder_period: float = 0.01, max_acceleration: float = 200.0,
                 watchdog_timeout: float = 0.0, motor=None, firmware: str = "0.6",
                 enable_watchdog: bool | None = None, endpoints=None,
                 version: proto.Version | None = None):
        """Periods [s]; ``watchdog_timeout`` [s]: the axis watchdog (see the
        class docstring), enabled by ``enable_watchdog`` (default: when the
        timeout is > 0); ``motor``: see the module docstring (default: an
        ideal motor that ramps at ``max_acceleration`` [rev/s^2]);
        ``version``: what Get_Version answers (0.6; default firmware 0.6.11
        on an ODrive Pro, board 4.4.58)."""
        super().__init__(channel, max_acceleration, motor)
        if firmware not in proto.FIRMWARES:
            raise ValueError(f"firmware {firmware!r} not one of {proto.FIRMWARES}")
        self.firmware = firmware
        self.node_id = node_id
        self.heartbeat_period = heartbeat_period
        self.encoder_period = encoder_period
        self.watchdog_timeout = watchdog_timeout
        self.enable_watchdog = watchdog_timeout > 0 if enable_watchdog is None \
            else bool(enable_watchdog)
        self.version = version or proto.Version(2, (4, 4, 58), (0, 6, 11))
        #: endpoint id -> (attribute, type) of what RxSdo can reach
        self._endpoints = {} if endpoints is None else {
            e.id: (e.path.rsplit(".", 1)[1], e.type) for e in endpoints.endpoints.values()}
        self.watchdog_expired: tuple[float, float] | None = None
        self.axis_state = AxisState.IDLE
        self.control_mode = ControlMode.VELOCITY_CONTROL
        self.input_mode = proto.InputMode.PASSTHROUGH
        self.input_vel = 0.0
        self.input_torque = 0.0
        self.condition = 0          # persistent error condition (hardware)
        self.disarm_reason = 0      # latched until Clear_Errors
        self._next_heartbeat = -math.inf
        self._last_input = 0.0

    @classmethod
    def settings_for(cls, params, joint: str) -> dict:
        """The keyword arguments that make this axis the one the validated
        ``odrive_can`` parameters ``params`` describe for ``joint`` (the
        firmware line; the node id is the caller's)."""
        return {"firmware": params["odrive_can.firmware"]}

    @property
    def encoder_period(self) -> float:
        """Period [s] of the cyclic encoder estimates (make it long: the axis
        answers late); a new period takes effect at once."""
        return self._encoder_period

    @encoder_period.setter
    def encoder_period(self, period: float) -> None:
        self._encoder_period = period
        self._next_encoder = -math.inf

    @property
    def last_feed(self) -> float:
        """When the axis watchdog was last fed [s, wall clock]."""
        return self._last_input

    @property
    def axis_error(self) -> int:
        return self.condition | self.disarm_reason

    def inject_error(self, bits: int) -> None:
        with self._lock:
            self.condition |= bits
            self._disarm(bits)

    def clear_condition(self) -> None:
        with self._lock:
            self.condition = 0

    def _disarm(self, reason: int) -> None:
        self.disarm_reason |= reason
        self.axis_state = AxisState.IDLE

    def handle(self, msg: can.Message, now: float) -> None:
        node, cmd = proto.split_id(msg.arbitration_id)
        if node != self.node_id or msg.is_extended_id:
            return
        data = bytes(msg.data)
        if self.firmware == "0.5":
            self._last_input = now       # any frame to the axis feeds 0.5's watchdog
        elif cmd == Cmd.GET_VERSION and msg.is_remote_frame:
            # the request is a remote frame (ODrive's CAN docs); an empty data
            # frame on this id is not one (it would collide with the answer)
            self.send(proto.frame_id(self.node_id, Cmd.GET_VERSION), self.version.encode())
            return
        elif cmd == Cmd.RX_SDO and not msg.is_remote_frame:
            self._sdo(data)
            return
        if msg.is_remote_frame:
            if cmd == Cmd.GET_ENCODER_ESTIMATES:
                self._send_estimates()
            elif cmd == Cmd.HEARTBEAT:
                self._send_heartbeat()
            return
        try:
            if cmd == Cmd.SET_AXIS_STATE:
                (state,) = struct.unpack("<I", data[:4])
                if state == AxisState.CLOSED_LOOP_CONTROL:
                    if self.axis_error == 0:
                        self.axis_state = AxisState.CLOSED_LOOP_CONTROL
                        self._last_input = now
                elif state == AxisState.IDLE:
                    self.axis_state = AxisState.IDLE
            elif cmd == Cmd.SET_CONTROLLER_MODE:
                control, inp = struct.unpack("<II", data[:8])
                self.control_mode, self.input_mode = ControlMode(control), proto.InputMode(inp)
            elif cmd == Cmd.SET_INPUT_VEL:
                self.input_vel, _ = struct.unpack("<ff", data[:8])
                self._last_input = now
            elif cmd == Cmd.SET_INPUT_TORQUE:
                (self.input_torque,) = struct.unpack("<f", data[:4])
                self._last_input = now
            elif cmd == Cmd.CLEAR_ERRORS:
                self.disarm_reason = 0
            elif cmd == Cmd.ESTOP:
                self._disarm(proto.ESTOP_REQUESTED[self.firmware])
        except (struct.error, ValueError):
            pass    # a real ODrive ignores malformed frames too

    def _sdo(self, data: bytes) -> None:
        """RxSdo: read or write one of the endpoints this axis knows."""
        try:
            opcode, endpoint_id, _ = struct.unpack_from("<BHB", data)
        except struct.error:
            return
        if endpoint_id not in self._endpoints:
            return
        name, kind = self._endpoints[endpoint_id]
        if opcode == proto.SDO_WRITE:
            try:
                setattr(self, name, proto.decode_value(kind, data[4:]))
            except ValueError:
                return
            if self.version.fw < (0, 6, 11):
                return
        elif opcode != proto.SDO_READ:
            return
        reply = proto.SdoReply(endpoint_id, proto.encode_value(kind, getattr(self, name)))
        self.send(proto.frame_id(self.node_id, Cmd.TX_SDO), reply.encode())

    def command_motor(self, now: float) -> None:
        # 0.5 checks the watchdog in every state, 0.6 (as emulated) in closed loop
        if (self.enable_watchdog and self.watchdog_timeout > 0
                and (self.firmware == "0.5" or self.axis_state == AxisState.CLOSED_LOOP_CONTROL)
                and now - self._last_input > self.watchdog_timeout):
            bit = proto.WATCHDOG_TIMER_EXPIRED[self.firmware]
            if not self.disarm_reason & bit:
                self.watchdog_expired = (self._last_input, now)
            self._disarm(bit)
        if self.axis_state != AxisState.CLOSED_LOOP_CONTROL:
            self.motor.command_velocity(0.0)
        elif self.control_mode == ControlMode.TORQUE_CONTROL:
            self.motor.command_torque(self.input_torque)          # [N m] at the motor
        else:
            self.motor.command_velocity(self.input_vel * TWO_PI)  # rev/s -> rad/s

    def cyclic(self, now: float) -> None:
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + self.heartbeat_period
            self._send_heartbeat()
        if now >= self._next_encoder:
            self._next_encoder = now + self._encoder_period
            self._send_estimates()

    def _send_heartbeat(self) -> None:
        self.send(proto.frame_id(self.node_id, Cmd.HEARTBEAT),
                  proto.Heartbeat(self.axis_error, int(self.axis_state), 0, True).encode(
                      self.firmware))

    def _send_estimates(self) -> None:
        self.send(proto.frame_id(self.node_id, Cmd.GET_ENCODER_ESTIMATES),
                  proto.EncoderEstimates(self.position_rev, self.velocity_rev_per_s).encode())


class EmulatorThread:
    """Runs devices in the background: ``poll`` + ``tick`` every ``period`` [s]."""

    def __init__(self, devices, period: float = 0.001):
        self.devices = list(devices)
        self.period = period
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="can-emulator", daemon=True)

    def start(self) -> "EmulatorThread":
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def __enter__(self):
        return self.start()

    def __exit__(self, *exc):
        self.stop()
        return False

    def _run(self) -> None:
        while not self._stop.is_set():
            now = time.time()       # the clock of python-can's frame timestamps
            for device in self.devices:
                device.poll(now)
                device.tick(now)
            self._stop.wait(self.period)
