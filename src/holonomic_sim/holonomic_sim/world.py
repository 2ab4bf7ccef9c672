"""A pybullet world with a flat floor, stepped at a fixed rate.

Fixed time step and no real-time mode (gym-pybullet-drones); every pybullet
call passes ``physicsClientId`` so several worlds can live in one process.
A world holds any number of robots (:meth:`SimWorld.add_robot`), each a
generated URDF with motor models on its joints.
"""

from __future__ import annotations

import math
import os
import tempfile
from collections import deque
from dataclasses import dataclass

import numpy as np
import pybullet as pb

from holonomic_core.description import frictionless_links, generate_urdf
from holonomic_core.link_transforms import rotate
from holonomic_core.se2 import relative_pose, rotate as rotate_2d, yaw_of_quaternion


#: [m] how high a lifted base (a bench test) is held above its resting height
_LIFT = 0.1
# the per-physics-step calls, looked up once (a drive-model step makes two)
_set_motors, _joint_states, _TORQUE = (pb.setJointMotorControlArray, pb.getJointStates,
                                       pb.TORQUE_CONTROL)
_base_pose, _base_velocity = pb.getBasePositionAndOrientation, pb.getBaseVelocity


class SimError(RuntimeError):
    """The physics server could not be started or a robot not loaded."""


@dataclass(frozen=True)
class Pose2D:
    """Planar pose [m, m, rad]."""

    x: float = 0.0
    y: float = 0.0
    yaw: float = 0.0

    def inverse_compose(self, x: float, y: float, yaw: float) -> np.ndarray:
        """``self^-1 * (x, y, yaw)``: a world pose expressed in this pose's frame."""
        return relative_pose((self.x, self.y, self.yaw), (x, y, yaw))


class SimRobot:
    """One robot in a :class:`SimWorld`: joint motors, encoders, ground truth.

    Joint arrays are in ``model.joint_names`` order. Two motor models:

    * with a :class:`~holonomic_sim.drive_model.DriveSpec` (``drive``): every
      joint is driven by a :class:`~holonomic_sim.drive_model.DriveBank`
      (velocity loop, torque limit, delays, encoder, friction) whose torques
      are applied with ``TORQUE_CONTROL`` each physics step; the rotor's
      reflected inertia is added to the joint's child link and Coulomb
      friction is pybullet's joint motor with zero target speed and the
      friction torque as its force (an implicit constraint: it holds a joint
      at rest below the breakaway torque without chattering);
    * without (ideal motors): each joint is pybullet's velocity motor, which
      reaches its target speed within a step with at most its ``max_effort``
      torque (never commanding more than ``max_velocity``), or, in torque
      mode, applies a torque clipped to ``max_effort``.

    ``lifted``: the base is held in the air, wheels off the floor (a bench test).
    """

    def __init__(self, world: "SimWorld", model, start: Pose2D, friction: np.ndarray,
                 drive=None, drive_rng: np.random.Generator | None = None,
                 lifted: bool = False):
        self.world = world
        self.model = model
        self.start = start
        self.lifted = lifted
        #: whether the disabled drives' joints are braked (idle) or free
        self.holding_brakes = True
        cid = self._client = world.client
        urdf = generate_urdf(model)
        with tempfile.TemporaryDirectory(prefix="holonomic_sim_") as tmp:
            path = os.path.join(tmp, f"{model.name}.urdf")
            with open(path, "w") as handle:
                handle.write(urdf)
            try:
                # loadURDF places the root link's URDF origin (on the floor)
                self.body = pb.loadURDF(
                    path, [start.x, start.y, _LIFT if lifted else 0.0],
                    pb.getQuaternionFromEuler([0.0, 0.0, start.yaw]),
                    flags=pb.URDF_USE_IMPLICIT_CYLINDER | pb.URDF_USE_INERTIA_FROM_FILE,
                    useFixedBase=lifted, physicsClientId=cid)
                # a lifted robot's drives tuned on the floor: the gains come
                # from a free-standing twin's inertia (removed once they are)
                twin = pb.loadURDF(
                    path, [start.x, start.y, -10.0],
                    pb.getQuaternionFromEuler([0.0, 0.0, start.yaw]),
                    flags=pb.URDF_USE_IMPLICIT_CYLINDER | pb.URDF_USE_INERTIA_FROM_FILE,
                    physicsClientId=cid) if (
                        lifted and drive is not None and drive.tuned_on == "floor") else None
            except pb.error as exc:
                raise SimError(f"pybullet could not load the generated URDF: {exc}") from exc
        # pybullet's base pose is the root's inertial frame (the body above
        # the floor); base_link's URDF origin is this offset below it.
        self._com_in_link = tuple(pb.getDynamicsInfo(self.body, -1, physicsClientId=cid)[3])
        joints_by_name, links_by_name = {}, {}
        for index in range(pb.getNumJoints(self.body, physicsClientId=cid)):
            info = pb.getJointInfo(self.body, index, physicsClientId=cid)
            joints_by_name[info[1].decode()] = index
            links_by_name[info[12].decode()] = index
        self.joint_indices = [joints_by_name[name] for name in model.joint_names]
        self.max_velocity = model.max_joint_velocity
        self.max_effort = np.array([j.max_effort for j in model.joint_limits])
        # per-cycle calls take Python lists: built once
        self._vmax = self.max_velocity.tolist()
        self._forces = self.max_effort.tolist()
        # No artificial drag: pybullet's default link damping slows every body.
        for link in [-1] + list(links_by_name.values()):
            pb.changeDynamics(self.body, link, linearDamping=0.0, angularDamping=0.0,
                              physicsClientId=cid)
        # Traction only at the wheels: friction set explicitly on each.
        wheels = [j for j, name in zip(self.joint_indices, model.joint_names)
                  if name.endswith("wheel_joint")]
        if len(friction) != len(wheels):
            raise ValueError(f"{len(friction)} friction values for {len(wheels)} wheels")
        for link, mu in zip(wheels, friction):
            pb.changeDynamics(self.body, link, lateralFriction=float(mu), rollingFriction=0.0,
                              spinningFriction=0.0, physicsClientId=cid)
        for name in frictionless_links(model):
            pb.changeDynamics(self.body, links_by_name[name], lateralFriction=0.0,
                              rollingFriction=0.0, spinningFriction=0.0, physicsClientId=cid)
        self._torque_mode = False
        self._efforts = np.zeros(len(self.joint_indices))
        #: the drives (None: ideal motors)
        self.drives = None
        # the base's state at each recorded joint state while the drives'
        # feedback is delayed: the truth at the instant a reading describes
        self._base_history: deque | None = None
        if drive is not None:
            self._attach_drives(drive, drive_rng or np.random.default_rng(0), twin)
        self.hold()

    def _attach_drives(self, spec, rng: np.random.Generator, twin: int | None) -> None:
        """Rotor inertia on the joints, then the drives, their gains designed
        for the inertia of ``spec.tuned_on`` (``twin``: a free-standing copy of
        a lifted body, for its floor inertia; removed here)."""
        from holonomic_sim.drive_model import DriveBank

        cid = self._client
        # the rotor spins N times faster than the joint: N^2 J_rotor about the
        # joint axis, added to the child link's inertia (the link's inertial
        # frames are unrotated, so the axis is a principal axis) as a thin
        # disc's (half of it about the two other axes), which keeps the
        # tensor physical (Bullet checks Ixx + Iyy >= Izz)
        bodies = [self.body] if twin is None else [self.body, twin]
        for joint, extra in zip(self.joint_indices, spec.reflected_inertia.tolist()):
            axis = np.abs(np.array(pb.getJointInfo(self.body, joint, physicsClientId=cid)[13]))
            diagonal = np.array(pb.getDynamicsInfo(self.body, joint, physicsClientId=cid)[2])
            disc = extra * (1.0 + axis ** 2) / 2.0
            for body in bodies:
                pb.changeDynamics(body, joint, localInertiaDiagonal=(diagonal + disc).tolist(),
                                  physicsClientId=cid)
        if spec.tuned_on == "lifted":
            inertia = self._locked_inertia()
        else:
            inertia = self.loaded_inertia(twin)
        if twin is not None:
            pb.removeBody(twin, physicsClientId=cid)
        self.drives = DriveBank(spec, inertia, self.world.dt, rng)
        if self.drives.feedback_steps > 0:
            self._base_history = deque(maxlen=self.drives.feedback_steps + 1)
        self._coulomb = self.drives.coulomb.tolist()
        self._set_joint_friction(self._coulomb)
        self._braked = False
        self._record_drive_states()

    def _set_joint_friction(self, torques: list[float]) -> None:
        """pybullet's joint motor at zero speed with ``torques`` [N m] as its
        force: Coulomb friction, or a holding brake."""
        pb.setJointMotorControlArray(self.body, self.joint_indices, pb.VELOCITY_CONTROL,
                                     targetVelocities=[0.0] * len(torques), forces=torques,
                                     physicsClientId=self.world.client)

    def _release_brakes(self) -> None:
        if self._braked:
            self._set_joint_friction(self._coulomb)
            self._braked = False

    def _joint_space_mass(self, body: int | None = None) -> tuple[np.ndarray, list[int]]:
        """pybullet's mass matrix of ``body`` (default this robot's) at its
        current pose: rows of the floating base first (angular then linear
        velocity of the base's centre of mass in the base's frame, 6 of them
        unless the base is fixed), then one per movable joint; and the indices
        of those joints."""
        cid = self._client
        body = self.body if body is None else body
        movable = [j for j in range(pb.getNumJoints(body, physicsClientId=cid))
                   if pb.getJointInfo(body, j, physicsClientId=cid)[2] != pb.JOINT_FIXED]
        q = [s[0] for s in pb.getJointStates(body, movable, physicsClientId=cid)]
        return np.array(pb.calculateMassMatrix(body, q, physicsClientId=cid)), movable

    def _locked_inertia(self) -> np.ndarray:
        """Each joint's inertia [kg m^2] with the base and the other joints
        held: the diagonal of the joint-space mass matrix at the current pose."""
        mass, movable = self._joint_space_mass()
        offset = mass.shape[0] - len(movable)          # 6 base rows when floating
        return np.array([mass[offset + movable.index(j), offset + movable.index(j)]
                         for j in self.joint_indices])

    def loaded_inertia(self, twin: int | None = None) -> np.ndarray:
        """Each joint's inertia [kg m^2] with the robot on the floor: what
        its velocity loop drives when the base moves as the joints say.

        On the floor the wheels roll without slipping, so joint rates ``dq``
        [rad/s] move base_link with the planar twist ``x = C dq`` (``C``: the
        model's ``J_joint_to_base``, 3 x n; for a PCV the slip-minimising fit
        C#, exact for every consistent motion, ``C A = I`` with ``A`` the
        inverse kinematics ``dq = A x``). The whole multibody's generalised
        velocity is then ``u = T dq``: ``T`` stacks the base's spatial velocity
        (angular ``(0, 0, wz)``; its centre of mass's linear velocity
        ``v_o + wz z x c``, ``c`` the centre of mass seen from base_link's
        origin) over the identity for the joints. With ``M`` pybullet's
        floating-base mass matrix (every link, rotors included) the
        joint-space inertia is ``M_q = T^T M T``: the base's mass and yaw
        inertia reflected through the wheel radii, caster offsets and gears.

        In a consistent acceleration ``ddq = A a`` the joints' torques are
        ``tau = M_q ddq`` (= C^T M_b a for a rigid body: the base's inertial
        force shared among the joints as C^T shares it), so joint ``i``'s
        loop sees ``tau_i / ddq_i``. That ratio depends on the motion: it is
        fitted, per joint, by least squares over the three unit motions
        ``a`` = forward, sideways and turning (the turn scaled by the
        radius of gyration ``rho = sqrt(I_z / m)``, so that each moves the
        mass alike): ``J_i = sum_k tau_ik ddq_ik / sum_k ddq_ik^2``. For a
        differential drive (no turret; wheel radius r, half track a, wheel
        joint inertia J_w) the forward share is ``J_w + m r^2 / 2`` and the
        turning share ``J_w + I_z r^2 / (2 a^2)``; the fit weighs them by
        ``1 : a^2 / rho^2``. For four casters in a straight run each wheel
        carries ``m r^2 / 4``. Evaluated at the current pose (steering angles
        at rest). A lifted robot's base is fixed (no base rows): pass
        ``twin``, a free-standing copy of its body, to get its floor inertia."""
        mass, movable = self._joint_space_mass(twin)
        offset = mass.shape[0] - len(movable)
        n = len(self.joint_indices)
        if offset != 6:
            return self._locked_inertia()
        transform = np.zeros((mass.shape[0], n))
        for i, joint in enumerate(self.joint_indices):
            transform[offset + movable.index(joint), i] = 1.0
        rest = np.zeros(n)
        # 3 x n: base_link's (vx, vy, wz) per unit joint rate, in base_link
        vx, vy, wz = self.model.jacobian(rest)
        # pybullet's base velocities are in the base's own frame, whose
        # axes are base_link's: the centre of mass moves with v_o + wz z x c
        com_x, com_y, _ = self._com_in_link
        transform[2] = wz
        transform[3] = vx - wz * com_y
        transform[4] = vy + wz * com_x
        joint_mass = transform.T @ mass @ transform
        # the whole robot's mass and yaw inertia about the base's centre of mass
        rho = math.sqrt(mass[2, 2] / mass[3, 3])
        motions = np.column_stack([self.model.inverse(rest, np.array(a)) for a in
                                   ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0 / rho))])
        torques = joint_mass @ motions
        return np.sum(torques * motions, axis=1) / np.sum(motions * motions, axis=1)

    # -- motors -----------------------------------------------------------------
    def command_velocities(self, velocities: np.ndarray) -> None:
        """Target joint speeds [rad/s], clipped to the speed limits."""
        target = [min(v, m) if v > -m else -m
                  for v, m in zip(np.asarray(velocities, float).tolist(), self._vmax)]
        if self.drives is not None:
            self._release_brakes()
            self.drives.command_velocities(target)
            return
        self._torque_mode = False
        pb.setJointMotorControlArray(self.body, self.joint_indices, pb.VELOCITY_CONTROL,
                                     targetVelocities=target, forces=self._forces,
                                     physicsClientId=self.world.client)

    def command_efforts(self, efforts: np.ndarray) -> None:
        """Joint torques [N m], clipped to the torque limits; applied every step."""
        if self.drives is not None:
            self._release_brakes()
            self.drives.command_efforts(efforts)
            return
        if not self._torque_mode:
            # pybullet's velocity motors must be released before torque control.
            pb.setJointMotorControlArray(self.body, self.joint_indices, pb.VELOCITY_CONTROL,
                                         forces=[0.0] * len(self.joint_indices),
                                         physicsClientId=self.world.client)
            self._torque_mode = True
        self._efforts = np.clip(np.asarray(efforts, float), -self.max_effort, self.max_effort)

    def hold(self) -> None:
        """Brake every joint: zero speed with full torque (a drive holding still),
        at once (no command delay). With the drive model: the drives' speed
        loops reset to zero and each joint's holding brake engaged (a brake
        torque of max_effort) until the next command."""
        if self.drives is not None:
            self.drives.hold()
            self._set_joint_friction(self._forces)
            self._braked = True
            return
        self.command_velocities(np.zeros(len(self.joint_indices)))

    def idle(self) -> None:
        """The drives disabled (disarmed): :meth:`hold` with holding brakes
        (``holding_brakes``, sim.holding_brakes), else :meth:`coast`."""
        if self.holding_brakes:
            self.hold()
        else:
            self.coast()

    def coast(self) -> None:
        """Power stage off, no brake: every joint free but for its friction
        (a real drive's idle without a holding brake; a base on a ramp rolls)."""
        n = len(self.joint_indices)
        if self.drives is not None:
            self.drives.coast()
            self._release_brakes()
            return
        self.command_efforts(np.zeros(n))

    def before_step(self) -> None:
        # TORQUE_CONTROL forces last one simulation step in pybullet.
        if self.drives is not None:
            _set_motors(self.body, self.joint_indices, _TORQUE,
                        forces=self.drives.torques(self._drive_velocities),
                        physicsClientId=self._client)
        elif self._torque_mode:
            pb.setJointMotorControlArray(self.body, self.joint_indices, pb.TORQUE_CONTROL,
                                         forces=self._efforts.tolist(),
                                         physicsClientId=self.world.client)

    def after_step(self) -> None:
        if self.drives is not None:
            self._record_drive_states()

    def _record_drive_states(self) -> None:
        # one read per physics step, kept whole: the loop needs the speeds
        # now, the driver the (delayed) positions only at the control rate
        states = _joint_states(self.body, self.joint_indices, physicsClientId=self._client)
        self._drive_velocities = [state[1] for state in states]
        self.drives.record_states(states)
        if self._base_history is not None:
            # two calls per physics step, only with a delay: small beside the
            # drive-model step they accompany
            self._base_history.append((_base_pose(self.body, physicsClientId=self._client),
                                       _base_velocity(self.body, physicsClientId=self._client)))

    # -- sensors ----------------------------------------------------------------
    def joint_states(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Positions [rad], velocities [rad/s] and motor torques [N m] as the
        drives report them (with the drive model: delayed, positions in whole
        encoder counts)."""
        if self.drives is not None:
            positions, velocities = self.drives.feedback()
            return positions, velocities, self.drives.torque
        states = pb.getJointStates(self.body, self.joint_indices,
                                   physicsClientId=self.world.client)
        columns = list(zip(*states))
        positions = np.array(columns[0])
        velocities = np.array(columns[1])
        efforts = self._efforts.copy() if self._torque_mode else np.array(columns[3])
        return positions, velocities, efforts

    def _com_offset(self, orientation) -> tuple[float, float, float]:
        """World-frame vector [m] from base_link's origin to its inertial origin."""
        return rotate(orientation, self._com_in_link)

    def wheel_contacts(self) -> tuple[np.ndarray, np.ndarray]:
        """The floor's contacts on this robot now: positions (n x 2) [m] and
        planar friction forces (n x 2) [N], both in base_link (x, y); one row
        per contact point pybullet reports (normally one per wheel)."""
        cid = self.world.client
        x, y, yaw = self.world_pose()
        c, s = math.cos(yaw), math.sin(yaw)
        positions, forces = [], []
        for point in pb.getContactPoints(bodyA=self.body, bodyB=self.world.floor,
                                         physicsClientId=cid):
            px, py = point[5][0] - x, point[5][1] - y
            fx = point[10] * point[11][0] + point[12] * point[13][0]
            fy = point[10] * point[11][1] + point[12] * point[13][1]
            positions.append((c * px + s * py, -s * px + c * py))
            forces.append((c * fx + s * fy, -s * fx + c * fy))
        return np.array(positions).reshape(-1, 2), np.array(forces).reshape(-1, 2)

    def world_pose(self) -> tuple[float, float, float]:
        """base_link's planar pose in the world [m, m, rad] (its URDF origin,
        on the floor, not pybullet's inertial base frame)."""
        return self._planar_pose(*pb.getBasePositionAndOrientation(
            self.body, physicsClientId=self.world.client))

    def _planar_pose(self, position, orientation) -> tuple[float, float, float]:
        """base_link's planar pose in the world [m, m, rad] from pybullet's
        base position [m] and orientation (quaternion)."""
        offset = self._com_offset(orientation)
        return position[0] - offset[0], position[1] - offset[1], yaw_of_quaternion(orientation)

    def pose(self) -> np.ndarray:
        """base_link's planar pose relative to its start pose (the odom frame)."""
        return self.start.inverse_compose(*self.world_pose())

    @property
    def sample_time(self) -> float:
        """The simulated time [s] :meth:`joint_states` describes: the world's
        time less the drives' feedback delay (whole physics steps; the world's
        time on ideal motors)."""
        if self.drives is None:
            return self.world.time
        return (self.world.steps - self.drives.feedback_steps_recorded) * self.world.dt

    def sampled_truth(self) -> tuple[np.ndarray, np.ndarray]:
        """The true pose (odom frame) [m, m, rad] and body twist [m/s, m/s,
        rad/s] of base_link at the instant :meth:`joint_states` describes
        (at :attr:`sample_time`): the reference that goes with a reading."""
        if not self._base_history:
            return self.pose(), self.body_twist()
        (position, orientation), (com_linear, angular) = self._base_history[0]
        return (self.start.inverse_compose(*self._planar_pose(position, orientation)),
                self._body_twist(orientation, com_linear, angular))

    def body_twist(self) -> np.ndarray:
        """(vx, vy, wz) of base_link in base_link [m/s, m/s, rad/s]."""
        com_linear, angular = pb.getBaseVelocity(self.body, physicsClientId=self.world.client)
        _, orientation = pb.getBasePositionAndOrientation(self.body,
                                                          physicsClientId=self.world.client)
        return self._body_twist(orientation, com_linear, angular)

    def _body_twist(self, orientation, com_linear, angular) -> np.ndarray:
        """base_link's body twist [m/s, m/s, rad/s] from pybullet's base
        orientation (quaternion) and its centre of mass's velocity [m/s] and
        angular velocity [rad/s] (world frame)."""
        # velocity of base_link's origin: v_com - w x (p_com - p_origin)
        r = self._com_offset(orientation)
        linear = (com_linear[0] - (angular[1] * r[2] - angular[2] * r[1]),
                  com_linear[1] - (angular[2] * r[0] - angular[0] * r[2]))
        # into base_link
        vx, vy = rotate_2d(linear[0], linear[1], -yaw_of_quaternion(orientation))
        return np.array([vx, vy, angular[2]])

    def tilt(self) -> float:
        """Angle [rad] between base_link's z axis and the vertical (tip-over check)."""
        _, (qx, qy, _, _) = pb.getBasePositionAndOrientation(self.body,
                                                             physicsClientId=self.world.client)
        # z-z entry of the rotation matrix of a unit quaternion
        return math.acos(max(-1.0, min(1.0, 1.0 - 2.0 * (qx * qx + qy * qy))))


class SimWorld:
    """A physics server with a flat floor, stepped at ``physics_rate`` [Hz]."""

    def __init__(self, physics_rate: float = 1000.0, gui: bool = False,
                 floor_tilt: float = 0.0):
        """``floor_tilt`` [deg]: the floor is a ramp rising along world +x by
        this angle (about world y; negative: falling). Modelled by tilting
        gravity instead of the plane -- the same physics on an endless floor --
        so poses and ground truth stay in the floor's plane."""
        self.dt = 1.0 / physics_rate
        self.floor_tilt = float(floor_tilt)
        self.client = pb.connect(pb.GUI if gui else pb.DIRECT)
        if self.client < 0:
            raise SimError("pybullet could not connect"
                           + (" to a GUI (is there a display?)" if gui else ""))
        cid = self.client
        pb.resetSimulation(physicsClientId=cid)
        tilt = math.radians(self.floor_tilt)
        pb.setGravity(-9.81 * math.sin(tilt), 0.0, -9.81 * math.cos(tilt), physicsClientId=cid)
        pb.setTimeStep(self.dt, physicsClientId=cid)
        pb.setRealTimeSimulation(0, physicsClientId=cid)
        floor = pb.createCollisionShape(pb.GEOM_PLANE, physicsClientId=cid)
        self.floor = pb.createMultiBody(0.0, floor, physicsClientId=cid)
        pb.changeDynamics(self.floor, -1, lateralFriction=1.0, physicsClientId=cid)
        self.robots: list[SimRobot] = []
        self.steps = 0

    @property
    def time(self) -> float:
        """Simulated time [s] since the world was created."""
        return self.steps * self.dt

    def add_robot(self, model, start: Pose2D = Pose2D(), friction=None, drive=None,
                  drive_rng: np.random.Generator | None = None, lifted: bool = False
                  ) -> SimRobot:
        """Load ``model`` at ``start`` (world frame); ``friction``: one Coulomb
        coefficient per wheel (default 1.0); ``drive``: a
        :class:`~holonomic_sim.drive_model.DriveSpec` (default: ideal motors),
        its per-joint spread drawn from ``drive_rng``; ``lifted``: base held
        in the air. The robot starts braked."""
        n_wheels = sum(name.endswith("wheel_joint") for name in model.joint_names)
        mu = np.ones(n_wheels) if friction is None else np.asarray(friction, float)
        robot = SimRobot(self, model, start, mu, drive, drive_rng, lifted)
        self.robots.append(robot)
        return robot

    def settle(self, seconds: float = 0.2) -> None:
        """Step with all robots braked so that they come to rest on the floor;
        then the clock restarts at 0 and each robot's start pose (the origin
        of its ground truth) is where it rests."""
        for robot in self.robots:
            robot.hold()
        self.step(max(1, round(seconds / self.dt)))
        self.steps = 0
        for robot in self.robots:
            robot.start = Pose2D(*robot.world_pose())

    def step(self, count: int = 1) -> None:
        for _ in range(count):
            for robot in self.robots:
                robot.before_step()
            pb.stepSimulation(physicsClientId=self.client)
            self.steps += 1
            for robot in self.robots:
                robot.after_step()

    def close(self) -> None:
        if self.client >= 0:
            try:
                pb.disconnect(physicsClientId=self.client)
            except pb.error:
                pass
            self.client = -1
