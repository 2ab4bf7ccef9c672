"""What a ROS user relies on around the base: recording and plotting,
robot_description, several robots in one world, DDS domains, the launch
file, and parameter docs that match the code."""

from __future__ import annotations

import ast
import contextlib
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from holonomic_testing.ros_probe import (Bringup, Probe, Teleop, claim_domain_id, relative_pose,
                                         spin_in_thread, wait_until)

ROOT = Path(__file__).resolve().parents[1]


def read_recording(path):
    """(topic -> [decoded message], metadata records) of an MCAP file."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory
    topics: dict[str, list] = {}
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        meta = [m for m in reader.iter_metadata()]
        for _, channel, _, msg in reader.iter_decoded_messages():
            topics.setdefault(channel.topic, []).append(msg)
    return topics, meta


#: the keys of one offered QoS profile, in rosbag2's order (rosbag2_storage,
#: qos.cpp: convert<Rosbag2QoS>::encode, metadata version 9)
ROSBAG2_QOS_KEYS = ["history", "depth", "reliability", "durability", "deadline", "lifespan",
                    "liveliness", "liveliness_lease_duration", "avoid_ros_namespace_conventions"]


def playback_durability(offered_qos_profiles: str) -> str:
    """The durability `ros2 bag play` offers when it republishes a channel,
    decided as rosbag2_storage's Rosbag2QoS::adapt_offer_to_recorded_offers
    does: the recorded publishers' profile when all of them agree on the
    policies that decide compatibility (reliability, durability, deadline,
    liveliness and its lease), else rosbag2's default profile (volatile)."""
    import yaml
    profiles = yaml.safe_load(offered_qos_profiles) or []
    same = ("reliability", "durability", "deadline", "liveliness", "liveliness_lease_duration")
    if profiles and all(p[k] == profiles[0][k] for p in profiles for k in same):
        return profiles[0]["durability"]
    return "volatile"


def channel_metadata(path):
    """topic -> the channel's metadata of an MCAP file."""
    from mcap.reader import make_reader
    with open(path, "rb") as handle:
        summary = make_reader(handle).get_summary()
    return {c.topic: dict(c.metadata) for c in summary.channels.values()}


def run(*argv, timeout=120):
    return subprocess.run(list(argv), capture_output=True, text=True, timeout=timeout)


# -- recording, plotting, robot_description ----------------------------------------------------
def test_recording_holds_every_topic_and_the_plot_reads_it(ros, tmp_path):
    bag = tmp_path / "run.mcap"
    robot = Bringup(["xr4000", "--namespace", "rec", "--enable", "--record", str(bag)],
                    tmp_path / "bringup.log")
    probe = Probe(ros, "rec")
    got = []
    latched = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
    try:
        probe.wait_ready()
        probe.drive((0.3, 0.2, 0.4), 2.0)
        probe.wait_at_rest()
        # a subscriber that comes late still gets the URDF (latched)
        sub = ros.create_subscription(String, "/rec/robot_description", got.append, latched)
        wait_until(lambda: got, 10, "robot_description")
        ros.destroy_subscription(sub)
    finally:
        probe.close()
        assert robot.stop() == 0, robot.log()
    urdf = got[0].data
    assert urdf.startswith("<?xml") or "<robot" in urdf
    assert all(f'joint name="{j}"' in urdf for j in ("front_left_steer_joint",
                                                      "rear_right_wheel_joint"))

    topics, meta = read_recording(bag)
    for topic in ("/rec/cmd_vel", "/rec/odom", "/tf", "/rec/joint_states",
                  "/rec/ground_truth/odom", "/rec/diagnostics", "/rec/robot_description"):
        assert topics.get(topic), f"{topic} not recorded: {sorted(topics)}"
    assert any(abs(m.linear.y - 0.2) < 1e-9 for m in topics["/rec/cmd_vel"])
    odom = topics["/rec/odom"]
    assert len(odom) > 50 and odom[-1].pose.pose.position.x > 0.3
    assert topics["/tf"][-1].transforms[0].child_frame_id == "rec/base_link"
    assert topics["/rec/joint_states"][-1].name[0] == "front_left_steer_joint"
    assert [m.name for m in meta] == ["holonomic_robot"]
    assert "xr4000" in meta[0].metadata["config"]
    # every channel carries its publishers' QoS as rosbag2 writes it, and a
    # replay re-latches the URDF (transient local) but not the odometry
    import yaml
    channels = channel_metadata(bag)
    for topic, metadata in channels.items():
        profiles = yaml.safe_load(metadata["offered_qos_profiles"])
        assert profiles and all(list(p) == ROSBAG2_QOS_KEYS for p in profiles), (topic, metadata)
        assert all(set(p["deadline"]) == {"sec", "nsec"} for p in profiles)
    assert playback_durability(channels["/rec/robot_description"]["offered_qos_profiles"]) \
        == "transient_local"
    assert playback_durability(channels["/rec/odom"]["offered_qos_profiles"]) == "volatile"
    assert yaml.safe_load(channels["/rec/odom"]["offered_qos_profiles"])[0]["reliability"] \
        == "reliable"

    out = tmp_path / "plots"
    proc = run(sys.executable, "-c", "import sys; from holonomic_bringup.recording_plot "
               "import main; sys.exit(main(sys.argv[1:]))", str(bag), "--out", str(out))
    assert proc.returncode == 0, proc.stderr
    assert "final_position_error_m" in proc.stdout and "max_slip_residual_m_s" in proc.stdout
    for name in ("run_rec_motion.png", "run_rec_slip.png"):
        assert (out / name).stat().st_size > 20_000
    # the same recording calibrates the odometry covariance (a real floor:
    # another reference topic); 2 s of driving is only a smoke test of the path
    proc = run(sys.executable, "-c", "import sys; from holonomic_bringup.odometry_calibrate "
               "import main; sys.exit(main(sys.argv[1:]))", str(bag), "--namespace", "rec")
    assert proc.returncode == 0, proc.stderr
    assert "calibrated coverage" in proc.stdout and "linear_variance_per_meter" in proc.stdout


def test_plot_refuses_a_file_that_is_not_a_recording(tmp_path):
    junk = tmp_path / "junk.mcap"
    junk.write_bytes(b"\x89MCAP0\r\n" + os.urandom(200))
    code = "import sys; from holonomic_bringup.recording_plot import main; sys.exit(main(sys.argv[1:]))"
    calibrate = code.replace("recording_plot", "odometry_calibrate")
    for path in (junk, tmp_path / "missing.mcap"):
        for program in (code, calibrate):
            proc = run(sys.executable, "-c", program, str(path))
            assert proc.returncode == 2 and "Traceback" not in proc.stderr, proc.stderr
            assert str(path) in proc.stderr


# -- several robots ------------------------------------------------------------------------
def test_a_fleet_of_three_in_one_world_each_obeys_only_its_own_cmd_vel(ros, tmp_path):
    bag = tmp_path / "fleet.mcap"
    fleet = Bringup(["hamr", "--fleet", "3", "--enable", "--record", str(bag)],
                    tmp_path / "fleet.log")
    probes = {k: Probe(ros, f"robot{k}") for k in (1, 2, 3)}
    try:
        for probe in probes.values():
            probe.wait_ready()
        starts = {k: p.latest_truth().pose for k, p in probes.items()}
        probes[2].drive((0.0, 0.4, 0.0), 1.5)         # strafe robot2 only
        probes[3].drive((0.4, 0.0, 0.0), 1.0)         # then robot3 forward
        for probe in probes.values():
            probe.wait_at_rest()
        moved = {k: relative_pose(starts[k], p.latest_truth().pose) for k, p in probes.items()}
        assert np.linalg.norm(moved[1][:2]) < 0.005, moved
        assert moved[2][1] > 0.4 and abs(moved[2][0]) < 0.03, moved
        assert moved[3][0] > 0.25 and abs(moved[3][1]) < 0.03, moved
        # each odometry follows its own robot
        for k, p in probes.items():
            assert np.linalg.norm(p.latest_odom().pose[:2] - p.latest_truth().pose[:2]) < 0.02
        # and every service is the robot's own
        assert probes[2].enable(False).success
        probes[2].drive((0.4, 0.0, 0.0), 0.5)
        probes[3].drive((0.4, 0.0, 0.0), 0.5)
        probes[3].wait_at_rest()
        assert np.linalg.norm(probes[2].latest_truth().twist) < 1e-3
    finally:
        for probe in probes.values():
            probe.close()
        assert fleet.stop() == 0, fleet.log()
    topics, meta = read_recording(bag)
    assert [m.metadata["namespace"] for m in meta] == ["/robot1", "/robot2", "/robot3"]
    frames = {t.transforms[0].header.frame_id for t in topics["/tf"]}
    assert frames == {"robot1/odom", "robot2/odom", "robot3/odom"}


def test_fleet_arguments_that_make_no_sense_are_refused(tmp_path):
    for extra, words in ((["--fleet", "0"], "between 1 and 100"),
                         (["--fleet", "2", "--driver", "mock"], "simulation only"),
                         (["--fleet", "2", "--namespace", "x"], "own namespace")):
        proc = run(sys.executable, "-c", "import sys; from holonomic_bringup.bringup import "
                   "main; sys.exit(main(sys.argv[1:]))", "hamr", *extra)
        assert proc.returncode == 2 and words in proc.stderr, proc.stderr


# -- DDS domains -------------------------------------------------------------------------------
@contextlib.contextmanager
def node_in_domain(domain_id: int, name: str):
    """An rclpy node in another ROS domain (its own context), spun in a thread."""
    import rclpy

    context = rclpy.Context()
    rclpy.init(context=context, domain_id=domain_id)
    node = rclpy.create_node(name, context=context)
    stop = spin_in_thread(node, context)
    try:
        yield node
    finally:
        stop()
        node.destroy_node()
        rclpy.try_shutdown(context=context)


def test_teleop_in_the_robots_domain_drives_it_and_another_domain_cannot(ros, tmp_path):
    """Two processes in one domain talk (teleop -> robot); a publisher in
    another domain (this test process) is not heard."""
    other = claim_domain_id()
    bag = tmp_path / "other.mcap"
    robot = Bringup(["hamr", "--namespace", "dom", "--enable", "--record", str(bag)],
                    tmp_path / "robot.log", env={"ROS_DOMAIN_ID": str(other)})
    probe = Probe(ros, "dom")                        # this process: the test's own domain
    teleop = None
    with node_in_domain(other, "other_domain_watcher") as watcher_node:
        watcher = Probe(watcher_node, "dom")         # a witness in the robot's domain
        try:
            # the robot is up and has matched a cmd_vel publisher in its own
            # domain: had our domain been the same, it would hear us now
            watcher.wait_ready()
            assert probe.cmd_pub.get_subscription_count() == 0
            probe.drive((0.5, 0.0, 0.0), 1.5)        # unheard
            env_before = os.environ["ROS_DOMAIN_ID"]
            os.environ["ROS_DOMAIN_ID"] = str(other)  # the teleop process inherits it
            try:
                teleop = Teleop("--namespace", "dom", "--speed", "0.4")
            finally:
                os.environ["ROS_DOMAIN_ID"] = env_before
            # hold J (strafe left at 0.4 m/s) until the robot has gone 0.5 m:
            # however long the teleop takes to discover the robot
            deadline = time.monotonic() + 30.0
            while watcher.latest_truth().pose[1] <= 0.5:
                assert time.monotonic() < deadline, "the teleop never drove the robot"
                teleop.hold("J", 0.2)
            watcher.wait_at_rest(timeout=10.0)
        finally:
            if teleop is not None:
                assert teleop.stop() == 0
            watcher.close()
            probe.close()
            assert robot.stop() == 0, robot.log()
    topics, _ = read_recording(bag)
    commands = topics.get("/dom/cmd_vel", [])
    assert commands and all(m.linear.x == 0.0 for m in commands)   # none from this domain
    assert any(m.linear.y == pytest.approx(0.4) for m in commands)  # the teleop's strafe
    truth = topics["/dom/ground_truth/odom"][-1].pose.pose.position
    assert truth.y > 0.5 and abs(truth.x) < 0.05, (truth.x, truth.y)


# -- full-ROS launch file, parameter docs ------------------------------------------------------
def test_launch_file_mirrors_the_bringup_arguments():
    path = ROOT / "src" / "holonomic_bringup" / "launch" / "bringup.launch.py"
    tree = ast.parse(path.read_text())
    functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in functions
    args = next(n for n in tree.body if isinstance(n, ast.Assign)
                and getattr(n.targets[0], "id", "") == "ARGUMENTS")
    names = {elt.elts[0].value for elt in args.value.elts}
    assert names == {"robot", "driver", "namespace", "params_file", "enable"}
    from holonomic_bringup.bringup import parse_args
    bringup = parse_args(["hamr", "--driver", "mock", "--namespace", "n",
                          "--params-file", str(ROOT / "config" / "hamr.yaml"), "--enable"])
    assert {"driver", "namespace", "params_file", "enable", "robot"} <= set(vars(bringup))


def test_launch_file_starts_the_base_controller_with_the_arguments_given():
    """Evaluates the launch description as `ros2 launch` would. launch and
    launch_ros are not on PyPI (only in a full ROS 2 install), so this runs
    only where a full ROS 2 Jazzy is sourced."""
    pytest.importorskip("launch", reason="launch is not on PyPI: needs a full ROS 2 install")
    pytest.importorskip("launch_ros",
                        reason="launch_ros is not on PyPI: needs a full ROS 2 install")
    import importlib.util

    from launch import LaunchContext
    from launch.actions import DeclareLaunchArgument, OpaqueFunction

    path = ROOT / "src" / "holonomic_bringup" / "launch" / "bringup.launch.py"
    spec = importlib.util.spec_from_file_location("bringup_launch", path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    declared = {e.name: e for e in description.entities if isinstance(e, DeclareLaunchArgument)}
    assert set(declared) == {"robot", "driver", "namespace", "params_file", "enable"}
    context = LaunchContext()
    context.launch_configurations.update({"robot": "xr4000", "driver": "mock",
                                          "namespace": "/left/", "params_file": "",
                                          "enable": "true"})
    opaque = next(e for e in description.entities if isinstance(e, OpaqueFunction))
    (node,) = opaque.execute(context)
    assert node.node_package == "holonomic_bringup" and node.node_executable == "base_controller"


def test_launch_file_keeps_an_exported_discovery_range():
    # The launch file needs `launch` (a full ROS install); its discovery rule
    # is a plain function, run here alone.
    path = ROOT / "src" / "holonomic_bringup" / "launch" / "bringup.launch.py"
    text = path.read_text()
    func = next(n for n in ast.parse(text).body
                if isinstance(n, ast.FunctionDef) and n.name == "discovery_env")
    scope: dict = {}
    exec(ast.get_source_segment(text, func), scope)
    assert scope["discovery_env"]({"ROS_AUTOMATIC_DISCOVERY_RANGE": "SUBNET"}) == {}
    assert scope["discovery_env"]({}) == {"ROS_AUTOMATIC_DISCOVERY_RANGE": "LOCALHOST"}
    assert "additional_env=discovery_env(os.environ)" in text


def test_parameter_tables_in_the_readme_match_the_schema():
    proc = run(sys.executable, str(ROOT / "scripts" / "param_docs.py"), "--check")
    assert proc.returncode == 0, proc.stderr
    readme = (ROOT / "src" / "holonomic_bringup" / "README.md").read_text()
    for key in ("`frame_prefix`", "`cmd_vel_stamped`", "`sim.start_pose`",
                "`odrive_can.heartbeat_timeout`", "`pcv.NAME.beta`"):
        assert key in readme
