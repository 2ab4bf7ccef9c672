"""The CAN protocols byte for byte: ODrive CANSimple and CANopen CiA 402.

Codecs against hand-assembled frames, then what the drivers really put on
the bus (sniffed on the rig's bus) against scripted frame sequences.
Little-endian IEEE 754: 1.0 = 0x3F800000, 0.5 = 0x3F000000, -2.5 = 0xC0200000,
0.25 = 0x3E800000.
"""

import math
import struct
import time

import can
import pytest

from holonomic_testing.can_rig import CanRig
from holonomic_drivers import cia402_protocol as co
from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers.cia402 import pdo_configuration
from holonomic_drivers.cia402_protocol import Control, State

H = bytes.fromhex


# -- ODrive CANSimple ----------------------------------------------------------------------
def test_odrive_frame_ids_pack_node_and_command():
    assert proto.frame_id(1, proto.Cmd.SET_INPUT_VEL) == 0x02D        # 1 << 5 | 0x0D
    assert proto.frame_id(0x3F, proto.Cmd.CLEAR_ERRORS) == 0x7F8      # 63 << 5 | 0x18
    assert proto.split_id(0x7F8) == (0x3F, 0x18)
    with pytest.raises(ValueError, match="outside 0..63"):
        proto.frame_id(64, proto.Cmd.HEARTBEAT)


def test_odrive_ids_and_enumerations_are_the_firmwares():
    """Written from the ODrive CAN protocol documentation (firmware 0.6; the
    same values in the independent odrive-messages crate), not from our enums."""
    ids = {"GET_VERSION": 0x00, "RX_SDO": 0x04, "TX_SDO": 0x05, "HEARTBEAT": 0x01, "ESTOP": 0x02, "GET_ERROR": 0x03, "SET_AXIS_STATE": 0x07,
           "GET_ENCODER_ESTIMATES": 0x09, "SET_CONTROLLER_MODE": 0x0B, "SET_INPUT_VEL": 0x0D,
           "SET_INPUT_TORQUE": 0x0E, "SET_LIMITS": 0x0F, "REBOOT": 0x16, "CLEAR_ERRORS": 0x18}
    assert {c.name: c.value for c in proto.Cmd} == ids
    assert {s.name: s.value for s in proto.AxisState} == {
        "UNDEFINED": 0, "IDLE": 1, "STARTUP_SEQUENCE": 2, "FULL_CALIBRATION_SEQUENCE": 3,
        "MOTOR_CALIBRATION": 4, "ENCODER_INDEX_SEARCH": 6, "ENCODER_OFFSET_CALIBRATION": 7,
        "CLOSED_LOOP_CONTROL": 8}
    assert {m.name: m.value for m in proto.ControlMode} == {
        "VOLTAGE_CONTROL": 0, "TORQUE_CONTROL": 1, "VELOCITY_CONTROL": 2, "POSITION_CONTROL": 3}
    assert {m.name: m.value for m in proto.InputMode} == {
        "INACTIVE": 0, "PASSTHROUGH": 1, "VEL_RAMP": 2}
    assert proto.MAX_NODE_ID == 63                      # 6 bits above the 5-bit command
    # firmware 0.6 reserves node id 0x3F for broadcast and discovery (ODrive's
    # CAN protocol docs), so an axis there gets at most 62; 0.5 allows all 6 bits
    assert proto.BROADCAST_NODE_ID == 0x3F
    assert proto.max_node_id("0.5") == 63 and proto.max_node_id("0.6") == 62
    assert proto.error_names(0x1000000 | 0x2000000) == "WATCHDOG_TIMER_EXPIRED|ESTOP_REQUESTED"
    assert proto.error_names(0x4 | 0x8) == "TIMING_ERROR|MISSING_ESTIMATE"
    assert proto.error_names(0x1 | 0x2) == "INITIALIZING|SYSTEM_LEVEL"
    assert proto.error_names(0) == "none"
    # firmware 0.5's Axis.Error bits (its axis.hpp): the same bits name
    # other errors on 0.6
    for bit, name in ((0x1, "INVALID_STATE"), (0x40, "MOTOR_FAILED"),
                      (0x80, "SENSORLESS_ESTIMATOR_FAILED"), (0x100, "ENCODER_FAILED"),
                      (0x200, "CONTROLLER_FAILED"), (0x800, "WATCHDOG_TIMER_EXPIRED"),
                      (0x1000, "MIN_ENDSTOP_PRESSED"), (0x2000, "MAX_ENDSTOP_PRESSED"),
                      (0x4000, "ESTOP_REQUESTED"), (0x20000, "HOMING_WITHOUT_ENDSTOP"),
                      (0x40000, "OVER_TEMP"), (0x80000, "UNKNOWN_POSITION")):
        assert proto.error_names(bit, "0.5") == name
    # the bits the emulated axis raises are these names on each firmware
    for firmware in proto.FIRMWARES:
        assert proto.error_names(proto.WATCHDOG_TIMER_EXPIRED[firmware], firmware) == \
            "WATCHDOG_TIMER_EXPIRED"
        assert proto.error_names(proto.ESTOP_REQUESTED[firmware], firmware) == "ESTOP_REQUESTED"


def test_odrive_host_commands_are_encoded_byte_for_byte():
    assert proto.set_input_vel(-2.5, 0.25) == H("00 00 20 c0 00 00 80 3e")
    assert proto.set_axis_state(proto.AxisState.CLOSED_LOOP_CONTROL) == H("08 00 00 00")
    assert proto.set_controller_mode(proto.ControlMode.VELOCITY_CONTROL,
                                     proto.InputMode.PASSTHROUGH) == H("02000000 01000000")
    assert proto.set_input_torque(1.0) == H("00 00 80 3f")
    assert proto.clear_errors() == H("00")


def test_odrive_axis_messages_are_decoded_and_bad_ones_refused():
    hb = proto.Heartbeat.decode(H("01 00 00 80 08 00 01 00"))
    assert (hb.axis_error, hb.axis_state, hb.trajectory_done) == (0x80000001, 8, True)
    assert proto.Heartbeat(0x20, 1, 0, False).encode() == H("20 00 00 00 01 00 00 00")
    est = proto.EncoderEstimates.decode(H("00 00 c0 3f 00 00 00 bf"))     # 1.5, -0.5
    assert (est.position_rev, est.velocity_rev_per_s) == (1.5, -0.5)
    with pytest.raises(ValueError, match="8 expected"):
        proto.EncoderEstimates.decode(H("00 00 c0 3f"))
    with pytest.raises(ValueError, match="non-finite"):
        proto.EncoderEstimates.decode(struct.pack("<ff", math.nan, 0.0))
    with pytest.raises(ValueError, match="7 or 8"):
        proto.Heartbeat.decode(H("00 00"))
    assert proto.error_names(0x20 | 0x1000) == "DRV_FAULT|CURRENT_LIMIT_VIOLATION"
    assert proto.error_names(0x80) == "0x80"


def _frames_to(frames, nodes):
    """(id, data) of the frames addressed to the given ODrive nodes, in order."""
    return [(m.arbitration_id, bytes(m.data)) for m in frames
            if proto.split_id(m.arbitration_id)[0] in nodes
            and proto.split_id(m.arbitration_id)[1] not in (proto.Cmd.HEARTBEAT,
                                                            proto.Cmd.GET_ENCODER_ESTIMATES)]


def test_odrive_driver_sends_the_scripted_frames():
    """configure -> velocity mode and idle; activate -> clear errors, closed
    loop; write -> one Set_Input_Vel per axis in motor rev/s through gear and
    direction; deactivate -> zero velocity and torque, and IDLE. HAMR wiring of
    config/hamr.yaml: nodes 0, 1 (direction -1), 2 (gear 10)."""
    rig = CanRig("odrive_can", "hamr")
    try:
        rig.configure_driver()
        configure = _frames_to(rig.sniff(), {0, 1, 2})
        expected = []
        for n in (0, 1, 2):
            expected += [(n << 5 | 0x0B, H("02000000 01000000")),
                         (n << 5 | 0x0D, H("00000000 00000000")),
                         (n << 5 | 0x07, H("01 00 00 00"))]
        assert configure == expected
        mark = len(rig.sniff())
        rig.driver.activate()
        expected = []
        for n in (0, 1, 2):
            expected += [(n << 5 | 0x18, H("00")), (n << 5 | 0x0B, H("02000000 01000000")),
                         (n << 5 | 0x0D, H("00000000 00000000")), (n << 5 | 0x07, H("08000000"))]
        armed = _frames_to(rig.sniff()[mark:], {0, 1, 2})
        assert armed[:12] == expected
        # until the heartbeats confirm closed loop: zero velocity to each axis
        # every 20 ms (it feeds the axis watchdogs)
        assert set(armed[12:]) <= {(n << 5 | 0x0D, bytes(8)) for n in (0, 1, 2)}

        mark = len(rig.sniff())
        # joint rad/s: left 2 pi -> 1 rev/s; right -pi, direction -1 -> +0.5 rev/s;
        # turret 0.2 pi, gear 10 -> 1 rev/s
        rig.driver.write_velocities([2 * math.pi, -math.pi, 0.2 * math.pi])
        assert _frames_to(rig.sniff()[mark:], {0, 1, 2}) == [
            (0x00D, H("0000803f 00000000")), (0x02D, H("0000003f 00000000")),
            (0x04D, H("0000803f 00000000"))]

        mark = len(rig.sniff())
        rig.driver.deactivate()
        # zero velocity, zero torque (the axis may be in torque mode), IDLE
        assert _frames_to(rig.sniff()[mark:], {0, 1, 2}) == [
            (0x00D, bytes(8)), (0x00E, bytes(4)), (0x007, H("01000000")),
            (0x02D, bytes(8)), (0x02E, bytes(4)), (0x027, H("01000000")),
            (0x04D, bytes(8)), (0x04E, bytes(4)), (0x047, H("01000000"))]
    finally:
        rig.close()


def test_odrive_driver_decodes_scripted_encoder_frames():
    """Frames written by hand: positions in rev -> joint rad through the mapping."""
    rig = CanRig("odrive_can", "hamr")
    try:
        rig.configure_driver()
        rig.emulators.stop()          # from here on only the script talks
        script = rig.open_bus()

        def send(estimates):
            for node, (pos, vel) in enumerate(estimates):
                script.send(can.Message(arbitration_id=node << 5 | 0x01, is_extended_id=False,
                                        data=H("00000000 01 00 00 00")))
                script.send(can.Message(arbitration_id=node << 5 | 0x09, is_extended_id=False,
                                        data=struct.pack("<ff", pos, vel)))
            script.barrier()          # they are in the driver's receive buffer

        send([(1.0, 0.0), (1.0, 0.0), (10.0, 0.0)])
        reading = rig.driver.read()
        # left: 1 rev = 2 pi; right: direction -1; turret: 10 rev / gear 10 = 2 pi
        assert reading.positions == pytest.approx([2 * math.pi, -2 * math.pi, 2 * math.pi])
        t_before = time.time()
        send([(1.0, 0.5), (1.0, 0.5), (10.0, -2.5)])
        reading = rig.driver.read()
        elapsed = time.time() - t_before
        assert reading.velocities == pytest.approx([math.pi, -math.pi, -0.5 * math.pi])
        # positions are brought to the read's instant with each axis's speed:
        # estimate + speed x (read - send), that time within (0, elapsed]
        # (the frames crossed the rig's hub and back, > 0.05 ms; ~1 ms idle,
        # 22 ms measured with two busy loops at load 16, which the former
        # fixed 0.05 rad did not allow at pi rad/s)
        for position, estimate, speed in zip(reading.positions,
                                             [2 * math.pi, -2 * math.pi, 2 * math.pi],
                                             reading.velocities):
            moved = position - estimate
            assert moved * speed > 0 and abs(moved) <= abs(speed) * elapsed + 1e-9, \
                (position, estimate, speed, elapsed)
        script.shutdown()
    finally:
        rig.close()


# -- CANopen / CiA 402 --------------------------------------------------------------------------
def test_canopen_identifiers_and_indices_are_the_standards():
    """Written from CiA 301 (pre-defined connection set, NMT, object
    dictionary) and CiA 402 (drive profile objects), not from our module:
    the driver and the emulated drive share those constants, so a wrong one
    would go unnoticed between them."""
    assert (co.NMT, co.SYNC, co.EMCY, co.SDO_TX, co.SDO_RX, co.HEARTBEAT) == (
        0x000, 0x080, 0x080, 0x580, 0x600, 0x700)
    assert co.TPDO == (0x180, 0x280, 0x380, 0x480) and co.RPDO == (0x200, 0x300, 0x400, 0x500)
    assert co.PDO_INVALID == 1 << 31
    assert {c.name: c.value for c in co.NmtCommand} == {
        "START": 0x01, "STOP": 0x02, "ENTER_PRE_OPERATIONAL": 0x80, "RESET_NODE": 0x81,
        "RESET_COMMUNICATION": 0x82}
    assert {s.name: s.value for s in co.NmtState} == {
        "BOOT_UP": 0x00, "STOPPED": 0x04, "OPERATIONAL": 0x05, "PRE_OPERATIONAL": 0x7F}
    assert (co.DEVICE_TYPE, co.ERROR_REGISTER, co.CONSUMER_HEARTBEAT_TIME,
            co.PRODUCER_HEARTBEAT_TIME) == (0x1000, 0x1001, 0x1016, 0x1017)
    # SDO abort codes (CiA 301): object / sub-index does not exist, write to a
    # read-only object, value range exceeded, not in the present device
    # state, command specifier not valid
    assert (co.ABORT_NO_OBJECT, co.ABORT_NO_SUBINDEX, co.ABORT_READ_ONLY, co.ABORT_RANGE,
            co.ABORT_STATE, co.ABORT_UNSUPPORTED) == (
        0x06020000, 0x06090011, 0x06010002, 0x06090030, 0x08000022, 0x05040001)
    # node guarding (CiA 301): guard time and life time factor
    assert (co.GUARD_TIME, co.LIFE_TIME_FACTOR) == (0x100C, 0x100D)
    # CiA 402 factor group: SI unit of velocity, gear ratio, feed constant
    assert (co.SI_UNIT_VELOCITY, co.GEAR_RATIO, co.FEED_CONSTANT) == (0x60A9, 0x6091, 0x6092)
    assert (co.RPDO_COMM, co.RPDO_MAP, co.TPDO_COMM, co.TPDO_MAP) == (0x1400, 0x1600, 0x1800,
                                                                      0x1A00)
    assert (co.ERROR_CODE, co.CONTROLWORD, co.STATUSWORD, co.QUICK_STOP_OPTION,
            co.MODES_OF_OPERATION, co.MODES_DISPLAY, co.POSITION_ACTUAL, co.VELOCITY_ACTUAL,
            co.TARGET_VELOCITY, co.TARGET_TORQUE, co.MOTOR_RATED_TORQUE, co.SUPPORTED_MODES) == (
        0x603F, 0x6040, 0x6041, 0x605A, 0x6060, 0x6061, 0x6064, 0x606C, 0x60FF, 0x6071, 0x6076,
        0x6502)
    assert co.PROFILE_402 == 402
    assert {m.name: m.value for m in co.OpMode} == {
        "PROFILE_VELOCITY": 3, "CYCLIC_SYNCHRONOUS_VELOCITY": 9, "CYCLIC_SYNCHRONOUS_TORQUE": 10}
    # CiA 402 device control commands (controlword bits 0-3 and 7)
    assert {c.name: c.value for c in co.Control} == {
        "DISABLE_VOLTAGE": 0x0000, "QUICK_STOP": 0x0002, "SHUTDOWN": 0x0006,
        "SWITCH_ON": 0x0007, "ENABLE_OPERATION": 0x000F, "FAULT_RESET": 0x0080}
    # the power states by their CiA 402 names (shown in the driver's messages)
    assert [s.value for s in co.State] == [
        "NOT READY TO SWITCH ON", "SWITCH ON DISABLED", "READY TO SWITCH ON", "SWITCHED ON",
        "OPERATION ENABLED", "QUICK STOP ACTIVE", "FAULT REACTION ACTIVE", "FAULT"]


def test_sdo_expedited_frames_byte_for_byte():
    assert co.sdo_download_request(0x6060, 0, H("09")) == H("2f 60 60 00 09 00 00 00")
    assert co.sdo_download_request(0x1017, 0, struct.pack("<H", 50)) == H("2b 17 10 00 32 00 00 00")
    assert co.sdo_download_request(0x1600, 1, struct.pack("<I", 0x60400010)) == \
        H("23 00 16 01 10 00 40 60")
    assert co.sdo_upload_request(0x6041, 0) == H("40 41 60 00 00 00 00 00")
    assert co.sdo_upload_response(0x6041, 0, H("37 02")) == H("4b 41 60 00 37 02 00 00")
    assert co.sdo_download_response(0x6040, 0) == H("60 40 60 00 00 00 00 00")
    assert co.sdo_abort(0x6060, 0, co.ABORT_RANGE) == H("80 60 60 00 30 00 09 06")
    assert co.emcy(0x2310) == H("10 23 01 00 00 00 00 00")
    # an EMCY frame is 8 bytes: the vendor field is cut to its 5
    assert co.emcy(0x2310, 0x01, bytes(range(1, 7))) == H("10 23 01 01 02 03 04 05")
    assert co.pdo_map_entry(0x60FF, 0, 32) == 0x60FF0020
    # index (16 bits), sub-index (8 bits), length in bits (8 bits), CiA 301
    assert co.pdo_map_entry(0x2000, 3, 8) == 0x20000308
    # an expedited transfer carries 1 to 4 bytes: more needs a segmented one
    with pytest.raises(ValueError, match="1..4 bytes"):
        co.sdo_download_request(0x2000, 0, bytes(5))


def test_statusword_decoding_and_power_state_machine():
    assert co.statusword_of(State.OPERATION_ENABLED) == 0x0237
    assert co.statusword_of(State.FAULT) == 0x0218
    assert co.state_of(0x0637) is State.OPERATION_ENABLED      # + target reached (bit 10)
    assert co.state_of(0x0250) is State.SWITCH_ON_DISABLED
    assert co.state_of(0x0231) is State.READY_TO_SWITCH_ON
    assert co.state_of(0x0233) is State.SWITCHED_ON
    assert co.state_of(0x0217) is State.QUICK_STOP_ACTIVE
    assert co.state_of(0x021F) is State.FAULT_REACTION_ACTIVE
    assert co.state_of(0x0218) is State.FAULT
    # statusword bits (CiA 402): 3 fault, 4 voltage enabled, 9 remote
    assert (co.STATUS_FAULT_BIT, co.STATUS_VOLTAGE_ENABLED, co.STATUS_REMOTE) == (
        0x0008, 0x0010, 0x0200)
    # bit 4 (voltage enabled) is not part of any state's pattern: each state
    # reads back from the word a drive reports in it, with or without voltage
    # (READY TO SWITCH ON without voltage: 0x21 with the remote bit 9)
    assert co.statusword_of(State.READY_TO_SWITCH_ON, voltage=False) == 0x0221
    for state in State:
        for voltage in (True, False):
            assert co.state_of(co.statusword_of(state, voltage)) is state, (state, voltage)
    state = State.SWITCH_ON_DISABLED
    for word, expected in ((Control.SHUTDOWN, State.READY_TO_SWITCH_ON),
                           (Control.SWITCH_ON, State.SWITCHED_ON),
                           (Control.ENABLE_OPERATION, State.OPERATION_ENABLED),
                           (Control.SWITCH_ON, State.SWITCHED_ON),          # disable operation
                           (Control.ENABLE_OPERATION, State.OPERATION_ENABLED),
                           (Control.QUICK_STOP, State.QUICK_STOP_ACTIVE),
                           (Control.DISABLE_VOLTAGE, State.SWITCH_ON_DISABLED)):
        state = co.next_state(state, word, 0)
        assert state is expected
    # the commands are bit patterns with don't-care bits (CiA 402 device control
    # commands): quick stop is bit 2 = 0, bit 1 = 1, bit 7 = 0, whatever bit 0
    # says (0x0003); disable voltage is bit 1 = 0, bit 7 = 0, whatever bits 0
    # and 2 say (0x0001, 0x0005)
    assert co.next_state(State.OPERATION_ENABLED, 0x0003, 0) is State.QUICK_STOP_ACTIVE
    assert co.next_state(State.QUICK_STOP_ACTIVE, 0x0001, 0) is State.SWITCH_ON_DISABLED
    assert co.next_state(State.OPERATION_ENABLED, 0x0005, 0) is State.SWITCH_ON_DISABLED
    # disable voltage or quick stop from the two "voltage enabled, not
    # operating" states ends in SWITCH ON DISABLED
    assert co.next_state(State.READY_TO_SWITCH_ON, Control.DISABLE_VOLTAGE, 0) \
        is State.SWITCH_ON_DISABLED
    assert co.next_state(State.SWITCHED_ON, Control.QUICK_STOP, 0) is State.SWITCH_ON_DISABLED
    # a drive in FAULT leaves it only by a fault reset, which the caller
    # handles: a disable-voltage word (0x0000) keeps it in FAULT
    assert co.next_state(State.FAULT, 0x0000, 0) is State.FAULT
    # enable operation is not a legal jump out of SWITCH ON DISABLED
    assert co.next_state(State.SWITCH_ON_DISABLED, Control.ENABLE_OPERATION, 0) \
        is State.SWITCH_ON_DISABLED


def test_pdo_configuration_follows_cia301_order():
    writes = pdo_configuration(5)
    # RPDO1: invalidate, transmission type 1, count 0, entries, count 2, validate
    assert writes[:6] == [
        (0x1400, 1, struct.pack("<I", 0x80000205)), (0x1400, 2, H("01")), (0x1600, 0, H("00")),
        (0x1600, 1, struct.pack("<I", 0x60400010)), (0x1600, 2, struct.pack("<I", 0x60FF0020)),
        (0x1600, 0, H("02"))]
    assert writes[6] == (0x1400, 1, struct.pack("<I", 0x205))
    # RPDO2: controlword, target torque (16 bits), mode of operation (8 bits)
    assert writes[7:14] == [
        (0x1401, 1, struct.pack("<I", 0x80000305)), (0x1401, 2, H("01")), (0x1601, 0, H("00")),
        (0x1601, 1, struct.pack("<I", 0x60400010)), (0x1601, 2, struct.pack("<I", 0x60710010)),
        (0x1601, 3, struct.pack("<I", 0x60600008)), (0x1601, 0, H("03"))]
    assert (0x1A00, 1, struct.pack("<I", 0x60640020)) in writes
    assert (0x1A01, 2, struct.pack("<I", 0x603F0010)) in writes
    assert writes[-1] == (0x1803, 1, struct.pack("<I", 0x80000485))   # TPDO4 invalid


def _sdo_requests(frames, node):
    return [bytes(m.data) for m in frames if m.arbitration_id == 0x600 + node]


def test_cia402_driver_sends_the_scripted_frames():
    """configure: NMT pre-operational, device type, heartbeat producer and
    consumer, mode csv, target 0, the PDO mapping, mode check, supported
    modes and rated torque (torque mode), NMT start;
    write: RPDO1 = enable operation + counts/s; deactivate: disable
    operation with target 0, then SYNC. HAMR wiring of config/hamr.yaml:
    nodes 1, 2 (direction -1), 3 (gear 10), 16384 counts/rev."""
    rig = CanRig("cia402", "hamr")
    try:
        rig.configure_driver()
        frames = rig.sniff()
        nmt = [bytes(m.data) for m in frames if m.arbitration_id == 0]
        assert nmt == [H("80 01"), H("80 02"), H("80 03"), H("01 01"), H("01 02"), H("01 03")]
        # Written by hand from CiA 301 (not with the codec under test): an
        # expedited SDO download is 0x23 / 0x2B / 0x2F for 4 / 2 / 1 data
        # bytes (ccs 1, e = s = 1, n = 4 - size), then index (LE), subindex,
        # data padded to 4; an upload request is 0x40, index, subindex, 0s.
        # PDO set-up per PDO: COB-ID with bit 31 (invalid), transmission
        # type 1 (every SYNC), mapping count 0, entries (index << 16 |
        # subindex << 8 | bits), count, COB-ID valid. Node 2: RPDO1 0x202,
        # RPDO2 0x302, TPDO1 0x182, TPDO2 0x282.
        expected = [H(x) for x in (
            "40 00 10 00 00 00 00 00",      # read 0x1000 device type
            "2b 17 10 00 32 00 00 00",      # 0x1017 producer heartbeat 50 ms
            "23 16 10 01 fa 00 7f 00",      # 0x1016.1 consumer: master 127, 250 ms
            "2b 07 60 00 01 00 00 00",      # 0x6007 abort connection option: 1 fault
            "2f 60 60 00 09 00 00 00",      # 0x6060 mode 9: cyclic synchronous velocity
            "23 ff 60 00 00 00 00 00",      # 0x60FF target velocity 0
            # RPDO1 (0x1400 / 0x1600): controlword 0x6040 16 bits, target velocity 0x60FF 32
            "23 00 14 01 02 02 00 80", "2f 00 14 02 01 00 00 00", "2f 00 16 00 00 00 00 00",
            "23 00 16 01 10 00 40 60", "23 00 16 02 20 00 ff 60", "2f 00 16 00 02 00 00 00",
            "23 00 14 01 02 02 00 00",
            # RPDO2 (0x1401 / 0x1601): controlword, target torque 0x6071 16, mode 0x6060 8
            "23 01 14 01 02 03 00 80", "2f 01 14 02 01 00 00 00", "2f 01 16 00 00 00 00 00",
            "23 01 16 01 10 00 40 60", "23 01 16 02 10 00 71 60", "23 01 16 03 08 00 60 60",
            "2f 01 16 00 03 00 00 00", "23 01 14 01 02 03 00 00",
            # TPDO1 (0x1800 / 0x1A00): position actual 0x6064 32, velocity actual 0x606C 32
            "23 00 18 01 82 01 00 80", "2f 00 18 02 01 00 00 00", "2f 00 1a 00 00 00 00 00",
            "23 00 1a 01 20 00 64 60", "23 00 1a 02 20 00 6c 60", "2f 00 1a 00 02 00 00 00",
            "23 00 18 01 82 01 00 00",
            # TPDO2 (0x1801 / 0x1A01): statusword 0x6041 16, error code 0x603F 16
            "23 01 18 01 82 02 00 80", "2f 01 18 02 01 00 00 00", "2f 01 1a 00 00 00 00 00",
            "23 01 1a 01 10 00 41 60", "23 01 1a 02 10 00 3f 60", "2f 01 1a 00 02 00 00 00",
            "23 01 18 01 82 02 00 00",
            # RPDO3/4 (0x402, 0x502) and TPDO3/4 (0x382, 0x482) invalid
            "23 02 14 01 02 04 00 80", "23 03 14 01 02 05 00 80",
            "23 02 18 01 82 03 00 80", "23 03 18 01 82 04 00 80",
            "40 61 60 00 00 00 00 00",      # read 0x6061 mode display
            "40 02 65 00 00 00 00 00",      # read 0x6502 supported drive modes
            "40 76 60 00 00 00 00 00",      # read 0x6076 rated torque
            # after every device's set-up: the quick stop option code
            "40 5A 60 00 00 00 00 00")]     # read 0x605A (the e-stop's behaviour)
        assert _sdo_requests(frames, 2) == expected

        rig.driver.activate()
        mark = len(rig.sniff())
        rig.driver.write_velocities([2 * math.pi, -math.pi, 0.2 * math.pi])
        rpdo = [(m.arbitration_id, bytes(m.data)) for m in rig.sniff()[mark:]
                if 0x200 <= m.arbitration_id < 0x280]
        # 1 rev/s = 16384 counts/s = 0x4000; 0.5 rev/s = 0x2000
        assert rpdo == [(0x201, H("0f 00 00 40 00 00")), (0x202, H("0f 00 00 20 00 00")),
                        (0x203, H("0f 00 00 40 00 00"))]
        mark = len(rig.sniff())
        rig.driver.deactivate()
        tail = [(m.arbitration_id, bytes(m.data)) for m in rig.sniff()[mark:]
                if m.arbitration_id in (0x080, 0x201, 0x202, 0x203)]
        assert tail[:4] == [(0x201, H("07 00 00 00 00 00")), (0x202, H("07 00 00 00 00 00")),
                            (0x203, H("07 00 00 00 00 00")), (0x080, b"")]
    finally:
        rig.close()


# -- the rig's bus between processes ------------------------------------------------------------


def test_the_rigs_bus_carries_frames_with_their_stamps():
    """holonomic_ipc (the bus the CAN tests' drives are on): a frame reaches
    every other node with its bytes and its send time, or with
    preserve_timestamps the sender's own stamp (as the emulated drives stamp
    their answers)."""
    rig = CanRig("odrive_can", "hamr")
    nodes = []
    try:
        rig.emulators.stop()
        a, b = rig.open_bus(), rig.open_bus(preserve_timestamps=True)
        nodes += [a, b]
        b.send(can.Message(arbitration_id=0x7E1, data=b"\x01\x02", is_extended_id=False,
                           timestamp=42.0))
        t0 = time.time()
        a.send(can.Message(arbitration_id=0x7E2, data=H("0f 00 00 40"), is_extended_id=False))
        t1 = time.time()
        # (frames of different senders in either order, as on a bus)
        sent = {m.arbitration_id: (bytes(m.data), m.timestamp) for m in rig.sniff()
                if m.arbitration_id in (0x7E1, 0x7E2)}
        assert sent[0x7E1] == (b"\x01\x02", 42.0)
        assert sent[0x7E2][0] == H("0f 00 00 40") and t0 <= sent[0x7E2][1] <= t1
    finally:
        for node in nodes:
            node.shutdown()
        rig.close()


def test_the_rigs_bus_delivers_the_last_frames_of_a_node_that_closes(tmp_path):
    """A node that closes with frames of others unread (the driver at
    shutdown: the drives kept talking) still delivers every frame it sent
    before closing (its stop frames). Linux first reports ECONNRESET to the
    hub there; the hub used to drop the node at that point, frames and all.
    The hub is served by hand: the node sends and closes before the hub
    reads anything."""
    from holonomic_testing.ipc_can import BusHub, IpcBus
    path = str(tmp_path / "bus")
    hub = BusHub(path, f"hub-test-{id(tmp_path)}")
    closing, listener = IpcBus(path), IpcBus(path)
    try:
        hub.serve_once(1.0)                          # both connect
        listener.send(can.Message(arbitration_id=0x7E3, is_extended_id=False))
        hub.serve_once(1.0)                          # ... now unread by the closing node
        for k in range(3):
            closing.send(can.Message(arbitration_id=0x7E4, data=bytes([k]),
                                     is_extended_id=False))
        closing.shutdown()
        got = []
        for _ in range(5):
            hub.serve_once(0.1)
            while (msg := listener.recv(timeout=0.0)) is not None:
                got.append(bytes(msg.data))
        assert got == [b"\x00", b"\x01", b"\x02"]
    finally:
        closing.shutdown()
        listener.shutdown()
        hub.stop()


def test_odrive_0_5_heartbeat_carries_the_sub_object_error_flags():
    """Firmware 0.5.x's heartbeat (ODrive CAN protocol docs of 0.5): bytes
    0-3 axis error, byte 4 axis state, then one byte each with the motor
    (bit 40 of the payload), encoder (bit 48) and controller (bit 56) error
    flags, and trajectory done in the last bit (63). So motor + encoder +
    controller flags and trajectory done give the bytes 01 01 81."""
    hb = proto.Heartbeat.decode(H("40 00 00 00 08 01 01 81"), "0.5")
    assert (hb.axis_error, hb.axis_state, hb.trajectory_done) == (0x40, 8, True)
    assert hb.error_flags == ("motor", "encoder", "controller")
    assert hb.faulted
    assert hb.describe("0.5") == "0x40 (MOTOR_FAILED), motor encoder controller error flag"
    only_encoder = proto.Heartbeat(0, 8, 0, False, ("encoder",))
    assert only_encoder.encode("0.5") == H("00 00 00 00 08 00 01 00")
    # an error flag alone (axis error 0) is a fault; no flag and no error is not
    assert only_encoder.faulted
    healthy = proto.Heartbeat(0, 8, 0, True)
    assert not healthy.faulted
    assert healthy.encode("0.5") == H("00 00 00 00 08 00 00 80")
    assert proto.Heartbeat.decode(healthy.encode("0.5"), "0.5") == healthy


def test_odrive_0_6_heartbeat_of_seven_bytes_with_a_procedure_result():
    """Firmware 0.6.x's heartbeat: bytes 0-3 axis error, byte 4 axis state,
    byte 5 procedure result, byte 6 bit 0 trajectory done; the 8th byte is
    reserved and may be left out. Here: procedure result 2, trajectory not
    done."""
    hb = proto.Heartbeat.decode(H("00 00 00 00 01 02 00"))
    assert (hb.axis_error, hb.axis_state, hb.procedure_result, hb.trajectory_done) == (
        0, 1, 2, False)
    assert not hb.faulted


def test_odrive_error_status_and_an_unfinished_0_5_trajectory():
    """Get_Error (0x03) on 0.6: active_errors and disarm_reason, two
    little-endian u32; anything but 8 bytes is refused. A 0.5 heartbeat with
    the top bit (63) clear: trajectory not done."""
    status = proto.ErrorStatus.decode(H("00 00 00 01 20 00 00 00"))
    assert (status.active_errors, status.disarm_reason) == (0x1000000, 0x20)
    assert status.encode() == H("00 00 00 01 20 00 00 00")
    with pytest.raises(ValueError, match="8 expected"):
        proto.ErrorStatus.decode(H("00 00 00 01 20 00 00"))
    moving = proto.Heartbeat.decode(H("00 00 00 00 08 00 01 00"), "0.5")
    assert moving.trajectory_done is False and moving.error_flags == ("encoder",)
