from setuptools import find_packages, setup

PACKAGE = "hamr_base"

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
    description="DDROT (offset-turret differential drive) kinematics",
    license="Apache-2.0",
    entry_points={
        # the family "ddrot" for holonomic_core (holonomic_core/plugins.py)
        "holonomic.kinematics": ["ddrot = hamr_base.offset_turret:OffsetTurretKinematics"],
        "holonomic.description": ["ddrot = hamr_base.description:OffsetTurretDescription"],
        "holonomic.calibration": ["ddrot = hamr_base.calibration:TurretCalibration"],
    },
)
