"""The fixed-rate loop and its statistics (holonomic_core.loop), without
timing assertions: what a cycle does, errors, stopping, counting."""

import threading
import time

import numpy as np
import pytest

from holonomic_core.loop import ControlLoop, LoopStats, ManualClock


def test_manual_clock_reads_what_its_owner_set():
    clock = ManualClock(2.5)
    assert clock() == 2.5
    clock.now += 0.005
    assert clock() == 2.505
    assert ManualClock()() == 0.0


def test_loop_stats_summary_over_the_window_and_since_start():
    stats = LoopStats(window=4)
    assert stats.summary() == {"rate_hz": 0.0, "period_p50_ms": 0.0, "period_p99_ms": 0.0,
                               "period_window_max_ms": 0.0, "period_max_ms": 0.0,
                               "compute_p99_ms": 0.0, "overruns": 0, "periods_over_2ms": 0,
                               "periods_over_5ms": 0, "wake_late_p99_ms": 0.0,
                               "wake_late_max_ms": 0.0, "compute_max_ms": 0.0,
                               "preempted_max_ms": 0.0, "over_2ms_woke_late": 0,
                               "over_2ms_compute": 0, "over_2ms_preempted": 0,
                               "page_faults": 0, "page_fault_cycles": 0,
                               "slowest_cycle": 0, "slowest_cpu_ms": 0.0,
                               "slowest_page_faults": 0}
    # six cycles in a window of four: the 9 ms period (second) leaves the
    # window but stays the maximum since start
    for period, compute in ((0.005, 0.001), (0.009, 0.002), (0.004, 0.001),
                            (0.006, 0.003), (0.005, 0.001), (0.004, 0.0005)):
        stats.add(period, compute)
    stats.overruns = 2
    s = stats.summary()
    # the window holds the last four periods: 4, 6, 5, 4 ms (mean 4.75 ms)
    assert stats.count == 6
    assert s["rate_hz"] == pytest.approx(1.0 / 0.00475)          # 1 / mean(window)
    assert s["period_p50_ms"] == pytest.approx(4.5)                # median of 4, 4, 5, 6
    # numpy's linear percentile: p99 of (4, 4, 5, 6) = 5 + 0.97 * (6 - 5)
    assert s["period_p99_ms"] == pytest.approx(5.97)
    assert s["period_window_max_ms"] == pytest.approx(6.0)
    assert s["period_max_ms"] == pytest.approx(9.0)
    assert s["compute_p99_ms"] == pytest.approx(
        1e3 * np.percentile([0.001, 0.003, 0.001, 0.0005], 99))
    assert s["overruns"] == 2
    # since start: 5, 9, 4, 6, 5, 4 ms are all over 2 ms; 9 and 6 over 5 ms
    assert s["periods_over_2ms"] == 6 and s["periods_over_5ms"] == 2


def test_each_long_period_is_put_down_to_its_largest_cause():
    """By hand, 1 ms cycles (period = previous compute + sleep + lateness):
    cycle 2 woke 2.5 ms late -> period 3.5 ms, cause woke_late; cycle 3
    computed 2.4 ms of wall time of which 0.4 ms on the CPU (2 ms preempted)
    -> cycle 4's period 3.4 ms, cause preempted; cycle 4 computed 3 ms on the
    CPU (a collection) -> cycle 5's period 4 ms, cause compute. The maxima
    and the named parts (p99 over the window by numpy's linear rule) too."""
    stats = LoopStats(window=8)
    stats.add(0.001, 0.0002, late=0.0, cpu=0.0002)          # cycle 1
    stats.add(0.0035, 0.0002, late=0.0025, cpu=0.0002)      # cycle 2: woke late
    stats.add(0.001, 0.0024, late=0.0, cpu=0.0004)          # cycle 3: preempted 2 ms
    stats.add(0.0034, 0.003, late=0.0, cpu=0.003)           # cycle 4: slow compute
    stats.add(0.004, 0.0002, late=0.0001)                   # cycle 5 (cpu: all of it)
    for seconds in (0.0004, 0.0006):
        stats.add_part("physics", seconds)
    s = stats.summary()
    assert (s["over_2ms_woke_late"], s["over_2ms_preempted"], s["over_2ms_compute"]) == (1, 1, 1)
    assert s["periods_over_2ms"] == 3
    assert s["wake_late_max_ms"] == pytest.approx(2.5)
    assert s["compute_max_ms"] == pytest.approx(3.0)
    assert s["preempted_max_ms"] == pytest.approx(2.0)
    assert s["physics_max_ms"] == pytest.approx(0.6)
    assert s["physics_p99_ms"] == pytest.approx(0.4 + 0.99 * 0.2)      # linear percentile


def test_a_period_that_is_not_positive_is_refused():
    for period in (0.0, -0.01):
        with pytest.raises(ValueError, match="period must be > 0"):
            ControlLoop(period, lambda: None)


def _run_until(loop, done: threading.Event, timeout: float = 30.0):
    loop.start()
    assert done.wait(timeout), "the loop did not run its cycles"


def test_the_loop_steps_until_stopped_and_stops_promptly():
    cycles = []
    done = threading.Event()

    def step():
        cycles.append(1)
        if len(cycles) == 20:
            done.set()

    loop = ControlLoop(0.002, step, name="test_loop")
    _run_until(loop, done)
    assert loop.running
    assert loop.stop() is True and not loop.running
    n = len(cycles)
    assert n >= 20
    # statistics: one period per cycle after the first
    assert loop.stats.count == n - 1


def test_an_error_the_owner_accepts_keeps_the_loop_running():
    errors, cycles = [], []
    done = threading.Event()

    def step():
        cycles.append(1)
        if len(cycles) == 3:
            raise RuntimeError("one bad cycle")
        if len(cycles) == 10:
            done.set()

    loop = ControlLoop(0.002, step, on_error=lambda exc: errors.append(exc) or True)
    _run_until(loop, done)
    loop.stop()
    assert len(cycles) >= 10
    assert [str(e) for e in errors] == ["one bad cycle"]


@pytest.mark.parametrize("handler", [None, lambda exc: False])
def test_an_error_the_owner_refuses_or_does_not_handle_ends_the_loop(handler):
    cycles = []

    def step():
        cycles.append(1)
        raise RuntimeError("broken")

    loop = ControlLoop(0.002, step, on_error=handler)
    loop.start()
    deadline = time.monotonic() + 30.0
    while loop.running and time.monotonic() < deadline:
        time.sleep(0.01)                          # poll: the loop ends by itself
    assert not loop.running
    assert cycles == [1]
    assert loop.stop() is True


def test_a_stalled_cycle_counts_as_an_overrun():
    cycles = []
    done = threading.Event()
    release = threading.Event()

    def step():
        cycles.append(1)
        if len(cycles) == 5:
            release.wait(0.2)             # stall: 0.2 s = 100 periods of 2 ms
        if len(cycles) == 10:
            done.set()

    loop = ControlLoop(0.002, step)
    _run_until(loop, done)
    loop.stop()
    assert loop.stats.overruns >= 1
    assert loop.stats.max_period >= 0.2


def test_loop_stats_window_default_and_partial_window_and_zero_periods():
    """By hand: the default window holds 2000 cycles (cycle 2001 overwrites
    the first); a window not yet full averages only the cycles seen; no
    overrun before one is counted; a window of zero periods (a clock that
    did not move) reports 0 Hz, not inf."""
    stats = LoopStats()
    assert stats.summary()["overruns"] == 0
    stats.add(1.0, 0.0)                      # one slow cycle, then 2000 of 5 ms
    for _ in range(2000):
        stats.add(0.005, 0.0)
    s = stats.summary()
    assert s["rate_hz"] == pytest.approx(200.0)           # the 1 s cycle left the window
    assert s["period_window_max_ms"] == pytest.approx(5.0)
    assert s["period_max_ms"] == pytest.approx(1000.0)   # ... but not the maximum since start
    assert s["overruns"] == 0
    partial = LoopStats(window=10)
    partial.add(0.004, 0.0)
    partial.add(0.006, 0.0)
    assert partial.summary()["rate_hz"] == pytest.approx(200.0)   # mean 5 ms of 2 cycles
    still = LoopStats(window=3)
    still.add(0.0, 0.0)
    assert still.summary()["rate_hz"] == 0.0


def test_boundaries_and_counts_of_the_long_period_causes():
    """By hand: "over 2 ms" means longer than 2 ms (a period of exactly
    2 ms is on time); the first cycle has no previous cycle, so a long first
    period can only be put down to its own lateness; each long period adds
    one to its cause (two late wake-ups: 2); a cycle added without its
    lateness woke on time (late 0). The wake-up lateness p99 over the
    window by numpy's linear rule: of (0, 1.5, 2.5) ms, 1.5 + 0.98 * 1."""
    stats = LoopStats(window=3)
    stats.add(0.003, 0.0001, late=0.0015, cpu=0.0001)   # first: no previous compute
    assert stats.over_2ms_causes == {"woke_late": 1, "compute": 0, "preempted": 0}
    stats.add(0.002, 0.0001)                             # exactly 2 ms: not over
    assert stats.over_2ms == 1                            # the first one only
    stats.add(0.0035, 0.0001, late=0.0025)
    s = stats.summary()
    assert (s["over_2ms_woke_late"], s["over_2ms_compute"], s["over_2ms_preempted"]) == (2, 0, 0)
    assert s["periods_over_2ms"] == 2
    assert s["wake_late_max_ms"] == pytest.approx(2.5)
    assert s["wake_late_p99_ms"] == pytest.approx(1.5 + 0.98 * 1.0)
    on_time = LoopStats()
    on_time.add(0.001, 0.0002)
    assert on_time.summary()["wake_late_max_ms"] == 0.0


def test_the_slowest_cycle_is_kept_with_its_parts_and_page_faults():
    """By hand: cycle 2 (compute 1.2 ms, its parts physics 0.3 and controller
    0.8 ms, 12 page faults) is the slowest of three. Cycle 3 is faster and
    does not replace it, though its controller part (0.9 ms) is the largest
    since start. Faults are counted over all cycles: 12 + 3 in two cycles.
    A discarded cycle's parts (the loop's first, which has no period) are in
    no record."""
    stats = LoopStats(window=8)
    stats.add_part("controller", 0.005)            # a first cycle's part
    stats.discard_cycle()
    stats.add_part("physics", 0.0002)
    stats.add_part("controller", 0.0004)
    stats.add(0.001, 0.0007, cpu=0.0007)                        # cycle 1
    stats.add_part("physics", 0.0003)
    stats.add_part("controller", 0.0008)
    stats.add(0.001, 0.0012, cpu=0.0011, faults=12)             # cycle 2: the slowest
    stats.add_part("controller", 0.0009)
    stats.add(0.0012, 0.001, cpu=0.001, faults=3)               # cycle 3
    s = stats.summary()
    assert s["compute_max_ms"] == pytest.approx(1.2)
    assert (s["slowest_cycle"], s["slowest_page_faults"]) == (2, 12)
    assert s["slowest_cpu_ms"] == pytest.approx(1.1)
    assert s["slowest_physics_ms"] == pytest.approx(0.3)
    assert s["slowest_controller_ms"] == pytest.approx(0.8)
    assert s["controller_max_ms"] == pytest.approx(5.0)      # parts_max: all add_part calls
    assert (s["page_faults"], s["page_fault_cycles"]) == (15, 2)


def test_the_loop_counts_the_page_faults_a_cycle_takes():
    """A cycle that maps 256 fresh pages and writes one byte to each takes
    at least 256 minor page faults (one per page, first touch), and the
    loop's statistics count them."""
    import mmap
    done = threading.Event()
    cycles = []
    pages = 256

    def step():
        cycles.append(1)
        if len(cycles) == 5:
            block = mmap.mmap(-1, pages * mmap.PAGESIZE)
            for k in range(pages):
                block[k * mmap.PAGESIZE] = 1
            block.close()
        if len(cycles) == 8:
            done.set()

    loop = ControlLoop(0.002, step, name="test_faults")
    _run_until(loop, done)
    loop.stop()
    assert loop.stats.page_faults >= pages
    assert loop.stats.fault_cycles >= 1


def test_loop_parameters_defaults_and_ranges():
    """The loop's parameters as the README tables give them: a loop process
    of its own with real-time priority by default, SCHED_FIFO priorities
    1-98, a 2 s watchdog within 0.01-60 s, and a 0.1 ms slice on the normal
    scheduler within 0-0.1 s (0: the kernel's own; the kernel takes 0.1-100 ms)."""
    from holonomic_core.loop import LOOP_SPECS
    from holonomic_core.realtime import DEFAULT_PRIORITY
    from holonomic_core.schema import ConfigError, validate

    defaults = validate(LOOP_SPECS, {})
    assert defaults == {"loop.process": True, "loop.realtime": True,
                        "loop.priority": DEFAULT_PRIORITY, "loop.watchdog_timeout": 2.0,
                        "loop.slice": 1e-4}
    for key, good, bad in (("loop.priority", (1, 98), (0, 99)),
                           ("loop.watchdog_timeout", (0.01, 60.0), (0.005, 60.5)),
                           ("loop.slice", (0.0, 0.1), (-1e-6, 0.11))):
        for value in good:
            assert validate(LOOP_SPECS, {key: value})[key] == value
        for value in bad:
            with pytest.raises(ConfigError):
                validate(LOOP_SPECS, {key: value})


def test_stop_before_start_and_from_inside_a_cycle():
    """stop() on a loop never started is a no-op that reports stopped; a
    step may stop its own loop (no join of the loop's own thread): the loop
    ends after that cycle."""
    idle = ControlLoop(0.002, lambda: None)
    assert idle.stop() is True and not idle.running
    cycles = []
    results = []

    def step():
        cycles.append(1)
        if len(cycles) == 3:
            results.append(loop.stop())

    loop = ControlLoop(0.002, step)
    loop.start()
    deadline = time.monotonic() + 30.0
    while loop.running and time.monotonic() < deadline:
        time.sleep(0.01)                          # poll: the loop ends by itself
    assert not loop.running
    assert cycles == [1, 1, 1]
    # from inside, the thread is still alive when stop() returns
    assert results == [False]


def test_the_loop_thread_does_not_keep_a_process_alive():
    """The loop runs in a daemon thread: a program that returns without
    stopping its loop (e.g. after an exception) exits instead of hanging."""
    loop = ControlLoop(0.01, lambda: None, name="test_loop_daemon")
    loop.start()
    try:
        threads = [t for t in threading.enumerate() if t.name == "test_loop_daemon"]
        assert len(threads) == 1 and threads[0].daemon
    finally:
        loop.stop()


class _SimulatedTime:
    """The loop's clocks and sleep, simulated: ``perf_counter`` [s] moves
    only when a step computes or the loop sleeps; ``thread_time`` [s] moves
    by the CPU share of each step. A sleep (``Event.wait``) ends exactly at
    the deadline (the timeout plus the loop's 0.2 ms busy-wait tail) plus
    any oversleep scripted for it. A clock read that never moves time on
    (a busy-wait past the deadline) ends the run with an error instead of
    spinning forever."""

    def __init__(self, spin, oversleep):
        self.now = 0.0
        self.cpu = 0.0
        self.spin = spin
        self.oversleep = list(oversleep)
        self.reads = 0
        sim = self

        class Event:
            def __init__(self):
                self.flag = False

            def set(self):
                self.flag = True

            def is_set(self):
                return self.flag

            def wait(self, timeout):
                sim.now += timeout + sim.spin + (sim.oversleep.pop(0) if sim.oversleep else 0.0)
                sim.reads = 0
                return self.flag

        self.Event = Event
        self.Thread = threading.Thread
        self.current_thread = threading.current_thread

    def perf_counter(self):
        self.reads += 1
        if self.reads > 1000:
            raise RuntimeError("busy-waiting on a clock that does not move")
        return self.now

    def thread_time(self):
        return self.cpu

    def compute(self, wall, cpu):
        self.now += wall
        self.cpu += cpu
        self.reads = 0


def test_the_cycle_timing_on_simulated_clocks(monkeypatch):
    """The pacing by hand, period 10 ms, deadlines t0 + k T from t0 = 0:
    cycle 1 computes 1 ms and sleeps to 10 ms; cycle 2 computes 25 ms
    (15 ms past its 20 ms deadline: more than a period, an overrun, the
    deadlines re-anchor to 35 ms); cycle 3 starts at once (period 25 ms),
    computes 1 ms (0.5 ms of it on the CPU: preempted 0.5 ms) and sleeps to
    45 ms but wakes 3 ms late (period 13 ms, late 3 ms); cycle 4 computes
    21 ms (ends at 69 ms, 14 ms past 55 ms: the second overrun); cycle 5
    starts at once (period 21 ms) and stops the loop."""
    import holonomic_core.loop as loop_module

    sim = _SimulatedTime(spin=2e-4, oversleep=[0.0, 0.003])
    monkeypatch.setattr(loop_module, "time", sim)
    monkeypatch.setattr(loop_module, "threading", sim)
    script = [(0.001, 0.001), (0.025, 0.025), (0.001, 0.0005), (0.021, 0.021), (0.001, 0.001)]
    starts = []

    def step():
        starts.append(sim.now)
        wall, cpu = script[len(starts) - 1]
        sim.compute(wall, cpu)
        if len(starts) == len(script):
            loop.stop()

    loop = ControlLoop(0.01, step)
    loop.run()
    np.testing.assert_allclose(starts, [0.0, 0.01, 0.035, 0.048, 0.069], atol=1e-12)
    stats = loop.stats
    assert stats.count == 4 and stats.overruns == 2
    np.testing.assert_allclose(stats.periods[:4], [0.01, 0.025, 0.013, 0.021], atol=1e-12)
    np.testing.assert_allclose(stats.compute[:4], [0.025, 0.001, 0.021, 0.001], atol=1e-12)
    np.testing.assert_allclose(stats.late[:4], [0.0, 0.0, 0.003, 0.0], atol=1e-12)
    assert stats.max_preempted == pytest.approx(0.0005, abs=1e-12)
