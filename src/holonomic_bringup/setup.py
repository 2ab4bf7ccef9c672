from glob import glob

from setuptools import find_packages, setup

PACKAGE = "holonomic_bringup"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/launch", glob("launch/*.launch.py")),
    ],
    install_requires=["setuptools"],
    # colcon test runs pytest (not unittest) on test/ when pytest is a test dependency
    extras_require={"test": ["pytest"]},
    zip_safe=True,
    maintainer="Holonomic base developers",
    maintainer_email="dev@holonomic.invalid",
    description="Base controller node, launcher and demo",
    license="Apache-2.0",
    entry_points={
        "console_scripts": [
            "holonomic-bringup = holonomic_bringup.bringup:main",
            "holonomic-demo = holonomic_bringup.demo:main",
            "holonomic-drive-test = holonomic_bringup.drive_step:main",
            "holonomic-teleop = holonomic_bringup.teleop:main",
            "holonomic-plot = holonomic_bringup.recording_plot:main",
            "holonomic-ctl = holonomic_bringup.ctl:main",
            "holonomic-odometry-calibrate = holonomic_bringup.odometry_calibrate:main",
            "holonomic-calibrate = holonomic_bringup.calibrate:main",
            "base_controller = holonomic_bringup.base_controller_node:main",
        ],
    },
)
