"""Dry run of a robot's CiA 402 configuration against its drives' EDS files,
before any wiring: ``python -m holonomic_drivers.eds_check ROBOT [-p KEY=VALUE ...]``.

ROBOT is a config name or YAML path with a ``cia402`` section; ``-p`` sets
any key (``-p cia402.eds=drive.eds -p cia402.mode=pv``). Every drive is
emulated from its own EDS/DCF (``EmulatedCia402Drive``: canopen's SDO
server enforces the file's types and access rights and refuses mappings
the file does not allow) on a private virtual bus, and the real ``cia402``
driver goes through what it will do on the robot: configure (printing each
joint's PDOs and watchdog), enable, a velocity of a tenth of each joint's
limit read back, a fault on the first drive, stop. The emulated drives'
velocity unit is what their 0x60A9 says, so a ``velocity_resolution`` that
contradicts the file fails here as it would on the robot.

Exit 0: every step passed; 2: a configuration error (one line naming the
key); 1: a step failed (the line says which). It proves the configuration
and the files agree with the driver; not that the drives are commissioned.
"""

from __future__ import annotations

import argparse
import os
import sys
import time

import numpy as np
import yaml

from holonomic_core.config import load_config
from holonomic_core.driver import DriverError, DriverFault
from holonomic_core.schema import ConfigError
from holonomic_drivers.emulated_cia402 import EmulatedCia402Drive
from holonomic_drivers.emulation import EmulatorThread

#: a dry run checks behaviour, not timing: the emulated drives share this
#: process and its CPU with the driver
_RELAXED = {"cia402.feedback_timeout": 1.0, "cia402.heartbeat_timeout": 2.0,
            "cia402.startup_timeout": 5.0, "cia402.sdo_timeout": 1.0}


def _parse(argv):
    parser = argparse.ArgumentParser(prog="python -m holonomic_drivers.eds_check",
                                     description=__doc__.split("\n\n")[0])
    parser.add_argument("robot", help="config name (hamr, xr4000, comr3) or YAML path")
    parser.add_argument("-p", "--param", action="append", default=[], metavar="KEY=VALUE",
                        help="set a parameter (YAML value), e.g. cia402.eds=drive.eds")
    return parser.parse_args(argv)


def run(robot: str, overrides: dict, out=None, err=None) -> int:
    """The dry run; returns the exit code (see the module docstring). Steps
    go to ``out`` (stdout), errors to ``err`` (stderr), one line each."""
    out = out or sys.stdout
    err = err or sys.stderr
    params = dict(_RELAXED)
    params.update(overrides)
    params.update({"driver": "cia402", "cia402.interface": "virtual",
                   "cia402.channel": f"eds-check-{os.getpid()}-{time.monotonic_ns()}"})
    try:
        config = load_config(robot, params)
        driver = config.driver_class(config.model, config.values,
                                     config.controller.control_rate)
    except ConfigError as exc:
        print(f"eds_check: configuration error: {exc}", file=err)
        return 2
    values, joints = config.values, config.model.joint_names
    devices = {}
    for i, node in enumerate(driver.joints.node_ids):
        if node not in devices:
            j = joints[i]
            devices[node] = EmulatedCia402Drive(
                node, values["cia402.channel"],
                values[f"cia402.joints.{j}.eds"] or values["cia402.eds"] or None,
                encoder_resolution=int(values[f"cia402.joints.{j}.encoder_resolution"]))
    step = "configure"
    try:
        with EmulatorThread(devices.values()):
            driver.configure()
            for line in driver.wiring():
                print(f"  {line}", file=out)
            for text in driver.warnings:
                print(f"  WARNING {text}", file=out)
            step = "enable"
            driver.activate()
            step = "velocity"
            command = np.array([0.1 * values[f"joints.{j}.max_velocity"] for j in joints])
            reading = cycle_until(driver, lambda r: np.allclose(r.velocities, command,
                                                                rtol=0.01, atol=1e-3), command)
            print(f"  velocity: commanded {np.round(command, 4).tolist()} rad/s, read "
                  f"{np.round(reading.velocities, 4).tolist()} rad/s", file=out)
            step = "fault"
            first = devices[driver.joints.node_ids[0]]
            first.inject_fault(0x2310)
            try:
                cycle_until(driver, lambda r: False, command)
            except DriverFault as exc:
                print(f"  fault reported: {exc}", file=out)
            step = "stop"
            driver.deactivate()
            wait_until(lambda: all(d.motor(k).velocity() == 0.0 for d in devices.values()
                                   for k in range(len(d.axes))), what="standstill")
            print("  stop: every motor at standstill", file=out)
    except (DriverError, TimeoutError) as exc:
        print(f"eds_check: {step} failed: {exc}", file=err)
        return 1
    finally:
        driver.close()
        for device in devices.values():
            device.close()
    print("eds_check: configure, enable, velocity, fault and stop passed", file=out)
    return 0


def cycle_until(driver, condition, velocities=None, timeout: float = 10.0):
    """Cycle ``driver`` (write ``velocities`` [rad/s] if given, read, 5 ms)
    until ``condition(reading)``; returns that reading, TimeoutError after
    ``timeout`` [s]. Driver errors propagate."""
    deadline = time.monotonic() + timeout
    while True:
        if velocities is not None:
            driver.write_velocities(velocities)
        reading = driver.read()
        if condition(reading):
            return reading
        if time.monotonic() > deadline:
            raise TimeoutError(f"no matching reading within {timeout:g} s (last: "
                               f"{np.round(reading.velocities, 4).tolist()} rad/s)")
        time.sleep(0.005)


def wait_until(condition, timeout: float = 5.0, what: str = "condition") -> None:
    """Poll ``condition()`` every 5 ms; TimeoutError after ``timeout`` [s]."""
    deadline = time.monotonic() + timeout
    while not condition():
        if time.monotonic() > deadline:
            raise TimeoutError(f"no {what} within {timeout:g} s")
        time.sleep(0.005)


def main(argv=None) -> int:
    args = _parse(argv)
    overrides = {}
    for item in args.param:
        key, sep, value = item.partition("=")
        if not sep:
            print(f"eds_check: -p {item}: expected KEY=VALUE", file=sys.stderr)
            return 2
        overrides[key] = yaml.safe_load(value)
    return run(args.robot, overrides)


if __name__ == "__main__":
    sys.exit(main())
