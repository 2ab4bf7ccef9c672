"""holonomic-bringup --foxglove end to end, seen by an independent Foxglove
WebSocket client (holonomic_testing.foxglove_client: the protocol written
out with the `websockets` library, none of the server's code), with a ROS probe
node driving the robot and watching its ground truth."""

import json
import math
import shutil
import signal
import socket
import subprocess
import threading
import time
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest
from tf2_msgs.msg import TFMessage

from holonomic_core.model import load_model
from holonomic_testing.foxglove_client import (FoxgloveClient, decode_frame_transforms,
                                               pitch_angle, yaw_of)
from holonomic_testing.ros_probe import Bringup, Probe, wait_until

HAMR = load_model("hamr").kinematics
LAYOUT = Path(__file__).resolve().parents[1] / "docs" / "foxglove" / "holonomic_base.json"
#: ROS topics the MCAP recorder writes that the bridge does not serve live
RECORDED_ONLY = {"/cmd_vel"}


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def connect(port: int, proc, *topics: str, timeout: float = 30.0) -> FoxgloveClient:
    """A client, once the bringup listens (it starts before the node) and
    has advertised ``topics`` (default: /odom of the robot without namespace)."""
    end = time.monotonic() + timeout
    while True:
        assert proc.proc.poll() is None, proc.log()
        try:
            client = FoxgloveClient(port)
            break
        except OSError:
            if time.monotonic() > end:
                raise
            time.sleep(0.1)
    client.wait_channels(*(topics or ("/odom",)))
    return client


@pytest.fixture(scope="module")
def hamr(ros, tmp_path_factory):
    """A simulated, armed HAMR served on Foxglove, link transforms on /tf too.
    cmd_timeout 2 s: this test process may stall for a moment on a loaded
    machine, and the robot must keep its speed through that."""
    port = free_port()
    proc = Bringup(["hamr", "--enable", "--foxglove", str(port), "-p", "publish_link_tf:=true",
                    "-p", "cmd_timeout:=2.0"],
                   tmp_path_factory.mktemp("fox") / "bringup.log")
    probe = Probe(ros)
    try:
        probe.wait_ready()
        yield probe, proc, port
    finally:
        probe.close()
        code = proc.stop(signal.SIGINT)
        assert code == 0, proc.log()


#: the channels of a simulated HAMR and their schemas: Foxglove's own for
#: transforms and paths, the ROS message names (JSON) that its panels know
SCHEMAS = {
    "/tf": "foxglove.FrameTransforms",
    "/robot_description": "std_msgs/msg/String",
    "/path/odom": "foxglove.PosesInFrame",
    "/path/ground_truth": "foxglove.PosesInFrame",
    "/odom": "nav_msgs/msg/Odometry",
    "/ground_truth/odom": "nav_msgs/msg/Odometry",
    "/twist_command": "geometry_msgs/msg/Twist",
    "/joint_states": "sensor_msgs/msg/JointState",
    "/controller_state": "holonomic/ControllerState",
    "/diagnostics": "diagnostic_msgs/msg/DiagnosticArray",
}


def publish_forward(client, topic: str, vx: float, seconds: float) -> None:
    """A client publishing "drive forward at vx [m/s]" at 20 Hz, as Foxglove's
    Teleop panel does (geometry_msgs/Twist as JSON on a client channel)."""
    for k in range(round(20 * seconds)):
        client.publish_json(7, topic, "geometry_msgs/msg/Twist",
                            {"linear": {"x": vx, "y": 0.0, "z": 0.0},
                             "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}, advertise=k == 0)
        time.sleep(0.05)


@pytest.fixture
def client(hamr):
    """A Foxglove client of the module's HAMR, every channel advertised."""
    probe, proc, port = hamr
    watcher = connect(port, proc, *SCHEMAS)     # a robot's channels appear one by one
    yield watcher
    watcher.close()


def unwrapped(angles):
    return np.unwrap(np.array(angles))


def tf_since(client, t0):
    """Every /tf message received since t0, decoded (one fixed list)."""
    return [decode_frame_transforms(data) for _, data in client.since("/tf", t0)]


def series(messages, child):
    """(parent, translation, rotation) of ``child`` in each decoded /tf message."""
    return [frames[child] for frames in messages if child in frames]


def test_channels_use_standard_schemas_and_the_server_is_read_only(client):
    info = client.server_info
    # no clientPublish, services or parameters: nothing a client can change
    assert not set(info["capabilities"]) & {"clientPublish", "services", "parameters",
                                            "parametersSubscribe"}, info
    schemas = {topic: c["schemaName"] for topic, c in client.channels.items()}
    assert schemas == SCHEMAS
    client.subscribe(*client.channels)
    # the URDF reaches a new subscriber at once (not only every 5 s)
    urdf = ET.fromstring(client.json("/robot_description")["data"])
    links = {link.get("name") for link in urdf.findall("link")}
    client.wait_for("/tf", 2)
    frames = client.transforms()
    # every link of the description is placed: base_link by odometry,
    # the others by their joints; plus the simulator's ground truth
    assert set(frames) == links | {"base_link_ground_truth"}
    assert frames["base_link"][0] == "odom"
    state = client.json("/controller_state")
    assert state["state"] == "armed" and state["fault"] == "" and state["estop"] == ""
    diagnostics = client.json("/diagnostics")
    names = {s["name"] for s in diagnostics["status"]}
    assert "base_controller: control loop" in names
    assert "base_controller: emergency stop" in names
    assert all(s["level"] in (0, 1, 2, 3) for s in diagnostics["status"])
    path = client.wait_for("/path/odom")
    assert path        # a PosesInFrame with at least the start pose


def _panels(node):
    return [node] if isinstance(node, str) else _panels(node["first"]) + _panels(node["second"])


def _plot_paths(layout):
    return [(panel, p["value"]) for panel, cfg in layout["configById"].items()
            if panel.startswith("Plot!") for p in cfg["paths"]]


def _field(message, path: str):
    for key in path.split("."):
        message = message[key]
    return message


def test_the_layout_shows_what_the_bridge_serves(client):
    """docs/foxglove/holonomic_base.json: every panel laid out, every topic
    served live (or recorded), every plotted field a number in the live data."""
    layout = json.loads(LAYOUT.read_text())
    assert sorted(_panels(layout["layout"])) == sorted(layout["configById"])
    three_d = layout["configById"]["3D!robot"]
    topics = set(three_d["topics"])
    topics.add(layout["configById"]["DiagnosticSummary!diagnostics"]["topicToRender"])
    topics.add(layout["configById"]["RawMessages!state"]["topicPath"])
    plotted = {path.split(".", 1)[0] for _, path in _plot_paths(layout)}
    assert topics | plotted <= set(SCHEMAS) | {"/slip_residual"} | RECORDED_ONLY
    assert three_d["followTf"] == "odom"
    live = sorted(plotted & set(SCHEMAS))
    client.subscribe(*live)
    for panel, path in _plot_paths(layout):
        topic, field = path.split(".", 1)
        if topic in live:
            assert isinstance(_field(client.json(topic), field), float), (panel, path)


def test_links_move_as_the_joints_do_and_the_base_follows_cmd_vel(hamr, client):
    probe = hamr[0]
    client.subscribe("/tf")
    probe.wait_at_rest()
    client.wait_for("/tf")
    start = client.transforms()
    t0 = time.monotonic()
    probe.drive((0.3, 0.0, 0.0), 2.0)
    probe.wait_at_rest()
    time.sleep(0.2)     # a few more /tf messages at rest (30 Hz)
    messages = tf_since(client, t0)
    base, wheel = series(messages, "base_link"), series(messages, "left_wheel")
    dx = base[-1][1][0] - start["base_link"][1][0]
    dy = base[-1][1][1] - start["base_link"][1][1]
    # 2 s at 0.3 m/s, ramps included: 0.55 m when the simulator keeps real
    # time, less on a loaded machine; straight ahead
    assert dx > 0.2 and abs(dy) < 0.02, (dx, dy)
    # the left wheel rolled the distance the base went: angle = d / r
    # (unwrapped from 30 Hz samples: < 0.2 rad apart at 4.9 rad/s)
    spin = unwrapped([pitch_angle(q) for _, _, q in wheel])
    rolled = spin[-1] - spin[0]
    # measured: 0.99984 of d / r (slip while accelerating)
    assert rolled == pytest.approx(dx / HAMR.r, rel=1e-3), (rolled, dx / HAMR.r)
    # /tf and ROS odom: the same estimate (at rest, to 1 mm). "At rest" above
    # is under 5 mm/s: wait until the odometry has stopped changing, then
    # compare it with a /tf message the bridge sent after that
    def settled():
        first = probe.latest_odom().pose
        time.sleep(0.2)
        return np.allclose(probe.latest_odom().pose[:2], first[:2], atol=1e-4)
    wait_until(settled, 5.0, "the odometry to settle")
    odom = probe.latest_odom().pose
    t_odom = time.monotonic()
    latest = wait_until(lambda: series(tf_since(client, t_odom), "base_link"), 2.0,
                        "a /tf message after the odometry settled")
    assert latest[-1][1][:2] == pytest.approx(tuple(odom[:2]), abs=1e-3)

    # strafing left at constant heading: the turret joint turns the
    # drive base to face +-y in base_link (CONTRACT: its forward axis)
    t1 = time.monotonic()
    probe.drive((0.0, 0.3, 0.0), 3.0)
    messages = tf_since(client, t1)
    drive_base = series(messages, "drive_base")
    yaw = yaw_of(drive_base[-1][2])
    # measured: 0.014 (0.057 on a machine at load 20, the simulator slower
    # than real time: the drive base still finishing its turn)
    assert abs(math.cos(yaw)) < 0.1, math.degrees(yaw)
    assert drive_base[-1][1][2] == pytest.approx(HAMR.r, abs=1e-6)   # axle height
    base = series(messages, "base_link")
    assert base[-1][1][1] - base[0][1][1] > 0.2
    probe.wait_at_rest()


def test_a_client_cannot_publish_cmd_vel_through_the_bridge(hamr, client):
    probe = hamr[0]
    probe.wait_at_rest()
    before = probe.latest_truth().pose
    t0 = time.monotonic()
    publish_forward(client, "/cmd_vel", 0.5, 1.0)
    wait_until(lambda: any(s["level"] == 2 and "clientPublish" in s["message"]
                           for s in client.statuses), 5.0, "the server's refusal")
    time.sleep(0.5)           # past any reaction time of the 200 Hz loop
    moved = np.linalg.norm(probe.latest_truth().pose[:2] - before[:2])
    assert moved < 0.002, moved
    assert max(abs(s.twist[0]) for s in probe.truth_since(t0)) < 0.01
    # the robot was armed and would have moved: a ROS command does
    probe.drive((0.2, 0.0, 0.0), 1.0)
    assert np.linalg.norm(probe.latest_truth().pose[:2] - before[:2]) > 0.05
    probe.wait_at_rest()


def test_a_second_client_and_a_vanishing_client_do_not_disturb_the_robot(hamr, client):
    probe, proc, port = hamr
    first = client
    first.subscribe("/tf")
    probe.wait_at_rest()
    driving = threading.Thread(target=probe.drive, args=((0.3, 0.0, 0.0), 5.0))
    t0 = time.monotonic()
    driving.start()
    others = []
    try:
        time.sleep(1.0)
        second, third = connect(port, proc), connect(port, proc)
        others += [second, third]
        second.subscribe(*second.channels)
        third.subscribe(*third.channels)
        third.wait_for("/tf", 3)
        third.drop()              # gone mid-stream, no closing handshake
        t_drop = time.monotonic()
        driving.join()
        # the robot kept its commanded speed through it all (steady window)
        window = [s.twist[0] for s in probe.truth_since(t0 + 1.5) if s.t < t0 + 4.8]
        # measured: mean 0.300004, min 0.299996 m/s
        assert np.mean(window) == pytest.approx(0.3, abs=0.003), np.mean(window)
        assert min(window) > 0.29, min(window)
        # both remaining clients kept receiving
        stamps = [t for t, _ in first.since("/tf", t0)]
        assert max(np.diff(stamps)) < 0.5, max(np.diff(stamps))    # measured: 0.043 s
        assert len(second.since("/tf", t_drop)) > 30
        assert proc.proc.poll() is None
    finally:
        driving.join()
        for other in others:
            other.close()
        probe.wait_at_rest()


def test_publish_link_tf_puts_every_link_on_ros_tf(ros, hamr):
    frames = {}

    def on_tf(msg):
        for t in msg.transforms:
            frames[t.child_frame_id] = t

    sub = ros.create_subscription(TFMessage, "/tf", on_tf, 100)
    try:
        wait_until(lambda: {"base_link", "drive_base", "left_wheel", "right_wheel"}
                   <= set(frames), 10.0, "every HAMR link on /tf")
        assert frames["drive_base"].header.frame_id == "base_link"
        assert frames["left_wheel"].header.frame_id == "drive_base"
        # base_link on the floor: the axle is a wheel radius above it
        assert frames["drive_base"].transform.translation.z == pytest.approx(HAMR.r, abs=1e-6)
    finally:
        ros.destroy_subscription(sub)


#: per robot: its namespace here, its steered wheel units (name, wheel
#: radius), the link each unit steers (the XR4000's caster fork, the swerve
#: module's yoke: pcv_base / swerve_base description.py) and how closely each
#: wheel's roll matches the base's dy / r (relative). Measured: XR4000 within
#: 4e-5; swerve4 within 1.9e-4, its front wheels short and its rear ones long
#: by as much (the simulated base turns a fraction of a mrad meanwhile)
STEERED_UNITS = {
    "xr4000": ("fox_pcv", lambda kin: kin.casters, "fork", 1e-4),
    "swerve4": ("fox_swerve", lambda kin: kin.modules, "yoke", 5e-4),
}


@pytest.mark.parametrize("robot", sorted(STEERED_UNITS))
def test_the_casters_steer_and_roll_as_their_joints(ros, start_bringup, robot):
    ns, units_of, steered, roll_tolerance = STEERED_UNITS[robot]
    port = free_port()
    proc = start_bringup(robot, "--enable", "--namespace", ns,
                         "--foxglove", str(port), "-p", "cmd_timeout:=2.0")
    probe = Probe(ros, ns)
    client = None
    try:
        probe.wait_ready()
        client = connect(port, proc, f"/{ns}/slip_residual")
        client.subscribe("/tf", f"/{ns}/slip_residual")
        units = units_of(load_model(robot).kinematics)
        # the casters (the swerve's modules) turn 90 deg, then roll along +y
        probe.drive((0.0, 0.3, 0.0), 2.5)
        t0 = time.monotonic()
        probe.drive((0.0, 0.3, 0.0), 1.5)
        messages = tf_since(client, t0)      # one window for the base and every unit
        base = series(messages, f"{ns}/base_link")
        dy = base[-1][1][1] - base[0][1][1]
        assert dy > 0.2, dy          # 0.45 m at full speed: it moved
        for unit in units:
            fork = series(messages, f"{ns}/{unit.name}_{steered}")
            assert fork[-1][0] == f"{ns}/base_link"
            yaw = yaw_of(fork[-1][2])
            assert abs(math.cos(yaw)) < 1e-3, (unit.name, math.degrees(yaw))  # meas. 3e-16
            wheel = series(messages, f"{ns}/{unit.name}_wheel")
            spin = unwrapped([pitch_angle(q) for _, _, q in wheel])
            # a wheel heading +-y rolls +-dy / r (sign: its heading)
            rolled = (spin[-1] - spin[0]) * math.copysign(1.0, math.sin(yaw))
            # steady rolling, no acceleration (tolerance: STEERED_UNITS)
            assert rolled == pytest.approx(dy / unit.wheel_radius, rel=roll_tolerance), unit.name
        residual = client.json(f"/{ns}/slip_residual")
        assert set(residual) == {u.name for u in units}
        # the layout's slip plot has a series for each of them
        slip = {path for panel, path in _plot_paths(json.loads(LAYOUT.read_text()))
                if panel == "Plot!slip"}
        assert {f"/slip_residual.{u.name}" for u in units} <= slip
    finally:
        if client is not None:
            client.close()
        probe.close()


def test_allow_control_lets_a_client_drive_and_the_command_timeout_stops_it(
        ros, start_bringup):
    port = free_port()
    proc = start_bringup("hamr", "--enable", "--namespace", "fox_ctl", "--foxglove", str(port),
                         "--foxglove-allow-control")
    probe = Probe(ros, "fox_ctl")
    client = None
    try:
        probe.wait_ready()
        client = connect(port, proc, "/fox_ctl/odom")
        assert "clientPublish" in client.server_info["capabilities"]
        assert client.server_info["supportedEncodings"] == ["json"]
        probe.wait_at_rest()
        before = probe.latest_truth().pose
        publish_forward(client, "/fox_ctl/cmd_vel", 0.3, 2.0)
        moved = probe.latest_truth().pose[0] - before[0]
        assert moved > 0.3, moved
        # the client stops publishing: cmd_timeout (0.5 s) stops the base
        wait_until(lambda: abs(probe.latest_truth().twist[0]) < 0.005, 3.0,
                   "the base to stop after the client went quiet")
    finally:
        if client is not None:
            client.close()
        probe.close()
    assert proc.stop() == 0, proc.log()


def test_a_fleet_is_served_under_its_namespaces(start_bringup):
    port = free_port()
    proc = start_bringup("hamr", "--fleet", "2", "--foxglove", str(port))
    client = connect(port, proc, "/robot1/odom", "/robot2/odom")
    try:
        for k in (1, 2):
            assert client.channels[f"/robot{k}/odom"]["schemaName"] == "nav_msgs/msg/Odometry"
            assert f"/robot{k}/robot_description" in client.channels
        client.subscribe("/tf")
        wait_until(lambda: {"robot1/left_wheel", "robot2/left_wheel"} <= set(client.transforms()),
                   20.0, "both robots' links on /tf")
        frames = client.transforms()
        assert frames["robot2/base_link"][0] == "robot2/odom"
        assert frames["robot2/left_wheel"][0] == "robot2/drive_base"
    finally:
        client.close()


def test_on_a_driver_without_ground_truth_no_ground_truth_is_served(start_bringup):
    port = free_port()
    proc = start_bringup("hamr", "--driver", "mock", "--namespace", "fox_mock",
                         "--foxglove", str(port))
    expected = {"/tf"} | {"/fox_mock" + topic for topic in SCHEMAS if topic != "/tf"} - {
        "/fox_mock/ground_truth/odom", "/fox_mock/path/ground_truth"}
    client = connect(port, proc, *expected)
    try:
        assert set(client.channels) == expected
        client.subscribe("/tf")
        wait_until(lambda: "fox_mock/left_wheel" in client.transforms(), 10.0, "the links")
        assert "fox_mock/base_link_ground_truth" not in client.transforms()
    finally:
        client.close()


def _bringup(*args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("holonomic-bringup")
    assert exe, "holonomic-bringup is not on PATH: run the tests with `make test`"
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=60)


def test_foxglove_on_a_port_in_use_is_one_line_and_exit_2():
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        result = _bringup("hamr", "--enable", "--foxglove", str(port))
    lines = (result.stdout + result.stderr).strip().splitlines()
    assert result.returncode == 2, result
    assert len(lines) == 1 and f"127.0.0.1:{port}" in lines[0] and "in use" in lines[0], lines


@pytest.mark.parametrize("args, what", [
    (("--foxglove", "8765", "--foxglove-host", "no.such.host.invalid"), "no.such.host"),
    (("--foxglove-allow-control",), "need --foxglove"),
    (("--foxglove", "70000"), "1..65535"),
    # a bad config: its own one line, nothing about Foxglove
    (("--foxglove", str(free_port()), "-p", "cmd_timeout:=-1"), "cmd_timeout"),
])
def test_bad_foxglove_arguments_are_one_line_and_exit_2(args, what):
    result = _bringup("hamr", *args)
    lines = (result.stdout + result.stderr).strip().splitlines()
    assert result.returncode == 2 and len(lines) == 1 and what in lines[0], result


def test_client_twists_are_read_as_ros_would_and_garbage_is_refused():
    from holonomic_bringup.foxglove_bridge import parse_twist_json

    # geometry_msgs/Twist as Foxglove's Teleop panel sends it; missing fields are 0
    assert parse_twist_json(b'{"linear": {"x": 0.5, "y": -0.25}, "angular": {"z": 1}}') \
        == (0.5, -0.25, 1.0)
    assert parse_twist_json(b'{"angular": {"z": -0.5}}') == (0.0, 0.0, -0.5)
    # TwistStamped: the twist inside
    assert parse_twist_json(b'{"header": {}, "twist": {"linear": {"x": 0.2}}}') \
        == (0.2, 0.0, 0.0)
    for bad in (b"not json", b"[1, 2]", b'{"linear": {"x": "fast"}}',
                b'{"linear": {"x": true}}', b'{"linear": 3}'):
        with pytest.raises(ValueError):
            parse_twist_json(bad)


def test_odometry_json_has_the_ros_layout_and_a_planar_covariance():
    from holonomic_bringup.foxglove_bridge import odometry_message

    cov = ((1.0, 2.0, 3.0), (2.0, 4.0, 5.0), (3.0, 5.0, 6.0))      # over (x, y, yaw)
    msg = odometry_message(1_500_000_000, "odom", "base_link", (1.0, 2.0, math.pi / 2),
                           (0.1, 0.2, 0.3), cov, cov)
    assert msg["header"] == {"stamp": {"sec": 1, "nsec": 500_000_000}, "frame_id": "odom"}
    q = msg["pose"]["pose"]["orientation"]
    assert (q["z"], q["w"]) == pytest.approx((math.sqrt(0.5), math.sqrt(0.5)))  # yaw 90 deg
    assert msg["twist"]["twist"]["angular"]["z"] == 0.3
    full = np.array(msg["pose"]["covariance"]).reshape(6, 6)
    # rows/columns x, y, yaw of the 6x6 (x y z roll pitch yaw) = 0, 1, 5
    assert full[np.ix_([0, 1, 5], [0, 1, 5])].tolist() == [list(r) for r in cov]
    assert full[2:5, :].sum() == 0.0
