"""What every CAN backend shares: the bus parameters, the joint <-> device
mapping and the conversion between joint units and motor units.

A joint ``j`` is driven by one device (an ODrive axis, a CiA 402 drive)
through a gear: ``gear_ratio`` motor revolutions per joint revolution, a
``direction`` sign (-1 when the motor is mounted mirrored) and a
``position_offset`` -- the joint angle [rad] when the motor's position
reads zero (absolute encoders, a calibrated steering zero)::

    q  = direction * 2 pi * motor_rev / gear_ratio + position_offset
    dq = direction * 2 pi * motor_rev_per_s / gear_ratio

Keys, for a backend ``B`` (``odrive_can`` or ``cia402``)::

    B.interface / B.channel / B.bitrate      python-can bus
    B.joints.<joint>.node_id                 device address on the bus
    B.joints.<joint>.gear_ratio              motor rev per joint rev
    B.joints.<joint>.direction               +1 or -1
    B.joints.<joint>.position_offset         [rad]
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace
from typing import Any, Mapping

import numpy as np

from holonomic_core.driver import Driver, DriverCommunicationError
from holonomic_core.schema import ConfigError, ParamSpec

TWO_PI = 2.0 * math.pi


def bus_specs(prefix: str, default_interface: str = "socketcan") -> list[ParamSpec]:
    """Schema of ``<prefix>.interface/channel/bitrate``."""
    return [
        ParamSpec(f"{prefix}.interface", "string",
                  "python-can interface: socketcan on a Linux robot, virtual for the "
                  "emulated drives of the tests (pcan, kvaser, slcan, ... also work).",
                  default=default_interface),
        ParamSpec(f"{prefix}.channel", "string",
                  "CAN channel of the interface (socketcan: the network device, e.g. can0).",
                  default="can0"),
        ParamSpec(f"{prefix}.bitrate", "int",
                  "Bit rate [bit/s]; must match the drives. socketcan takes it from "
                  "`ip link set can0 type can bitrate ...` and ignores this.",
                  default=1_000_000, minimum=10_000, maximum=1_000_000),
    ]


def joint_map_specs(prefix: str, joint_names, node_id_range: tuple[int, int],
                    extra: tuple[ParamSpec, ...] = ()) -> list[ParamSpec]:
    """Schema of ``<prefix>.joints.<joint>.*`` for every joint of the model.

    ``extra``: per-joint specs of the backend, named with ``{joint}``.
    """
    low, high = node_id_range
    specs = []
    for joint in joint_names:
        base = f"{prefix}.joints.{joint}"
        specs += [
            ParamSpec(f"{base}.node_id", "int",
                      f"Bus address of the device that drives {joint} ({low}..{high}).",
                      minimum=low, maximum=high),
            ParamSpec(f"{base}.gear_ratio", "double",
                      f"Motor revolutions per revolution of {joint} [-].",
                      default=1.0, minimum=0.0, exclusive_minimum=True, maximum=1e4),
            ParamSpec(f"{base}.direction", "int",
                      f"+1, or -1 when a positive motor turn moves {joint} negatively.",
                      default=1, minimum=-1, maximum=1),
            ParamSpec(f"{base}.position_offset", "double",
                      f"Angle of {joint} when the motor position reads zero [rad].",
                      default=0.0, minimum=-1e3, maximum=1e3),
        ]
        specs += [replace(s, name=s.name.format(joint=joint),
                          description=s.description.format(joint=joint)) for s in extra]
    return specs


@dataclass(frozen=True)
class JointMap:
    """Joint <-> device mapping of one backend, in ``joint_names`` order."""

    joint_names: tuple[str, ...]
    node_ids: tuple[int, ...]
    #: joint rad -> motor rev: direction * gear_ratio / 2 pi
    motor_rev_per_rad: np.ndarray
    position_offset: np.ndarray
    #: axis of a multi-axis device (0 for single-axis devices)
    axes: tuple[int, ...] = ()

    @classmethod
    def from_params(cls, prefix: str, joint_names, params: Mapping[str, Any],
                    axis_key: str | None = None) -> "JointMap":
        """``axis_key``: per-joint key of the axis on a multi-axis device
        (joints may then share a node id on different axes)."""
        node_ids, scale, offsets, axes = [], [], [], []
        seen: dict[tuple[int, int], str] = {}
        for joint in joint_names:
            base = f"{prefix}.joints.{joint}"
            node_id = int(params[f"{base}.node_id"])
            axis = int(params[f"{base}.{axis_key}"]) if axis_key else 0
            if (node_id, axis) in seen:
                what = f"an address not already used by {seen[(node_id, axis)]}"
                if axis_key:
                    what += f" (or another {base}.{axis_key})"
                raise ConfigError(f"{base}.node_id", node_id, what)
            seen[(node_id, axis)] = joint
            axes.append(axis)
            direction = int(params[f"{base}.direction"])
            if direction not in (-1, 1):
                raise ConfigError(f"{base}.direction", direction, "+1 or -1")
            node_ids.append(node_id)
            scale.append(direction * float(params[f"{base}.gear_ratio"]) / TWO_PI)
            offsets.append(float(params[f"{base}.position_offset"]))
        return cls(tuple(joint_names), tuple(node_ids), np.array(scale), np.array(offsets),
                   tuple(axes))

    def to_joint_positions(self, motor_rev: np.ndarray) -> np.ndarray:
        """Motor positions [rev] -> joint positions [rad]."""
        return motor_rev / self.motor_rev_per_rad + self.position_offset

    def to_joint_velocities(self, motor_rev_per_s: np.ndarray) -> np.ndarray:
        """Motor speeds [rev/s] -> joint speeds [rad/s]."""
        return motor_rev_per_s / self.motor_rev_per_rad

    def to_motor_velocities(self, joint_rad_per_s: np.ndarray) -> np.ndarray:
        """Joint speeds [rad/s] -> motor speeds [rev/s]."""
        return joint_rad_per_s * self.motor_rev_per_rad

    def to_motor_torques(self, joint_torques: np.ndarray) -> np.ndarray:
        """Joint torques [N m] -> motor torques [N m] (ideal gear)."""
        return joint_torques / (self.motor_rev_per_rad * TWO_PI)

    def device(self, i: int, kind: str) -> str:
        """Name of joint ``i``'s device for messages: ``left_wheel_joint (ODrive node 3)``,
        ``turret_joint (CANopen node 4 axis 1)``."""
        axis = f" axis {self.axes[i]}" if self.axes and self.axes[i] else ""
        return f"{self.joint_names[i]} ({kind} node {self.node_ids[i]}{axis})"


def open_bus(prefix: str, params: Mapping[str, Any]):
    """Open the python-can bus of ``<prefix>.*``; DriverCommunicationError if it fails."""
    import can

    interface, channel = params[f"{prefix}.interface"], params[f"{prefix}.channel"]
    try:
        return can.Bus(interface=interface, channel=channel, bitrate=params[f"{prefix}.bitrate"])
    except (can.CanError, OSError, ValueError, ImportError, NotImplementedError) as exc:
        raise DriverCommunicationError(
            f"cannot open CAN bus {interface}:{channel} ({exc}); on socketcan check "
            f"`ip link show {channel}` (up, right bitrate)", prefix) from exc


class CanDriver(Driver):
    """What both CAN backends share: the joint map (parameter prefix = the
    backend's registry name), each joint's device name for messages, the bus
    and frame counters in ``status``, and NaN efforts (no torque read-back)."""

    #: how messages name a device: "ODrive", "CANopen"
    device_kind = ""
    #: per-joint key of the axis on multi-axis devices (None: one axis per node)
    axis_key: str | None = None

    def __init__(self, model, params, control_rate: float):
        super().__init__(model, params, control_rate)
        self.joints = JointMap.from_params(self.name, model.joint_names, params, self.axis_key)
        #: "left_wheel_joint (ODrive node 0)", by joint index
        self.devices = tuple(self.joints.device(i, self.device_kind)
                             for i in range(len(self.joints.node_ids)))
        self.counters: dict[str, int] = {}
        self._no_efforts = np.full(len(self.devices), np.nan)
        self._no_efforts.flags.writeable = False

    def status(self) -> dict[str, str]:
        out = super().status()
        out["bus"] = f"{self.params[f'{self.name}.interface']}:{self.params[f'{self.name}.channel']}"
        out.update({k: str(v) for k, v in self.counters.items()})
        return out
