"""One-way latency of the CAN rig's bus between processes against python-can's
in-process virtual bus.

    python bench/ipc_can.py [--frames 2000] [--period 0.001]

The rig (holonomic_testing.can_rig) runs the emulated drives in a process of
their own and joins them to the driver through ``holonomic_ipc``
(holonomic_testing.ipc_can): a hub in the drives' process and a Unix socket.
This sends ``frames`` frames, one every ``period`` seconds, from one node to
another through such a hub (a drives' process without drives) and through
python-can's virtual bus, and prints each one's median, p99 and largest
delay (receive time minus the frame's send stamp).
"""

from __future__ import annotations

import shutil
import struct
import tempfile
import threading
import time

import can
import numpy as np
from can import BusABC, Message

from holonomic_core.command_line import ArgumentParser, number
from holonomic_testing.drive_host import DriveHost
from holonomic_testing.ipc_can import IpcBus


def measure_latency(frames: int = 2000, period: float = 1e-3) -> dict[str, list[float]]:
    """One-way latency [s] (receive time - send stamp) of ``frames`` frames
    sent every ``period`` [s] from one node to another: through a hub in a
    drives' process (holonomic_testing.drive_host, no drives) and through
    python-can's virtual bus in this process, for comparison."""
    def run(sender: BusABC, receiver: BusABC) -> list[float]:
        delays: list[float] = []

        def receive() -> None:
            while len(delays) < frames:
                msg = receiver.recv(timeout=5.0)
                if msg is None:
                    return
                delays.append(time.time() - msg.timestamp)

        thread = threading.Thread(target=receive)
        thread.start()
        for k in range(frames):
            sender.send(Message(arbitration_id=0x180 + k % 8, data=struct.pack("<q", k),
                                is_extended_id=False))
            time.sleep(period)
        thread.join()
        return delays

    folder = tempfile.mkdtemp(prefix="holonomic-can-")
    host = DriveHost([], f"{folder}/bus")
    try:
        a, b = IpcBus(f"{folder}/bus"), IpcBus(f"{folder}/bus")
        hub = run(a, b)
        a.shutdown()
        b.shutdown()
    finally:
        host.close()
        shutil.rmtree(folder, ignore_errors=True)
    a, b = can.Bus(interface="virtual", channel=folder), can.Bus(interface="virtual", channel=folder)
    virtual = run(a, b)
    a.shutdown()
    b.shutdown()
    return {"holonomic_ipc (hub in a drives' process)": hub, "python-can virtual": virtual}


def main(argv=None) -> int:
    parser = ArgumentParser(prog="bench/ipc_can.py", description=__doc__.split("\n")[0])
    parser.add_argument("--frames", type=number(10, 10**6, integer=True), default=2000)
    parser.add_argument("--period", type=number(1e-4, 1.0, unit="s"), default=1e-3,
                        help="[s] between frames")
    args = parser.parse_args(argv)
    for name, delays in measure_latency(args.frames, args.period).items():
        d = np.array(delays) * 1e3
        print(f"{name}: {len(d)} frames, latency median {np.median(d):.3f} ms, "
              f"p99 {np.percentile(d, 99):.3f} ms, max {d.max():.3f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
