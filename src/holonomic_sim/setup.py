from setuptools import find_packages, setup

PACKAGE = "holonomic_sim"

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
    description="pybullet stand-in for the hardware, as a driver backend",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "holonomic-odometry-experiment = holonomic_sim.odometry_experiment:main",
            "holonomic-torque-experiment = holonomic_sim.torque_experiment:main",
            "holonomic-calibration-experiment = holonomic_sim.calibration_experiment:main",
        ],
        # plugins of holonomic_core (holonomic_core/plugins.py)
        "holonomic.drivers": ["sim = holonomic_sim.sim_driver:SimDriver"],
        "holonomic.driver_adapters": ["sim_drives = holonomic_sim.sim_drives:sim_drives_driver"],
    },
)
