"""How a simulated robot drives to be calibrated, for the calibration
experiment (holonomic_sim.calibration_experiment) and the documented routes
(holonomic_sim.calibration_routes): the hidden faults each family gets, the
mode it drives in for a self-calibration, and the DDROT's measured line and
rotation with what a user with a tape measure reads off the floor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from holonomic_core.config import load_config
from holonomic_core.controller import BaseController
from holonomic_core.loop import ManualClock
from holonomic_core.nominal import driver_for
from holonomic_core.schema import ConfigError
from holonomic_core.se2 import relative_pose

#: hidden faults per family: +-2 % radii, +-10 % caster offsets (PCV) or
#: +-2 % wheel separation (DDROT), +-3 deg steering / turret encoder zeros
FAULTS = {
    "pcv": {"sim.wheel_radius_spread": 0.02, "sim.caster_offset_spread": 0.10,
            "sim.steer_zero_spread": math.radians(3.0)},
    "ddrot": {"sim.wheel_radius_spread": 0.02, "sim.wheel_separation_spread": 0.02,
              "sim.steer_zero_spread": math.radians(3.0)},
}
#: how each family drives for calibration: a PCV in torque mode, where the
#: joints follow the body (in velocity mode the stiff wheel and steering
#: loops impose the configured kinematics on the joints and the floor takes
#: the conflict as slip, so the joints alone cannot show the error); the
#: DDROT has no conflict to hide (three joints, three degrees of freedom)
# On the simulator's default drive model the readings are feedback_delay old
# and stamped with their sample time; the ground truth comes at that stamp.
CALIBRATION_DRIVE = {"pcv": {"control_mode": "torque"}, "ddrot": {}}


@dataclass
class ReferenceDrive:
    """A measured-line-and-rotation drive: the readings, and what a user
    with a tape measure reads off the floor (from the simulator's truth)."""

    config: object
    stamps: np.ndarray          # (N,) [s]
    positions: np.ndarray       # (N x joints) [rad], as the controller saw them
    hidden_truth: dict          # the simulator's hidden geometry (config keys)
    forward: float              # end of the straight run along its start heading [m]
    lateral: float              # ... to the left of that heading [m]
    turns: float                # revolutions of the rotation [-] (unsigned)
    heading: float              # heading change over the straight run [rad], ccw


def reference_drive(robot: str, sim_seed: int, distance: float = 5.0, turns: float = 3.0,
                    faults: dict | None = None, speed: float = 0.5,
                    spin_rate: float = 1.0) -> ReferenceDrive:
    """Offline (controller core + sim driver): rest 1 s, drive ``distance``
    [m] forward at ``speed`` [m/s] (commanded, open loop), rest 1.5 s, spin
    the drive about its axle ``turns`` revolutions at ``spin_rate`` [rad/s]
    with the turret locked (twist (b w sin phi, b w cos phi, w): the axle
    midpoint stays put), rest 1.5 s. A DDROT only. The measurements are
    taken from the true poses at rest, as a user would."""
    faults = FAULTS["ddrot"] if faults is None else faults
    merged = {**faults, "sim.seed": sim_seed, "cmd_timeout": 0.0, "enable_on_start": True}
    cfg = load_config(robot, merged)
    if cfg.model.kind != "ddrot":
        raise ConfigError("robot.kinematics", cfg.model.kind, "ddrot (a reference drive)")
    b = cfg.model.kinematics.b
    clock = ManualClock()
    stamps, readings, truths = [], [], []
    with driver_for(cfg) as driver:
        ctrl = BaseController(cfg, driver, clock=clock)
        ctrl.request_enable(True)

        def hold(seconds: float, command) -> None:
            end = clock.now + seconds
            while clock.now < end:
                if callable(command):
                    ctrl.set_command(command(ctrl.reading.positions))
                else:
                    ctrl.set_command(command)
                ctrl.step()
                clock.now = ctrl.reading.stamp
                stamps.append(clock.now)
                readings.append(ctrl.reading.positions.copy())
                truths.append(driver.ground_truth().pose.copy())

        still = (0.0, 0.0, 0.0)
        hold(1.0, still)
        at_start = len(truths) - 1
        hold(distance / speed, (speed, 0.0, 0.0))
        hold(1.5, still)
        at_line_end = len(truths) - 1
        hold(2 * math.pi * turns / spin_rate,
             lambda q: (b * spin_rate * math.sin(q[2]), b * spin_rate * math.cos(q[2]),
                        spin_rate))
        hold(1.5, still)
        hidden = dict(driver.hidden_truth)
    truth = np.array(truths)
    forward, lateral, heading = relative_pose(truth[at_start], truth[at_line_end])
    turned = np.unwrap(truth[at_line_end:, 2])
    return ReferenceDrive(cfg, np.array(stamps), np.array(readings), hidden, float(forward),
                          float(lateral), abs(float(turned[-1] - turned[0])) / (2 * math.pi),
                          float(heading))
