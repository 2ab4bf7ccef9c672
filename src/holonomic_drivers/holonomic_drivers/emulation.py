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

Motors are ideal: in velocity control the speed follows the setpoint within
``max_acceleration``; an idle or disabled motor stops at the same rate.
"""

from __future__ import annotations

import math
import struct
import threading
import time
from dataclasses import dataclass

import can

from holonomic_drivers import cia402_protocol as co
from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers.odrive_protocol import AxisState, Cmd, ControlMode


def _approach(value: float, target: float, step: float) -> float:
    return target if abs(target - value) <= step else value + math.copysign(step, target - value)


class EmulatedDevice:
    """Common part: own bus, failure switch, the ideal motor."""

    def __init__(self, channel: str, max_acceleration: float):
        """``max_acceleration`` [motor rev/s^2] of the ideal motor."""
        # the device stamps what it sends (preserve_timestamps): a real drive
        # answers a SYNC within a fraction of a millisecond, whenever this
        # emulator's thread gets to run on a busy test machine
        self.bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
        self.max_acceleration = float(max_acceleration)
        #: no frame at all leaves the device (unplugged, dead CPU)
        self.silent = False
        self.position_rev = 0.0
        self.velocity_rev_per_s = 0.0
        self._last_tick: float | None = None
        self._lock = threading.RLock()

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
        target = self.target_velocity(now)
        self.velocity_rev_per_s = _approach(self.velocity_rev_per_s, target,
                                            self.max_acceleration * dt)
        self.position_rev += self.velocity_rev_per_s * dt

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

    def target_velocity(self, now: float) -> float:
        raise NotImplementedError

    def cyclic(self, now: float) -> None:
        pass


class EmulatedOdriveAxis(EmulatedDevice):
    """One ODrive axis speaking CANSimple (firmware 0.6 message layout).

    Failure injection: ``silent``; ``encoder_period`` (make it long: the
    axis answers late); ``inject_error(bits)`` -- a condition that disarms
    the axis and persists until ``clear_condition()``; after that a
    Clear_Errors from the host clears the latched error.
    """

    def __init__(self, node_id: int, channel: str, heartbeat_period: float = 0.1,
                 encoder_period: float = 0.01, max_acceleration: float = 200.0,
                 watchdog_timeout: float = 0.0):
        """Periods [s]; ``watchdog_timeout`` [s] > 0: no setpoint for that long
        in closed loop -> WATCHDOG_TIMER_EXPIRED (the ODrive's axis watchdog)."""
        super().__init__(channel, max_acceleration)
        self._ramp = float(max_acceleration)
        #: [kg m^2] of the free motor in torque mode
        self.motor_inertia = 1e-4
        self.node_id = node_id
        self.heartbeat_period = heartbeat_period
        self.encoder_period = encoder_period
        self.watchdog_timeout = watchdog_timeout
        self.axis_state = AxisState.IDLE
        self.control_mode = ControlMode.VELOCITY_CONTROL
        self.input_mode = proto.InputMode.PASSTHROUGH
        self.input_vel = 0.0
        self.input_torque = 0.0
        self.condition = 0          # persistent error condition (hardware)
        self.disarm_reason = 0      # latched until Clear_Errors
        self._next_heartbeat = -math.inf
        self._last_input = 0.0

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
                self._disarm(0x2000000)   # ESTOP_REQUESTED
        except (struct.error, ValueError):
            pass    # a real ODrive ignores malformed frames too

    def target_velocity(self, now: float) -> float:
        if self.axis_state != AxisState.CLOSED_LOOP_CONTROL:
            return 0.0
        if self.watchdog_timeout > 0 and now - self._last_input > self.watchdog_timeout:
            self._disarm(0x1000000)       # WATCHDOG_TIMER_EXPIRED
            return 0.0
        if self.control_mode == ControlMode.VELOCITY_CONTROL:
            return self.input_vel
        # torque mode: a free motor of inertia ``motor_inertia`` accelerates
        # at torque / inertia (toward a far target, at that rate)
        return math.copysign(1e9, self.input_torque) if self.input_torque else \
            self.velocity_rev_per_s

    def _advance(self, now: float) -> None:
        if (self.control_mode == ControlMode.TORQUE_CONTROL
                and self.axis_state == AxisState.CLOSED_LOOP_CONTROL):
            # the ideal motor's acceleration is the torque's, not a ramp's
            self.max_acceleration = abs(self.input_torque) / self.motor_inertia / (2 * math.pi)
        else:
            self.max_acceleration = self._ramp
        super()._advance(now)

    def cyclic(self, now: float) -> None:
        if now >= self._next_heartbeat:
            self._next_heartbeat = now + self.heartbeat_period
            self._send_heartbeat()
        if now >= self._next_encoder:
            self._next_encoder = now + self._encoder_period
            self._send_estimates()

    def _send_heartbeat(self) -> None:
        self.send(proto.frame_id(self.node_id, Cmd.HEARTBEAT),
                  proto.Heartbeat(self.axis_error, int(self.axis_state), 0, True).encode())

    def _send_estimates(self) -> None:
        self.send(proto.frame_id(self.node_id, Cmd.GET_ENCODER_ESTIMATES),
                  proto.EncoderEstimates(self.position_rev, self.velocity_rev_per_s).encode())


@dataclass
class _Obj:
    """One object-dictionary entry of the emulated drive."""

    fmt: str            # struct format of the value ("<H", "<i", ...)
    value: int
    writable: bool = True


def _cia402_dictionary(node_id: int) -> dict[tuple[int, int], _Obj]:
    od = {
        (co.DEVICE_TYPE, 0): _Obj("<I", 0x00020000 | co.PROFILE_402, False),
        (co.ERROR_REGISTER, 0): _Obj("<B", 0, False),
        (co.CONSUMER_HEARTBEAT_TIME, 0): _Obj("<B", 1, False),
        (co.CONSUMER_HEARTBEAT_TIME, 1): _Obj("<I", 0),
        (co.PRODUCER_HEARTBEAT_TIME, 0): _Obj("<H", 0),
        (co.ERROR_CODE, 0): _Obj("<H", 0, False),
        (co.CONTROLWORD, 0): _Obj("<H", 0),
        (co.STATUSWORD, 0): _Obj("<H", co.statusword_of(co.State.SWITCH_ON_DISABLED), False),
        (co.QUICK_STOP_OPTION, 0): _Obj("<h", 2),
        (co.MODES_OF_OPERATION, 0): _Obj("<b", 0),
        (co.MODES_DISPLAY, 0): _Obj("<b", 0, False),
        (co.POSITION_ACTUAL, 0): _Obj("<i", 0, False),
        (co.VELOCITY_ACTUAL, 0): _Obj("<i", 0, False),
        (co.TARGET_VELOCITY, 0): _Obj("<i", 0),
        (co.TARGET_TORQUE, 0): _Obj("<h", 0),
        (co.MOTOR_RATED_TORQUE, 0): _Obj("<I", 1000, False),              # 1 N m
        (co.SUPPORTED_MODES, 0): _Obj("<I", (1 << 2) | (1 << 8) | (1 << 9), False),  # pv csv cst
    }
    # four RPDOs and TPDOs with the predefined COB-IDs, RPDO1/TPDO1 valid
    for k in range(4):
        for comm, mapping, base in ((co.RPDO_COMM, co.RPDO_MAP, co.RPDO[k]),
                                    (co.TPDO_COMM, co.TPDO_MAP, co.TPDO[k])):
            od[(comm + k, 0)] = _Obj("<B", 5, False)
            od[(comm + k, 1)] = _Obj("<I", (base + node_id) | (0 if k == 0 else co.PDO_INVALID))
            od[(comm + k, 2)] = _Obj("<B", 0xFF)
            od[(mapping + k, 0)] = _Obj("<B", 0)
            for sub in range(1, 9):
                od[(mapping + k, sub)] = _Obj("<I", 0)
    return od


class EmulatedCia402Drive(EmulatedDevice):
    """A CANopen CiA 402 drive: NMT, SDO server (expedited), heartbeat
    producer and consumer, SYNC, dynamic PDO mapping, EMCY, the 402 power
    state machine, the velocity modes (pv, csv) and cyclic synchronous torque.

    Positions are in counts (``encoder_resolution`` per motor rev), speeds
    in counts/s. Failure injection: ``silent``; ``inject_fault(code)`` -- a
    fault condition (EMCY, FAULT state) that persists until
    ``clear_condition()``; ``answer_every`` = k: TPDOs only on every k-th
    SYNC (the drive answers late); ``sdo_silent``: no SDO answers.
    """

    def __init__(self, node_id: int, channel: str, encoder_resolution: int = 4096,
                 max_acceleration: float = 200.0):
        super().__init__(channel, max_acceleration)
        self._ramp = float(max_acceleration)
        #: [kg m^2] of the free motor in cyclic synchronous torque
        self.motor_inertia = 1e-4
        self.node_id = node_id
        self.encoder_resolution = encoder_resolution
        self.od = _cia402_dictionary(node_id)
        self.nmt = co.NmtState.PRE_OPERATIONAL
        self.state = co.State.SWITCH_ON_DISABLED
        self.condition = 0
        self.answer_every = 1
        self.sdo_silent = False
        self._syncs = 0
        self._next_heartbeat = -math.inf
        self._master_heartbeat: float | None = None
        self._pending: dict[tuple[int, int], int] = {}   # RPDO data applied at SYNC
        self._booted = False
        self._previous_controlword = 0

    # -- object dictionary -----------------------------------------------------------
    def get(self, index: int, sub: int = 0) -> int:
        return self.od[(index, sub)].value

    def _set(self, index: int, sub: int, value: int) -> None:
        self.od[(index, sub)].value = value
        if index == co.CONTROLWORD:
            self._on_controlword(value)
            self.od[(co.STATUSWORD, 0)].value = co.statusword_of(self.state)
        elif index == co.MODES_OF_OPERATION:
            self.od[(co.MODES_DISPLAY, 0)].value = value

    # -- failure injection ---------------------------------------------------------------
    def inject_fault(self, error_code: int = 0x2310) -> None:
        """A fault condition (default 0x2310: continuous over-current)."""
        with self._lock:
            self.condition = error_code
            self._fault(error_code)

    def clear_condition(self) -> None:
        with self._lock:
            self.condition = 0

    def _fault(self, error_code: int) -> None:
        self.state = co.State.FAULT
        self.od[(co.STATUSWORD, 0)].value = co.statusword_of(self.state)
        self.od[(co.ERROR_CODE, 0)].value = error_code
        self.od[(co.ERROR_REGISTER, 0)].value = 0x01
        if not self.silent:
            self.send(co.EMCY + self.node_id, co.emcy(error_code))

    # -- protocol -------------------------------------------------------------------------------
    def handle(self, msg: can.Message, now: float) -> None:
        if msg.is_extended_id or msg.is_remote_frame:
            return
        cob, data = msg.arbitration_id, bytes(msg.data)
        if cob == co.NMT and len(data) == 2 and data[1] in (0, self.node_id):
            self._on_nmt(data[0])
        elif cob == co.SYNC:
            self._on_sync(now)
        elif cob == co.SDO_RX + self.node_id and self.nmt != co.NmtState.STOPPED:
            if not self.sdo_silent:
                self._on_sdo(data)
        elif cob == self._master_cob():
            self._master_heartbeat = now
        elif self.nmt == co.NmtState.OPERATIONAL:
            for k in range(4):
                if cob == self.get(co.RPDO_COMM + k, 1):      # valid: bit 31 clear
                    self._on_rpdo(k, data)

    def _master_cob(self) -> int | None:
        entry = self.get(co.CONSUMER_HEARTBEAT_TIME, 1)
        return co.HEARTBEAT + (entry >> 16 & 0x7F) if entry & 0xFFFF else None

    def _on_nmt(self, command: int) -> None:
        if command == co.NmtCommand.START:
            self.nmt = co.NmtState.OPERATIONAL
        elif command == co.NmtCommand.STOP:
            self.nmt = co.NmtState.STOPPED
        elif command == co.NmtCommand.ENTER_PRE_OPERATIONAL:
            self.nmt = co.NmtState.PRE_OPERATIONAL
        elif command in (co.NmtCommand.RESET_NODE, co.NmtCommand.RESET_COMMUNICATION):
            self.od = _cia402_dictionary(self.node_id)
            self.state = co.State.SWITCH_ON_DISABLED
            self.nmt = co.NmtState.PRE_OPERATIONAL
            self._booted = False
        if self.nmt != co.NmtState.OPERATIONAL and self.state is co.State.OPERATION_ENABLED:
            # losing the PDO link while enabled is a communication fault
            self._fault(0x8100)

    def _on_sdo(self, data: bytes) -> None:
        if len(data) != 8:
            return
        command = data[0]
        index, sub = struct.unpack_from("<HB", data, 1)
        reply = co.SDO_TX + self.node_id
        obj = self.od.get((index, sub))
        if obj is None:
            exists = any(i == index for i, _ in self.od)
            self.send(reply, co.sdo_abort(index, sub, co.ABORT_NO_SUBINDEX if exists
                                          else co.ABORT_NO_OBJECT))
            return
        size = struct.calcsize(obj.fmt)
        if command == 0x40:                                  # upload
            self.send(reply, co.sdo_upload_response(index, sub, struct.pack(obj.fmt, obj.value)))
        elif command & 0xE3 == 0x23:                         # expedited download, size given
            n = 4 - ((command >> 2) & 0x3)
            if not obj.writable:
                self.send(reply, co.sdo_abort(index, sub, co.ABORT_READ_ONLY))
            elif n != size:
                self.send(reply, co.sdo_abort(index, sub, 0x06070010))   # length mismatch
            else:
                (value,) = struct.unpack(obj.fmt, data[4:4 + n])
                if index == co.MODES_OF_OPERATION and value not in (
                        co.OpMode.PROFILE_VELOCITY, co.OpMode.CYCLIC_SYNCHRONOUS_VELOCITY):
                    self.send(reply, co.sdo_abort(index, sub, co.ABORT_RANGE))
                    return
                self._set(index, sub, value)
                self.send(reply, co.sdo_download_response(index, sub))
        else:
            self.send(reply, co.sdo_abort(index, sub, co.ABORT_UNSUPPORTED))

    def _mapping(self, map_index: int) -> list[tuple[int, int, int]]:
        count = self.get(map_index, 0)
        entries = [self.get(map_index, s) for s in range(1, count + 1)]
        return [(e >> 16, (e >> 8) & 0xFF, e & 0xFF) for e in entries]

    def _on_rpdo(self, k: int, data: bytes) -> None:
        offset = 0
        values = {}
        for index, sub, bits in self._mapping(co.RPDO_MAP + k):
            obj = self.od.get((index, sub))
            n = bits // 8
            if obj is None or offset + n > len(data):
                return          # a PDO shorter than its mapping is ignored
            (values[(index, sub)],) = struct.unpack(obj.fmt, data[offset:offset + n])
            offset += n
        if self.get(co.RPDO_COMM + k, 2) <= 240:
            self._pending.update(values)                    # applied at the next SYNC
        else:
            for (index, sub), value in values.items():
                self._set(index, sub, value)

    #: [s] from a SYNC to the drive's answer on the bus
    ANSWER_DELAY = 1e-4

    def _on_sync(self, at: float) -> None:
        """The SYNC sent at ``at`` [s, wall clock]: apply the RPDOs, sample, answer."""
        pending, self._pending = self._pending, {}
        for (index, sub), value in pending.items():
            self._set(index, sub, value)
        if self.nmt != co.NmtState.OPERATIONAL:
            return
        self._syncs += 1
        if self._syncs % self.answer_every:
            return
        self._update_feedback()
        for k in range(4):
            cob = self.get(co.TPDO_COMM + k, 1)
            if cob & co.PDO_INVALID or not 1 <= self.get(co.TPDO_COMM + k, 2) <= 240:
                continue
            payload = b"".join(struct.pack(self.od[(i, s)].fmt, self.od[(i, s)].value)
                               for i, s, _ in self._mapping(co.TPDO_MAP + k))
            self.send(cob, payload, at + self.ANSWER_DELAY)

    def _on_controlword(self, word: int) -> None:
        previous, self._previous_controlword = self._previous_controlword, word
        if self.state is co.State.FAULT:
            if word & 0x80 and not previous & 0x80 and not self.condition:
                self.state = co.State.SWITCH_ON_DISABLED
                self.od[(co.ERROR_CODE, 0)].value = 0
                self.od[(co.ERROR_REGISTER, 0)].value = 0
            return
        self.state = co.next_state(self.state, word, previous)

    def _update_feedback(self) -> None:
        self.od[(co.STATUSWORD, 0)].value = co.statusword_of(self.state)
        self.od[(co.POSITION_ACTUAL, 0)].value = _int32(
            round(self.position_rev * self.encoder_resolution))
        self.od[(co.VELOCITY_ACTUAL, 0)].value = _int32(
            round(self.velocity_rev_per_s * self.encoder_resolution))

    def target_velocity(self, now: float) -> float:
        consumer = self.get(co.CONSUMER_HEARTBEAT_TIME, 1) & 0xFFFF
        if (consumer and self._master_heartbeat is not None and self.state is not co.State.FAULT
                and now - self._master_heartbeat > consumer * 1e-3):
            self._fault(0x8130)             # heartbeat (life guard) error
        if self.state is co.State.QUICK_STOP_ACTIVE and self.velocity_rev_per_s == 0.0:
            self.state = co.State.SWITCH_ON_DISABLED      # quick stop option code 2
        if self.state is not co.State.OPERATION_ENABLED:
            return 0.0
        if self.get(co.MODES_OF_OPERATION) == co.OpMode.CYCLIC_SYNCHRONOUS_TORQUE:
            # a free motor: toward a far target at torque / inertia (_advance)
            torque = self.get(co.TARGET_TORQUE)
            return math.copysign(1e9, torque) if torque else self.velocity_rev_per_s
        return self.get(co.TARGET_VELOCITY) / self.encoder_resolution

    def _advance(self, now: float) -> None:
        if (self.get(co.MODES_OF_OPERATION) == co.OpMode.CYCLIC_SYNCHRONOUS_TORQUE
                and self.state is co.State.OPERATION_ENABLED):
            torque = self.get(co.TARGET_TORQUE) * 1e-3 * self.get(co.MOTOR_RATED_TORQUE) * 1e-3
            self.max_acceleration = abs(torque) / self.motor_inertia / (2 * math.pi)
        else:
            self.max_acceleration = self._ramp
        super()._advance(now)

    def cyclic(self, now: float) -> None:
        if not self._booted:
            self._booted = True
            self.send(co.HEARTBEAT + self.node_id, bytes([co.NmtState.BOOT_UP]))
        self.od[(co.STATUSWORD, 0)].value = co.statusword_of(self.state)
        period = self.get(co.PRODUCER_HEARTBEAT_TIME) * 1e-3
        if period > 0 and now >= self._next_heartbeat:
            self._next_heartbeat = now + period
            self.send(co.HEARTBEAT + self.node_id, bytes([self.nmt]))


def _int32(value: int) -> int:
    return (value + 2 ** 31) % 2 ** 32 - 2 ** 31


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
