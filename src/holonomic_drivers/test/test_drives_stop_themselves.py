"""Drives that stop themselves: the CiA 402 and ODrive details that decide
whether a drive follows, and stops, when it should.

* RPDO COB-IDs with bit 30 set (``$NODEID+0x40000200``): CiA 301 makes bits
  29..31 of a COB-ID entry flags, so the RPDO goes out on the 11-bit
  identifier; the emulated drive receives only that (an 11-bit PDO ignores
  a 29-bit frame), so velocity reaches it and a deactivate or another
  drive's fault takes it out of OPERATION ENABLED.
* 0x6007, the abort connection option code: 0 ("no action") in the file
  means a drive that detects the lost controller keeps turning; the driver
  writes 1 (fault) or 3 (quick stop) per ``cia402.drive_watchdog_reaction``,
  and warns where 0x6007 is read-only or missing.
* A refused SDO read names the joint, node, object and abort code.
* ODrive Get_Version is requested with a remote frame.

Each EDS here is ours (data/cia402/README.md); the emulated drives act as
CiA 301/402 say for each variant.
"""

import time

import can
import numpy as np
import pytest

from holonomic_core.driver import DriverFault
from holonomic_drivers import odrive_endpoints
from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers.cia402_protocol import State
from holonomic_drivers.eds_check import wait_until

from test_cia402_eds import (COMMAND, DATA, JOINTS, MOTOR_REV_S, final_values,  # noqa: F401
                             rig_factory, run_until, sdo_writes)
from test_odrive_watchdog import Axes, endpoints_file  # noqa: F401


def motors_at_command(rig):
    return lambda r: np.allclose([d.velocity_rev_per_s for d in rig.devices], MOTOR_REV_S,
                                 atol=1e-9)


# -- RPDO COB-IDs with bit 30 --------------------------------------------------------------

def test_rpdos_with_bit_30_go_out_on_the_11_bit_id_and_move_the_motors(rig_factory):
    """rpdo_no_rtr.eds: RPDO1 COB-ID $NODEID+0x40000200. By hand for node 1:
    0x1400:1 is written 0xC0000201 (invalid, no RTR), then 0x40000201 (valid,
    bit 30 kept as the file has it); the velocity RPDO is a standard
    (11-bit) data frame on 0x201, and the motors turn at the command."""
    rig = rig_factory("rpdo_no_rtr.eds")
    rig.driver.configure()
    writes = [w for w in sdo_writes(rig.sniff(), 1) if w[:2] == (0x1400, 1)]
    assert [w[2] for w in writes] == [0xC0000201, 0x40000201]
    rig.driver.activate()
    run_until(rig, motors_at_command(rig), velocities=COMMAND)
    rpdos = [m for m in rig.sniff() if m.arbitration_id & 0x7FF == 0x201]
    assert rpdos and all(m.arbitration_id == 0x201 and not m.is_extended_id
                         and not m.is_remote_frame for m in rpdos)


def test_rpdo_bit_30_drives_leave_operation_enabled_on_deactivate(rig_factory):
    """Arming walks the state machine over SDO; disarming is "disable
    operation" in the velocity RPDO: it reaches the drive only on its 11-bit
    identifier (sent elsewhere, the drives stayed OPERATION ENABLED)."""
    rig = rig_factory("rpdo_no_rtr.eds")
    rig.driver.configure()
    rig.driver.activate()
    assert all(d.state() is State.OPERATION_ENABLED for d in rig.devices)
    rig.driver.deactivate()
    wait_until(lambda: all(d.state() is State.SWITCHED_ON for d in rig.devices), 5.0,
               "disable operation")
    wait_until(lambda: all(d.velocity_rev_per_s == 0.0 for d in rig.devices), what="standstill")


def test_rpdo_bit_30_drives_stop_when_another_drive_faults(rig_factory):
    """The right wheel's drive faults: the driver's read reports it, the
    deactivate that follows (as the controller's fault handling does) takes
    the two others out of OPERATION ENABLED and their motors stop."""
    rig = rig_factory("rpdo_no_rtr.eds")
    rig.driver.configure()
    rig.driver.activate()
    run_until(rig, motors_at_command(rig), velocities=COMMAND)
    rig.devices[1].inject_fault(0x2310)
    with pytest.raises(DriverFault, match="right_wheel_joint"):
        run_until(rig, lambda r: False, velocities=COMMAND)
    rig.driver.deactivate()
    others = (rig.devices[0], rig.devices[2])
    wait_until(lambda: all(d.state() is State.SWITCHED_ON for d in others), 5.0,
               "disable operation")
    wait_until(lambda: all(d.velocity_rev_per_s == 0.0 for d in others), what="standstill")


# -- 0x6007: what a drive does when it loses the controller --------------------------------

@pytest.mark.parametrize("reaction, code, state", [("fault", 1, State.FAULT),
                                                    ("quick_stop", 3, State.SWITCH_ON_DISABLED)])
def test_a_drive_whose_0x6007_defaults_to_0_stops_when_the_controller_dies(
        rig_factory, reaction, code, state):
    """abort_connection_zero.eds: 0x6007 = 0 (no action), writable. The driver
    writes 0x6007 = 1 (fault) or 3 (quick stop); when the controller stops
    (no more reads: no master heartbeat), each drive's heartbeat consumer
    expires after drive_watchdog (1 s here: this test's own thread cycles the
    driver, and a stall of it longer than the default 0.25 s on a loaded
    machine would expire the watchdog early) and the drive does what 0x6007
    says: FAULT, or QUICK STOP ACTIVE and, at rest, SWITCH ON DISABLED (their
    quick stop option code 0x605A is 2) -- the motors stop either way, and
    not in OPERATION ENABLED; and the controller, back, can arm them again."""
    # (fault is the default: no override, as a user's config would have it)
    rig = rig_factory("abort_connection_zero.eds", **{"cia402.drive_watchdog": 1.0}, **(
        {} if reaction == "fault" else {"cia402.drive_watchdog_reaction": reaction}))
    rig.driver.configure()
    last = final_values(sdo_writes(rig.sniff(), 1))
    assert last[(0x6007, 0)] == code
    assert not rig.driver.warnings
    rig.driver.activate()
    run_until(rig, motors_at_command(rig), velocities=COMMAND)
    wait_until(lambda: all(d.velocity_rev_per_s == 0.0 for d in rig.devices), what="standstill")
    wait_until(lambda: all(d.state() is state for d in rig.devices), 5.0, "watchdog reaction")
    # the controller back: arming brings the drives out of FAULT (fault reset)
    # or QUICK STOP ACTIVE (disable voltage first) to OPERATION ENABLED again
    rig.driver.deactivate()
    rig.driver.activate()
    assert all(d.state() is State.OPERATION_ENABLED for d in rig.devices)


def test_a_read_only_0x6007_is_warned_about_and_the_drive_keeps_turning(rig_factory):
    """abort_connection_ro.eds: 0x6007 = 0, read-only. The driver cannot set
    it: one warning per drive in the log and in status (diagnostics), with
    the value it reads; and, as CiA 402 says for 0, the drive that loses the
    controller does nothing: still OPERATION ENABLED, still turning."""
    rig = rig_factory("abort_connection_ro.eds")
    rig.driver.configure()
    assert (0x6007, 0) not in final_values(sdo_writes(rig.sniff(), 1))
    assert len(rig.driver.warnings) == 3
    assert rig.driver.warnings[0] == (
        "left_wheel_joint (CANopen node 1): has a read-only abort connection option code "
        "0x6007; it reads 0 (0: no action): its reaction to losing this controller is not "
        "fault (1)")
    assert rig.driver.status()["warning 1"] == rig.driver.warnings[0]
    rig.driver.activate()
    run_until(rig, motors_at_command(rig), velocities=COMMAND)
    time.sleep(0.6)                        # > drive_watchdog 0.25 s, the controller silent
    assert all(d.state() is State.OPERATION_ENABLED for d in rig.devices)
    assert np.allclose([d.velocity_rev_per_s for d in rig.devices], MOTOR_REV_S, atol=1e-9)


def test_a_missing_0x6007_is_warned_about_and_the_drive_reacts_its_own_way(rig_factory):
    """abort_connection_missing.eds: no 0x6007. A warning per drive; the
    emulated drive's own reaction (its maker's choice) is a fault."""
    rig = rig_factory("abort_connection_missing.eds")
    rig.driver.configure()
    assert len(rig.driver.warnings) == 3
    assert rig.driver.warnings[2].startswith(
        "turret_joint (CANopen node 3): has no abort connection option code 0x6007")
    rig.driver.activate()
    run_until(rig, motors_at_command(rig), velocities=COMMAND)
    wait_until(lambda: all(d.state() is State.FAULT for d in rig.devices), 5.0, "own reaction")


# -- refused SDO transfers ------------------------------------------------------------------

def test_a_refused_sdo_read_names_joint_node_object_and_abort_code(rig_factory):
    """rpm_unit.eds lists 0x60A9 (velocity unit); the drives, emulated from
    velocity_only.eds, do not have it and abort the read with 0x06020000
    (CiA 301: object does not exist). Configure fails naming the first
    drive, its node, the object (as the file names it) and the code."""
    rig = rig_factory("rpm_unit.eds", drive_eds=str(DATA / "velocity_only.eds"),
                      **{f"cia402.joints.{j}.velocity_resolution": 60.0 for j in JOINTS})
    with pytest.raises(DriverFault) as err:
        rig.driver.configure()
    assert str(err.value) == (
        "left_wheel_joint (CANopen node 1): refused the SDO read of 0x60A9:0 (SI unit "
        "velocity): abort code 0x06020000 (object does not exist in the object dictionary)")


def test_a_refused_sdo_write_names_joint_node_object_value_and_abort_code(rig_factory):
    """The controlword write of a drive that refuses it (the emulated drive
    aborts with 0x06090030 for a mode it does not have: 0x6060 = 10, cyclic
    synchronous torque, on velocity_only.eds)."""
    rig = rig_factory("velocity_only.eds")
    rig.driver.configure()
    with pytest.raises(DriverFault) as err:
        rig.driver._write(0, 0x6060, 10)      # the driver's own SDO write, as arming uses
    assert str(err.value) == (
        "left_wheel_joint (CANopen node 1): refused the SDO write of 0x6060:0 (Modes of "
        "operation) = 0x0A: abort code 0x06090030 (value range of parameter exceeded)")


# -- ODrive Get_Version -----------------------------------------------------------------------

def test_odrive_get_version_is_requested_with_a_remote_frame(endpoints_file):
    """ODrive's CAN docs: Get_Version (cmd 0x00) is requested by RTR; the
    answer is an 8-byte data frame on the same id. For node 0: id 0x000,
    remote, DLC 8 (the answer's length). The emulated axis answers only a
    remote frame (an empty data frame would collide with its answer)."""
    rig = Axes("0.6", {"odrive_can.endpoints": endpoints_file,
                       "odrive_can.watchdog_check": "refuse"},
               endpoints=odrive_endpoints.load(endpoints_file), watchdog_timeout=0.2)
    sniffer = can.Bus(interface="virtual", channel=rig.config.values["odrive_can.channel"])
    try:
        rig.driver.configure()
        frames = []
        while (m := sniffer.recv(timeout=0.0)) is not None:
            frames.append(m)
        requests = [m for m in frames if proto.split_id(m.arbitration_id)[1]
                    == proto.Cmd.GET_VERSION and m.is_remote_frame]
        assert {proto.split_id(m.arbitration_id)[0] for m in requests} == {0, 1, 2}
        assert all(m.dlc == 8 and not m.is_extended_id for m in requests)
        empty = [m for m in frames if proto.split_id(m.arbitration_id)[1]
                 == proto.Cmd.GET_VERSION and not m.is_remote_frame and not m.data]
        assert not empty
        assert rig.driver.status()["left_wheel_joint"].endswith("firmware 0.6.11)")
    finally:
        sniffer.shutdown()
        rig.close()
