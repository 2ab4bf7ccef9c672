from setuptools import find_packages, setup

PACKAGE = "holonomic_drivers"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    # colcon test runs pytest (not unittest) on test/ when pytest is a test dependency
    extras_require={"test": ["pytest"]},
    zip_safe=True,
    maintainer="Holonomic base developers",
    maintainer_email="dev@holonomic.invalid",
    description="Motor drive backends over CAN (ODrive CANSimple, CANopen CiA 402) and "
                "their emulators",
    license="Apache-2.0",
    entry_points={
        # plugins of holonomic_core (holonomic_core/plugins.py)
        "holonomic.drivers": [
            "odrive_can = holonomic_drivers.odrive_can:OdriveCanDriver",
            "cia402 = holonomic_drivers.cia402:Cia402Driver",
        ],
        # each backend's emulated drive, under the backend's name
        "holonomic.emulated_drives": [
            "odrive_can = holonomic_drivers.emulation:EmulatedOdriveAxis",
            "cia402 = holonomic_drivers.emulated_cia402:EmulatedCia402Drive",
        ],
    },
)
