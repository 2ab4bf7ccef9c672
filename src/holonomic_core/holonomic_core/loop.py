"""A fixed-rate loop in its own thread, paced by absolute deadlines.

rclpy timers drop missed ticks, and their period jitters with whatever
else the executor runs (a timer shares its thread with the publishers and
subscriptions); a thread that sleeps to absolute deadlines ``t0 + k T``
(and busy-waits the last ``spin`` seconds) holds its rate (``make bench``
measures this loop in the base controller under traffic,
docs/benchmarks.md). If a cycle overruns
by more than a whole period the loop does not try to catch up with a burst
of cycles: it counts the miss and re-anchors its deadlines to now.
"""

from __future__ import annotations

import resource
import threading
import time
from typing import Callable

import numpy as np

from holonomic_core.realtime import DEFAULT_PRIORITY, DEFAULT_SLICE, SLICE_MAX
from holonomic_core.schema import ParamSpec

#: where and how the base controller runs its loop (docs/realtime.md)
LOOP_SPECS: list[ParamSpec] = [
    ParamSpec("loop.process", "bool",
              "Run the control loop (driver, controller, simulator) in a process of its own, "
              "out of the ROS executor's interpreter lock; false: in a thread of the node's "
              "process (for a driver that cannot leave it, e.g. python-can's in-process "
              "virtual bus).", default=True),
    ParamSpec("loop.realtime", "bool",
              "The loop process requests real-time priority: SCHED_FIFO at loop.priority "
              "and its memory locked (mlockall), which need privilege; when the system "
              "does not permit it, one warning and the loop runs on the normal scheduler "
              "with loop.slice (docs/realtime.md says how to grant it). false: it does "
              "not ask, and runs on the normal scheduler with loop.slice.", default=True),
    ParamSpec("loop.priority", "int", "SCHED_FIFO priority of the loop process (1-98).",
              default=DEFAULT_PRIORITY, minimum=1, maximum=98),
    ParamSpec("loop.slice", "double",
              "On the normal scheduler (no SCHED_FIFO), the time slice the loop process "
              "asks for (Linux 6.12+, no privilege needed; the kernel clamps to 0.1-100 "
              "ms): a short slice lets its wake-ups preempt the node and DDS instead of "
              "waiting behind them, at the same CPU share [s]. 0: the kernel's default "
              "slice. On an older kernel one warning, and the loop runs on.",
              default=DEFAULT_SLICE, minimum=0.0, maximum=SLICE_MAX),
    ParamSpec("loop.watchdog_timeout", "double",
              "A loop process whose cycles stop for this long is hung: the node kills it "
              "(the drives' own watchdogs stop the motors; the simulation stops with it) "
              "and reports an ERROR in diagnostics [s]. Default 2 s: far beyond any "
              "drive's command watchdog, and long enough that a loop without real-time "
              "priority starved on an overloaded machine is not taken for hung (such a "
              "loop can stall for half a second).",
              default=2.0, minimum=0.01, maximum=60.0),
]


class ManualClock:
    """A clock its owner advances (``now`` [s]): simulated time for running
    the controller offline, faster than real time (experiments, tools,
    benchmarks, tests). Call it for the time, as ``time.monotonic``."""

    def __init__(self, now: float = 0.0):
        self.now = float(now)

    def __call__(self) -> float:
        return self.now


def _percentile(values: np.ndarray, q: float) -> float:
    """numpy's default (linear) percentile ``q`` [%] of ``values``, by two
    partitions, without ``np.percentile``'s general-purpose overhead (the loop
    computes ten of them once a second, inside a cycle)."""
    n = values.size
    position = q / 100.0 * (n - 1)
    low = int(position)
    high = min(low + 1, n - 1)
    part = np.partition(values, (low, high))
    return float(part[low] + (position - low) * (part[high] - part[low]))


class LoopStats:
    """Period and compute-time statistics over the last ``window`` cycles [s],
    and where the long periods came from.

    A period (start to start) is the previous cycle's compute plus the sleep
    to the next deadline plus how late the loop woke after it. So each
    period over 2 ms is put down to the largest of: the wake-up's lateness
    (``woke_late``: the scheduler ran something else when the deadline came),
    the previous cycle's CPU time (``compute``: the cycle itself was slow,
    e.g. a garbage collection) and the rest of its wall time
    (``preempted``: the cycle was taken off the CPU while it ran).

    The slowest cycle since start (longest compute) is kept with its named
    parts and the page faults it took, so that a rare spike can be traced
    from the diagnostics alone. The minor page faults of all cycles are
    counted too: under mlockall a cycle should take none, and a fault means
    something mapped memory inside the cycle (numpy's BLAS work buffer would,
    for many periods, were it not set up before the first cycle:
    :func:`holonomic_core.realtime.warm_up_linear_algebra`).
    """

    def __init__(self, window: int = 2000):
        self.periods = np.zeros(window)
        self.compute = np.zeros(window)
        self.late = np.zeros(window)
        self.count = 0
        self.overruns = 0
        self.max_period = 0.0
        #: periods since start longer than 2 ms and 5 ms (the 1 kHz targets' bounds)
        self.over_2ms = 0
        self.over_5ms = 0
        #: the periods over 2 ms by cause (see the class docstring)
        self.over_2ms_causes = {"woke_late": 0, "compute": 0, "preempted": 0}
        self.max_late = 0.0
        self.max_compute = 0.0
        self.max_preempted = 0.0
        self._previous = (0.0, 0.0)         # the last cycle's (compute, cpu) [s]
        #: named parts of a cycle (e.g. physics, state writes): ring buffers and maxima [s]
        self.parts: dict[str, np.ndarray] = {}
        self.parts_max: dict[str, float] = {}
        self._parts_count: dict[str, int] = {}
        #: minor page faults in the cycles since start, and the cycles that took any
        self.page_faults = 0
        self.fault_cycles = 0
        #: the slowest cycle since start: its number, compute and CPU time
        #: [s], page faults and named parts [s]
        self.slowest: dict[str, float] = {}
        self._cycle_parts: dict[str, float] = {}     # this cycle's parts so far

    def add(self, period: float, compute: float, late: float = 0.0,
            cpu: float | None = None, faults: int = 0) -> None:
        """One cycle: the period that ended at its start, its compute
        (wall) time, how late it woke after its deadline and the CPU time its
        compute took (None: the whole compute time) [s], and the minor page
        faults it took. The parts added since the last cycle are its parts."""
        i = self.count % self.periods.size
        self.periods[i] = period
        self.compute[i] = compute
        self.late[i] = late
        self.count += 1
        cpu = compute if cpu is None else min(cpu, compute)
        preempted = compute - cpu
        self.max_late = max(self.max_late, late)
        if faults:
            self.page_faults += faults
            self.fault_cycles += 1
        if compute > self.max_compute:
            self.max_compute = compute
            self.slowest = {"cycle": self.count, "compute": compute, "cpu": cpu,
                            "faults": faults, **self._cycle_parts}
        self._cycle_parts.clear()
        self.max_preempted = max(self.max_preempted, preempted)
        if period > self.max_period:
            self.max_period = period
        if period > 2e-3:
            self.over_2ms += 1
            if period > 5e-3:
                self.over_5ms += 1
            before, before_cpu = self._previous
            causes = {"woke_late": late, "compute": before_cpu,
                      "preempted": before - before_cpu}
            self.over_2ms_causes[max(causes, key=causes.get)] += 1
        self._previous = (compute, cpu)

    def discard_cycle(self) -> None:
        """Forget the parts added for a cycle that is not added (the first:
        it has no period)."""
        self._cycle_parts.clear()

    def add_part(self, name: str, seconds: float) -> None:
        """The time [s] one named part of this cycle took."""
        self._cycle_parts[name] = seconds
        ring = self.parts.get(name)
        if ring is None:
            ring = self.parts[name] = np.zeros(self.periods.size)
            self.parts_max[name] = 0.0
            self._parts_count[name] = 0
        n = self._parts_count[name]
        ring[n % ring.size] = seconds
        self._parts_count[name] = n + 1
        if seconds > self.parts_max[name]:
            self.parts_max[name] = seconds

    def summary(self) -> dict[str, float]:
        """rate [Hz], period p50/p99/max over the window and max since start
        [ms], compute p99 [ms], overruns and periods over 2 ms / 5 ms since
        start; the split: wake-up lateness p99 and max, compute max, time
        preempted during a compute max [ms], the periods over 2 ms by cause,
        and each named part's p99 over the window and max since start [ms];
        page faults since start and the cycles that took them; the slowest
        cycle since start (its compute is compute_max_ms): its number, CPU
        time [ms], page faults and each of its named parts [ms]."""
        n = min(self.count, self.periods.size)
        slowest = self.slowest
        split = {"wake_late_p99_ms": 0.0, "wake_late_max_ms": 1e3 * self.max_late,
                 "compute_max_ms": 1e3 * self.max_compute,
                 "preempted_max_ms": 1e3 * self.max_preempted,
                 **{f"over_2ms_{k}": v for k, v in self.over_2ms_causes.items()},
                 "page_faults": self.page_faults, "page_fault_cycles": self.fault_cycles,
                 "slowest_cycle": slowest.get("cycle", 0),
                 "slowest_cpu_ms": 1e3 * slowest.get("cpu", 0.0),
                 "slowest_page_faults": slowest.get("faults", 0)}
        for name, ring in self.parts.items():
            m = min(self._parts_count[name], ring.size)
            split[f"{name}_p99_ms"] = 1e3 * _percentile(ring[:m], 99)
            split[f"{name}_max_ms"] = 1e3 * self.parts_max[name]
        for name, seconds in slowest.items():
            if name not in ("cycle", "compute", "cpu", "faults"):
                split[f"slowest_{name}_ms"] = 1e3 * seconds
        if n == 0:
            return {"rate_hz": 0.0, "period_p50_ms": 0.0, "period_p99_ms": 0.0,
                    "period_window_max_ms": 0.0, "period_max_ms": 0.0,
                    "compute_p99_ms": 0.0, "overruns": 0, "periods_over_2ms": 0,
                    "periods_over_5ms": 0, **split}
        periods = self.periods[:n]
        mean = float(np.mean(periods))
        split["wake_late_p99_ms"] = 1e3 * _percentile(self.late[:n], 99)
        return {"rate_hz": 1.0 / mean if mean > 0 else 0.0,
                "period_p50_ms": 1e3 * _percentile(periods, 50),
                "period_p99_ms": 1e3 * _percentile(periods, 99),
                "period_window_max_ms": 1e3 * float(periods.max()),
                "period_max_ms": 1e3 * self.max_period,
                "compute_p99_ms": 1e3 * _percentile(self.compute[:n], 99),
                "overruns": self.overruns, "periods_over_2ms": self.over_2ms,
                "periods_over_5ms": self.over_5ms, **split}


class ControlLoop:
    """Calls ``step()`` every ``period`` seconds in a daemon thread.

    ``on_error(exc)`` is called with any exception ``step`` raises; the loop
    keeps running unless it returns False (then the loop stops). ``spin``
    [s]: how long before each deadline to stop sleeping and busy-wait.
    """

    def __init__(self, period: float, step: Callable[[], object],
                 on_error: Callable[[BaseException], bool] | None = None,
                 spin: float = 2e-4, name: str = "control_loop"):
        if not period > 0:
            raise ValueError(f"loop period must be > 0 s, got {period}")
        self.period = float(period)
        self._step = step
        self._on_error = on_error
        self._spin = min(spin, 0.2 * period)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self.stats = LoopStats()

    def start(self) -> None:
        """Run the loop in its own (daemon) thread."""
        self._thread.start()

    def run(self) -> None:
        """Run the loop in the calling thread until :meth:`stop` (e.g. the
        main thread of a process of its own, on a real-time priority)."""
        self._run()

    def stop(self, timeout: float = 2.0) -> bool:
        """Stop the loop; returns True if the thread ended within ``timeout``."""
        self._stop.set()
        if self._thread.is_alive() and threading.current_thread() is not self._thread:
            self._thread.join(timeout)
        return not self._thread.is_alive()

    @property
    def running(self) -> bool:
        return self._thread.is_alive()

    def _run(self) -> None:
        clock = time.perf_counter
        cpu_clock = time.thread_time      # this thread's CPU time: compute vs preempted
        usage = resource.getrusage        # minor page faults: one system call
        thread = resource.RUSAGE_THREAD
        deadline = clock()
        last: float | None = None
        while not self._stop.is_set():
            start = clock()
            cpu_start = cpu_clock()
            faults_start = usage(thread).ru_minflt
            try:
                self._step()
            except Exception as exc:  # keep the loop alive; the owner decides
                if self._on_error is None or not self._on_error(exc):
                    break
            end = clock()
            if last is not None:
                self.stats.add(start - last, end - start, max(0.0, start - deadline),
                               cpu_clock() - cpu_start, usage(thread).ru_minflt - faults_start)
            else:
                self.stats.discard_cycle()
            last = start
            deadline += self.period
            if end - deadline > self.period:
                self.stats.overruns += 1
                deadline = end  # re-anchor: no burst of catch-up cycles
                continue
            remaining = deadline - clock() - self._spin
            if remaining > 0:
                if self._stop.wait(remaining):
                    break
            while clock() < deadline:
                pass
