"""Benchmarks with ROS in the loop: the control loop at 1 kHz under traffic,
and the command latency against DDS's own, measured in the same run.

Both start real processes; every ROS process runs with
ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST and the benchmark's ROS_DOMAIN_ID
(bench/run.py sets them).
"""

from __future__ import annotations

import gc
import os
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import numpy as np



def _spin(nodes):
    """A SingleThreadedExecutor for ``nodes`` in a daemon thread; returns stop()."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    executor = SingleThreadedExecutor()
    for node in nodes:
        executor.add_node(node)
    stop = threading.Event()

    def run():
        while not stop.is_set() and rclpy.ok():
            executor.spin_once(timeout_sec=0.05)

    thread = threading.Thread(target=run, daemon=True)
    thread.start()

    def finish():
        stop.set()
        thread.join(2.0)
        executor.shutdown()
    return finish


def _start_bringup(args: list[str], name: str):
    """A ``holonomic-bringup`` process (its own session) logging to a file."""
    log = open(os.environ.get("BENCH_LOG_DIR", "/tmp") + f"/bench_{name}_bringup.log", "w")
    proc = subprocess.Popen([shutil.which("holonomic-bringup"), *args], stdout=log,
                            stderr=subprocess.STDOUT, start_new_session=True)
    return proc, log


def _stop_bringup(proc, log) -> None:
    """SIGINT (the normal shutdown), killed only if it hangs."""
    proc.send_signal(signal.SIGINT)
    try:
        proc.wait(15)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
    log.close()


def loop_at_1khz(seconds: float = 60.0, robot: str = "hamr") -> dict:
    """``holonomic-bringup ROBOT --driver mock`` at 1 kHz for ``seconds``
    with cmd_vel at 100 Hz in and odom at 50 Hz out; the loop's own period
    statistics, read from its diagnostics once a second (each covers the
    last 2000 cycles), and the overruns during the measurement."""
    return {"robot": robot,
            **_measure_loop([robot, "--driver", "mock"], "bench_loop", "loop", seconds)}


#: the 1 kHz loop rows of the benchmark page: robot, bringup arguments, what it is
LOOP_1KHZ_CASES = (
    ("hamr", ["hamr", "--driver", "mock"], "hamr, mock driver"),
    ("xr4000_torque", ["xr4000", "--driver", "sim", "-p", "control_mode:=torque",
                       "-p", "sim.physics_rate:=1000.0"],
     "xr4000, torque mode, simulator (1 kHz physics in the loop process)"),
    ("xr4000_torque_pp", ["xr4000", "--driver", "sim", "-p", "control_mode:=torque",
                          "-p", "sim.physics_rate:=1000.0", "-p", "sim.physics_process:=true"],
     "xr4000, torque mode, simulator (physics in its own process, sim.physics_process)"),
)


def loop_1khz_rows(seconds: float = 60.0) -> list[dict]:
    """Every case of LOOP_1KHZ_CASES at 1 kHz with odom, joint_states and
    /tf published every cycle (publish_rate 1000) and cmd_vel at 100 Hz in,
    ``seconds`` each, without and with real-time scheduling
    (``loop.realtime``). Period statistics from the loop process's own cycle
    timestamps (its diagnostics) and from outside (the joint_states this
    process receives: their stamps -- the cycle's driver reading, for the
    mock on the monotonic clock -- and their arrival times)."""
    rows = []
    for key, args, what in LOOP_1KHZ_CASES:
        for realtime in (False, True):
            ns = f"bench_{key}_rt{int(realtime)}"
            # a loop starved for seconds on a loaded machine is measured, not killed
            result = _measure_loop(
                [*args, "-p", f"loop.realtime:={str(realtime).lower()}",
                 "-p", "loop.watchdog_timeout:=30.0"], ns,
                f"{key}_rt{int(realtime)}", seconds, publish_rate=1000.0, outside=True)
            rows.append({"case": key, "what": what, "realtime": realtime, **result})
    return rows


def _period_stats(times: np.ndarray) -> dict:
    """p50, p99, max [ms] and counts over 2 ms / 5 ms of the periods between
    consecutive ``times`` [s]."""
    periods = np.diff(np.sort(times)) * 1e3
    if periods.size == 0:
        return {"count": 0}
    return {"count": int(periods.size), "p50_ms": float(np.percentile(periods, 50)),
            "p99_ms": float(np.percentile(periods, 99)), "max_ms": float(periods.max()),
            "over_2ms": int(np.sum(periods > 2.0)), "over_5ms": int(np.sum(periods > 5.0))}


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time [s] process ``pid`` has used (all its threads)."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _children(pid: int) -> list[int]:
    """The child processes of ``pid`` (the node's loop process)."""
    found = []
    for task in Path(f"/proc/{pid}/task").iterdir():
        found += [int(c) for c in (task / "children").read_text().split()]
    return found


#: the loop's cycle split (LoopStats.summary) reported with each row
_SPLIT_KEYS = ("wake_late_p99_ms", "wake_late_max_ms", "compute_p99_ms", "compute_max_ms",
               "preempted_max_ms", "controller_p99_ms", "controller_max_ms",
               "physics_p99_ms", "physics_max_ms", "state_write_p99_ms",
               "state_write_max_ms", "status_p99_ms", "status_max_ms", "gc_p99_ms",
               "gc_max_ms",
               # since the loop started (not only the measured window)
               "page_faults", "slowest_cpu_ms", "slowest_page_faults",
               "slowest_controller_ms", "slowest_physics_ms")
_CAUSE_KEYS = ("over_2ms_woke_late", "over_2ms_compute", "over_2ms_preempted")


def _measure_loop(args: list[str], ns: str, name: str, seconds: float,
                  started=None, publish_rate: float = 50.0, outside: bool = False) -> dict:
    """The loop statistics of ``holonomic-bringup ARGS --enable`` at 1 kHz in
    namespace ``ns``, driven by cmd_vel at 100 Hz for ``seconds``.
    ``started(proc)``: called once the robot publishes, before measuring;
    it returns a function called after the measurement (or None).
    ``outside``: also the periods of the joint_states received here."""
    import rclpy
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import JointState

    proc, log = _start_bringup([*args, "--enable", "--namespace", ns,
                                "-p", "control_rate:=1000.0",
                                "-p", f"publish_rate:={publish_rate}"], name)
    node = rclpy.create_node(f"{ns}_client")
    after = None
    windows, odom_count = [], [0]
    latest = {}
    joint_stamps, joint_arrivals = [], []
    measuring = [False]

    def on_diag(msg):
        for status in msg.status:
            if status.name.endswith("control loop") and status.level != DiagnosticStatus.ERROR:
                values = {kv.key: kv.value for kv in status.values}
                latest.update(values)
                windows.append(values)

    def on_joints(msg):
        if measuring[0]:
            joint_arrivals.append(time.monotonic())
            joint_stamps.append(msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec)

    node.create_subscription(DiagnosticArray, f"/{ns}/diagnostics", on_diag, 10)
    node.create_subscription(Odometry, f"/{ns}/odom",
                             lambda m: odom_count.__setitem__(0, odom_count[0] + 1), 100)
    if outside:
        node.create_subscription(JointState, f"/{ns}/joint_states", on_joints, 1000)
    pub = node.create_publisher(Twist, f"/{ns}/cmd_vel", 10)
    finish = _spin([node])
    try:
        deadline = time.monotonic() + 30.0
        while not windows and time.monotonic() < deadline:
            time.sleep(0.1)
        if not windows:
            raise RuntimeError("the robot did not publish diagnostics within 30 s")
        # each window covers the last 2000 cycles (2 s at 1 kHz): measure from
        # the third message on, so that no window holds the start-up
        while len(windows) < 3 and time.monotonic() < deadline:
            time.sleep(0.1)
        if started is not None:
            after = started(proc)
        windows.clear()
        overruns_before = int(latest["overruns"])
        causes_before = {k: int(latest.get(k, 0)) for k in _CAUSE_KEYS}
        loop_pids = _children(proc.pid)
        cpu_before = [_cpu_seconds(p) for p in [proc.pid, *loop_pids]]
        over_before = (int(latest.get("periods_over_2ms", 0)),
                       int(latest.get("periods_over_5ms", 0)))
        odom_count[0] = 0
        measuring[0] = True
        msg = Twist()
        t0 = time.monotonic()
        k = 0
        while time.monotonic() - t0 < seconds:
            msg.linear.x = 0.3 * np.sin(0.5 * k / 100.0)
            msg.linear.y = 0.2
            msg.angular.z = 0.5
            pub.publish(msg)
            k += 1
            time.sleep(max(0.0, t0 + k / 100.0 - time.monotonic()))
        elapsed = time.monotonic() - t0
        cpu_used = [_cpu_seconds(p) - c for p, c in zip([proc.pid, *loop_pids], cpu_before)]
        measuring[0] = False
        time.sleep(1.2)              # one more diagnostics message
    finally:
        if after is not None:
            after()
        finish()
        node.destroy_node()
        _stop_bringup(proc, log)
    p99 = [float(w["period_p99_ms"]) for w in windows]
    p50 = [float(w["period_p50_ms"]) for w in windows]
    result = {
        "seconds": seconds, "windows": len(windows),
        "rate_hz": float(np.median([float(w["rate_hz"]) for w in windows])),
        "period_p50_ms": float(np.median(p50)),
        "period_p99_ms_worst_window": max(p99),
        "period_p99_ms_median_window": float(np.median(p99)),
        # the worst period inside the measurement (each window's own max;
        # the windows overlap and cover it); the start-up is not measured
        "period_max_ms": max(float(w["period_window_max_ms"]) for w in windows),
        "period_max_since_start_ms": float(latest["period_max_ms"]),
        "overruns": int(latest["overruns"]) - overruns_before,
        "odom_hz": odom_count[0] / elapsed,
        "cmd_hz": k / elapsed,
        "scheduling": latest.get("scheduling", "thread"),
        # CPU use over the measurement [% of one core]: the node (ROS, DDS,
        # publishing) and its loop process
        "node_cpu_percent": 100.0 * cpu_used[0] / elapsed,
        "loop_cpu_percent": 100.0 * sum(cpu_used[1:]) / elapsed,
        "split": {k: float(latest[k]) for k in _SPLIT_KEYS if k in latest},
        "over_2ms_causes": {k: int(latest[k]) - causes_before[k]
                            for k in _CAUSE_KEYS if k in latest},
    }
    if "periods_over_2ms" in latest:
        result["periods_over_2ms"] = int(latest["periods_over_2ms"]) - over_before[0]
        result["periods_over_5ms"] = int(latest["periods_over_5ms"]) - over_before[1]
    if outside:
        result["outside_stamps"] = _period_stats(np.array(joint_stamps))
        result["outside_arrivals"] = _period_stats(np.array(joint_arrivals))
        result["joint_states_hz"] = len(joint_stamps) / elapsed
    return result


def _foxglove_watcher(port: int):
    """A Foxglove client (``websockets``) subscribed to every channel,
    draining messages in a thread, as the Foxglove app would; returns
    stop() -> number of messages received."""
    import json

    from websockets.sync.client import connect

    deadline = time.monotonic() + 30.0
    while True:
        try:
            ws = connect(f"ws://127.0.0.1:{port}", subprotocols=["foxglove.sdk.v1"],
                         max_size=None, legacy=True)
            break
        except OSError:
            if time.monotonic() > deadline:
                raise
            time.sleep(0.2)
    channels, stop, count = {}, threading.Event(), [0]
    end = time.monotonic() + 5.0        # collect the advertisements
    while time.monotonic() < end:
        try:
            frame = ws.recv(timeout=0.5)
        except TimeoutError:
            continue
        if isinstance(frame, str):
            msg = json.loads(frame)
            if msg["op"] == "advertise":
                channels.update({c["id"]: c["topic"] for c in msg["channels"]})
    ws.send(json.dumps({"op": "subscribe", "subscriptions": [
        {"id": k, "channelId": cid} for k, cid in enumerate(channels)]}))

    def drain():
        while not stop.is_set():
            try:
                ws.recv(timeout=0.2)
                count[0] += 1
            except TimeoutError:
                continue
            except Exception:
                return

    thread = threading.Thread(target=drain, daemon=True)
    thread.start()

    def finish() -> int:
        stop.set()
        thread.join(2.0)
        ws.close()
        return count[0]
    return finish


def foxglove_cost(seconds: float = 30.0, blocks: int = 2, robot: str = "hamr") -> dict:
    """The 1 kHz loop of the simulated robot without and with ``--foxglove``
    (a client subscribed to every channel), in alternating blocks of
    ``seconds``; each block its own bringup. Loop period statistics of each
    block as in :func:`loop_at_1khz`."""
    import socket

    import re

    runs = {"without": [], "with": []}
    received, bridge_cpu = [], []
    for block in range(blocks):
        runs["without"].append(_measure_loop([robot], f"bench_fox_off{block}",
                                             "foxglove_off", seconds))
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            port = s.getsockname()[1]
        holder = {}

        def started(proc, port=port):
            holder["finish"] = _foxglove_watcher(port)
            return lambda: received.append(holder["finish"]())

        runs["with"].append(_measure_loop([robot, "--foxglove", str(port)],
                                          f"bench_fox_on{block}", "foxglove_on", seconds,
                                          started=started))
        # the bringup's last line: "Foxglove bridge: CPU X % of a core ..."
        log = Path(os.environ.get("BENCH_LOG_DIR", "/tmp")) / "bench_foxglove_on_bringup.log"
        found = re.search(r"Foxglove bridge: CPU ([0-9.]+) %.*p50 ([0-9.]+) ms, p99 ([0-9.]+) ms",
                          log.read_text())
        if found:
            bridge_cpu.append(tuple(float(v) for v in found.groups()))

    def summary(results):
        return {"period_p50_ms": float(np.median([r["period_p50_ms"] for r in results])),
                "period_p99_ms_median_window": float(np.median(
                    [r["period_p99_ms_median_window"] for r in results])),
                "period_p99_ms_worst_window": max(r["period_p99_ms_worst_window"]
                                                  for r in results),
                "period_max_ms": max(r["period_max_ms"] for r in results),
                "overruns": sum(r["overruns"] for r in results),
                "rate_hz": float(np.median([r["rate_hz"] for r in results]))}
    return {"robot": robot, "seconds": seconds, "blocks": blocks,
            "without": summary(runs["without"]), "with": summary(runs["with"]),
            "messages_per_s": float(np.mean(received)) / seconds if received else 0.0,
            # the bridge thread's own CPU: share of a core [%], per tick p50, p99 [ms]
            "bridge_cpu_percent": max(c[0] for c in bridge_cpu) if bridge_cpu else None,
            "bridge_tick_p50_ms": max(c[1] for c in bridge_cpu) if bridge_cpu else None,
            "bridge_tick_p99_ms": max(c[2] for c in bridge_cpu) if bridge_cpu else None}


PUBLISHER = """
import random, sys, time
import rclpy
from geometry_msgs.msg import TwistStamped
count, rate, topic = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
subscribers = int(sys.argv[4])
rclpy.init()
node = rclpy.create_node("bench_latency_publisher")
pub = node.create_publisher(TwistStamped, topic, 10)
deadline = time.monotonic() + 30.0
while pub.get_subscription_count() < subscribers and time.monotonic() < deadline:
    time.sleep(0.05)
time.sleep(1.0)
msg = TwistStamped()
random.seed(24)
t0 = time.monotonic()
for k in range(count):
    # each message at a random moment of its slot: a fixed rate on the same
    # clock as the 1 kHz loop could keep one phase to its cycles for the
    # whole run, and every message wait the same part of a period
    time.sleep(max(0.0, t0 + (k + random.random()) / rate - time.monotonic()))
    msg.twist.linear.x = (k + 1) * 1e-5
    msg.header.stamp = node.get_clock().now().to_msg()
    pub.publish(msg)
time.sleep(0.5)
rclpy.shutdown()
"""

#: a plain rclpy subscriber in a process of its own: DDS's one-way latency
#: as a Python ROS program sees it. Prints "vx arrival stamp" per message
#: (system clock) once ``count`` arrived or nothing came for 5 s.
PLAIN_SUBSCRIBER = """
import sys, time
import rclpy
from rclpy.executors import SingleThreadedExecutor
from geometry_msgs.msg import TwistStamped
count, topic = int(sys.argv[1]), sys.argv[2]
rclpy.init()
node = rclpy.create_node("bench_latency_plain")
rows = []
def on_msg(msg):
    rows.append((msg.twist.linear.x, time.time(),
                 msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec))
node.create_subscription(TwistStamped, topic, on_msg, 10)
executor = SingleThreadedExecutor()
executor.add_node(node)
print("ready", flush=True)
last = time.monotonic() + 60.0
while len(rows) < count and time.monotonic() - last < 5.0:
    n = len(rows)
    executor.spin_once(timeout_sec=0.1)
    if len(rows) > n:
        last = time.monotonic()
for vx, arrival, stamp in rows:
    print(f"{vx!r} {arrival!r} {stamp!r}")
rclpy.shutdown()
"""

#: the stages of a command's way, between consecutive timestamps (command_latency)
LATENCY_STAGES = (
    ("publish", "the publisher's stamp -> DDS's write (rclpy publish)"),
    ("dds", "DDS's write -> its arrival in the node's process (Fast DDS's reception stamp)"),
    ("dispatch", "arrival -> the node's cmd_vel callback starts (the executor wakes, takes "
                 "and converts the message)"),
    ("callback", "the callback starts -> it writes the command into the loop's command pipe"),
    ("wait", "the write -> the loop's next cycle takes it (after its reading, immediately "
             "before the control law)"),
)


def _percentiles(values_ms) -> dict:
    values = np.asarray(values_ms)
    return {"p50_ms": float(np.percentile(values, 50)), "p99_ms": float(np.percentile(values, 99)),
            "mean_ms": float(values.mean())}


def command_latency(count: int = 5000, rate: float = 200.0, robot: str = "hamr",
                    node_publishes: bool = True) -> dict:
    """TwistStamped from another process -> the control cycle that uses it
    (a 1 kHz base controller node in this process, its loop in its own
    process, mock driver), against the DDS one-way latency of the same
    messages to a plain rclpy subscriber in a third process. Percentiles in ms.

    Each message is followed on one clock (CLOCK_MONOTONIC; the system-clock
    stamps converted with the offset between the two clocks, which only a
    step of the system clock changes): its stamp, DDS's write and reception
    timestamps (the message info of the node's own subscription, whose
    callback this function wraps through rclpy's public
    ``Subscription.callback``), the callback's start, the start of the write
    into the loop's command pipe (``link.send_command`` wrapped), and the
    moment the loop took it (``command_taken`` of the first state record
    whose commanded twist is the message's, through the node's public
    state-record hook ``node.link.on_record``). The end-to-end time is stamp
    -> taken: the control law uses the command right after; the cycle's
    reading precedes that by ``reading_to_take``. ``node_publishes`` False:
    the node does not publish the records (odom, /tf, joint_states): an A/B
    of how much its 1 kHz publishing delays the command's callback."""
    import rclpy
    from geometry_msgs.msg import TwistStamped
    from rclpy.parameter import Parameter

    from holonomic_bringup.base_controller_node import BaseControllerNode, switch_interval

    ns = "bench_latency"
    topic = f"/{ns}/cmd_vel"
    params = [Parameter("robot_config", value=robot), Parameter("driver", value="mock"),
              Parameter("control_rate", value=1000.0),
              # a state record every cycle: the hook sees the first cycle using each command
              Parameter("publish_rate", value=1000.0),
              Parameter("cmd_vel_stamped", value=True),
              Parameter("enable_on_start", value=True), Parameter("cmd_timeout", value=0.0)]
    for axis in ("linear.x", "linear.y", "angular.z"):
        # the limiter passes each command through in one cycle: the latency
        # measured is transport + waiting for the next cycle, not a ramp
        params += [Parameter(f"limits.{axis}.max_acceleration", value=1000.0),
                   Parameter(f"limits.{axis}.max_deceleration", value=1000.0)]
    node = BaseControllerNode(namespace=ns, parameter_overrides=params)
    period = 1.0 / node.config.controller.control_rate
    # as holonomic-bringup runs the node (run_robots): with Python's default
    # 5 ms, the callback waits up to 5 ms for the lock the reader thread holds
    switch_before = sys.getswitchinterval()
    sys.setswitchinterval(switch_interval(node.config.controller.control_rate))
    gc.freeze()
    wall_minus_mono = time.time() - time.monotonic()
    traced: dict[float, list] = {}      # vx -> [stamp, dds write, dds arrival, callback]
    written: dict[float, float] = {}    # vx -> start of the pipe write
    cycles: dict[float, tuple] = {}     # vx -> (reading, taken) of the first cycle using it
    link = node.link
    publish = link.on_record
    send = link.send_command

    def on_record(record):
        vx = round(float(record.twist_command[0]), 9)
        if vx and vx not in cycles:
            cycles[vx] = (record.stamp, record.command_taken)
        if node_publishes:
            publish(record)

    def send_command(twist, received):
        # stamped before the write: after it, this thread may wait for the
        # interpreter lock while the loop already has the command
        written[round(twist[0], 9)] = time.monotonic()
        send(twist, received)

    subscription = next(s for s in node.subscriptions if s.topic_name == topic)
    callback = subscription.callback

    def on_cmd_vel(msg, info):          # two arguments: rclpy passes the message info
        start = time.monotonic()
        stamp = msg.header.stamp.sec + 1e-9 * msg.header.stamp.nanosec
        traced[round(msg.twist.linear.x, 9)] = [
            stamp - wall_minus_mono, info["source_timestamp"] * 1e-9 - wall_minus_mono,
            info["received_timestamp"] * 1e-9 - wall_minus_mono, start]
        callback(msg)

    link.on_record = on_record
    link.send_command = send_command
    subscription.callback = on_cmd_vel
    finish = _spin([node])
    plain = subprocess.Popen([sys.executable, "-c", PLAIN_SUBSCRIBER, str(count), topic],
                             stdout=subprocess.PIPE, text=True)
    try:
        plain.stdout.readline()          # "ready"
        subprocess.run([sys.executable, "-c", PUBLISHER, str(count), str(rate), topic, "2"],
                       check=True, timeout=count / rate + 60)
        out, _ = plain.communicate(timeout=30)
        time.sleep(0.2)
    finally:
        if plain.poll() is None:
            plain.kill()
            plain.wait()
        finish()
        node.shutdown()
        node.destroy_node()
        sys.setswitchinterval(switch_before)
    step_ms = abs(time.time() - time.monotonic() - wall_minus_mono) * 1e3
    arrived = {}
    for line in out.splitlines():
        vx, arrival, stamp = (float(v) for v in line.split())
        arrived[round(vx, 9)] = (arrival - stamp) * 1e3
    both = [vx for vx in traced if vx in written and vx in cycles and vx in arrived]
    if len(both) < 2:
        raise RuntimeError(f"command latency: {len(both)} of {count} commands followed "
                           "through every stage (the node or the subscriber got none)")
    times = np.array([[*traced[vx], written[vx], cycles[vx][1]] for vx in both])
    stages = {name: _percentiles(np.diff(times[:, k:k + 2], axis=1)[:, 0] * 1e3)
              for k, (name, _) in enumerate(LATENCY_STAGES)}
    e2e = (times[:, -1] - times[:, 0]) * 1e3
    dds = np.array([arrived[vx] for vx in both])
    reading_to_take = np.array([cycles[vx][1] - cycles[vx][0] for vx in both]) * 1e3
    e2e_p50, dds_p50 = float(np.percentile(e2e, 50)), float(np.percentile(dds, 50))
    node_rx_p50 = float(np.percentile((times[:, 3] - times[:, 0]) * 1e3, 50))
    # the design's floor: the command cannot be used before the next cycle,
    # on average half a period after it arrives (fixed-period sampling of a
    # message stream with no phase relation to the loop)
    floor_p50 = dds_p50 + 0.5 * period * 1e3
    return {"robot": robot, "commands": count, "matched": len(both),
            "dds_p50_ms": dds_p50, "dds_p99_ms": float(np.percentile(dds, 99)),
            "e2e_p50_ms": e2e_p50, "e2e_p99_ms": float(np.percentile(e2e, 99)),
            "ratio_p50": e2e_p50 / dds_p50,
            "stages": stages, "reading_to_take": _percentiles(reading_to_take),
            # DDS one-way into the node itself (stamp -> its callback starts)
            "node_rx_p50_ms": node_rx_p50, "ratio_to_node_rx_p50": e2e_p50 / node_rx_p50,
            "period_ms": period * 1e3, "floor_p50_ms": floor_p50,
            "floor_ratio": floor_p50 / dds_p50, "clock_step_ms": step_ms,
            "node_publishes": node_publishes}


def latency_lines(r: dict) -> list[str]:
    """The command latency's breakdown as text lines (bench output and page)."""
    lines = [f"{r['matched']} of {r['commands']} commands; end to end p50 "
             f"{r['e2e_p50_ms']:.3f} ms, p99 {r['e2e_p99_ms']:.3f} ms; DDS one-way to a plain "
             f"subscriber p50 {r['dds_p50_ms']:.3f} ms, p99 {r['dds_p99_ms']:.3f} ms: "
             f"{r['ratio_p50']:.2f}x; to the node's own callback (DDS one-way into the node) "
             f"p50 {r['node_rx_p50_ms']:.3f} ms: {r['ratio_to_node_rx_p50']:.2f}x"]
    for name, what in LATENCY_STAGES:
        st = r["stages"][name]
        lines.append(f"{name:9s} p50 {st['p50_ms']:.3f}  p99 {st['p99_ms']:.3f}  mean "
                     f"{st['mean_ms']:.3f} ms  {what}")
    rt = r["reading_to_take"]
    lines.append(f"the cycle's reading precedes the take by p50 {rt['p50_ms']:.3f} ms, "
                 f"p99 {rt['p99_ms']:.3f} ms")
    lines.append(f"floor of the design (DDS one-way + half a {r['period_ms']:g} ms period): "
                 f"p50 {r['floor_p50_ms']:.3f} ms = {r['floor_ratio']:.2f}x DDS")
    return lines


def memory_growth(seconds: float = 240.0, robot: str = "hamr") -> dict:
    """RSS [MB] of a simulated ``holonomic-bringup`` (node and loop process)
    driven the whole time
    (cmd_vel at 20 Hz, turning so it stays in place), sampled every 10 s;
    growth after the first minute."""
    import rclpy
    from geometry_msgs.msg import Twist

    ns = "bench_memory"
    proc, log = _start_bringup([robot, "--enable", "--namespace", ns], "memory")
    node = rclpy.create_node("bench_memory_client")
    pub = node.create_publisher(Twist, f"/{ns}/cmd_vel", 10)
    samples = []

    def rss_mb() -> float:
        # the wrapper execs python: the PID is the program's; its children
        # (the control loop process) count too
        pids = [proc.pid]
        for task in Path(f"/proc/{proc.pid}/task").iterdir():
            pids += [int(p) for p in (task / "children").read_text().split()]
        total = 0.0
        for pid in pids:
            for line in Path(f"/proc/{pid}/status").read_text().splitlines():
                if line.startswith("VmRSS:"):
                    total += int(line.split()[1]) / 1024.0
        return total

    try:
        time.sleep(5.0)
        t0 = time.monotonic()
        msg = Twist()
        next_sample = 0.0
        while time.monotonic() - t0 < seconds:
            t = time.monotonic() - t0
            msg.linear.x = 0.4 * np.cos(0.4 * t)
            msg.linear.y = 0.4 * np.sin(0.4 * t)
            msg.angular.z = 0.3
            pub.publish(msg)
            if t >= next_sample:
                samples.append((t, rss_mb()))
                next_sample += 10.0
            time.sleep(0.05)
        samples.append((time.monotonic() - t0, rss_mb()))
    finally:
        node.destroy_node()
        _stop_bringup(proc, log)
    after_minute = [mb for t, mb in samples if t >= 60.0]
    return {"robot": robot, "seconds": seconds, "rss_start_mb": samples[0][1],
            "rss_at_1min_mb": after_minute[0], "rss_end_mb": samples[-1][1],
            "growth_after_1min_mb": samples[-1][1] - after_minute[0],
            "max_growth_after_1min_mb": max(after_minute) - after_minute[0]}


def slice_ab(seconds: float = 25.0, reps: int = 3) -> list[dict]:
    """The 1 kHz HAMR row without real-time priority (as loop_1khz_rows),
    alternately with the kernel's default time slice (``loop.slice`` 0)
    and the default 0.1 ms, ``reps`` times each: an A/B in one window of
    whatever else the machine runs (docs/realtime.md)."""
    rows = []
    for rep in range(reps):
        for name, slice_s in (("kernel slice", 0.0), ("loop.slice 0.1 ms", 1e-4)):
            result = _measure_loop(
                ["hamr", "--driver", "mock", "-p", "loop.realtime:=false",
                 "-p", f"loop.slice:={slice_s}", "-p", "loop.watchdog_timeout:=30.0"],
                "bench_slice_ab", f"slice_ab_{rep}_{int(slice_s > 0)}", seconds,
                publish_rate=1000.0, outside=True)
            rows.append({"variant": name, "rep": rep, "load": os.getloadavg()[0], **result})
            print(_ab_line(rows[-1]), flush=True)
    return rows


def _ab_line(r: dict) -> str:
    return (f"{r['variant']:18s} load {r['load']:5.1f} | {r['scheduling']:28s} | p99 "
            f"{r['period_p99_ms_median_window']:.3f} ms (worst window "
            f"{r['period_p99_ms_worst_window']:.3f}), max {r['period_max_ms']:.2f} ms, "
            f"> 2 ms: {r['periods_over_2ms']}, > 5 ms: {r['periods_over_5ms']}, woke late p99 "
            f"{r['split']['wake_late_p99_ms']:.3f} ms | CPU node "
            f"{r['node_cpu_percent']:.0f} %, loop {r['loop_cpu_percent']:.0f} % | "
            f"{r['joint_states_hz']:.0f} joint_states/s")


_USAGE = ("usage: python bench/ros_loop.py slice-ab [SECONDS [REPS]]\n"
          "       python bench/ros_loop.py latency [COMMANDS [REPS [publish-ab]]]")


if __name__ == "__main__":
    # python bench/ros_loop.py slice-ab [SECONDS [REPS]] | latency [COMMANDS [REPS [publish-ab]]]
    try:
        if len(sys.argv) < 2 or sys.argv[1] not in ("slice-ab", "latency"):
            raise ValueError
        numbers = [float(sys.argv[2]) if len(sys.argv) > 2 else None,
                   int(sys.argv[3]) if len(sys.argv) > 3 else None]
        if any(n is not None and n <= 0 for n in numbers):
            raise ValueError
    except ValueError:
        print(_USAGE, file=sys.stderr)
        sys.exit(2)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    os.environ.setdefault("ROS_DOMAIN_ID", "97")
    import rclpy
    rclpy.init()
    try:
        if sys.argv[1] == "slice-ab":
            slice_ab(numbers[0] or 25.0, numbers[1] or 3)
        else:
            # with "publish-ab": alternately with and without the node's 1 kHz publishing
            variants = (True, False) if "publish-ab" in sys.argv[4:] else (True,)
            for rep in range(numbers[1] or 1):
                for publishes in variants:
                    result = command_latency(int(numbers[0] or 3000), node_publishes=publishes)
                    print(f"run {rep + 1}, node {'publishing' if publishes else 'silent'}, "
                          f"load {os.getloadavg()[0]:.1f}:", flush=True)
                    for line in latency_lines(result):
                        print("  " + line, flush=True)
    finally:
        rclpy.try_shutdown()
