"""Mutation testing of the ROS-free core with its fast unit tests (make mutation).

For each module below, mutmut 2 changes one thing at a time (an operator, a
number, a name, a keyword...) and runs the module's fast unit tests; a mutant
the tests do not notice "survives". The run happens in a scratch copy of
config/ and src/ (with the packages' test/ folders; mutmut edits the file it
mutates in place), so the working tree is never left mutated, even when the
run is interrupted.

Mutations of plain string literals are off: mutmut turns "text" into
"XXtextXX", and in these modules such literals are mostly messages that the
tests check by substring, or keys and names whose mutation fails with a
KeyError anyway. (f-strings are still mutated.)

Usage (from the repository, with ros2_ws/env.sh sourced; `make mutation`):
    python scripts/mutation.py [--budget MINUTES] [MODULE ...]   # default: every module
Prints a table of killed / survived / timed out per module and writes the
diff of every surviving mutant to out/mutation/<module>.txt.
"""

from __future__ import annotations

import argparse
import os
import shutil
import signal
import sqlite3
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
#: the hypothesis tests of test_hostile_commands.py take minutes per run: not "fast"
SLOW = ("not test_any_sequence_of_commands_stays_within_limits and "
        "not test_any_single_command_is_safe_and_keeps_its_direction and "
        "not test_malformed_commands_are_rejected_without_an_exception")
#: module -> (file, pytest arguments: the fast unit tests that own it)
MODULES = {
    "offset_turret": ("src/hamr_base/hamr_base/offset_turret.py",
                      ["src/hamr_base/test/test_offset_turret.py"]),
    "powered_caster": ("src/pcv_base/pcv_base/powered_caster.py",
                       ["src/pcv_base/test/test_powered_caster.py"]),
    "pcv_estimators": ("src/pcv_base/pcv_base/estimators.py",
                       ["src/pcv_base/test/test_powered_caster.py"]),
    "limits": ("src/holonomic_core/holonomic_core/limits.py",
               ["src/holonomic_core/test/test_limits_odometry.py",
                "src/holonomic_core/test/test_controller_core.py",
                "src/holonomic_core/test/test_hostile_commands.py", "-k", SLOW]),
    "odometry": ("src/holonomic_core/holonomic_core/odometry.py",
                 ["src/holonomic_core/test/test_limits_odometry.py",
                  "src/holonomic_core/test/test_controller_core.py"]),
    "monitor": ("src/holonomic_core/holonomic_core/monitor.py",
                ["src/holonomic_core/test/test_reading_monitor.py"]),
    "loop": ("src/holonomic_core/holonomic_core/loop.py",
             ["src/holonomic_core/test/test_control_loop.py"]),
    "controller": ("src/holonomic_core/holonomic_core/controller.py",
                   ["src/holonomic_core/test/test_controller_core.py",
                    "src/holonomic_core/test/test_reading_monitor.py",
                    "src/holonomic_core/test/test_hostile_commands.py", "-k", SLOW]),
    "odrive_protocol": ("src/holonomic_drivers/holonomic_drivers/odrive_protocol.py",
                        ["src/holonomic_drivers/test/test_can_protocols.py"]),
    "cia402_protocol": ("src/holonomic_drivers/holonomic_drivers/cia402_protocol.py",
                        ["src/holonomic_drivers/test/test_can_protocols.py"]),
}
STATUS = {"ok_killed": "killed", "bad_survived": "survived", "bad_timeout": "timeout",
          "ok_suspicious": "suspicious", "skipped": "skipped", "untested": "untested"}


def scratch_copy() -> Path:
    """config/, src/ (the packages and their test/ folders) and pytest.ini in a fresh folder."""
    work = Path(tempfile.mkdtemp(prefix="holonomic_mutation_"))
    for name in ("config", "src"):
        shutil.copytree(ROOT / name, work / name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc"))
    shutil.copy(ROOT / "pytest.ini", work / "pytest.ini")
    return work


#: [s] without a new result, a mutmut run is taken as hung and stopped
STALL = 240.0


def _tested(cache: Path) -> int:
    """Mutants with a result so far (0 before mutmut has written its cache)."""
    if not cache.exists():
        return 0
    try:
        with sqlite3.connect(cache, timeout=1.0) as db:
            return db.execute("SELECT COUNT(*) FROM Mutant WHERE status != 'untested'"
                              ).fetchone()[0]
    except sqlite3.Error:
        return -1


def run_module(work: Path, name: str, out: Path, budget: float | None) -> dict[str, int]:
    path, tests = MODULES[name]
    cache = work / ".mutmut-cache"
    cache.unlink(missing_ok=True)
    # mutmut 2 counts only exit code 1 as "killed"; pytest exits 2 when a
    # mutant breaks the import (collection error): any failure is a kill
    pytest = " ".join([sys.executable, "-m", "pytest", "-x", "-q", "-p", "no:cacheprovider",
                       *(f"'{t}'" if " " in t else t for t in tests)])
    runner = f'sh -c "{pytest} || exit 1"'       # (mutmut splits it for the baseline run)
    env = dict(os.environ)
    # the scratch copy's packages first (the workspace's would be the unmutated ones)
    packages = [str(p) for p in sorted((work / "src").iterdir()) if (p / p.name).is_dir()]
    env["PYTHONPATH"] = os.pathsep.join(packages + [env.get("PYTHONPATH", "")])
    env["HOLONOMIC_CONFIG_PATH"] = str(work / "config")
    cmd = [sys.executable, "-m", "mutmut", "run", "--paths-to-mutate", path,
           "--runner", runner, "--tests-dir", str(Path(tests[0]).parent),
           "--disable-mutation-types", "string",
           "--simple-output", "--no-progress", "-b", "20"]
    started = time.monotonic()
    log = open(out / f"{name}.log", "w")
    # mutmut 2 can hang when its test worker dies (seen on an overloaded
    # machine): a run without a new result for STALL seconds is stopped and
    # started again (it resumes from its cache). A run may also have to end
    # by a deadline (budget): the mutants not run yet are reported as such.
    while True:
        # its own process group: stopping it stops its test worker and pytest too
        proc = subprocess.Popen(cmd, cwd=work, env=env, stdout=log, stderr=subprocess.STDOUT,
                                start_new_session=True)
        last_change, last_done, stalled = time.monotonic(), -1, False
        over_budget = False
        while proc.poll() is None:
            time.sleep(5.0)
            done = _tested(cache)
            if done != last_done:
                last_change, last_done = time.monotonic(), done
            over_budget = budget is not None and time.monotonic() - started > budget
            stalled = time.monotonic() - last_change > STALL
            if over_budget or stalled:
                os.killpg(proc.pid, signal.SIGTERM)
                proc.wait()
        if not stalled or over_budget:
            break
    log.close()
    rows = []
    if cache.exists():
        with sqlite3.connect(cache) as db:
            rows = db.execute("SELECT Mutant.id, Mutant.status FROM Mutant").fetchall()
    if not rows:
        raise SystemExit(f"mutation: mutmut failed on {name} (see {out / name}.log)")
    counts = {v: 0 for v in STATUS.values()}
    for _, status in rows:
        counts[STATUS[status]] += 1
    survivors = [mid for mid, status in rows if status == "bad_survived"]
    with open(out / f"{name}.txt", "w") as handle:
        handle.write(f"{name}: {path}\n{counts}\n\n")
        for mid in survivors:
            shown = subprocess.run([sys.executable, "-m", "mutmut", "show", str(mid)], cwd=work,
                                   env=env, capture_output=True, text=True)
            handle.write(f"--- mutant {mid}\n{shown.stdout}\n")
    counts["seconds"] = round(time.monotonic() - started)
    return counts


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("modules", nargs="*", default=list(MODULES),
                        help=f"some of {', '.join(MODULES)}")
    parser.add_argument("--budget", type=float, default=None, metavar="MINUTES",
                        help="stop each module after this long (the rest: not run)")
    args = parser.parse_args(argv)
    unknown = [m for m in args.modules if m not in MODULES]
    if unknown:
        print(f"mutation: unknown module(s) {unknown}; choose from {list(MODULES)}",
              file=sys.stderr)
        return 2
    out = ROOT / "out" / "mutation"
    out.mkdir(parents=True, exist_ok=True)
    work = scratch_copy()
    # killed: a test failed ("suspicious": failed, but slowly); timeout: the
    # tests hung (a mutant that loops forever); not run: interrupted
    print(f"{'module':<16} {'mutants':>7} {'killed':>6} {'timeout':>7} {'survived':>8} "
          f"{'not run':>7} {'score':>6} {'time':>6}")
    try:
        for name in args.modules:
            budget = None if args.budget is None else 60.0 * args.budget
            c = run_module(work, name, out, budget)
            caught = c["killed"] + c["suspicious"] + c["timeout"]
            tested = caught + c["survived"]
            score = 100.0 * caught / tested if tested else 100.0
            print(f"{name:<16} {tested + c['untested'] + c['skipped']:>7} "
                  f"{c['killed'] + c['suspicious']:>6} {c['timeout']:>7} {c['survived']:>8} "
                  f"{c['untested'] + c['skipped']:>7} {score:>5.1f}% {c['seconds']:>5}s",
                  flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"surviving mutants: {out}/<module>.txt")
    return 0


if __name__ == "__main__":
    sys.exit(main())
