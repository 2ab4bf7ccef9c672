"""Every kind of invalid robot YAML fails at start with a message naming the
key and what is allowed, and a non-zero exit -- never a bare traceback."""

import re

import pytest

from holonomic_core.config import load_config, resolve_config
from holonomic_core.schema import ConfigError

HAMR = resolve_config("hamr").read_text()
XR4000 = resolve_config("xr4000").read_text()
SWERVE4 = resolve_config("swerve4").read_text()


def mutate(pattern: str, replacement: str, base: str = HAMR) -> str:
    text, count = re.subn(pattern, replacement, base, count=1, flags=re.MULTILINE)
    assert count == 1, f"pattern {pattern!r} not in the config"
    return text


def mutate_xr(pattern: str, replacement: str) -> str:
    return mutate(pattern, replacement, XR4000)


def mutate_sw(pattern: str, replacement: str) -> str:
    return mutate(pattern, replacement, SWERVE4)


# (case, YAML text, key the message must name, words of what is allowed)
CASES = [
    ("missing required key", mutate(r"^\s*turret_offset: .*\n", ""),
     "ddrot.turret_offset", "required"),
    ("negative radius", mutate(r"wheel_radius: 0.0615", "wheel_radius: -0.0615"),
     "ddrot.wheel_radius", "(0, 100]"),
    ("zero turret offset", mutate(r"turret_offset: 0.1641", "turret_offset: 0.0"),
     "ddrot.turret_offset", "not holonomic"),
    ("string for a number", mutate(r"control_rate: 200.0", "control_rate: fast"),
     "control_rate", "a number"),
    ("number for a bool", mutate(r"publish_tf: true", "publish_tf: 1"),
     "publish_tf", "true or false"),
    ("list for a number", mutate(r"cmd_timeout: 0.5", "cmd_timeout: [0.5]"),
     "cmd_timeout", "a number"),
    ("empty value", mutate(r"cmd_timeout: 0.5", "cmd_timeout:"), "cmd_timeout", "a number"),
    ("infinite value", mutate(r"max_velocity: 20.0", "max_velocity: .inf"),
     "joints.left_wheel_joint.max_velocity", "finite"),
    ("out of range", mutate(r"control_rate: 200.0", "control_rate: 5000.0"),
     "control_rate", "[1, 1000]"),
    ("unknown driver", mutate(r"driver: sim ", "driver: tcp "), "driver", "one of"),
    ("unknown kinematics", mutate(r"kinematics: ddrot", "kinematics: mecanum"),
     "robot.kinematics", "one of"),
    ("unknown estimator", mutate(r"estimator: slip_min", "estimator: kalman"),
     "estimator", "one of"),
    ("typo in a key", mutate(r"cmd_timeout: 0.5", "cmd_timout: 0.5"),
     "cmd_timout", "no such parameter"),
    ("unknown glitch policy", mutate(r"cmd_timeout: 0.5", "cmd_timeout: 0.5\n    safety: "
                                     "{glitch_policy: ignore}"),
     "safety.glitch_policy", "one of"),
    ("negative glitch rate", mutate(r"cmd_timeout: 0.5", "cmd_timeout: 0.5\n    safety: "
                                    "{glitch_rate: -1.0}"),
     "safety.glitch_rate", "[0, 600]"),
    ("glitch rate over 10 a second", mutate(r"cmd_timeout: 0.5", "cmd_timeout: 0.5\n    "
                                            "safety: {glitch_rate: 601}"),
     "safety.glitch_rate", "[0, 600]"),
    ("physics not a multiple of control", mutate(r"physics_rate: 1000.0", "physics_rate: 1100.0"),
     "sim.physics_rate", "integer multiple"),
    ("section that is not a mapping", mutate(r"^    ddrot:\n(.*\n){3}", "    ddrot: 5\n"),
     "ddrot.wheel_radius", "required"),
    ("wrong node name", HAMR.replace("base_controller:", "controller:", 1),
     "robot", "base_controller: ros__parameters"),
    ("not YAML", HAMR + "\n  : - : [\n", "robot", "valid YAML"),
    # powered-caster vehicles
    ("zero caster offset", mutate_xr(r"caster_offset: 0.02", "caster_offset: 0.0"),
     "pcv.caster_offset", "not be holonomic"),
    ("duplicate caster names (duplicate joint names)",
     mutate_xr(r"casters: \[front_left, rear_left,", "casters: [front_left, front_left,"),
     "pcv.casters", "unique caster names"),
    ("one caster", mutate_xr(r"casters: \[.*\]", "casters: [front_left]"),
     "pcv.casters", "at least 2"),
    ("coincident steering axes",
     mutate_xr(r"rear_left: \{h: 0.240416, beta: 2.356194\}",
               "rear_left: {h: 0.240416, beta: 0.785398}"),
     "pcv.rear_left.h", "coincide"),
    ("caster without its geometry", mutate_xr(r"^\s*rear_right: \{h: .*\n", ""),
     "pcv.rear_right.h", "required"),
    ("missing joint limit of a caster",
     mutate_xr(r"^\s*rear_left_steer_joint: .*\n", ""),
     "joints.rear_left_steer_joint.max_velocity", "required"),
    # twist and joint limits
    ("negative speed norm", mutate(r"max_speed: 1.2", "max_speed: -1.2"),
     "limits.linear.max_speed", "[0, 100]"),
    ("speed norm too large", mutate(r"max_speed: 1.2", "max_speed: 1000.0"),
     "limits.linear.max_speed", "[0, 100]"),
    ("negative jerk", mutate(r"max_deceleration: 2.0, max_jerk: 0.0",
                             "max_deceleration: 2.0, max_jerk: -3.0"),
     "limits.linear.x.max_jerk", "[0, 100000]"),
    ("jerk not a number", mutate(r"max_deceleration: 10.0, max_jerk: 0.0",
                                 "max_deceleration: 10.0, max_jerk: high"),
     "limits.angular.z.max_jerk", "a number"),
    ("negative joint acceleration", mutate(r"max_acceleration: 20.0", "max_acceleration: -20.0"),
     "joints.turret_joint.max_acceleration", "[0, 1e+06]"),
    ("infinite joint acceleration",
     mutate_xr(r"front_left_steer_joint: \{max_velocity: 12.0, max_effort: 5.0, "
               r"max_acceleration: 400.0\}",
               "front_left_steer_joint: {max_velocity: 12.0, max_effort: 5.0, "
               "max_acceleration: .inf}"),
     "joints.front_left_steer_joint.max_acceleration", "finite"),
    # swerve bases
    ("one swerve module", mutate_sw(r"modules: \[.*\]", "modules: [fl]"),
     "swerve.modules", "at least 2"),
    ("coincident swerve modules",
     mutate_sw(r"rl: \{x: -0.25, y: 0.25\}", "rl: {x: 0.25, y: 0.25}"),
     "swerve.rl.x", "coincide"),
    ("zero swerve wheel radius", mutate_sw(r"wheel_radius: 0.075", "wheel_radius: 0.0"),
     "swerve.wheel_radius", "(0, 10]"),
    ("negative radius of one module",
     mutate_sw(r"fr: \{x: 0.25, y: -0.25\}", "fr: {x: 0.25, y: -0.25, wheel_radius: -0.1}"),
     "swerve.fr.wheel_radius", "(0, 10]"),
    ("swerve module without its geometry", mutate_sw(r"^\s*rr: \{x: .*\n", ""),
     "swerve.rr.x", "required"),
    ("zero steering gain", mutate_sw(r"steering_gain: 8.0", "steering_gain: 0.0"),
     "swerve.steering_gain", "(0, 1000]"),
    ("negative swerve hold speed", mutate_sw(r"hold_speed: 0.01", "hold_speed: -0.01"),
     "swerve.hold_speed", "[0, 10]"),
    ("swerve drive alignment beyond a right angle",
     mutate_sw(r"drive_alignment: 0.1745", "drive_alignment: 2.0"),
     "swerve.drive_alignment", "[0, 1.5708]"),
    ("negative swerve drive alignment",
     mutate_sw(r"drive_alignment: 0.1745", "drive_alignment: -0.1"),
     "swerve.drive_alignment", "[0, 1.5708]"),
    ("torque mode on a swerve base", mutate_sw(r"control_rate: 200.0",
                                               "control_rate: 200.0\n    control_mode: torque"),
     "control_mode", "'velocity' for kinematics 'swerve'"),
    # typos are named as written, with the nearest key and the section's keys
    ("misspelt key in a section", mutate(r"physics_rate: 1000.0", "physics_rat: 1000.0"),
     "sim.physics_rat", "did you mean 'sim.physics_rate'? Valid keys of section 'sim': "),
    ("misspelt required key", mutate(r"turret_offset: 0.1641", "turet_offset: 0.1641"),
     "ddrot.turet_offset", "did you mean 'ddrot.turret_offset'? Valid keys of section 'ddrot': "
     "half_wheel_separation, left_wheel_radius, right_wheel_radius, turret_offset, wheel_radius"),
    # joint ranges (joints.NAME.min_position / max_position)
    ("joint range with one end only",
     mutate(r"# min_position: -6.2832 .*", "min_position: -6.2832"),
     "joints.turret_joint.max_position", "both ends"),
    ("joint range upside down",
     mutate(r"# min_position: -6.2832 .*\n(\s*)# max_position: 6.2832 .*",
            "min_position: 1.0\n\\1max_position: -1.0"),
     "joints.turret_joint.max_position", "at least min_position + 0.5 rad = 1.5"),
    ("joint range narrower than 0.5 rad",
     mutate(r"# min_position: -6.2832 .*\n(\s*)# max_position: 6.2832 .*",
            "min_position: 0.0\n\\1max_position: 0.2"),
     "joints.turret_joint.max_position", "at least min_position + 0.5 rad"),
    ("joint range beyond three turns",
     mutate(r"# min_position: -6.2832 .*\n(\s*)# max_position: 6.2832 .*",
            "min_position: -30.0\n\\1max_position: 6.2832"),
     "joints.turret_joint.min_position", "[-18.8496, 18.8496]"),
    ("joint range not a number",
     mutate(r"# min_position: -6.2832 .*\n(\s*)# max_position: 6.2832 .*",
            "min_position: -6.2832\n\\1max_position: one turn"),
     "joints.turret_joint.max_position", "a number"),
    ("joint range on a wheel joint",
     mutate_xr(r"front_left_wheel_joint: \{max_velocity: 24.0, max_effort: 6.0, "
               r"max_acceleration: 500.0\}",
               "front_left_wheel_joint: {max_velocity: 24.0, max_effort: 6.0, "
               "max_acceleration: 500.0, min_position: -3.0, max_position: 3.0}"),
     "joints.front_left_wheel_joint.min_position", "continuous"),
    ("misspelt section", mutate(r"^    ddrot:", "    ddrott:"),
     "ddrott.wheel_radius", "did you mean 'ddrot.wheel_radius'? Known sections: "),
]


@pytest.mark.parametrize("case,text,key,allowed", CASES, ids=[c[0] for c in CASES])
def test_invalid_yaml_is_rejected_naming_the_key(tmp_path, case, text, key, allowed):
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    with pytest.raises(ConfigError) as err:
        cfg = load_config(path)
        # driver-level checks happen when the driver is built
        cfg.driver_class(cfg.model, cfg.values, cfg.controller.control_rate)
    assert err.value.key == key, str(err.value)
    assert allowed in str(err.value)


@pytest.mark.parametrize("index", [1, 3, 9, 13, 17, 18, 26], ids=lambda i: CASES[i][0])
def test_bringup_exits_2_with_one_line_naming_the_key(start_bringup, tmp_path, index):
    case, text, key, allowed = CASES[index]
    path = tmp_path / "robot.yaml"
    path.write_text(text)
    proc = start_bringup(str(path))
    assert proc.proc.wait(30) == 2
    log = proc.log()
    assert key in log and allowed in log
    assert "Traceback" not in log


def test_bringup_with_a_missing_file_exits_2(start_bringup, tmp_path):
    proc = start_bringup(str(tmp_path / "nowhere.yaml"))
    assert proc.proc.wait(30) == 2
    assert "an existing YAML file" in proc.log() and "Traceback" not in proc.log()
