"""Is an ODrive axis watchdog good enough? Pure verdicts, no bus.

The axis watchdog disarms the motor when the axis has not been fed for
``axis.config.watchdog_timeout`` [s] (``axis.config.enable_watchdog``):
the only thing that stops an ODrive whose controller died or hangs. A
watchdog is good enough when it is on, no longer than the bound the user
accepts (``odrive_can.max_watchdog_timeout``), and at least three control
periods long (a shorter one would disarm the motors on one late cycle).
"""

from __future__ import annotations

from dataclasses import dataclass

#: what an axis whose watchdog is not good enough does (``odrive_can.watchdog_check``)
POLICIES = ("warn", "refuse")
#: a watchdog shorter than this many control periods trips on a late cycle
MIN_PERIODS = 3
#: the drive stores float32: 0.3 s reads back as 0.30000001 s (relative
#: rounding <= 6e-8), which is not longer than a bound of 0.3 s
FLOAT32_SLACK = 1e-6


@dataclass(frozen=True)
class Verdict:
    ok: bool
    #: for ``status`` and messages: "on, 0.20 s (read over CAN, ...)", "OFF (...)"
    text: str


def assess(enabled: bool, timeout: float, bound: float, control_period: float,
           source: str) -> Verdict:
    """Settings read from the drive: ``timeout`` [s], ``bound`` [s] the
    longest accepted, ``control_period`` [s]."""
    if not enabled:
        return Verdict(False, f"OFF (enable_watchdog false, timeout {timeout:g} s; {source})")
    if not timeout > 0.0:
        return Verdict(False, f"on but with timeout {timeout:g} s, which never expires "
                              f"({source})")
    if timeout > bound * (1.0 + FLOAT32_SLACK):
        return Verdict(False, f"{timeout:.3g} s, longer than max_watchdog_timeout "
                              f"{bound:g} s ({source})")
    if timeout < MIN_PERIODS * control_period:
        return Verdict(False, f"{timeout:.3g} s, shorter than {MIN_PERIODS} control periods "
                              f"({MIN_PERIODS * control_period * 1e3:.0f} ms): a late cycle "
                              f"would disarm the motors ({source})")
    return Verdict(True, f"on, {timeout:.3g} s ({source})")


def probed(since: float, heartbeats: list[tuple[float, int]], bit: int, bound: float,
           control_period: float, how: str) -> Verdict:
    """The axis heard nothing from us after ``since`` [s]; ``heartbeats``
    are (stamp [s], axis error) of its heartbeats after it; ``how`` the
    probe was made, for the text.

    The watchdog expired after the last heartbeat without ``bit`` and by the
    first one with it: its timeout lies between the two (resolution: one
    heartbeat period). Good enough when the bit came and the clean interval
    before it is no longer than ``bound``.
    """
    clean = since
    for stamp, error in heartbeats:
        if error & bit:
            low, high = clean - since, stamp - since
            text = f"expired {low * 1e3:.0f}-{high * 1e3:.0f} ms after the last frame ({how})"
            if low > bound:
                return Verdict(False, f"{text}: longer than max_watchdog_timeout {bound:g} s")
            if high < MIN_PERIODS * control_period:
                return Verdict(False, f"{text}: shorter than {MIN_PERIODS} control periods")
            return Verdict(True, text)
        clean = stamp
    heard = f"{len(heartbeats)} heartbeats over {(clean - since) * 1e3:.0f} ms"
    return Verdict(False, f"OFF or longer than max_watchdog_timeout {bound:g} s (no "
                          f"WATCHDOG_TIMER_EXPIRED in {heard} without a frame from us; "
                          f"{how})")
