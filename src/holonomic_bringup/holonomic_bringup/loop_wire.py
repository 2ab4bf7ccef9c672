"""The wire between the ROS node and its control loop process (both sides):
the fixed record formats, the control messages (framed by
:mod:`holonomic_core.control_socket`), the heartbeat.

Everything is plain bytes on pipes and a ``SOCK_SEQPACKET`` socket, so the
two sides need no shared Python objects; see
:mod:`holonomic_bringup.loop_host` for the design.
"""

from __future__ import annotations

import struct
from dataclasses import dataclass

import numpy as np

# the control messages' framing (one pickled message per packet), shared
# with the simulator's physics process: ``wire.send`` / ``wire.receive``
from holonomic_core.control_socket import MAX_MESSAGE, receive, send  # noqa: F401

#: a command record: vx [m/s], vy [m/s], wz [rad/s] in base_link and the
#: time.monotonic() [s] it was received (CLOCK_MONOTONIC: one clock for
#: every process on the machine)
COMMAND = struct.Struct("<4d")
#: state record flags: publish odom/tf/joint_states; publish /clock
PUBLISH, CLOCK = 1, 2
#: the heartbeat block: one int64, the number of cycles run
HEARTBEAT_SIZE = 8


_SCALARS = ("flags", "cycle", "stamp", "command_taken", "state", "stale", "saturation",
            "truth_valid")


@dataclass(frozen=True)
class RecordLayout:
    """Offsets (slices of a float64 array) of one state record for a robot
    with ``joints`` joints and ``units`` casters (slip residuals)."""

    joints: int
    units: int

    @classmethod
    def for_model(cls, model) -> "RecordLayout":
        return cls(len(model.joint_names), len(getattr(model.kinematics, "caster_names", ())))

    def __post_init__(self):
        n, k = self.joints, self.units
        fields = [("flags", 1), ("cycle", 1), ("stamp", 1), ("command_taken", 1), ("pose", 3),
                  ("pose_cov", 9), ("twist", 3), ("twist_cov", 9), ("twist_command", 3),
                  ("positions", n), ("velocities", n), ("efforts", n), ("residual", k),
                  ("state", 1), ("stale", 1), ("saturation", 1), ("truth_valid", 1),
                  ("truth_pose", 3), ("truth_twist", 3)]
        offset = 0
        for name, length in fields:
            object.__setattr__(self, name, offset if name in _SCALARS
                               else slice(offset, offset + length))
            offset += length
        object.__setattr__(self, "size", offset)

    @property
    def nbytes(self) -> int:
        return 8 * self.size


class StateRecord:
    """A read-only view of one state record (node side): the cycle's stamp
    [s, driver clock], when the cycle took its command from the command
    pipe [s, time.monotonic()], odometry pose (x, y, yaw) [m, m, rad] in
    odom and its 3x3 covariance, twist (vx, vy, wz) in base_link and covariance, the
    commanded twist, joint positions [rad], velocities [rad/s], efforts
    [N m] (NaN: unknown), slip residuals [m/s], ground truth (simulator)."""

    __slots__ = ("data", "layout")

    def __init__(self, data: np.ndarray, layout: RecordLayout):
        self.data, self.layout = data, layout

    def _get(self, name):
        return self.data[getattr(self.layout, name)]

    flags = property(lambda self: int(self._get("flags")))
    cycle = property(lambda self: int(self._get("cycle")))
    stamp = property(lambda self: float(self._get("stamp")))
    command_taken = property(lambda self: float(self._get("command_taken")))
    pose = property(lambda self: self._get("pose"))
    pose_covariance = property(lambda self: self._get("pose_cov").reshape(3, 3))
    twist = property(lambda self: self._get("twist"))
    twist_covariance = property(lambda self: self._get("twist_cov").reshape(3, 3))
    twist_command = property(lambda self: self._get("twist_command"))
    positions = property(lambda self: self._get("positions"))
    velocities = property(lambda self: self._get("velocities"))
    efforts = property(lambda self: self._get("efforts"))
    residual = property(lambda self: self._get("residual"))
    state_index = property(lambda self: int(self._get("state")))
    stale = property(lambda self: bool(self._get("stale")))
    saturation = property(lambda self: float(self._get("saturation")))
    truth_pose = property(lambda self: self._get("truth_pose")
                          if self._get("truth_valid") else None)
    truth_twist = property(lambda self: self._get("truth_twist")
                           if self._get("truth_valid") else None)
