"""The control loop's scheduling requests (holonomic_core.realtime): the
normal scheduler's time slice (``loop.slice``) and what the loop asks for
under each ``loop.*`` setting. ROS-free; nothing here is timed.

A slice is a property of one thread: every request runs in a thread of its
own (or a forked child), so the test process's own scheduling is untouched.
"""

from __future__ import annotations

import ast
import os
import platform
import threading

import pytest

from holonomic_core import realtime

#: Linux gives a normal task a slice of its own from 6.12 on (EEVDF custom
#: slices, kernel/sched/syscalls.c); before, the call is accepted and ignored
_CUSTOM_SLICES = tuple(int(p) for p in platform.release().split(".")[:2]) >= (6, 12)


def _in_thread(fn):
    """fn() in a new thread; its result (or its exception, raised here)."""
    out = {}

    def run():
        try:
            out["value"] = fn()
        except BaseException as exc:      # noqa: BLE001 -- handed to the test
            out["error"] = exc
    thread = threading.Thread(target=run)
    thread.start()
    thread.join()
    if "error" in out:
        raise out["error"]
    return out["value"]


def _unprivileged_child(fn) -> str:
    """fn() in a forked child that is not root (it drops to uid/gid 65534,
    'nobody', when the tests run as root); its repr() back through a pipe."""
    realtime.current_slice()        # load the C library before forking
    read_end, write_end = os.pipe()
    pid = os.fork()
    if pid == 0:                    # the child: no pytest, no threads of its own
        try:
            os.close(read_end)
            if os.getuid() == 0:
                os.setgroups([])
                os.setresgid(65534, 65534, 65534)
                os.setresuid(65534, 65534, 65534)
            text = repr((os.getuid() != 0, fn()))
        except BaseException as exc:  # noqa: BLE001 -- reported to the parent
            text = repr((False, f"child failed: {exc!r}"))
        os.write(write_end, text.encode())
        os._exit(0)
    os.close(write_end)
    with os.fdopen(read_end) as f:
        text = f.read()
    os.waitpid(pid, 0)
    return text


def test_a_short_slice_needs_no_privilege_and_keeps_the_nice_value():
    def ask():
        os.nice(3)          # as under `nice -n 3`: the request must not undo it
        nice = os.getpriority(os.PRIO_PROCESS, 0)
        refused = realtime.request_slice(2e-4)
        return (refused, realtime.current_slice(), os.getpriority(os.PRIO_PROCESS, 0) - nice,
                realtime.current_policy())

    unprivileged, (refused, got, nice_change, policy) = ast.literal_eval(_unprivileged_child(ask))
    assert unprivileged
    assert nice_change == 0
    if _CUSTOM_SLICES:
        # granted as asked: 2e-4 s = 200000 ns, the kernel's own unit
        assert refused is None
        assert got == pytest.approx(2e-4, abs=1e-12)
        assert policy == "SCHED_OTHER 0, slice 0.20 ms"
    else:
        assert "needs Linux 6.12 or later" in refused and "\n" not in refused


@pytest.mark.skipif(not _CUSTOM_SLICES, reason="slices per task need Linux 6.12+; "
                    "test_a_short_slice_needs_no_privilege... checks the older kernel's line")
def test_the_kernel_clamps_a_slice_to_0_1_ms_and_100_ms():
    # kernel/sched/syscalls.c: clamp_t(u64, sched_runtime, NSEC_PER_MSEC/10, NSEC_PER_MSEC*100)
    assert _in_thread(lambda: (realtime.request_slice(1e-5), realtime.current_slice())) \
        == (None, pytest.approx(1e-4, abs=1e-12))
    assert _in_thread(lambda: (realtime.request_slice(1.0), realtime.current_slice())) \
        == (None, pytest.approx(0.1, abs=1e-12))


def test_a_kernel_that_keeps_its_own_slice_is_one_line_naming_the_kernel(monkeypatch):
    # a kernel before 6.12 accepts sched_setattr and reports no slice back
    # (sched_getattr's sched_runtime is 0 for a normal task): current_slice None
    monkeypatch.setattr(realtime, "current_slice", lambda: None)
    refused = _in_thread(lambda: realtime.request_slice(1e-4))
    assert refused == (f"this kernel ({platform.release()}) keeps its own time slice "
                       "(a slice per task needs Linux 6.12 or later)")


def test_an_unknown_architecture_is_one_line(monkeypatch):
    monkeypatch.setattr(platform, "machine", lambda: "mips")
    assert realtime.request_slice(1e-4) == "no sched_setattr system call number known for mips"
    assert realtime.current_slice() is None


class _Requests:
    """Stand-ins for the two requests, recording what schedule_loop asked."""

    def __init__(self, monkeypatch, fifo_granted: bool, slice_refusal=None):
        self.asked = []

        def realtime_request(priority):
            self.asked.append(("fifo", priority))
            return None if fifo_granted else "real-time scheduling unavailable, ..."

        def slice_request(seconds):
            self.asked.append(("slice", seconds))
            return slice_refusal
        monkeypatch.setattr(realtime, "request_realtime", realtime_request)
        monkeypatch.setattr(realtime, "request_slice", slice_request)
        policy = os.SCHED_FIFO if fifo_granted else os.SCHED_OTHER
        monkeypatch.setattr(os, "sched_getscheduler", lambda pid: policy)


def test_without_real_time_the_loop_asks_only_for_the_slice(monkeypatch):
    # (a request for SCHED_FIFO would be recorded, and refused, here)
    requests = _Requests(monkeypatch, fifo_granted=False)
    assert realtime.schedule_loop(False, 50, 1e-4) == []
    assert requests.asked == [("slice", 1e-4)]


def test_refused_real_time_falls_back_to_the_slice_with_one_warning(monkeypatch):
    requests = _Requests(monkeypatch, fifo_granted=False)
    assert realtime.schedule_loop(True, 60, 1e-4) == ["real-time scheduling unavailable, ..."]
    assert requests.asked == [("fifo", 60), ("slice", 1e-4)]


def test_granted_real_time_asks_for_no_slice(monkeypatch):
    requests = _Requests(monkeypatch, fifo_granted=True)
    assert realtime.schedule_loop(True, 50, 1e-4) == []
    assert requests.asked == [("fifo", 50)]


def test_slice_zero_keeps_the_kernels_default(monkeypatch):
    requests = _Requests(monkeypatch, fifo_granted=False)
    assert realtime.schedule_loop(False, 50, 0.0) == []
    assert requests.asked == []


def test_a_refused_slice_is_one_warning_and_the_loop_runs_on(monkeypatch):
    _Requests(monkeypatch, fifo_granted=False, slice_refusal="sched_setattr refused (EPERM)")
    assert realtime.schedule_loop(False, 50, 1e-4) == [
        "loop.slice 0.1 ms not applied, the loop keeps the kernel's default time slice: "
        "sched_setattr refused (EPERM)"]


def test_set_normal_leaves_an_inherited_real_time_policy():
    # the simulator's physics process is started by a loop that is already
    # SCHED_FIFO; where it should run on the normal scheduler it calls set_normal
    def run():
        granted = realtime.set_fifo(10) is None
        before = os.sched_getscheduler(0)
        realtime.set_normal()
        return granted, before, os.sched_getscheduler(0)

    granted, before, after = _in_thread(run)
    if not granted:
        pytest.skip("SCHED_FIFO is not permitted here, so there is no real-time policy to leave")
    assert (before, after) == (os.SCHED_FIFO, os.SCHED_OTHER)


#: A fresh interpreter feeds a PCV's drift watch (the loop's only user of
#: level-3 BLAS and LAPACK) 6 s of driving. It prints how much its address
#: space grew [kB] while doing so, optionally after warm_up_linear_algebra.
_DRIFT_CHILD = """
import math, sys
import numpy as np
from holonomic_core import realtime
from holonomic_core.config import load_model
from holonomic_core.drift_watch import DriftWatch, PERIOD

def vm_size_kb():
    with open("/proc/self/status") as f:
        return int(next(line for line in f if line.startswith("VmSize:")).split()[1])

model = load_model("xr4000")
watch = DriftWatch(model, window=5.0)
if sys.argv[1] == "warm":
    realtime.warm_up_linear_algebra()
q = np.zeros(len(model.joint_names))
before = vm_size_kb()
for k in range(int(6.0 / PERIOD)):
    t = k * PERIOD
    q = q + PERIOD * model.inverse(q, (0.3 * math.sin(t), 0.2, 0.5))
    watch.update(t, q)
print(vm_size_kb() - before, watch.moving_time)
"""


def _drift_watch_growth(mode: str) -> tuple[int, float]:
    import subprocess
    import sys
    out = subprocess.run([sys.executable, "-c", _DRIFT_CHILD, mode], capture_output=True,
                         text=True, timeout=120, check=True).stdout.split()
    return int(out[0]), float(out[1])


def test_after_the_warm_up_the_drift_watch_maps_no_new_memory():
    """The cost of numpy's BLAS work buffer is paid before the loop's first cycle.

    OpenBLAS maps that 32 MiB buffer on the first product that needs one.
    Under mlockall(MCL_FUTURE) this mapping is faulted in and locked inside
    that cycle: 8192 minor faults, 10-37 ms, seen as the XR4000's
    12-17 ms "controller" spike. Its trace is the address space growing by
    the buffer's size. Without the warm-up, the drift watch's first batch
    grows it (measured: 32768 kB). After the warm-up, the same 6 s map
    nothing new (measured: 0 kB). The bound, 4 MiB, is far from both.
    """
    grown_cold, moving_cold = _drift_watch_growth("cold")
    grown_warm, moving_warm = _drift_watch_growth("warm")
    # both watches took batches (2 s each; measured 3.3 s of motion), past a
    # quarter of the 5 s window, from where each batch also runs pinv and solve
    assert moving_cold > 1.25 and moving_warm > 1.25
    assert grown_cold > 16 * 1024, "this numpy's BLAS no longer maps its buffer lazily"
    assert grown_warm < 4 * 1024
