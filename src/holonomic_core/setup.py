import glob
import os

from setuptools import find_packages, setup

PACKAGE = "holonomic_core"

# The robot configs live at the repository root (config/) so users find them;
# install them into share/ so an installed workspace finds them too.
CONFIGS = sorted(os.path.relpath(p) for p in glob.glob(os.path.join("..", "..", "config", "*.yaml")))

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    # the demo's scripted teleop (holonomic_core/teleop_script.py)
    package_data={PACKAGE: ["demo_script.yaml"]},
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
        ("share/" + PACKAGE + "/config", CONFIGS),
    ],
    install_requires=["setuptools"],
    # colcon test runs pytest (not unittest) on test/ when pytest is a test dependency
    extras_require={"test": ["pytest"]},
    zip_safe=True,
    maintainer="Holonomic base developers",
    maintainer_email="dev@holonomic.invalid",
    description="ROS-free core: robot model, kinematics protocol, odometry, limits, driver interface",
    license="Apache-2.0",
    entry_points={
        # its own backend, registered like every other (holonomic_core/plugins.py)
        "holonomic.drivers": ["mock = holonomic_core.mock_driver:MockDriver"],
    },
)
