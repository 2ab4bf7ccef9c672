"""ODrive CANSimple protocol (firmware 0.5.x and 0.6.x): frame ids and payloads.

Every frame has an 11-bit id ``node_id << 5 | cmd_id`` and a little-endian
payload. Pure functions, no bus: the driver and the emulated ODrive both use
them, and the protocol tests check them against ODrive's CANSimple DBC files
(``odrive-cansimple-0.5.6.dbc`` and ``-0.6.10.dbc``).

What differs between the firmware lines, for the messages used here:

=================== ============================== ===================================
                    0.5.x (ODrive v3.x)            0.6.x (ODrive Pro, S1, Micro)
=================== ============================== ===================================
node ids            0..63                          0..62 (0x3F: broadcast / unaddressed)
Heartbeat bytes 5-7 motor / encoder / controller   procedure result (byte 5),
                    error flags (bit 40, 48, 56),  trajectory done (bit 48)
                    trajectory done (bit 63)
Axis_Error bits     AxisError of 0.5.x:            ODrive.Error: 0x40 MISSING_INPUT,
                    0x40 MOTOR_FAILED, 0x800       0x1000000 WATCHDOG_TIMER_EXPIRED, ...
                    WATCHDOG_TIMER_EXPIRED, ...
Clear_Errors        no payload                     1 byte (Identify)
endpoint access     none                           RxSdo / TxSdo by endpoint id
                                                   (ids from the firmware's
                                                   flat_endpoints.json), Get_Version
watchdog fed by     any frame to the axis          Set_Input_Vel, Set_Axis_State (ODrive's
                    (its can_simple.cpp)           can_watchdog example)
=================== ============================== ===================================

Only the messages this stack uses are here; see the ODrive documentation
("CAN Protocol") for the rest.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

MAX_NODE_ID = 0x3F      # 6 bits of node id in an 11-bit frame id
#: firmware lines whose CANSimple layout this module speaks
FIRMWARES = ("0.5", "0.6")
#: 0.6.x: node id 0x3F addresses every ODrive (discovery, broadcast), so an
#: axis can only be given 0..0x3E
BROADCAST_NODE_ID = 0x3F


def max_node_id(firmware: str) -> int:
    """Highest node id an axis can have on ``firmware`` ("0.5" or "0.6")."""
    return MAX_NODE_ID if firmware == "0.5" else BROADCAST_NODE_ID - 1


class Cmd(enum.IntEnum):
    GET_VERSION = 0x00           # 0.6.x: axis -> host on request: hardware and firmware versions
    HEARTBEAT = 0x01             # axis -> host, cyclic
    ESTOP = 0x02
    GET_ERROR = 0x03             # axis -> host (RTR or cyclic): active_errors, disarm_reason
    RX_SDO = 0x04                # 0.6.x: host -> axis, read / write one endpoint by id
    TX_SDO = 0x05                # 0.6.x: axis -> host, the endpoint's value
    SET_AXIS_STATE = 0x07
    GET_ENCODER_ESTIMATES = 0x09  # axis -> host (cyclic or RTR): pos [rev], vel [rev/s]
    SET_CONTROLLER_MODE = 0x0B
    SET_INPUT_VEL = 0x0D
    SET_INPUT_TORQUE = 0x0E
    SET_LIMITS = 0x0F
    REBOOT = 0x16
    CLEAR_ERRORS = 0x18


class AxisState(enum.IntEnum):
    UNDEFINED = 0
    IDLE = 1
    STARTUP_SEQUENCE = 2
    FULL_CALIBRATION_SEQUENCE = 3
    MOTOR_CALIBRATION = 4
    ENCODER_INDEX_SEARCH = 6
    ENCODER_OFFSET_CALIBRATION = 7
    CLOSED_LOOP_CONTROL = 8


class ControlMode(enum.IntEnum):
    VOLTAGE_CONTROL = 0
    TORQUE_CONTROL = 1
    VELOCITY_CONTROL = 2
    POSITION_CONTROL = 3


class InputMode(enum.IntEnum):
    INACTIVE = 0
    PASSTHROUGH = 1
    VEL_RAMP = 2


#: ODrive.Error bits (firmware 0.6.x) named in messages
AXIS_ERRORS = {
    0x1: "INITIALIZING", 0x2: "SYSTEM_LEVEL", 0x4: "TIMING_ERROR", 0x8: "MISSING_ESTIMATE",
    0x10: "BAD_CONFIG", 0x20: "DRV_FAULT", 0x40: "MISSING_INPUT", 0x100: "DC_BUS_OVER_VOLTAGE",
    0x200: "DC_BUS_UNDER_VOLTAGE", 0x400: "DC_BUS_OVER_CURRENT",
    0x800: "DC_BUS_OVER_REGEN_CURRENT", 0x1000: "CURRENT_LIMIT_VIOLATION",
    0x2000: "MOTOR_OVER_TEMP", 0x4000: "INVERTER_OVER_TEMP", 0x8000: "VELOCITY_LIMIT_VIOLATION",
    0x10000: "POSITION_LIMIT_VIOLATION", 0x1000000: "WATCHDOG_TIMER_EXPIRED",
    0x2000000: "ESTOP_REQUESTED", 0x4000000: "SPINOUT_DETECTED", 0x8000000: "BRAKE_RESISTOR_DISARMED",
    0x10000000: "THERMISTOR_DISCONNECTED", 0x40000000: "CALIBRATION_ERROR",
}

#: Axis.Error bits of firmware 0.5.x (the same bit means something else on 0.6)
AXIS_ERRORS_0_5 = {
    0x1: "INVALID_STATE", 0x40: "MOTOR_FAILED", 0x80: "SENSORLESS_ESTIMATOR_FAILED",
    0x100: "ENCODER_FAILED", 0x200: "CONTROLLER_FAILED", 0x800: "WATCHDOG_TIMER_EXPIRED",
    0x1000: "MIN_ENDSTOP_PRESSED", 0x2000: "MAX_ENDSTOP_PRESSED", 0x4000: "ESTOP_REQUESTED",
    0x20000: "HOMING_WITHOUT_ENDSTOP", 0x40000: "OVER_TEMP", 0x80000: "UNKNOWN_POSITION",
}

#: per firmware: the error bits the emulated axis raises for these conditions
WATCHDOG_TIMER_EXPIRED = {"0.5": 0x800, "0.6": 0x1000000}
ESTOP_REQUESTED = {"0.5": 0x4000, "0.6": 0x2000000}


#: the types of flat_endpoints.json -> struct format (those of ODrive's own
#: client, odrive/codecs.py of the odrive package 0.6.11)
ENDPOINT_TYPES = {"bool": "?", "uint8": "B", "int8": "b", "uint16": "H", "int16": "h",
                  "uint32": "I", "int32": "i", "uint64": "Q", "int64": "q", "float": "f"}
SDO_READ, SDO_WRITE = 0, 1


def error_names(bits: int, firmware: str = "0.6") -> str:
    """``0x20`` -> ``'DRV_FAULT'`` (names of ``firmware``'s axis error bits);
    unknown bits in hex."""
    table = AXIS_ERRORS_0_5 if firmware == "0.5" else AXIS_ERRORS
    names = [name for bit, name in table.items() if bits & bit]
    rest = bits & ~sum(table)
    if rest:
        names.append(f"0x{rest:X}")
    return "|".join(names) or "none"


def frame_id(node_id: int, cmd: int) -> int:
    if not 0 <= node_id <= MAX_NODE_ID:
        raise ValueError(f"ODrive node id {node_id} outside 0..{MAX_NODE_ID}")
    return (node_id << 5) | int(cmd)


def split_id(arbitration_id: int) -> tuple[int, int]:
    """Frame id -> (node_id, cmd_id)."""
    return arbitration_id >> 5, arbitration_id & 0x1F


# -- host -> axis ------------------------------------------------------------------
def set_axis_state(state: int) -> bytes:
    return struct.pack("<I", int(state))


def set_controller_mode(control_mode: int, input_mode: int) -> bytes:
    return struct.pack("<II", int(control_mode), int(input_mode))


def set_input_vel(vel_rev_per_s: float, torque_ff: float = 0.0) -> bytes:
    return struct.pack("<ff", vel_rev_per_s, torque_ff)


def set_input_torque(torque: float) -> bytes:
    return struct.pack("<f", torque)


def clear_errors(identify: bool = False, firmware: str = "0.6") -> bytes:
    """0.6.x: one byte, Identify (blink the LED); 0.5.x: no payload."""
    return b"" if firmware == "0.5" else struct.pack("<B", int(identify))


def sdo_request(opcode: int, endpoint_id: int, value: bytes = b"") -> bytes:
    """RxSdo payload: opcode (0 read, 1 write), endpoint id (uint16), a
    reserved byte, then the value (little endian, at most 4 bytes here)."""
    if len(value) > 4:
        raise ValueError(f"endpoint value of {len(value)} bytes (at most 4 in one frame)")
    return struct.pack("<BHB", int(opcode), int(endpoint_id), 0) + value


def encode_value(kind: str, value) -> bytes:
    """``value`` as an endpoint of type ``kind`` ("float", "bool", ...) sends it."""
    return struct.pack("<" + ENDPOINT_TYPES[kind], value)


def decode_value(kind: str, data: bytes):
    """The value of an endpoint of type ``kind`` from the first bytes of ``data``."""
    fmt = "<" + ENDPOINT_TYPES[kind]
    if len(data) < struct.calcsize(fmt):
        raise ValueError(f"{kind} endpoint value of {len(data)} bytes")
    return struct.unpack_from(fmt, data)[0]


@dataclass(frozen=True)
class SdoReply:
    """TxSdo: the endpoint id and the raw value bytes (decode with
    :func:`decode_value` and the endpoint's type)."""

    endpoint_id: int
    value: bytes

    def encode(self) -> bytes:
        return struct.pack("<BHB", 0, self.endpoint_id, 0) + self.value

    @classmethod
    def decode(cls, data: bytes) -> "SdoReply":
        if len(data) < 4:
            raise ValueError(f"TxSdo of {len(data)} bytes (at least 4 expected)")
        _, endpoint_id, _ = struct.unpack_from("<BHB", data)
        return cls(endpoint_id, bytes(data[4:]))


@dataclass(frozen=True)
class Version:
    """Get_Version (0.6.x): the board (hardware product line, version,
    variant: 4.4.58 is an ODrive Pro, 5.2.0 an S1, 6.x.0 a Micro) and the
    firmware (major.minor.revision; ``unreleased`` != 0 for a development
    build)."""

    protocol: int
    hw: tuple[int, int, int]
    fw: tuple[int, int, int]
    unreleased: int = 0

    @property
    def hw_text(self) -> str:
        return ".".join(map(str, self.hw))

    @property
    def fw_text(self) -> str:
        return ".".join(map(str, self.fw))

    def encode(self) -> bytes:
        return bytes((self.protocol, *self.hw, *self.fw, self.unreleased))

    @classmethod
    def decode(cls, data: bytes) -> "Version":
        if len(data) != 8:
            raise ValueError(f"version of {len(data)} bytes (8 expected)")
        return cls(data[0], tuple(data[1:4]), tuple(data[4:7]), data[7])


# -- axis -> host ----------------------------------------------------------------------
#: 0.5.x heartbeat flags: (name, bit of the 64-bit payload)
_FLAGS_0_5 = (("motor", 40), ("encoder", 48), ("controller", 56))


@dataclass(frozen=True)
class Heartbeat:
    """Cyclic status of one axis. ``procedure_result`` exists on 0.6.x only;
    ``error_flags`` on 0.5.x only: the names of the sub-objects (motor,
    encoder, controller) that report an error of their own."""

    axis_error: int
    axis_state: int
    procedure_result: int
    trajectory_done: bool
    error_flags: tuple[str, ...] = ()

    @property
    def faulted(self) -> bool:
        return bool(self.axis_error or self.error_flags)

    def describe(self, firmware: str = "0.6") -> str:
        """``0x40 (MOTOR_FAILED), motor error flag`` for messages."""
        text = f"0x{self.axis_error:X} ({error_names(self.axis_error, firmware)})"
        if self.error_flags:
            text += ", " + " ".join(self.error_flags) + " error flag"
        return text

    def encode(self, firmware: str = "0.6") -> bytes:
        if firmware == "0.5":
            bits = sum(1 << bit for name, bit in _FLAGS_0_5 if name in self.error_flags)
            bits |= int(self.trajectory_done) << 63
            return struct.pack("<IB", self.axis_error, self.axis_state) + \
                (bits >> 40).to_bytes(3, "little")
        return struct.pack("<IBBBx", self.axis_error, self.axis_state, self.procedure_result,
                           int(self.trajectory_done))

    @classmethod
    def decode(cls, data: bytes, firmware: str = "0.6") -> "Heartbeat":
        if len(data) < 7:
            raise ValueError(f"heartbeat of {len(data)} bytes (7 or 8 expected)")
        error, state = struct.unpack_from("<IB", data)
        if firmware == "0.5":
            bits = int.from_bytes(bytes(data[:8]).ljust(8, b"\0"), "little")
            flags = tuple(name for name, bit in _FLAGS_0_5 if bits >> bit & 1)
            return cls(error, state, 0, bool(bits >> 63 & 1), flags)
        result, done = data[5], data[6]
        return cls(error, state, result, bool(done & 1))


@dataclass(frozen=True)
class EncoderEstimates:
    position_rev: float
    velocity_rev_per_s: float

    def encode(self) -> bytes:
        return struct.pack("<ff", self.position_rev, self.velocity_rev_per_s)

    @classmethod
    def decode(cls, data: bytes) -> "EncoderEstimates":
        if len(data) != 8:
            raise ValueError(f"encoder estimates of {len(data)} bytes (8 expected)")
        pos, vel = struct.unpack("<ff", data)
        if not (math.isfinite(pos) and math.isfinite(vel)):
            raise ValueError(f"non-finite encoder estimates ({pos}, {vel})")
        return cls(pos, vel)


@dataclass(frozen=True)
class ErrorStatus:
    active_errors: int
    disarm_reason: int

    def encode(self) -> bytes:
        return struct.pack("<II", self.active_errors, self.disarm_reason)

    @classmethod
    def decode(cls, data: bytes) -> "ErrorStatus":
        if len(data) != 8:
            raise ValueError(f"error status of {len(data)} bytes (8 expected)")
        return cls(*struct.unpack("<II", data))
