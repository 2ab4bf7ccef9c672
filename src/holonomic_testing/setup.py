from setuptools import find_packages, setup

PACKAGE = "holonomic_testing"

setup(
    name=PACKAGE,
    version="0.1.0",
    packages=find_packages(exclude=["test", "test.*"]),
    data_files=[
        ("share/ament_index/resource_index/packages", ["resource/" + PACKAGE]),
        ("share/" + PACKAGE, ["package.xml"]),
    ],
    install_requires=["setuptools"],
    zip_safe=True,
    maintainer="Holonomic base developers",
    maintainer_email="dev@holonomic.invalid",
    description="Test helpers and the shared pytest fixtures of the workspace's tests "
                "(no product code imports it)",
    license="Apache-2.0",
    entry_points={
        # the shared fixtures (ros, start_bringup) and the per-session ROS
        # domain: loaded by every pytest run in the workspace's environment,
        # `make test` over all packages and `colcon test` of one package alike
        "pytest11": ["holonomic_testing = holonomic_testing.pytest_plugin"],
        # a CAN bus between processes (the rig's drives run in a process of
        # their own): can.Bus(interface="holonomic_ipc", channel=hub socket)
        "can.interface": ["holonomic_ipc = holonomic_testing.ipc_can:IpcBus"],
    },
)
