"""Write the EDS/DCF files of this folder (ours, not a vendor's: see README.md).

Each file is the generic CiA 402 drive of
``holonomic_drivers.cia402_dictionary.generic_dictionary`` with the one or
two features changed that real drives differ in, exported with canopen's
own EDS writer. Run from the repository root after ``make setup``:

    . ros2_ws/env.sh && python src/holonomic_drivers/test/data/cia402/make_eds.py
"""

from pathlib import Path

import canopen
from canopen.objectdictionary import datatypes as dt

from holonomic_drivers.cia402_dictionary import generic_dictionary, mode_bit

HERE = Path(__file__).resolve().parent
RPM = 0x00B44700        # CiA 402 0x60A9: prefix 0, rev (0xB4) per minute (0x47)

FILES = {
    # velocity only: no target torque 0x6071 / rated torque 0x6076, no error code 0x603F
    "velocity_only.eds": dict(torque=False, error_code="none",
                              supported_modes=mode_bit(3) | mode_bit(9)),
    # profile velocity only; node guarding (0x100C/0x100D) instead of a heartbeat consumer;
    # RPDO1 and TPDO1 hold one mapping entry only
    "pv_only_guarding.eds": dict(supported_modes=mode_bit(1) | mode_bit(3), torque=False,
                                 watchdog="guarding", rtr_not_allowed=True,
                                 error_code="sdo", first_pdo_entries=1),
    # 16-bit target and actual velocity in rpm (0x60A9), error code not mappable
    "int16_rpm.eds": dict(target_velocity_type=dt.INTEGER16, velocity_unit=RPM,
                          error_code="sdo"),
    # two axes, the second one's profile objects at +0x800 (0x6840, 0x6841, ...)
    "two_axis.eds": dict(axes=2, torque=False),
    # no drive-side watchdog at all: no 0x1016, no 0x100C/0x100D
    "no_watchdog.eds": dict(watchdog="none", torque=False),
    # bit 30 (no RTR) on the RPDO COB-IDs as well as the TPDOs: $NODEID+0x40000200
    "rpdo_no_rtr.eds": dict(rpdo_rtr_bit=True, rtr_not_allowed=True, torque=False),
    # abort connection option code 0x6007 = 0 (no action) by default, writable
    "abort_connection_zero.eds": dict(abort_connection=("rw", 0), torque=False),
    # 0x6007 = 0 and read-only: the drive keeps running when it loses the master
    "abort_connection_ro.eds": dict(abort_connection=("ro", 0), torque=False),
    # no 0x6007 at all
    "abort_connection_missing.eds": dict(abort_connection=None, torque=False),
    # velocity_only.eds plus a velocity unit 0x60A9 (rpm): the file of a drive that,
    # emulated from velocity_only.eds, does not have the 0x60A9 its file lists
    "rpm_unit.eds": dict(velocity_unit=RPM, torque=False, error_code="none",
                         supported_modes=mode_bit(3) | mode_bit(9)),
}


def main() -> None:
    for name, features in FILES.items():
        od = generic_dictionary(None, **features)
        od.device_information.vendor_name = "holonomic test data (not a vendor)"
        od.device_information.product_name = name.rsplit(".", 1)[0]
        canopen.export_od(od, str(HERE / name))
    # the same drive as a DCF (a configured device's file)
    canopen.export_od(generic_dictionary(None, torque=False), str(HERE / "generic.dcf"))


if __name__ == "__main__":
    main()
