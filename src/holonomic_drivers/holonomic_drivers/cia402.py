"""The ``cia402`` backend: CANopen drives with the CiA 402 profile.

Built on the ``canopen`` package (its Network, SDO client and NMT master);
one drive per joint, addressed by node id. What the driver sets up in
``configure`` (all over SDO, each step checked):

* NMT pre-operational; device type 0x1000 must name profile 402;
* the drive's heartbeat producer 0x1017 and, with ``cia402.drive_watchdog``
  > 0, its heartbeat consumer 0x1016 on *this* master's heartbeat -- which
  the control loop itself sends, so a dead or hung controller faults the
  drives and they stop on their own;
* mode of operation 0x6060: cyclic synchronous velocity (9) or profile
  velocity (3), checked in 0x6061;
* the PDOs (transmission type 1, i.e. every SYNC):
  RPDO1 = controlword 0x6040 + target velocity 0x60FF,
  RPDO2 = controlword + target torque 0x6071 + mode of operation 0x6060
  (torque mode: the mode switches at the SYNC that applies the torque),
  TPDO1 = position actual 0x6064 + velocity actual 0x606C,
  TPDO2 = statusword 0x6041 + error code 0x603F; other PDOs disabled;
* supported modes 0x6502 and motor rated torque 0x6076 (torque mode needs
  cyclic synchronous torque and a rated torque to scale 0x6071);
* NMT operational, then wait for the first PDOs and heartbeats.

Every cycle ``read`` takes what the drives sent after the previous SYNC,
checks heartbeats, PDO age (late answers), NMT state and the 402 state,
and sends SYNC (and the master heartbeat when due) in every case; ``write_velocities``
sends RPDO1, which the drives apply at the next SYNC (one cycle of latency,
as in any CSV set-up). ``activate`` walks the 402 state machine over SDO
(fault reset if the fault is gone, shutdown, switch on, enable operation);
``deactivate`` sends "disable operation" with a zero target followed by a
SYNC at once: the drives ramp to standstill and switch their power stage off
(their 0x605C option code decides how).

Drives whose TPDOs are fixed, or that need an EDS for vendor objects, are
not covered: see README "CiA 402 drives".
"""

from __future__ import annotations

import math
import struct
import threading
import time
from collections import deque
from dataclasses import dataclass
from typing import Callable

import can
import canopen
import numpy as np

from holonomic_core.driver import (DriverCommunicationError, DriverError, DriverFault,
                                   JointReading)
from holonomic_core.schema import ConfigError, ParamSpec
from holonomic_drivers import cia402_protocol as co
from holonomic_drivers.can_link import CanDriver, bus_specs, joint_map_specs, open_bus
from holonomic_drivers.cia402_protocol import Control, State

PREFIX = "cia402"
_MODES = {"csv": co.OpMode.CYCLIC_SYNCHRONOUS_VELOCITY, "pv": co.OpMode.PROFILE_VELOCITY}
_INT32 = 2 ** 31 - 1

#: the PDO layout the driver writes: (comm index, map index, [(object, sub, bits)])
RPDO1_LAYOUT = [(co.CONTROLWORD, 0, 16), (co.TARGET_VELOCITY, 0, 32)]
# torque mode: the mode of operation travels with the setpoint, so that the
# switch to cyclic synchronous torque happens at the SYNC that applies it
RPDO2_LAYOUT = [(co.CONTROLWORD, 0, 16), (co.TARGET_TORQUE, 0, 16),
                (co.MODES_OF_OPERATION, 0, 8)]
TPDO1_LAYOUT = [(co.POSITION_ACTUAL, 0, 32), (co.VELOCITY_ACTUAL, 0, 32)]
TPDO2_LAYOUT = [(co.STATUSWORD, 0, 16), (co.ERROR_CODE, 0, 16)]


def pdo_configuration(node_id: int) -> list[tuple[int, int, bytes]]:
    """The SDO downloads ``(index, subindex, data)`` that set up the PDOs.

    Per CiA 301: invalidate the PDO (COB-ID bit 31), set the transmission
    type, zero the mapping count, write the entries, set the count, then
    validate the COB-ID. RPDOs 3..4 and TPDOs 3..4 are invalidated.
    """
    u8, u32 = (lambda v: struct.pack("<B", v)), (lambda v: struct.pack("<I", v))
    writes = []
    for comm, mapping, cob, layout in (
            (co.RPDO_COMM, co.RPDO_MAP, co.RPDO[0] + node_id, RPDO1_LAYOUT),
            (co.RPDO_COMM + 1, co.RPDO_MAP + 1, co.RPDO[1] + node_id, RPDO2_LAYOUT),
            (co.TPDO_COMM, co.TPDO_MAP, co.TPDO[0] + node_id, TPDO1_LAYOUT),
            (co.TPDO_COMM + 1, co.TPDO_MAP + 1, co.TPDO[1] + node_id, TPDO2_LAYOUT)):
        writes += [(comm, 1, u32(cob | co.PDO_INVALID)), (comm, 2, u8(1)), (mapping, 0, u8(0))]
        writes += [(mapping, k + 1, u32(co.pdo_map_entry(*entry)))
                   for k, entry in enumerate(layout)]
        writes += [(mapping, 0, u8(len(layout))), (comm, 1, u32(cob))]
    for k in (2, 3):
        writes.append((co.RPDO_COMM + k, 1, u32(co.RPDO[k] + node_id | co.PDO_INVALID)))
    for k in (2, 3):
        writes.append((co.TPDO_COMM + k, 1, u32(co.TPDO[k] + node_id | co.PDO_INVALID)))
    return writes


@dataclass
class _Drive:
    """What the driver last heard from one drive (times on the driver clock)."""

    nmt_state: int | None = None
    heartbeat_time: float = -math.inf
    position: int = 0
    velocity: int = 0
    feedback_time: float = -math.inf
    sample_time: float = -math.inf
    statusword: int = 0
    error_code: int = 0
    status_time: float = -math.inf
    emcy_code: int = 0


class Cia402Driver(CanDriver):
    name = "cia402"
    device_kind = "CANopen"
    # Torque mode: cyclic synchronous torque (0x6060 = 10) through RPDO2 on
    # drives that list it in 0x6502, scaled by their rated torque 0x6076.
    supports_effort = True

    def __init__(self, model, params, control_rate: float):
        super().__init__(model, params, control_rate)
        p = lambda key: params[f"{PREFIX}.{key}"]  # noqa: E731
        self._master_id = int(p("master_node_id"))
        if self._master_id in self.joints.node_ids:
            raise ConfigError(f"{PREFIX}.master_node_id", self._master_id,
                              "a node id that no drive uses")
        self._mode = _MODES[p("mode")]
        self._heartbeat_period = float(p("heartbeat_period"))
        self._heartbeat_timeout = float(p("heartbeat_timeout"))
        self._feedback_timeout = float(p("feedback_timeout"))
        self._startup_timeout = float(p("startup_timeout"))
        self._watchdog = float(p("drive_watchdog"))
        self._sdo_timeout = float(p("sdo_timeout"))
        counts, vel_units = [], []
        for joint in model.joint_names:
            res = float(params[f"{PREFIX}.joints.{joint}.encoder_resolution"])
            vres = float(params[f"{PREFIX}.joints.{joint}.velocity_resolution"])
            counts.append(res)
            vel_units.append(vres if vres > 0 else res)
        self._counts_per_rev = np.array(counts)
        self._vel_units_per_rev_s = np.array(vel_units)
        self._drives = [_Drive() for _ in self.devices]
        #: rated motor torque [N m] per drive (0: no cyclic synchronous torque)
        self._rated_torque = [0.0] * len(self.devices)
        #: drives last switched to torque mode
        self._in_torque = [False] * len(self.devices)
        self._cob = {}
        for i, node in enumerate(self.joints.node_ids):
            self._cob[co.TPDO[0] + node] = (i, self._on_tpdo1)
            self._cob[co.TPDO[1] + node] = (i, self._on_tpdo2)
            self._cob[co.HEARTBEAT + node] = (i, self._on_heartbeat)
            self._cob[co.EMCY + node] = (i, self._on_emcy)
        self._lock = threading.Lock()
        self._network = None
        self._nodes = []
        self._next_master_heartbeat = -math.inf
        self._sync_time = -math.inf
        #: (wall clock, driver clock) [s] of the last SYNCs sent, newest last
        self._syncs: deque[tuple[float, float]] = deque(maxlen=16)
        self.counters = {"bad_frames": 0, "emcy": 0, "syncs": 0, "frames_sent": 0}

    @classmethod
    def param_specs(cls, model) -> list[ParamSpec]:
        extra = (
            ParamSpec(f"{PREFIX}.joints.{{joint}}.encoder_resolution", "double",
                      "Position units (0x6064) per motor revolution of {joint}'s drive "
                      "[counts/rev].", minimum=0.0, exclusive_minimum=True, maximum=1e12),
            ParamSpec(f"{PREFIX}.joints.{{joint}}.velocity_resolution", "double",
                      "Velocity units (0x606C, 0x60FF) per motor rev/s of {joint}'s drive; "
                      "0: counts/s, i.e. encoder_resolution (60 for a drive in rpm).",
                      default=0.0, minimum=0.0, maximum=1e12),
        )
        return bus_specs(PREFIX) + [
            ParamSpec(f"{PREFIX}.mode", "string",
                      "Mode of operation: csv (cyclic synchronous velocity, 0x6060 = 9) or "
                      "pv (profile velocity, 3).", default="csv", choices=tuple(_MODES)),
            ParamSpec(f"{PREFIX}.master_node_id", "int",
                      "Node id of this controller's heartbeat (0x700 + id); no drive may "
                      "use it.", default=127, minimum=1, maximum=127),
            ParamSpec(f"{PREFIX}.heartbeat_period", "double",
                      "Heartbeat period set in each drive (0x1017) and of the master [s].",
                      default=0.05, minimum=0.001, maximum=60.0),
            ParamSpec(f"{PREFIX}.heartbeat_timeout", "double",
                      "A drive whose heartbeat is older than this is lost: fault and stop [s].",
                      default=0.2, minimum=0.002, maximum=60.0),
            ParamSpec(f"{PREFIX}.feedback_timeout", "double",
                      "PDOs older than this are late (the drive stopped answering SYNC): "
                      "fault and stop [s].", default=0.05, minimum=0.002, maximum=10.0),
            ParamSpec(f"{PREFIX}.drive_watchdog", "double",
                      "Heartbeat consumer time set in each drive (0x1016) on this master's "
                      "heartbeat: the drives fault by themselves when the controller stops "
                      "[s]; 0 leaves 0x1016 alone.", default=0.25, minimum=0.0, maximum=60.0),
            ParamSpec(f"{PREFIX}.startup_timeout", "double",
                      "How long configure waits for the first PDOs and arming for each "
                      "state transition [s].", default=2.0, minimum=0.05, maximum=60.0),
            ParamSpec(f"{PREFIX}.sdo_timeout", "double",
                      "Time a drive has to answer one SDO request [s].",
                      default=0.3, minimum=0.01, maximum=10.0),
        ] + joint_map_specs(PREFIX, model.joint_names, (1, 127), extra)

    # -- lifecycle hooks -------------------------------------------------------------
    def _on_configure(self) -> None:
        network = canopen.Network()
        network.bus = open_bus(PREFIX, self.params)
        network.listeners.append(_FrameListener(self))
        network.connect()
        self._network = network
        try:
            self._nodes = []
            for node_id in self.joints.node_ids:
                node = canopen.RemoteNode(node_id, canopen.ObjectDictionary())
                network.add_node(node)
                node.sdo.RESPONSE_TIMEOUT = self._sdo_timeout
                self._nodes.append(node)
            for i, node in enumerate(self._nodes):
                self._configure_drive(i, node)
            for node in self._nodes:
                node.nmt.send_command(co.NmtCommand.START)
            self._wait("first PDOs and heartbeats",
                       lambda: self._first_not_ready(enabled=False))
        except (canopen.SdoCommunicationError, canopen.SdoAbortedError, can.CanError) as exc:
            self._disconnect()
            raise DriverCommunicationError(str(exc), PREFIX) from exc
        except BaseException:
            self._disconnect()
            raise

    def _configure_drive(self, i: int, node) -> None:
        device = self.devices[i]
        node.nmt.send_command(co.NmtCommand.ENTER_PRE_OPERATIONAL)
        try:
            (device_type,) = struct.unpack("<I", node.sdo.upload(co.DEVICE_TYPE, 0)[:4])
        except canopen.SdoCommunicationError as exc:
            raise DriverCommunicationError(
                f"no answer to SDO ({exc}): is it powered, on this bus, with this node id "
                "and bit rate?", device) from exc
        if device_type & 0xFFFF != co.PROFILE_402:
            raise DriverFault(f"device type 0x{device_type:08X} is not a CiA 402 drive", device)
        writes = [(co.PRODUCER_HEARTBEAT_TIME, 0,
                   struct.pack("<H", max(1, round(self._heartbeat_period * 1e3))))]
        if self._watchdog > 0:
            writes.append((co.CONSUMER_HEARTBEAT_TIME, 1, struct.pack(
                "<I", (self._master_id << 16) | max(1, round(self._watchdog * 1e3)))))
        writes.append((co.MODES_OF_OPERATION, 0, struct.pack("<b", int(self._mode))))
        writes.append((co.TARGET_VELOCITY, 0, struct.pack("<i", 0)))
        writes += pdo_configuration(node.id)
        for index, sub, data in writes:
            try:
                node.sdo.download(index, sub, data)
            except canopen.SdoAbortedError as exc:
                raise DriverFault(f"refused 0x{index:04X}:{sub} = {data.hex()} ({exc})",
                                  device) from exc
        (mode,) = struct.unpack("<b", node.sdo.upload(co.MODES_DISPLAY, 0)[:1])
        if mode != int(self._mode):
            raise DriverFault(f"did not take mode {self._mode.name} (0x6061 reads {mode})",
                              device)
        # torque mode needs CST in 0x6502 and a rated torque to scale 0x6071
        (supported,) = struct.unpack("<I", node.sdo.upload(co.SUPPORTED_MODES, 0)[:4])
        try:
            (rated,) = struct.unpack("<I", node.sdo.upload(co.MOTOR_RATED_TORQUE, 0)[:4])
        except canopen.SdoAbortedError:
            rated = 0                       # no 0x6076: no torque mode
        cst = supported & (1 << (co.OpMode.CYCLIC_SYNCHRONOUS_TORQUE - 1))
        self._rated_torque[i] = rated * 1e-3 if cst else 0.0

    def _on_activate(self) -> None:
        try:
            for i, node in enumerate(self._nodes):
                self._enable_drive(i, node)
                # keep SYNC and the master heartbeat going (drive watchdogs)
                self._cycle_frames(time.monotonic())
            # the first read after arming must find fresh PDOs from enabled drives
            enabled = time.monotonic()
            self._wait("PDOs from the enabled drives", lambda: self._first_not_ready(enabled))
        except (canopen.SdoCommunicationError, canopen.SdoAbortedError, can.CanError) as exc:
            self._stop_all()
            raise DriverCommunicationError(str(exc), PREFIX) from exc
        except DriverError:
            self._stop_all()
            raise

    def _enable_drive(self, i: int, node) -> None:
        device = self.devices[i]
        state = self._sdo_state(node)
        if state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            # fault reset acts on the rising edge of bit 7
            self._controlword(node, Control.DISABLE_VOLTAGE)
            self._controlword(node, Control.FAULT_RESET)
            state = self._sdo_state(node)
            if state is State.FAULT:
                (code,) = struct.unpack("<H", node.sdo.upload(co.ERROR_CODE, 0)[:2])
                raise DriverFault(f"fault persists after fault reset (error code 0x{code:04X})",
                                  device)
        node.sdo.download(co.TARGET_VELOCITY, 0, struct.pack("<i", 0))
        if self._in_torque[i]:
            # every arming starts in the configured velocity mode, target 0
            node.sdo.download(co.TARGET_TORQUE, 0, struct.pack("<h", 0))
            node.sdo.download(co.MODES_OF_OPERATION, 0, struct.pack("<b", int(self._mode)))
            self._in_torque[i] = False
        for command, expected in ((Control.SHUTDOWN, State.READY_TO_SWITCH_ON),
                                  (Control.SWITCH_ON, State.SWITCHED_ON),
                                  (Control.ENABLE_OPERATION, State.OPERATION_ENABLED)):
            self._controlword(node, command)
            deadline = time.monotonic() + self._startup_timeout
            while (state := self._sdo_state(node)) is not expected:
                if time.monotonic() > deadline:
                    raise DriverFault(f"did not reach {expected.value} after controlword "
                                      f"0x{int(command):04X} (state {state.value})", device)
                time.sleep(0.002)

    def _on_deactivate(self) -> None:
        self._stop_all()

    def _on_close(self) -> None:
        if self._network is not None:
            for node in self._nodes:
                try:
                    node.nmt.send_command(co.NmtCommand.ENTER_PRE_OPERATIONAL)
                except Exception:  # noqa: BLE001 (bus already gone: nothing to tell)
                    pass
        self._disconnect()

    # -- cycle --------------------------------------------------------------------------------
    def _on_read(self) -> JointReading:
        now = time.monotonic()
        with self._lock:
            drives = [_Drive(**vars(d)) for d in self._drives]
        try:
            return self._reading(now, drives)
        finally:
            # SYNC and the master heartbeat go out whatever this cycle found:
            # the healthy drives keep answering, and a drive that recovers is
            # seen to recover
            self._cycle_frames(now)

    def _reading(self, now: float, drives: list[_Drive]) -> JointReading:
        positions = np.empty(len(drives))
        velocities = np.empty(len(drives))
        armed = self.armed
        for i, d in enumerate(drives):
            device = self.devices[i]
            age = now - d.heartbeat_time
            if age > self._heartbeat_timeout:
                raise DriverCommunicationError(f"no heartbeat for {age * 1e3:.0f} ms (limit "
                                               f"{self._heartbeat_timeout * 1e3:.0f} ms)", device)
            if d.nmt_state != co.NmtState.OPERATIONAL:
                raise DriverCommunicationError(
                    f"left NMT OPERATIONAL (heartbeat says {_nmt_name(d.nmt_state)})", device)
            age = now - min(d.feedback_time, d.status_time)
            if age > self._feedback_timeout:
                raise DriverCommunicationError(
                    f"PDOs late: last one {age * 1e3:.0f} ms ago (limit "
                    f"{self._feedback_timeout * 1e3:.0f} ms)", device)
            state = co.state_of(d.statusword)
            if armed and state is not State.OPERATION_ENABLED:
                detail = (f", error code 0x{d.error_code or d.emcy_code:04X}"
                          if state in (State.FAULT, State.FAULT_REACTION_ACTIVE) else "")
                raise DriverFault(f"left OPERATION ENABLED (now {state.value}{detail})", device)
            positions[i] = d.position
            velocities[i] = d.velocity
        # stamped with the SYNC at which the drives sampled; a cycle whose
        # PDOs have not arrived yet repeats the stamp (the odometry then
        # waits for them instead of seeing a standstill)
        return JointReading(max(d.sample_time for d in drives),
                            self.joints.to_joint_positions(positions / self._counts_per_rev),
                            self.joints.to_joint_velocities(velocities / self._vel_units_per_rev_s),
                            self._no_efforts)

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        motor = self.joints.to_motor_velocities(np.asarray(velocities, float))
        units = np.clip(np.rint(motor * self._vel_units_per_rev_s), -_INT32, _INT32)
        for i, (node, value) in enumerate(zip(self.joints.node_ids, units)):
            if self._in_torque[i]:
                # back to the velocity mode: one SDO (RPDO1 does not carry it)
                try:
                    self._nodes[i].sdo.download(co.MODES_OF_OPERATION, 0,
                                                struct.pack("<b", int(self._mode)))
                except (canopen.SdoCommunicationError, canopen.SdoAbortedError) as exc:
                    raise DriverCommunicationError(f"mode switch failed: {exc}",
                                                   self.devices[i]) from exc
                self._in_torque[i] = False
            self._send(co.RPDO[0] + node,
                       struct.pack("<Hi", Control.ENABLE_OPERATION, int(value)))

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        """Joint torques [N m] -> motor torques (gear, direction) -> 0x6071 in
        per mille of each drive's rated torque, with 0x6060 = cyclic
        synchronous torque, in RPDO2."""
        motor = self.joints.to_motor_torques(np.asarray(efforts, float))
        for i, (node, value) in enumerate(zip(self.joints.node_ids, motor)):
            rated = self._rated_torque[i]
            if rated <= 0.0:
                raise DriverFault("has no cyclic synchronous torque mode (0x6502) or no "
                                  "rated torque (0x6076)", self.devices[i])
            units = int(np.clip(round(1000.0 * value / rated), -32767, 32767))
            self._send(co.RPDO[1] + node, struct.pack(
                "<Hhb", Control.ENABLE_OPERATION, units, co.OpMode.CYCLIC_SYNCHRONOUS_TORQUE))
            self._in_torque[i] = True

    def status(self) -> dict[str, str]:
        out = super().status()
        now = time.monotonic()
        with self._lock:
            for i, d in enumerate(self._drives):
                out[self.joints.joint_names[i]] = (
                    f"node {self.joints.node_ids[i]}: NMT {_nmt_name(d.nmt_state)}, "
                    f"{co.state_of(d.statusword).value}, error code 0x{d.error_code:04X}, "
                    f"heartbeat {(now - d.heartbeat_time) * 1e3:.0f} ms ago")
        return out

    # -- bus ---------------------------------------------------------------------------------
    def _cycle_frames(self, now: float) -> None:
        """SYNC every cycle (the drives sample and answer), master heartbeat when due."""
        if now >= self._next_master_heartbeat:
            self._next_master_heartbeat = now + self._heartbeat_period
            self._send(co.HEARTBEAT + self._master_id, bytes([co.NmtState.OPERATIONAL]))
        # both clocks as the SYNC leaves (the drives sample then)
        sent = time.monotonic()
        self._sync_time = sent
        with self._lock:
            self._syncs.append((time.time(), sent))
        self._send(co.SYNC, b"")
        self.counters["syncs"] += 1

    def _send(self, cob_id: int, data: bytes) -> None:
        try:
            self._network.send_message(cob_id, data)
        except (can.CanError, RuntimeError) as exc:
            raise DriverCommunicationError(f"send of 0x{cob_id:03X} failed: {exc}",
                                           PREFIX) from exc
        self.counters["frames_sent"] += 1

    def _stop_all(self) -> None:
        """Disable operation with zero targets on every drive, then SYNC now."""
        failure = None
        for i, node in enumerate(self.joints.node_ids):
            try:
                if self._in_torque[i]:
                    self._send(co.RPDO[1] + node, struct.pack(
                        "<Hhb", Control.SWITCH_ON, 0, co.OpMode.CYCLIC_SYNCHRONOUS_TORQUE))
                self._send(co.RPDO[0] + node, struct.pack("<Hi", Control.SWITCH_ON, 0))
            except DriverCommunicationError as exc:
                failure = failure or exc
        try:
            self._send(co.SYNC, b"")
        except DriverCommunicationError as exc:
            failure = failure or exc
        if failure is not None:
            raise failure

    def _controlword(self, node, command: int) -> None:
        node.sdo.download(co.CONTROLWORD, 0, struct.pack("<H", int(command)))

    def _sdo_state(self, node) -> State:
        (word,) = struct.unpack("<H", node.sdo.upload(co.STATUSWORD, 0)[:2])
        return co.state_of(word)

    def _wait(self, what: str, ready: Callable[[], int | None]) -> None:
        """Send SYNC + heartbeat each 5 ms until ``ready()`` is None (it returns
        the index of a drive not ready yet) or the startup timeout."""
        deadline = time.monotonic() + self._startup_timeout
        while (i := ready()) is not None:
            if time.monotonic() > deadline:
                raise DriverCommunicationError(
                    f"no {what} within {self._startup_timeout:g} s",
                    self.devices[i])
            self._cycle_frames(time.monotonic())
            time.sleep(0.005)

    def _first_not_ready(self, since: float = -math.inf, enabled: bool = True) -> int | None:
        """Index of the first drive not yet operational with PDOs newer than
        ``since`` (and, if ``enabled``, in OPERATION ENABLED); None if all are."""
        with self._lock:
            for i, d in enumerate(self._drives):
                if (d.nmt_state != co.NmtState.OPERATIONAL or d.feedback_time <= since
                        or d.status_time <= since or (enabled and co.state_of(d.statusword)
                                                      is not State.OPERATION_ENABLED)):
                    return i
        return None

    def _disconnect(self) -> None:
        if self._network is not None:
            self._network.disconnect()
            self._network = None

    # -- receive (canopen's notifier thread) ---------------------------------------------------
    def on_frame(self, cob_id: int, data: bytes, timestamp: float | None = None) -> None:
        """A frame from the bus; ``timestamp`` [s, wall clock]: when it arrived
        (python-can's, from the kernel on socketcan), if known."""
        entry = self._cob.get(cob_id)
        if entry is None:
            return
        i, handler = entry
        try:
            with self._lock:
                if handler == self._on_tpdo1:
                    self._on_tpdo1(self._drives[i], bytes(data), time.monotonic(),
                                   self._answered_sync(timestamp))
                else:
                    handler(self._drives[i], bytes(data), time.monotonic())
        except (struct.error, ValueError):
            self.counters["bad_frames"] += 1

    def _answered_sync(self, arrived: float | None) -> float:
        """Driver-clock time of the SYNC a TPDO that arrived at ``arrived``
        [s, wall clock] answers: the last one sent before it arrived. (The
        last SYNC sent *now* is wrong for an answer handled late -- this
        thread starved, frames queued: that sample would be stamped a cycle
        or a stall late, and the next one would seem to move that far in no
        time.) Without an arrival time: the last SYNC sent."""
        if arrived:
            for wall, clock in reversed(self._syncs):
                if wall <= arrived:
                    return clock
        return self._sync_time

    def _on_tpdo1(self, d: _Drive, data: bytes, now: float, sampled: float) -> None:
        if len(data) != 8:
            raise ValueError("TPDO1 length")
        d.position, d.velocity = struct.unpack("<ii", data)
        d.feedback_time = now
        # the drive sampled these at the SYNC they answer
        d.sample_time = sampled

    def _on_tpdo2(self, d: _Drive, data: bytes, now: float) -> None:
        if len(data) != 4:
            raise ValueError("TPDO2 length")
        d.statusword, d.error_code = struct.unpack("<HH", data)
        d.status_time = now

    def _on_heartbeat(self, d: _Drive, data: bytes, now: float) -> None:
        if len(data) != 1:
            raise ValueError("heartbeat length")
        d.nmt_state = data[0] & 0x7F
        d.heartbeat_time = now

    def _on_emcy(self, d: _Drive, data: bytes, now: float) -> None:
        if len(data) != 8:
            raise ValueError("EMCY length")
        (d.emcy_code,) = struct.unpack_from("<H", data)
        self.counters["emcy"] += 1


class _FrameListener(can.Listener):
    """A python-can listener beside canopen's: hands our drives' frames to the
    driver and counts error frames."""

    def __init__(self, driver: Cia402Driver):
        self._driver = driver

    def on_message_received(self, msg) -> None:
        if msg.is_error_frame:
            self._driver.counters["bad_frames"] += 1
            return
        if not msg.is_extended_id and not msg.is_remote_frame:
            self._driver.on_frame(msg.arbitration_id, msg.data, msg.timestamp)

    def stop(self) -> None:
        pass


def _nmt_name(state: int | None) -> str:
    if state is None:
        return "none yet"
    try:
        return co.NmtState(state).name
    except ValueError:
        return f"0x{state:02X}"
