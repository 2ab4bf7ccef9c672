"""Mutation testing of the ROS-free core with its fast unit tests (make mutation).

For each module below, mutmut 2's mutation generator changes one thing at a
time (an operator, a number, a name, a keyword...) and the module's fast unit
tests run against each change ("mutant"); a mutant the tests do not notice
"survives". The run happens in a scratch copy of config/ and src/ (with the
packages' test/ folders), so the working tree is never left mutated, even
when the run is interrupted.

Why not `mutmut run`: it starts a new Python and pytest for every mutant
(numpy, the ROS message modules the test plugin imports, collection) and runs
all the module's tests each time: a few mutants a minute on two shared
cores, hours for one module. This runner does the same
mutations and counts the same way, but

* runs only the tests that execute the mutated line: one pytest run under
  coverage with per-test contexts maps each line to the tests that run it (a
  line run at import -- module level, `def` lines with their defaults,
  decorators -- maps to all the module's tests; a line no test runs gives a
  survivor without running anything);
* forks each mutant's pytest from a worker that has already imported pytest,
  numpy, rclpy and the rest of the third-party stack (our own packages are
  imported afresh in each child, so the child sees the mutated file);
* stops at the first failing test (-x).

Mutations of string literals and f-strings are off: mutmut turns "text"
into "XXtextXX", and in these modules such literals are mostly messages that
the tests check by substring (which still matches), or keys and names whose
mutation fails with a KeyError anyway. The expressions inside an f-string
(a number a message reports) are still mutated.

Mutants that no behaviour can tell apart from the original ("equivalent") are
listed, each with its reason, in scripts/mutation_equivalent.yaml; the score
leaves them out: killed / (tested - equivalent).

Bugs written by hand (scripts/mutation_planted.yaml: the ones mutmut's
operators cannot make -- a lost abs(), two names swapped, a change of the C
twin) run with --planted: each is applied to the scratch copy, a bug in
_hot_path.c is compiled into the scratch copy's extension, and its tests run
on the path the bug lives on (HOLONOMIC_HOT_PATH and the hot_path_mode
fixture's HOLONOMIC_TEST_HOT_PATHS: compiled for the C file, pure otherwise).

Usage (from the repository, with ros2_ws/env.sh sourced; `make mutation`):
    python scripts/mutation.py [--budget MINUTES] [MODULE ...]   # default: every module
    python scripts/mutation.py --again MODULE ...   # after adding tests: the survivors only
    python scripts/mutation.py --planted [NAME ...]  # the planted bugs (default: all)
Prints a table per module, writes the diff of every surviving mutant to
out/mutation/<module>.txt and the killed ones to out/mutation/<module>.json
(what --again starts from). While a module's mutants run, its progress goes
to stderr (holonomic_core.progress): a bar with the time left on a terminal,
in a log a plain line with the mutants tested and the time left every 5 %.
"""

from __future__ import annotations

import argparse
import difflib
import hashlib
import json
import os
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
EQUIVALENT = Path(__file__).with_name("mutation_equivalent.yaml")
PLANTED = Path(__file__).with_name("mutation_planted.yaml")
#: the hypothesis tests of test_hostile_commands.py take minutes per run: not "fast"
SLOW = ("not test_any_sequence_of_commands_stays_within_limits and "
        "not test_any_single_command_is_safe_and_keeps_its_direction and "
        "not test_malformed_commands_are_rejected_without_an_exception")
CORE_TESTS = "src/holonomic_core/test/"
#: module -> (file, pytest arguments: the fast unit tests that can exercise it)
MODULES = {
    "offset_turret": ("src/hamr_base/hamr_base/offset_turret.py",
                      ["src/hamr_base/test/test_offset_turret.py"]),
    "powered_caster": ("src/pcv_base/pcv_base/powered_caster.py",
                       ["src/pcv_base/test/test_powered_caster.py",
                        "src/pcv_base/test/test_estimator_slip_models.py"]),
    "pcv_estimators": ("src/pcv_base/pcv_base/estimators.py",
                       ["src/pcv_base/test/test_powered_caster.py",
                        "src/pcv_base/test/test_estimator_slip_models.py"]),
    "limits": ("src/holonomic_core/holonomic_core/limits.py",
               [CORE_TESTS + "test_limits_odometry.py", CORE_TESTS + "test_controller_core.py",
                CORE_TESTS + "test_hostile_commands.py", "-k", SLOW]),
    "odometry": ("src/holonomic_core/holonomic_core/odometry.py",
                 [CORE_TESTS + "test_limits_odometry.py", CORE_TESTS + "test_odometry_latency.py",
                  CORE_TESTS + "test_controller_core.py"]),
    "monitor": ("src/holonomic_core/holonomic_core/monitor.py",
                [CORE_TESTS + "test_reading_monitor.py"]),
    "loop": ("src/holonomic_core/holonomic_core/loop.py",
             [CORE_TESTS + "test_control_loop.py"]),
    "controller": ("src/holonomic_core/holonomic_core/controller.py",
                   [CORE_TESTS + "test_controller_core.py",
                    CORE_TESTS + "test_controller_torque_mode.py",
                    CORE_TESTS + "test_reading_monitor.py", CORE_TESTS + "test_slip_monitor.py",
                    # (the other calibration tests fit recordings: a minute and a half)
                    CORE_TESTS + "test_calibration.py::"
                    "test_drift_watch_names_the_caster_and_the_parameter",
                    CORE_TESTS + "test_hostile_commands.py", "-k", SLOW]),
    "odrive_protocol": ("src/holonomic_drivers/holonomic_drivers/odrive_protocol.py",
                        ["src/holonomic_drivers/test/test_can_protocols.py"]),
    "cia402_protocol": ("src/holonomic_drivers/holonomic_drivers/cia402_protocol.py",
                        ["src/holonomic_drivers/test/test_can_protocols.py"]),
    "torque": ("src/holonomic_core/holonomic_core/torque.py",
               ["src/pcv_base/test/test_torque_control.py"]),
    "se2": ("src/holonomic_core/holonomic_core/se2.py", [CORE_TESTS + "test_se2.py"]),
}
#: pytest options of every run: quiet, no cache written into the scratch copy,
#: no reruns of flaky-marked tests (a failure is a kill)
PYTEST = ["-q", "-p", "no:cacheprovider", "-p", "no:rerunfailures"]
#: third-party modules the worker imports once, before forking (the test
#: plugin imports the ROS message modules; each costs a second or more to import)
PRELOAD = ("numpy", "pytest", "_pytest.python", "yaml", "hypothesis", "rclpy",
           "geometry_msgs.msg", "nav_msgs.msg", "diagnostic_msgs.msg", "std_srvs.srv",
           "sensor_msgs.msg", "can")


def scratch_copy() -> Path:
    """config/, src/ (the packages and their test/ folders) and pytest.ini in a fresh folder."""
    work = Path(tempfile.mkdtemp(prefix="holonomic_mutation_"))
    for name in ("config", "src"):
        shutil.copytree(ROOT / name, work / name,
                        ignore=shutil.ignore_patterns("__pycache__", "*.pyc", "*.so"))
    shutil.copy(ROOT / "pytest.ini", work / "pytest.ini")
    return work


def scratch_env(work: Path) -> dict[str, str]:
    env = dict(os.environ)
    # the scratch copy's packages first (the workspace's would be the unmutated ones)
    packages = [str(p) for p in sorted((work / "src").iterdir()) if (p / p.name).is_dir()]
    env["PYTHONPATH"] = os.pathsep.join(packages + [env.get("PYTHONPATH", "")])
    env["HOLONOMIC_CONFIG_PATH"] = str(work / "config")
    # The cycle's closed forms have a compiled twin (holonomic_core._hot_path,
    # docs/hot_path.md) that `auto` prefers when it is importable: a test run
    # on it never executes the mutated Python closed form, and the mutant
    # would survive falsely. The scratch copy leaves out *.so, but the
    # workspace's build could still be found, so the pure path is forced. The
    # C twin is checked separately: test_hot_path.py compares it with the pure
    # path, result by result.
    env["HOLONOMIC_HOT_PATH"] = "pure"
    # and the tests that run on both paths (holonomic_testing's hot_path_mode
    # fixture) run only their pure variant: the compiled one would not run
    # the mutated Python either (--planted builds the scratch copy's C twin
    # for a planted bug in it and runs the compiled variants)
    env["HOLONOMIC_TEST_HOT_PATHS"] = "pure"
    # no .pyc of a mutated file: a later mutant of the same size written in
    # the same second would otherwise load the earlier one's stale bytecode
    env["PYTHONDONTWRITEBYTECODE"] = "1"
    return env


# -- the mutants -------------------------------------------------------------

def mutants(source: str, filename: str) -> list[dict]:
    """Every mutant of source: line number (1-based), mutmut's id, the mutated source."""
    from types import SimpleNamespace

    import mutmut

    # mutmut reads only these two fields of its Config while mutating
    config = SimpleNamespace(covered_lines_by_filename=None,
                             mutation_types_to_apply=set(mutmut.mutations_by_type) - {"string", "fstring"})
    listing = mutmut.Context(source=source, filename=filename, config=config)
    found = []
    for mid in mutmut.list_mutations(listing):
        context = mutmut.Context(source=source, filename=filename, mutation_id=mid, config=config)
        mutated, _ = mutmut.mutate(context)
        lines = mutated.split("\n")
        line = lines[mid.line_number] if mid.line_number < len(lines) else ""
        # what a reader sees: the first line that differs (mutmut's own line
        # is the last line of a multi-line statement)
        old_lines, new_lines = source.split("\n"), mutated.split("\n")
        first = next(i for i, (a, b) in enumerate(zip(old_lines, new_lines)) if a != b)
        found.append({"line": mid.line_number + 1, "index": mid.index,
                      # (line, index, mutated): the key of a result in the record
                      "mutated": line.strip(), "source": mutated,
                      "shown": (old_lines[first - 1].strip() if first else "",
                                old_lines[first].strip(), new_lines[first].strip())})
    return found


def load_equivalent() -> dict[str, list[dict]]:
    import yaml

    by_module: dict[str, list[dict]] = {}
    for entry in yaml.safe_load(EQUIVALENT.read_text()) or []:
        by_module.setdefault(entry["module"], []).append(entry)
    return by_module


def is_equivalent(mutant: dict, listed: list[dict]) -> dict | None:
    for entry in listed:
        # "above": the line before it, where the line alone is ambiguous
        above, line, mutated = mutant["shown"]
        if entry["line"].strip() == line and entry["mutant"].strip() == mutated and \
                entry.get("above", above).strip() == above:
            return entry
    return None


# -- which tests run each line -----------------------------------------------

def line_tests(work: Path, env: dict, path: str, tests: list[str], log
               ) -> tuple[dict[int, set[str]], dict[str, float]]:
    """Line (1-based) -> node ids of the tests that execute it ("" for import
    time); and each test's duration [s] in the unmutated run."""
    from coverage import CoverageData
    from coverage.parser import PythonParser

    target = work / path
    data_file = work / ".coverage.mutation"
    data_file.unlink(missing_ok=True)
    run_env = dict(env, COVERAGE_FILE=str(data_file))
    junit = work / ".mutation-junit.xml"
    result = subprocess.run([sys.executable, "-m", "pytest", *PYTEST, f"--cov={target.parent}",
                             "--cov-context=test", "--cov-report=", f"--junitxml={junit}",
                             *tests], cwd=work, env=run_env, stdout=log, stderr=subprocess.STDOUT)
    if result.returncode != 0:
        raise SystemExit(f"mutation: the unmutated tests fail ({path}): see the log")
    data = CoverageData(basename=str(data_file))
    data.read()
    by_line: dict[int, set[str]] = {}
    for line, contexts in data.contexts_by_lineno(str(target)).items():
        # pytest-cov's contexts: "<node id>|setup", "|run", "|teardown"; "" = no test
        by_line[line] = {c.rsplit("|", 1)[0] for c in contexts}
    # coverage records a multi-line statement on its first line
    parser = PythonParser(filename=str(target))
    parser.parse_source()
    by_line = {line: by_line.get(parser.first_line(line), set())
               for line in range(1, target.read_text().count("\n") + 2)}
    return by_line, _durations(junit)


def _durations(junit: Path) -> dict[str, float]:
    """Node id -> seconds the test took in the unmutated run (from pytest's JUnit XML)."""
    import xml.etree.ElementTree as ET

    seconds = {}
    for case in ET.parse(junit).iter("testcase"):
        # classname "src.pkg.test.test_x" (+ ".Class"), name "test_y[param]"
        parts = case.get("classname", "").split(".")
        for split in range(len(parts), 0, -1):
            module = "/".join(parts[:split]) + ".py"
            rest = parts[split:]
            if (junit.parent / module).exists():
                seconds["::".join([module, *rest, case.get("name", "")])] = float(
                    case.get("time", 0.0))
                break
    return seconds


# -- the worker: fork one pytest per mutant -----------------------------------

def worker(job_file: str) -> int:
    """Run in the scratch copy: preload, then fork a pytest per mutant (json lines out)."""
    import importlib

    job = json.loads(Path(job_file).read_text())
    work = Path(job["work"])
    for name in PRELOAD:
        try:
            importlib.import_module(name)
        except ImportError:
            pass
    import pytest  # noqa: F401  (preloaded above; used in the child)

    target = work / job["path"]
    # src/<package>/<package>/<module>.py -> <package>.<module>
    module_name = ".".join(Path(job["path"]).with_suffix("").parts[2:])
    original = target.read_text()
    out = open(job["results"], "a")

    def run(source: str, tests: list[str], timeout: float) -> tuple[str, int, float]:
        target.write_text(source)
        started = time.monotonic()
        pid = os.fork()
        if pid == 0:                                # the child: one pytest run, no output
            try:
                devnull = os.open(os.devnull, os.O_WRONLY)
                os.dup2(devnull, 1)
                os.dup2(devnull, 2)
                try:
                    # a mutant that breaks the import is killed (given node
                    # ids, pytest would report that as "not found", exit 4)
                    importlib.import_module(module_name)
                except BaseException:
                    os._exit(2)
                code = pytest.main([*PYTEST, "-x", "-W", "ignore", *tests])
            except BaseException:
                code = 3
            os._exit(int(code))
        while True:
            done, status = os.waitpid(pid, os.WNOHANG)
            if done:
                break
            if time.monotonic() - started > timeout:
                os.kill(pid, signal.SIGKILL)
                os.waitpid(pid, 0)
                return "timeout", -9, time.monotonic() - started
            time.sleep(0.005)
        code = os.waitstatus_to_exitcode(status)
        # 1 tests failed, 2 collection error (the mutant broke the import),
        # 3 internal error; negative: killed by a signal (e.g. a crash);
        # 4 or 5: a selected test was not found (none ran): not a kill
        verdict = ("survived" if code == 0 else "error" if code in (4, 5) else "killed")
        return verdict, code, time.monotonic() - started

    try:
        # the unmutated code must pass in this very set-up, or no kill means anything
        verdict, code, seconds = run(original, job["all_tests"], 3600.0)
        if verdict != "survived":
            print(f"mutation: the unmutated tests fail in the worker (exit {code})",
                  file=sys.stderr)
            return 1
        # a mutant that makes a test wait for a condition until its deadline
        # counts as hung (the unmutated run of all the tests took `seconds`)
        timeout = 10.0 + 4.0 * seconds
        for item in job["mutants"]:
            verdict, code, took = run(item["source"], item["tests"], timeout)
            if verdict == "error":
                # a selected test "not found": a test module whose import
                # fails under this mutant (e.g. it builds a limiter at
                # import) is reported so; by file, that is a collection error
                verdict, code, more = run(item["source"], job["all_tests"], timeout)
                took += more
            out.write(json.dumps({"id": item["id"], "status": verdict, "exit": code,
                                  "seconds": round(took, 2)}) + "\n")
            out.flush()
    finally:
        target.write_text(original)
    return 0


# -- one module --------------------------------------------------------------

def run_module(work: Path, name: str, out: Path, budget: float | None,
               again: bool = False) -> dict:
    path, tests = MODULES[name]
    started = time.monotonic()
    env = scratch_env(work)
    log = open(out / f"{name}.log", "w")
    by_line, durations = line_tests(work, env, path, tests, log)
    source = (work / path).read_text()
    found = mutants(source, path)
    # the module's test files (with -k) when a line runs at import; else its tests
    selectors = list(tests)
    # every test of the selection (the JUnit report lists them all): a test
    # that only reads a constant runs no line of the module after its import
    every_test = set(durations)
    if not every_test:
        raise SystemExit(f"mutation: no test durations for {name} (JUnit report empty?)")
    results: dict[int, dict] = {}
    job_mutants = []
    record_file = out / f"{name}.json"
    digest = hashlib.sha256(source.encode()).hexdigest()
    before = {}
    if again and record_file.exists():
        record = json.loads(record_file.read_text())
        if record["sha256"] == digest:
            before = {tuple(k): v for k, v in record["killed"]}
        else:
            print(f"mutation: {path} changed since the last run: all of it again",
                  file=sys.stderr)
    for number, item in enumerate(found):
        item["id"] = number
        covering = by_line.get(item["line"], set())
        key = (item["line"], item["index"], item["mutated"])
        if key in before:
            # killed in the last run of this same source: added tests cannot
            # revive it (tests that were changed or removed need a full run)
            results[number] = {"status": before[key], "again": True}
        elif not covering:
            results[number] = {"status": "survived", "why": "no test runs this line"}
        else:
            # a line run at import can change what any test of the module sees
            if "" in covering:
                covering = every_test
            # the quickest tests first: with -x the first failure ends the run
            chosen = sorted(covering, key=lambda node: (durations.get(node, 1e3), node))
            job_mutants.append({"id": number, "source": item["source"], "tests": chosen})
    results_file = work / f".mutation-{name}.jsonl"
    results_file.unlink(missing_ok=True)
    job_file = work / f".mutation-{name}.json"
    job_file.write_text(json.dumps({"work": str(work), "path": path, "all_tests": selectors,
                                    "results": str(results_file), "mutants": job_mutants}))
    proc = subprocess.Popen([sys.executable, str(Path(__file__).resolve()), "--worker",
                             str(job_file)], cwd=work, env=env, stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    # imported here, in this process only: the worker imports none of our
    # packages before its children, which import the mutated module afresh
    from holonomic_core.progress import progress
    with progress(len(job_mutants), f"mutation {name}", "mutants") as bar:
        wait_worker(proc, results_file, bar,
                    None if budget is None else started + budget)
    log.close()
    if proc.returncode not in (0, -signal.SIGKILL):
        raise SystemExit(f"mutation: the worker failed on {name} (see {out / name}.log)")
    if results_file.exists():
        for line in results_file.read_text().splitlines():
            row = json.loads(line)
            results[row["id"]] = row
    record_file.write_text(json.dumps({
        "sha256": digest, "killed": [
            [[item["line"], item["index"], item["mutated"]], results[item["id"]]["status"]]
            for item in found if results.get(item["id"], {}).get("status") in ("killed",
                                                                              "timeout")]}))
    listed = load_equivalent().get(name, [])
    counts = {k: 0 for k in ("killed", "timeout", "error", "survived", "equivalent",
                             "not run")}
    with open(out / f"{name}.txt", "w") as handle:
        handle.write(f"{name}: {path}\n\n")
        for item in found:
            row = results.get(item["id"])
            status = "not run" if row is None else row["status"]
            if status == "survived" and is_equivalent(item, listed):
                status = "equivalent"
            counts[status] += 1
            if status == "survived":
                diff = difflib.unified_diff(source.splitlines(), item["source"].splitlines(),
                                            path, path, n=2, lineterm="")
                why = f" ({row['why']})" if "why" in row else ""
                handle.write(f"--- mutant {item['id']} line {item['line']}{why}\n"
                             + "\n".join(list(diff)[2:]) + "\n\n")
    counts["mutants"] = len(found)
    counts["seconds"] = round(time.monotonic() - started)
    return counts


def wait_worker(proc: subprocess.Popen, results_file: Path, bar, deadline: float | None,
                poll: float = 1.0) -> None:
    """Wait for the worker ``proc``, killing its session at ``deadline``
    (time.monotonic() [s], None: never). ``bar`` (holonomic_core.progress)
    advances once per mutant the worker has reported (a line each of
    ``results_file``); the mutants a stopped worker did not reach are
    skipped, so the display ends."""
    reported = 0

    def catch_up() -> None:
        nonlocal reported
        try:
            lines = results_file.read_bytes().count(b"\n")
        except FileNotFoundError:           # no mutant reported yet
            lines = 0
        if lines > reported:
            bar.advance(lines - reported)
            reported = lines

    while proc.poll() is None:
        time.sleep(poll)
        catch_up()
        if deadline is not None and time.monotonic() > deadline:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    catch_up()
    bar.skip(bar.total - bar.done)


# -- planted bugs ---------------------------------------------------------------

def build_hot_path(work: Path, log) -> None:
    """Compile the scratch copy's holonomic_core._hot_path in place (about 2 s)."""
    package = work / "src" / "holonomic_core"
    subprocess.run([sys.executable, "setup.py", "-q", "build_ext", "--inplace",
                    "--build-temp", str(work / ".build-temp"), "--build-lib",
                    str(work / ".build-lib")], cwd=package, stdout=log,
                   stderr=subprocess.STDOUT, check=True)


def run_planted(work: Path, out: Path, names: list[str]) -> int:
    """Apply each planted bug of PLANTED in turn, run its tests on its path,
    print killed / survived; 1 when one survives or an entry is stale."""
    import yaml

    entries = yaml.safe_load(PLANTED.read_text()) or []
    unknown = set(names) - {e["name"] for e in entries}
    if unknown:
        print(f"mutation: unknown planted bug(s) {sorted(unknown)}; see {PLANTED}",
              file=sys.stderr)
        return 2
    log = open(out / "planted.log", "w")
    build_hot_path(work, log)               # the unmutated twin, for the compiled runs
    failures = 0
    print(f"{'planted bug':<56} {'path':<8} {'verdict':<9} {'time':>5}", flush=True)
    for entry in entries:
        if names and entry["name"] not in names:
            continue
        target = work / entry["file"]
        original = target.read_text()
        if original.count(entry["find"]) != 1:
            print(f"{entry['name']:<56} {'':<8} {'stale':<9} (its text is not once in "
                  f"{entry['file']})", flush=True)
            failures += 1
            continue
        compiled = target.suffix == ".c"
        path = "compiled" if compiled else "pure"
        env = dict(scratch_env(work), HOLONOMIC_HOT_PATH=path, HOLONOMIC_TEST_HOT_PATHS=path)
        started = time.monotonic()
        command = [sys.executable, "-m", "pytest", *PYTEST, "-x", *entry["tests"]]
        # the tests must pass without the bug, or a failure means nothing
        if subprocess.run(command, cwd=work, env=env, stdout=log,
                          stderr=subprocess.STDOUT).returncode != 0:
            print(f"{entry['name']:<56} {path:<8} {'error':<9} (its tests fail without it: "
                  f"{out / 'planted.log'})", flush=True)
            failures += 1
            continue
        try:
            target.write_text(original.replace(entry["find"], entry["replace"]))
            if compiled:
                build_hot_path(work, log)
            result = subprocess.run(command, cwd=work, env=env, stdout=log,
                                    stderr=subprocess.STDOUT)
        finally:
            target.write_text(original)
            if compiled:
                build_hot_path(work, log)
        # 1: a test failed (killed); 0: all passed (survived); else pytest
        # could not run them (the entry's tests are wrong)
        verdict = {0: "survived", 1: "killed"}.get(result.returncode, "error")
        failures += verdict != "killed"
        print(f"{entry['name']:<56} {path:<8} {verdict:<9} "
              f"{time.monotonic() - started:>4.0f}s", flush=True)
    log.close()
    return 1 if failures else 0


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("modules", nargs="*", default=None,
                        help=f"some of {', '.join(MODULES)} (default: all)")
    parser.add_argument("--budget", type=float, default=None, metavar="MINUTES",
                        help="stop each module after this long (the rest: not run)")
    parser.add_argument("--again", action="store_true",
                        help="run only the mutants the last run of each module did not kill "
                             "(out/mutation/<module>.json), when its source is unchanged: after "
                             "adding tests")
    parser.add_argument("--planted", action="store_true",
                        help="run the planted bugs of scripts/mutation_planted.yaml instead "
                             "(MODULE ...: their names; default all)")
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.worker:
        return worker(args.worker)
    if args.planted:
        out = ROOT / "out" / "mutation"
        out.mkdir(parents=True, exist_ok=True)
        work = scratch_copy()
        try:
            return run_planted(work, out, args.modules or [])
        finally:
            shutil.rmtree(work, ignore_errors=True)
    modules = args.modules or list(MODULES)
    unknown = [m for m in modules if m not in MODULES]
    if unknown:
        print(f"mutation: unknown module(s) {unknown}; choose from {list(MODULES)}",
              file=sys.stderr)
        return 2
    out = ROOT / "out" / "mutation"
    out.mkdir(parents=True, exist_ok=True)
    work = scratch_copy()
    # killed: a test failed; timeout: the tests hung (a mutant that loops
    # forever); error: pytest found no test to run; equivalent: a survivor
    # listed in mutation_equivalent.yaml; not run: stopped by the budget
    print(f"{'module':<16} {'mutants':>7} {'killed':>6} {'timeout':>7} {'error':>5} "
          f"{'survived':>8} {'equiv':>5} {'not run':>7} {'score':>6} {'time':>6}", flush=True)
    try:
        for name in modules:
            budget = None if args.budget is None else 60.0 * args.budget
            c = run_module(work, name, out, budget, args.again)
            caught = c["killed"] + c["timeout"]
            counted = caught + c["survived"] + c["error"]
            score = 100.0 * caught / counted if counted else 100.0
            print(f"{name:<16} {c['mutants']:>7} {c['killed']:>6} {c['timeout']:>7} "
                  f"{c['error']:>5} {c['survived']:>8} {c['equivalent']:>5} {c['not run']:>7} "
                  f"{score:>5.1f}% {c['seconds']:>5}s", flush=True)
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print(f"surviving mutants: {out}/<module>.txt")
    return 0


if __name__ == "__main__":
    sys.exit(main())
