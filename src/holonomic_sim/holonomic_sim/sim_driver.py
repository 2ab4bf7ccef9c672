"""The ``sim`` driver backend: the pybullet stand-in for the hardware.

Behind the same :class:`~holonomic_core.driver.Driver` interface as the real
motor drives: velocity (or torque) commands in, joint positions, velocities
and torques out, with each joint's speed and torque limits as the motor
model. Each :meth:`read` advances the physics by one control period
(``physics_rate / control_rate`` fixed steps), so the simulation runs exactly
as fast as the control loop calls it -- in real time under the base
controller, faster in offline tools -- and its clock is the driver's stamp.

Every joint is driven by a drive model (:mod:`holonomic_sim.drive_model`:
velocity loop at the drive's rate, torque limit, rotor inertia, friction,
encoder counts, command and feedback delays, a per-joint spread), as a real
motor drive would; ``sim.ideal_motors: true`` replaces it with pybullet's
ideal velocity motors (an infinitely stiff servo with a torque cap), for
comparison and for tests of the kinematics alone.

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
ideal_motors        --      ideal velocity motors instead of the drive model
lifted              --      base held in the air, wheels off the floor (bench test)
drive.*             ...     the drive model (see :func:`drive_specs`)
gui                 --      open the pybullet GUI instead of DIRECT mode
start_pose          m, rad  (x, y, yaw) of base_link in the world at start
physics_process     --      step the physics in a process of its own, on the wall clock
floor_tilt          deg     the floor rises along world +x by this angle (a ramp)
holding_brakes      --      disabled drives brake the joints (false: they turn freely)
================== ======= ============================================================

With ``sim.physics_process: true`` the world lives in a process of its own
(:mod:`holonomic_sim.physics_process`) that steps it in real time; ``read``
then returns the newest state without stepping (the plant no longer runs
inside the control cycle, as on a real robot) and the run is no longer
lock-step: a loop that calls faster than real time sees the same reading
again.

The driver talks to either through one interface, its *plant*
(:class:`Plant`): :class:`InProcessPlant` (the world in this process) or the
physics process's :class:`~holonomic_sim.physics_process.PhysicsLink`,
chosen once in ``configure``.
"""

from __future__ import annotations

import math
from typing import Protocol

import numpy as np

from holonomic_core.driver import Driver, DriverCommunicationError, GroundTruth, JointReading
from holonomic_core.schema import ConfigError, ParamSpec
from holonomic_sim.physics_process import PhysicsLink

#: a base tilted more than this has tipped over: stop reporting a valid state
_TIP_OVER = math.radians(30.0)


class Plant(Protocol):
    """What :class:`SimDriver` drives: the simulated robot, in this process
    (:class:`InProcessPlant`) or in the physics process
    (:class:`~holonomic_sim.physics_process.PhysicsLink`). Joint vectors
    are in the model's joint order."""

    #: the physics process's PID; None in this process
    pid: int | None

    def release(self) -> None:
        """Brakes released, every joint commanded to rest (activate)."""

    def hold(self) -> None:
        """Brakes on: the joints held still (deactivate)."""

    def command_velocities(self, velocities: np.ndarray) -> None:
        """Joint speeds [rad/s]."""

    def command_efforts(self, efforts: np.ndarray) -> None:
        """Joint torques [N m]."""

    def read(self) -> JointReading:
        """The joints as the drives' encoders report them, stamped with the
        sim time [s]; raises DriverCommunicationError when the base tipped
        over or the physics process ended."""

    @property
    def sim_time(self) -> float:
        """Sim time [s] of the latest state."""

    def ground_truth(self) -> GroundTruth:
        """base_link's true pose in odom and twist, at :attr:`sim_time`."""

    def wheel_contacts(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Floor contact points and planar friction forces in base_link [m], [N]."""

    def status(self) -> dict[str, str]:
        """Extra lines for the driver's status."""

    def close(self) -> None:
        """Release the world (or end the physics process)."""


class InProcessPlant:
    """The simulated robot in a world of this process: :meth:`read` steps
    the world by ``steps`` physics steps (one control period; 0 in a shared
    world, which its owner steps for every robot), then reports the joints
    with the encoders' zero errors ``reading_offset`` [rad] added."""

    pid = None

    def __init__(self, world, robot, steps: int, reading_offset: np.ndarray,
                 owns_world: bool):
        #: the pybullet world (holonomic_sim.world.SimWorld) and this robot in it
        self.world, self.robot = world, robot
        self._steps = steps
        self._reading_offset = reading_offset
        self._owns_world = owns_world

    def release(self) -> None:
        self.robot.command_velocities(np.zeros(len(self._reading_offset)))

    def hold(self) -> None:
        self.robot.idle()

    def command_velocities(self, velocities: np.ndarray) -> None:
        self.robot.command_velocities(velocities)

    def command_efforts(self, efforts: np.ndarray) -> None:
        self.robot.command_efforts(efforts)

    def read(self) -> JointReading:
        if self._steps:
            self.world.step(self._steps)
        if self.robot.tilt() > _TIP_OVER:
            raise DriverCommunicationError(
                f"the simulated base tipped over ({math.degrees(self.robot.tilt()):.0f} deg)",
                "pybullet")
        positions, velocities, efforts = self.robot.joint_states()
        # the encoders report the angle plus their zero's error and the
        # configured offset, which the controller subtracts again
        positions = positions + self._reading_offset
        # the reading's stamp: the time the positions describe [s, sim time]
        # (a drive's feedback is feedback_delay old), as the CAN drivers stamp theirs
        return JointReading(self.robot.sample_time, positions, velocities, efforts)

    @property
    def sim_time(self) -> float:
        return self.world.time

    def ground_truth(self) -> GroundTruth:
        # at the newest reading's stamp: the truth that goes with it
        return GroundTruth(self.robot.sample_time, *self.robot.sampled_truth())

    def wheel_contacts(self) -> tuple[np.ndarray, np.ndarray]:
        return self.robot.wheel_contacts()

    def status(self) -> dict[str, str]:
        return {}

    def close(self) -> None:
        if self._owns_world:
            self.world.close()
        else:               # a shared world goes on for the other robots
            self.robot.hold()


class SimDriver(Driver):
    name = "sim"
    supports_effort = True
    #: the simulated robot is a body of its own: :func:`holonomic_core.nominal.driver_for`
    #: passes the robot's nominal description as ``body``
    simulates_body = True

    def __init__(self, model, params, control_rate: float, world=None, body=None):
        """``model``: the controller's model (joint order and limits);
        ``body``: the simulated robot's nominal description, the drawing
        (:func:`holonomic_core.nominal.nominal_model`), which the hidden
        ``sim.*`` errors perturb; default ``model``. A calibration the
        controller loaded is in ``model`` only: it never changes the body or
        its encoders. ``world``: a shared
        :class:`~holonomic_sim.world.SimWorld` (a fleet in one simulation).
        Its owner then steps it once per control period for all robots, and
        ``read`` does not step; by default the driver owns a world of its own
        and steps it."""
        super().__init__(model, params, control_rate)
        if body is not None and tuple(body.joint_names) != tuple(model.joint_names):
            raise ConfigError("robot.kinematics", body.kind,
                              f"a body with the controller's joints {model.joint_names}")
        #: the simulated robot's nominal description (before the sim.* errors)
        self.body = model if body is None else body
        self._shared_world = world
        rate = float(params["sim.physics_rate"])
        ratio = rate / self.control_rate
        if abs(ratio - round(ratio)) > 1e-9 or round(ratio) < 1:
            raise ConfigError("sim.physics_rate", rate,
                              f"an integer multiple of control_rate ({self.control_rate:g} Hz)")
        self.substeps = int(round(ratio))
        self.physics_rate = rate
        self._plant: Plant | None = None
        #: simulated wheel radii [m] when sim.wheel_radius_spread > 0
        self.wheel_radii: list[float] | None = None
        #: the simulated geometry the sim.* errors changed: flat config keys
        #: -> true values (what a perfect calibration writes); every other
        #: key is as in the nominal description (:attr:`body`)
        self.hidden_truth: dict[str, float] = {}
        if params.get("sim.physics_process") and world is not None:
            raise ConfigError("sim.physics_process", True,
                              "false in a shared world (--fleet steps one world for all robots)")

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
            ParamSpec("sim.ideal_motors", "bool",
                      "Ideal motors: pybullet's velocity motor on every joint (reaches the "
                      "commanded speed within a physics step with up to max_effort) instead "
                      "of the drive model (sim.drive.*).",
                      default=False),
            ParamSpec("sim.lifted", "bool",
                      "Hold the base in the air, wheels off the floor (a bench test, as "
                      "holonomic-drive-test asks of a real robot); ground truth stays at "
                      "the start.",
                      default=False),
            ParamSpec("sim.floor_tilt", "double",
                      "Slope of the floor [deg]: a ramp rising along the world's +x axis (a "
                      "rotation about world y; negative: falling along +x), so a base at "
                      "sim.start_pose yaw 0 faces uphill. Modelled by tilting gravity.",
                      default=0.0, minimum=-30.0, maximum=30.0),
            ParamSpec("sim.holding_brakes", "bool",
                      "The simulated joints have holding brakes: disabled drives (disarmed, "
                      "safety.disarm_mode coast, a fault) brake them. false: disabled drives "
                      "let them turn freely (an ODrive or CiA 402 drive without a brake: a "
                      "base on a ramp rolls).", default=True),
            ParamSpec("sim.physics_process", "bool",
                      "Step the physics (pybullet and the drive model) in a process of its own "
                      "on the wall clock instead of inside each read: the control loop writes "
                      "commands and takes the newest state, as with real drives (the plant's "
                      "CPU leaves the control cycle); not lock-step, so runs are not "
                      "reproducible step for step (docs/realtime.md).",
                      default=False),
        ] + drive_specs()

    # -- lifecycle ---------------------------------------------------------------
    def _on_configure(self) -> None:
        from holonomic_sim.world import Pose2D, SimError, SimWorld

        p = self.params
        if p.get("sim.physics_process"):
            link = PhysicsLink(self.body, p, self.control_rate)
            self._plant = link
            info = link.info
            self.hidden_truth = info["hidden_truth"]
            self.wheel_radii = info["wheel_radii"]
            self.friction = info["friction"]
            return
        start = tuple(p["sim.start_pose"])
        if len(start) != 3:
            raise ConfigError("sim.start_pose", start, "exactly 3 numbers (x, y, yaw)")
        n_wheels = sum(name.endswith("wheel_joint") for name in self.model.joint_names)
        rng = np.random.default_rng(p["sim.seed"])
        friction = p["sim.wheel_friction"] * (
            1.0 + p["sim.friction_spread"] * rng.uniform(-1.0, 1.0, n_wheels))
        body_model = self._body_model(rng)
        # the physical robot's encoders read (angle - the drawing's
        # correction) + the zero error: a controller with the drawing's
        # config adds the correction back and sees angle + error; one with a
        # calibrated correction (drawing's - error) sees the angle
        reading_offset = self._encoder_zeros(rng) - self.body.zero_corrections
        drive = None if p["sim.ideal_motors"] else drive_spec(self.model, p)
        # the drives' spread has its own stream: adding it left the friction
        # and radius draws of a seed unchanged
        drive_rng = np.random.default_rng([p["sim.seed"], 1])
        shared = self._shared_world
        world = None
        try:
            if shared is not None:
                if abs(shared.dt * self.physics_rate - 1.0) > 1e-9:
                    raise ConfigError("sim.physics_rate", self.physics_rate,
                                      f"the shared world's rate ({1 / shared.dt:g} Hz)")
                if shared.floor_tilt != p["sim.floor_tilt"]:
                    raise ConfigError("sim.floor_tilt", p["sim.floor_tilt"],
                                      f"the shared world's tilt ({shared.floor_tilt:g} deg)")
                world = shared
            else:
                world = SimWorld(self.physics_rate, gui=p["sim.gui"],
                                 floor_tilt=p["sim.floor_tilt"])
            robot = world.add_robot(body_model, Pose2D(*start), friction, drive,
                                    drive_rng, lifted=p["sim.lifted"])
            robot.holding_brakes = bool(p["sim.holding_brakes"])
        except SimError as exc:
            if world is not None and shared is None:
                world.close()
            raise DriverCommunicationError(str(exc), "pybullet") from exc
        if shared is None:
            world.settle()      # odom = where base_link rests once settled
        self._plant = InProcessPlant(world, robot, 0 if shared is not None else self.substeps,
                                     reading_offset, owns_world=shared is None)
        self.friction = friction

    def _body_model(self, rng: np.random.Generator):
        """The model the simulated body is built from: the nominal
        description (:attr:`body`), with per-wheel radius, caster offset or
        wheel separation errors (``sim.*_spread``), which the controller
        does not know about -- the actuator conflict and slip of real,
        imperfect wheels. Records the truth in :attr:`hidden_truth`."""
        p = self.params
        nominal = self.body
        kin = nominal.kinematics
        casters = getattr(kin, "casters", None)
        flat = dict(nominal.params)
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
                                  f"0 for kinematics '{nominal.kind}' (casters only)")
            for caster, u in zip(casters, rng.uniform(-1.0, 1.0, len(casters))):
                changed[f"pcv.{caster.name}.caster_offset"] = \
                    caster.caster_offset * (1.0 + offset * u)
        separation = p["sim.wheel_separation_spread"]
        if separation > 0.0:
            if casters is not None:
                raise ConfigError("sim.wheel_separation_spread", separation,
                                  f"0 for kinematics '{nominal.kind}' (DDROT only)")
            changed["ddrot.half_wheel_separation"] = kin.a * (
                1.0 + separation * rng.uniform(-1.0, 1.0))
        self.hidden_truth = dict(changed)
        if not changed:
            return nominal
        from holonomic_core.config import build_model

        flat.update(changed)
        return build_model(flat)[0]

    def _encoder_zeros(self, rng: np.random.Generator) -> np.ndarray:
        """Per joint, the error [rad] of the encoder's zero (sim.steer_zero_spread):
        steering joints and the turret; recorded in :attr:`hidden_truth` as
        the zero_correction a perfect calibration writes."""
        spread = self.params["sim.steer_zero_spread"]
        names = self.body.joint_names
        zeros = np.zeros(len(names))
        if spread > 0.0:
            steer = [i for i, n in enumerate(names) if n.endswith(("steer_joint", "turret_joint"))]
            zeros[steer] = spread * rng.uniform(-1.0, 1.0, len(steer))
            corrections = self.body.zero_corrections
            for i in steer:
                self.hidden_truth[f"joints.{names[i]}.zero_correction"] = float(
                    corrections[i] - zeros[i])
        return zeros

    def _on_activate(self) -> None:
        self._plant.release()

    def _on_deactivate(self) -> None:
        self._plant.hold()

    def _on_quick_stop(self) -> None:
        # the drives' speed loops to zero at full torque, then held there
        # (CiA 402 quick stop options 5-8: stay in QUICK STOP ACTIVE) until
        # the next activate; braked, never coasting
        self._plant.command_velocities(np.zeros(len(self.model.joint_names)))

    def _on_close(self) -> None:
        if self._plant is not None:         # None: configure failed
            self._plant.close()
            self._plant = None

    # -- I/O ----------------------------------------------------------------------
    def _on_read(self) -> JointReading:
        # the reading and its stamp: InProcessPlant.read / PhysicsLink.read
        return self._plant.read()

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        self._plant.command_velocities(velocities)

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        self._plant.command_efforts(efforts)

    # -- capabilities -------------------------------------------------------------
    @property
    def plant(self) -> Plant | None:
        """The simulated robot this driver drives (:class:`InProcessPlant`,
        or the physics process's link with sim.physics_process); None
        before configure and after close. For tests and tools that reach
        into the simulation (the in-process plant's ``world`` and ``robot``)."""
        return self._plant

    @property
    def physics_pid(self) -> int | None:
        """The physics process's PID (sim.physics_process), else None."""
        return None if self._plant is None else self._plant.pid

    def sim_time(self) -> float | None:
        return None if self._plant is None else self._plant.sim_time

    def ground_truth(self) -> GroundTruth | None:
        return None if self._plant is None else self._plant.ground_truth()

    def wheel_contacts(self) -> tuple[np.ndarray, np.ndarray] | None:
        """The floor's contact points on the robot and their planar friction
        forces, in base_link ([m], [N]; n x 2 each); simulation only. With
        sim.physics_process a round trip to the physics process (None if it
        does not answer)."""
        return None if self._plant is None else self._plant.wheel_contacts()

    def status(self) -> dict[str, str]:
        values = super().status()
        values.update({"physics_rate_hz": f"{self.physics_rate:g}",
                       "substeps": str(self.substeps),
                       "motors": "ideal" if self.params["sim.ideal_motors"] else "drive model"})
        if self.wheel_radii:
            values["simulated_wheel_radii"] = " ".join(f"{r:.5f}" for r in self.wheel_radii)
        if self._plant is not None:
            values["sim_time_s"] = f"{self.sim_time():.3f}"
            values["wheel_friction"] = " ".join(f"{mu:.3f}" for mu in self.friction)
            values.update(self._plant.status())
        return values


def drive_specs() -> list[ParamSpec]:
    """Schema of ``sim.drive.*``: the drive model's parameters.

    The defaults describe a small geared BLDC servo of the kind these bases
    use (a Maxon EC 45 flat class motor on a planetary gearbox, driven by an
    ODrive / EPOS4 class drive over CAN); each description says where its
    number comes from. Fit them to a real drive with ``holonomic-drive-test``.
    """
    return [
        ParamSpec("sim.drive.bandwidth", "double",
                  "Closed-loop bandwidth of each joint's velocity loop where it was tuned "
                  "(sim.drive.tuned_on) [Hz]: Kp = J 2 pi f (J: the joint's inertia there, "
                  "rotor included). Default: 40 Hz, mid-range of velocity loops tuned for stiffness without "
                  "ringing on a 1 kHz position read-out (EPOS4 / ODrive tuning guides put "
                  "velocity loops at tens of Hz).",
                  default=40.0, minimum=0.1, maximum=500.0),
        ParamSpec("sim.drive.tuned_on", "string",
                  "Where the velocity loops were tuned, i.e. which inertia J the gains are "
                  "designed for. 'lifted' (default): the joint alone, base held (a bench "
                  "tuning); on the floor, where each wheel also moves its share of the base "
                  "(5-20x the inertia), these loops are ~2 Hz. 'floor': the robot on its "
                  "wheels, the base's mass and yaw inertia reflected to each joint through the "
                  "wheel radii, caster offsets and gears, as drives are tuned on a real base; "
                  "sim.drive.bandwidth is then the loaded bandwidth. Not the default: at the "
                  "1 ms physics step such a loop is unstable on a wheel that unloads (lifted, "
                  "or slipping: Kp h / J is ~5 > 2) and chatters at its torque limit "
                  "(docs/drive_model.md).",
                  default="lifted", choices=("floor", "lifted")),
        ParamSpec("sim.drive.integral_ratio", "double",
                  "Integrator corner of the velocity PI over its bandwidth [-]: "
                  "Ki = Kp 2 pi f r. Default 0.05: the integrator removes the friction's "
                  "steady-state error (within ~3 / (2 pi f r) s) while adding only ~5 % "
                  "overshoot to the bench step (a corner more than a decade below crossover).",
                  default=0.05, minimum=0.0, maximum=1.0),
        ParamSpec("sim.drive.loop_rate", "double",
                  "Rate of the drives' velocity loop [Hz]; sub-stepped inside each physics step "
                  "when faster. Default 1 kHz, the velocity-loop rate of common CAN servo "
                  "drives' (and of the simulated physics); ODrive runs 8 kHz, EPOS4 2.5 kHz.",
                  default=1000.0, minimum=10.0, maximum=40000.0),
        ParamSpec("sim.drive.wheel_gear_ratio", "double",
                  "Motor turns per wheel turn [-] (reflects the rotor inertia, scales the encoder "
                  "counts). Default 10: a one-stage planetary gearhead under a 5-6 cm wheel, "
                  "as in the example CAN wiring of config/xr4000.yaml.",
                  default=10.0, minimum=1.0, maximum=1000.0),
        ParamSpec("sim.drive.steer_gear_ratio", "double",
                  "Motor turns per turn of a steering or turret joint [-]. Default 20, as in the "
                  "example CAN wiring of config/xr4000.yaml.",
                  default=20.0, minimum=1.0, maximum=1000.0),
        ParamSpec("sim.drive.rotor_inertia", "double",
                  "Rotor inertia of each motor, motor side [kg m^2]; the joint sees N^2 times it. "
                  "Default 1.35e-5: Maxon EC 45 flat 70 W (135 g cm^2, datasheet).",
                  default=1.35e-5, minimum=0.0, maximum=1.0),
        ParamSpec("sim.drive.coulomb_friction", "double",
                  "Coulomb (dry) friction of each joint, joint side [N m]: gearbox and bearings. "
                  "Default 0.1: an EC 45 flat's no-load current (~0.15 A at 24 V) times its "
                  "torque constant (~0.04 N m/A) through a 10:1 gearhead at ~70 % no-load "
                  "efficiency, rounded up.",
                  default=0.1, minimum=0.0, maximum=100.0),
        ParamSpec("sim.drive.viscous_friction", "double",
                  "Viscous friction of each joint, joint side [N m s/rad]. Default 0.002: "
                  "about 0.05 N m of drag at 24 rad/s (top wheel speed), a quarter of the "
                  "no-load loss of a geared motor of this class.",
                  default=0.002, minimum=0.0, maximum=10.0),
        ParamSpec("sim.drive.encoder_counts", "int",
                  "Encoder counts per motor turn [-]; the driver reads positions in whole counts "
                  "of counts x gear ratio per joint turn. Default 16384: a 14-bit absolute "
                  "magnetic encoder (AS5047P, AMT21), as in the example cia402 wiring.",
                  default=16384, minimum=1, maximum=2 ** 30),
        ParamSpec("sim.drive.command_delay", "double",
                  "Delay from a written command to the drive acting on it [s], rounded to physics "
                  "steps. Default 0.002: a CAN frame at 1 Mbit/s (0.13 ms) waiting for the drive's "
                  "next cycle and a SYNC-applied setpoint (CiA 402 applies at the next SYNC).",
                  default=0.002, minimum=0.0, maximum=0.5),
        ParamSpec("sim.drive.feedback_delay", "double",
                  "Age of the joint positions and speeds the driver reads [s], rounded to physics "
                  "steps. Default 0.005: half the 10 ms period of an ODrive's cyclic encoder "
                  "message (encoder_msg_rate_ms = 10, the example wiring's feedback rate).",
                  default=0.005, minimum=0.0, maximum=0.5),
        ParamSpec("sim.drive.spread", "double",
                  "Relative spread of each joint's loop gains and friction around the nominal "
                  "values: x_i = x (1 + spread u_i), u_i uniform in [-1, 1], drawn from sim.seed "
                  "(no two drives are alike) [-]. Default 0.1: unit-to-unit spread of motor "
                  "constants and gearbox losses (datasheet tolerances are about +-10 %).",
                  default=0.1, minimum=0.0, maximum=0.9),
    ]


def drive_spec(model, params):
    """The :class:`~holonomic_sim.drive_model.DriveSpec` of ``model``'s joints
    from validated ``sim.drive.*`` ``params``. Wheel joints (``*wheel_joint``)
    take the wheel gear ratio, the others (steering, turret) the steering one;
    each joint's torque limit is its ``max_effort``."""
    from holonomic_sim.drive_model import DriveSpec

    n = len(model.joint_names)
    ratio = np.array([params["sim.drive.wheel_gear_ratio"] if name.endswith("wheel_joint")
                      else params["sim.drive.steer_gear_ratio"] for name in model.joint_names])
    return DriveSpec(
        bandwidth=params["sim.drive.bandwidth"],
        integral_ratio=params["sim.drive.integral_ratio"],
        tuned_on=params["sim.drive.tuned_on"],
        loop_rate=params["sim.drive.loop_rate"],
        torque_limit=np.array([j.max_effort for j in model.joint_limits]),
        coulomb=np.full(n, params["sim.drive.coulomb_friction"]),
        viscous=np.full(n, params["sim.drive.viscous_friction"]),
        gear_ratio=ratio,
        rotor_inertia=params["sim.drive.rotor_inertia"],
        encoder_counts=params["sim.drive.encoder_counts"],
        command_delay=params["sim.drive.command_delay"],
        feedback_delay=params["sim.drive.feedback_delay"],
        spread=params["sim.drive.spread"])
