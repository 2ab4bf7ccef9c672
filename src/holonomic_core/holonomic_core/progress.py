"""Progress of long work (experiments, calibrations, benchmarks) on stderr.

On a terminal, a tqdm bar redrawn in place, with the steps done, the rate and
the time left. In a log (stderr a file or a pipe: ``make bench > log 2>&1``,
CI) a redrawn bar would leave carriage returns and hundreds of partial lines,
so the work reports plain lines instead, one each time it completes another
:data:`LINE_EVERY` percent of the steps (so every step of twenty or fewer)::

    holonomic-odometry-experiment: 3/20 runs (15 %), 42 s elapsed, about 3 min 58 s left

The time left is the mean time per step so far times the steps still to do.
The work's own messages (:meth:`Progress.write`, or a plain ``print`` to
stderr or to a terminal's stdout while the bar is shown) appear above the bar
on a terminal, as they are in a log.

Usage::

    with progress(len(runs), "holonomic-odometry-experiment", unit="runs") as bar:
        for run in bar.over(runs):
            ...
            bar.write(f"{run}: done")
"""

from __future__ import annotations

import sys
import time
from typing import Callable, Iterable, Iterator, TextIO

#: [%] a log gets a line each time this much more of the work is done
LINE_EVERY = 5


def duration_text(seconds: float) -> str:
    """``seconds`` [s] as a person reads it: ``42 s``, ``3 min 58 s``, ``1 h 05 min``."""
    whole = max(0, int(round(seconds)))
    if whole < 60:
        return f"{whole} s"
    if whole < 3600:
        return f"{whole // 60} min {whole % 60} s"
    return f"{whole // 3600} h {whole % 3600 // 60:02d} min"


class Progress:
    """Progress of ``total`` steps of work named ``label`` (a program's name
    or what it does), counted in ``unit``. A context manager; subclasses
    show it (:class:`LineProgress`, :class:`BarProgress`)."""

    def __init__(self, total: int, label: str, unit: str = "steps",
                 stream: TextIO | None = None):
        self.total = int(total)
        self.done = 0
        self.label = label
        self.unit = unit
        self.stream = sys.stderr if stream is None else stream

    def advance(self, steps: int = 1) -> None:
        """``steps`` more steps are done."""
        self.done += steps

    def skip(self, steps: int) -> None:
        """``steps`` of the planned steps will not run (e.g. a condition a
        robot cannot have): the total shrinks, the time left with it."""
        self.total = max(self.done, self.total - steps)

    def write(self, line: str) -> None:
        """Print one message line of the work without breaking the progress display."""
        print(line, file=self.stream, flush=True)

    def over(self, items: Iterable) -> Iterator:
        """Yield ``items``, one step done each time the loop body for an item ends."""
        for item in items:
            yield item
            self.advance()

    def close(self) -> None:
        """End the display (nothing to end in a log)."""

    def __enter__(self) -> "Progress":
        return self

    def __exit__(self, *exc) -> None:
        self.close()


class LineProgress(Progress):
    """Plain lines for a log: ``label: done/total unit (percent), elapsed,
    time left`` each time another :data:`LINE_EVERY` percent is done, and
    a last line with the whole time. ``clock`` [s]: monotonic time."""

    def __init__(self, total: int, label: str, unit: str = "steps",
                 stream: TextIO | None = None, clock: Callable[[], float] = time.monotonic):
        super().__init__(total, label, unit, stream)
        self._clock = clock
        self._started = clock()
        self._reported = 0          # the last LINE_EVERY-percent mark printed
        self._finished = False

    def advance(self, steps: int = 1) -> None:
        super().advance(steps)
        self._report()

    def skip(self, steps: int) -> None:
        super().skip(steps)
        if self.done >= self.total:
            self._report()           # the last steps were the skipped ones

    def _report(self) -> None:
        if self.total <= 0 or self._finished:
            return
        elapsed = self._clock() - self._started
        head = (f"{self.label}: {self.done}/{self.total} {self.unit} "
                f"({100 * self.done // self.total} %), {duration_text(elapsed)} elapsed")
        if self.done >= self.total:
            self._finished = True
            self.write(f"{head}, done")
            return
        mark = self.done * 100 // (self.total * LINE_EVERY)
        if mark > self._reported:
            self._reported = mark
            left = elapsed / self.done * (self.total - self.done)
            self.write(f"{head}, about {duration_text(left)} left")


class BarProgress(Progress):
    """A tqdm bar on a terminal (steps, rate, elapsed and time left).

    While it is shown, what the program prints to ``sys.stderr`` (when that is
    the bar's stream) and to ``sys.stdout`` (when that is a terminal too)
    goes above the bar, a line at a time, instead of through it."""

    def __init__(self, total: int, label: str, unit: str = "steps",
                 stream: TextIO | None = None):
        from tqdm import tqdm
        from tqdm.contrib import DummyTqdmFile

        super().__init__(total, label, unit, stream)
        self._bar = tqdm(total=self.total, desc=label, unit=f" {unit}", file=self.stream,
                         dynamic_ncols=True, leave=True)
        self._redirected = []
        for name in ("stdout", "stderr"):
            original = getattr(sys, name)
            if original is self.stream or _is_terminal(original):
                setattr(sys, name, DummyTqdmFile(original))
                self._redirected.append((name, original))

    def advance(self, steps: int = 1) -> None:
        super().advance(steps)
        self._bar.update(steps)

    def skip(self, steps: int) -> None:
        super().skip(steps)
        self._bar.total = self.total
        self._bar.refresh()

    def write(self, line: str) -> None:
        self._bar.write(line, file=self.stream)

    def close(self) -> None:
        self._bar.close()
        for name, original in self._redirected:
            setattr(sys, name, original)
        self._redirected = []


def _is_terminal(stream) -> bool:
    try:
        return bool(stream.isatty())
    except (AttributeError, ValueError, OSError):    # no such method, or closed
        return False


def progress(total: int, label: str, unit: str = "steps",
             stream: TextIO | None = None) -> Progress:
    """The progress display for ``stream`` (default stderr): a tqdm bar when
    it is a terminal, plain lines (:class:`LineProgress`) otherwise."""
    stream = sys.stderr if stream is None else stream
    if _is_terminal(stream):
        return BarProgress(total, label, unit, stream)
    return LineProgress(total, label, unit, stream)
