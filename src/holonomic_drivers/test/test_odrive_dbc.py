"""The ODrive backend against ODrive's own description of CANSimple: the
DBC files ``odrive-cansimple-0.6.10.dbc`` and ``odrive-cansimple-0.5.6.dbc``
as shipped in the PyPI package odrive-can 2.1.0 (a pinned test dependency;
the files are read from the installed package, never copied here), decoded
and encoded with cantools.

* every frame the driver sends -- configure, arm, velocity, torque, disarm
  -- is decoded with the DBC: message name, signal values and units;
* heartbeats and encoder estimates *encoded from the DBC* are read back by
  the driver: positions, speeds, axis states, and the error names of each
  firmware line (the same bit is MOTOR_FAILED on 0.5.x, MISSING_INPUT on 0.6.x);
* the emulated axis's own frames decode with the DBC too;
* node ids: 0..63 on 0.5.x, 0..62 on 0.6.x (0x3F is 0.6's broadcast id).
"""

from __future__ import annotations

import importlib.util
import json
import math
import struct
import threading
import time
from pathlib import Path

import can
import cantools
import pytest

from holonomic_core.config import load_config
from holonomic_core.driver import DriverFault
from holonomic_core.schema import ConfigError
from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers.emulation import EmulatedOdriveAxis
from holonomic_testing.can_rig import CanRig, unique_channel
from holonomic_testing.ros_probe import wait_until

DBC_FILES = {"0.6": "odrive-cansimple-0.6.10.dbc", "0.5": "odrive-cansimple-0.5.6.dbc"}


def load_dbc(firmware: str):
    """ODrive's CANSimple DBC for ``firmware``, from the installed odrive-can package."""
    spec = importlib.util.find_spec("odrive_can")
    assert spec is not None, "odrive-can (requirements.txt) is not installed"
    folder = Path(next(iter(spec.submodule_search_locations))) / "dbc"
    return cantools.database.load_file(str(folder / DBC_FILES[firmware]))


def decode(db, msg: can.Message) -> tuple[str, dict, dict]:
    """(message name, {signal: value or choice name}, {signal: unit}); the frame
    must carry every signal of the DBC's message and be no longer than it (a
    real ODrive takes a frame shorter than the DBC's 8 bytes when it covers
    the signals: 4-byte Set_Axis_State, as in ODrive's own examples)."""
    message = db.get_message_by_frame_id(msg.arbitration_id)
    assert len(msg.data) <= message.length, (message.name, bytes(msg.data))
    values = message.decode(bytes(msg.data), decode_choices=True, allow_truncated=True)
    assert set(values) == {s.name for s in message.signals}, (message.name, bytes(msg.data))
    return (message.name, {k: str(v) if hasattr(v, "name") else v for k, v in values.items()},
            {s.name: s.unit for s in message.signals})


# hamr.yaml's odrive_can mapping: left node 0 (+1, 1:1), right node 1 (-1, 1:1),
# turret node 2 (+1, 10:1)
JOINT_VELOCITIES = [2.0, 3.0, 0.5]                         # [rad/s]
# motor rev/s = direction * gear * w / 2 pi
MOTOR_REV_PER_S = [2.0 / (2 * math.pi), -3.0 / (2 * math.pi), 10 * 0.5 / (2 * math.pi)]
JOINT_TORQUES = [0.4, -0.2, 1.5]                           # [N m]
# motor N m = direction * tau / gear (ideal gear)
MOTOR_TORQUES = [0.4, 0.2, 0.15]


@pytest.mark.parametrize("firmware", ["0.6", "0.5"])
def test_every_frame_the_driver_sends_decodes_with_odrives_dbc(firmware):
    db = load_dbc(firmware)
    rig = CanRig("odrive_can", "hamr", **{"odrive_can.firmware": firmware})
    driver = rig.driver
    try:
        phases = {}

        def phase(name, action):
            start = len(rig.sniff())
            action()
            time.sleep(0.05)          # let the emulated axes answer
            phases[name] = rig.sniff()[start:]

        phase("configure", rig.configure_driver)
        phase("arm", driver.activate)
        phase("velocity", lambda: driver.write_velocities(JOINT_VELOCITIES))
        phase("torque", lambda: driver.write_efforts(JOINT_TORQUES))
        phase("disarm", driver.deactivate)
    finally:
        rig.close()

    def sent(name):
        """(node, message name without the axis prefix, values) the host sent."""
        out = []
        for msg in phases[name]:
            node, cmd = proto.split_id(msg.arbitration_id)
            if cmd in (proto.Cmd.HEARTBEAT, proto.Cmd.GET_ENCODER_ESTIMATES):
                continue                       # the axes' own cyclic messages
            message, values, units = decode(db, msg)
            assert message.startswith(f"Axis{node}_")
            out.append((node, message.split("_", 1)[1], values, units))
        return out

    velocity_mode = {"Control_Mode": "VELOCITY_CONTROL", "Input_Mode": "PASSTHROUGH"}
    zero_velocity = {"Input_Vel": 0.0, "Input_Torque_FF": 0.0}
    for node in (0, 1, 2):
        assert [(m, v) for n, m, v, _ in sent("configure") if n == node] == [
            ("Set_Controller_Mode", velocity_mode), ("Set_Input_Vel", zero_velocity),
            ("Set_Axis_State", {"Axis_Requested_State": "IDLE"})]
        # 0.6.10: Clear_Errors carries Identify (0: do not blink); 0.5.6: no payload
        clear = {"Identify": 0} if firmware == "0.6" else {}
        arm = [(m, v) for n, m, v, _ in sent("arm") if n == node]
        assert arm[:4] == [
            ("Clear_Errors", clear), ("Set_Controller_Mode", velocity_mode),
            ("Set_Input_Vel", zero_velocity),
            ("Set_Axis_State", {"Axis_Requested_State": "CLOSED_LOOP_CONTROL"})]
        # then, until the heartbeats confirm closed loop, zero velocity every
        # ARM_FEED_PERIOD: it feeds the axis watchdog while the driver waits
        assert set(map(str, arm[4:])) <= {str(("Set_Input_Vel", zero_velocity))}
        [(_, message, values, units)] = [s for s in sent("velocity") if s[0] == node]
        assert message == "Set_Input_Vel"
        assert values["Input_Vel"] == pytest.approx(MOTOR_REV_PER_S[node], rel=1e-6)
        assert values["Input_Torque_FF"] == 0.0
        torque = [(m, v) for n, m, v, _ in sent("torque") if n == node]
        assert torque[0] == ("Set_Controller_Mode", {"Control_Mode": "TORQUE_CONTROL",
                                                     "Input_Mode": "PASSTHROUGH"})
        assert torque[1][0] == "Set_Input_Torque"
        assert torque[1][1]["Input_Torque"] == pytest.approx(MOTOR_TORQUES[node], rel=1e-6)
        assert [(m, v) for n, m, v, _ in sent("disarm") if n == node] == [
            ("Set_Input_Vel", zero_velocity), ("Set_Input_Torque", {"Input_Torque": 0.0}),
            ("Set_Axis_State", {"Axis_Requested_State": "IDLE"})]
    if firmware == "0.6":
        # the units the driver assumes are the DBC's (0.5.6's file labels
        # Input_Vel "rev", a slip of that file: its Vel_Estimate is "rev/s")
        units = {m: u for _, m, _, u in sent("velocity") + sent("torque")}
        assert units["Set_Input_Vel"] == {"Input_Vel": "rev/s", "Input_Torque_FF": "Nm"}
        assert units["Set_Input_Torque"] == {"Input_Torque": "Nm"}
    # the emulated axes' heartbeats decode with the same file: IDLE while
    # configured, CLOSED_LOOP_CONTROL once armed, no error
    states = {name: {decode(db, m)[1]["Axis_State"] for m in phases[name]
                     if proto.split_id(m.arbitration_id)[1] == proto.Cmd.HEARTBEAT}
              for name in ("configure", "velocity")}
    assert states == {"configure": {"IDLE"}, "velocity": {"CLOSED_LOOP_CONTROL"}}


class DbcAxes:
    """Three scripted ODrive axes (nodes 0, 1, 2) on a virtual channel whose
    every frame is encoded from the DBC; heartbeats and estimates every 5 ms."""

    def __init__(self, db, channel: str, firmware: str):
        self.db, self.firmware = db, firmware
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.heartbeat = {n: {"Axis_Error": 0, "Axis_State": "IDLE"} for n in range(3)}
        self.estimates = {n: {"Pos_Estimate": 0.0, "Vel_Estimate": 0.0} for n in range(3)}
        self.lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)
        self._thread.start()

    def _encode(self, name: str, values: dict) -> can.Message:
        message = self.db.get_message_by_name(name)
        full = {s.name: 0 for s in message.signals}
        full.update(values)
        return can.Message(arbitration_id=message.frame_id, data=message.encode(full),
                           is_extended_id=False)

    def _listen(self):
        """Handle what reached the axes (nothing here: they only send)."""

    def _run(self):
        while not self._stop.is_set():
            self._listen()
            with self.lock:
                frames = [self._encode(f"Axis{n}_Heartbeat", self.heartbeat[n])
                          for n in range(3)]
                frames += [self._encode(f"Axis{n}_Get_Encoder_Estimates", self.estimates[n])
                           for n in range(3)]
            for msg in frames:
                self.bus.send(msg)
            self._stop.wait(0.005)

    def close(self):
        self._stop.set()
        self._thread.join(2.0)
        self.bus.shutdown()


@pytest.fixture(params=["0.6", "0.5"])
def dbc_axes(request):
    firmware = request.param
    channel = unique_channel("dbc")
    config = load_config("hamr", {"driver": "odrive_can", "odrive_can.interface": "virtual",
                                  "odrive_can.channel": channel,
                                  "odrive_can.firmware": firmware})
    axes = DbcAxes(load_dbc(firmware), channel, firmware)
    driver = config.driver_class(config.model, config.values, config.controller.control_rate)
    try:
        driver.configure()
        yield driver, axes
    finally:
        driver.close()
        axes.close()


def test_encoder_estimates_and_heartbeats_encoded_from_the_dbc_are_read_back(dbc_axes):
    driver, axes = dbc_axes
    # at rest: joint = direction * 2 pi * rev / gear (hamr.yaml), no extrapolation
    with axes.lock:
        for n, rev in enumerate((1.25, -0.5, 3.75)):
            axes.estimates[n] = {"Pos_Estimate": rev, "Vel_Estimate": 0.0}
    expected = [2 * math.pi * 1.25, -2 * math.pi * -0.5, 2 * math.pi * 3.75 / 10]
    wait_until(lambda: driver.read().positions.tolist() == pytest.approx(expected, rel=1e-6),
               2.0, "the DBC-encoded positions")
    # moving: joint rad/s = direction * 2 pi * rev/s / gear
    with axes.lock:
        for n, rev_s in enumerate((0.5, 0.25, -2.0)):
            axes.estimates[n]["Vel_Estimate"] = rev_s
    expected = [2 * math.pi * 0.5, -2 * math.pi * 0.25, 2 * math.pi * -2.0 / 10]
    wait_until(lambda: driver.read().velocities.tolist() == pytest.approx(expected, rel=1e-6),
               2.0, "the DBC-encoded speeds")
    # disarmed, an axis error is only reported, by its name in this firmware's file
    with axes.lock:
        axes.heartbeat[2] = {"Axis_Error": 0x40, "Axis_State": "IDLE"}
    name = axes.db.get_message_by_name("Axis2_Heartbeat").get_signal_by_name(
        "Axis_Error").choices[0x40]
    assert str(name) == ("MOTOR_FAILED" if axes.firmware == "0.5" else "MISSING_INPUT")
    wait_until(lambda: driver.read() and str(name) in driver.status()["turret_joint"], 2.0,
               "the error in status")


def first_fault(driver, timeout: float = 2.0) -> str:
    """Read every 5 ms until the driver faults; the fault's message."""
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            driver.read()
        except DriverFault as exc:
            return str(exc)
        time.sleep(0.005)
    pytest.fail(f"no DriverFault within {timeout} s")


def _arm(driver, axes, heartbeat_extra: dict) -> None:
    """Arm: the scripted axes report closed-loop control from now on."""
    with axes.lock:
        for n in range(3):
            axes.heartbeat[n] = {"Axis_Error": 0, "Axis_State": "CLOSED_LOOP_CONTROL",
                                 **heartbeat_extra}
    driver.activate()


def test_heartbeat_layout_and_error_names_follow_the_firmware(dbc_axes):
    driver, axes = dbc_axes
    # bytes 5..7 of a healthy heartbeat: 0.6 procedure result BUSY (1) and
    # trajectory done; 0.5 trajectory done (bit 63). Read in the other
    # firmware's layout, 0.6's byte 5 = 1 would be a motor error flag.
    healthy = ({"Procedure_Result": 1, "Trajectory_Done_Flag": 1} if axes.firmware == "0.6"
               else {"Trajectory_Done_Flag": 1})
    _arm(driver, axes, healthy)
    for _ in range(10):
        driver.read()
        time.sleep(0.005)
    assert driver.armed
    # the same Axis_Error bit, named as this firmware names it
    fault = {"Axis_Error": 0x800, "Axis_State": "IDLE"}
    if axes.firmware == "0.5":
        fault["Controller_Error_Flag"] = 1
    with axes.lock:
        axes.heartbeat[1] = fault
    name = str(axes.db.get_message_by_name("Axis1_Heartbeat").get_signal_by_name(
        "Axis_Error").choices[0x800])
    assert name == ("WATCHDOG_TIMER_EXPIRED" if axes.firmware == "0.5"
                    else "DC_BUS_OVER_REGEN_CURRENT")
    fault = first_fault(driver)
    assert "right_wheel_joint (ODrive node 1)" in fault
    assert f"0x800 ({name})" in fault
    if axes.firmware == "0.5":
        assert "controller error flag" in fault


def test_a_0_5_error_flag_alone_faults_the_axis():
    """On 0.5.x a sub-object's error flag is an error even while Axis_Error is 0."""
    channel = unique_channel("dbc")
    config = load_config("hamr", {"driver": "odrive_can", "odrive_can.interface": "virtual",
                                  "odrive_can.channel": channel, "odrive_can.firmware": "0.5"})
    axes = DbcAxes(load_dbc("0.5"), channel, "0.5")
    driver = config.driver_class(config.model, config.values, config.controller.control_rate)
    try:
        driver.configure()
        _arm(driver, axes, {})
        with axes.lock:
            axes.heartbeat[0] = {"Axis_Error": 0, "Axis_State": "CLOSED_LOOP_CONTROL",
                                 "Encoder_Error_Flag": 1}
        fault = first_fault(driver)
        assert "left_wheel_joint (ODrive node 0): axis error 0x0 (none), encoder error flag" \
            in fault
    finally:
        driver.close()
        axes.close()


@pytest.mark.parametrize("firmware", ["0.6", "0.5"])
def test_error_names_are_the_dbc_files(firmware):
    choices = load_dbc(firmware).get_message_by_name("Axis0_Heartbeat").get_signal_by_name(
        "Axis_Error").choices
    table = {int(bit): str(name) for bit, name in choices.items() if bit}
    assert table == (proto.AXIS_ERRORS if firmware == "0.6" else proto.AXIS_ERRORS_0_5)
    for bit, name in table.items():
        assert proto.error_names(bit, firmware) == name


@pytest.mark.parametrize("firmware", ["0.6", "0.5"])
def test_frame_ids_are_the_dbc_files(firmware):
    """Every Axis<n>_<message> of the DBC (n = 0..7 in the files) has the id
    node << 5 | cmd that the driver computes."""
    db = load_dbc(firmware)
    commands = {"Heartbeat": proto.Cmd.HEARTBEAT, "Set_Axis_State": proto.Cmd.SET_AXIS_STATE,
                "Get_Encoder_Estimates": proto.Cmd.GET_ENCODER_ESTIMATES,
                "Set_Controller_Mode": proto.Cmd.SET_CONTROLLER_MODE,
                "Set_Input_Vel": proto.Cmd.SET_INPUT_VEL,
                "Set_Input_Torque": proto.Cmd.SET_INPUT_TORQUE,
                "Clear_Errors": proto.Cmd.CLEAR_ERRORS}
    if firmware == "0.6":          # 0.6's endpoint access and version query
        commands.update({"Get_Version": proto.Cmd.GET_VERSION, "RxSdo": proto.Cmd.RX_SDO,
                         "TxSdo": proto.Cmd.TX_SDO})
    for node in range(8):
        for name, cmd in commands.items():
            assert db.get_message_by_name(f"Axis{node}_{name}").frame_id == \
                proto.frame_id(node, cmd)
    # the protocol's own encoders agree with the DBC's (float32 little endian)
    message = db.get_message_by_name("Axis0_Set_Input_Vel")
    assert message.decode(proto.set_input_vel(1.5, -0.25)) == \
        {"Input_Vel": 1.5, "Input_Torque_FF": -0.25}
    assert struct.unpack("<f", proto.set_input_torque(0.125)) == (0.125,)


def _driver_with_node(node_id: int, firmware: str):
    config = load_config("hamr", {"driver": "odrive_can", "odrive_can.firmware": firmware,
                                  "odrive_can.joints.turret_joint.node_id": node_id})
    return config.driver_class(config.model, config.values, config.controller.control_rate)


def test_node_ids_are_limited_to_what_each_firmware_allows():
    # ODrive documentation: 6 bits of node id (0..0x3F); firmware 0.6 uses
    # 0x3F as the broadcast / unaddressed id of discovery, so axes get 0..0x3E
    assert _driver_with_node(63, "0.5").joints.node_ids[2] == 63
    assert _driver_with_node(62, "0.6").joints.node_ids[2] == 62
    with pytest.raises(ConfigError, match=r"odrive_can.joints.turret_joint.node_id.*0\.\.62"):
        _driver_with_node(63, "0.6")
    for firmware in ("0.5", "0.6"):
        with pytest.raises(ConfigError, match=r"odrive_can.joints.turret_joint.node_id"):
            _driver_with_node(64, firmware)


# -- the axis watchdog over the DBC's Get_Version, RxSdo and TxSdo ----------------------------
class DbcEndpointAxes(DbcAxes):
    """DbcAxes that also answer, in frames encoded from the DBC, Get_Version
    (board 4.4.58, firmware 0.6.11) and RxSdo reads and writes of the
    endpoints in ``values`` ((node, endpoint id) -> the DBC's 32-bit Value);
    writes are confirmed (0.6.11). Every RxSdo is recorded as the DBC
    decodes it. Firmware 0.5: heartbeats report WATCHDOG_TIMER_EXPIRED once
    no frame has come to the node for ``watchdog_timeout`` [s] (0.5's
    can_simple.cpp feeds the watchdog on every frame; main.cpp checks it in
    every state)."""

    def __init__(self, db, channel, firmware, values=None, watchdog_timeout=0.0):
        self.values = dict(values or {})
        self.requests: list[tuple[int, dict]] = []
        self.watchdog_timeout = watchdog_timeout
        self.fed = {n: time.monotonic() for n in range(3)}
        super().__init__(db, channel, firmware)

    def _answer(self, msg):
        node, cmd = proto.split_id(msg.arbitration_id)
        if node not in range(3):
            return
        self.fed[node] = time.monotonic()
        if self.firmware != "0.6":
            return
        if cmd == proto.Cmd.GET_VERSION and msg.is_remote_frame:
            self.bus.send(self._encode(f"Axis{node}_Get_Version", {
                "Protocol_Version": 2, "Hw_Version_Major": 4, "Hw_Version_Minor": 4,
                "Hw_Version_Variant": 58, "Fw_Version_Major": 0, "Fw_Version_Minor": 6,
                "Fw_Version_Revision": 11, "Fw_Version_Unreleased": 0}))
        elif cmd == proto.Cmd.RX_SDO:
            # a write of a bool is 5 bytes (as ODrive's can_param_access example
            # packs it): the DBC's Value is then the bytes present, zero-padded
            request = self.db.get_message_by_name(f"Axis{node}_RxSdo").decode(
                bytes(msg.data).ljust(8, b"\0"), decode_choices=False)
            self.requests.append((node, request))
            key = (node, request["Endpoint_ID"])
            if request["Opcode"] == 1:
                self.values[key] = request["Value"]
            self.bus.send(self._encode(f"Axis{node}_TxSdo", {
                "Endpoint_ID": request["Endpoint_ID"], "Value": self.values[key]}))

    def _listen(self):
        while (msg := self.bus.recv(timeout=0.0)) is not None:
            with self.lock:
                self._answer(msg)
        if self.firmware == "0.5" and self.watchdog_timeout > 0:
            with self.lock:
                for n in range(3):
                    if time.monotonic() - self.fed[n] > self.watchdog_timeout:
                        self.heartbeat[n]["Axis_Error"] = 0x800


def _f32(value: float) -> int:
    """The DBC's 32-bit Value carrying a float32 endpoint."""
    return struct.unpack("<I", struct.pack("<f", value))[0]


def test_watchdog_endpoints_are_read_and_written_in_the_dbcs_rxsdo_and_txsdo(tmp_path):
    db = load_dbc("0.6")
    rx = db.get_message_by_name("Axis0_RxSdo")
    # the DBC's opcodes and field layout are the protocol module's
    assert {int(k): str(v) for k, v in rx.get_signal_by_name("Opcode").choices.items()} == \
        {proto.SDO_READ: "READ", proto.SDO_WRITE: "WRITE"}
    assert rx.decode(proto.sdo_request(proto.SDO_WRITE, 0x1234, struct.pack("<f", 1.0)),
                     decode_choices=False) == {"Opcode": 1, "Endpoint_ID": 0x1234,
                                               "Reserved": 0, "Value": 0x3F800000}
    reply = db.get_message_by_name("Axis0_TxSdo").encode(
        {"Reserved0": 0, "Endpoint_ID": 0x1234, "Reserved1": 0, "Value": 0x3F800000})
    assert proto.SdoReply.decode(reply) == proto.SdoReply(0x1234, struct.pack("<f", 1.0))
    version = db.get_message_by_name("Axis0_Get_Version").encode({
        "Protocol_Version": 2, "Hw_Version_Major": 4, "Hw_Version_Minor": 4,
        "Hw_Version_Variant": 58, "Fw_Version_Major": 0, "Fw_Version_Minor": 6,
        "Fw_Version_Revision": 11, "Fw_Version_Unreleased": 1})
    assert proto.Version.decode(version) == proto.Version(2, (4, 4, 58), (0, 6, 11), 1)
    # what the file's comments say, and the emulated axis does: protocol
    # version 2; a heartbeat's Axis_Error is active_errors | disarm_reason (an
    # axis the watchdog disarmed shows the bit); in 0.6.10 a TxSdo answers a
    # read only (ODrive's can_param_access example: 0.6.11 confirms writes too)
    assert db.get_message_by_name("Axis0_Get_Version").get_signal_by_name(
        "Protocol_Version").comment == "Always reported as 2"
    emulated = EmulatedOdriveAxis(0, unique_channel("dbcversion"))
    try:
        assert emulated.version.protocol == 2
    finally:
        emulated.close()
    axis_error = db.get_message_by_name("Axis0_Heartbeat").get_signal_by_name("Axis_Error")
    assert "active_errors" in axis_error.comment and "disarm_reason" in axis_error.comment
    assert "in response to an RxSdo with Opcode=READ" in \
        db.get_message_by_name("Axis0_TxSdo").comment
    ids = {"axis0.config.enable_watchdog": 411, "axis0.config.watchdog_timeout": 412}
    path = tmp_path / "flat_endpoints.json"
    path.write_text(json.dumps({"fw_version": "0.6.11", "hw_version": "4.4.58", "endpoints": {
        name: {"id": i, "type": "bool" if "enable" in name else "float", "access": "rw"}
        for name, i in ids.items()}}))
    channel = unique_channel("dbc")
    config = load_config("hamr", {"driver": "odrive_can", "odrive_can.interface": "virtual",
                                  "odrive_can.channel": channel, "odrive_can.endpoints": str(path),
                                  "odrive_can.set_watchdog": 0.15,
                                  "odrive_can.watchdog_check": "refuse"})
    # every drive: watchdog off, 0 s
    axes = DbcEndpointAxes(db, channel, "0.6",
                           {(n, i): 0 for n in range(3) for i in ids.values()})
    driver = config.driver_class(config.model, config.values, config.controller.control_rate)
    try:
        driver.configure()
        for node in range(3):
            sent = [(r["Opcode"], r["Endpoint_ID"], r["Value"]) for n, r in axes.requests
                    if n == node]
            # the timeout first, read back; then enable, read back; then both read
            assert sent == [(1, 412, _f32(0.15)), (0, 412, 0), (1, 411, 1), (0, 411, 0),
                            (0, 411, 0), (0, 412, 0)]
            assert axes.values[(node, 411)] == 1 and axes.values[(node, 412)] == _f32(0.15)
        assert driver.status()["turret_joint"].endswith(
            "watchdog on, 0.15 s (read over CAN, firmware 0.6.11)")
        _arm(driver, axes, {})
        assert driver.armed
    finally:
        driver.close()
        axes.close()


def test_a_0_6_drive_whose_dbc_value_says_off_is_refused(tmp_path):
    path = tmp_path / "flat_endpoints.json"
    path.write_text(json.dumps({"fw_version": "0.6.11", "hw_version": "4.4.58", "endpoints": {
        "axis0.config.enable_watchdog": {"id": 7, "type": "bool"},
        "axis0.config.watchdog_timeout": {"id": 8, "type": "float"}}}))
    channel = unique_channel("dbc")
    config = load_config("hamr", {"driver": "odrive_can", "odrive_can.interface": "virtual",
                                  "odrive_can.channel": channel, "odrive_can.endpoints": str(path),
                                  "odrive_can.watchdog_check": "refuse"})
    # nodes 0 and 2 on with 0.2 s; node 1 off (its timeout says 0.2 s all the same)
    values = {(n, 7): int(n != 1) for n in range(3)}
    values.update({(n, 8): _f32(0.2) for n in range(3)})
    axes = DbcEndpointAxes(load_dbc("0.6"), channel, "0.6", values)
    driver = config.driver_class(config.model, config.values, config.controller.control_rate)
    try:
        driver.configure()
        assert driver.status()["left_wheel_joint"].endswith("watchdog on, 0.2 s (read over CAN, "
                                                            "firmware 0.6.11)")
        with pytest.raises(DriverFault, match=r"right_wheel_joint \(ODrive node 1\): axis "
                                              r"watchdog OFF \(enable_watchdog false, timeout "
                                              r"0.2 s"):
            driver.activate()
    finally:
        driver.close()
        axes.close()


@pytest.mark.parametrize("timeout, ok", [(0.15, True), (0.0, False)])
def test_a_0_5_drive_is_probed_through_the_dbcs_heartbeat(timeout, ok):
    """0.5.6's DBC names bit 0x800 WATCHDOG_TIMER_EXPIRED: the probe reads it
    from heartbeats encoded with that file, while the axes stay IDLE."""
    channel = unique_channel("dbc")
    config = load_config("hamr", {"driver": "odrive_can", "odrive_can.interface": "virtual",
                                  "odrive_can.channel": channel, "odrive_can.firmware": "0.5",
                                  "odrive_can.watchdog_check": "refuse"})
    db = load_dbc("0.5")
    assert str(db.get_message_by_name("Axis0_Heartbeat").get_signal_by_name(
        "Axis_Error").choices[0x800]) == "WATCHDOG_TIMER_EXPIRED"
    axes = DbcEndpointAxes(db, channel, "0.5", watchdog_timeout=timeout)
    driver = config.driver_class(config.model, config.values, config.controller.control_rate)
    try:
        driver.configure()
        text = driver.status()["left_wheel_joint"]
        assert "error 0x800 (WATCHDOG_TIMER_EXPIRED)" in text if ok else "error 0x0" in text
        assert ("watchdog expired" in text) == ok
        if not ok:
            with pytest.raises(DriverFault, match="OFF or longer than max_watchdog_timeout"):
                driver.activate()
    finally:
        driver.close()
        axes.close()
