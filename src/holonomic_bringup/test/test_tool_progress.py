"""The long tools show their progress: in a log (stderr not a terminal), plain
lines with the steps done and the time left, never a redrawn bar; their
results on stdout unchanged. `make bench` (bench/run.py) at unit level: a
tiny workload through the code that counts its steps."""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[3]


def load_script(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_bench_logs_each_benchmark_then_the_benchmarks_done_and_the_time_left(capsys):
    bench = load_script("bench_run", ROOT / "bench" / "run.py")
    with bench.bench_progress(2) as bar:
        step = bench.stepper(bar)
        assert step("cycle compute hamr", lambda cycles: {"cycles": cycles}, 10) == {"cycles": 10}
        assert step("fleet", lambda: [1, 2]) == [1, 2]
    captured = capsys.readouterr()
    assert captured.out == ""
    assert "\r" not in captured.err
    assert captured.err.splitlines() == [
        "bench: cycle compute hamr ...",
        'bench: cycle compute hamr: {"cycles": 10} (0 s)',
        "bench: 1/2 benchmarks (50 %), 0 s elapsed, about 0 s left",
        "bench: fleet ...",
        "bench: fleet: [1, 2] (0 s)",
        "bench: 2/2 benchmarks (100 %), 0 s elapsed, done",
    ]


def test_bench_counts_every_benchmark_of_a_run():
    bench = load_script("bench_run", ROOT / "bench" / "run.py")
    names = []

    def step(name, fn, *a, **kw):            # counts, runs nothing
        names.append(name)
        return {}

    bench.compute_rows(step, True)
    assert len(names) == bench.STEPS["compute"]
    bench.sim_rows(step, True)
    bench.sim_drive_rows(step, True)
    assert len(names) == bench.STEPS["compute"] + bench.STEPS["sim"]
    bench.loop_rows(step, True, init=False)
    assert len(names) == bench.STEPS["compute"] + bench.STEPS["sim"] + bench.STEPS["loop"]
    # the whole run: these, the fleet, the memory and the Foxglove bridge
    assert bench.STEPS_ALL == len(names) + 3
