"""Every program, every kind of bad input a new user types: ONE line on
stderr naming the problem, exit status 2, no traceback -- and nothing moves
(a program that fails on its arguments never starts a controller).

One table per program: (arguments, words the line must contain). Another
program or option adds its own list and an entry in ``TABLES``. In the
arguments, ``{bad_yaml}``, ``{typo_yaml}``, ``{junk_mcap}`` and ``{file}``
stand for files made by the ``inputs`` fixture (``{file}/x``: a path whose
folder cannot be created, even by root).
"""

from __future__ import annotations

import os
import shutil
import subprocess
import sys

import pytest

from holonomic_core.config import resolve_config

BRINGUP = [
    ([], "the following arguments are required: robot"),
    (["hamrr"], "did you mean 'hamr'"),
    (["hamr", "--driver", "tcp"], "invalid choice: 'tcp'"),
    (["hamr", "-p", "control_rate"], "-p expects NAME:=VALUE"),
    (["hamr", "-p", "control_rate:=[1"], "not valid YAML"),
    (["hamr", "-p", "control_rate:=fast"], "'control_rate' = 'fast': expected a number"),
    (["hamr", "-p", "safety.disarm_mode:=brake"],
     "'safety.disarm_mode' = 'brake': expected one of ['hold', 'coast']"),
    (["hamr", "-p", "safety.hold_time:=-1"], "'safety.hold_time' = -1"),
    (["hamr", "-p", "safety.estop_timeout:=-1"], "'safety.estop_timeout' = -1"),
    (["hamr", "-p", "sim.floor_tilt:=95"], "'sim.floor_tilt' = 95"),
    (["hamr", "-p", "sim.wheel_fiction:=0.8"], "did you mean 'sim.wheel_friction'"),
    (["hamr", "-p", "safety.glitch_policy:=ignore"],
     "'safety.glitch_policy' = 'ignore': expected one of"),
    (["hamr", "-p", "safety.glitch_rate:=-1"], "'safety.glitch_rate' = -1"),
    (["hamr", "-p", "safety.glitch_rate:=often"],
     "'safety.glitch_rate' = 'often': expected a number"),
    (["hamr", "--driver", "cia402", "-p", "cia402.drive_watchdog_reaction:=coast"],
     "'cia402.drive_watchdog_reaction' = 'coast': expected one of"),
    (["hamr", "-p", "limits.linear.max_speed:=-1"],
     "'limits.linear.max_speed' = -1: expected a number in [0, 100]"),
    (["hamr", "-p", "limits.linear.x.max_jerk:=fast"],
     "'limits.linear.x.max_jerk' = 'fast': expected a number"),
    (["hamr", "-p", "joints.turret_joint.max_acceleration:=-5"],
     "'joints.turret_joint.max_acceleration' = -5: expected a number in [0, 1e+06]"),
    (["hamr", "-p", "joints.turret_joint.min_position:=-3.0"],
     "'joints.turret_joint.max_position' = '<missing>': expected a number: a range needs both"),
    (["hamr", "-p", "joints.turret_joint.min_position:=1.0",
      "-p", "joints.turret_joint.max_position:=-1.0"],
     "'joints.turret_joint.max_position' = -1.0: expected at least min_position + 0.5 rad"),
    (["hamr", "--namespace", "my robot"], "'my robot' is not a ROS namespace"),
    (["hamr", "--namespace", "1abc"], "'1abc' is not a ROS namespace"),
    (["hamr", "--params-file", "/nonexistent/params.yaml"], "--params-file: no such file"),
    (["hamr", "--params-file", "{bad_yaml}"], "expected valid YAML"),
    (["{typo_yaml}"], "unknown parameter 'ddrot.turet_offset'"),
    (["hamr", "--gui"], "--gui needs a display"),
    (["hamr", "--record", "run.bag"], "--record wants a FILE.mcap"),
    (["hamr", "--record", "{file}/x/run.mcap"], "--record: cannot create the folder"),
    (["hamr", "--fleet", "0"], "--fleet N must be between 1 and 100"),
    (["hamr", "--fleet", "two"], "invalid int value: 'two'"),
    (["hamr", "--fleet", "2", "--namespace", "r"], "own namespace"),
    (["hamr", "--fleet", "2", "-p", "control_rate:=fast"], "expected a number"),
    (["hamr", "--sim-drives"], "--sim-drives needs --driver cia402 or --driver odrive_can"),
    (["hamr", "--driver", "sim", "--sim-drives"], "--sim-drives needs --driver"),
    (["hamr", "--foxglove", "0"], "--foxglove PORT must be 1..65535"),
    (["hamr", "--foxglove", "http"], "invalid int value: 'http'"),
    (["hamr", "--foxglove-allow-control"], "need --foxglove"),
    (["hamr", "--foxglove-host", "0.0.0.0"], "need --foxglove"),
]

TELEOP = [
    (["--speed", "-1"], "--speed: expected a number > 0"),
    (["--speed", "fast"], "--speed: expected a number > 0, got 'fast'"),
    (["--turn", "nan"], "--turn: expected a number > 0"),
    (["--rate", "0"], "--rate: expected a number in (0, 1000]"),
    (["--key-timeout", "-0.5"], "--key-timeout: expected a number >= 0"),
    (["--speed", "3"], "must not exceed --max-speed"),
    (["--namespace", "1abc"], "'1abc' is not a ROS namespace"),
    (["--colour"], "unrecognized arguments: --colour"),
    ([], "needs a terminal on stdin"),          # stdin is not a terminal here
]

CTL = [
    ([], "the following arguments are required: command"),
    (["arm"], "invalid choice: 'arm'"),
    (["enable", "--namespace", "my robot"], "'my robot' is not a ROS namespace"),
    (["status", "--timeout", "0"], "--timeout: expected a number in (0, 600] s"),
    (["enable", "--json"], "--json goes with status only"),
    (["unwind", "--json"], "--json goes with status only"),
    (["unwind", "--timeout", "-1"], "--timeout: expected a number in (0, 600] s"),
    (["unwnd"], "invalid choice: 'unwnd'"),
    (["set-pose", "1", "nan", "0"], "X Y YAW: expected a number in [-1e+06, 1e+06]"),
    (["set-pose", "1", "2"], "set-pose needs X Y YAW (3 numbers), got 2"),
    (["estop", "1"], "estop takes no numbers"),
]

PLOT = [
    ([], "the following arguments are required: recording"),
    (["/nonexistent/run.mcap"], "no such file: /nonexistent/run.mcap"),
    (["{junk_mcap}"], "cannot read"),
    (["{bad_yaml}"], "cannot read"),
]

ANALYZE = [
    (["hamrr"], "did you mean 'hamr'"),
    (["hamr", "--distance", "0"], "--distance: expected a number in (0, 100] m"),
    (["hamr", "--directions", "1"], "--directions: expected an integer in [2, 360]"),
    (["hamr", "--turret", "nan"], "--turret: expected a number"),
    (["xr4000", "--steer", "a,b"], "comma-separated radians"),
    (["hamr", "-p", "ddrot.turet_offset:=0.2"], "did you mean 'ddrot.turret_offset'"),
    (["hamr", "--sweep", "ddrot.turret_offset"], "--sweep wants KEY=START:STOP:N"),
    (["hamr", "--isotropy"], "powered-caster vehicle"),
    (["hamr", "--plot", "{file}/x"], "cannot write"),
]

DEMO = [
    (["--robot", "hamrr"], "did you mean 'hamr'"),
    (["--robot", "{typo_yaml}"], "unknown parameter 'ddrot.turet_offset'"),
    (["--out", "{file}/x"], "--out: cannot create"),
    (["--speed", "2"], "unrecognized arguments: --speed"),
]

ODOMETRY_EXPERIMENT = [
    (["--robot", "hamrr"], "did you mean 'hamr'"),
    (["--seeds", "0"], "--seeds: expected an integer in [1, 10000]"),
    (["--first-seed", "-1"], "--first-seed: expected an integer in [0, 1e+06]"),
    (["--duration", "-5"], "--duration: expected a number in (0, 3600] s"),
    (["--condition", "wet"], "expected one of nominal, uneven, slippery, worn"),
    (["--json", "{file}/x/trials.json"], "--json: cannot write"),
    (["--profiles", "out"], "--profiles needs --calibrate"),
    (["--default-floor", "worn"], "--default-floor needs --calibrate"),
    (["--calibrate", "--condition", "uneven", "--default-floor", "worn"],
     "--default-floor 'worn tyres (r +-2 %)' is not among the --condition runs"),
    (["--calibrate", "--default-floor", "wet"], "expected one of nominal, uneven"),
    (["--self-calibrate", "--duration", "20"], "--self-calibrate needs --duration >= 40 s"),
    (["--calibrate", "--profiles", "{file}/x"], "--profiles: cannot create the folder"),
    (["--recordings", "{file}/x"], "--recordings: cannot create the folder"),
    (["--validate-motion", "zigzag"], "expected comma-separated kinds of motion among random"),
    (["--validate-motion", ","], "expected comma-separated kinds of motion"),
    (["--fit-motion", "spin"], "--fit-motion needs --calibrate"),
    (["--calibrate", "--fit-motion", "spin,wobble"], "got 'spin,wobble'"),
    (["--validate-floor", "uneven"], "--validate-floor needs --validate-motion"),
    (["--validate-duration", "10"], "--validate-duration needs --validate-motion"),
    (["--validate-motion", "spin", "--validate-duration", "0"],
     "--validate-duration: expected a number in (0, 3600] s"),
    (["--condition", "nominal", "--validate-motion", "spin", "--validate-floor", "uneven"],
     "--validate-floor 'uneven (mu 0.8 +-40 %)' is not among the --condition runs"),
]

TORQUE_EXPERIMENT = [
    (["--robot", "hamr"], "needs a powered-caster vehicle"),
    (["--robot", "xr4001"], "did you mean 'xr4000'"),
    (["--friction", "0"], "--friction: expected a number in (0, 10]"),
    (["--markdown", "{file}/x/table.md"], "--markdown: cannot write"),
]

DRIVE_TEST = [
    ([], "the following arguments are required"),
    (["hamrr", "--joint", "left_wheel_joint"], "did you mean 'hamr'"),
    (["hamr", "--joint", "nope"], "no joint 'nope' on hamr"),
    (["hamr", "--joint", "left_wheel_joint", "--amplitude", "x"], "--amplitude"),
    # a real drive without a confirmation typed at a terminal: nothing moves
    (["hamr", "--joint", "left_wheel_joint", "--driver", "odrive_can"], "not confirmed"),
]

CALIBRATE = [
    ([], "the following arguments are required: robot, recording"),
    (["hamr", "/nonexistent/run.mcap"], "no such file"),
    (["hamr", "{junk_mcap}"], "as an MCAP recording"),
    (["hamr", "{junk_mcap}", "--distance", "-1"], "--distance"),
    (["hamr", "{junk_mcap}", "--distance", "5", "--turns", "-3"], "--turns must be a counted"),
    (["hamr", "{junk_mcap}", "--turns", "3"], "--turns needs --distance"),
    (["hamr", "{junk_mcap}", "--heading-deg", "2"], "--heading-deg needs --distance and --turns"),
    (["hamr", "{junk_mcap}", "--distance", "5", "--turns", "3", "--reference", "ground_truth"],
     "not both"),
    (["hamr", "{junk_mcap}", "--distance", "5", "--turns", "three"], "invalid float value"),
    (["xr4000", "{junk_mcap}", "--straight-run"], "--straight-run needs --distance"),
    (["xr4000", "{junk_mcap}", "--straight-run", "--reference", "ground_truth"],
     "--straight-run needs --distance"),
    (["hamr", "{junk_mcap}", "--distance", "5", "--turns", "3", "--straight-run"],
     "--straight-run is for a pcv"),
    (["xr4000", "{junk_mcap}", "--straight-run=yes"], "ignored explicit argument"),
]

ODOMETRY_CALIBRATE = [
    ([], "the following arguments are required: files"),
    (["/nonexistent/run.mcap"], "/nonexistent/run.mcap"),
]

#: the base controller node alone (``ros2 run holonomic_bringup base_controller``)
BASE_CONTROLLER = [
    ([], "robot_config"),
    (["--ros-args", "-p", "robot_config:=hamrr"], "did you mean 'hamr'"),
    (["--ros-args", "-p", "robot_config:=hamr", "-p", "cmd_timout:=1.0"],
     "did you mean 'cmd_timeout'"),
    # plugins by name (holonomic.drivers / holonomic.kinematics entry points)
    (["--ros-args", "-p", "robot_config:=hamr", "-p", "driver:=sims"], "did you mean 'sim'"),
    (["--ros-args", "-p", "robot_config:=hamr", "-p", "robot.kinematics:=ddrott"],
     "did you mean 'ddrot'"),
]

CALIBRATION_EXPERIMENT = [
    (["--routes", "0"], "--routes N must be 1..100"),
    (["--routes", "two"], "invalid int value: 'two'"),
    (["--route", "tape"], "--route needs --routes N"),
    (["--routes", "1", "--route", "tapes"], "invalid choice: 'tapes'"),
    (["--routes", "1", "--robot", "hamrr"], "did you mean 'hamr'"),
]

TABLES = {
    "holonomic-bringup": BRINGUP,
    "holonomic-teleop": TELEOP,
    "holonomic-ctl": CTL,
    "holonomic-plot": PLOT,
    "holonomic-analyze": ANALYZE,
    "holonomic-demo": DEMO,
    "holonomic-odometry-experiment": ODOMETRY_EXPERIMENT,
    "holonomic-torque-experiment": TORQUE_EXPERIMENT,
    "holonomic-drive-test": DRIVE_TEST,
    "holonomic-calibrate": CALIBRATE,
    "holonomic-odometry-calibrate": ODOMETRY_CALIBRATE,
    "holonomic-calibration-experiment": CALIBRATION_EXPERIMENT,
    "base_controller": BASE_CONTROLLER,
}
CASES = [(program, argv, words) for program, rows in TABLES.items() for argv, words in rows]


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bad_input")
    bad_yaml = folder / "bad.yaml"
    bad_yaml.write_text("base_controller:\n  ros__parameters: [\n")
    typo_yaml = folder / "typo.yaml"
    typo_yaml.write_text(resolve_config("hamr").read_text().replace("turret_offset:",
                                                                   "turet_offset:", 1))
    junk = folder / "junk.mcap"
    junk.write_bytes(b"\x89MCAP0\r\n" + bytes(range(256)))
    plain = folder / "plain_file"
    plain.write_text("")
    return {"bad_yaml": bad_yaml, "typo_yaml": typo_yaml, "junk_mcap": junk, "file": plain}


def command(program: str) -> list[str]:
    if program == "base_controller":
        return [sys.executable, "-c", "import sys; from holonomic_bringup.base_controller_node "
                "import main; sys.exit(main())"]
    exe = shutil.which(program)
    assert exe, f"{program} is not on PATH: run the tests with `make test`"
    return [exe]


@pytest.mark.parametrize("program,argv,words", CASES,
                         ids=[f"{p} {' '.join(a) or '(none)'}" for p, a, _ in CASES])
def test_bad_input_gives_one_line_and_exit_2(inputs, tmp_path, program, argv, words):
    args = [a.format(**inputs) for a in argv]
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "WAYLAND_DISPLAY")}
    proc = subprocess.run(command(program) + args, capture_output=True, text=True, timeout=120,
                          stdin=subprocess.DEVNULL, cwd=tmp_path, env=env)
    lines = proc.stderr.strip().splitlines()
    assert proc.returncode == 2, proc.stderr
    assert len(lines) == 1, proc.stderr
    assert words in lines[0], lines[0]
    assert "Traceback" not in proc.stdout + proc.stderr


#: every program a user runs from the shell (the node is started by bringup)
HELP_PROGRAMS = sorted((set(TABLES) - {"base_controller"}) | {"holonomic-calibration-experiment"})


@pytest.mark.parametrize("program", HELP_PROGRAMS)
def test_help_prints_usage_and_exits_0(tmp_path, program):
    """``--help`` is the first thing a new user types: it prints the usage
    and every option and exits 0. argparse %-formats each help string, so a
    literal '%' in one (holonomic-odometry-experiment's condition names,
    "+-40 %") made --help itself crash with a ValueError."""
    proc = subprocess.run(command(program) + ["--help"], capture_output=True, text=True,
                          timeout=120, stdin=subprocess.DEVNULL, cwd=tmp_path)
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.startswith(f"usage: {program}"), proc.stdout[:200]
    assert "Traceback" not in proc.stdout + proc.stderr
