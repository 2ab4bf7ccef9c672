"""``make bench``: the benchmark suite. Prints a table of every target and
writes it, with the machine it ran on, to docs/benchmarks.md.

Not part of the test suite's pass/fail: timings on shared machines are
noisy, so every target is a ratio measured in the same run or a percentile
over many samples, and the page records what one run measured.

Usage: python bench/run.py [--quick] [--out docs/benchmarks.md]
(--quick: shorter runs, for trying changes; the page says so.)

Progress over the benchmarks goes to stderr (holonomic_core.progress): a bar
with the time left on a terminal, in a log a plain line with the benchmarks
done and the time left after each one, below that benchmark's own line.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import sys
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
ROOT = HERE.parent
sys.path.insert(0, str(HERE))

import compute  # noqa: E402  (bench/ is not a package)
import ros_loop  # noqa: E402

from holonomic_core.progress import Progress, progress  # noqa: E402

#: the robots of the per-robot rows (cycle compute, simulation speed)
ROBOTS = ("hamr", "xr4000")
#: benchmarks (calls of the step function) of a whole run and of each --only
STEPS = {"compute": len(ROBOTS), "sim": 2 * len(ROBOTS), "loop": 2, "latency": 1}
STEPS_ALL = STEPS["compute"] + STEPS["sim"] + 1 + STEPS["loop"] + 2   # + fleet, memory, foxglove


def machine() -> str:
    cpu = "unknown CPU"
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    mem = ""
    try:
        kb = int(Path("/proc/meminfo").read_text().split()[1])
        mem = f", {kb / 1024 / 1024:.0f} GiB RAM"
    except (OSError, ValueError, IndexError):
        pass
    import numpy
    from importlib.metadata import version
    return (f"{cpu}, {os.cpu_count()} cores{mem}; {platform.system()} {platform.release()}; "
            f"Python {platform.python_version()}, numpy {numpy.__version__}, "
            f"pybullet {version('pybullet')}, rclpy (ROS 2 Jazzy wheels)")


def stepper(bar: Progress):
    """The step function of a run: it runs one benchmark, logs it on stderr
    (its name when it starts, its result and time when it ends, above the
    bar on a terminal) and counts it in ``bar``."""
    def step(name, fn, *a, **kw):
        t0 = time.monotonic()
        bar.write(f"bench: {name} ...")
        value = fn(*a, **kw)
        bar.write(f"bench: {name}: {json.dumps(value)} ({time.monotonic() - t0:.0f} s)")
        bar.advance()
        return value
    return step


def bench_progress(total: int) -> Progress:
    """The progress display of ``total`` benchmarks on stderr."""
    return progress(total, "bench", "benchmarks")


def verdict(ok: bool) -> str:
    return "met" if ok else "**not met**"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(prog="bench/run.py", description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs (not for the docs)")
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "benchmarks.md")
    parser.add_argument("--render", type=Path, metavar="JSON",
                        help="only rewrite the page from a previous run's results")
    parser.add_argument("--only", choices=("sim", "compute", "loop", "latency"),
                        help="re-run only the simulation-speed rows (ideal motors and drive "
                             "model), the control-cycle compute rows, the 1 kHz loop and "
                             "command latency rows, or the command latency alone; the page "
                             "keeps the last run's others")
    args = parser.parse_args(argv)
    if args.only:
        saved = json.loads(args.out.with_suffix(".json").read_text())
        t0 = time.monotonic()
        with bench_progress(STEPS[args.only]) as bar:
            step = stepper(bar)
            if args.only == "sim":
                saved["results"]["sim"] = sim_rows(step, args.quick)
                saved["results"]["sim_drive"] = sim_drive_rows(step, args.quick)
            elif args.only == "compute":
                saved["results"]["compute"] = compute_rows(step, args.quick)
            elif args.only == "latency":
                saved["results"]["latency"] = latency_row(step, args.quick)
            else:
                saved["results"].update(loop_rows(step, args.quick))
        saved.setdefault("reruns", {})[args.only] = (
            datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
            + f" on: {machine()}")
        table = format_table(saved["results"])
        print(table + "\n" + latency_block(saved["results"]))
        args.out.with_suffix(".json").write_text(json.dumps(saved, indent=1))
        write_page(args.out, table, saved, saved["elapsed"], saved["quick"])
        print(f"bench: wrote {args.out} ({(time.monotonic() - t0) / 60:.1f} min)",
              file=sys.stderr)
        return 0
    if args.render:
        saved = json.loads(args.render.read_text())
        table = format_table(saved["results"])
        print(table)
        write_page(args.out, table, saved, saved["elapsed"], saved["quick"])
        return 0
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "97")
    quick = args.quick
    started = time.monotonic()
    results: dict = {}

    with bench_progress(STEPS_ALL) as bar:
        step = stepper(bar)
        results["compute"] = compute_rows(step, quick)
        results["sim"] = sim_rows(step, quick)
        results["sim_drive"] = sim_drive_rows(step, quick)
        results["fleet"] = step("fleet", compute.fleet_speed, "hamr",
                                (1, 4, 8) if quick else (1, 2, 4, 8, 16, 24, 32, 40, 48),
                                2.0 if quick else 3.0)
        import rclpy
        rclpy.init()
        try:
            results.update(loop_rows(step, quick, init=False))
            results["memory"] = step("memory", ros_loop.memory_growth, 75.0 if quick else 240.0)
            results["foxglove"] = step("foxglove bridge cost", ros_loop.foxglove_cost,
                                       10.0 if quick else 30.0, 1 if quick else 2)
        finally:
            rclpy.try_shutdown()
    elapsed = time.monotonic() - started
    table = format_table(results)
    print(table + "\n" + latency_block(results))
    saved = {"results": results, "elapsed": elapsed, "quick": quick, "machine": machine(),
             "when": datetime.datetime.now(datetime.timezone.utc).strftime("%Y-%m-%d %H:%M UTC")}
    args.out.with_suffix(".json").write_text(json.dumps(saved, indent=1))
    write_page(args.out, table, saved, elapsed, quick)
    print(f"bench: wrote {args.out} ({elapsed / 60:.1f} min)", file=sys.stderr)
    return 0


def compute_rows(step, quick: bool) -> list[dict]:
    """Control-cycle compute, compiled and pure-Python paths, against the baseline."""
    cycles = 20_000 if quick else 100_000
    return [step(f"cycle compute {r}", compute.cycle_compute, r, cycles)
            for r in ROBOTS]


def loop_rows(step, quick: bool, init: bool = True) -> dict:
    """The 1 kHz loop rows (hamr; xr4000 in torque mode; without and with
    real-time scheduling) and the command latency."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "97")
    import rclpy
    if init:
        rclpy.init()
    try:
        return {"loop_1khz": step("1 kHz loop", ros_loop.loop_1khz_rows, 15.0 if quick else 60.0),
                "latency": step("command latency", ros_loop.command_latency,
                                1000 if quick else 5000)}
    finally:
        if init:
            rclpy.try_shutdown()


def latency_row(step, quick: bool) -> dict:
    """The command latency alone (``--only latency``)."""
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "97")
    import rclpy
    rclpy.init()
    try:
        return step("command latency", ros_loop.command_latency, 1000 if quick else 5000)
    finally:
        rclpy.try_shutdown()


def sim_rows(step, quick: bool) -> list[dict]:
    """Simulation speed with ideal motors (``sim.ideal_motors``) against raw pybullet."""
    return [step(f"simulation speed {r}", compute.simulation_speed, r, 5.0 if quick else 20.0)
            for r in ROBOTS]


def sim_drive_rows(step, quick: bool) -> list[dict]:
    """Simulation speed with the drive model on every joint (the default of
    ``--driver sim``) against raw pybullet."""
    return [step(f"simulation speed {r}, drive model", compute.simulation_speed, r,
                 5.0 if quick else 20.0, ideal_motors=False) for r in ROBOTS]


def format_table(r: dict) -> str:
    rows = ["| what | measured | target | |", "|---|---|---|---|"]
    for c in r["compute"]:
        pure = ("compute_pure_us" in c) and (
            f" (pure-Python path {c['compute_pure_us']:.1f} µs: {c['speedup_pure']:.1f}×)")
        pure_full = ("full_cycle_pure_us" in c) and f" (pure {c['full_cycle_pure_us']:.1f} µs)"
        same = ("same_numbers" in c) and (
            "; both paths computed the same commands and pose" if c["same_numbers"]
            else "; **the two paths' commands or pose differ**")
        rows.append(
            f"| control-cycle compute, {c['robot']} ({c['joints']} joints) | "
            f"{'compiled ' if pure else ''}{c['compute_us']:.1f} µs vs baseline "
            f"{c['baseline_us']:.1f} µs: **{c['speedup']:.1f}×**{pure or ''}; full cycle with "
            f"driver I/O and checks {c['full_cycle_us']:.1f} µs{pure_full or ''} (median of "
            f"{c['cycles']} each{same or ''}) | ≥ 5× faster (aim 10×)"
            + (", ≤ 30 µs" if c["joints"] > 3 else "") + " | "
            + verdict(c["speedup"] >= 5.0 and (c["joints"] <= 3 or c["compute_us"] <= 30.0))
            + (f" (≤ 30 µs met)" if c["joints"] > 3 and c["compute_us"] <= 30.0
               and c["speedup"] < 5.0 else "") + " |")
    for lp in r.get("loop_1khz") or ([dict(r["loop"], what=f"{r['loop']['robot']}, mock "
                                           "driver, odom 50 Hz", realtime=None)]
                                     if "loop" in r else []):
        rt = lp["realtime"]
        limit_p99, limit_max = (1.05, 2.0) if rt else (1.1, 5.0)
        over = (f", periods > 2 ms: {lp['periods_over_2ms']}, > 5 ms: {lp['periods_over_5ms']}"
                if "periods_over_2ms" in lp else "")
        out = ""
        if "outside_stamps" in lp and lp["outside_stamps"].get("count"):
            st, ar = lp["outside_stamps"], lp["outside_arrivals"]
            out = (f"; from outside ({lp['joint_states_hz']:.0f} joint_states/s received): "
                   f"stamps p99 {st['p99_ms']:.3f} ms, max {st['max_ms']:.2f} ms, > 2 ms: "
                   f"{st['over_2ms']}, > 5 ms: {st['over_5ms']}; arrivals p99 "
                   f"{ar['p99_ms']:.3f} ms, max {ar['max_ms']:.2f} ms")
        split = ""
        if "split" in lp:
            sp, causes = lp["split"], lp["over_2ms_causes"]
            parts = ", ".join(f"{name} {sp[name + '_p99_ms']:.3f}/{sp[name + '_max_ms']:.2f}"
                              for name in ("controller", "physics", "state_write", "status",
                                           "gc") if name + "_p99_ms" in sp)
            split = (f"; cycle split p99/max [ms]: woke late {sp['wake_late_p99_ms']:.3f}/"
                     f"{sp['wake_late_max_ms']:.2f}, compute {sp['compute_p99_ms']:.3f}/"
                     f"{sp['compute_max_ms']:.2f} (preempted in it up to "
                     f"{sp['preempted_max_ms']:.2f}), {parts}; periods > 2 ms by cause: woke "
                     f"late {causes['over_2ms_woke_late']}, preempted "
                     f"{causes['over_2ms_preempted']}, compute {causes['over_2ms_compute']}; "
                     f"CPU: node {lp['node_cpu_percent']:.0f} %, loop process "
                     f"{lp['loop_cpu_percent']:.0f} % of a core")
        # the loop's own counts over the measurement decide "none later than";
        # the windows' max can reach up to 2 s before it (a window spans 2000 cycles)
        if "periods_over_2ms" in lp:
            none_later = lp["periods_over_2ms" if rt else "periods_over_5ms"] == 0
        else:
            none_later = lp["period_max_ms"] <= limit_max
        rows.append(
            f"| 1 kHz loop, {lp['what']}, "
            + ("" if rt is None else f"real-time {'on' if rt else 'off'} "
               f"({lp.get('scheduling', '?')}), ")
            + f"cmd_vel {lp['cmd_hz']:.0f} Hz in, odom {lp['odom_hz']:.0f} Hz out, "
            f"{lp['seconds']:.0f} s | {lp['rate_hz']:.1f} Hz; loop's own period "
            f"p50 {lp['period_p50_ms']:.3f} ms, p99 {lp['period_p99_ms_median_window']:.3f} ms "
            f"(median of {lp['windows']} 2-s windows; worst window "
            f"{lp['period_p99_ms_worst_window']:.3f} ms), max {lp['period_max_ms']:.2f} ms "
            f"(the windows'), "
            f"{lp['overruns']} overruns{over}{out}{split} | p99 ≤ {limit_p99} ms, none later than "
            f"{limit_max:g} ms | {verdict(lp['period_p99_ms_worst_window'] <= limit_p99)} (p99), "
            f"{verdict(none_later)} (max) |")
    la = r["latency"]
    floor = (f"; the design's floor (DDS one-way + half a period) "
             f"{la['floor_p50_ms']:.3f} ms = {la['floor_ratio']:.2f}×; stages below the table"
             if "floor_ratio" in la else "")
    rows.append(
        f"| command latency, TwistStamped from another process → "
        + ("the control law of the cycle that takes it" if "stages" in la else
           "the reading of the control cycle using it")
        + f", {la['matched']} commands | p50 {la['e2e_p50_ms']:.3f} ms, p99 "
        f"{la['e2e_p99_ms']:.3f} ms"
        + (f" (in the node's callback: p50 {la['node_rx_p50_ms']:.3f} ms"
           + (f", {la['ratio_to_node_rx_p50']:.2f}× that" if "ratio_to_node_rx_p50" in la
              else "") + ")"
           if "node_rx_p50_ms" in la else "") + "; "
        f"DDS one-way p50 {la['dds_p50_ms']:.3f} ms, p99 {la['dds_p99_ms']:.3f} ms: "
        f"**{la['ratio_p50']:.2f}×**{floor} | p50 ≤ 2× DDS | {verdict(la['ratio_p50'] <= 2.0)} |")
    for s in r["sim"]:
        rows.append(
            f"| simulation speed, {s['robot']}, controller in the loop, 1 kHz physics, "
            f"ideal motors | "
            f"{s['with_controller_x']:.1f}× real time vs raw pybullet "
            f"{s['raw_pybullet_x']:.1f}×: **{100 * s['ratio']:.0f} %** | ≥ 80 % | "
            f"{verdict(s['ratio'] >= 0.8)} |")
    for s in r.get("sim_drive", []):
        rows.append(
            f"| simulation speed, {s['robot']}, controller in the loop, 1 kHz physics, "
            f"drive model on every joint | "
            f"{s['with_controller_x']:.1f}× real time vs raw pybullet "
            f"{s['raw_pybullet_x']:.1f}×: **{100 * s['ratio']:.0f} %** | ≥ 60 % | "
            f"{verdict(s['ratio'] >= 0.6)} |")
    f = r["fleet"]
    factors = ", ".join(f"{n}: {x:.1f}×" for n, x in f["realtime_factor"].items())
    rows.append(f"| fleet, {f['robot']}, one world, a controller each | real-time factor by N: "
                f"{factors}; **largest N at ≥ 1×: {f['largest_n_realtime']}** | report | — |")
    fx = r.get("foxglove")
    if fx is not None:
        off, on = fx["without"], fx["with"]
        rows.append(
            f"| Foxglove bridge: 1 kHz loop, simulated {fx['robot']}, without / with "
            f"`--foxglove` and a client subscribed to every channel "
            f"({fx['messages_per_s']:.0f} messages/s), {fx['blocks']} × {fx['seconds']:.0f} s "
            f"alternating{', ' + fx['when'] if 'when' in fx else ''} | "
            f"{off['rate_hz']:.0f} / {on['rate_hz']:.0f} Hz; period p99 "
            f"{off['period_p99_ms_median_window']:.3f} / **{on['period_p99_ms_median_window']:.3f} "
            f"ms** (median window; worst {off['period_p99_ms_worst_window']:.3f} / "
            f"{on['period_p99_ms_worst_window']:.3f} ms), p50 {off['period_p50_ms']:.3f} / "
            f"{on['period_p50_ms']:.3f} ms, max {off['period_max_ms']:.2f} / "
            f"{on['period_max_ms']:.2f} ms, overruns {off['overruns']} / {on['overruns']}"
            + (f"; the bridge thread: {fx['bridge_cpu_percent']:.1f} % of a core, "
               f"{fx['bridge_tick_p50_ms']:.2f} ms a tick (p99 {fx['bridge_tick_p99_ms']:.2f})"
               if fx.get("bridge_cpu_percent") is not None else "") + " | "
            f"p99 with ≤ p99 without + 0.05 ms | "
            f"{verdict(on['period_p99_ms_median_window'] <= off['period_p99_ms_median_window'] + 0.05)} |")
    m = r["memory"]
    rows.append(
        f"| memory, simulated bringup driven {m['seconds']:.0f} s | RSS {m['rss_start_mb']:.1f} → "
        f"{m['rss_at_1min_mb']:.1f} MB at 1 min → {m['rss_end_mb']:.1f} MB: "
        f"**{m['growth_after_1min_mb']:+.1f} MB** after the first minute | ≤ 5 MB | "
        f"{verdict(m['max_growth_after_1min_mb'] <= 5.0)} |")
    return "\n".join(rows)


def latency_block(results: dict) -> str:
    """The command latency stage by stage (a results' ``latency`` with
    ``stages``), as a fenced block; empty for older results."""
    la = results.get("latency", {})
    if "stages" not in la:
        return ""
    return ("\nCommand latency, stage by stage (ms, each message followed on one clock; "
            "`bench/ros_loop.py: command_latency`):\n\n```\n"
            + "\n".join(ros_loop.latency_lines(la)) + "\n```\n")


def write_page(path: Path, table: str, saved: dict, elapsed: float, quick: bool) -> None:
    odometry = (ROOT / "docs" / "odometry_experiment.md").read_text()
    start = odometry.index("## Results")
    block = odometry[start:odometry.index("## What it shows")].strip()
    text = f"""# Benchmarks

`make bench` (about {elapsed / 60:.0f} minutes) runs `bench/run.py`, prints this table and
rewrites this page (and `docs/benchmarks.json`, the raw results). It is not part of `make test`:
timings on a shared machine are noisy, so every target is a ratio measured within one run (ours
against a baseline or the raw library, in alternating blocks) or a percentile over many samples.
While it runs, its progress over the benchmarks goes to stderr: a bar with the time left on a
terminal, and in a log a plain line with the benchmarks done and the time left after each one.

Run {saved['when']}{' (--quick: shorter runs)' if quick else ''} on: {saved['machine']}.
{''.join(f"Rows `{k}` re-run with `--only {k}` {v}." + chr(10) for k, v in saved.get('reruns', {}).items())}
{table}
{latency_block(saved['results'])}
## The targets not met, and what it would take

- **1 kHz loop** (docs/realtime.md, "What limits the jitter"). The loop runs in a process of
  its own (the driver, the controller and the simulator; the ROS node is a shell). Each row
  gives the loop's own cycle split: nearly every period over 2 ms is the loop *not running*
  (woken late, or preempted mid-cycle), not its work (the `compute` part). What remains:
  * *without real-time priority* (no SCHED_FIFO, nothing that needs privilege) the loop is
    an ordinary process on two cores with the node, DDS and the bench's own subscriber. It
    asks the normal scheduler for a 0.1 ms time slice (`loop.slice`, Linux 6.12+), so its
    wake-ups preempt those processes instead of waiting for their 1.4 ms slices to end; the
    node publishes its three 1 kHz topics as pre-serialized messages (no per-message
    conversion and serialization in the cycle); `python bench/ros_loop.py slice-ab`
    measures the slice's effect on the wake-up lateness, with and without it in
    alternating blocks (docs/realtime.md). What a
    slice cannot change: the loop's share of the CPU when other processes want more
    than two cores, and a kernel that is not preemptible (`Dynamic Preempt: none` at
    boot): a wake-up waits until the running process leaves the kernel;
  * *with SCHED_FIFO* on such a kernel, on a machine shared with other real-time loops of the
    same priority (the other runs' loop processes): a few periods over 2 ms a minute,
    woken late, for the same reason or behind those loops; a preemption of about 50 ms is
    the kernel's real-time throttling (950 ms of real-time per second, `sched_rt_runtime_us`);
  * *the XR4000 in torque mode*: with the physics in the loop process, pybullet and the drive
    model step inside each cycle (the `controller` part); with `sim.physics_process` (its own
    rows) the physics runs in a process of its own (SCHED_FIFO 49 below a real-time loop), as
    the plant does on a robot, and the cycle is the operational-space torque law (33 µs a call
    with its dynamics compiled, 83 µs on the pure-Python path: `python bench/torque_law.py`).
    numpy's BLAS maps a 32 MiB work buffer on first use (8192 page faults under mlockall,
    a `compute` spike of many periods if that lands inside a cycle, as the drift watch's
    first batch would); the loop process sets BLAS up before its first cycle, works
    a drift batch off over four cycles, and runs its once-a-second status and collector in
    different cycles (docs/realtime.md; the loop's status keeps its page faults and its slowest
    cycle with its parts: `slowest_*` in the split). With SCHED_FIFO the remaining periods over
    2 ms are mostly woken late; without real-time priority three 1 kHz processes (loop,
    physics, node) share two cores;
  * *command latency* (its stages: `python bench/run.py --only latency` prints them and puts
    them under the table; docs/realtime.md, "The command's way to the control law"): DDS itself (write to reception in the node's process)
    and rclpy's dispatch to the callback are the same for any Python subscriber; the node's
    callback until the command is in the loop's pipe takes about 0.04 ms; then the command
    waits for the loop's next cycle: it arrives at any moment of the 1 ms period, so it waits
    up to a period, on average half. The loop takes it after its reading, immediately
    before the control law (`BaseController.step(take_command)`), not at the start of the
    cycle. So the end-to-end p50 is about DDS one-way + 0.04 ms + 0.5 ms, and **the floor
    of a fixed-period 1 kHz loop is DDS one-way + half a period**: the ratio can reach 2×
    only where DDS one-way is above about 0.55 ms. On a shared machine DDS one-way p50 varies
    from run to run, and the floor with it, so the verdict of the row above holds for its
    run only. Running an extra control cycle when a command arrives would
    remove the wait and break the fixed period the limiter, the odometry, the torque law
    and the drives' SYNC and watchdogs are built on; it is not done;
  * *from outside*: the node republishes odom, joint_states and /tf at 1 kHz; on a loaded
    machine the node and the bench's own subscriber fall behind (fewer than 1000
    joint_states a second received), and the outside periods then measure the publishing
    path, not the loop.
"""
    text += f"""

## How each row is measured

- **Control-cycle compute**: the work a control cycle does besides I/O -- twist limits, exact
  inverse kinematics, joint-rate saturation, odometry (the slip_min fit, the SE(2) arc, the
  covariance) -- with the classes the controller uses, against the same work written the
  straightforward way (`bench/compute.py: BaselineCycle`: C rebuilt and `numpy.linalg.pinv(C)`
  every cycle, fresh arrays, numpy clipping), 5000-cycle blocks alternating, medians. "Full
  cycle" is `BaseController.step` with the mock driver: also driver read and write, the
  plausibility checks of every reading, the command timeout. Both paths of
  `HOLONOMIC_HOT_PATH` (docs/hot_path.md) are measured in the same run, objects built under
  each: the compiled closed forms (the ratio that counts) and the pure-Python reference, which
  stays interpreter-bound (its ratio is in the row, in brackets). The
  benchmark also checks that both controllers end with the same joint commands and pose.
  `python bench/run.py --only compute` re-runs these two rows alone.
- **1 kHz loop** (`python bench/run.py --only loop` re-runs these rows and the latency):
  `holonomic-bringup hamr --driver mock`, `holonomic-bringup xr4000 --driver sim -p
  control_mode:=torque` and the same with `-p sim.physics_process:=true` (the physics in a
  process of its own), with `-p control_rate:=1000.0 -p publish_rate:=1000.0`, each once with
  `-p loop.realtime:=false` (the normal scheduler with the default `loop.slice`, 0.1 ms)
  and once with the default (SCHED_FIFO 50 and mlockall where permitted; the row names
  the policy and slice the loop got), 60 s each, as their own processes; this
  process publishes `cmd_vel` at 100 Hz and subscribes `odom` and `joint_states`. The loop's
  own period statistics come from its diagnostics (the loop process's cycle timestamps; 1 Hz,
  each over the last 2000 cycles, overlapping and covering the measurement; periods over 2 ms
  and 5 ms counted by the loop); the measurement starts at the third diagnostics message, so
  no window holds the start-up. The cycle split (wake-up lateness, compute and the time
  preempted in it, named parts, periods over 2 ms by cause) comes from the same diagnostics;
  the CPU use of the node and its loop process from `/proc/<pid>/stat` over the measurement. From outside: the periods between
  consecutive `joint_states` stamps (the cycle's driver reading; for the mock on the monotonic
  clock, for the simulator simulated time, so only the mock's say anything) and between their
  arrivals here (DDS and this subscriber included). A received rate below 1000/s means the
  node or this subscriber did not keep up with three 1 kHz topics.
- **Command latency** (`python bench/run.py --only latency` re-runs this row and its
  stages on the page; `python bench/ros_loop.py latency 3000 3` repeats it three times and
  only prints; `... latency 3000 3 publish-ab` alternates with a node that does not
  publish its 1 kHz topics): a base
  controller node (1 kHz, mock driver, `cmd_vel_stamped`, acceleration limits out of the
  way, its loop in its own process, publishing its three 1 kHz topics) in this process; a
  publisher process sends 5000 `TwistStamped` at 200 Hz, each at a random moment of its
  5 ms slot (a fixed rate on the loop's clock could hold one phase to the cycles for the
  whole run, every message then waiting the same part of a period). Each message is
  followed on one clock (CLOCK_MONOTONIC; system-clock stamps converted): its stamp,
  DDS's write and reception timestamps (the message info of the node's own subscription,
  through rclpy's `Subscription.callback`), the node's callback start, the start of
  its write into the loop's command pipe, and when the loop took it (`command_taken` in the
  state record of the first cycle whose commanded twist is the message's, through the
  node's state-record hook `node.link.on_record`); the end-to-end time is stamp -> taken,
  the control law runs right after. DDS one-way is the same messages' latency to a plain
  rclpy subscriber in a process of its own; the row also gives the ratio to the node's own
  callback start (DDS one-way into the node, the same path without the loop).
- **Simulation speed**: `BaseController` + `sim` driver stepped as fast as possible (1 kHz
  physics, 200 Hz control, a constant twist), against raw pybullet: the time the
  `pybullet.stepSimulation` calls of the same run take alone (each timed); once with ideal
  motors (`sim.ideal_motors`) and once with the drive model on every joint (the default: a
  velocity loop, a `TORQUE_CONTROL` call and a joint-state read per physics step), timed
  call by call in the same run. `python bench/run.py --only sim` re-runs just these four
  rows and rewrites the page with the other rows of the last run.
- **Fleet**: N robots in one world, a `BaseController` each, one loop (the `--fleet` runner's
  cycle), no ROS.
- **Memory**: `holonomic-bringup hamr --enable` (simulator) driven by `cmd_vel` at 20 Hz for the
  whole run; RSS of the node and its loop process from `/proc` every 10 s.
- **Foxglove bridge**: `holonomic-bringup hamr -p control_rate:=1000.0` (simulator) driven as
  the 1 kHz row, in alternating blocks without and with `--foxglove PORT`; with it, a
  `websockets` client in this process subscribes to every channel and reads everything (what
  the Foxglove app does). Period statistics from the loop's diagnostics, as the 1 kHz row
  (`bench/ros_loop.py: foxglove_cost`); a rate well below 1 kHz in both blocks means the
  machine was busy with other work, and only the difference between the blocks is the bridge's.
  The bridge thread's CPU is its own `time.thread_time()`, which `holonomic-bringup` logs at exit.

## Odometry accuracy (XR4000, from docs/odometry_experiment.md)

{block}
"""
    path.write_text(text)


if __name__ == "__main__":
    sys.exit(main())
