"""The ``cia402`` backend: CANopen drives with the CiA 402 profile.

Built on the ``canopen`` package (its Network, SDO client and NMT master);
one drive axis per joint, addressed by node id (and ``axis`` on multi-axis
devices). What the drive has comes from its EDS or DCF file
(``cia402.joints.<joint>.eds`` or the bus-wide ``cia402.eds``), read with
canopen's object dictionary: object sizes and types, which objects exist
and may be mapped into PDOs, how many PDOs, the COB-ID flag bits, the modes
of 0x6502, the watchdog objects and the velocity unit. Without a file the
driver assumes the generic drive of :mod:`cia402_dictionary` (32-bit
velocities, pv/csv/cst, heartbeat consumer, four PDOs each way).

At construction (no bus yet, a ConfigError naming the key): the files are
read, each joint's axis must exist in its file, the file must have the
velocity objects, its 0x6502 must offer ``cia402.mode`` (the message names
the modes it offers), torque mode needs 0x6071 and cst, and the drive
must have the PDOs the joints on it need. Then ``configure`` (all over
SDO, each step checked), per device:

* NMT pre-operational; device type 0x1000 must name profile 402;
* the watchdog: with a heartbeat consumer 0x1016, the drive's heartbeat
  producer 0x1017 and its consumer on *this* master's heartbeat (which the
  control loop itself sends); without 0x1016 but with node guarding
  0x100C/0x100D, guarding (0x1017 = 0, guard time = the heartbeat period,
  life time factor from ``cia402.drive_watchdog``; the loop sends the
  guarding requests and the drive's answers count as its heartbeat);
  without either, a warning that the drive will not stop by itself if the
  controller dies. Either way a dead or hung controller faults the drives
  and they stop on their own: the abort connection option code 0x6007
  (CiA 402: what the drive does when it detects the loss; 0 = nothing) is
  written per axis with ``cia402.drive_watchdog_reaction`` (fault: 1, quick
  stop: 3), and where the file has no 0x6007 or the drive refuses the write,
  a warning (log and diagnostics) says the reaction is the drive's own;

and per axis:

* mode of operation 0x6060: cyclic synchronous velocity (9) or profile
  velocity (3), checked in 0x6061; target velocity 0;
* the PDOs (transmission type 1, i.e. every SYNC), numbered per device in
  axis order: an RPDO with controlword 0x6040 + target velocity 0x60FF;
  in torque mode (or, without a file, always, as before) an RPDO with
  controlword + target torque 0x6071 + mode of operation 0x6060 (the mode
  switches at the SYNC that applies the torque); a TPDO with position
  actual 0x6064 + velocity actual 0x606C; a TPDO with statusword 0x6041
  + error code 0x603F (0x603F only where the file lets it be mapped; the
  error code then comes from the drive's EMCY); the other PDOs disabled;
* supported modes 0x6502 (the mode must be in it) and motor rated torque
  0x6076; the velocity unit 0x60A9 (with gear ratio 0x6091) where the
  drive has them, against ``velocity_resolution``;
* NMT operational, then wait for the first PDOs and heartbeats.

Every cycle ``read`` takes what the drives sent after the previous SYNC,
checks heartbeats, PDO age (late answers), NMT state and the 402 state,
and sends SYNC (and the master heartbeat or guarding requests when due)
in every case; ``write_velocities`` sends the velocity RPDOs, which the
drives apply at the next SYNC (one cycle of latency, as in any CSV
set-up). ``activate`` walks the 402 state machine over SDO (fault reset if
the fault is gone, shutdown, switch on, enable operation); ``deactivate``
sends "disable operation" with a zero target followed by a SYNC at once:
the drives ramp to standstill and switch their power stage off (their
0x605C option code decides how).

Drives whose TPDOs are fixed, or that need vendor objects, are not
covered: see README "CiA 402 drives".
"""

from __future__ import annotations

import logging
import math
import os
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
from holonomic_drivers.cia402_dictionary import (MAX_AXES, SI_VELOCITY_UNITS, AxisObjects,
                                                 DictionaryError, generic_dictionary,
                                                 load_dictionary, mode_bit, mode_names)
from holonomic_drivers.cia402_protocol import Control, OpMode, State, sdo_abort_text

PREFIX = "cia402"
_MODES = {"csv": OpMode.CYCLIC_SYNCHRONOUS_VELOCITY, "pv": OpMode.PROFILE_VELOCITY}
#: cia402.drive_watchdog_reaction -> 0x6007
_REACTIONS = {"fault": co.AbortConnection.FAULT, "quick_stop": co.AbortConnection.QUICK_STOP}
#: [s] how far back the SYNCs sent are kept to place a late-handled answer
SYNC_RECORD = 2.0
_log = logging.getLogger(__name__)

#: what each PDO carries: (profile object, sub) in order
RX_VELOCITY = ((co.CONTROLWORD, 0), (co.TARGET_VELOCITY, 0))
# torque mode: the mode of operation travels with the setpoint, so that the
# switch to cyclic synchronous torque happens at the SYNC that applies it
RX_TORQUE = ((co.CONTROLWORD, 0), (co.TARGET_TORQUE, 0), (co.MODES_OF_OPERATION, 0))
TX_FEEDBACK = ((co.POSITION_ACTUAL, 0), (co.VELOCITY_ACTUAL, 0))
TX_STATUS = ((co.STATUSWORD, 0), (co.ERROR_CODE, 0))
#: objects a velocity-controlled axis cannot do without
_REQUIRED = (co.CONTROLWORD, co.STATUSWORD, co.MODES_OF_OPERATION, co.MODES_DISPLAY,
             co.POSITION_ACTUAL, co.VELOCITY_ACTUAL, co.TARGET_VELOCITY)


class SdoRefused(DriverFault):
    """The drive aborted an SDO transfer (CiA 301 abort ``code``); the
    message names the joint, node, object and code."""

    def __init__(self, message: str, code: int, device: str):
        self.code = code
        super().__init__(f"{message}: abort code {sdo_abort_text(code)}", device)


@dataclass(frozen=True)
class PdoPlan:
    """The PDOs of one device (node): ``rx``/``tx`` map a PDO number
    (0-based) to its mapping entries ``(index, sub, bits)``, absolute
    indices (axis offset included); ``cob_ids`` the COB-ID of each PDO used
    (flags from the file); ``rx_count``/``tx_count`` the PDOs the device
    has (the unused ones are invalidated)."""

    node_id: int
    rx: dict[int, tuple[tuple[int, int, int], ...]]
    tx: dict[int, tuple[tuple[int, int, int], ...]]
    rx_cob: dict[int, int]
    tx_cob: dict[int, int]
    rx_count: int
    tx_count: int
    #: the PDOs not used: number -> COB-ID written with bit 31 (invalid)
    invalid_rx: dict[int, int]
    invalid_tx: dict[int, int]

    def writes(self) -> list[tuple[int, int, bytes]]:
        """The SDO downloads ``(index, subindex, data)`` that set up the PDOs.

        Per CiA 301: invalidate the PDO (COB-ID bit 31), set the transmission
        type, zero the mapping count, write the entries, set the count, then
        validate the COB-ID; the PDOs not used are invalidated.
        """
        u8, u32 = (lambda v: struct.pack("<B", v)), (lambda v: struct.pack("<I", v))
        writes = []
        for comm, mapping, pdos, cobs in ((co.RPDO_COMM, co.RPDO_MAP, self.rx, self.rx_cob),
                                          (co.TPDO_COMM, co.TPDO_MAP, self.tx, self.tx_cob)):
            for k, entries in sorted(pdos.items()):
                cob = cobs[k]
                writes += [(comm + k, 1, u32(cob | co.PDO_INVALID)), (comm + k, 2, u8(1)),
                           (mapping + k, 0, u8(0))]
                writes += [(mapping + k, n + 1, u32(co.pdo_map_entry(*entry)))
                           for n, entry in enumerate(entries)]
                writes += [(mapping + k, 0, u8(len(entries))), (comm + k, 1, u32(cob))]
        for comm, invalid in ((co.RPDO_COMM, self.invalid_rx), (co.TPDO_COMM, self.invalid_tx)):
            writes += [(comm + k, 1, u32(cob | co.PDO_INVALID)) for k, cob in invalid.items()]
        return writes


def plan_pdos(node_id: int, axes: list[tuple[AxisObjects, bool]]) -> PdoPlan:
    """The PDO plan of one device whose axes are ``(objects, torque)`` in
    axis order: per axis the velocity RPDO (+ the torque RPDO if
    ``torque``), the feedback TPDO and the status TPDO, each in the
    lowest-numbered free PDO whose mapping record holds its entries (a drive
    may declare fewer than eight mapping entries on some PDOs). Raises
    ValueError (one line) if the device has too few PDOs."""
    device = axes[0][0]
    rx_count, tx_count = device.pdo_count(co.RPDO_COMM), device.pdo_count(co.TPDO_COMM)
    rx, tx = {}, {}

    def place(pdos: dict, count: int, map_base: int, entries, what: str) -> None:
        for k in range(count):
            if k not in pdos and device.mapping_capacity(map_base + k) >= len(entries):
                pdos[k] = entries
                return
        raise ValueError(f"no free PDO can hold the {what} ({len(entries)} objects; the drive "
                         f"has {count} {'RPDOs' if map_base == co.RPDO_MAP else 'TPDOs'})")

    for objects, torque in axes:
        axis = f"axis {objects.axis} " if len(axes) > 1 else ""
        place(rx, rx_count, co.RPDO_MAP, _entries(objects, RX_VELOCITY), f"{axis}velocity")
        if torque:
            place(rx, rx_count, co.RPDO_MAP, _entries(objects, RX_TORQUE), f"{axis}torque")
        place(tx, tx_count, co.TPDO_MAP, _entries(objects, TX_FEEDBACK), f"{axis}feedback")
        place(tx, tx_count, co.TPDO_MAP, _entries(objects, TX_STATUS), f"{axis}status")

    def ident(base, comm, k) -> int:
        """11-bit identifier: the predefined connection set for PDOs 1..4, the
        file's default beyond (0 if it has none)."""
        return base[k] + node_id if k < 4 else device.cob_id_default(comm + k) or 0

    def cob(base, comm, k):
        if not ident(base, comm, k):
            raise ValueError(f"PDO {k + 1} has no default COB-ID in the file")
        return ident(base, comm, k) | device.cob_id_flags(comm + k)

    def unused(base, comm, count, used):
        return {k: ident(base, comm, k) for k in range(count)
                if k not in used and ident(base, comm, k)}

    return PdoPlan(node_id, rx, tx,
                   {k: cob(co.RPDO, co.RPDO_COMM, k) for k in rx},
                   {k: cob(co.TPDO, co.TPDO_COMM, k) for k in tx},
                   rx_count, tx_count,
                   unused(co.RPDO, co.RPDO_COMM, rx_count, rx),
                   unused(co.TPDO, co.TPDO_COMM, tx_count, tx))


def _entries(objects: AxisObjects, layout) -> tuple[tuple[int, int, int], ...]:
    """Mapping entries of the objects of ``layout`` that the axis may map
    (the error code is left out where it cannot be)."""
    return tuple((objects.index(index), sub, objects.bits(index, sub)) for index, sub in layout
                 if objects.mappable(index, sub) or index != co.ERROR_CODE)


def pdo_configuration(node_id: int) -> list[tuple[int, int, bytes]]:
    """The PDO set-up of a drive without an EDS file (the generic drive):
    RPDO1 velocity, RPDO2 torque, TPDO1 feedback, TPDO2 status, 3..4
    invalidated."""
    return plan_pdos(node_id, [(AxisObjects(generic_dictionary(node_id)), True)]).writes()


@dataclass
class _Drive:
    """What the driver last heard from one drive axis (times on the driver clock)."""

    nmt_state: int | None = None
    heartbeat_time: float = -math.inf
    position: int = 0
    velocity: int = 0
    feedback_time: float = -math.inf
    sample_time: float = -math.inf
    #: the sample before (position, velocity, sample_time): a reading takes
    #: every drive at one SYNC, and a drive whose next answer came early is
    #: read at the previous one
    previous: tuple[int, int, float] = (0, 0, -math.inf)
    statusword: int = 0
    error_code: int = 0
    status_time: float = -math.inf
    emcy_code: int = 0


@dataclass(frozen=True)
class _Wiring:
    """One joint's axis as the driver uses it: its objects, and the COB-IDs
    and layouts of its PDOs."""

    objects: AxisObjects
    rx_velocity: int
    rx_torque: int | None
    tx_feedback: int
    tx_status: int
    feedback: tuple[tuple[int, int, int], ...]
    status: tuple[tuple[int, int, int], ...]


class Cia402Driver(CanDriver):
    name = "cia402"
    device_kind = "CANopen"
    axis_key = "axis"
    # Torque mode: cyclic synchronous torque (0x6060 = 10) through a second
    # RPDO on drives that list it in 0x6502, scaled by their rated torque 0x6076.
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
        self._reaction = _REACTIONS[p("drive_watchdog_reaction")]
        self._sdo_timeout = float(p("sdo_timeout"))
        counts, vel_units = [], []
        for joint in model.joint_names:
            res = float(params[f"{PREFIX}.joints.{joint}.encoder_resolution"])
            vres = float(params[f"{PREFIX}.joints.{joint}.velocity_resolution"])
            counts.append(res)
            vel_units.append(vres if vres > 0 else res)
        self._counts_per_rev = np.array(counts)
        self._vel_units_per_rev_s = np.array(vel_units)
        torque_mode = params.get("control_mode") == "torque"
        self._objects = self._load_objects(params, model.joint_names, torque_mode)
        #: node id -> the joints (indices) on that device, in axis order
        self._node_joints: dict[int, list[int]] = {}
        for i in sorted(range(len(self.devices)), key=lambda i: self.joints.axes[i]):
            self._node_joints.setdefault(self.joints.node_ids[i], []).append(i)
        self._plans: dict[int, PdoPlan] = {}
        self._wiring: list[_Wiring | None] = [None] * len(self.devices)
        for node, joints in self._node_joints.items():
            # without a file, the torque RPDO is mapped always (as before files)
            with_torque = [bool(self._objects[i].source == "" or torque_mode) for i in joints]
            try:
                plan = plan_pdos(node, [(self._objects[i], t)
                                        for i, t in zip(joints, with_torque)])
            except ValueError as exc:
                raise ConfigError(self._eds_key(joints[0]), self._objects[joints[0]].source,
                                  f"a drive with the PDOs its joints need ({exc})") from None
            self._plans[node] = plan
            # dicts keep the order in which plan_pdos placed the PDOs
            rx, tx = iter(plan.rx), iter(plan.tx)
            for i, torque in zip(joints, with_torque):
                velocity = next(rx)
                torque_pdo = next(rx) if torque else None
                feedback, status = next(tx), next(tx)
                # the frames go out on the 11-bit identifier (CiA 301: bits 29..31
                # of the COB-ID entry are flags, not part of the identifier)
                self._wiring[i] = _Wiring(self._objects[i], plan.rx_cob[velocity] & co.PDO_ID_11,
                                          None if torque_pdo is None
                                          else plan.rx_cob[torque_pdo] & co.PDO_ID_11,
                                          plan.tx_cob[feedback] & co.PDO_ID_11,
                                          plan.tx_cob[status] & co.PDO_ID_11,
                                          plan.tx[feedback], plan.tx[status])
        self._drives = [_Drive() for _ in self.devices]
        #: rated motor torque [N m] per drive (0: no cyclic synchronous torque)
        self._rated_torque = [0.0] * len(self.devices)
        #: drives last switched to torque mode
        self._in_torque = [False] * len(self.devices)
        #: node id -> "heartbeat" (0x1016), "guarding" (0x100C/0x100D) or "none"
        self._watchdog_kind: dict[int, str] = {}
        #: messages a user must see (also in ``status``)
        self.warnings: list[str] = []
        self._cob: dict[int, list[tuple[int, Callable]]] = {}
        for i, node in enumerate(self.joints.node_ids):
            w = self._wiring[i]
            for cob, handler in ((w.tx_feedback, self._on_feedback),
                                 (w.tx_status, self._on_status),
                                 (co.HEARTBEAT + node, self._on_heartbeat),
                                 (co.EMCY + node, self._on_emcy)):
                self._cob.setdefault(cob, []).append((i, handler))
        self._lock = threading.Lock()
        self._network = None
        self._nodes: dict[int, canopen.RemoteNode] = {}
        self._next_master_heartbeat = -math.inf
        self._sync_time = -math.inf
        #: (wall clock, driver clock) [s] of the SYNCs sent over the last
        #: SYNC_RECORD seconds, newest last: an answer handled after a stall of
        #: this thread must still find the SYNC it answers (a fixed 16 SYNCs,
        #: 80 ms at 200 Hz, would be shorter than a 0.2 s feedback_timeout
        #: allows, and shorter than the 50 ms default at 1 kHz: such an answer
        #: would be stamped with the newest SYNC, a stall late, and read as an
        #: encoder glitch)
        self._syncs: deque[tuple[float, float]] = deque(
            maxlen=max(16, math.ceil(SYNC_RECORD * control_rate)))
        #: the last reading returned (a cycle with nothing new repeats it)
        self._last_reading: JointReading | None = None
        self.counters = {"bad_frames": 0, "emcy": 0, "syncs": 0, "frames_sent": 0,
                         "unplaced_answers": 0}

    def _eds_key(self, i: int) -> str:
        joint_key = f"{PREFIX}.joints.{self.joints.joint_names[i]}.eds"
        return joint_key if self.params.get(joint_key) else f"{PREFIX}.eds"

    def _load_objects(self, params, joint_names, torque_mode: bool) -> list[AxisObjects]:
        """Each joint's axis from its EDS/DCF (or the generic drive), checked
        for what the configured mode needs; ConfigError naming the key."""
        default = str(params.get(f"{PREFIX}.eds", ""))
        loaded: dict[tuple[str, int], object] = {}
        out = []
        for i, joint in enumerate(joint_names):
            path = str(params.get(f"{PREFIX}.joints.{joint}.eds", "")) or default
            path = os.path.expanduser(path)
            node, axis = self.joints.node_ids[i], self.joints.axes[i]
            key = self._eds_key(i)
            if not path:
                if axis:
                    raise ConfigError(f"{PREFIX}.joints.{joint}.axis", axis,
                                      "0 for a drive without an EDS file (set "
                                      f"{PREFIX}.joints.{joint}.eds for a multi-axis device)")
                out.append(AxisObjects(generic_dictionary(node)))
                continue
            if (path, node) not in loaded:
                try:
                    loaded[(path, node)] = load_dictionary(path, node)
                except DictionaryError as exc:
                    raise ConfigError(key, path, f"a readable EDS/DCF file ({exc})") from None
            objects = AxisObjects(loaded[(path, node)], axis, path)
            if not objects.has(co.CONTROLWORD):
                axes = sum(1 for k in range(MAX_AXES)
                           if AxisObjects(objects.od, k).has(co.CONTROLWORD))
                if axes == 0:
                    raise ConfigError(key, path, "the EDS of a CiA 402 drive (it has no "
                                      "controlword 0x6040)")
                raise ConfigError(f"{PREFIX}.joints.{joint}.axis", axis,
                                  f"an axis of {path} (it has {axes}: 0..{axes - 1})")
            missing = [f"0x{objects.index(x):04X}" for x in _REQUIRED if not objects.has(x)]
            if missing:
                raise ConfigError(key, path, "the EDS of a CiA 402 velocity drive (it lacks "
                                  f"{', '.join(missing)})")
            unmappable = [f"0x{objects.index(x):04X}" for x, _ in RX_VELOCITY + TX_FEEDBACK
                          + ((co.STATUSWORD, 0),) if not objects.mappable(x)]
            if unmappable:
                raise ConfigError(key, path, "a drive whose velocity objects can be mapped "
                                  f"into PDOs ({', '.join(unmappable)} cannot)")
            offered = objects.default(co.SUPPORTED_MODES)
            if offered is not None and not int(offered) & mode_bit(self._mode):
                raise ConfigError(f"{PREFIX}.mode", self.params[f"{PREFIX}.mode"],
                                  f"a mode that {joint}'s drive offers in 0x6502 ({path}: "
                                  f"{mode_names(int(offered))})")
            if torque_mode:
                cst = offered is None or int(offered) & mode_bit(OpMode.CYCLIC_SYNCHRONOUS_TORQUE)
                if not (cst and objects.mappable(co.TARGET_TORQUE)
                        and objects.has(co.MOTOR_RATED_TORQUE)):
                    raise ConfigError("control_mode", "torque",
                                      f"'velocity': {joint}'s drive ({path}) has no cyclic "
                                      "synchronous torque with a mappable 0x6071 and 0x6076")
            out.append(objects)
        return out

    @classmethod
    def param_specs(cls, model) -> list[ParamSpec]:
        extra = (
            ParamSpec(f"{PREFIX}.joints.{{joint}}.encoder_resolution", "double",
                      "Position units (0x6064) per motor revolution of {joint}'s drive "
                      "[counts/rev].", minimum=0.0, exclusive_minimum=True, maximum=1e12),
            ParamSpec(f"{PREFIX}.joints.{{joint}}.velocity_resolution", "double",
                      "Velocity units (0x606C, 0x60FF) per motor rev/s of {joint}'s drive; "
                      "0: counts/s, i.e. encoder_resolution (60 for a drive in rpm, 600 in "
                      "0.1 rpm); checked against the drive's 0x60A9 where it has one.",
                      default=0.0, minimum=0.0, maximum=1e12),
            ParamSpec(f"{PREFIX}.joints.{{joint}}.eds", "string",
                      "EDS or DCF file of {joint}'s drive (absolute path, or relative to the "
                      "working directory); empty: the bus-wide cia402.eds.", default=""),
            ParamSpec(f"{PREFIX}.joints.{{joint}}.axis", "int",
                      "Axis of a multi-axis device that drives {joint} (its profile objects "
                      "at index + 0x800 x axis); joints on one node use different axes.",
                      default=0, minimum=0, maximum=MAX_AXES - 1),
        )
        return bus_specs(PREFIX) + [
            ParamSpec(f"{PREFIX}.mode", "string",
                      "Mode of operation: csv (cyclic synchronous velocity, 0x6060 = 9) or "
                      "pv (profile velocity, 3); must be in each drive's 0x6502.",
                      default="csv", choices=tuple(_MODES)),
            ParamSpec(f"{PREFIX}.eds", "string",
                      "EDS or DCF file (absolute path, or relative to the working directory) "
                      "of the drives of joints without their own; empty: a generic CiA 402 "
                      "drive (32-bit velocities, 4 PDOs each way, heartbeat consumer).",
                      default=""),
            ParamSpec(f"{PREFIX}.master_node_id", "int",
                      "Node id of this controller's heartbeat (0x700 + id); no drive may "
                      "use it.", default=127, minimum=1, maximum=127),
            ParamSpec(f"{PREFIX}.heartbeat_period", "double",
                      "Heartbeat period set in each drive (0x1017) and of the master; guard "
                      "time (0x100C) on drives watched by node guarding [s].",
                      default=0.05, minimum=0.001, maximum=60.0),
            ParamSpec(f"{PREFIX}.heartbeat_timeout", "double",
                      "A drive whose heartbeat (or guarding answer) is older than this is "
                      "lost: fault and stop [s].", default=0.2, minimum=0.002, maximum=60.0),
            ParamSpec(f"{PREFIX}.feedback_timeout", "double",
                      "PDOs older than this are late (the drive stopped answering SYNC): "
                      "fault and stop [s].", default=0.05, minimum=0.002, maximum=10.0),
            ParamSpec(f"{PREFIX}.drive_watchdog", "double",
                      "Time after which each drive faults by itself when this controller "
                      "stops [s]: heartbeat consumer 0x1016 on this master's heartbeat, or on "
                      "drives without it node guarding (life time 0x100C x 0x100D); 0 "
                      "leaves both alone.", default=0.25, minimum=0.0, maximum=60.0),
            ParamSpec(f"{PREFIX}.drive_watchdog_reaction", "string",
                      "What each drive does when its watchdog (cia402.drive_watchdog) finds "
                      "this controller gone, written to its abort connection option code "
                      "0x6007: fault (1: its fault reaction 0x605E, then FAULT) or quick_stop "
                      "(3: its quick stop ramp 0x6085, then as 0x605A says); a drive without "
                      "a writable 0x6007 keeps its own, with a warning.",
                      default="fault", choices=tuple(_REACTIONS)),
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
            self._nodes = {}
            for node_id, joints in self._node_joints.items():
                node = canopen.RemoteNode(node_id, self._objects[joints[0]].od)
                network.add_node(node)
                node.sdo.RESPONSE_TIMEOUT = self._sdo_timeout
                self._nodes[node_id] = node
            for node_id, joints in self._node_joints.items():
                self._configure_device(node_id, joints)
            self._read_quick_stop_options()
            for node in self._nodes.values():
                node.nmt.send_command(co.NmtCommand.START)
            self._wait("first PDOs and heartbeats",
                       lambda: self._first_not_ready(enabled=False))
        except (canopen.SdoCommunicationError, canopen.SdoAbortedError, can.CanError) as exc:
            self._disconnect()
            raise DriverCommunicationError(str(exc), PREFIX) from exc
        except BaseException:
            self._disconnect()
            raise

    def _read_quick_stop_options(self) -> None:
        """Each axis's quick stop option code 0x605A (how it obeys the
        emergency stop's quick stop command), for the status; a warning where
        it coasts (0: power stage off at once) or cannot be read."""
        self.quick_stop_options = []
        for i, device in enumerate(self.devices):
            option = None
            if self._objects[i].has(co.QUICK_STOP_OPTION):
                try:
                    option = int(self._upload(i, co.QUICK_STOP_OPTION))
                except (DriverError, canopen.SdoAbortedError) as exc:
                    self.warnings.append(f"{device}: quick stop option code 0x605A not "
                                         f"readable ({exc}): the drive's default applies")
            else:
                self.warnings.append(f"{device}: no quick stop option code 0x605A: the "
                                     "emergency stop's quick stop does what the drive defaults to")
            if option == 0:
                self.warnings.append(f"{device}: quick stop option code 0x605A = 0 disables "
                                     "the power stage at once: the emergency stop coasts "
                                     "(1/2 ramp then disable, 5/6 ramp and hold)")
            self.quick_stop_options.append(option)

    def _on_quick_stop(self) -> None:
        """The emergency stop: controlword QUICK STOP (0x0002) with a zero
        target on every drive, then SYNC at once. Each drive brakes as its
        0x605A says (on its quick stop deceleration 0x6085 for 2 and 6) and
        then disables (1-4) or holds in QUICK STOP ACTIVE (5-8)."""
        self._stop_all(Control.QUICK_STOP)

    def _download(self, i: int, index: int, sub: int, data: bytes) -> None:
        """One SDO write to joint ``i``'s device; a refusal (SdoRefused) names
        the joint, node, object and abort code."""
        try:
            self._nodes[self.joints.node_ids[i]].sdo.download(index, sub, data)
        except canopen.SdoAbortedError as exc:
            raise SdoRefused(f"refused the SDO write of {self._object_name(i, index, sub)} = "
                             f"0x{data[::-1].hex().upper()}", exc.code,
                             self.devices[i]) from exc
        except canopen.SdoCommunicationError as exc:
            raise DriverCommunicationError(f"no answer to the SDO write of 0x{index:04X}:{sub} "
                                           f"({exc})", self.devices[i]) from exc

    def _upload(self, i: int, index: int, sub: int = 0):
        """Joint ``i``'s axis object (profile index) read by SDO, decoded by its type."""
        objects = self._objects[i]
        try:
            data = self._nodes[self.joints.node_ids[i]].sdo.upload(objects.index(index), sub)
        except canopen.SdoAbortedError as exc:
            # a sibling of SdoCommunicationError in canopen, not a subclass
            raise SdoRefused(f"refused the SDO read of "
                             f"{self._object_name(i, objects.index(index), sub)}", exc.code,
                             self.devices[i]) from exc
        except canopen.SdoCommunicationError as exc:
            raise DriverCommunicationError(f"no answer to the SDO read of "
                                           f"0x{objects.index(index):04X}:{sub} ({exc})",
                                           self.devices[i]) from exc
        return objects.decode(index, sub, data)

    def _object_name(self, i: int, index: int, sub: int) -> str:
        """``0x6076:0 (Motor rated torque)``: an absolute index of joint ``i``'s
        device, named as its dictionary names it where it has it."""
        try:
            var = self._objects[i].od.get_variable(index, sub)
        except (KeyError, TypeError):
            var = None
        return f"0x{index:04X}:{sub}" + (f" ({var.name})" if var is not None else "")

    def _write(self, i: int, index: int, value, sub: int = 0) -> None:
        """Joint ``i``'s axis object (profile index) written by SDO in its own type."""
        objects = self._objects[i]
        self._download(i, objects.index(index), sub, objects.encode(index, sub, value))

    def _configure_device(self, node_id: int, joints: list[int]) -> None:
        first = joints[0]
        device, objects, node = self.devices[first], self._objects[first], self._nodes[node_id]
        node.nmt.send_command(co.NmtCommand.ENTER_PRE_OPERATIONAL)
        try:
            (device_type,) = struct.unpack("<I", node.sdo.upload(co.DEVICE_TYPE, 0)[:4])
        except canopen.SdoAbortedError as exc:
            raise SdoRefused("refused the SDO read of "
                             f"{self._object_name(first, co.DEVICE_TYPE, 0)}",
                             exc.code, device) from exc
        except canopen.SdoCommunicationError as exc:
            raise DriverCommunicationError(
                f"no answer to SDO ({exc}): is it powered, on this bus, with this node id "
                "and bit rate?", device) from exc
        if device_type & 0xFFFF != co.PROFILE_402:
            raise DriverFault(f"device type 0x{device_type:08X} is not a CiA 402 drive", device)
        kind = self._watchdog_plan(objects)
        self._watchdog_kind[node_id] = kind
        period_ms = max(1, round(self._heartbeat_period * 1e3))
        if kind == "guarding":
            # CiA 301: a heartbeat producer time != 0 disables node guarding
            if objects.has(co.PRODUCER_HEARTBEAT_TIME):
                self._write(first, co.PRODUCER_HEARTBEAT_TIME, 0)
            factor = min(255, max(1, math.ceil(self._watchdog / self._heartbeat_period)))
            self._write(first, co.GUARD_TIME, min(period_ms, 0xFFFF))
            self._write(first, co.LIFE_TIME_FACTOR, factor)
        else:
            if not objects.has(co.PRODUCER_HEARTBEAT_TIME):
                raise DriverFault("has neither a heartbeat producer (0x1017) nor node guarding "
                                  "(0x100C/0x100D): the driver cannot tell that it is alive",
                                  device)
            self._write(first, co.PRODUCER_HEARTBEAT_TIME, period_ms)
            if kind == "heartbeat":
                self._write(first, co.CONSUMER_HEARTBEAT_TIME, (self._master_id << 16)
                            | min(0xFFFF, max(1, round(self._watchdog * 1e3))), sub=1)
            elif self._watchdog > 0:
                self._warn(first, "has neither a heartbeat consumer (0x1016) nor node "
                           "guarding (0x100C/0x100D): it will NOT stop by itself if this "
                           "controller dies or hangs")
        for i in joints:
            if kind != "none":
                self._set_watchdog_reaction(i)
            self._write(i, co.MODES_OF_OPERATION, int(self._mode))
            self._write(i, co.TARGET_VELOCITY, 0)
        for index, sub, data in self._plans[node_id].writes():
            self._download(first, index, sub, data)
        for i in joints:
            self._check_axis(i)

    def _set_watchdog_reaction(self, i: int) -> None:
        """0x6007 = cia402.drive_watchdog_reaction on joint ``i``'s axis, or a
        warning where the file has no 0x6007, the file makes it read-only or
        the drive refuses the write (what it then does is its own, read back
        where it can be)."""
        objects = self._objects[i]
        wanted = f"{self.params[f'{PREFIX}.drive_watchdog_reaction']} ({int(self._reaction)})"
        if not objects.has(co.ABORT_CONNECTION_OPTION):
            self._warn(i, "has no abort connection option code 0x6007: what it does when its "
                       f"watchdog finds this controller gone is its maker's choice, not "
                       f"{wanted}")
            return
        var = objects.variable(co.ABORT_CONNECTION_OPTION)
        refused = None
        if var.writable:
            try:
                self._write(i, co.ABORT_CONNECTION_OPTION, int(self._reaction))
                return
            except SdoRefused as exc:
                refused = exc
        try:
            current = f"it reads {self._upload(i, co.ABORT_CONNECTION_OPTION)}"
        except SdoRefused as exc:
            current = f"its value cannot be read ({sdo_abort_text(exc.code)})"
        why = (f"refused the write of 0x6007 = {int(self._reaction)} "
               f"({sdo_abort_text(refused.code)})" if refused is not None
               else "has a read-only abort connection option code 0x6007")
        self._warn(i, f"{why}; {current} (0: no action): its reaction to losing this "
                   f"controller is not {wanted}")

    def _watchdog_plan(self, objects: AxisObjects) -> str:
        if self._watchdog <= 0:
            return "none"
        if objects.has(co.CONSUMER_HEARTBEAT_TIME, 1):
            return "heartbeat"
        if objects.has(co.GUARD_TIME) and objects.has(co.LIFE_TIME_FACTOR):
            return "guarding"
        return "none"

    def _warn(self, i: int, message: str) -> None:
        text = f"{self.devices[i]}: {message}"
        self.warnings.append(text)
        _log.warning(text)

    def _check_axis(self, i: int) -> None:
        """After the set-up: the mode took, it is in 0x6502, torque scaling,
        the velocity unit."""
        device, objects = self.devices[i], self._objects[i]
        mode = self._upload(i, co.MODES_DISPLAY)
        supported = self._upload(i, co.SUPPORTED_MODES) if objects.has(co.SUPPORTED_MODES) \
            else None
        name = self.params[f"{PREFIX}.mode"]
        if supported is not None and not supported & mode_bit(self._mode):
            raise DriverFault(f"does not offer mode {name} (0x6502 offers: "
                              f"{mode_names(supported)})", device)
        if mode != int(self._mode):
            raise DriverFault(f"did not take mode {name} (0x6061 reads {mode})", device)
        # torque mode needs CST in 0x6502 and a rated torque to scale 0x6071
        rated = 0
        if objects.has(co.MOTOR_RATED_TORQUE):
            try:
                rated = self._upload(i, co.MOTOR_RATED_TORQUE)
            except SdoRefused:
                rated = 0                   # no 0x6076: no torque mode
        cst = supported is not None and supported & mode_bit(OpMode.CYCLIC_SYNCHRONOUS_TORQUE)
        torque_pdo = self._wiring[i].rx_torque is not None
        self._rated_torque[i] = rated * 1e-3 if cst and torque_pdo else 0.0
        if objects.has(co.SI_UNIT_VELOCITY):
            self._check_velocity_unit(i)

    def _check_velocity_unit(self, i: int) -> None:
        """0x60A9 (and the gear ratio 0x6091 it applies after) against the
        configured velocity units per motor rev/s."""
        joint = self.joints.joint_names[i]
        unit = self._upload(i, co.SI_UNIT_VELOCITY)
        if unit not in SI_VELOCITY_UNITS:
            self._warn(i, f"velocity unit 0x60A9 = 0x{unit:08X} is not one the driver knows "
                       f"(counts/s, rev/s, rpm, 0.1 rpm, 0.001 rpm): check "
                       f"{PREFIX}.joints.{joint}.velocity_resolution by hand")
            return
        name, per_rev = SI_VELOCITY_UNITS[unit]
        per_rev_s = self._counts_per_rev[i] if per_rev is None else per_rev
        gear = ""
        objects = self._objects[i]
        if objects.has(co.GEAR_RATIO, 1) and objects.has(co.GEAR_RATIO, 2):
            motor_revs = self._upload(i, co.GEAR_RATIO, 1)
            shaft_revs = self._upload(i, co.GEAR_RATIO, 2)
            if motor_revs and shaft_revs and motor_revs != shaft_revs:
                # the drive's velocity is of the shaft after its gear
                per_rev_s = per_rev_s * shaft_revs / motor_revs
                gear = f" after its gear 0x6091 = {motor_revs}:{shaft_revs}"
        configured = self._vel_units_per_rev_s[i]
        if not math.isclose(configured, per_rev_s, rel_tol=1e-6):
            raise DriverFault(
                f"velocity unit 0x60A9 = 0x{unit:08X} ({name}{gear}) means {per_rev_s:g} "
                f"units per motor rev/s, but {PREFIX}.joints.{joint}.velocity_resolution "
                f"gives {configured:g}", self.devices[i])

    def _on_activate(self) -> None:
        try:
            for i in range(len(self.devices)):
                self._enable_drive(i)
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

    def _enable_drive(self, i: int) -> None:
        device = self.devices[i]
        state = self._sdo_state(i)
        if state is State.QUICK_STOP_ACTIVE:
            # after an emergency stop with 0x605A 5-8: out of it through
            # disable voltage (shutdown is no transition from there)
            self._write(i, co.CONTROLWORD, Control.DISABLE_VOLTAGE)
            state = self._sdo_state(i)
        if state in (State.FAULT, State.FAULT_REACTION_ACTIVE):
            # fault reset acts on the rising edge of bit 7
            self._write(i, co.CONTROLWORD, Control.DISABLE_VOLTAGE)
            self._write(i, co.CONTROLWORD, Control.FAULT_RESET)
            state = self._sdo_state(i)
            if state is State.FAULT:
                code = (self._upload(i, co.ERROR_CODE) if self._objects[i].has(co.ERROR_CODE)
                        else self._drives[i].emcy_code)
                raise DriverFault(f"fault persists after fault reset (error code 0x{code:04X})",
                                  device)
        elif state is State.QUICK_STOP_ACTIVE:
            # e.g. its watchdog's quick stop (0x6007 = 3): CiA 402 leaves QUICK
            # STOP ACTIVE only by "disable voltage" (transition 12)
            self._write(i, co.CONTROLWORD, Control.DISABLE_VOLTAGE)
        self._write(i, co.TARGET_VELOCITY, 0)
        if self._in_torque[i]:
            # every arming starts in the configured velocity mode, target 0
            self._write(i, co.TARGET_TORQUE, 0)
            self._write(i, co.MODES_OF_OPERATION, int(self._mode))
            self._in_torque[i] = False
        for command, expected in ((Control.SHUTDOWN, State.READY_TO_SWITCH_ON),
                                  (Control.SWITCH_ON, State.SWITCHED_ON),
                                  (Control.ENABLE_OPERATION, State.OPERATION_ENABLED)):
            self._write(i, co.CONTROLWORD, command)
            deadline = time.monotonic() + self._startup_timeout
            while (state := self._sdo_state(i)) is not expected:
                if time.monotonic() > deadline:
                    raise DriverFault(f"did not reach {expected.value} after controlword "
                                      f"0x{int(command):04X} (state {state.value})", device)
                time.sleep(0.002)

    def _on_deactivate(self) -> None:
        self._stop_all()

    def _on_close(self) -> None:
        if self._network is not None:
            for node in self._nodes.values():
                try:
                    node.nmt.send_command(co.NmtCommand.ENTER_PRE_OPERATIONAL)
                except Exception:  # noqa: BLE001 (bus already gone: nothing to tell)
                    pass
        self._disconnect()

    # -- cycle --------------------------------------------------------------------------------
    def _on_read(self) -> JointReading:
        now = time.monotonic()
        if now - self._sync_time > self._feedback_timeout:
            # No SYNC for longer than the PDOs may be late (the first read
            # after configure, a caller that paused): their age says nothing
            # about the drives, so ask again before judging them.
            self._wait("PDOs after a pause of the control loop",
                       lambda: self._first_not_ready(now, enabled=False))
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
        # One SYNC for every joint: the newest one all drives have answered.
        # A drive whose answer to the next SYNC is already in is read at its
        # previous sample -- mixing samples of two SYNCs under one stamp would
        # show the early drives moving in no time. A cycle whose PDOs have not
        # arrived yet repeats the stamp (the odometry waits for them instead
        # of seeing a standstill).
        stamp = min(d.sample_time for d in drives)
        last = self._last_reading
        if last is not None and stamp <= last.stamp:
            return last             # no SYNC answered by all drives since: nothing new
        for i, d in enumerate(drives):
            if d.sample_time > stamp and d.previous[2] <= stamp:
                positions[i], velocities[i] = d.previous[0], d.previous[1]
            else:
                positions[i], velocities[i] = d.position, d.velocity
        self._last_reading = JointReading(
            stamp, self.joints.to_joint_positions(positions / self._counts_per_rev),
            self.joints.to_joint_velocities(velocities / self._vel_units_per_rev_s),
            self._no_efforts)
        return self._last_reading

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        motor = self.joints.to_motor_velocities(np.asarray(velocities, float))
        units = np.rint(motor * self._vel_units_per_rev_s)
        for i, value in enumerate(units):
            if self._in_torque[i]:
                # back to the velocity mode: one SDO (the velocity RPDO does not
                # carry it); a failure names the drive and the object
                self._write(i, co.MODES_OF_OPERATION, int(self._mode))
                self._in_torque[i] = False
            self._send_velocity(i, Control.ENABLE_OPERATION, value)

    def _send_velocity(self, i: int, word: int, value: float) -> None:
        """The velocity RPDO: controlword + target velocity, each in the size
        the drive's dictionary gives it (a 16-bit target saturates)."""
        w = self._wiring[i]
        self._send(w.rx_velocity, w.objects.encode(co.CONTROLWORD, 0, int(word))
                   + w.objects.encode(co.TARGET_VELOCITY, 0, value))

    def _send_torque(self, i: int, word: int, per_mille: int) -> None:
        w = self._wiring[i]
        self._send(w.rx_torque, w.objects.encode(co.CONTROLWORD, 0, int(word))
                   + w.objects.encode(co.TARGET_TORQUE, 0, per_mille)
                   + w.objects.encode(co.MODES_OF_OPERATION, 0,
                                      OpMode.CYCLIC_SYNCHRONOUS_TORQUE))

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        """Joint torques [N m] -> motor torques (gear, direction) -> 0x6071 in
        per mille of each drive's rated torque, with 0x6060 = cyclic
        synchronous torque, in the torque RPDO."""
        motor = self.joints.to_motor_torques(np.asarray(efforts, float))
        for i, value in enumerate(motor):
            rated = self._rated_torque[i]
            if rated <= 0.0:
                raise DriverFault("has no cyclic synchronous torque mode (0x6502) or no "
                                  "rated torque (0x6076)", self.devices[i])
            units = int(np.clip(round(1000.0 * value / rated), -32767, 32767))
            self._send_torque(i, Control.ENABLE_OPERATION, units)
            self._in_torque[i] = True

    def wiring(self) -> list[str]:
        """One line per joint: its drive, file, axis, PDOs (COB-ID = objects)
        and watchdog -- what configure sets up (the watchdog once configured)."""
        lines = []
        for i, w in enumerate(self._wiring):
            node = self.joints.node_ids[i]
            plan = self._plans[node]

            def pdo(kind: str, pdos: dict, cobs: dict, cob: int | None) -> str:
                if cob is None:
                    return ""
                k = next(k for k in pdos if cobs[k] & 0x7FF == cob & 0x7FF)
                objects = " + ".join(f"0x{index:04X} ({bits})" for index, _, bits in pdos[k])
                return f"{kind}{k + 1} 0x{cob & 0x7FF:03X} = {objects}; "

            lines.append(
                f"{self.devices[i]}: {w.objects.source or 'generic drive (no EDS)'}; "
                + pdo("RPDO", plan.rx, plan.rx_cob, w.rx_velocity)
                + pdo("RPDO", plan.rx, plan.rx_cob, w.rx_torque)
                + pdo("TPDO", plan.tx, plan.tx_cob, w.tx_feedback)
                + pdo("TPDO", plan.tx, plan.tx_cob, w.tx_status)
                + f"watchdog {self._watchdog_kind.get(node, 'not set up yet')}")
        return lines

    def status(self) -> dict[str, str]:
        out = super().status()
        now = time.monotonic()
        with self._lock:
            for i, d in enumerate(self._drives):
                node = self.joints.node_ids[i]
                out[self.joints.joint_names[i]] = (
                    f"node {node}: NMT {_nmt_name(d.nmt_state)}, "
                    f"{co.state_of(d.statusword).value}, error code "
                    f"0x{d.error_code or d.emcy_code:04X}, heartbeat "
                    f"{(now - d.heartbeat_time) * 1e3:.0f} ms ago, watchdog "
                    f"{self._watchdog_kind.get(node, 'not set up')}")
        for k, text in enumerate(self.warnings):
            out[f"warning {k + 1}"] = text
        return out

    # -- bus ---------------------------------------------------------------------------------
    def _cycle_frames(self, now: float) -> None:
        """SYNC every cycle (the drives sample and answer); the master
        heartbeat and the node guarding requests when due."""
        if now >= self._next_master_heartbeat:
            self._next_master_heartbeat = now + self._heartbeat_period
            self._send(co.HEARTBEAT + self._master_id, bytes([co.NmtState.OPERATIONAL]))
            for node, kind in self._watchdog_kind.items():
                if kind == "guarding":
                    self._send(co.HEARTBEAT + node, b"", remote=True)
        self._send_sync()

    def _send_sync(self) -> None:
        """A SYNC, recorded with both clocks as it leaves (the drives sample
        then; ``_answered_sync`` places their answers with it)."""
        sent = time.monotonic()
        self._sync_time = sent
        with self._lock:
            self._syncs.append((time.time(), sent))
        self._send(co.SYNC, b"")
        self.counters["syncs"] += 1

    def _send(self, cob_id: int, data: bytes, remote: bool = False) -> None:
        try:
            self._network.send_message(cob_id, data, remote=remote)
        except (can.CanError, RuntimeError) as exc:
            raise DriverCommunicationError(f"send of 0x{cob_id:03X} failed: {exc}",
                                           PREFIX) from exc
        self.counters["frames_sent"] += 1

    def _stop_all(self, word: int = Control.SWITCH_ON) -> None:
        """Controlword ``word`` (default: disable operation) with zero targets
        on every drive, then SYNC now."""
        failure = None
        for i in range(len(self.devices)):
            try:
                if self._in_torque[i]:
                    self._send_torque(i, word, 0)
                self._send_velocity(i, word, 0)
            except DriverCommunicationError as exc:
                failure = failure or exc
        try:
            self._send_sync()
        except DriverCommunicationError as exc:
            failure = failure or exc
        if failure is not None:
            raise failure

    def _sdo_state(self, i: int) -> State:
        return co.state_of(self._upload(i, co.STATUSWORD))

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
        entries = self._cob.get(cob_id)
        if entries is None:
            return
        now = time.monotonic()
        try:
            with self._lock:
                for i, handler in entries:
                    if handler == self._on_feedback:
                        handler(i, bytes(data), now, self._answered_sync(timestamp))
                    else:
                        handler(i, bytes(data), now)
        except (struct.error, ValueError, KeyError):
            self.counters["bad_frames"] += 1
            return
        if co.EMCY < cob_id <= co.EMCY + 127:
            self.counters["emcy"] += 1          # once per frame, whatever the axes

    def _decode(self, i: int, entries, data: bytes) -> list[int]:
        """Values of a TPDO laid out as ``entries``; ValueError if its length differs."""
        if len(data) != sum(bits // 8 for _, _, bits in entries):
            raise ValueError("PDO length")
        od, values, offset = self._objects[i].od, [], 0
        for index, sub, bits in entries:
            n = bits // 8
            values.append(od.get_variable(index, sub).decode_raw(data[offset:offset + n]))
            offset += n
        return values

    def _answered_sync(self, arrived: float | None) -> float:
        """Driver-clock time of the SYNC a TPDO that arrived at ``arrived``
        [s, wall clock] answers: the last one sent before it arrived. (The
        last SYNC sent *now* is wrong for an answer handled late -- this
        thread starved, frames queued: that sample would be stamped a cycle
        or a stall late, and the next one would seem to move that far in no
        time.) Without an arrival time: the last SYNC sent. None: it arrived
        before every SYNC of a full record (SYNC_RECORD seconds ago): which
        SYNC it answers is unknown."""
        if arrived:
            for wall, clock in reversed(self._syncs):
                if wall <= arrived:
                    return clock
            if len(self._syncs) == self._syncs.maxlen:
                return None
        return self._sync_time

    def _on_feedback(self, i: int, data: bytes, now: float, sampled: float | None) -> None:
        d = self._drives[i]
        position, velocity = self._decode(i, self._wiring[i].feedback, data)
        if sampled is None:
            # a sample of unknown time is no sample: the next answer is read
            self.counters["unplaced_answers"] += 1
            return
        if sampled != d.sample_time:
            d.previous = (d.position, d.velocity, d.sample_time)
        d.position, d.velocity = position, velocity
        d.feedback_time = now
        # the drive sampled these at the SYNC they answer
        d.sample_time = sampled

    def _on_status(self, i: int, data: bytes, now: float) -> None:
        d = self._drives[i]
        values = self._decode(i, self._wiring[i].status, data)
        d.statusword = values[0]
        if len(values) > 1:
            d.error_code = values[1]
        d.status_time = now

    def _on_heartbeat(self, i: int, data: bytes, now: float) -> None:
        if len(data) != 1:
            raise ValueError("heartbeat length")
        d = self._drives[i]
        # the toggle bit 7 of a node guarding answer is not part of the state
        d.nmt_state = data[0] & 0x7F
        d.heartbeat_time = now

    def _on_emcy(self, i: int, data: bytes, now: float) -> None:
        if len(data) != 8:
            raise ValueError("EMCY length")
        (self._drives[i].emcy_code,) = struct.unpack_from("<H", data)


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
