"""An emulated CANopen CiA 402 drive on python-can's virtual bus.

The drive's object dictionary is a ``canopen.LocalNode`` built from an EDS
or DCF file (or the generic dictionary of :mod:`cia402_dictionary`), so
canopen's own SDO server answers the master and enforces the file's data
types, sizes and access rights. On top of it this module adds what a drive
does: NMT, heartbeat producer and consumer, node guarding and life
guarding, SYNC, PDOs as the master maps them (refusing objects the file
does not allow in a PDO), EMCY, the CiA 402 power state machine per axis,
the velocity modes (pv, csv) and cyclic synchronous torque (cst), and the
motors.

Users: the tests (drivers against drives as their EDS files describe them)
and the CAN-in-the-loop simulation (``--sim-drives``), which plugs a
simulated joint in as the motor. Constructor::

    EmulatedCia402Drive(node_id, channel, eds=None, *, encoder_resolution=4096,
                        velocity_resolution=None, max_acceleration=200.0,
                        motor=None)

* ``eds``: path of an EDS/DCF file, a ``canopen`` ObjectDictionary, or None
  for the generic drive; multi-axis devices (profile objects at +0x800 per
  axis) get one motor per axis;
* ``encoder_resolution`` [counts per motor rev] of 0x6064;
* ``velocity_resolution`` [units of 0x606C/0x60FF per motor rev/s]; None:
  what the file's 0x60A9 says (rpm: 60, 0.1 rpm: 600, ...), else counts/s;
* ``max_acceleration`` [motor rev/s^2] of the default :class:`IdealMotor`;
* ``motor``: an object with the :class:`Motor` protocol (motor shaft, SI
  units), or a sequence of them, one per axis.

Run it by hand (``poll(now)`` handles waiting frames, ``tick(now)``
advances the motors and sends what is due; ``now`` on the wall clock, that
of python-can's frame timestamps) or with ``emulation.EmulatorThread``.
Failure injection: ``silent`` (no frame leaves the device), ``sdo_silent``
(no SDO answers), ``answer_every`` = k (TPDOs on every k-th SYNC only),
``inject_fault(code, axis)`` (a fault condition that persists until
``clear_condition()``).
"""

from __future__ import annotations

import bisect
import math
import threading
import time
from collections import deque
from dataclasses import dataclass, field
from typing import Sequence

import can
import canopen
from canopen.objectdictionary import ODVariable, ObjectDictionary
from canopen.objectdictionary.datatypes import FLOAT_TYPES, NUMBER_TYPES
from canopen.sdo import SdoAbortedError

from holonomic_drivers import cia402_protocol as co
from holonomic_drivers.cia402_dictionary import (AXIS_OFFSET, MAX_AXES, AxisObjects,
                                                 SI_VELOCITY_UNITS, generic_dictionary,
                                                 integer_range, mode_bit)
from holonomic_drivers.cia402_protocol import OpMode, State
from holonomic_drivers.emulation import IdealMotor, Motor

TWO_PI = 2.0 * math.pi
#: SDO abort codes (CiA 301) the drive uses beyond canopen's own
ABORT_CANNOT_MAP = 0x06040041
ABORT_PDO_TOO_LONG = 0x06040042
ABORT_VALUE_RANGE = 0x06090030
#: motor states kept per axis (about 2 s of 1 ms steps)
_HISTORY = 2048
#: objects the drive writes itself (read-only to the master)
_OWN_OBJECTS = frozenset((co.STATUSWORD, co.POSITION_ACTUAL, co.VELOCITY_ACTUAL,
                          co.MODES_DISPLAY, co.ERROR_CODE, co.ERROR_REGISTER))


@dataclass
class _Axis:
    """State of one axis of the device."""

    objects: AxisObjects
    motor: Motor
    state: State = State.SWITCH_ON_DISABLED
    condition: int = 0
    controlword: int = 0
    #: (wall-clock time [s], motor position [rad], speed [rad/s]) after each
    #: step, newest last: what the motor did, for sampling at a past SYNC
    history: deque = field(default_factory=lambda: deque(maxlen=_HISTORY))


class _DeviceNetwork(canopen.Network):
    """canopen's Network on the device's own bus, with no receive thread (the
    device reads its bus in ``poll``) and no periodic sender: canopen's NMT
    slave would start a heartbeat thread when 0x1017 is written, but the
    device sends its heartbeat itself so that ``silent`` silences it."""

    def send_periodic(self, can_id, data, period, remote=False):
        return _NoTask()

    def send_message(self, can_id: int, data: bytes, remote: bool = False,
                     at: float | None = None) -> None:
        """canopen's send, stamped ``at`` [s, wall clock] (default: now): the
        device's bus preserves the sender's stamps (a SYNC answer carries
        the time a real drive would have sent it)."""
        msg = can.Message(is_extended_id=can_id > 0x7FF, arbitration_id=can_id, data=data,
                          is_remote_frame=remote, timestamp=time.time() if at is None else at)
        with self.send_lock:
            self.bus.send(msg)


class _NoTask:
    def stop(self) -> None:
        pass

    def update(self, data) -> None:
        pass


@dataclass
class _Guarding:
    """Node guarding / life guarding state (CiA 301 7.2.8.3.2.1)."""

    toggle: int = 0
    last_request: float | None = None


class EmulatedCia402Drive:
    """See the module docstring."""

    @classmethod
    def settings_for(cls, params, joint: str) -> dict:
        """The keyword arguments that make this drive the one the validated
        ``cia402`` parameters ``params`` describe for ``joint``: built from
        the joint's EDS, else the bus-wide one, else the generic drive, with
        the joint's encoder resolution (the node id is the caller's)."""
        base = f"cia402.joints.{joint}"
        return {"eds": params.get(f"{base}.eds") or params.get("cia402.eds") or None,
                "encoder_resolution": params[f"{base}.encoder_resolution"]}

    def __init__(self, node_id: int, channel: str, eds: str | ObjectDictionary | None = None,
                 *, encoder_resolution: int = 4096, velocity_resolution: float | None = None,
                 max_acceleration: float = 200.0, motor: Motor | Sequence[Motor] | None = None):
        if isinstance(eds, ObjectDictionary):
            od = eds
        elif eds is None:
            od = generic_dictionary(node_id)
        else:
            od = canopen.import_od(str(eds), node_id)
        self.node_id = node_id
        self.encoder_resolution = float(encoder_resolution)
        count = sum(1 for k in range(MAX_AXES) if co.CONTROLWORD + AXIS_OFFSET * k in od)
        if count == 0:
            raise ValueError("the dictionary has no controlword 0x6040: not a CiA 402 drive")
        if motor is None:
            motors = [IdealMotor(max_acceleration * TWO_PI) for _ in range(count)]
        elif isinstance(motor, Sequence):
            motors = list(motor)
        else:
            motors = [motor]
        if len(motors) != count:
            raise ValueError(f"{count} axes in the dictionary, {len(motors)} motors given")
        # the device stamps what it sends (preserve_timestamps): a real drive
        # answers a SYNC within a fraction of a millisecond, whenever this
        # emulator's thread gets to run on a busy test machine
        self.bus = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
        self.network = _DeviceNetwork(self.bus)
        self.node = canopen.LocalNode(node_id, od)
        self.network.add_node(self.node)
        self.axes = [_Axis(AxisObjects(od, k), m) for k, m in enumerate(motors)]
        self.velocity_resolution = [self._velocity_resolution(a.objects, velocity_resolution)
                                    for a in self.axes]
        #: no frame at all leaves the device (unplugged, dead CPU)
        self.silent = False
        #: no SDO answers (the SDO server hangs)
        self.sdo_silent = False
        #: TPDOs on every k-th SYNC only (the drive answers late)
        self.answer_every = 1
        self.nmt = co.NmtState.PRE_OPERATIONAL
        self._lock = threading.RLock()
        self._last_tick: float | None = None
        self._booted = False
        self._next_heartbeat = -math.inf
        self._master_heartbeat: float | None = None
        self._guarding = _Guarding()
        self._syncs = 0
        self._pending: dict[tuple[int, int], bytes] = {}
        #: (axis, index, sub) -> (variable, low, high) of the objects the drive reports
        self._own: dict[tuple[int, int, int], tuple] = {}
        #: a write changed what the drive does: recompute it before the next step
        self._dirty = True
        self._heartbeat_period = 0.0
        self._consumer: tuple[int, float] | None = None     # (master COB-ID, limit [s])
        self._life_time = 0.0
        #: valid RPDOs: COB-ID -> (transmission type, mapping); valid TPDOs:
        #: (COB-ID, transmission type, mapping)
        self._rpdos: dict[int, tuple[int, list[tuple[int, int, int]]]] = {}
        self._tpdos: list[tuple[int, int, list[tuple[int, int, int]]]] = []
        self.node.add_write_callback(self._on_write)
        self._reset_values()

    # -- public view -------------------------------------------------------------------
    def get(self, index: int, sub: int = 0):
        """The current value of object ``index:sub`` (device index, no axis offset)."""
        return self.node.object_dictionary.get_variable(index, sub).decode_raw(
            self.node.get_data(index, sub))

    def motor(self, axis: int = 0) -> Motor:
        return self.axes[axis].motor

    def state(self, axis: int = 0) -> State:
        return self.axes[axis].state

    @property
    def position_rev(self) -> float:
        """Axis 0's motor position [rev]."""
        return self.axes[0].motor.position() / TWO_PI

    @property
    def velocity_rev_per_s(self) -> float:
        """Axis 0's motor speed [rev/s]."""
        return self.axes[0].motor.velocity() / TWO_PI

    def inject_fault(self, error_code: int = 0x2310, axis: int = 0) -> None:
        """A fault condition on ``axis`` (default 0x2310: continuous over-current)."""
        with self._lock:
            self.axes[axis].condition = error_code
            self._fault(self.axes[axis], error_code)

    def clear_condition(self) -> None:
        """The fault conditions are gone; a fault reset from the master clears the fault."""
        with self._lock:
            for axis in self.axes:
                axis.condition = 0

    def close(self) -> None:
        self.bus.shutdown()

    # -- running -----------------------------------------------------------------------
    def poll(self, now: float) -> None:
        """Handle every frame waiting on the device's bus, each after the
        motors were advanced to the frame's send time (a drive sampling on
        SYNC samples when the SYNC was sent)."""
        with self._lock:
            while (msg := self.bus.recv(timeout=0.0)) is not None:
                at = min(msg.timestamp or now, now)
                self._advance(at)
                if not self.silent and not msg.is_extended_id:
                    self._handle(msg, at)

    def tick(self, now: float) -> None:
        """Advance the motors to ``now`` [s, wall clock] and send what is due."""
        with self._lock:
            self._advance(now)
            if not self.silent:
                self._cyclic(now)

    # -- objects -----------------------------------------------------------------------
    def _velocity_resolution(self, objects: AxisObjects, given: float | None) -> float:
        if given is not None:
            return float(given)
        unit = objects.default(co.SI_UNIT_VELOCITY)
        if unit is not None and unit in SI_VELOCITY_UNITS:
            per_rev_s = SI_VELOCITY_UNITS[unit][1]
            if per_rev_s is not None:
                return per_rev_s
        return self.encoder_resolution

    def _put(self, objects: AxisObjects, index: int, value, sub: int = 0) -> None:
        """Set an object that the drive itself reports (statusword, actual
        values, error code ...): stored directly, clipped to its type."""
        key = (objects.axis, index, sub)
        entry = self._own.get(key)
        if entry is None:
            var = objects.variable(index, sub)
            if var is None:
                return
            entry = self._own[key] = (var, *integer_range(var))
        var, low, high = entry
        self.node.data_store.setdefault(var.index, {})[var.subindex] = \
            var.encode_raw(min(max(int(value), low), high))

    def _value(self, objects: AxisObjects, index: int, default=0):
        if not objects.has(index):
            return default
        return objects.decode(index, 0, self.node.get_data(objects.index(index), 0))

    def _reset_values(self) -> None:
        """Power-on values: the file's defaults, and each axis SWITCH ON DISABLED."""
        self.node.data_store.clear()
        self._pending.clear()
        # objects the file gives no default have a value in a real drive all the same
        for var in _variables(self.node.object_dictionary):
            if var.default is None and var.value is None and var.data_type in NUMBER_TYPES:
                zero = 0.0 if var.data_type in FLOAT_TYPES else 0
                zero = max(zero, var.min) if var.min is not None else zero   # within its limits
                zero = min(zero, var.max) if var.max is not None else zero
                self.node.data_store.setdefault(var.index, {})[var.subindex] = \
                    var.encode_raw(zero)
        for axis in self.axes:
            axis.state, axis.controlword = State.SWITCH_ON_DISABLED, 0
            self._put(axis.objects, co.STATUSWORD, co.statusword_of(axis.state))
        self._master_heartbeat = None
        self._guarding = _Guarding()

    def _axis_of(self, index: int) -> _Axis | None:
        if 0x6000 <= index < 0x6000 + AXIS_OFFSET * len(self.axes):
            return self.axes[(index - 0x6000) // AXIS_OFFSET]
        return None

    def _on_write(self, index: int, subindex: int, od, data: bytes, **_) -> None:
        """canopen's SDO server (and our RPDOs) write through here: the drive
        reacts, or refuses with an SDO abort code."""
        axis = self._axis_of(index)
        base = index if axis is None else index - AXIS_OFFSET * axis.objects.axis
        if base in _OWN_OBJECTS:
            return              # what the drive itself reports changes nothing it does
        self._dirty = True
        if axis is not None:
            value = od.decode_raw(data)
            if base == co.CONTROLWORD:
                self._on_controlword(axis, value)
            elif base == co.MODES_OF_OPERATION:
                supported = axis.objects.default(co.SUPPORTED_MODES)
                if value <= 0 or supported is not None and not supported & mode_bit(value):
                    raise SdoAbortedError(ABORT_VALUE_RANGE)
                self._put(axis.objects, co.MODES_DISPLAY, value)
        elif co.RPDO_MAP <= index < co.RPDO_MAP + 0x200 or \
                co.TPDO_MAP <= index < co.TPDO_MAP + 0x200:
            self._check_mapping(index, subindex, od.decode_raw(data))

    def _check_mapping(self, index: int, sub: int, value: int) -> None:
        """A real drive refuses to map what its dictionary does not allow."""
        if sub == 0:
            entries = [self.get(index, s) for s in range(1, value + 1)]
            if sum(e & 0xFF for e in entries) > 64:
                raise SdoAbortedError(ABORT_PDO_TOO_LONG)
            return
        if value == 0:
            return
        target, target_sub, bits = value >> 16, (value >> 8) & 0xFF, value & 0xFF
        try:
            var = self.node.object_dictionary.get_variable(target, target_sub)
        except KeyError:
            var = None
        if var is None or not var.pdo_mappable or len(var) != bits:
            raise SdoAbortedError(ABORT_CANNOT_MAP)

    # -- protocol ----------------------------------------------------------------------
    def _handle(self, msg: can.Message, now: float) -> None:
        cob, data = msg.arbitration_id, bytes(msg.data)
        if msg.is_remote_frame:
            if cob == co.HEARTBEAT + self.node_id:
                self._on_guard_request(now)
            return
        if cob == co.NMT:
            if len(data) == 2 and data[1] in (0, self.node_id):
                self._on_nmt(data[0])
        elif cob == co.SYNC:
            self._on_sync(now)
        elif cob == co.SDO_RX + self.node_id:
            if self.nmt != co.NmtState.STOPPED and not self.sdo_silent:
                self.network.notify(cob, data, now)
        elif cob == self._master_cob():
            self._master_heartbeat = now
        elif self.nmt == co.NmtState.OPERATIONAL:
            if self._dirty:
                self._refresh()
            # a PDO is received on its identifier in its frame format only
            # (CiA 301 bit 29): an 11-bit RPDO ignores a 29-bit frame
            key = (cob, bool(msg.is_extended_id))
            if key in self._rpdos:
                self._on_rpdo(*self._rpdos[key], data)

    def _master_cob(self) -> int | None:
        return None if self._consumer is None else self._consumer[0]

    def _refresh(self) -> None:
        """Read back what writes changed: each axis's command, the heartbeat
        period, the watchdog limits (cached: the emulator steps every ms)."""
        self._dirty = False
        od = self.node.object_dictionary
        for axis, vres in zip(self.axes, self.velocity_resolution):
            self._command(axis, vres)
        self._heartbeat_period = (self.get(co.PRODUCER_HEARTBEAT_TIME) * 1e-3
                                  if co.PRODUCER_HEARTBEAT_TIME in od else 0.0)
        self._consumer = None
        if co.CONSUMER_HEARTBEAT_TIME in od:
            entry = self.get(co.CONSUMER_HEARTBEAT_TIME, 1)
            if entry & 0xFFFF:
                self._consumer = (co.HEARTBEAT + (entry >> 16 & 0x7F), (entry & 0xFFFF) * 1e-3)
        self._life_time = (self.get(co.GUARD_TIME) * self.get(co.LIFE_TIME_FACTOR) * 1e-3
                           if co.GUARD_TIME in od and co.LIFE_TIME_FACTOR in od else 0.0)
        self._rpdos, self._tpdos = {}, []
        for k in range(self.axes[0].objects.pdo_count(co.RPDO_COMM)):
            cob = self.get(co.RPDO_COMM + k, 1)
            if not cob & co.PDO_INVALID:
                self._rpdos[_identifier(cob)] = (self.get(co.RPDO_COMM + k, 2),
                                                 self._mapping(co.RPDO_MAP + k))
        for k in range(self.axes[0].objects.pdo_count(co.TPDO_COMM)):
            cob = self.get(co.TPDO_COMM + k, 1)
            if not cob & co.PDO_INVALID:
                self._tpdos.append((_identifier(cob)[0], self.get(co.TPDO_COMM + k, 2),
                                    self._mapping(co.TPDO_MAP + k)))

    def _on_nmt(self, command: int) -> None:
        if command == co.NmtCommand.START:
            self.nmt = co.NmtState.OPERATIONAL
        elif command == co.NmtCommand.STOP:
            self.nmt = co.NmtState.STOPPED
        elif command == co.NmtCommand.ENTER_PRE_OPERATIONAL:
            self.nmt = co.NmtState.PRE_OPERATIONAL
        elif command in (co.NmtCommand.RESET_NODE, co.NmtCommand.RESET_COMMUNICATION):
            self._reset_values()
            self.nmt = co.NmtState.PRE_OPERATIONAL
            self._booted = False
        if self.nmt != co.NmtState.OPERATIONAL:
            for axis in self.axes:
                if axis.state is State.OPERATION_ENABLED:
                    # losing the PDO link while enabled is a communication fault
                    self._fault(axis, 0x8100)

    def _on_guard_request(self, now: float) -> None:
        """Node guarding: answer the master's remote frame with the NMT state
        and the toggle bit; the request also feeds life guarding."""
        g = self._guarding
        self.network.send_message(co.HEARTBEAT + self.node_id, bytes([self.nmt | g.toggle]))
        g.toggle ^= 0x80
        g.last_request = now

    def _mapping(self, map_index: int) -> list[tuple[int, int, int]]:
        entries = [self.get(map_index, s) for s in range(1, self.get(map_index, 0) + 1)]
        return [(e >> 16, (e >> 8) & 0xFF, e & 0xFF) for e in entries]

    def _on_rpdo(self, kind: int, entries, data: bytes) -> None:
        offset, values = 0, {}
        for index, sub, bits in entries:
            n = bits // 8
            if offset + n > len(data):
                return          # a PDO shorter than its mapping is ignored
            values[(index, sub)] = data[offset:offset + n]
            offset += n
        if kind <= 240:
            self._pending.update(values)                    # applied at the next SYNC
        else:
            self._apply(values)

    def _apply(self, values: dict[tuple[int, int], bytes]) -> None:
        for (index, sub), raw in values.items():
            try:
                self.node.set_data(index, sub, raw)
            except SdoAbortedError:
                pass            # e.g. a mode the drive does not have: ignored

    #: [s] from a SYNC to the drive's answer on the bus
    ANSWER_DELAY = 1e-4

    def _on_sync(self, at: float) -> None:
        """The SYNC sent at ``at`` [s, wall clock]: apply the RPDOs, sample, answer."""
        pending, self._pending = self._pending, {}
        self._apply(pending)
        if self.nmt != co.NmtState.OPERATIONAL:
            return
        self._syncs += 1
        if self._syncs % self.answer_every:
            return
        self._update_feedback(at)
        if self._dirty:
            self._refresh()
        for cob, kind, entries in self._tpdos:
            if not 1 <= kind <= 240 or self._syncs % kind:
                continue
            payload = b"".join(self.node.get_data(i, s) for i, s, _ in entries)
            # stamped as a real drive's answer leaves the bus, not when this
            # thread got to run
            self.network.send_message(cob, payload, at=at + self.ANSWER_DELAY)

    def _on_controlword(self, axis: _Axis, word: int) -> None:
        previous, axis.controlword = axis.controlword, word
        if axis.state is State.FAULT:
            if word & 0x80 and not previous & 0x80 and not axis.condition:
                axis.state = State.SWITCH_ON_DISABLED
                self._put(axis.objects, co.ERROR_CODE, 0)
                if not any(a.state is State.FAULT for a in self.axes):
                    self.node.set_data(co.ERROR_REGISTER, 0, b"\x00")
        else:
            axis.state = co.next_state(axis.state, word, previous)
        self._put(axis.objects, co.STATUSWORD, co.statusword_of(axis.state))

    def _fault(self, axis: _Axis, error_code: int) -> None:
        axis.state = State.FAULT
        self._dirty = True
        self._put(axis.objects, co.STATUSWORD, co.statusword_of(axis.state))
        self._put(axis.objects, co.ERROR_CODE, error_code)
        self.node.set_data(co.ERROR_REGISTER, 0, b"\x01")
        if not self.silent:
            self.network.send_message(co.EMCY + self.node_id, co.emcy(error_code))

    def _update_feedback(self, at: float) -> None:
        for axis, vres in zip(self.axes, self.velocity_resolution):
            o = axis.objects
            position, velocity = self._motor_at(axis, at)
            self._put(o, co.STATUSWORD, co.statusword_of(axis.state))
            self._put(o, co.POSITION_ACTUAL, _int32(round(
                position / TWO_PI * self.encoder_resolution)))
            self._put(o, co.VELOCITY_ACTUAL, round(velocity / TWO_PI * vres))

    def _motor_at(self, axis: _Axis, at: float) -> tuple[float, float]:
        """The motor's (position [rad], speed [rad/s]) at ``at`` [s, wall clock].

        A real drive samples the instant the SYNC reaches it. Here the SYNC
        can reach the device after its motors were stepped past the SYNC's
        stamp: python-can's virtual bus stamps a frame, then copies it into
        each receiver's queue in turn, and the sending thread can lose the
        CPU in between (six drives on one bus: seven copies). Sampling the
        motor as it is then would report a position up to that delay late
        under an early stamp -- a jump the driver's glitch check rightly
        flags. So a SYNC in the past is sampled from the motor's recorded
        steps (linear between the two around it)."""
        history = axis.history
        if not history or at >= history[-1][0]:
            return axis.motor.position(), axis.motor.velocity()
        k = bisect.bisect_right(history, at, key=lambda h: h[0])
        if k == 0:
            return history[0][1], history[0][2]      # older than the record: its oldest
        (t0, p0, v0), (t1, p1, v1) = history[k - 1], history[k]
        w = (at - t0) / (t1 - t0)
        return p0 + w * (p1 - p0), v0 + w * (v1 - v0)

    # -- time --------------------------------------------------------------------------
    def _advance(self, now: float) -> None:
        if self._last_tick is not None and now <= self._last_tick:
            return
        dt = 0.0 if self._last_tick is None else now - self._last_tick
        self._last_tick = now
        if self._dirty:
            self._refresh()
        self._watchdogs(now)
        for axis in self.axes:
            axis.motor.advance(dt)
            axis.history.append((now, axis.motor.position(), axis.motor.velocity()))
            if axis.state is State.QUICK_STOP_ACTIVE and axis.motor.velocity() == 0.0:
                axis.state = State.SWITCH_ON_DISABLED      # quick stop option code 2
                self._put(axis.objects, co.STATUSWORD, co.statusword_of(axis.state))

    def _command(self, axis: _Axis, vres: float) -> None:
        """What the axis's power stage does now: off / ramping down unless
        OPERATION ENABLED, else the target of its mode of operation."""
        o = axis.objects
        if axis.state is not State.OPERATION_ENABLED:
            axis.motor.command_velocity(0.0)
        elif self._value(o, co.MODES_OF_OPERATION) == OpMode.CYCLIC_SYNCHRONOUS_TORQUE:
            rated = self._value(o, co.MOTOR_RATED_TORQUE) * 1e-3          # mN m -> N m
            axis.motor.command_torque(self._value(o, co.TARGET_TORQUE) * 1e-3 * rated)
        else:
            axis.motor.command_velocity(self._value(o, co.TARGET_VELOCITY) / vres * TWO_PI)

    def _watchdogs(self, now: float) -> None:
        """Heartbeat consumer (0x1016) and life guarding (0x100C x 0x100D):
        the master went quiet -> each axis does what its abort connection
        option code 0x6007 says (CiA 402): 0 nothing, 1 fault (0x8130, life
        guard error), 2 disable voltage (the motor coasts), 3 quick stop (the
        motor brakes to rest, QUICK STOP ACTIVE); without 0x6007 this drive
        faults (the maker's choice)."""
        expired = (self._consumer is not None and self._master_heartbeat is not None
                   and now - self._master_heartbeat > self._consumer[1])
        last_guard = self._guarding.last_request
        if self._life_time > 0 and last_guard is not None and now - last_guard > self._life_time:
            expired = True
        if expired:
            # CiA 301: after the event, the monitoring waits for the next
            # heartbeat (guarding request) before it can expire again
            self._master_heartbeat = None
            self._guarding.last_request = None
            for axis in self.axes:
                self._lost_connection(axis)

    def _lost_connection(self, axis: _Axis) -> None:
        option = (self._value(axis.objects, co.ABORT_CONNECTION_OPTION)
                  if axis.objects.has(co.ABORT_CONNECTION_OPTION) else co.AbortConnection.FAULT)
        if option == co.AbortConnection.NO_ACTION or axis.state is State.FAULT:
            return
        # (this emulator's motor ramps to rest in every state but OPERATION
        # ENABLED: _command, at the next step)
        if option == co.AbortConnection.DISABLE_VOLTAGE:
            axis.state = State.SWITCH_ON_DISABLED
        elif option == co.AbortConnection.QUICK_STOP:
            if axis.state is State.OPERATION_ENABLED:
                axis.state = State.QUICK_STOP_ACTIVE
        else:
            self._fault(axis, 0x8130)
            return
        self._dirty = True
        self._put(axis.objects, co.STATUSWORD, co.statusword_of(axis.state))

    def _cyclic(self, now: float) -> None:
        if not self._booted:
            self._booted = True
            self.network.send_message(co.HEARTBEAT + self.node_id, bytes([co.NmtState.BOOT_UP]))
        if self._heartbeat_period > 0 and now >= self._next_heartbeat:
            self._next_heartbeat = now + self._heartbeat_period
            self.network.send_message(co.HEARTBEAT + self.node_id, bytes([self.nmt]))


def _variables(od: ObjectDictionary):
    for obj in od.values():
        if isinstance(obj, ODVariable):
            yield obj
        else:
            yield from obj.values()


def _identifier(cob: int) -> tuple[int, bool]:
    """(CAN identifier, 29-bit) of a PDO COB-ID entry (CiA 301: bit 29 picks
    the frame format; bits 30 and 31 are flags, not part of the identifier)."""
    if cob & co.PDO_EXTENDED:
        return cob & 0x1FFFFFFF, True
    return cob & co.PDO_ID_11, False


def _int32(value: int) -> int:
    return (value + 2 ** 31) % 2 ** 32 - 2 ** 31
