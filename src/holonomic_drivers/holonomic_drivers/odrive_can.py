"""The ``odrive_can`` backend: ODrive motor controllers over CANSimple.

One ODrive axis per joint, addressed by its CAN node id; ``odrive_can.firmware``
(0.5 or 0.6) selects the firmware line's heartbeat layout and error names. The driver sends
velocity setpoints every cycle and takes positions and speeds
from the encoder estimates that each axis broadcasts (``encoder_msg_rate_ms``
on the ODrive, 10 ms by default) or, with ``odrive_can.poll_encoders``,
answers to a remote request sent every cycle.

Safety logic (all checks run in ``read``, i.e. every control cycle):

* a missing heartbeat (``heartbeat_timeout``) or encoder stream
  (``feedback_timeout``: the axis answers late) -> DriverCommunicationError;
* while armed, an axis error or an axis that left closed-loop control ->
  DriverFault. The controller then calls ``deactivate``, which sends every
  axis a zero velocity, a zero torque and IDLE in the same cycle;
* while disarmed a latched axis error is only reported (``status``); arming
  sends Clear_Errors and refuses, naming the axis, if the error does not
  clear or the axis does not reach closed-loop control within
  ``startup_timeout``.

The axis watchdog (the drive stops by itself when this controller dies or
hangs) is checked at configure, per axis (:mod:`holonomic_drivers.odrive_watchdog`):

* firmware 0.6 with ``odrive_can.endpoints`` (the drives' flat_endpoints.json):
  Get_Version must match the file, then ``axis0.config.enable_watchdog`` and
  ``watchdog_timeout`` are read over RxSdo/TxSdo -- after writing them when
  ``odrive_can.set_watchdog`` > 0;
* firmware 0.6 without the file: unknown (no endpoint ids, nothing to read);
* firmware 0.5 (no endpoint access): probed with the motors idle -- 0.5 feeds
  an axis's watchdog with any frame addressed to it and raises
  WATCHDOG_TIMER_EXPIRED even in IDLE, so the driver stays silent towards the
  axes and times the bit's appearance in their heartbeats;
* any firmware with ``odrive_can.watchdog_probe``: at the first arming, every
  axis is armed at zero velocity and left alone until its watchdog disarms it
  (the heartbeat reports WATCHDOG_TIMER_EXPIRED); that verdict replaces
  configure's.

An axis whose watchdog is off, unknown, longer than
``odrive_can.max_watchdog_timeout`` or shorter than three control periods is
a warning (stderr and ``status``) or, with ``watchdog_check: refuse``, a
refusal to arm (DriverFault, one line).

The bus is drained without blocking at the start of every ``read`` (no
receive thread): what the drives sent before the cycle is what the cycle
sees. Frames that cannot be decoded are ignored and counted.
"""

from __future__ import annotations

import logging
import math
import time
from dataclasses import dataclass, field

import numpy as np

from holonomic_core.driver import DriverCommunicationError, DriverFault, JointReading
from holonomic_core.schema import ConfigError, ParamSpec
from holonomic_drivers import odrive_endpoints
from holonomic_drivers import odrive_protocol as proto
from holonomic_drivers import odrive_watchdog as wd
from holonomic_drivers.can_link import CanDriver, bus_specs, joint_map_specs, open_bus
from holonomic_drivers.odrive_protocol import AxisState, Cmd, ControlMode, InputMode

PREFIX = "odrive_can"
#: frames handled per read at most: a flooded bus cannot stall the loop
MAX_FRAMES_PER_READ = 2000
_INPUT_MODES = {"passthrough": InputMode.PASSTHROUGH, "vel_ramp": InputMode.VEL_RAMP}
#: while arming, zero velocity is resent this often [s]: it feeds the axis
#: watchdogs until the heartbeats confirm closed-loop control
ARM_FEED_PERIOD = 0.02
_log = logging.getLogger(__name__)


@dataclass
class _Axis:
    """What the driver last heard from one axis (times on the driver clock)."""

    heartbeat: proto.Heartbeat | None = None
    heartbeat_time: float = -math.inf
    heartbeats: int = 0
    position_rev: float = math.nan
    velocity_rev_per_s: float = math.nan
    estimate_time: float = -math.inf
    version: proto.Version | None = None
    #: endpoint id -> (raw value, how many replies so far)
    sdo: dict[int, tuple[bytes, int]] = field(default_factory=dict)
    #: when set: (stamp, axis error, axis state) of every heartbeat stamped after it
    probe_since: float | None = None
    probe: list[tuple[float, int, int]] | None = None
    #: the last frame sent to the axis [s, driver clock] (it feeds 0.5's watchdog)
    last_sent: float = -math.inf
    watchdog: wd.Verdict | None = None


class OdriveCanDriver(CanDriver):
    name = "odrive_can"
    device_kind = "ODrive"
    # Torque mode: Set_Controller_Mode(TORQUE_CONTROL) on the first torque
    # command, then Set_Input_Torque [N m at the motor]; a velocity command
    # switches the axes back. The ODrive keeps its own vel_limit in torque
    # mode (controller.config.enable_torque_mode_vel_limit).
    supports_effort = True

    def __init__(self, model, params, control_rate: float):
        super().__init__(model, params, control_rate)
        self._index = {node: i for i, node in enumerate(self.joints.node_ids)}
        self._axes = [_Axis() for _ in self.joints.node_ids]
        self._heartbeat_timeout = float(params[f"{PREFIX}.heartbeat_timeout"])
        self._feedback_timeout = float(params[f"{PREFIX}.feedback_timeout"])
        self._startup_timeout = float(params[f"{PREFIX}.startup_timeout"])
        self._input_mode = _INPUT_MODES[params[f"{PREFIX}.input_mode"]]
        self._poll = bool(params[f"{PREFIX}.poll_encoders"])
        self.firmware = params[f"{PREFIX}.firmware"]
        highest = proto.max_node_id(self.firmware)
        for joint, node in zip(self.joints.joint_names, self.joints.node_ids):
            if node > highest:
                raise ConfigError(f"{PREFIX}.joints.{joint}.node_id", node,
                                  f"0..{highest} on firmware {self.firmware} (0x3F is the "
                                  "broadcast address of 0.6.x)")
        self._watchdog_policy = params[f"{PREFIX}.watchdog_check"]
        self._watchdog_bound = float(params[f"{PREFIX}.max_watchdog_timeout"])
        self._set_watchdog = float(params[f"{PREFIX}.set_watchdog"])
        self._sdo_timeout = float(params[f"{PREFIX}.sdo_timeout"])
        #: probe the watchdogs armed at the first arming (then False)
        self._armed_probe = bool(params[f"{PREFIX}.watchdog_probe"])
        self._endpoints = self._load_endpoints(params)
        self._bus = None
        #: the control mode the axes were last told (per axis)
        self._mode = [ControlMode.VELOCITY_CONTROL] * len(self._axes)
        self.counters = {"bad_frames": 0, "foreign_frames": 0, "error_frames": 0,
                         "frames_received": 0, "frames_sent": 0}

    @classmethod
    def param_specs(cls, model) -> list[ParamSpec]:
        return bus_specs(PREFIX) + [
            ParamSpec(f"{PREFIX}.heartbeat_timeout", "double",
                      "An axis whose heartbeat is older than this is lost: fault and stop "
                      "[s] (ODrive heartbeat_msg_rate_ms is 100 ms by default).",
                      default=0.25, minimum=0.005, maximum=10.0),
            ParamSpec(f"{PREFIX}.feedback_timeout", "double",
                      "Encoder estimates older than this are late: fault and stop [s] "
                      "(encoder_msg_rate_ms is 10 ms by default).",
                      default=0.05, minimum=0.002, maximum=10.0),
            ParamSpec(f"{PREFIX}.startup_timeout", "double",
                      "How long configure waits for every axis to be heard, and arming "
                      "for every axis to reach closed-loop control [s].",
                      default=2.0, minimum=0.05, maximum=60.0),
            ParamSpec(f"{PREFIX}.input_mode", "string",
                      "ODrive input mode: passthrough (the controller already limits "
                      "acceleration) or vel_ramp (the ODrive's own ramp on top).",
                      default="passthrough", choices=tuple(_INPUT_MODES)),
            ParamSpec(f"{PREFIX}.firmware", "string",
                      "ODrive firmware line: 0.6 (ODrive Pro, S1, Micro) or 0.5 (ODrive v3.x). "
                      "Selects the heartbeat layout (0.5: motor/encoder/controller error "
                      "flags), the names of the axis error bits (the same bit means different "
                      "things on the two lines) and the node id range (0.6: 0..62).",
                      default="0.6", choices=proto.FIRMWARES),
            ParamSpec(f"{PREFIX}.poll_encoders", "bool",
                      "Request the encoder estimates every cycle (remote frame) instead of "
                      "relying on the axes' cyclic messages.", default=False),
            ParamSpec(f"{PREFIX}.watchdog_check", "string",
                      "What an axis whose watchdog is off, unknown, longer than "
                      "max_watchdog_timeout or shorter than three control periods does: "
                      "refuse (arming fails, naming the axis) or warn (stderr and "
                      "diagnostics; the motor would NOT stop if this controller died).",
                      default="warn", choices=wd.POLICIES),
            ParamSpec(f"{PREFIX}.max_watchdog_timeout", "double",
                      "Longest axis watchdog timeout accepted [s]: how long a motor may "
                      "keep its last command after this controller dies or hangs.",
                      default=0.3, minimum=0.01, maximum=10.0),
            ParamSpec(f"{PREFIX}.set_watchdog", "double",
                      "Firmware 0.6 with an endpoints file: write this axis watchdog "
                      "timeout [s] and enable the watchdog at configure (RAM only, not "
                      "saved on the drive); 0 leaves the drive's setting alone.",
                      default=0.0, minimum=0.0, maximum=10.0),
            ParamSpec(f"{PREFIX}.endpoints", "string",
                      "Firmware 0.6: the flat_endpoints.json of the drives' firmware and "
                      "board (ODrive publishes one per release and board; absolute path, or "
                      "relative to the working directory), to read the axis watchdog "
                      "settings over CAN; empty = they cannot be read.",
                      default=""),
            ParamSpec(f"{PREFIX}.watchdog_probe", "bool",
                      "At the first arming, arm every axis at zero velocity and send it "
                      "nothing until its watchdog disarms it (at most max_watchdog_timeout + "
                      "heartbeat_timeout): the watchdog verified by what it does, on any "
                      "firmware, without an endpoints file; this verdict replaces "
                      "configure's.", default=False),
            ParamSpec(f"{PREFIX}.sdo_timeout", "double",
                      "Time a drive has to answer Get_Version or an endpoint read [s].",
                      default=0.2, minimum=0.005, maximum=10.0),
        ] + joint_map_specs(PREFIX, model.joint_names, (0, proto.MAX_NODE_ID))

    def _load_endpoints(self, params) -> odrive_endpoints.EndpointFile | None:
        key, path = f"{PREFIX}.endpoints", params[f"{PREFIX}.endpoints"]
        if self._set_watchdog > self._watchdog_bound:
            raise ConfigError(f"{PREFIX}.set_watchdog", self._set_watchdog,
                              f"at most {PREFIX}.max_watchdog_timeout "
                              f"({self._watchdog_bound:g} s)")
        if not path:
            if self._set_watchdog > 0:
                raise ConfigError(f"{PREFIX}.set_watchdog", self._set_watchdog,
                                  f"0 without {key} (the endpoint ids come from that file)")
            return None
        if self.firmware != "0.6":
            raise ConfigError(key, path, f"empty on firmware {self.firmware} (no endpoint "
                                         "access over CAN before 0.6)")
        try:
            return odrive_endpoints.load(path)
        except (OSError, ValueError) as exc:
            raise ConfigError(key, path, f"an ODrive flat_endpoints.json ({exc})") from None

    # -- lifecycle hooks ----------------------------------------------------------
    def _on_configure(self) -> None:
        self._bus = open_bus(PREFIX, self.params)
        try:
            # waits are on the wall clock, whatever clock stamps the readings
            deadline = time.monotonic() + self._startup_timeout
            while True:
                self._drain()
                missing = [i for i, a in enumerate(self._axes)
                           if a.heartbeat is None or math.isinf(a.estimate_time)]
                if not missing:
                    break
                if time.monotonic() > deadline:
                    i = missing[0]
                    what = ("no heartbeat" if self._axes[i].heartbeat is None
                            else "no encoder estimates")
                    raise DriverCommunicationError(
                        f"{what} within {self._startup_timeout:g} s (is it powered, on "
                        f"this bus, with this node id and bit rate?)",
                        self.devices[i])
                if self._poll:
                    self._request_estimates()
                time.sleep(0.002)
            # Velocity control, idle: nothing moves until activate.
            for node in self.joints.node_ids:
                self._send(node, Cmd.SET_CONTROLLER_MODE, proto.set_controller_mode(
                    ControlMode.VELOCITY_CONTROL, self._input_mode))
                self._send(node, Cmd.SET_INPUT_VEL, proto.set_input_vel(0.0))
                self._send(node, Cmd.SET_AXIS_STATE, proto.set_axis_state(AxisState.IDLE))
            self._check_watchdogs()
        except BaseException:
            self._shutdown_bus()
            raise

    def _on_activate(self) -> None:
        if self._armed_probe:
            self._armed_probe = False
            self._probe_watchdogs_armed()
        if self._watchdog_policy == "refuse":
            for i, axis in enumerate(self._axes):
                if not axis.watchdog.ok:
                    raise DriverFault(f"axis watchdog {axis.watchdog.text}: refused to arm "
                                      f"({PREFIX}.watchdog_check: refuse)", self.devices[i])
        # only heartbeats sent after the request count
        seen = [a.heartbeats for a in self._axes]
        self._mode = [ControlMode.VELOCITY_CONTROL] * len(self._axes)
        self._request_closed_loop()
        deadline = time.monotonic() + self._startup_timeout
        next_feed = time.monotonic() + ARM_FEED_PERIOD
        while True:
            self._drain()
            if time.monotonic() >= next_feed:
                next_feed += ARM_FEED_PERIOD
                for node in self.joints.node_ids:
                    self._send(node, Cmd.SET_INPUT_VEL, proto.set_input_vel(0.0))
            waiting = [i for i, a in enumerate(self._axes) if not (
                a.heartbeats > seen[i] and not a.heartbeat.faulted
                and a.heartbeat.axis_state == AxisState.CLOSED_LOOP_CONTROL)]
            if not waiting:
                return
            # an axis that still reports an error after Clear_Errors will not
            # arm: say so now rather than at the timeout
            faulty = [i for i in waiting if self._axes[i].heartbeats > seen[i]
                      and self._axes[i].heartbeat.faulted]
            if faulty or time.monotonic() > deadline:
                self._idle_all()
                i = (faulty or waiting)[0]
                hb = self._axes[i].heartbeat
                why = ("no heartbeat since the request" if self._axes[i].heartbeats == seen[i]
                       else f"state {_state_name(hb.axis_state)}, error "
                            f"{hb.describe(self.firmware)}")
                raise DriverFault(f"did not enter closed-loop control ({why}); motors left idle",
                                  self.devices[i])
            time.sleep(0.002)

    def _request_closed_loop(self) -> None:
        """Every axis: clear errors, velocity control, zero input, closed loop."""
        for node in self.joints.node_ids:
            self._send(node, Cmd.CLEAR_ERRORS, proto.clear_errors(firmware=self.firmware))
            self._send(node, Cmd.SET_CONTROLLER_MODE, proto.set_controller_mode(
                ControlMode.VELOCITY_CONTROL, self._input_mode))
            self._send(node, Cmd.SET_INPUT_VEL, proto.set_input_vel(0.0))
            self._send(node, Cmd.SET_AXIS_STATE,
                       proto.set_axis_state(AxisState.CLOSED_LOOP_CONTROL))

    def _on_deactivate(self) -> None:
        self._idle_all()

    def _on_quick_stop(self) -> None:
        """The emergency stop. Firmware 0.6: ODrive's Estop message to every
        axis (the axis disarms at once with ESTOP_REQUESTED -- power stage
        off, the wheels coast to rest -- which the next activate's
        Clear_Errors clears). Firmware 0.5: a braking ramp instead -- zero
        velocity input, the axes stay in closed-loop control and brake at
        their current limit (and ramp, input_mode VEL_RAMP) until the next
        activate or close, or until their CAN watchdog idles them once no
        feed arrives."""
        for node in self.joints.node_ids:
            if self.firmware == "0.6":
                self._send(node, Cmd.ESTOP, b"")
            else:
                self._send(node, Cmd.SET_INPUT_VEL, proto.set_input_vel(0.0))

    def _on_close(self) -> None:
        self._shutdown_bus()

    # -- cycle ------------------------------------------------------------------------
    def _on_read(self) -> JointReading:
        now = self._drain()
        positions = np.empty(len(self._axes))
        velocities = np.empty(len(self._axes))
        armed = self.armed
        for i, axis in enumerate(self._axes):
            device = self.devices[i]
            age = now - axis.heartbeat_time
            if age > self._heartbeat_timeout:
                raise DriverCommunicationError(
                    f"no heartbeat for {age * 1e3:.0f} ms (limit "
                    f"{self._heartbeat_timeout * 1e3:.0f} ms)", device)
            age = now - axis.estimate_time
            if age > self._feedback_timeout:
                raise DriverCommunicationError(
                    f"encoder estimates late: last one {age * 1e3:.0f} ms ago (limit "
                    f"{self._feedback_timeout * 1e3:.0f} ms)", device)
            hb = axis.heartbeat
            if armed and hb.faulted:
                raise DriverFault(f"axis error {hb.describe(self.firmware)}", device)
            if armed and hb.axis_state != AxisState.CLOSED_LOOP_CONTROL:
                raise DriverFault(f"left closed-loop control (now "
                                  f"{_state_name(hb.axis_state)})", device)
            # Each axis sends its estimates on its own schedule: bring them
            # to one instant with the axis's own speed estimate, or a cycle
            # in which only some axes were heard would see the base twist.
            positions[i] = axis.position_rev + axis.velocity_rev_per_s * (now - axis.estimate_time)
            velocities[i] = axis.velocity_rev_per_s
        return JointReading(now, self.joints.to_joint_positions(positions),
                            self.joints.to_joint_velocities(velocities), self._no_efforts)

    def _on_write_velocities(self, velocities: np.ndarray) -> None:
        motor = self.joints.to_motor_velocities(np.asarray(velocities, float))
        for i, (node, value) in enumerate(zip(self.joints.node_ids, motor)):
            self._ensure_mode(i, ControlMode.VELOCITY_CONTROL)
            self._send(node, Cmd.SET_INPUT_VEL, proto.set_input_vel(float(value)))
        if self._poll:
            self._request_estimates()

    def _on_write_efforts(self, efforts: np.ndarray) -> None:
        """Joint torques [N m] -> motor torques (gear ratio, direction) ->
        Set_Input_Torque, after switching each axis to torque control."""
        motor = self.joints.to_motor_torques(np.asarray(efforts, float))
        for i, (node, value) in enumerate(zip(self.joints.node_ids, motor)):
            self._ensure_mode(i, ControlMode.TORQUE_CONTROL)
            self._send(node, Cmd.SET_INPUT_TORQUE, proto.set_input_torque(float(value)))
        if self._poll:
            self._request_estimates()

    def _ensure_mode(self, i: int, mode: ControlMode) -> None:
        if self._mode[i] != mode:
            # passthrough: the torque controller shapes its own setpoints
            input_mode = self._input_mode if mode == ControlMode.VELOCITY_CONTROL \
                else proto.InputMode.PASSTHROUGH
            self._send(self.joints.node_ids[i], Cmd.SET_CONTROLLER_MODE,
                       proto.set_controller_mode(mode, input_mode))
            self._mode[i] = mode

    def status(self) -> dict[str, str]:
        out = super().status()
        now = time.monotonic()
        for i, axis in enumerate(self._axes):
            hb = axis.heartbeat
            out[self.joints.joint_names[i]] = (
                f"node {self.joints.node_ids[i]}: no heartbeat" if hb is None else
                f"node {self.joints.node_ids[i]}: {_state_name(hb.axis_state)}, error "
                f"{hb.describe(self.firmware)}, heartbeat "
                f"{(now - axis.heartbeat_time) * 1e3:.0f} ms ago") + (
                f", watchdog {axis.watchdog.text}" if axis.watchdog else "")
        for k, text in enumerate(self.warnings):
            out[f"warning {k + 1}"] = text
        return out

    # -- axis watchdog ------------------------------------------------------------------
    def _check_watchdogs(self) -> None:
        """Give every axis a :class:`~holonomic_drivers.odrive_watchdog.Verdict`;
        warn about those that are not ok."""
        if self.firmware == "0.5":
            self._probe_watchdogs()
        elif self._endpoints is None:
            for axis in self._axes:
                axis.watchdog = wd.Verdict(False, f"unknown (firmware 0.6 without {PREFIX}."
                                           "endpoints: its settings cannot be read)")
        else:
            for i in range(len(self._axes)):
                self._read_watchdog(i)
        for text in self.warnings:
            _log.warning(text)

    @property
    def warnings(self) -> list[str]:
        """What a user must see (also in ``status``): one line per axis whose
        watchdog is not good enough."""
        return [f"{self.devices[i]}: axis watchdog {axis.watchdog.text}: the motor will NOT "
                "stop by itself if this controller dies or hangs"
                for i, axis in enumerate(self._axes) if axis.watchdog and not axis.watchdog.ok]

    def _read_watchdog(self, i: int) -> None:
        """Firmware 0.6: check the board against the endpoints file, write the
        settings if asked, read them back."""
        node, device, table = self.joints.node_ids[i], self.devices[i], self._endpoints
        axis = self._axes[i]
        axis.version = None
        # a remote frame, as ODrive's CAN documentation and its Arduino library
        # ask: an empty *data* frame on the id of the answer collides with it
        self._send(node, Cmd.GET_VERSION, b"", remote=True)
        self._await(lambda: axis.version is not None, device, "Get_Version")
        why = table.mismatch(axis.version)
        if why:
            raise DriverFault(f"{why}: set {PREFIX}.endpoints to the file of this build",
                              device)
        enable = table.endpoints[odrive_endpoints.ENABLE_WATCHDOG]
        timeout = table.endpoints[odrive_endpoints.WATCHDOG_TIMEOUT]
        if self._set_watchdog > 0:
            # the timeout first: the watchdog never runs with the old one
            self._write_endpoint(i, timeout, self._set_watchdog)
            self._write_endpoint(i, enable, True)
        values = {e.path: self._read_endpoint(i, e) for e in (enable, timeout)}
        axis.watchdog = wd.assess(bool(values[enable.path]), float(values[timeout.path]),
                                  self._watchdog_bound, 1.0 / self.control_rate,
                                  f"read over CAN, firmware {axis.version.fw_text}")

    def _read_endpoint(self, i: int, endpoint: odrive_endpoints.Endpoint):
        axis = self._axes[i]
        before = axis.sdo.get(endpoint.id, (b"", 0))[1]
        self._send(self.joints.node_ids[i], Cmd.RX_SDO,
                   proto.sdo_request(proto.SDO_READ, endpoint.id))
        self._await(lambda: axis.sdo.get(endpoint.id, (b"", 0))[1] > before, self.devices[i],
                    f"the read of {endpoint.path} (endpoint {endpoint.id})")
        try:
            return proto.decode_value(endpoint.type, axis.sdo[endpoint.id][0])
        except ValueError as exc:
            raise DriverFault(f"{endpoint.path}: {exc}", self.devices[i]) from None

    def _write_endpoint(self, i: int, endpoint: odrive_endpoints.Endpoint, value) -> None:
        """Write, then read back. Firmware before 0.6.11 does not confirm a
        write; a later one does (ODrive's can_param_access example): the
        confirmation is waited out, so that it is not taken for the answer to
        the read, but not required -- the read-back is the check."""
        axis = self._axes[i]
        before = axis.sdo.get(endpoint.id, (b"", 0))[1]
        self._send(self.joints.node_ids[i], Cmd.RX_SDO, proto.sdo_request(
            proto.SDO_WRITE, endpoint.id, proto.encode_value(endpoint.type, value)))
        if axis.version.fw >= (0, 6, 11):
            self._await(lambda: axis.sdo.get(endpoint.id, (b"", 0))[1] > before,
                        self.devices[i], f"the write of {endpoint.path}", required=False)
        back = self._read_endpoint(i, endpoint)
        if back != proto.decode_value(endpoint.type, proto.encode_value(endpoint.type, value)):
            raise DriverFault(f"wrote {value} to {endpoint.path}, reads back {back}",
                              self.devices[i])

    def _await(self, done, device: str, what: str, required: bool = True) -> None:
        """Drain the bus until ``done()`` or ``sdo_timeout``; then raise if ``required``."""
        deadline = time.monotonic() + self._sdo_timeout
        while True:
            self._drain()
            if done():
                return
            if time.monotonic() > deadline:
                if not required:
                    return
                raise DriverCommunicationError(
                    f"no answer to {what} within {self._sdo_timeout:g} s (firmware 0.6 "
                    f"with {PREFIX}.endpoints of this firmware and board?)", device)
            time.sleep(0.001)

    def _probe_watchdogs(self) -> None:
        """Firmware 0.5, motors idle: clear a latched watchdog error, send the
        axes nothing for max_watchdog_timeout plus a heartbeat timeout, and
        time when their heartbeats report WATCHDOG_TIMER_EXPIRED."""
        bit = proto.WATCHDOG_TIMER_EXPIRED["0.5"]
        for node, axis in zip(self.joints.node_ids, self._axes):
            if axis.heartbeat.axis_error & bit:
                self._send(node, Cmd.CLEAR_ERRORS, proto.clear_errors(firmware="0.5"))
        self._await_silence(bit)
        for axis in self._axes:
            axis.watchdog = wd.probed(axis.probe_since, [p[:2] for p in axis.probe], bit,
                                      self._watchdog_bound, 1.0 / self.control_rate,
                                      "probed while idle, firmware 0.5")
            axis.probe_since = None

    def _probe_watchdogs_armed(self) -> None:
        """``watchdog_probe``: arm every axis at zero velocity, then send
        nothing until each disarms itself with WATCHDOG_TIMER_EXPIRED (0.6's
        heartbeat reports active_errors | disarm_reason); then idle."""
        bit = proto.WATCHDOG_TIMER_EXPIRED[self.firmware]
        self._request_closed_loop()
        try:
            self._await_silence(bit)
        finally:
            self._idle_all()
        for axis in self._axes:
            # only what follows closed-loop control counts (a bit latched while idle does not)
            closed = [k for k, p in enumerate(axis.probe)
                      if p[2] == AxisState.CLOSED_LOOP_CONTROL]
            if closed:
                since = axis.probe_since
                axis.watchdog = wd.probed(since, [p[:2] for p in axis.probe[closed[0]:]], bit,
                                          self._watchdog_bound, 1.0 / self.control_rate,
                                          "probed armed at zero velocity")
            else:
                hb = axis.heartbeat
                axis.watchdog = wd.Verdict(False, "not verified: the armed probe never saw "
                                           f"closed-loop control (state "
                                           f"{_state_name(hb.axis_state)}, error "
                                           f"{hb.describe(self.firmware)})")
            axis.probe_since = None
        for text in self.warnings:
            _log.warning(text)

    def _await_silence(self, bit: int) -> None:
        """Send the axes nothing and record their heartbeats (``probe``) until
        each reports ``bit`` or max_watchdog_timeout + heartbeat_timeout have
        passed since the last frame."""
        for axis in self._axes:
            axis.probe_since, axis.probe = axis.last_sent, []
        deadline = max(a.last_sent for a in self._axes) + self._watchdog_bound + \
            self._heartbeat_timeout
        while time.monotonic() < deadline and not all(
                any(p[1] & bit for p in a.probe) for a in self._axes):
            self._drain()
            time.sleep(0.002)

    # -- bus ------------------------------------------------------------------------------
    def _drain(self) -> float:
        """Take every waiting frame off the bus; returns the clock after it."""
        import can

        now = time.monotonic()
        # python-can stamps frames on the wall clock when they arrive (the
        # kernel does, on socketcan): mapped onto our clock, that is when the
        # axis sent its estimate, free of this loop's jitter.
        wall_to_clock = now - time.time()
        for _ in range(MAX_FRAMES_PER_READ):
            try:
                msg = self._bus.recv(timeout=0.0)
            except can.CanError as exc:
                raise DriverCommunicationError(f"receive failed: {exc}", PREFIX) from exc
            if msg is None:
                break
            stamp = msg.timestamp + wall_to_clock if msg.timestamp else now
            self._handle(msg, min(stamp, now))
        return now

    def _handle(self, msg, now: float) -> None:
        self.counters["frames_received"] += 1
        if msg.is_error_frame:
            self.counters["error_frames"] += 1
            return
        node, cmd = proto.split_id(msg.arbitration_id)
        i = self._index.get(node)
        if msg.is_extended_id or i is None or msg.is_remote_frame:
            self.counters["foreign_frames"] += 1
            return
        axis = self._axes[i]
        try:
            if cmd == Cmd.HEARTBEAT:
                axis.heartbeat = proto.Heartbeat.decode(bytes(msg.data), self.firmware)
                axis.heartbeat_time = now
                axis.heartbeats += 1
                if axis.probe_since is not None and now > axis.probe_since:
                    axis.probe.append((now, axis.heartbeat.axis_error,
                                       axis.heartbeat.axis_state))
            elif cmd == Cmd.TX_SDO and self.firmware == "0.6":
                reply = proto.SdoReply.decode(bytes(msg.data))
                count = axis.sdo.get(reply.endpoint_id, (b"", 0))[1]
                axis.sdo[reply.endpoint_id] = (reply.value, count + 1)
            elif (cmd == Cmd.GET_VERSION and self.firmware == "0.6"
                  and not msg.is_remote_frame and len(msg.data)):
                axis.version = proto.Version.decode(bytes(msg.data))
            elif cmd == Cmd.GET_ENCODER_ESTIMATES:
                est = proto.EncoderEstimates.decode(bytes(msg.data))
                axis.position_rev, axis.velocity_rev_per_s = est.position_rev, est.velocity_rev_per_s
                axis.estimate_time = now
            else:
                # a command to "our" node from someone else, or a message we
                # do not use (Get_Error, Get_Iq, ...)
                self.counters["foreign_frames"] += 1
        except ValueError:
            self.counters["bad_frames"] += 1

    def _send(self, node: int, cmd: int, data: bytes, remote: bool = False) -> None:
        import can

        msg = can.Message(arbitration_id=proto.frame_id(node, cmd), data=data,
                          is_extended_id=False, is_remote_frame=remote,
                          dlc=8 if remote else len(data))
        try:
            self._bus.send(msg, timeout=0.01)
        except can.CanError as exc:
            raise DriverCommunicationError(f"send failed: {exc}", f"ODrive node {node}") from exc
        self.counters["frames_sent"] += 1
        self._axes[self._index[node]].last_sent = time.monotonic()

    def _request_estimates(self) -> None:
        for node in self.joints.node_ids:
            self._send(node, Cmd.GET_ENCODER_ESTIMATES, b"", remote=True)

    def _idle_all(self) -> None:
        """Zero setpoints and IDLE to every axis; tries all before raising."""
        failure = None
        for node in self.joints.node_ids:
            for cmd, data in ((Cmd.SET_INPUT_VEL, proto.set_input_vel(0.0)),
                              (Cmd.SET_INPUT_TORQUE, proto.set_input_torque(0.0)),
                              (Cmd.SET_AXIS_STATE, proto.set_axis_state(AxisState.IDLE))):
                try:
                    self._send(node, cmd, data)
                except DriverCommunicationError as exc:
                    failure = failure or exc
        if failure is not None:
            raise failure

    def _shutdown_bus(self) -> None:
        if self._bus is not None:
            self._bus.shutdown()
            self._bus = None


def _state_name(state: int) -> str:
    try:
        return AxisState(state).name
    except ValueError:
        return f"state {state}"
