"""Emergency stop and holding still: the controller's safety state, ROS-free.

Two pieces the base controller consults every cycle:

* :class:`EmergencyStop` -- the latched e-stop input. Any safety source
  (a panel button's bridge, a wireless e-stop's receiver,
  ``holonomic-ctl estop``, teleop's e-stop key) sends ``pressed`` or
  ``released``; the last message wins. With a heartbeat timeout
  (``safety.estop_timeout`` > 0) the input must *keep* saying "released":
  no fresh "released" within the timeout counts as pressed (a wireless
  e-stop out of range, its bridge dead). Before the first message the
  input is released without a heartbeat and pressed with one (the robot
  cannot arm before its e-stop is heard).
* :class:`DisarmPolicy` -- what disarming does with the drives
  (``safety.disarm_mode``): ``coast`` idles them at once (power stage off:
  the base is free to roll); ``hold`` first brings the base to rest under
  the deceleration limits and keeps the drives in closed-loop zero velocity
  for ``safety.hold_time`` (0: until a second disarm request) before idling,
  so a base on a ramp stays where it stopped.

What the controller does with them (``holonomic_core.controller``): pressed
-> every drive quick-stops (:meth:`Driver.quick_stop
<holonomic_core.driver.Driver.quick_stop>`), the controller disarms and says
why (``status().estop``), arming is refused until released; released ->
nothing moves until someone arms again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

from holonomic_core.schema import ParamSpec

#: what disarming does with the drives
DISARM_MODES = ("hold", "coast")

SAFETY_SPECS: list[ParamSpec] = [
    ParamSpec("safety.disarm_mode", "string",
              "What disarming (~/enable false) does with the drives: hold brings the base to "
              "rest under the deceleration limits and keeps the drives in closed-loop zero "
              "velocity for safety.hold_time, then idles them (a base on a ramp stays put); "
              "coast idles them at once (power stage off, the base is free to roll). A fault "
              "or the emergency stop never holds.", default="hold", choices=DISARM_MODES),
    ParamSpec("safety.hold_time", "double",
              "How long disarm_mode hold keeps the drives at zero velocity before idling "
              "them [s]; 0: until a second disarm request (or an arm).",
              default=0.0, minimum=0.0, maximum=86400.0),
    ParamSpec("safety.estop_timeout", "double",
              "Heartbeat of the emergency_stop input: with a value > 0, no 'released' message "
              "(false) within this time counts as pressed (a wireless e-stop out of range or "
              "its bridge dead), and the robot cannot arm before the first one [s]; 0: no "
              "heartbeat, the last message holds for ever.",
              default=0.0, minimum=0.0, maximum=60.0),
]


class EmergencyStop:
    """The latched emergency-stop input (see the module docstring).

    ``timeout`` [s]: the heartbeat (0: none). Stamps are on the controller's
    monotonic clock. :meth:`update` may be called from any thread (it
    replaces one tuple); :meth:`reason` from the loop thread.
    """

    def __init__(self, timeout: float = 0.0):
        if not (math.isfinite(timeout) and timeout >= 0.0):
            raise ValueError(f"estop timeout must be a finite number >= 0 s, got {timeout}")
        self.timeout = float(timeout)
        # (pressed, source, stamp) of the last message; None: none yet
        self._last: tuple[bool, str, float] | None = None

    def update(self, pressed: bool, source: str, stamp: float) -> None:
        """One message from a safety source: pressed (True) or released."""
        self._last = (bool(pressed), str(source) or "emergency_stop", float(stamp))

    def reason(self, now: float) -> str | None:
        """Why the e-stop is pressed at ``now`` (naming the source), or None
        when it is released."""
        last = self._last
        if last is None:
            if self.timeout > 0.0:
                return (f"emergency_stop heartbeat: no 'released' message yet "
                        f"(safety.estop_timeout {self.timeout:g} s)")
            return None
        pressed, source, stamp = last
        if pressed:
            return f"emergency stop pressed by {source}"
        if self.timeout > 0.0 and now - stamp > self.timeout:
            return (f"emergency_stop heartbeat lost: no 'released' from {source} for "
                    f"{now - stamp:.2f} s (safety.estop_timeout {self.timeout:g} s)")
        return None


@dataclass(frozen=True)
class DisarmPolicy:
    """``safety.disarm_mode`` and ``safety.hold_time`` [s] (0: hold until a
    second disarm request)."""

    mode: str = "hold"
    hold_time: float = 0.0

    def __post_init__(self):
        if self.mode not in DISARM_MODES:
            raise ValueError(f"disarm mode must be one of {DISARM_MODES}, got {self.mode!r}")
        if not (math.isfinite(self.hold_time) and self.hold_time >= 0.0):
            raise ValueError(f"hold_time must be a finite number >= 0 s, got {self.hold_time}")

    @property
    def holds(self) -> bool:
        return self.mode == "hold"

    def hold_over(self, since: float, now: float) -> bool:
        """Whether a hold that began at ``since`` [s] has run its time."""
        return self.hold_time > 0.0 and now - since >= self.hold_time


def safety_from_values(values: Mapping[str, Any]) -> tuple[EmergencyStop, DisarmPolicy]:
    """The e-stop input and the disarm policy from validated flat values
    (SAFETY_SPECS' defaults where a key is absent)."""
    defaults = {s.name: s.default for s in SAFETY_SPECS}
    get = lambda key: values.get(key, defaults[key])  # noqa: E731
    return (EmergencyStop(float(get("safety.estop_timeout"))),
            DisarmPolicy(str(get("safety.disarm_mode")), float(get("safety.hold_time"))))


def parse_pose(values) -> tuple[float, float, float]:
    """``(x, y, yaw)`` [m, m, rad] as finite floats, or ValueError naming the
    bad component (set_pose, ``holonomic-ctl set-pose``)."""
    try:
        parts = [float(v) for v in values]
    except (TypeError, ValueError) as exc:
        raise ValueError(f"pose must be three numbers x y yaw, got {values!r}") from exc
    if len(parts) != 3:
        raise ValueError(f"pose must be three numbers x y yaw, got {len(parts)}")
    for name, v in zip(("x", "y", "yaw"), parts):
        if not math.isfinite(v):
            raise ValueError(f"pose {name} must be a finite number, got {v}")
    return parts[0], parts[1], parts[2]


def parse_covariance(values) -> tuple[float, ...]:
    """A planar pose covariance (3 x 3 of x, y, yaw, row-major, 9 values)
    checked to be finite, symmetric and positive semi-definite; ValueError
    otherwise."""
    import numpy as np

    try:
        c = np.asarray(values, dtype=float).reshape(3, 3)
    except (TypeError, ValueError) as exc:
        raise ValueError("pose covariance must be 9 numbers (3 x 3 of x, y, yaw)") from exc
    if not np.isfinite(c).all():
        raise ValueError("pose covariance must be finite")
    if np.abs(c - c.T).max() > 1e-9 * max(1.0, np.abs(c).max()):
        raise ValueError("pose covariance must be symmetric")
    if np.linalg.eigvalsh(c).min() < -1e-12 * max(1.0, np.abs(c).max()):
        raise ValueError("pose covariance must be positive semi-definite")
    return tuple(float(v) for v in c.ravel())


def planar_covariance(covariance36) -> tuple[float, ...]:
    """The (x, y, yaw) block (9 values, row-major) of a ROS 6 x 6 pose
    covariance (x, y, z, roll, pitch, yaw; geometry_msgs/PoseWithCovariance)."""
    if len(covariance36) != 36:
        raise ValueError(f"pose covariance must have 36 values, got {len(covariance36)}")
    rows = (0, 1, 5)
    return tuple(float(covariance36[6 * i + j]) for i in rows for j in rows)
