import glob
import os

from setuptools import Extension, find_packages, setup

import numpy

PACKAGE = "holonomic_core"

# The robot configs live at the repository root (config/) so users find them;
# install them into share/ so an installed workspace finds them too.
CONFIGS = sorted(os.path.relpath(p) for p in glob.glob(os.path.join("..", "..", "config", "*.yaml")))

# The control cycle's closed forms, compiled (holonomic_core/hot_path.py says
# which functions dispatch to it). Not optional: `make setup` fails loudly
# when it does not compile; at run time a missing module falls back to the
# pure-Python path with one warning line. -ffp-contract=off: no fused
# multiply-add, so the results stay those of the Python expressions.
HOT_PATH = Extension(
    PACKAGE + "._hot_path", [PACKAGE + "/_hot_path.c"],
    include_dirs=[numpy.get_include()],
    extra_compile_args=["-O2", "-ffp-contract=off", "-fno-fast-math"],
)

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
    ext_modules=[HOT_PATH],
    install_requires=["setuptools", "numpy", "tqdm"],
    # colcon test runs pytest (not unittest) on test/ when pytest is a test dependency
    extras_require={"test": ["pytest"]},
    zip_safe=False,
    maintainer="Holonomic base developers",
    maintainer_email="dev@holonomic.invalid",
    description="ROS-free core: robot model, kinematics protocol, odometry, limits, driver interface",
    license="Apache-2.0",
    entry_points={
        # its own backend, registered like every other (holonomic_core/plugins.py)
        "holonomic.drivers": ["mock = holonomic_core.mock_driver:MockDriver"],
    },
)
