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

Without that privilege, :func:`request_slice` asks the normal scheduler
(EEVDF, Linux 6.12 and later) for a short time slice: no privilege is
needed, the loop's share of the CPU stays what it was, but its wake-ups come
with an earlier virtual deadline and so preempt the tasks running on the
kernel's default slice (the node, DDS) instead of waiting behind them.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
import platform

#: mlockall flags (linux/mman.h): what is mapped now and everything mapped later
MCL_CURRENT, MCL_FUTURE = 1, 2
#: the default SCHED_FIFO priority: ros2_control's controller manager uses 50,
#: below the kernel's interrupt threads (50 on PREEMPT_RT) would be 49; 50 is
#: what robot integrators expect to see in ``chrt -p``
DEFAULT_PRIORITY = 50


@functools.lru_cache(maxsize=1)
def _libc():
    """The C library (loaded once: find_library may run ldconfig), or None."""
    name = ctypes.util.find_library("c")
    return None if name is None else ctypes.CDLL(name, use_errno=True)


def set_fifo(priority: int) -> str | None:
    """Put the calling process on SCHED_FIFO at ``priority`` (1..99).
    Returns None when granted, else why not (one line)."""
    try:
        os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(priority))
    except (PermissionError, OSError, AttributeError) as exc:
        return (f"SCHED_FIFO priority {priority} not permitted "
                f"({getattr(exc, 'strerror', None) or exc})")
    return None


def set_normal() -> None:
    """Put the calling process on the normal scheduler (SCHED_OTHER), e.g. a
    helper process started by a real-time loop, which inherits its policy.
    Leaving real-time needs no privilege."""
    if os.sched_getscheduler(0) != os.SCHED_OTHER:
        os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))


def lock_memory() -> str | None:
    """``mlockall(MCL_CURRENT | MCL_FUTURE)``. Returns None when granted,
    else why not (one line)."""
    libc = _libc()
    if libc is None:
        return "mlockall unavailable (no C library found)"
    if libc.mlockall(MCL_CURRENT | MCL_FUTURE) != 0:
        errno = ctypes.get_errno()
        return f"mlockall not permitted ({os.strerror(errno)})"
    return None


def warm_up_linear_algebra() -> None:
    """Do numpy's one-time BLAS and LAPACK set-up now, before the loop's first
    cycle, instead of inside whichever cycle first needs it.

    OpenBLAS, numpy's linear algebra, maps a 32 MiB work buffer on the first
    call that needs one and then keeps it. Products of 2x2 and 3x3 matrices
    don't need it; ``A.T @ A`` (syrk) or an LU solve do. Under
    ``mlockall(MCL_FUTURE)`` (:func:`lock_memory`) that mapping is faulted in
    and locked page by page inside the call: 8192 minor faults (32 MiB of
    4 KiB pages), many 1 ms cycles' worth of CPU. In the loop, the first such
    call is the PCV's drift watch's first batch, about 2 s after the base
    first moves, where it would show as a long "controller" part
    (docs/realtime.md). The first SVD also sets itself up. Each routine here
    is one the cycle can reach: the drift watch's ``J.T @ J``, ``pinv`` and
    ``solve``, the torque law's ``pinv`` distribution, and the estimators'
    ``lstsq``. It leaves the buffer mapped, and locked under mlockall
    (test_realtime: after the warm-up the drift watch maps no new memory).
    """
    import numpy as np

    a = np.eye(4) + 0.5                      # symmetric, positive definite
    a.T @ a                                  # level-3 product: maps the buffer
    a @ a
    np.linalg.solve(a, np.ones(4))           # LU (getrf/getrs)
    np.linalg.pinv(a)                        # SVD (gesdd)
    np.linalg.lstsq(a, np.ones(4), rcond=None)


def tighten_timer_slack(nanoseconds: int = 1000) -> bool:
    """Let the kernel wake the calling thread's sleeps at most ``nanoseconds``
    after their deadline (``prctl(PR_SET_TIMERSLACK)``; the default is 50 µs,
    which the kernel uses to batch wake-ups of normal threads). Needs no
    privilege. Returns whether it was set."""
    pr_set_timerslack = 29                      # linux/prctl.h
    libc = _libc()
    if libc is None:
        return False
    return libc.prctl(pr_set_timerslack, ctypes.c_ulong(nanoseconds), 0, 0, 0) == 0


#: sched_setattr / sched_getattr system call numbers (glibc has no wrapper):
#: x86_64 arch/x86/entry/syscalls/syscall_64.tbl 314/315; arm64 and the other
#: architectures of include/uapi/asm-generic/unistd.h 274/275
_SCHED_ATTR_SYSCALLS = {"x86_64": (314, 315), "aarch64": (274, 275), "arm64": (274, 275)}
#: the slice the kernel accepts (kernel/sched/syscalls.c clamps to 0.1-100 ms) [s]
SLICE_MIN, SLICE_MAX = 1e-4, 0.1
#: the loop's slice on the normal scheduler [s]: the shortest the kernel
#: grants, so that the loop's wake-ups get the earliest virtual deadline; a
#: cycle's compute is of that order (the ``compute`` part of the 1 kHz loop
#: rows in docs/benchmarks.md, ``make bench``)
DEFAULT_SLICE = SLICE_MIN


class _SchedAttr(ctypes.Structure):
    """``struct sched_attr`` (include/uapi/linux/sched/types.h), 56 bytes."""

    _fields_ = [("size", ctypes.c_uint32), ("sched_policy", ctypes.c_uint32),
                ("sched_flags", ctypes.c_uint64), ("sched_nice", ctypes.c_int32),
                ("sched_priority", ctypes.c_uint32), ("sched_runtime", ctypes.c_uint64),
                ("sched_deadline", ctypes.c_uint64), ("sched_period", ctypes.c_uint64),
                ("sched_util_min", ctypes.c_uint32), ("sched_util_max", ctypes.c_uint32)]


def _get_attr(libc, getattr_nr: int) -> _SchedAttr | None:
    attr = _SchedAttr()
    if libc.syscall(getattr_nr, 0, ctypes.byref(attr), ctypes.sizeof(attr), 0) != 0:
        return None
    return attr


def current_slice() -> float | None:
    """The calling thread's time slice on the normal scheduler [s] (what
    ``sched_getattr`` reports as ``sched_runtime``: Linux 6.12 and later),
    or None (another policy, an older kernel, an unknown architecture)."""
    numbers = _SCHED_ATTR_SYSCALLS.get(platform.machine())
    libc = _libc()
    if numbers is None or libc is None or os.sched_getscheduler(0) not in (
            os.SCHED_OTHER, os.SCHED_BATCH):
        return None
    attr = _get_attr(libc, numbers[1])
    return None if attr is None or attr.sched_runtime == 0 else attr.sched_runtime * 1e-9


def request_slice(seconds: float) -> str | None:
    """Ask the normal scheduler for a time slice of ``seconds`` (0.1-100 ms;
    the kernel clamps) for the calling thread: ``sched_setattr`` with
    ``sched_runtime`` on its current policy (SCHED_OTHER or SCHED_BATCH) and
    its current nice value, which needs no privilege. Returns None when the
    kernel took it, else why not (one line): a kernel before 6.12 accepts the
    call but keeps its own slice (read back through ``sched_getattr``)."""
    numbers = _SCHED_ATTR_SYSCALLS.get(platform.machine())
    if numbers is None:
        return f"no sched_setattr system call number known for {platform.machine()}"
    libc = _libc()
    if libc is None:
        return "sched_setattr unavailable (no C library found)"
    policy = os.sched_getscheduler(0)
    if policy not in (os.SCHED_OTHER, os.SCHED_BATCH):
        return "a time slice applies to the normal scheduler only"
    # the thread's own nice value: sched_setattr sets it too, and lowering
    # it (e.g. under `nice -n 10`) would need privilege
    nice = os.getpriority(os.PRIO_PROCESS, 0)
    nanoseconds = int(round(seconds * 1e9))
    attr = _SchedAttr(size=ctypes.sizeof(_SchedAttr), sched_policy=policy,
                      sched_nice=nice, sched_runtime=nanoseconds)
    if libc.syscall(numbers[0], 0, ctypes.byref(attr), 0) != 0:
        return f"sched_setattr refused ({os.strerror(ctypes.get_errno())})"
    got = current_slice()
    wanted = min(max(nanoseconds, int(SLICE_MIN * 1e9)), int(SLICE_MAX * 1e9)) * 1e-9
    if got is None or abs(got - wanted) > 1e-9:
        return (f"this kernel ({platform.release()}) keeps its own time slice (a slice "
                "per task needs Linux 6.12 or later)")
    return None


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
    """The calling thread's scheduling policy and priority, and on the normal
    scheduler its time slice where the kernel reports one, e.g.
    'SCHED_FIFO 50' or 'SCHED_OTHER 0, slice 0.10 ms'."""
    names = {os.SCHED_OTHER: "SCHED_OTHER", os.SCHED_FIFO: "SCHED_FIFO",
             os.SCHED_RR: "SCHED_RR", os.SCHED_BATCH: "SCHED_BATCH"}
    policy = os.sched_getscheduler(0)
    text = f"{names.get(policy, str(policy))} {os.sched_getparam(0).sched_priority}"
    slice_s = current_slice()
    return text if slice_s is None else f"{text}, slice {slice_s * 1e3:.2f} ms"


def schedule_loop(realtime: bool, priority: int, slice_s: float) -> list[str]:
    """Schedule the calling thread (the control loop's) as the ``loop.*``
    parameters say: with ``realtime``, SCHED_FIFO at ``priority`` and
    mlockall (:func:`request_realtime`); then, if it is on the normal
    scheduler (``realtime`` false, or SCHED_FIFO refused) and ``slice_s`` >
    0, a time slice of ``slice_s`` [s] (:func:`request_slice`). Returns the
    warning lines to log, one per refusal (none: all granted)."""
    warnings = []
    if realtime:
        refused = request_realtime(priority)
        if refused is not None:
            warnings.append(refused)
    if slice_s > 0.0 and os.sched_getscheduler(0) == os.SCHED_OTHER:
        why = request_slice(slice_s)
        if why is not None:
            warnings.append(f"loop.slice {slice_s * 1e3:g} ms not applied, the loop keeps "
                            f"the kernel's default time slice: {why}")
    return warnings
