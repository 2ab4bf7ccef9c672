"""Real-time scheduling for the control loop's process, where the system allows it.

:func:`request_realtime` asks Linux for what ros2_control's controller
manager asks for: the calling thread on ``SCHED_FIFO`` at a fixed priority
(it then preempts every normal process, DDS and the ROS executor included)
and all of the process's memory locked in RAM (``mlockall``: no page fault
-- a disk read of milliseconds -- in the middle of a cycle). Neither is
allowed to an ordinary user by default; each refusal is returned as one
line for the caller to log, and the loop runs on without it.

Granting it on a robot (docs/realtime.md): ``rtprio`` and ``memlock`` limits
for the user in ``/etc/security/limits.conf`` (or CAP_SYS_NICE and
CAP_IPC_LOCK), ideally a PREEMPT_RT kernel.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os

#: mlockall flags (linux/mman.h): what is mapped now and everything mapped later
MCL_CURRENT, MCL_FUTURE = 1, 2
#: the default SCHED_FIFO priority: ros2_control's controller manager uses 50,
#: below the kernel's interrupt threads (50 on PREEMPT_RT) would be 49; 50 is
#: what robot integrators expect to see in ``chrt -p``
DEFAULT_PRIORITY = 50


def set_fifo(priority: int) -> str | None:
    """Put the calling process on SCHED_FIFO at ``priority`` (1..99).
    Returns None when granted, else why not (one line)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as exc:
        return (f"SCHED_FIFO priority {priority} not permitted "
                f"({getattr(exc, 'strerror', None) or exc})")
    return None


def lock_memory() -> str | None:
    """``mlockall(MCL_CURRENT | MCL_FUTURE)``. Returns None when granted,
    else why not (one line)."""
    libc_name = ctypes.util.find_library("c")
    if libc_name is None:
        return "mlockall unavailable (no C library found)"
    libc = ctypes.CDLL(libc_name, use_errno=True)
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        errno = ctypes.get_errno()
        return f"mlockall not permitted ({os.strerror(errno)})"
    return None


def tighten_timer_slack(nanoseconds: int = 1000) -> bool:
    """Let the kernel wake the calling thread's sleeps at most ``nanoseconds``
    after their deadline (``prctl(PR_SET_TIMERSLACK)``; the default is 50 µs,
    which the kernel uses to batch wake-ups of normal threads). Needs no
    privilege. Returns whether it was set."""
    pr_set_timerslack = 29                      # linux/prctl.h
    libc_name = ctypes.util.find_library("c")
    if libc_name is None:
        return False
    libc = ctypes.CDLL(libc_name, use_errno=True)
    return libc.prctl(pr_set_timerslack, ctypes.c_ulong(nanoseconds), 0, 0, 0) == 0


def request_realtime(priority: int = DEFAULT_PRIORITY) -> str | None:
    """Both of the above. Returns None when both were granted, else one
    warning line naming what was refused and how to grant it."""
    refused = [why for why in (set_fifo(priority), lock_memory()) if why is not None]
    if not refused:
        return None
    return ("real-time scheduling unavailable, running without it: " + "; ".join(refused)
            + " (grant rtprio and memlock in /etc/security/limits.conf, docs/realtime.md; "
            "-p loop.realtime:=false silences this)")


def current_policy() -> str:
    """The calling process's scheduling policy and priority, e.g. 'SCHED_FIFO 50'."""
    names = {os.SCHED_OTHER: "SCHED_OTHER", os.SCHED_FIFO: "SCHED_FIFO",
             os.SCHED_RR: "SCHED_RR"}
    policy = os.sched_getscheduler(0)
    return f"{names.get(policy, str(policy))} {os.sched_getparam(0).sched_priority}"
