"""CANopen (CiA 301) and drive profile CiA 402: ids, objects, state machine.

Pure definitions and codecs shared by the ``cia402`` driver and the emulated
drive; the protocol tests check them byte for byte.
"""

from __future__ import annotations

import enum
import struct

# -- CiA 301 communication objects (COB-IDs for the predefined connection set) --
NMT = 0x000
SYNC = 0x080
EMCY = 0x080        # + node id
TPDO = (0x180, 0x280, 0x380, 0x480)   # + node id
RPDO = (0x200, 0x300, 0x400, 0x500)   # + node id
SDO_TX = 0x580      # server -> client, + node id
SDO_RX = 0x600      # client -> server, + node id
HEARTBEAT = 0x700   # + node id
# PDO COB-ID entries (0x1400.., 0x1800.. sub 1), CiA 301:
PDO_INVALID = 0x80000000              # COB-ID bit 31: PDO not valid
PDO_NO_RTR = 0x40000000               # bit 30: no remote frame (RTR) allowed on this PDO
PDO_EXTENDED = 0x20000000             # bit 29: 29-bit identifier (0: 11-bit)
PDO_ID_11 = 0x7FF                     # bits 0..10: the 11-bit CAN identifier


class NmtCommand(enum.IntEnum):
    START = 0x01
    STOP = 0x02
    ENTER_PRE_OPERATIONAL = 0x80
    RESET_NODE = 0x81
    RESET_COMMUNICATION = 0x82


class NmtState(enum.IntEnum):
    """State byte of a heartbeat."""

    BOOT_UP = 0x00
    STOPPED = 0x04
    OPERATIONAL = 0x05
    PRE_OPERATIONAL = 0x7F


# -- objects -----------------------------------------------------------------------------
DEVICE_TYPE = 0x1000            # u32, low 16 bits = profile number (402)
ERROR_REGISTER = 0x1001
GUARD_TIME = 0x100C              # u16 [ms], node guarding
LIFE_TIME_FACTOR = 0x100D        # u8: life time = guard time x factor
CONSUMER_HEARTBEAT_TIME = 0x1016  # sub 1: u32 = master node id << 16 | time [ms]
PRODUCER_HEARTBEAT_TIME = 0x1017  # u16 [ms]
RPDO_COMM = 0x1400              # + n - 1; sub 1 COB-ID, sub 2 transmission type
RPDO_MAP = 0x1600
TPDO_COMM = 0x1800
TPDO_MAP = 0x1A00
ERROR_CODE = 0x603F             # u16
CONTROLWORD = 0x6040            # u16
STATUSWORD = 0x6041             # u16
ABORT_CONNECTION_OPTION = 0x6007    # i16: what the drive does on a lost connection
QUICK_STOP_OPTION = 0x605A      # i16
MODES_OF_OPERATION = 0x6060     # i8
MODES_DISPLAY = 0x6061          # i8
POSITION_ACTUAL = 0x6064        # i32 [position units]
VELOCITY_ACTUAL = 0x606C        # i32 [velocity units]
TARGET_VELOCITY = 0x60FF        # i32 [velocity units]
TARGET_TORQUE = 0x6071          # i16 [per mille of the motor rated torque]
MOTOR_RATED_TORQUE = 0x6076     # u32 [mN m]
SI_UNIT_VELOCITY = 0x60A9       # u32, CiA 402 unit code of 0x606C/0x60FF
GEAR_RATIO = 0x6091             # sub 1 motor revs, sub 2 shaft revs
FEED_CONSTANT = 0x6092          # sub 1 feed, sub 2 shaft revs
SUPPORTED_MODES = 0x6502        # u32 bit field

PROFILE_402 = 402


class OpMode(enum.IntEnum):
    PROFILE_VELOCITY = 3
    CYCLIC_SYNCHRONOUS_VELOCITY = 9
    CYCLIC_SYNCHRONOUS_TORQUE = 10


class Control(enum.IntEnum):
    """Controlword commands (CiA 402 Table 'device control commands')."""

    DISABLE_VOLTAGE = 0x0000
    QUICK_STOP = 0x0002
    SHUTDOWN = 0x0006
    SWITCH_ON = 0x0007          # also "disable operation" from OPERATION ENABLED
    ENABLE_OPERATION = 0x000F
    FAULT_RESET = 0x0080        # acts on the rising edge of bit 7


class State(enum.Enum):
    NOT_READY_TO_SWITCH_ON = "NOT READY TO SWITCH ON"
    SWITCH_ON_DISABLED = "SWITCH ON DISABLED"
    READY_TO_SWITCH_ON = "READY TO SWITCH ON"
    SWITCHED_ON = "SWITCHED ON"
    OPERATION_ENABLED = "OPERATION ENABLED"
    QUICK_STOP_ACTIVE = "QUICK STOP ACTIVE"
    FAULT_REACTION_ACTIVE = "FAULT REACTION ACTIVE"
    FAULT = "FAULT"


#: (mask, value) of the statusword for each state, and the bits a drive reports
_STATUS = {
    State.NOT_READY_TO_SWITCH_ON: (0x4F, 0x00),
    State.SWITCH_ON_DISABLED: (0x4F, 0x40),
    State.READY_TO_SWITCH_ON: (0x6F, 0x21),
    State.SWITCHED_ON: (0x6F, 0x23),
    State.OPERATION_ENABLED: (0x6F, 0x27),
    State.QUICK_STOP_ACTIVE: (0x6F, 0x07),
    State.FAULT_REACTION_ACTIVE: (0x4F, 0x0F),
    State.FAULT: (0x4F, 0x08),
}
STATUS_FAULT_BIT = 0x0008
STATUS_VOLTAGE_ENABLED = 0x0010
STATUS_REMOTE = 0x0200


def state_of(statusword: int) -> State:
    for state, (mask, value) in _STATUS.items():
        if statusword & mask == value:
            return state
    return State.NOT_READY_TO_SWITCH_ON


def statusword_of(state: State, voltage: bool = True) -> int:
    """The statusword a drive reports in ``state`` (quick-stop bit 5 set when
    not quick-stopping, remote bit 9 set: the drive obeys the bus)."""
    mask, value = _STATUS[state]
    word = value | STATUS_REMOTE
    if state in (State.READY_TO_SWITCH_ON, State.SWITCHED_ON, State.OPERATION_ENABLED):
        word |= 0x0020
    if voltage and state is not State.SWITCH_ON_DISABLED:
        word |= STATUS_VOLTAGE_ENABLED
    return word


def next_state(state: State, controlword: int, previous_controlword: int) -> State:
    """The 402 power state machine's transition on a new controlword.

    Fault reset (bit 7 rising) is left to the caller: only the drive knows
    whether the fault condition is gone.
    """
    cmd_shutdown = controlword & 0x87 == 0x06
    cmd_switch_on = controlword & 0x8F == 0x07
    cmd_enable = controlword & 0x8F == 0x0F
    cmd_disable_voltage = controlword & 0x82 == 0x00
    cmd_quick_stop = controlword & 0x86 == 0x02
    if state is State.SWITCH_ON_DISABLED and cmd_shutdown:
        return State.READY_TO_SWITCH_ON
    if state is State.READY_TO_SWITCH_ON:
        if cmd_switch_on:
            return State.SWITCHED_ON
        if cmd_disable_voltage or cmd_quick_stop:
            return State.SWITCH_ON_DISABLED
    if state is State.SWITCHED_ON:
        if cmd_enable:
            return State.OPERATION_ENABLED
        if cmd_shutdown:
            return State.READY_TO_SWITCH_ON
        if cmd_disable_voltage or cmd_quick_stop:
            return State.SWITCH_ON_DISABLED
    if state is State.OPERATION_ENABLED:
        if cmd_switch_on:
            return State.SWITCHED_ON
        if cmd_shutdown:
            return State.READY_TO_SWITCH_ON
        if cmd_quick_stop:
            return State.QUICK_STOP_ACTIVE
        if cmd_disable_voltage:
            return State.SWITCH_ON_DISABLED
    if state is State.QUICK_STOP_ACTIVE and cmd_disable_voltage:
        return State.SWITCH_ON_DISABLED
    return state


# -- SDO (expedited transfers: every object used here fits in 4 bytes) ----------------------
SDO_ABORT = 0x80
ABORT_NO_OBJECT = 0x06020000
ABORT_NO_SUBINDEX = 0x06090011
ABORT_READ_ONLY = 0x06010002
ABORT_RANGE = 0x06090030
ABORT_STATE = 0x08000022
ABORT_UNSUPPORTED = 0x05040001   # command specifier not valid


class AbortConnection(enum.IntEnum):
    """CiA 402 0x6007, the abort connection option code: what the drive does
    when it detects a lost connection (heartbeat consumer or life guarding
    expired, bus-off, NMT left OPERATIONAL). Negative values are the maker's."""

    NO_ACTION = 0
    FAULT = 1               # fault signal: the fault reaction (0x605E), then FAULT
    DISABLE_VOLTAGE = 2     # power stage off: the motor coasts
    QUICK_STOP = 3          # quick stop (0x605A, 0x6085), then as 0x605A says


#: CiA 301 SDO abort codes, for messages that name the refusal
SDO_ABORT_CODES = {
    0x05030000: "toggle bit not alternated",
    0x05040000: "SDO protocol timed out",
    0x05040001: "command specifier not valid or unknown",
    0x06010000: "unsupported access to an object",
    0x06010001: "attempt to read a write-only object",
    0x06010002: "attempt to write a read-only object",
    0x06020000: "object does not exist in the object dictionary",
    0x06040041: "object cannot be mapped to the PDO",
    0x06040042: "the objects would exceed the PDO length",
    0x06040043: "general parameter incompatibility",
    0x06040047: "general internal incompatibility in the device",
    0x06060000: "access failed due to a hardware error",
    0x06070010: "data type does not match, length of service parameter does not match",
    0x06090011: "sub-index does not exist",
    0x06090030: "value range of parameter exceeded",
    0x06090031: "value of parameter written too high",
    0x06090032: "value of parameter written too low",
    0x08000000: "general error",
    0x08000020: "data cannot be transferred or stored to the application",
    0x08000021: "data cannot be transferred or stored because of local control",
    0x08000022: "data cannot be transferred or stored in the present device state",
    0x060A0023: "resource not available: SDO connection",
}


def sdo_abort_text(code: int) -> str:
    """``0x06020000 (object does not exist in the object dictionary)``."""
    meaning = SDO_ABORT_CODES.get(code)
    return f"0x{code:08X}" + (f" ({meaning})" if meaning else "")


def sdo_download_request(index: int, subindex: int, data: bytes) -> bytes:
    """Initiate expedited download (client -> server) of 1..4 bytes."""
    n = len(data)
    if not 1 <= n <= 4:
        raise ValueError("expedited SDO carries 1..4 bytes")
    command = 0x23 | ((4 - n) << 2)
    return struct.pack("<BHB", command, index, subindex) + data.ljust(4, b"\0")


def sdo_upload_request(index: int, subindex: int) -> bytes:
    return struct.pack("<BHB4x", 0x40, index, subindex)


def sdo_download_response(index: int, subindex: int) -> bytes:
    return struct.pack("<BHB4x", 0x60, index, subindex)


def sdo_upload_response(index: int, subindex: int, data: bytes) -> bytes:
    """Expedited upload response with the size indicated."""
    n = len(data)
    return struct.pack("<BHB", 0x43 | ((4 - n) << 2), index, subindex) + data.ljust(4, b"\0")


def sdo_abort(index: int, subindex: int, code: int) -> bytes:
    return struct.pack("<BHBI", SDO_ABORT, index, subindex, code)


def pdo_map_entry(index: int, subindex: int, bits: int) -> int:
    """A PDO mapping entry: index << 16 | subindex << 8 | length in bits."""
    return (index << 16) | (subindex << 8) | bits


def emcy(error_code: int, error_register: int = 0x01, vendor: bytes = b"") -> bytes:
    return struct.pack("<HB", error_code, error_register) + vendor.ljust(5, b"\0")[:5]
