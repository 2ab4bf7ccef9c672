"""The motor drives of a simulated robot: what sits between a command and a joint torque.

ROS-free and physics-free (numpy only): :class:`DriveBank` holds one drive
per joint, vectorised over the joints, and is advanced once per physics step
by whoever owns the physics (``world.SimRobot``), which applies the torque it
returns and feeds back the joint states. Per joint:

* **velocity loop** (velocity mode): a PI controller on the joint speed,
  ``tau = Kp e + Ki \\int e dt`` with ``e = v_cmd - v`` [rad/s], run at the
  drive's own rate ``loop_rate``. When that is faster than the physics step,
  the loop is sub-stepped inside the step against the joint's own inertia
  (``v += tau h / J``, the drive's view between two physics updates); the
  step then receives the mean torque. Gains from the configured closed-loop
  bandwidth ``f_bw`` and the inertia ``J`` the drive was tuned on (by default
  lifted: the joint's links and rotor; or on the floor, plus its share of the
  base's mass and yaw inertia, ``world.SimRobot.loaded_inertia``):
  ``Kp = J w_c``, ``Ki = Kp w_c r_i`` (``Kp`` in its sampled-exact form, see
  the code), with ``w_c`` such that the closed loop
  ``T(s) = w_c (s + r_i w_c) / (s^2 + w_c s + r_i w_c^2)`` has its -3 dB
  point at ``f_bw`` (:func:`crossover`). With ``r_i`` small this is nearly a
  first-order loop of bandwidth ``f_bw`` (10-90 % rise time close to
  ``ln 9 / (2 pi f_bw)``) whose integrator removes the steady-state error
  left by friction. Gains tuned lifted give a loop 5-20
  times slower on the floor; gains tuned on the floor (``tuned_on="floor"``)
  a loop 5-20 times faster on a lifted or slipping wheel, which at a 1 ms
  physics step (``Kp h / J > 2``) is unstable.
* **torque limit** (the drive's current limit times its torque constant and
  gear ratio): ``|tau| <= tau_max``; the integrator stops winding up while
  the output is saturated (conditional integration).
* **torque mode**: the commanded torque, limited, after the command delay.
* **command delay** and **feedback delay** [s] (bus transfer and the drive's
  cycle; rounded to whole physics steps): a command takes effect
  ``command_delay`` after it is written; the positions and velocities the
  driver reads are ``feedback_delay`` old (:attr:`DriveBank.feedback_steps_recorded`),
  and the driver stamps them with the time they were sampled, as a real
  driver stamps a reading with its SYNC or CAN receive time.
* **encoder resolution**: the positions the driver reads are whole counts of
  ``counts_per_turn`` per joint revolution (motor counts times gear ratio).
* **friction**: viscous ``-b v`` is added to the torque here; Coulomb
  friction ``c`` is the physics owner's job (an implicit joint-friction
  constraint, stable at standstill where an explicit ``-c sign(v)`` chatters).
* **spread**: no two drives are alike -- each joint's gains and friction are
  the nominal ones times ``1 + s u`` with ``u`` uniform in [-1, 1], drawn
  from a seeded generator.

The rotor inertia reflected through the gearbox (``N^2 J_rotor``) is a
property of the joint's mass, also the physics owner's job (added to the
link's inertia about the joint axis); :attr:`DriveSpec.rotor_inertia` carries
it there.
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class DriveSpec:
    """Nominal drive parameters of a robot's joints (arrays in joint order).

    ``bandwidth`` [Hz]: closed-loop velocity bandwidth on the inertia the
    gains are designed for (``tuned_on``: "floor", the robot on its wheels,
    or "lifted", the joint alone with the base held; the physics owner
    computes that inertia); ``integral_ratio`` [-]: integrator corner over
    bandwidth; ``loop_rate`` [Hz]; ``torque_limit`` [N m]; ``coulomb`` [N m];
    ``viscous`` [N m s/rad]; ``gear_ratio`` [-] (motor turns per joint turn);
    ``rotor_inertia`` [kg m^2] (motor side); ``encoder_counts`` [counts per
    motor turn]; ``command_delay``, ``feedback_delay`` [s]; ``spread`` [-].
    """

    bandwidth: float
    integral_ratio: float
    loop_rate: float
    torque_limit: np.ndarray
    coulomb: np.ndarray
    viscous: np.ndarray
    gear_ratio: np.ndarray
    rotor_inertia: float
    encoder_counts: int
    command_delay: float
    feedback_delay: float
    spread: float
    tuned_on: str = "lifted"

    @property
    def reflected_inertia(self) -> np.ndarray:
        """Rotor inertia seen at each joint, ``N^2 J_rotor`` [kg m^2]."""
        return self.gear_ratio ** 2 * self.rotor_inertia

    @property
    def counts_per_joint_turn(self) -> np.ndarray:
        """Encoder counts per joint revolution (motor counts times gear ratio)."""
        return self.encoder_counts * self.gear_ratio


def crossover(bandwidth: float, integral_ratio: float) -> float:
    """``w_c`` [rad/s] of the PI loop on an inertia whose closed loop
    ``T(s) = w_c (s + r w_c) / (s^2 + w_c s + r w_c^2)`` is 3 dB down at
    ``bandwidth`` [Hz]. With ``x = w / w_c``, ``|T|^2 = (x^2 + r^2) /
    ((r - x^2)^2 + x^2) = 1/2`` gives ``x^4 - (1 + 2r) x^2 - r^2 = 0``."""
    r = integral_ratio
    x2 = ((1.0 + 2.0 * r) + math.sqrt((1.0 + 2.0 * r) ** 2 + 4.0 * r * r)) / 2.0
    return 2.0 * math.pi * bandwidth / math.sqrt(x2)


class DriveBank:
    """The drives of one robot's joints, advanced once per physics step.

    ``inertia`` [kg m^2]: each joint's inertia where the drives were tuned
    (rotor included), the plant the gains are designed for; ``physics_dt`` [s]; ``rng`` draws the per-joint spread.

    Use: :meth:`command_velocities` / :meth:`command_efforts` at the control
    rate; per physics step :meth:`torques` (joint speeds now -> torques to
    apply for the step) then, after the step, :meth:`record` (positions and
    speeds); :meth:`feedback` for the delayed, quantised reading.
    """

    def __init__(self, spec: DriveSpec, inertia: np.ndarray, physics_dt: float,
                 rng: np.random.Generator):
        self.spec = spec
        n = len(spec.torque_limit)
        self.n = n
        self.inertia = np.asarray(inertia, float)
        if self.inertia.shape != (n,) or np.any(self.inertia <= 0.0):
            raise ValueError(f"inertia: {n} positive values expected, got {inertia!r}")
        self.dt = float(physics_dt)
        gain_factor = 1.0 + spec.spread * rng.uniform(-1.0, 1.0, n)
        friction_factor = 1.0 + spec.spread * rng.uniform(-1.0, 1.0, n)
        self.substeps = max(1, int(round(spec.loop_rate * self.dt)))
        self.h = self.dt / self.substeps
        omega = crossover(spec.bandwidth, spec.integral_ratio)
        # Kp = J (1 - exp(-w_c h)) / h rather than J w_c: the sampled loop
        # v[k+1] = v[k] + h Kp (v* - v[k]) / J then has the pole exp(-w_c h)
        # of the continuous one (J w_c would make it 15 % faster at w_c h = 0.25)
        #: [N m s/rad] and [N m/rad] per joint, spread included
        self.kp = self.inertia * (-math.expm1(-omega * self.h) / self.h) * gain_factor
        self.ki = self.kp * omega * spec.integral_ratio
        self.coulomb = spec.coulomb * friction_factor
        self.viscous = spec.viscous * friction_factor
        self.torque_limit = np.asarray(spec.torque_limit, float)
        self._cmd_steps = int(round(spec.command_delay / self.dt))
        self._fb_steps = int(round(spec.feedback_delay / self.dt))
        self._pending: deque = deque()          # (apply at step, torque mode?, values)
        self._torque_mode = False
        self._step = 0
        self._history: deque = deque(maxlen=self._fb_steps + 1)
        #: [rad] one encoder count of each joint
        self._quanta = (2.0 * math.pi / spec.counts_per_joint_turn).tolist()
        # The per-step path runs on Python floats: for 3-8 joints a loop over
        # floats costs a third of the same dozen numpy calls on tiny arrays
        # (the simulator's speed target: docs/benchmarks.md). One tuple per
        # joint, unpacked in the loop, instead of five indexed lists.
        self._params = list(zip(self.kp.tolist(), (self.ki * self.h).tolist(),
                                self.torque_limit.tolist(), self.viscous.tolist(),
                                (self.h / self.inertia).tolist()))
        self._viscous = self.viscous.tolist()
        self._target = [0.0] * n                # [rad/s] or [N m], in effect
        self._integral = [0.0] * n              # [N m]
        self._torque = [0.0] * n

    # -- commands (control rate) ---------------------------------------------------
    def command_velocities(self, velocities) -> None:
        """Speed setpoints [rad/s] (a sequence or array), effective after the command delay."""
        self._push(False, _floats(velocities))

    def command_efforts(self, efforts) -> None:
        """Torque setpoints [N m], limited, effective after the command delay."""
        self._push(True, np.clip(np.asarray(efforts, float), -self.torque_limit,
                                 self.torque_limit).tolist())

    def hold(self) -> None:
        """Zero speed now, no delay (the drive's own brake / stop ramp), loop reset."""
        self._pending.clear()
        self._torque_mode = False
        self._target = [0.0] * self.n
        self._integral = [0.0] * self.n

    def coast(self) -> None:
        """Power stage off now: zero torque, no speed loop, loop reset."""
        self._pending.clear()
        self._torque_mode = True
        self._target = [0.0] * self.n
        self._integral = [0.0] * self.n

    def _push(self, torque_mode: bool, values: list[float]) -> None:
        if len(values) != self.n:
            raise ValueError(f"{self.n} joint values expected, got {len(values)}")
        self._pending.append((self._step + self._cmd_steps, torque_mode, values))

    @property
    def torque(self) -> np.ndarray:
        """Motor torque of the last step [N m] (what a drive reports as its current)."""
        return np.array(self._torque)

    @property
    def torque_mode(self) -> bool:
        """Whether the command in effect is a torque (else a speed)."""
        return self._torque_mode

    # -- physics step ------------------------------------------------------------
    def torques(self, velocities) -> list[float]:
        """Joint torques [N m] to apply during the coming physics step, from
        the joint speeds ``velocities`` [rad/s] (a sequence) at its start
        (viscous friction included; Coulomb friction is applied by the physics)."""
        pending = self._pending
        if pending and pending[0][0] <= self._step:
            while pending and pending[0][0] <= self._step:
                _, mode, values = pending.popleft()
                if mode != self._torque_mode:
                    self._integral = [0.0] * self.n
                self._torque_mode, self._target = mode, values
        self._step += 1
        if self._torque_mode:
            tau = self._target
        elif self.substeps > 1:
            tau = self._substepped(velocities)
        else:
            tau = self._pi(velocities)
        self._torque = tau
        return [t - b * v for t, b, v in zip(tau, self._viscous, velocities)]

    def _substepped(self, velocities) -> list[float]:
        """The loop run ``substeps`` times inside the physics step against each
        joint's own inertia (``v += (tau - b v) h / J``); the mean motor torque [N m]."""
        v = list(velocities)
        total = [0.0] * self.n
        for _ in range(self.substeps):
            tau = self._pi(v)
            for i, (_, _, _, viscous, h_over_j) in enumerate(self._params):
                v[i] += (tau[i] - viscous * v[i]) * h_over_j
                total[i] += tau[i]
        return [t / self.substeps for t in total]

    def _pi(self, velocities) -> list[float]:
        """One loop cycle: PI on ``target - velocities`` with conditional
        integration (the integral is kept only where the output is not
        saturated, or where integrating drives it back out) [N m]."""
        integral = self._integral
        tau = [0.0] * self.n
        i = 0
        for (kp, ki_h, limit, _, _), target, v in zip(self._params, self._target, velocities):
            error = target - v
            new = integral[i] + ki_h * error
            raw = kp * error + new
            t = limit if raw > limit else (-limit if raw < -limit else raw)
            if t == raw or (error > 0.0) != (raw > 0.0):
                integral[i] = new
            tau[i] = t
            i += 1
        return tau

    # -- feedback -----------------------------------------------------------------
    def record(self, positions, velocities) -> None:
        """The joint states after a physics step [rad, rad/s] (sequences)."""
        self._history.append(tuple(zip(positions, velocities)))

    def record_states(self, states) -> None:
        """The joint states after a physics step as rows ``(position [rad],
        velocity [rad/s], ...)`` per joint (what ``pybullet.getJointStates``
        returns), kept as they are: unpacked only when :meth:`feedback` reads
        them, at the control rate."""
        self._history.append(states)

    @property
    def feedback_steps(self) -> int:
        """``feedback_delay`` in whole physics steps [-]."""
        return self._fb_steps

    @property
    def feedback_steps_recorded(self) -> int:
        """How many physics steps old the states :meth:`feedback` returns are:
        :attr:`feedback_steps` once that many are recorded (before, the oldest
        recorded)."""
        return len(self._history) - 1

    def feedback(self) -> tuple[np.ndarray, np.ndarray]:
        """Positions [rad] (whole encoder counts) and speeds [rad/s] as the
        driver receives them: ``feedback_delay`` old (or the oldest recorded)."""
        states = self._history[0]
        # floor(q / quantum + 0.5) whole counts, on floats: the same IEEE
        # operations as numpy's, without three array calls per reading
        positions = [math.floor(state[0] / quantum + 0.5) * quantum
                     for state, quantum in zip(states, self._quanta)]
        return np.array(positions), np.array([state[1] for state in states])


def _floats(values) -> list[float]:
    """A joint vector as a list of Python floats (the per-step path's form)."""
    if isinstance(values, np.ndarray):
        return values.astype(float, copy=False).tolist()
    return [float(v) for v in values]
