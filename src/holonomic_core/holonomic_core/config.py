"""Robot configuration: schema, search path, params files and assembly.

``load_config("hamr")`` returns a validated :class:`RobotConfig` -- the
immutable :class:`~holonomic_core.model.RobotModel`, the controller settings,
the driver class and every parameter's value -- and ``load_model`` the model
alone.

A config file is a valid ROS 2 params file::

    base_controller:
      ros__parameters:
        robot: {name: hamr, kinematics: ddrot}
        ddrot: {wheel_radius: 0.0615, ...}

Nested keys are flattened to dotted names (``ddrot.wheel_radius``) exactly as
ROS 2 does, and every key is validated against the schema of
:mod:`holonomic_core.schema` -- the same schema the ROS node declares. A key
that no schema declares is rejected with the nearest valid key ("did you
mean"), so that a typo is never silently ignored.
"""

from __future__ import annotations

import difflib
import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any, Mapping

import yaml

from holonomic_core import plugins
from holonomic_core.description import Description, description_class
from holonomic_core.drift_watch import DRIFT_SPECS
from holonomic_core.glitch_policy import POLICIES as GLITCH_POLICIES, GlitchLimits
from holonomic_core.driver import driver_class, driver_names, sim_drives_driver
from holonomic_core.kinematics import ESTIMATORS, BaseKinematics, kinematics_class
from holonomic_core.joint_range import checked_range, range_specs
from holonomic_core.loop import LOOP_SPECS
from holonomic_core.robot_model import JointLimits, RobotModel
from holonomic_core.monitor import MonitorLimits
from holonomic_core.odometry import OdometryNoise
from holonomic_core.safety import SAFETY_SPECS
from holonomic_core.schema import (ConfigError, ParamSpec, flatten, unknown_key_error,
                                   unknown_keys, validate)
from holonomic_core.slip_monitor import SlipLimits
from holonomic_core.torque import dynamics_for

_NOISE = OdometryNoise()

#: the node name under which config files hold their parameters
NODE_NAME = "base_controller"

ROBOT_SPECS = [
    ParamSpec("robot.name", "string", "Robot name, used in diagnostics and logs."),
    ParamSpec("robot.kinematics", "string",
              "Kinematic family, an installed holonomic.kinematics entry point: "
              + ", ".join(plugins.names("kinematics")) + ".",
              choices=plugins.names("kinematics")),
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
        ParamSpec(f"joints.{joint}.max_acceleration", "double",
                  f"Acceleration limit of {joint} [rad/s^2]: the commanded twist's change "
                  "is scaled so that no joint's rate changes faster (joint_acceleration.py); "
                  "0: no limit.", default=0.0, minimum=0.0, maximum=1e6),
    ] + range_specs(joint)



_AXES = (("linear.x", "m/s", "m/s^2"), ("linear.y", "m/s", "m/s^2"),
         ("angular.z", "rad/s", "rad/s^2"))


def _limit_specs() -> list[ParamSpec]:
    specs = []
    for axis, vel_unit, acc_unit in _AXES:
        specs += [
            ParamSpec(f"limits.{axis}.max_velocity", "double",
                      f"Speed limit of the commanded twist's {axis} [{vel_unit}].",
                      minimum=0.0, exclusive_minimum=True, maximum=100.0),
            ParamSpec(f"limits.{axis}.max_acceleration", "double",
                      f"Acceleration limit on {axis} when speeding up [{acc_unit}].",
                      minimum=0.0, exclusive_minimum=True, maximum=1000.0),
            ParamSpec(f"limits.{axis}.max_deceleration", "double",
                      f"Deceleration limit on {axis} when slowing down or stopping "
                      f"(also after a command timeout) [{acc_unit}].",
                      minimum=0.0, exclusive_minimum=True, maximum=1000.0),
            ParamSpec(f"limits.{axis}.max_jerk", "double",
                      f"Jerk limit on {axis}: how fast its acceleration may change "
                      f"[{acc_unit[:-1]}3]; it also lengthens every stop, a timeout's too "
                      "(docs/limits.md); 0: no limit.",
                      default=0.0, minimum=0.0, maximum=1e5),
        ]
    return specs + [
        ParamSpec("limits.linear.max_speed", "double",
                  "Limit on the commanded translation speed, the norm of (vx, vy) [m/s]: a "
                  "diagonal is no faster than a straight line (the per-axis max_velocity "
                  "still apply); 0: no limit.", default=0.0, minimum=0.0, maximum=100.0),
    ]


CONTROLLER_SPECS: list[ParamSpec] = [
    ParamSpec("driver", "string",
              "Driver backend, an installed holonomic.drivers entry point: "
              + ", ".join(driver_names()) + ".", default="sim", choices=driver_names()),
    ParamSpec("sim_drives", "bool",
              "Run the CAN backend (odrive_can, cia402) against emulated drives whose motors "
              "are the simulator's joints (holonomic-bringup --sim-drives).", default=False),
    ParamSpec("control_rate", "double", "Rate of the control loop [Hz].",
              default=200.0, minimum=1.0, maximum=1000.0),
    ParamSpec("publish_rate", "double",
              "Rate of odom, /tf and joint_states [Hz]; at most control_rate.",
              default=50.0, minimum=0.1, maximum=1000.0),
    ParamSpec("cmd_timeout", "double",
              "Age [s] after which the last cmd_vel is stale and the base stops "
              "under the deceleration limits; 0 disables the timeout.",
              default=0.5, minimum=0.0, maximum=60.0),
    ParamSpec("control_mode", "string",
              "velocity: joint velocity commands from the exact inverse kinematics (every "
              "robot); torque: dynamically decoupled operational-space control, F = Lambda F* "
              "+ mu, joint torques C#^T F (Holmberg & Khatib; PCV on a driver with torque "
              "mode).", default="velocity", choices=("velocity", "torque")),
    ParamSpec("torque.kp", "double_array",
              "Torque mode: position gains of the unit-mass system for (x, y, yaw) [1/s^2].",
              default=(36.0, 36.0, 36.0), minimum=0.0, maximum=1e4, min_length=3),
    ParamSpec("torque.kv", "double_array",
              "Torque mode: velocity gains for (x, y, yaw) [1/s] (2 sqrt(kp): critically "
              "damped).", default=(12.0, 12.0, 12.0), minimum=0.0, maximum=1e3, min_length=3),
    ParamSpec("estimator", "string",
              "Odometry estimator: slip_min (C# = Cp+ Cq^-1), robust (slip_min, except that "
              "one caster alone disagreeing by more than 0.1 m/s is left out) or pinv.",
              default="slip_min", choices=ESTIMATORS),
    ParamSpec("odom_frame", "string", "Frame of the odometry (REP 105).", default="odom"),
    ParamSpec("base_frame", "string", "Frame of the base (REP 105).", default="base_link"),
    ParamSpec("frame_prefix", "string",
              "Prefix of odom_frame and base_frame, e.g. 'robot1/' for one robot of several "
              "(holonomic-bringup --namespace NS sets 'NS/').", default=""),
    ParamSpec("publish_tf", "bool", "Publish odom -> base_link on /tf.", default=True),
    ParamSpec("publish_link_tf", "bool",
              "Also publish every URDF link's transform on /tf, from the measured joint "
              "positions (wheels, turret, casters), for rviz where no robot_state_publisher "
              "runs (a pip-only install). Off by default: on a full ROS install "
              "robot_state_publisher does this from joint_states.", default=False),
    ParamSpec("cmd_vel_stamped", "bool",
              "Subscribe cmd_vel as geometry_msgs/TwistStamped instead of Twist.", default=False),
    ParamSpec("enable_on_start", "bool",
              "Arm the motors at start. Default false: motors start disarmed and "
              "~/enable arms them.", default=False),
    # the noise defaults are OdometryNoise's, written once there (the XR4000's
    # profile for its default floor; config/xr4000.yaml, docs/odometry_experiment.md)
    ParamSpec("odometry.twist_window", "double",
              "Span of the encoder readings whose least-squares line gives the published "
              "twist [s]; it lags a ramp by half of it; 0: the last two readings.",
              default=0.03, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.linear_variance_per_meter", "double",
              "Position variance added per metre travelled [m^2/m].",
              default=_NOISE.linear_variance_per_meter, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.angular_variance_per_radian", "double",
              "Heading variance added per radian turned [rad^2/rad].",
              default=_NOISE.angular_variance_per_radian, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.angular_variance_per_meter", "double",
              "Heading variance added per metre travelled [rad^2/m].",
              default=_NOISE.angular_variance_per_meter, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.slip_position_gain", "double",
              "Position variance added per squared RMS contact residual the estimator could "
              "not explain, per second [s] (m^2 per (m/s)^2 s).",
              default=_NOISE.slip_position_gain, minimum=0.0, maximum=1e4),
    ParamSpec("odometry.slip_heading_gain", "double",
              "Heading variance added per squared RMS contact residual, per second [s/m^2] "
              "(rad^2 per (m/s)^2 s).", default=_NOISE.slip_heading_gain, minimum=0.0,
              maximum=1e6),
    ParamSpec("odometry.slip4_position_gain", "double",
              "Position variance added per fourth power of the RMS contact residual, per "
              "second [s^3/m^2] (m^2 per (m/s)^4 s): the slip no residual shows grows faster "
              "than the residual when the tyres slide.", default=_NOISE.slip4_position_gain,
              minimum=0.0, maximum=1e8),
    ParamSpec("odometry.slip4_heading_gain", "double",
              "Heading variance added per fourth power of the RMS contact residual, per "
              "second [s^3/m^4] (rad^2 per (m/s)^4 s).", default=_NOISE.slip4_heading_gain,
              minimum=0.0, maximum=1e10),
    ParamSpec("odometry.latency_variance", "double",
              "Mean square of the readings' latency (how much older a reading is than its "
              "stamp) [s^2]: the published pose covariance adds latency_variance x u u^T, u "
              "the current twist in odom (the pose error of a delay, which does not "
              "accumulate).", default=_NOISE.latency_variance, minimum=0.0, maximum=1.0),
    ParamSpec("odometry.twist_variance", "double_array",
              "Variances of the reported twist (vx, vy, wz) without slip or acceleration "
              "[(m/s)^2, (m/s)^2, (rad/s)^2].",
              default=_NOISE.twist_variance, minimum=0.0, maximum=100.0, min_length=3),
    ParamSpec("odometry.twist_slip_gain", "double_array",
              "Twist variance (vx, vy, wz) added per (m/s)^2 of squared RMS contact residual "
              "[-, -, 1/m^2].", default=_NOISE.twist_slip_gain, minimum=0.0, maximum=1e4,
              min_length=3),
    ParamSpec("odometry.twist_lag_gain", "double_array",
              "Twist variance (vx, vy, wz) added per squared lag error of the axis, "
              "(acceleration x half the twist window)^2 [-].", default=_NOISE.twist_lag_gain,
              minimum=0.0, maximum=1e4, min_length=3),
    ParamSpec("diagnostics.slip_threshold", "double",
              "Odometry residual of one caster above which it counts as slipping [m/s].",
              default=0.05, minimum=0.0, exclusive_minimum=True, maximum=10.0),
    ParamSpec("diagnostics.slip_duration", "double",
              "How long a caster must stay above diagnostics.slip_threshold before the "
              "odometry diagnostics WARN, naming it [s].",
              default=1.0, minimum=0.0, maximum=600.0),
    ParamSpec("safety.velocity_factor", "double",
              "A measured joint speed above this multiple of the joint's speed limit is an "
              "encoder glitch: the controller faults and stops the base [-].",
              default=3.0, minimum=1.5, maximum=1000.0),
    ParamSpec("safety.reading_timeout", "double",
              "Joint readings whose stamp has not advanced for this long are frozen: "
              "fault and stop [s].", default=0.05, minimum=0.001, maximum=10.0),
    ParamSpec("safety.tracking_error", "double",
              "A joint whose measured speed differs from its command by more than this "
              "fraction of its speed limit, for safety.tracking_timeout, cannot follow "
              "(saturated or blocked): fault and stop [-].",
              default=0.3, minimum=0.01, maximum=100.0),
    ParamSpec("safety.tracking_timeout", "double",
              "How long a joint may miss its command by safety.tracking_error before the "
              "controller faults [s]; 0 disables the check.",
              default=0.5, minimum=0.0, maximum=60.0),
    # drop by default: one 4000 rad/s spike every few hours must not stop a robot,
    # while a dead encoder (invalid on every cycle) passes glitch_rate within
    # glitch_rate + 1 cycles, or safety.reading_timeout, and faults
    ParamSpec("safety.glitch_policy", "string",
              "What an invalid joint reading (non-finite value, velocity over "
              "safety.velocity_factor x the limit, position jump) does: fault (fault and "
              "stop) or drop (ignore it, count it in diagnostics; the odometry bridges it), "
              "unless more than safety.glitch_rate were dropped in the last minute or they "
              "last longer than safety.reading_timeout.",
              default="drop", choices=GLITCH_POLICIES),
    ParamSpec("safety.glitch_rate", "double",
              "With safety.glitch_policy drop: dropped readings per minute above which the "
              "next invalid reading faults [1/min].",
              default=10.0, minimum=0.0, maximum=600.0),
] + _limit_specs() + DRIFT_SPECS + LOOP_SPECS + SAFETY_SPECS


@dataclass(frozen=True)
class ControllerConfig:
    """Validated settings of the base controller (units in CONTROLLER_SPECS)."""

    driver: str
    control_rate: float
    publish_rate: float
    cmd_timeout: float
    estimator: str
    odom_frame: str
    base_frame: str
    publish_tf: bool
    publish_link_tf: bool
    cmd_vel_stamped: bool
    enable_on_start: bool
    control_mode: str
    torque_kp: tuple[float, float, float]
    torque_kv: tuple[float, float, float]
    max_velocity: tuple[float, float, float]
    max_acceleration: tuple[float, float, float]
    max_deceleration: tuple[float, float, float]
    #: [m/s], inf: none (limits.linear.max_speed = 0)
    max_speed: float
    #: [m/s^3, m/s^3, rad/s^3], inf: none on that axis (limits.*.max_jerk = 0)
    max_jerk: tuple[float, float, float]
    noise: OdometryNoise
    twist_window: float
    monitor: MonitorLimits
    slip: SlipLimits
    glitch: GlitchLimits

    @classmethod
    def from_values(cls, v: Mapping[str, Any]) -> "ControllerConfig":
        if v["publish_rate"] > v["control_rate"]:
            raise ConfigError("publish_rate", v["publish_rate"],
                              f"<= control_rate ({v['control_rate']:g} Hz)")
        for key in ("odometry.twist_variance", "odometry.twist_slip_gain",
                    "odometry.twist_lag_gain"):
            if len(v[key]) != 3:
                raise ConfigError(key, v[key], "exactly 3 values (vx, vy, wz)")
        for key in ("torque.kp", "torque.kv"):
            if len(v[key]) != 3:
                raise ConfigError(key, v[key], "exactly 3 gains (x, y, yaw)")
        axes = [a for a, _, _ in _AXES]
        return cls(
            driver=v["driver"], control_rate=v["control_rate"], publish_rate=v["publish_rate"],
            cmd_timeout=v["cmd_timeout"], estimator=v["estimator"],
            odom_frame=v["odom_frame"], base_frame=v["base_frame"],
            publish_tf=v["publish_tf"], publish_link_tf=v["publish_link_tf"],
            cmd_vel_stamped=v["cmd_vel_stamped"],
            enable_on_start=v["enable_on_start"], control_mode=v["control_mode"],
            torque_kp=tuple(v["torque.kp"]), torque_kv=tuple(v["torque.kv"]),
            max_velocity=tuple(v[f"limits.{a}.max_velocity"] for a in axes),
            max_acceleration=tuple(v[f"limits.{a}.max_acceleration"] for a in axes),
            max_deceleration=tuple(v[f"limits.{a}.max_deceleration"] for a in axes),
            max_speed=v["limits.linear.max_speed"] or math.inf,
            max_jerk=tuple(v[f"limits.{a}.max_jerk"] or math.inf for a in axes),
            noise=OdometryNoise(v["odometry.linear_variance_per_meter"],
                                v["odometry.angular_variance_per_radian"],
                                v["odometry.angular_variance_per_meter"],
                                v["odometry.slip_position_gain"],
                                v["odometry.slip_heading_gain"],
                                tuple(v["odometry.twist_variance"]),
                                tuple(v["odometry.twist_slip_gain"]),
                                tuple(v["odometry.twist_lag_gain"]),
                                v["odometry.latency_variance"],
                                v["odometry.slip4_position_gain"],
                                v["odometry.slip4_heading_gain"]),
            twist_window=v["odometry.twist_window"],
            slip=SlipLimits(v["diagnostics.slip_threshold"], v["diagnostics.slip_duration"]),
            monitor=MonitorLimits(v["safety.velocity_factor"], v["safety.reading_timeout"],
                                  v["safety.tracking_error"], v["safety.tracking_timeout"]),
            glitch=GlitchLimits(v["safety.glitch_policy"], v["safety.glitch_rate"],
                                v["safety.reading_timeout"]),
        )


@dataclass(frozen=True)
class RobotConfig:
    """Everything needed to run one robot, validated.

    ``specs``: every parameter's schema (the ROS node declares them);
    ``values``: every validated value by flat key.
    """

    model: RobotModel
    controller: ControllerConfig
    driver_class: type
    specs: tuple[ParamSpec, ...]
    values: Mapping[str, Any] = field(repr=False)
    source: str = ""


def config_from_flat(flat: Mapping[str, Any], source: str = "") -> RobotConfig:
    """Validate a flat parameter dict (file + overrides) into a RobotConfig."""
    model, mspecs = build_model(flat)
    values = dict(model.params)
    values.update(validate(CONTROLLER_SPECS, flat))
    controller = ControllerConfig.from_values(values)
    dcls = driver_class(controller.driver)
    if values["sim_drives"]:
        dcls = sim_drives_driver(dcls)
    if controller.control_mode == "torque":
        if not dcls.supports_effort:
            raise ConfigError("control_mode", "torque",
                              f"'velocity' with driver '{controller.driver}' (it has no torque "
                              "mode; the sim driver has)")
        dynamics_for(model)      # a family without a dynamic model says so here
    dspecs = dcls.param_specs(model)
    values.update(validate(dspecs, flat))
    # Keys of the backends not in use (e.g. `sim.*` on a real robot) are
    # allowed in the file; anything else unknown is a typo.
    others = tuple(f"{name}." for name in driver_names() if name != controller.driver)
    specs = tuple(mspecs + CONTROLLER_SPECS + dspecs)
    check_no_unknown(list(specs), flat, ignore_prefixes=others)
    return RobotConfig(model, controller, dcls, specs, values, source)


def load_config(source, overrides: Mapping[str, Any] | None = None) -> RobotConfig:
    """Load and validate a robot config (a name from config/ or a YAML path).

    ``overrides``: flat keys applied over the file (e.g. ``{"driver": "mock"}``).
    Raises :class:`ConfigError` naming the first bad key.
    """
    path = resolve_config(source)
    flat = read_params_file(path)
    flat.update(overrides or {})
    return config_from_flat(flat, str(path))


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


def model_specs(flat: Mapping[str, Any]) -> tuple[list[ParamSpec], type[BaseKinematics],
                                                  type[Description] | None]:
    """Schema of the model keys for the family that ``flat`` names: its
    kinematics' and its body's (:mod:`holonomic_core.description`); the
    kinematics class and the description class (None: the family has none)."""
    if "robot.kinematics" not in flat:
        raise ConfigError("robot.kinematics", "<missing>", ROBOT_SPECS[1].allowed() + " (required)")
    kind = ROBOT_SPECS[1].coerce(flat["robot.kinematics"])
    cls = kinematics_class(kind)
    description = description_class(kind)
    specs = ROBOT_SPECS + cls.param_specs(flat)
    if description is not None:
        specs += description.param_specs(flat)
    return specs, cls, description


def build_model(flat: Mapping[str, Any]) -> tuple[RobotModel, list[ParamSpec]]:
    """Validate the model keys of ``flat`` and build the model.

    Returns the model and the specs it consumed (the caller checks the rest).
    """
    specs, cls, description = model_specs(flat)
    values = validate(specs, flat)
    kinematics = cls.from_params(values)
    if description is not None:
        description.check(kinematics, values)
    jspecs = [s for j in kinematics.joint_names for s in joint_specs(j)]
    jvalues = validate(jspecs, flat)
    values.update(jvalues)
    limits = tuple(JointLimits(jvalues[f"joints.{j}.max_velocity"],
                               jvalues[f"joints.{j}.max_effort"],
                               *checked_range(j, jvalues))
                   for j in kinematics.joint_names)
    if any(lim.ranged for lim in limits):
        kinematics = kinematics.with_joint_ranges(
            [(lim.min_position, lim.max_position) if lim.ranged else None for lim in limits])
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
