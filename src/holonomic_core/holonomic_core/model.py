"""Robot model and configuration, loaded once from a YAML params file.

``load_model("hamr")`` returns an immutable :class:`RobotModel` (geometry and
joint limits, pinocchio's *Model*); ``load_config`` returns everything a base
controller needs (model, controller settings, driver choice and parameters).

A config file is a valid ROS 2 params file::

    base_controller:
      ros__parameters:
        robot: {name: hamr, kinematics: ddrot}
        ddrot: {wheel_radius: 0.0615, ...}

Nested keys are flattened to dotted names (``ddrot.wheel_radius``) exactly as
ROS 2 does, and every key is validated against the schema of
:mod:`holonomic_core.schema` -- the same schema the ROS node declares.
"""

from __future__ import annotations

import difflib
import os
from dataclasses import dataclass
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import numpy as np
import yaml

from holonomic_core.kinematics import BaseKinematics, kinematics_class
from holonomic_core.schema import (ConfigError, ParamSpec, flatten, unknown_key_error,
                                   unknown_keys, validate)

#: the node name under which config files hold their parameters
NODE_NAME = "base_controller"

ROBOT_SPECS = [
    ParamSpec("robot.name", "string", "Robot name, used in diagnostics and logs."),
    ParamSpec("robot.kinematics", "string",
              "Kinematic family: 'ddrot' (differential drive with offset turret) "
              "or 'pcv' (powered-caster vehicle).", choices=("ddrot", "pcv")),
]


def joint_specs(joint: str) -> list[ParamSpec]:
    """Schema of the per-joint keys ``joints.<joint>.*``."""
    return [
        ParamSpec(f"joints.{joint}.max_velocity", "double",
                  f"Speed limit of {joint} [rad/s]; commands are scaled to respect it.",
                  minimum=0.0, exclusive_minimum=True, maximum=1e4),
        ParamSpec(f"joints.{joint}.max_effort", "double",
                  f"Torque limit of {joint} [N m] (motor model of the simulator, "
                  "current limit of a real drive).",
                  default=10.0, minimum=0.0, exclusive_minimum=True, maximum=1e5),
        # Added to every position reading before the kinematics see it (the
        # sign of the drivers' position_offset), so that a steering or turret
        # encoder whose zero moved (re-assembly) is corrected in the config;
        # holonomic-calibrate estimates it.
        ParamSpec(f"joints.{joint}.zero_correction", "double",
                  f"Correction [rad] added to {joint}'s reading so that 0 is its kinematic "
                  "zero (a steering joint: the wheel rolls along base_link x; the turret: the "
                  "drive base faces base_link x); holonomic-calibrate estimates it.",
                  default=0.0, minimum=-3.2, maximum=3.2),
    ]


@dataclass(frozen=True)
class JointLimits:
    """Limits of one joint: speed [rad/s] and effort [N m]."""

    max_velocity: float
    max_effort: float


@dataclass(frozen=True)
class RobotModel:
    """Immutable geometry, joint limits and physical parameters of one robot."""

    name: str
    kinematics: BaseKinematics
    joint_limits: tuple[JointLimits, ...]
    #: every validated parameter (read-only), for the simulator's URDF and tools
    params: Mapping[str, Any]

    @property
    def kind(self) -> str:
        return self.kinematics.kind

    @property
    def joint_names(self) -> tuple[str, ...]:
        return self.kinematics.joint_names

    @property
    def max_joint_velocity(self) -> np.ndarray:
        """Joint speed limits [rad/s], joint_names order (a fresh array)."""
        return np.array([j.max_velocity for j in self.joint_limits])

    @property
    def zero_corrections(self) -> np.ndarray:
        """Encoder zero corrections [rad], joint_names order (a fresh array):
        the kinematics take ``reading + zero_corrections``."""
        return np.array([self.params[f"joints.{j}.zero_correction"] for j in self.joint_names])

    def inverse(self, positions, twist) -> np.ndarray:
        """Joint rates [rad/s], ``joint_names`` order, for the base_link ``twist``
        (vx, vy, wz) [m/s, m/s, rad/s] at joint ``positions`` [rad].

        Raises ValueError naming the expected length for a wrong-length or
        non-finite input."""
        return self.kinematics.inverse(self._joint_vector("positions", positions),
                                       _vector("twist", twist, 3, "vx, vy, wz in base_link"))

    def forward(self, positions, velocities, estimator: str = "slip_min") -> np.ndarray:
        """Body twist (vx, vy, wz) [m/s, m/s, rad/s] in base_link from joint
        ``positions`` [rad] and ``velocities`` [rad/s] (``joint_names`` order).

        ``estimator``: "slip_min" (C# = Cp+ Cq^-1), "pinv" or "robust". Raises
        ValueError for a wrong-length or non-finite input or an unknown estimator."""
        return self.kinematics.forward(self._joint_vector("positions", positions),
                                       self._joint_vector("velocities", velocities), estimator)

    def jacobian(self, positions) -> np.ndarray:
        """``J_joint_to_base`` (3 x n) at joint ``positions`` [rad]."""
        return self.kinematics.jacobian(self._joint_vector("positions", positions))

    def _joint_vector(self, what: str, value) -> np.ndarray:
        return _vector(what, value, len(self.joint_names),
                       f"one per joint of {self.name}: {', '.join(self.joint_names)}")


def _vector(what: str, value, length: int, meaning: str) -> np.ndarray:
    """``value`` as a finite float vector of ``length``, or ValueError saying
    what was expected."""
    try:
        out = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{what}: expected {length} numbers ({meaning}), got {value!r}") from None
    if out.shape != (length,):
        raise ValueError(f"{what}: expected {length} numbers ({meaning}), "
                         f"got shape {out.shape}: {value!r}")
    if not np.all(np.isfinite(out)):
        raise ValueError(f"{what}: expected finite numbers ({meaning}), got {value!r}")
    return out


def config_search_path() -> list[Path]:
    """Folders searched for ``<name>.yaml``, first match wins.

    ``HOLONOMIC_CONFIG_PATH`` (os.pathsep-separated), then the repository's
    ``config/`` (found through this file's real location, so it works from a
    colcon symlink install), then ``share/holonomic_core/config`` of every
    AMENT_PREFIX_PATH entry.
    """
    dirs = [Path(p) for p in os.environ.get("HOLONOMIC_CONFIG_PATH", "").split(os.pathsep) if p]
    here = Path(__file__).resolve()
    if len(here.parents) > 3:
        dirs.append(here.parents[3] / "config")
    for prefix in os.environ.get("AMENT_PREFIX_PATH", "").split(os.pathsep):
        if prefix:
            dirs.append(Path(prefix) / "share" / "holonomic_core" / "config")
    return dirs


def resolve_config(source: str | os.PathLike) -> Path:
    """A config name (``hamr``) or a path to a YAML file -> an existing path."""
    text = os.fspath(source)
    path = Path(text)
    if text.endswith((".yaml", ".yml")) or os.sep in text:
        if not path.is_file():
            raise ConfigError("robot", text, "an existing YAML file")
        return path
    for folder in config_search_path():
        candidate = folder / f"{text}.yaml"
        if candidate.is_file():
            return candidate
    names = sorted({p.stem for d in config_search_path() if d.is_dir() for p in d.glob("*.yaml")})
    nearest = difflib.get_close_matches(text, names, n=1)
    raise ConfigError("robot", text, f"a config name {names} or a path to a YAML file"
                      + (f"; did you mean '{nearest[0]}'?" if nearest else ""))


def read_params_file(path: Path, node_name: str = NODE_NAME) -> dict[str, Any]:
    """Flat parameters of ``node_name`` (and ``/**``) from a ROS 2 params file."""
    try:
        doc = yaml.safe_load(path.read_text())
    except yaml.YAMLError as exc:
        # pyyaml's message spans several lines (it quotes the text): one line here
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        what = getattr(exc, "problem", None) or " ".join(str(exc).split())
        raise ConfigError("robot", str(path), f"valid YAML ({what}{where})") from exc
    if not isinstance(doc, Mapping):
        raise ConfigError("robot", str(path), "a ROS 2 params file (a mapping at top level)")
    flat: dict[str, Any] = {}
    found = False
    for key in ("/**", node_name, "/" + node_name):
        section = doc.get(key)
        if section is None:
            continue
        params = section.get("ros__parameters") if isinstance(section, Mapping) else None
        if not isinstance(params, Mapping):
            raise ConfigError(f"{key}.ros__parameters", params, "a mapping of parameters")
        flat.update(flatten(params))
        found = True
    if not found:
        raise ConfigError("robot", str(path),
                          f"a params file with a '{node_name}: ros__parameters:' section")
    return flat


def model_specs(flat: Mapping[str, Any]) -> tuple[list[ParamSpec], type[BaseKinematics]]:
    """Schema of the model keys for the family that ``flat`` names."""
    if "robot.kinematics" not in flat:
        raise ConfigError("robot.kinematics", "<missing>", ROBOT_SPECS[1].allowed() + " (required)")
    kind = ROBOT_SPECS[1].coerce(flat["robot.kinematics"])
    cls = kinematics_class(kind)
    specs = ROBOT_SPECS + cls.param_specs(flat)
    return specs, cls


def build_model(flat: Mapping[str, Any]) -> tuple[RobotModel, list[ParamSpec]]:
    """Validate the model keys of ``flat`` and build the model.

    Returns the model and the specs it consumed (the caller checks the rest).
    """
    specs, cls = model_specs(flat)
    values = validate(specs, flat)
    kinematics = cls.from_params(values)
    jspecs = [s for j in kinematics.joint_names for s in joint_specs(j)]
    jvalues = validate(jspecs, flat)
    values.update(jvalues)
    limits = tuple(JointLimits(jvalues[f"joints.{j}.max_velocity"],
                               jvalues[f"joints.{j}.max_effort"])
                   for j in kinematics.joint_names)
    model = RobotModel(values["robot.name"], kinematics, limits, MappingProxyType(values))
    return model, specs + jspecs


def load_model(source: str | os.PathLike, overrides: Mapping[str, Any] | None = None) -> RobotModel:
    """Load the immutable robot model from a config name or YAML path.

    ``overrides`` are flat keys (``{"ddrot.turret_offset": 0.2}``) applied on
    top of the file, e.g. for design sweeps. Other sections of the file
    (controller, driver) are not validated here: see ``load_config``.
    """
    flat = read_params_file(resolve_config(source))
    flat.update(overrides or {})
    return build_model(flat)[0]


def check_no_unknown(specs: list[ParamSpec], flat: Mapping[str, Any],
                     ignore_prefixes: tuple[str, ...] = ()) -> None:
    """Reject keys no schema declares, so that a typo is not silently ignored."""
    extra = [k for k in unknown_keys(specs, flat) if not k.startswith(ignore_prefixes)]
    if extra:
        raise unknown_key_error(extra[0], flat[extra[0]], (s.name for s in specs))
