"""The real CAN drivers on simulated physics (``--driver odrive_can|cia402 --sim-drives``).

:func:`sim_drives_driver` turns a CAN backend class into a driver that runs,
in this process:

* the backend itself, unchanged -- frames, scaling through the YAML's gear
  ratios and directions, heartbeats, timeouts, fault handling -- on a private
  python-can ``virtual`` channel (the YAML's ``interface`` and ``channel``
  are ignored);
* one emulated drive per joint (the backend's ``holonomic.emulated_drives``
  entry point, as the YAML describes it: the ODrive axis of
  :mod:`holonomic_drivers.emulation` with the YAML's ``odrive_can.firmware``,
  the CiA 402 drive of :mod:`holonomic_drivers.emulated_cia402` from the
  joint's EDS) in a background thread that polls the bus every millisecond;
* the pybullet simulator (:class:`~holonomic_sim.sim_driver.SimDriver`, all
  ``sim.*`` parameters apply), whose joints are the drives' motors
  (:mod:`holonomic_sim.joint_motor`) through the mechanism's true gear ratio
  and direction: ``sim_drives.joints.<joint>.gear_ratio`` / ``.direction``,
  by default the YAML's own.

Who steps the physics: a thread of its own (:class:`PhysicsThread`), on the
wall clock like the drives (the emulator thread polls them every
millisecond) and like real physics, which does not wait for a late control
loop: every control period it hands the drives' latest setpoints to the
simulator and advances it by one period (several after a late wake-up, at
most MAX_CATCH_UP; beyond that the lost time is skipped). The control loop's
:meth:`read` only reads the CAN backend. Readings are stamped on
``time.monotonic()`` as on a real robot (no ``/clock``);
``ground_truth/odom`` comes from the simulator.

The YAML check: each joint's reading through the YAML's mapping is compared
with the simulated joint over windows of joint travel (at least 0.5 rad, and
long enough that the reading's lag behind the joint cannot pass for a
mistake: as far as the joint goes in 1 s at its speeds at both ends); if it reads more than 15 % off
(a gear ratio) or backwards (a direction) the driver faults, naming the
joint, the factor and the keys to check. The factor is
``(d_true g_true) / (d_yaml g_yaml)``: -1 for a wrong direction, 1.2 for a
YAML gear ratio of 10 on a 12:1 gearbox.
"""

from __future__ import annotations

import itertools
import os
import threading
import time

import numpy as np

from holonomic_core.driver import (Driver, DriverError, DriverFault, JointReading,
                                   emulated_drive_class, emulated_drive_names)
from holonomic_core.schema import ConfigError, ParamSpec

#: the YAML check: relative tolerance of a joint's reading against the
#: simulated joint, the least joint travel [rad] it compares over, and how
#: far [s] a reading may lag the joint (the backends' default feedback
#: timeouts: a later reading is a fault of its own)
CHECK_TOLERANCE = 0.15
CHECK_MIN_TRAVEL = 0.5
READING_LAG = 0.05
#: control periods the physics may catch up after a late wake-up
MAX_CATCH_UP = 20
_channels = itertools.count()


class PhysicsThread:
    """Steps :class:`~holonomic_sim.joint_motor.SimulatedJoints` every
    ``period`` [s] of the wall clock. ``lock`` guards the simulator: hold it
    for any other call into it (ground truth, status)."""

    def __init__(self, joints, period: float):
        self.joints = joints
        self.period = float(period)
        self.lock = threading.Lock()
        self._truth = None
        self._error: BaseException | None = None
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name="sim-drives-physics",
                                        daemon=True)

    def start(self) -> "PhysicsThread":
        with self.lock:
            self._truth = self.joints.step()
        self._thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._thread.join(timeout=2.0)

    def latest(self) -> JointReading:
        """The simulator's reading after the last step; re-raises what stopped the thread."""
        if self._error is not None:
            raise self._error
        return self._truth

    def _run(self) -> None:
        stepped_to = time.monotonic()
        while not self._stop.is_set():
            periods = int((time.monotonic() - stepped_to) / self.period)
            if periods > MAX_CATCH_UP:
                stepped_to += (periods - MAX_CATCH_UP) * self.period    # time lost
                periods = MAX_CATCH_UP
            try:
                for _ in range(periods):
                    with self.lock:
                        self._truth = self.joints.step()
            except DriverError as exc:          # e.g. the simulated base tipped over
                self._error = exc
                return
            stepped_to += periods * self.period
            self._stop.wait(max(0.0, stepped_to + self.period - time.monotonic()))


def sim_drives_driver(backend: type[Driver]) -> type[Driver]:
    """The ``--sim-drives`` driver class for CAN backend class ``backend``."""
    emulated = emulated_drive_names()
    if backend.name not in emulated:
        raise ConfigError("sim_drives", True,
                          f"false with driver '{backend.name}' (simulated drives exist for "
                          f"{' and '.join(emulated)} only)")
    return type(f"SimDrives{backend.__name__}", (SimDrivesDriver,),
                {"backend": backend, "name": backend.name,
                 "supports_effort": backend.supports_effort})


def truth_specs(model) -> list[ParamSpec]:
    """Schema of ``sim_drives.joints.<joint>.gear_ratio / direction``."""
    specs = []
    for joint in model.joint_names:
        base = f"sim_drives.joints.{joint}"
        specs += [
            ParamSpec(f"{base}.gear_ratio", "double",
                      f"--sim-drives: the true gear ratio of {joint}'s mechanism (motor rev "
                      "per joint rev); 0: the one the driver's YAML states [-].",
                      default=0.0, minimum=0.0, maximum=1e4),
            ParamSpec(f"{base}.direction", "int",
                      f"--sim-drives: the true direction of {joint}'s motor (+1 or -1); "
                      "0: the one the driver's YAML states.",
                      default=0, minimum=-1, maximum=1),
        ]
    return specs


class SimDrivesDriver(Driver):
    """A CAN backend on emulated drives whose motors are simulated joints.

    Subclasses made by :func:`sim_drives_driver` set ``backend``.
    """

    backend: type[Driver]
    #: the simulated joints belong to a body of its own (see SimDriver)
    simulates_body = True

    @classmethod
    def param_specs(cls, model) -> list[ParamSpec]:
        from holonomic_sim.sim_driver import SimDriver

        return cls.backend.param_specs(model) + SimDriver.param_specs(model) + truth_specs(model)

    def __init__(self, model, params, control_rate: float, body=None):
        """``body``: the simulated robot's nominal description (see
        :class:`~holonomic_sim.sim_driver.SimDriver`); default ``model``."""
        from holonomic_sim.sim_driver import SimDriver

        super().__init__(model, params, control_rate)
        if params["sim.physics_process"]:
            raise ConfigError("sim.physics_process", True,
                              "false with simulated drives (their physics runs in a thread "
                              "of its own on the wall clock already)")
        self.channel = f"sim-drives-{os.getpid()}-{next(_channels)}"
        own = dict(params)
        own[f"{self.name}.interface"] = "virtual"
        own[f"{self.name}.channel"] = self.channel
        self.can = self.backend(model, own, control_rate)
        self.sim = SimDriver(model, params, control_rate, body=body)
        prefix = f"{self.name}.joints"
        self.true_gear_ratios, self.true_directions = [], []
        for joint in model.joint_names:
            gear = params[f"sim_drives.joints.{joint}.gear_ratio"]
            direction = params[f"sim_drives.joints.{joint}.direction"]
            self.true_gear_ratios.append(gear or params[f"{prefix}.{joint}.gear_ratio"])
            self.true_directions.append(direction or params[f"{prefix}.{joint}.direction"])
        #: the emulated drives, joint_names order
        self.drives = []
        self._emulators = None
        self._joints = None
        self._reference: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
        self._physics: PhysicsThread | None = None

    # -- lifecycle ----------------------------------------------------------------
    def _on_configure(self) -> None:
        from holonomic_drivers.emulation import EmulatorThread
        from holonomic_sim.joint_motor import SimulatedJoints

        self.sim.configure()
        try:
            # the simulated motors are powered; the emulated drives decide
            # (an idle drive commands zero speed)
            self.sim.activate()
            self._joints = SimulatedJoints(
                self.sim, np.array([j.max_effort for j in self.model.joint_limits]),
                self.model.max_joint_velocity)
            self._physics = PhysicsThread(self._joints, 1.0 / self.control_rate).start()
            self.drives = [self._make_drive(i) for i in range(len(self.model.joint_names))]
            self._emulators = EmulatorThread(self.drives).start()
            self.can.configure()
        except BaseException:
            self._shutdown()
            raise

    def _make_drive(self, i: int):
        from holonomic_sim.joint_motor import SimulatedJointMotor

        joint = self.model.joint_names[i]
        base = f"{self.name}.joints.{joint}"
        motor = SimulatedJointMotor(self._joints, i, self.true_gear_ratios[i],
                                    self.true_directions[i], self.params[f"{base}.position_offset"])
        # the drive the YAML describes for the joint; one emulated device per
        # joint: multi-axis devices (joints sharing a node id) are not emulated here
        emulated = emulated_drive_class(self.name)
        return emulated(self.params[f"{base}.node_id"], self.channel, motor=motor,
                        **emulated.settings_for(self.params, joint))

    def _on_activate(self) -> None:
        self.can.activate()

    def _on_deactivate(self) -> None:
        self.can.deactivate()

    def _on_quick_stop(self) -> None:
        self.can.quick_stop()

    def _on_close(self) -> None:
        self._shutdown()

    def _shutdown(self) -> None:
        try:
            self.can.close()
        finally:
            if self._emulators is not None:
                self._emulators.stop()
                self._emulators = None
            for drive in self.drives:
                drive.close()
            self.drives = []
            if self._physics is not None:
                self._physics.stop()
                self._physics = None
            self.sim.close()

    # -- cycle --------------------------------------------------------------------------
    def _on_read(self) -> JointReading:
        truth = self._physics.latest()
        reading = self.can.read()
        self._check_mapping(reading.positions, truth.positions, truth.velocities)
        return reading

    def _check_mapping(self, read: np.ndarray, true: np.ndarray, speed: np.ndarray) -> None:
        """Fault when a joint's YAML mapping disagrees with the simulated mechanism.

        ``read``: the backend's joint positions [rad]; ``true``, ``speed``: the
        simulated joints' positions [rad] and speeds [rad/s]. Per joint, a
        window runs from a reference sample until the joint has travelled far
        enough that the reading's lag (at most READING_LAG x speed at each
        end) is below a third of the tolerance; the factor is then the
        reading's travel over the joint's, within 0.05 of the truth."""
        if self._reference is None:
            self._reference = (read.copy(), true.copy(), np.abs(speed))
            return
        read0, true0, speed0 = self._reference
        travel = true - true0
        needed = np.maximum(CHECK_MIN_TRAVEL, (speed0 + np.abs(speed)) * READING_LAG
                            * 3.0 / CHECK_TOLERANCE)
        for i in np.flatnonzero(np.abs(travel) >= needed):
            factor = (read[i] - read0[i]) / travel[i]
            read0[i], true0[i], speed0[i] = read[i], true[i], abs(speed[i])
            if abs(factor - 1.0) > CHECK_TOLERANCE:
                joint = self.model.joint_names[i]
                raise DriverFault(
                    f"reads {factor:+.2f} times the simulated joint's motion: "
                    f"{self.name}.joints.{joint}.direction x gear_ratio in the YAML "
                    f"({self.params[f'{self.name}.joints.{joint}.direction']:+d} x "
                    f"{self.params[f'{self.name}.joints.{joint}.gear_ratio']:g}) does "
                    f"not match the mechanism ({self.true_directions[i]:+d} x "
                    f"{self.true_gear_ratios[i]:g})", self.can.devices[i])

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        self.can.write_velocities(velocities)

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        self.can.write_efforts(efforts)

    # -- capabilities -------------------------------------------------------------------
    def ground_truth(self):
        if self._physics is None:
            return None
        with self._physics.lock:
            return self.sim.ground_truth()

    def status(self) -> dict[str, str]:
        values = self.can.status()
        values["state"] = self.state.value
        values["sim_drives"] = (f"{len(self.drives)} emulated {self.can.device_kind} drives "
                                f"on virtual:{self.channel}, motors = simulated joints")
        if self._physics is None:
            return values
        with self._physics.lock:
            sim = self.sim.status()
        for key in ("physics_rate_hz", "sim_time_s", "wheel_friction"):
            if key in sim:
                values[key] = sim[key]
        return values
