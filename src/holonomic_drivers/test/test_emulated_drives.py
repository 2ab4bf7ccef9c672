"""Each backend's emulated drive is registered next to its driver
(``holonomic.emulated_drives`` entry points in this package's setup.py) and
found through one function, ``holonomic_core.driver.emulated_drive_class``:
the simulated drives (``--sim-drives``), the CAN test rig and the drives'
process all build their devices from it.
"""

from pathlib import Path

import pytest

from holonomic_core.config import load_config
from holonomic_core.driver import driver_names, emulated_drive_class, emulated_drive_names
from holonomic_core.schema import ConfigError
from holonomic_drivers.emulated_cia402 import EmulatedCia402Drive
from holonomic_drivers.emulation import EmulatedOdriveAxis
from holonomic_testing.drive_host import DriveHost

DATA = Path(__file__).parent / "data" / "cia402"


def test_the_registry_lists_the_shipped_backends_and_their_emulated_drives():
    assert emulated_drive_names() == ("cia402", "odrive_can")
    assert emulated_drive_class("odrive_can") is EmulatedOdriveAxis
    assert emulated_drive_class("cia402") is EmulatedCia402Drive
    # each emulates an installed backend
    assert set(emulated_drive_names()) <= set(driver_names())


@pytest.mark.parametrize("backend, nearest", [("sim", None), ("odrive", "odrive_can")])
def test_an_unknown_backend_is_refused_in_one_line_naming_the_known_ones(backend, nearest):
    with pytest.raises(ConfigError) as caught:
        emulated_drive_class(backend)
    line = str(caught.value)
    assert "\n" not in line
    assert f"'driver' = '{backend}'" in line
    assert "['cia402', 'odrive_can']" in line
    if nearest:
        assert f"did you mean '{nearest}'?" in line


def test_the_drives_process_refuses_an_unknown_backend_before_it_starts(tmp_path):
    with pytest.raises(ConfigError, match=r"'driver' = 'odrive': expected one of "
                                          r"\['cia402', 'odrive_can'\]"):
        DriveHost([("odrive", 0, {})], str(tmp_path / "bus"))


def test_an_odrive_axis_is_emulated_with_the_yaml_firmware():
    values = load_config("hamr", {"driver": "odrive_can",
                                  "odrive_can.firmware": "0.5"}).values
    assert EmulatedOdriveAxis.settings_for(values, "turret_joint") == {"firmware": "0.5"}


def test_a_cia402_drive_is_emulated_from_the_joint_eds_else_the_bus_eds():
    generic = load_config("hamr", {"driver": "cia402"}).values
    # config/hamr.yaml: 16384 counts per motor rev on every joint, no EDS:
    # the generic drive
    assert EmulatedCia402Drive.settings_for(generic, "turret_joint") == {
        "eds": None, "encoder_resolution": 16384}
    bus, own = str(DATA / "rpm_unit.eds"), str(DATA / "two_axis.eds")
    values = load_config("hamr", {"driver": "cia402", "cia402.eds": bus,
                                  "cia402.joints.turret_joint.eds": own,
                                  "cia402.joints.turret_joint.encoder_resolution": 4096}).values
    assert EmulatedCia402Drive.settings_for(values, "turret_joint") == {
        "eds": own, "encoder_resolution": 4096}
    assert EmulatedCia402Drive.settings_for(values, "left_wheel_joint")["eds"] == bus
