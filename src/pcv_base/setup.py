from setuptools import find_packages, setup

PACKAGE = "pcv_base"

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
    description="Powered-caster vehicle kinematics and slip-minimising odometry",
    license="Apache-2.0",
    entry_points={
        # the family "pcv" for holonomic_core (holonomic_core/plugins.py)
        "holonomic.kinematics": ["pcv = pcv_base.powered_caster:PoweredCasterKinematics"],
        "holonomic.description": ["pcv = pcv_base.description:PoweredCasterDescription"],
        "holonomic.dynamics": ["pcv = pcv_base.dynamics:PcvDynamics"],
        "holonomic.calibration": ["pcv = pcv_base.calibration:CasterCalibration"],
    },
)
