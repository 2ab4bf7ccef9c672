"""Scripted teleop: a list of twists held for a time, read from YAML.

The demo's script (``demo_script.yaml`` beside this module) is data that
``holonomic-demo`` publishes over ROS and the analysis drives through the
controller (``holonomic-analyze --trajectory``), so the two cannot drift
apart. A script file::

    rate: 50.0          # [Hz] how often the teleop renews its command
    segments:
      - {name: forward, twist: [0.5, 0.0, 0.0], seconds: 3.0}
      - {name: line in odom, twist: [-0.3, 0.2, 1.0], seconds: 4.0, frame: odom}
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import yaml

from holonomic_core.schema import ConfigError
from holonomic_core.se2 import rotate

FRAMES = ("base_link", "odom")


@dataclass(frozen=True)
class Segment:
    """A scripted motion: ``twist`` (vx, vy, wz) [m/s, m/s, rad/s] held for
    ``seconds`` [s]; in ``frame`` base_link (a body twist) or odom (vx, vy in
    the odom frame, turned into a body twist every cycle with the odometry
    heading)."""

    name: str
    twist: tuple[float, float, float]
    seconds: float
    frame: str = "base_link"


def _segment(index: int, item) -> Segment:
    key = f"segments[{index}]"
    if not isinstance(item, dict) or not {"name", "twist", "seconds"} <= set(item):
        raise ConfigError(key, item, "a mapping with name, twist and seconds (frame optional)")
    twist, seconds, frame = item["twist"], item["seconds"], item.get("frame", "base_link")
    if not (isinstance(twist, list) and len(twist) == 3
            and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                    and math.isfinite(v) for v in twist)):
        raise ConfigError(f"{key}.twist", twist, "3 finite numbers (vx, vy, wz)")
    if isinstance(seconds, bool) or not isinstance(seconds, (int, float)) \
            or not 0.0 < seconds < math.inf:
        raise ConfigError(f"{key}.seconds", seconds, "a duration > 0 [s]")
    if frame not in FRAMES:
        raise ConfigError(f"{key}.frame", frame, f"one of {list(FRAMES)}")
    return Segment(str(item["name"]), tuple(float(v) for v in twist), float(seconds), frame)


@dataclass(frozen=True)
class Script:
    """Segments played in order, the command renewed at ``rate`` [Hz]."""

    rate: float
    segments: tuple[Segment, ...]


def read_script(path: Path) -> Script:
    """The script file ``path``; ConfigError naming the bad entry."""
    doc = yaml.safe_load(Path(path).read_text())
    if not isinstance(doc, dict):
        raise ConfigError("segments", doc, f"a mapping with rate and segments in {path}")
    rate, items = doc.get("rate"), doc.get("segments")
    if isinstance(rate, bool) or not isinstance(rate, (int, float)) or not 0.0 < rate < math.inf:
        raise ConfigError("rate", rate, f"a command rate > 0 [Hz] in {path}")
    if not isinstance(items, list) or not items:
        raise ConfigError("segments", items, f"a list of segments in {path}")
    return Script(float(rate), tuple(_segment(i, item) for i, item in enumerate(items)))


def demo_script() -> Script:
    """The demo's script (``demo_script.yaml``, installed with this package)."""
    with resources.as_file(resources.files("holonomic_core") / "demo_script.yaml") as path:
        return read_script(path)


def body_command(seg: Segment, yaw: float, rate: float) -> tuple[float, float, float]:
    """The body twist (vx, vy, wz) [m/s, m/s, rad/s] to command now for
    ``seg``; ``yaw`` [rad]: the odometry heading; ``rate`` [Hz]: how often the
    command is renewed."""
    vx, vy, wz = seg.twist
    if seg.frame == "odom":
        # The command holds until the next one: aim at the mid-period heading.
        bx, by = rotate(vx, vy, -(yaw + 0.5 * wz / rate))
        return (bx, by, wz)
    return seg.twist
