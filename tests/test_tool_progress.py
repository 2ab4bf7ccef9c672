"""The long tools show their progress: in a log (stderr not a terminal), plain
lines with the steps done and the time left, never a redrawn bar; their
results on stdout unchanged. `make bench` (bench/run.py) and `make mutation`
(scripts/mutation.py) at unit level: a tiny workload through the code that
counts their steps."""

from __future__ import annotations

import importlib.util
import re
import subprocess
import sys
from pathlib import Path

from holonomic_core.progress import progress

ROOT = Path(__file__).resolve().parents[1]


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


def test_mutation_logs_the_mutants_the_worker_reports_with_the_time_left(tmp_path, capsys):
    mutation = load_script("mutation_script", ROOT / "scripts" / "mutation.py")
    results = tmp_path / "results.jsonl"
    # a stand-in worker: three mutants, one result line each, 0.2 s apart
    worker = subprocess.Popen(
        [sys.executable, "-c",
         "import sys, time\n"
         "for k in range(3):\n"
         "    time.sleep(0.2)\n"
         "    with open(sys.argv[1], 'a') as out:\n"
         "        out.write('{\"id\": %d, \"status\": \"killed\"}\\n' % k)\n", str(results)],
        start_new_session=True)
    with progress(4, "mutation limits", "mutants") as bar:
        mutation.wait_worker(worker, results, bar, deadline=None, poll=0.05)
    assert worker.returncode == 0
    lines = capsys.readouterr().err.splitlines()
    for k, line in enumerate(lines[:3], 1):
        assert re.fullmatch(rf"mutation limits: {k}/4 mutants \({25 * k} %\), \d+ s elapsed, "
                            r"about \d+ s left", line), lines
    # the worker ended before the fourth (e.g. stopped by --budget): the display ends
    assert re.fullmatch(r"mutation limits: 3/3 mutants \(100 %\), \d+ s elapsed, done",
                        lines[3]), lines
    assert len(lines) == 4
