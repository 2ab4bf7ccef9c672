"""The kinematics protocol every base family implements, and its lookup.

A base's kinematics map joint rates to the planar body twist of ``base_link``
and back. Conventions (REP 103, docs/conventions.md):

* twist: ``(vx, vy, wz)`` in ``base_link`` -- m/s, m/s, rad/s;
* joint positions / rates: arrays in :attr:`BaseKinematics.joint_names` order,
  rad and rad/s.

A kinematics object is immutable geometry (pinocchio's *Model*): the changing
state (joint positions, odometry) lives in the caller.
"""

from __future__ import annotations

import abc
from typing import Mapping, Sequence

import numpy as np

from holonomic_core import plugins
from holonomic_core.schema import ParamSpec

#: The estimators ``forward`` understands (docs/conventions.md, Python API).
ESTIMATORS = ("slip_min", "pinv", "robust")


class BaseKinematics(abc.ABC):
    """Geometry of one base family; pure functions of (positions, rates)."""

    #: registry name used in the YAML (``robot.kinematics``)
    kind: str = ""

    @property
    @abc.abstractmethod
    def joint_names(self) -> tuple[str, ...]:
        """All actuated joints, in the order of every joint array."""

    @abc.abstractmethod
    def inverse(self, positions: np.ndarray, twist: np.ndarray) -> np.ndarray:
        """Joint rates [rad/s] that realise ``twist`` (base_link) at ``positions``."""

    def command(self, positions: np.ndarray, twist: np.ndarray,
                twist_rate: np.ndarray | None = None) -> np.ndarray:
        """Joint rates [rad/s] the control cycle commands towards ``twist`` at
        the measured ``positions``, knowing the twist's rate ``twist_rate``
        (ax, ay, alpha) [m/s^2, m/s^2, rad/s^2] in base_link (None: constant).

        :meth:`inverse` for a family that realises any twist at once; a
        family that must first turn its wheels (a swerve) feeds its steering
        forward with the rate."""
        return self.inverse(positions, twist)

    def command_and_fraction(self, positions: np.ndarray, twist: np.ndarray,
                             twist_rate: np.ndarray | None = None) -> tuple[np.ndarray, float]:
        """:meth:`command`'s joint rates and the fraction in [0, 1] of
        ``twist`` the base follows with them: 1 for a family that realises
        any twist at once; a family whose wheels wait while they turn to a
        new direction (a swerve) drives only that fraction, and the control
        cycle continues from the twist really commanded, ``fraction *
        twist``, so the base then accelerates within its limits."""
        return self.command(positions, twist, twist_rate), 1.0

    def with_joint_ranges(self, ranges: Sequence[tuple[float, float] | None]) -> "BaseKinematics":
        """This kinematics for joints with position ranges: ``ranges`` per joint
        in :attr:`joint_names` order, ``(min_position, max_position)`` [rad]
        or None (continuous). A family whose command chooses among joint
        positions (a swerve's flip) returns a copy that chooses inside the
        ranges; the others return themselves (the controller's range guard
        keeps every family's joints inside)."""
        return self

    @abc.abstractmethod
    def forward(
        self,
        positions: np.ndarray,
        velocities: np.ndarray,
        estimator: str = "slip_min",
    ) -> np.ndarray:
        """Body twist ``(vx, vy, wz)`` in base_link estimated from joint rates."""

    @abc.abstractmethod
    def jacobian(self, positions: np.ndarray) -> np.ndarray:
        """``J_joint_to_base`` (3 x n): twist = J @ rates for a rigid, no-slip base.

        For bases with more joints than DOF (the PCV) this is the estimator
        ``C#`` of the default estimator; for the DDROT it is the exact inverse
        of the square inverse-kinematics matrix.
        """

    def fit_residual(self, positions: np.ndarray, velocities: np.ndarray,
                     estimator: str = "slip_min") -> np.ndarray:
        """Per-wheel-unit slip the estimator could not explain.

        Returns an array (one entry per wheel unit, m/s) of the norm of the
        contact-velocity residual. A square (exactly determined) base has
        nothing to explain away, so the default is empty.
        """
        return np.zeros(0)

    def estimate(self, positions: np.ndarray, velocities: np.ndarray,
                 estimator: str = "slip_min") -> tuple[np.ndarray, np.ndarray]:
        """``(forward(...), fit_residual(...))`` in one call: the odometry
        needs both every cycle, and a family whose fit is not trivial (the
        PCV) computes them together."""
        return (self.forward(positions, velocities, estimator),
                self.fit_residual(positions, velocities, estimator))

    def hot_path_geometry(self, estimator: str = "slip_min") -> tuple[int, np.ndarray] | None:
        """``(kind, geometry)`` of the compiled closed forms
        (:mod:`holonomic_core.hot_path`) for this family and ``estimator``, or
        None when they have none (the pure-Python methods then run). A
        family without a compiled form needs nothing here."""
        return None

    @classmethod
    @abc.abstractmethod
    def param_specs(cls, params: Mapping[str, object]) -> list[ParamSpec]:
        """Schema of this family's YAML keys (may depend on e.g. caster names)."""

    @classmethod
    @abc.abstractmethod
    def from_params(cls, params: Mapping[str, object]) -> "BaseKinematics":
        """Build from validated flat parameters; raise :class:`ConfigError`."""


def kinematics_class(kind: str) -> type[BaseKinematics]:
    """Resolve a ``robot.kinematics`` value to its class (the installed
    ``holonomic.kinematics`` entry point of that name, imported only now)."""
    return plugins.load("kinematics", kind, "robot.kinematics")
