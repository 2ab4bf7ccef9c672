"""The progress display of long work: a tqdm bar on a terminal, plain lines in a log."""

from __future__ import annotations

import fcntl
import io
import os
import re
import select
import struct
import sys
import termios
import tty

from holonomic_core.progress import (BarProgress, LineProgress, duration_text, progress)


def open_terminal():
    """A pseudo-terminal of 100 columns: (master fd, the terminal's writable
    file); raw, so what the program writes arrives unchanged."""
    master, slave = os.openpty()
    tty.setraw(slave)
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))
    return master, os.fdopen(slave, "w")


def read_terminal(master: int) -> str:
    """Everything written to the terminal so far: the kernel passes it to the
    master side in pieces, so read until nothing more comes for 0.5 s."""
    chunks = []
    while select.select([master], [], [], 0.5)[0]:
        chunk = os.read(master, 65536)
        if not chunk:
            break
        chunks.append(chunk)
    return b"".join(chunks).decode()


class FakeClock:
    """Monotonic time [s] the test moves by hand."""

    def __init__(self):
        self.now = 100.0

    def __call__(self) -> float:
        return self.now


def test_a_log_gets_a_plain_line_per_step_with_the_time_left():
    log, clock = io.StringIO(), FakeClock()
    bar = LineProgress(4, "experiment", "runs", stream=log, clock=clock)
    for _ in range(4):
        clock.now += 10.0            # each run takes 10 s
        bar.advance()
    # after k runs: 10 k s elapsed, (4 - k) runs left at 10 s a run
    assert log.getvalue().splitlines() == [
        "experiment: 1/4 runs (25 %), 10 s elapsed, about 30 s left",
        "experiment: 2/4 runs (50 %), 20 s elapsed, about 20 s left",
        "experiment: 3/4 runs (75 %), 30 s elapsed, about 10 s left",
        "experiment: 4/4 runs (100 %), 40 s elapsed, done",
    ]
    assert "\r" not in log.getvalue()


def test_a_long_log_gets_a_line_every_five_percent():
    log, clock = io.StringIO(), FakeClock()
    with LineProgress(200, "mutation", "mutants", stream=log, clock=clock) as bar:
        for _ in bar.over(range(200)):
            clock.now += 3.0
    lines = log.getvalue().splitlines()
    # 5 % of 200 = every 10 mutants: 10, 20, ..., 190 with the time left, 200 done
    assert len(lines) == 20
    assert lines[0] == "mutation: 10/200 mutants (5 %), 30 s elapsed, about 9 min 30 s left"
    assert lines[-1] == "mutation: 200/200 mutants (100 %), 10 min 0 s elapsed, done"


def test_skipped_steps_shorten_the_time_left():
    log, clock = io.StringIO(), FakeClock()
    bar = LineProgress(10, "experiment", "runs", stream=log, clock=clock)
    clock.now += 60.0
    bar.advance()                    # 1 run in 60 s: 9 runs left, 9 min
    bar.skip(4)                      # 4 of them cannot run: 6 runs in all
    clock.now += 60.0
    bar.advance()                    # 2 runs in 120 s: 4 left at 60 s, 4 min
    bar.skip(4)                      # the rest cannot run either: done
    assert log.getvalue().splitlines() == [
        "experiment: 1/10 runs (10 %), 1 min 0 s elapsed, about 9 min 0 s left",
        "experiment: 2/6 runs (33 %), 2 min 0 s elapsed, about 4 min 0 s left",
        "experiment: 2/2 runs (100 %), 2 min 0 s elapsed, done",
    ]


def test_durations_read_as_seconds_minutes_and_hours():
    assert duration_text(42.4) == "42 s"
    assert duration_text(238.0) == "3 min 58 s"
    assert duration_text(3900.0) == "1 h 05 min"


def test_a_file_or_pipe_gets_plain_lines_and_a_terminal_a_tqdm_bar():
    assert isinstance(progress(3, "x", stream=io.StringIO()), LineProgress)
    master, terminal = open_terminal()
    try:
        bar = progress(2, "calibration", "runs", stream=terminal)
        assert isinstance(bar, BarProgress)
        bar.advance()
        bar.write("seed 1: done")
        bar.advance()
        bar.close()
        terminal.flush()
        shown = read_terminal(master)
    finally:
        terminal.close()
        os.close(master)
    # tqdm redraws in place ("\r") and shows the count and its elapsed<left time
    # (their values depend on how fast a loaded machine gets here)
    assert "\rcalibration:  50%|" in shown, shown
    assert re.search(r"\| 1/2 \[\d\d:\d\d<\d\d:\d\d", shown), shown
    assert "\rcalibration: 100%|" in shown
    assert "seed 1: done\n" in shown


def test_prints_to_stderr_go_above_the_bar_and_stderr_is_restored(monkeypatch):
    master, terminal = open_terminal()
    monkeypatch.setattr(sys, "stderr", terminal)
    try:
        with progress(1, "bench") as bar:
            assert sys.stderr is not terminal    # a line at a time through tqdm
            print("bench: memory ...", file=sys.stderr)
            bar.advance()
        assert sys.stderr is terminal
        terminal.flush()
        shown = read_terminal(master)
    finally:
        terminal.close()
        os.close(master)
    assert "bench: memory ..." in shown
