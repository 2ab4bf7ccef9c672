"""One driver interface for every backend: simulator, mock, real motor drives.

Lifecycle (ros2_control's hardware interface, python-can's ``BusABC``)::

    UNCONFIGURED --configure()--> INACTIVE --activate()--> ACTIVE
         ^                          |  ^                      |
         +------- close() ----------+  +---- deactivate() ----+

* ``configure`` opens communication and checks that every device answers;
* ``activate`` arms the motors (power stage on), ``deactivate`` stops and
  disarms them; ``read`` works in INACTIVE and ACTIVE (odometry keeps running
  while disarmed), ``write_velocities`` only in ACTIVE;
* ``close`` deactivates if needed and releases everything; a driver is a
  context manager that closes on exit;
* ``quick_stop`` is the emergency stop: from ACTIVE the drives brake to rest
  at their own quick-stop deceleration (CiA 402 quick stop, ODrive Estop or a
  braking ramp, the simulator's speed loops at full torque) and the driver
  ends INACTIVE, like ``deactivate``; ``activate`` arms again.

All joint arrays are in the model's ``joint_names`` order, in joint units
(rad, rad/s, N m) -- gear ratios, encoder counts and direction signs are the
backend's business. Backends are found by name among the ``holonomic.drivers``
entry points (:mod:`holonomic_core.plugins`) and imported lazily, so a user of
the simulator needs no CAN library.

The controller never asks which backend it has: optional capabilities
(``sim_time``, ``ground_truth``) are methods that return ``None`` on
backends without them.
"""

from __future__ import annotations

import abc
import enum
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from holonomic_core import plugins
from holonomic_core.schema import ParamSpec


class DriverError(RuntimeError):
    """Base of every driver failure; ``device`` names the joint/device if known."""

    def __init__(self, message: str, device: str | None = None):
        self.device = device
        super().__init__(f"{device}: {message}" if device else message)


class DriverStateError(DriverError):
    """A call that the current lifecycle state does not allow."""


class DriverCommunicationError(DriverError):
    """A device did not answer (timeout, missing heartbeat, bus down)."""


class DriverFault(DriverError):
    """A device reported a fault (drive error, over-current, encoder failure)."""


class DriverUnsupported(DriverError):
    """The backend cannot do what was asked (e.g. torque mode)."""


class DriverState(enum.Enum):
    UNCONFIGURED = "unconfigured"
    INACTIVE = "inactive"
    ACTIVE = "active"
    FINALIZED = "finalized"


@dataclass(frozen=True)
class JointReading:
    """One sample of every joint.

    ``stamp`` [s] is on the driver's clock: simulated time for the simulator,
    ``time.monotonic()`` for hardware; it is the time the positions and
    velocities describe (their sample time: a SYNC, a CAN frame's arrival, the
    simulated drives' feedback delay before now), not the time the loop
    received them. ``efforts`` may be NaN where unknown.
    """

    stamp: float
    positions: np.ndarray
    velocities: np.ndarray
    efforts: np.ndarray


@dataclass(frozen=True)
class GroundTruth:
    """True planar pose and body twist of base_link at ``stamp`` [s]
    (simulation only; the stamp of the newest reading, so the two pair up).

    Pose ``(x, y, yaw)`` [m, m, rad] relative to base_link's pose at start
    (the ``odom`` frame); twist ``(vx, vy, wz)`` in base_link.
    """

    stamp: float
    pose: np.ndarray
    twist: np.ndarray


class Driver(abc.ABC):
    """Abstract driver. Subclasses implement the ``_on_*`` hooks.

    Public methods enforce the lifecycle and raise :class:`DriverStateError`
    when called out of order; hooks may raise any :class:`DriverError`.
    """

    #: registry name
    name: str = ""
    #: whether ``write_efforts`` is supported
    supports_effort: bool = False

    def __init__(self, model, params: Mapping[str, Any], control_rate: float):
        """``model``: the RobotModel; ``params``: validated flat parameters
        (this backend's :meth:`param_specs` included); ``control_rate`` [Hz]:
        the rate at which the controller will call ``read``/``write``."""
        self.model = model
        self.params = params
        self.control_rate = float(control_rate)
        self._state = DriverState.UNCONFIGURED

    # -- schema -------------------------------------------------------------
    @classmethod
    def param_specs(cls, model) -> list[ParamSpec]:
        """Schema of the ``driver.<name>.*`` / per-joint keys this backend reads."""
        return []

    # -- lifecycle ----------------------------------------------------------
    @property
    def state(self) -> DriverState:
        return self._state

    @property
    def armed(self) -> bool:
        return self._state is DriverState.ACTIVE

    def configure(self) -> None:
        self._require(DriverState.UNCONFIGURED)
        self._on_configure()
        self._state = DriverState.INACTIVE

    def activate(self) -> None:
        self._require(DriverState.INACTIVE)
        self._on_activate()
        self._state = DriverState.ACTIVE

    def deactivate(self) -> None:
        """Stop and disarm. Safe to call in any state but FINALIZED."""
        if self._state is DriverState.ACTIVE:
            try:
                self._on_deactivate()
            finally:
                self._state = DriverState.INACTIVE

    def quick_stop(self) -> None:
        """Emergency stop: brake every drive to rest (the backend's quick
        stop, never a coast) and disarm. Safe to call in any state but
        FINALIZED; a no-op unless ACTIVE."""
        if self._state is DriverState.ACTIVE:
            try:
                self._on_quick_stop()
            finally:
                self._state = DriverState.INACTIVE

    def close(self) -> None:
        """Deactivate (if active) and release resources; idempotent."""
        if self._state is DriverState.FINALIZED:
            return
        try:
            self.deactivate()
        finally:
            try:
                if self._state is not DriverState.UNCONFIGURED:
                    self._on_close()
            finally:
                self._state = DriverState.FINALIZED

    def read(self) -> JointReading:
        if self._state not in (DriverState.INACTIVE, DriverState.ACTIVE):
            raise DriverStateError(f"read() in state {self._state.value}")
        return self._on_read()

    def write_velocities(self, velocities: np.ndarray) -> None:
        """Command joint velocities [rad/s]; the caller has already limited them."""
        self._require(DriverState.ACTIVE)
        self._on_write_velocities(velocities)

    def write_efforts(self, efforts: np.ndarray) -> None:
        """Command joint torques [N m] (backends with ``supports_effort``)."""
        self._require(DriverState.ACTIVE)
        if not self.supports_effort:
            raise DriverUnsupported(f"backend '{self.name}' has no torque mode")
        self._on_write_efforts(efforts)

    # -- optional capabilities ----------------------------------------------
    def sim_time(self) -> float | None:
        """Simulated time [s] for backends that own a clock, else ``None``."""
        return None

    def ground_truth(self) -> GroundTruth | None:
        """True base pose and twist where the backend knows it, else ``None``."""
        return None

    def status(self) -> dict[str, str]:
        """Key/value pairs for ``diagnostics`` (device states, error counts)."""
        return {"backend": self.name, "state": self._state.value}

    # -- context manager ----------------------------------------------------
    def __enter__(self):
        if self._state is DriverState.UNCONFIGURED:
            self.configure()
        return self

    def __exit__(self, *exc):
        self.close()
        return False

    # -- hooks ----------------------------------------------------------------
    @abc.abstractmethod
    def _on_configure(self) -> None: ...

    def _on_activate(self) -> None:
        pass

    def _on_deactivate(self) -> None:
        pass

    def _on_quick_stop(self) -> None:
        """Brake to rest and disarm. Backends whose ``_on_deactivate``
        already brakes need not override it."""
        self._on_deactivate()

    def _on_close(self) -> None:
        pass

    @abc.abstractmethod
    def _on_read(self) -> JointReading: ...

    @abc.abstractmethod
    def _on_write_velocities(self, velocities: np.ndarray) -> None: ...

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        raise DriverUnsupported(f"backend '{self.name}' has no torque mode")

    def _require(self, state: DriverState) -> None:
        if self._state is not state:
            raise DriverStateError(
                f"{self.name}: operation needs state {state.value}, driver is {self._state.value}")


def driver_names() -> tuple[str, ...]:
    """Names of the installed backends (``holonomic.drivers`` entry points)."""
    return plugins.names("drivers")


def sim_drives_driver(backend: type[Driver]) -> type[Driver]:
    """The ``sim_drives`` driver class for ``backend`` (the
    ``holonomic.driver_adapters`` entry point ``sim_drives``, imported only
    now); ConfigError where the simulator is not installed or ``backend`` is
    not a CAN backend."""
    adapter = plugins.load("driver_adapters", "sim_drives", "sim_drives",
                           wanted="false: the simulator is not installed")
    return adapter(backend)


def driver_class(name: str) -> type[Driver]:
    """Resolve a backend name (``holonomic.drivers`` entry point), importing
    its module only now."""
    return plugins.load("drivers", name, "driver")


def emulated_drive_names() -> tuple[str, ...]:
    """Names of the backends that have an emulated drive
    (``holonomic.emulated_drives`` entry points)."""
    return plugins.names("emulated_drives")


def emulated_drive_class(name: str) -> type:
    """The emulated drive of backend ``name`` (``holonomic.emulated_drives``
    entry point, its module imported only now): one device on a python-can
    ``virtual`` channel, built as ``cls(node_id, channel, **kwargs)``, where
    ``cls.settings_for(params, joint)`` gives the keyword arguments that the
    backend's validated parameters describe for a joint. ConfigError on
    ``driver`` for a backend without one, naming those that have one."""
    return plugins.load("emulated_drives", name, "driver")
