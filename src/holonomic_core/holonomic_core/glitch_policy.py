"""What an isolated invalid joint reading does: fault the base, or drop it.

Real encoders glitch. A velocity of thousands of rad/s for one sample, a
position that jumps for one sample and is back on the next, a NaN in one
frame: such a reading says nothing about the motion, and the next one is good
again. A controller that faults on each of them stops the robot every time
one comes (a commercial base's controller documents 4000 rad/s spikes "once
every few hours"), so :class:`GlitchPolicy` can *drop* them instead:

* ``fault``: every invalid reading faults and stops the base;
* ``drop``: an invalid reading is counted and ignored -- the odometry keeps
  its last good reading as the reference, and the next good reading
  integrates the whole displacement since then as one exact arc (encoders
  report positions, so no motion is lost: only the arc's mid-point
  configuration spans two periods instead of one) -- unless the readings are
  not isolated any more: more than ``rate`` dropped in the last minute, or
  a run of dropped readings longer than ``max_gap`` seconds (a dead encoder
  that keeps answering NaN, a position that jumped for good), which faults
  as ``fault`` does.

Only the per-joint value tests of :class:`~holonomic_core.monitor.ReadingMonitor`
(non-finite value, speed over the bound, position jump) are glitches; a
reading of the wrong shape, frozen readings and a joint that cannot follow
its command fault whatever the policy.

The policy runs only on a reading that failed a check (rare), so it has no
compiled twin: the per-cycle test stays :func:`hot_path` 's
``reading_plausible`` in both paths.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

#: glitch_policy values
POLICIES = ("fault", "drop")
#: the window [s] of ``rate``
WINDOW = 60.0


class Glitch(str):
    """The message of an invalid value in one joint's reading (a ``str``, as
    every check's message), carrying the joint's name."""

    joint: str

    def __new__(cls, message: str, joint: str):
        self = super().__new__(cls, message)
        self.joint = joint
        return self


@dataclass(frozen=True)
class GlitchLimits:
    """``policy``: "fault" or "drop"; ``rate`` [1/min]: dropped readings in
    the last minute above which the next is a fault; ``max_gap`` [s]: the
    longest run of consecutive dropped readings (the frozen-reading timeout:
    a joint unseen for longer is as blind as a frozen one)."""

    policy: str
    rate: float
    max_gap: float


class GlitchPolicy:
    """Decides, reading by reading, whether a glitch is dropped or faults."""

    def __init__(self, limits: GlitchLimits):
        if limits.policy not in POLICIES:
            raise ValueError(f"glitch policy {limits.policy!r}: one of {', '.join(POLICIES)}")
        self.limits = limits
        #: readings dropped since start (diagnostics)
        self.dropped = 0
        #: the message of the last dropped reading (None: none yet)
        self.last: str | None = None
        self.reset()

    def reset(self) -> None:
        """Forget the recent drops (arming again after a fault)."""
        self._times: deque[float] = deque()
        self._run_start: float | None = None

    def good(self) -> None:
        """A reading passed every check: a run of drops is over."""
        self._run_start = None

    def judge(self, problem: str, now: float) -> str | None:
        """None: drop the reading ``problem`` describes (counted); else the
        fault's message. ``now`` [s]: the controller's monotonic clock."""
        if not isinstance(problem, Glitch) or self.limits.policy == "fault":
            return problem
        times = self._times
        while times and now - times[0] > WINDOW:
            times.popleft()
        if self._run_start is None:
            self._run_start = now
        run = now - self._run_start
        if len(times) + 1 > self.limits.rate:
            return (f"{problem}; {len(times) + 1} invalid readings in the last minute, over "
                    f"safety.glitch_rate ({self.limits.rate:g}/min)")
        if run > self.limits.max_gap:
            return (f"{problem}; invalid readings for {run:.3f} s, over "
                    f"safety.reading_timeout ({self.limits.max_gap:g} s)")
        times.append(now)
        self.dropped += 1
        self.last = str(problem)
        return None
