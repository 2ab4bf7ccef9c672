"""ODrive CANSimple protocol (firmware 0.6): frame ids and payloads.

Every frame has an 11-bit id ``node_id << 5 | cmd_id`` and a little-endian
payload. Pure functions, no bus: the driver and the emulated ODrive both use
them, and the protocol tests check them byte for byte.

Only the messages this stack uses are here; see the ODrive documentation
("CAN Protocol") for the rest.
"""

from __future__ import annotations

import enum
import math
import struct
from dataclasses import dataclass

MAX_NODE_ID = 0x3F      # 6 bits of node id in an 11-bit frame id


class Cmd(enum.IntEnum):
    HEARTBEAT = 0x01             # axis -> host, cyclic
    ESTOP = 0x02
    GET_ERROR = 0x03             # axis -> host (RTR or cyclic): active_errors, disarm_reason
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


#: ODrive.Error bits (firmware 0.6) named in messages
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


def error_names(bits: int) -> str:
    """``0x20`` -> ``'DRV_FAULT'``; unknown bits in hex."""
    names = [name for bit, name in AXIS_ERRORS.items() if bits & bit]
    rest = bits & ~sum(AXIS_ERRORS)
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


def set_limits(vel_limit_rev_per_s: float, current_limit: float) -> bytes:
    return struct.pack("<ff", vel_limit_rev_per_s, current_limit)


def clear_errors(identify: bool = False) -> bytes:
    return struct.pack("<B", int(identify))


# -- axis -> host ----------------------------------------------------------------------
@dataclass(frozen=True)
class Heartbeat:
    axis_error: int
    axis_state: int
    procedure_result: int
    trajectory_done: bool

    def encode(self) -> bytes:
        return struct.pack("<IBBBx", self.axis_error, self.axis_state, self.procedure_result,
                           int(self.trajectory_done))

    @classmethod
    def decode(cls, data: bytes) -> "Heartbeat":
        if len(data) < 7:
            raise ValueError(f"heartbeat of {len(data)} bytes (7 or 8 expected)")
        error, state, result, done = struct.unpack_from("<IBBB", data)
        return cls(error, state, result, bool(done))


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
