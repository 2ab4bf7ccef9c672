"""Emulated drives in a process of their own, as real drives are.

A real drive is hardware of its own: however busy the host computer is,
the drive answers on time. Emulated drives that are threads of the test
process are starved with it on a busy machine and answer late, and the
driver under test then rightly faults. So the rig runs them in a child
process (``python -m holonomic_testing.drive_host FD``) that

* asks for the product loop's real-time scheduling (``SCHED_FIFO`` at
  ``realtime.DEFAULT_PRIORITY`` and locked memory, the loop host's own
  :func:`holonomic_core.realtime.request_realtime`) before it starts any
  thread, so the bus and the drives inherit it; when the system refuses,
  one line says so and the drives run without it;
* builds the drives (each backend's ``holonomic.emulated_drives`` entry
  point: :mod:`holonomic_drivers.emulation`,
  :mod:`holonomic_drivers.emulated_cia402`, unchanged) on a virtual channel
  of its own, runs them in an ``EmulatorThread``, and joins that channel
  to the bus the driver opens (:class:`holonomic_testing.ipc_can.BusHub`);
* lets the test reach the drives as if they were local: :class:`DriveHost`
  gives a :class:`Remote` per device whose attributes, properties and
  methods are those of the device in the child (``device.silent = True``,
  ``device.inject_fault(0x2310)``, ``device.motor(0).inertia``, ...).

The control channel is a socket pair (``multiprocessing.connection``
framing, pickled requests). The child exits when it is closed (the test
process ended or :meth:`DriveHost.close`).
"""

from __future__ import annotations

import enum
import os
import socket
import subprocess
import sys
import threading
import traceback
from multiprocessing.connection import Connection
from typing import Any

from holonomic_core.driver import emulated_drive_class

#: result types sent back by value; anything else stays in the child and is
#: reached through a Remote
_PLAIN = (type(None), bool, int, float, complex, str, bytes, tuple, list, dict, set,
          frozenset, enum.Enum)
#: how long the child may take to import, build the drives and start [s]:
#: generous, since a start starved of CPU by other work takes seconds and a
#: slow start is not a failure
START_TIMEOUT = 60.0


class Remote:
    """An object of the drives' process: attribute reads, writes and method
    calls go to it and back (exceptions are raised here)."""

    __slots__ = ("_host", "_ref", "_label")

    def __init__(self, host: "DriveHost", ref: int, label: str):
        object.__setattr__(self, "_host", host)
        object.__setattr__(self, "_ref", ref)
        object.__setattr__(self, "_label", label)

    def __getattr__(self, name: str):
        return self._host.request("getattr", self._ref, name, label=f"{self._label}.{name}")

    def __setattr__(self, name: str, value) -> None:
        self._host.request("setattr", self._ref, name, (value,))

    def __call__(self, *args, **kwargs):
        return self._host.request("call", self._ref, None, (args, kwargs), f"{self._label}()")

    def __repr__(self) -> str:
        return f"<Remote {self._label} in the drives' process>"


class DriveHost:
    """The drives' process, seen from the test: ``DriveHost(specs, bus_path)``
    starts it; ``devices`` (Remote each), ``emulators`` (the Remote
    EmulatorThread), ``realtime`` (None when real-time scheduling was
    granted, else the one-line reason), ``close()``.

    ``specs``: one ``(backend, node_id, kwargs)`` per device: the emulated
    drive of ``backend`` (:func:`holonomic_core.driver.emulated_drive_class`,
    e.g. "odrive_can", "cia402"), kwargs those of its class after the node
    and channel. ConfigError, before anything starts, for a backend without
    an emulated drive.
    """

    def __init__(self, specs: list[tuple[str, int, dict]], bus_path: str,
                 realtime: bool = True):
        for backend, _, _ in specs:
            emulated_drive_class(backend)
        ours, theirs = socket.socketpair()
        self._conn = Connection(ours.detach())
        self._lock = threading.Lock()
        self._process = subprocess.Popen(
            [sys.executable, "-m", "holonomic_testing.drive_host", str(theirs.fileno())],
            pass_fds=(theirs.fileno(),))
        theirs.close()
        try:
            self._conn.send((specs, bus_path, realtime))
            if not self._conn.poll(START_TIMEOUT):
                raise RuntimeError(f"the drives' process did not start within {START_TIMEOUT} s")
            status, *ready = self._conn.recv()
        except (EOFError, OSError, RuntimeError) as exc:
            self._kill()
            raise RuntimeError(f"the drives' process failed to start "
                               f"(exit {self._process.returncode}): {exc}") from None
        if status != "ready":
            self._kill()
            raise RuntimeError(f"the drives' process failed to start: {ready[0]}")
        self.realtime, self.policy, device_refs, emulator_ref = ready
        self.devices = [Remote(self, ref, f"device[{k}]") for k, ref in enumerate(device_refs)]
        self.emulators = Remote(self, emulator_ref, "emulators")

    def request(self, op: str, ref: int, name: str | None, payload: tuple = (),
                label: str = ""):
        """One request to the child: ``op`` "getattr" / "setattr" (payload:
        the value) / "call" (payload: args, kwargs) on object ``ref``."""
        with self._lock:
            self._conn.send((op, ref, name, *payload))
            kind, value = self._conn.recv()
        if kind == "value":
            return value
        if kind == "method":
            def method(*args, **kwargs):
                return self.request("call", ref, name, (args, kwargs), f"{label}()")
            return method
        if kind == "ref":
            return Remote(self, value, label)
        raise value

    def close(self) -> None:
        try:
            with self._lock:
                self._conn.send(("close", 0, None))
                self._conn.recv()
        except (EOFError, OSError):
            pass
        self._conn.close()
        try:
            self._process.wait(timeout=10.0)
        except subprocess.TimeoutExpired:
            self._kill()

    def _kill(self) -> None:
        self._process.kill()
        self._process.wait()


# -- the child ----------------------------------------------------------------------------


def _build(specs, channel: str) -> list:
    return [emulated_drive_class(backend)(node, channel, **kwargs)
            for backend, node, kwargs in specs]


def _answer(objects: list, value) -> tuple[str, Any]:
    if isinstance(value, _PLAIN) or type(value).__module__ == "numpy":
        return "value", value
    if callable(value) and hasattr(value, "__self__"):
        return "method", None
    objects.append(value)
    return "ref", len(objects) - 1


def _serve(conn: Connection, objects: list) -> None:
    while True:
        try:
            op, ref, name, *args = conn.recv()
        except EOFError:
            return
        if op == "close":
            conn.send(("value", None))
            return
        try:
            target = objects[ref]
            if op == "getattr":
                reply = _answer(objects, getattr(target, name))
            elif op == "setattr":
                setattr(target, name, args[0])
                reply = ("value", None)
            else:
                call = target if name is None else getattr(target, name)
                reply = _answer(objects, call(*args[0], **args[1]))
        except Exception as exc:        # raised in the test instead
            try:
                conn.send(("error", exc))
                continue
            except Exception:
                reply = ("error", RuntimeError(traceback.format_exc()))
        conn.send(reply)


def main(argv: list[str]) -> int:
    conn = Connection(int(argv[0]))
    specs, bus_path, realtime = conn.recv()
    try:
        from holonomic_core.realtime import current_policy, request_realtime
        # before any thread starts: the hub and the emulator thread inherit it
        warning = request_realtime() if realtime else "not requested"
        if warning is not None and realtime:
            print(f"drive_host: {warning}", file=sys.stderr, flush=True)
        from holonomic_drivers.emulation import EmulatorThread
        from holonomic_testing.ipc_can import BusHub
        channel = f"drives-{os.getpid()}"
        devices = _build(specs, channel)
        hub = BusHub(bus_path, channel).start()
        emulators = EmulatorThread(devices).start()
    except Exception:
        conn.send(("failed", traceback.format_exc()))
        return 2
    objects: list = [*devices, emulators]
    conn.send(("ready", warning, current_policy(), list(range(len(devices))), len(devices)))
    try:
        _serve(conn, objects)
    finally:
        emulators.stop()
        hub.stop()
        for device in devices:
            device.close()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
