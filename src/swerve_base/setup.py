from setuptools import find_packages, setup

PACKAGE = "swerve_base"

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
    description="Swerve-drive kinematics, steering law and least-squares odometry",
    license="Apache-2.0",
    entry_points={
        # the family "swerve" for holonomic_core (holonomic_core/plugins.py); no
        # holonomic.dynamics entry: torque mode is refused for it (velocity only)
        "holonomic.kinematics": ["swerve = swerve_base.swerve:SwerveKinematics"],
        "holonomic.description": ["swerve = swerve_base.description:SwerveDescription"],
        "holonomic.calibration": ["swerve = swerve_base.calibration:SwerveCalibration"],
    },
)
