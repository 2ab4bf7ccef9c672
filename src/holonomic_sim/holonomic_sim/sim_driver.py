"""The ``sim`` driver backend: the pybullet stand-in for the hardware.

Behind the same :class:`~holonomic_core.driver.Driver` interface as the real
motor drives: velocity (or torque) commands in, joint positions, velocities
and torques out, with each joint's speed and torque limits as the motor
model. Each :meth:`read` advances the physics by one control period
(``physics_rate / control_rate`` fixed steps), so the simulation runs exactly
as fast as the control loop calls it -- in real time under the base
controller, faster in offline tools -- and its clock is the driver's stamp.

Disarmed (configured but not active), the motors hold their joints still, as
a drive with its brake engaged would.

Parameters (``sim.*``, in the robot config):

================== ======= ============================================================
key                 unit    meaning
================== ======= ============================================================
physics_rate        Hz      fixed physics step rate, an integer multiple of control_rate
wheel_friction      --      Coulomb friction coefficient of the drive wheels on the floor
friction_spread     --      relative spread of per-wheel friction (uneven floor), 0..0.9
*_spread            --/rad  hidden geometry errors: wheel radius, caster offset, wheel
                            separation, steering/turret encoder zero (calibration tests)
seed                --      seed of the spreads (reproducible runs)
gui                 --      open the pybullet GUI instead of DIRECT mode
start_pose          m, rad  (x, y, yaw) of base_link in the world at start
================== ======= ============================================================
"""

from __future__ import annotations

import math

import numpy as np

from holonomic_core.driver import Driver, DriverCommunicationError, GroundTruth, JointReading
from holonomic_core.schema import ConfigError, ParamSpec

#: a base tilted more than this has tipped over: stop reporting a valid state
_TIP_OVER = math.radians(30.0)


class SimDriver(Driver):
    name = "sim"
    supports_effort = True

    def __init__(self, model, params, control_rate: float, world=None):
        """``world``: a shared :class:`~holonomic_sim.world.SimWorld` (a fleet
        in one simulation). Its owner then steps it once per control period
        for all robots, and ``read`` does not step; by default the driver
        owns a world of its own and steps it."""
        super().__init__(model, params, control_rate)
        self._shared_world = world
        rate = float(params["sim.physics_rate"])
        ratio = rate / self.control_rate
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ConfigError("sim.physics_rate", rate,
                              f"an integer multiple of control_rate ({self.control_rate:g} Hz)")
        self.substeps = int(round(ratio))
        self.physics_rate = rate
        self._world = None
        self._robot = None
        #: simulated wheel radii [m] when sim.wheel_radius_spread > 0
        self.wheel_radii: list[float] | None = None
        #: the simulated geometry where it differs from the config: flat
        #: config keys -> true values (what a perfect calibration writes)
        self.hidden_truth: dict[str, float] = {}
        self._reading_offset = np.zeros(len(model.joint_names))

    @classmethod
    def param_specs(cls, model) -> list[ParamSpec]:
        return [
            ParamSpec("sim.physics_rate", "double",
                      "Fixed physics step rate [Hz]; an integer multiple of control_rate.",
                      default=1000.0, minimum=10.0, maximum=20000.0),
            ParamSpec("sim.wheel_friction", "double",
                      "Coulomb friction coefficient between the drive wheels and the floor [-].",
                      default=1.0, minimum=0.0, exclusive_minimum=True, maximum=10.0),
            ParamSpec("sim.friction_spread", "double",
                      "Relative spread of each wheel's friction around wheel_friction: "
                      "mu_i = mu (1 + spread u_i), u_i uniform in [-1, 1] [-].",
                      default=0.0, minimum=0.0, maximum=0.9),
            ParamSpec("sim.wheel_radius_spread", "double",
                      "Relative error of each simulated wheel's radius against the config "
                      "(worn or unevenly inflated tyres): r_i = r (1 + spread u_i), u_i "
                      "uniform in [-1, 1]; the controller keeps the nominal radius (casters, "
                      "or a DDROT's two wheels) [-].",
                      default=0.0, minimum=0.0, maximum=0.2),
            ParamSpec("sim.caster_offset_spread", "double",
                      "Relative error of each simulated caster offset against the config: "
                      "b_i = b (1 + spread u_i), u_i uniform in [-1, 1], hidden from the "
                      "controller (PCV only) [-].", default=0.0, minimum=0.0, maximum=0.5),
            ParamSpec("sim.wheel_separation_spread", "double",
                      "Relative error of the simulated DDROT wheel separation against the "
                      "config: a = a_config (1 + spread u), u uniform in [-1, 1] [-].",
                      default=0.0, minimum=0.0, maximum=0.2),
            ParamSpec("sim.steer_zero_spread", "double",
                      "Error of each steering (PCV) or turret (DDROT) encoder's zero: the "
                      "simulated encoder reads angle + spread u_i, u_i uniform in [-1, 1] "
                      "(the controller's zero_correction removes the configured part) [rad].",
                      default=0.0, minimum=0.0, maximum=0.5),
            ParamSpec("sim.seed", "int", "Seed of the per-wheel friction and geometry spreads.",
                      default=0, minimum=0, maximum=2 ** 31 - 1),
            ParamSpec("sim.gui", "bool", "Open the pybullet GUI (needs a display).",
                      default=False),
            ParamSpec("sim.start_pose", "double_array",
                      "Start pose (x, y, yaw) of base_link in the world [m, m, rad]; "
                      "ground truth is reported relative to it.",
                      default=(0.0, 0.0, 0.0), minimum=-1e4, maximum=1e4, min_length=3),
        ]

    # -- lifecycle ---------------------------------------------------------------
    def _on_configure(self) -> None:
        from holonomic_sim.world import Pose2D, SimError, SimWorld

        p = self.params
        start = tuple(p["sim.start_pose"])
        if len(start) != 3:
            raise ConfigError("sim.start_pose", start, "exactly 3 numbers (x, y, yaw)")
        n_wheels = sum(name.endswith("wheel_joint") for name in self.model.joint_names)
        rng = np.random.default_rng(p["sim.seed"])
        friction = p["sim.wheel_friction"] * (
            1.0 + p["sim.friction_spread"] * rng.uniform(-1.0, 1.0, n_wheels))
        body_model = self._body_model(rng)
        # the physical robot's encoders read (angle - its configured
        # correction) + the zero error; a controller with the same config
        # adds the correction back and sees angle + error
        self._reading_offset = self._encoder_zeros(rng) - self.model.zero_corrections
        try:
            if self._shared_world is not None:
                if abs(self._shared_world.dt * self.physics_rate - 1.0) > 1e-9:
                    raise ConfigError("sim.physics_rate", self.physics_rate,
                                      f"the shared world's rate ({1 / self._shared_world.dt:g} Hz)")
                self._world = self._shared_world
            else:
                self._world = SimWorld(self.physics_rate, gui=p["sim.gui"])
            self._robot = self._world.add_robot(body_model, Pose2D(*start), friction)
        except SimError as exc:
            if self._world is not None and self._shared_world is None:
                self._world.close()
            raise DriverCommunicationError(str(exc), "pybullet") from exc
        if self._shared_world is None:
            self._world.settle()      # odom = where base_link rests once settled
        self.friction = friction

    def _body_model(self, rng: np.random.Generator):
        """The model the simulated body is built from: the controller's, or
        with per-wheel radius, caster offset or wheel separation errors
        (``sim.*_spread``), which the controller does not know about -- the
        actuator conflict and slip of real, imperfect wheels. Records the
        truth in :attr:`hidden_truth`."""
        p = self.params
        kin = self.model.kinematics
        casters = getattr(kin, "casters", None)
        flat = dict(self.model.params)
        changed = {}
        radius = p["sim.wheel_radius_spread"]
        if radius > 0.0:
            if casters is not None:
                for caster, u in zip(casters, rng.uniform(-1.0, 1.0, len(casters))):
                    changed[f"pcv.{caster.name}.wheel_radius"] = \
                        caster.wheel_radius * (1.0 + radius * u)
                self.wheel_radii = [changed[f"pcv.{c.name}.wheel_radius"] for c in casters]
            else:
                sides = rng.uniform(-1.0, 1.0, 2)
                changed["ddrot.left_wheel_radius"] = kin.r_left * (1.0 + radius * sides[0])
                changed["ddrot.right_wheel_radius"] = kin.r_right * (1.0 + radius * sides[1])
                self.wheel_radii = [changed["ddrot.left_wheel_radius"],
                                    changed["ddrot.right_wheel_radius"]]
        offset = p["sim.caster_offset_spread"]
        if offset > 0.0:
            if casters is None:
                raise ConfigError("sim.caster_offset_spread", offset,
                                  f"0 for kinematics '{self.model.kind}' (casters only)")
            for caster, u in zip(casters, rng.uniform(-1.0, 1.0, len(casters))):
                changed[f"pcv.{caster.name}.caster_offset"] = \
                    caster.caster_offset * (1.0 + offset * u)
        separation = p["sim.wheel_separation_spread"]
        if separation > 0.0:
            if casters is not None:
                raise ConfigError("sim.wheel_separation_spread", separation,
                                  f"0 for kinematics '{self.model.kind}' (DDROT only)")
            changed["ddrot.half_wheel_separation"] = kin.a * (
                1.0 + separation * rng.uniform(-1.0, 1.0))
        self.hidden_truth = dict(changed)
        if not changed:
            return self.model
        from holonomic_core.model import build_model

        flat.update(changed)
        return build_model(flat)[0]

    def _encoder_zeros(self, rng: np.random.Generator) -> np.ndarray:
        """Per joint, the error [rad] of the encoder's zero (sim.steer_zero_spread):
        steering joints and the turret; recorded in :attr:`hidden_truth` as
        the zero_correction a perfect calibration writes."""
        spread = self.params["sim.steer_zero_spread"]
        names = self.model.joint_names
        zeros = np.zeros(len(names))
        if spread > 0.0:
            steer = [i for i, n in enumerate(names) if n.endswith(("steer_joint", "turret_joint"))]
            zeros[steer] = spread * rng.uniform(-1.0, 1.0, len(steer))
            corrections = self.model.zero_corrections
            for i in steer:
                self.hidden_truth[f"joints.{names[i]}.zero_correction"] = float(
                    corrections[i] - zeros[i])
        return zeros

    def _on_activate(self) -> None:
        self._robot.command_velocities(np.zeros(len(self.model.joint_names)))

    def _on_deactivate(self) -> None:
        self._robot.hold()

    def _on_close(self) -> None:
        if self._world is not None:
            if self._shared_world is None:
                self._world.close()
            else:
                self._robot.hold()
            self._world = None

    # -- I/O ----------------------------------------------------------------------
    def _on_read(self) -> JointReading:
        if self._shared_world is None:
            self._world.step(self.substeps)
        if self._robot.tilt() > _TIP_OVER:
            raise DriverCommunicationError(
                f"the simulated base tipped over ({math.degrees(self._robot.tilt()):.0f} deg)",
                "pybullet")
        positions, velocities, efforts = self._robot.joint_states()
        # the encoders report the angle plus their zero's error and the
        # configured offset, which the controller subtracts again
        positions = positions + self._reading_offset
        return JointReading(self._world.time, positions, velocities, efforts)

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        self._robot.command_velocities(velocities)

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        self._robot.command_efforts(efforts)

    # -- capabilities -------------------------------------------------------------
    def sim_time(self) -> float | None:
        return self._world.time if self._world is not None else None

    def ground_truth(self) -> GroundTruth | None:
        if self._robot is None:
            return None
        return GroundTruth(self._world.time, self._robot.pose(), self._robot.body_twist())

    def status(self) -> dict[str, str]:
        values = super().status()
        values.update({"physics_rate_hz": f"{self.physics_rate:g}",
                       "substeps": str(self.substeps)})
        if self.wheel_radii:
            values["simulated_wheel_radii"] = " ".join(f"{r:.5f}" for r in self.wheel_radii)
        if self._world is not None:
            values["sim_time_s"] = f"{self._world.time:.3f}"
            values["wheel_friction"] = " ".join(f"{mu:.3f}" for mu in self.friction)
        return values
