"""A CAN bus between processes of one machine, for emulated drives in a
process of their own: python-can interface ``holonomic_ipc``.

python-can's ``virtual`` bus joins the buses of one process only. Here a
:class:`BusHub` in the drives' process joins that process's virtual channel
(the emulated drives) with every :class:`IpcBus` that connects to its Unix
socket (the driver under test, a sniffer, a test script), so that the
driver opens the bus the way it opens ``socketcan``:
``can.Bus(interface="holonomic_ipc", channel="/path/of/the/hub/socket")``.

Why not python-can's own: socketcan on ``vcan`` needs the kernel module
(not loadable in these containers); ``udp_multicast`` needs msgpack and
sends to a multicast group on the default route -- onto the network, and
into every other test run on the machine using the same group and port.
A Unix socket in a private folder reaches this machine's processes only,
and only the rig's.

Each frame is one ``SOCK_SEQPACKET`` datagram: a 16-byte header (kind,
flags, dlc, send time [s, wall clock], arbitration id) and the data. A
frame is stamped with ``time.time()`` when sent (as the virtual bus does;
``preserve_timestamps=True`` keeps the sender's stamp: the emulated drives
stamp their answers as a real drive would). The hub forwards each frame to
every other client and into its virtual channel; it never blocks on a slow
client (one queue per client).

:meth:`IpcBus.barrier` returns once every frame that any client had sent
before the call has reached this bus, the drives and the other clients'
sockets: a test's sniffer sees what the driver just sent, and the driver
what a test script just sent, as on python-can's synchronous virtual bus.
What the drives send stays asynchronous, as on a real bus.
"""

from __future__ import annotations

import collections
import itertools
import os
import select
import socket
import struct
import threading
import time
from typing import Any

import can
from can import BusABC, CanInterfaceNotImplementedError, CanOperationError, Message

#: kind, flags, dlc, pad, timestamp [s], arbitration id
_HEADER = struct.Struct("<BBBxdI")
_FRAME, _BARRIER, _BARRIER_DONE = 0, 1, 2
_EXTENDED, _REMOTE, _ERROR, _FD, _BRS, _ESI = (1 << k for k in range(6))
_MAX_PACKET = _HEADER.size + 64


def pack(msg: Message, timestamp: float, kind: int = _FRAME) -> bytes:
    """One frame as a datagram, stamped ``timestamp`` [s, wall clock]."""
    flags = ((_EXTENDED if msg.is_extended_id else 0) | (_REMOTE if msg.is_remote_frame else 0)
             | (_ERROR if msg.is_error_frame else 0) | (_FD if msg.is_fd else 0)
             | (_BRS if msg.bitrate_switch else 0) | (_ESI if msg.error_state_indicator else 0))
    return _HEADER.pack(kind, flags, msg.dlc, timestamp, msg.arbitration_id) + bytes(msg.data)


def unpack(packet: bytes, channel: Any = None) -> tuple[int, Message]:
    """(kind, message) of a datagram."""
    kind, flags, dlc, timestamp, arbitration_id = _HEADER.unpack_from(packet)
    msg = Message(timestamp=timestamp, arbitration_id=arbitration_id,
                  is_extended_id=bool(flags & _EXTENDED), is_remote_frame=bool(flags & _REMOTE),
                  is_error_frame=bool(flags & _ERROR), is_fd=bool(flags & _FD),
                  bitrate_switch=bool(flags & _BRS), error_state_indicator=bool(flags & _ESI),
                  dlc=dlc, data=packet[_HEADER.size:], channel=channel, is_rx=True)
    return kind, msg


class IpcBus(BusABC):
    """A node on the bus of the :class:`BusHub` listening at ``channel`` (a
    Unix socket path). ``preserve_timestamps``: as python-can's virtual bus
    (keep the stamp of the sent Message instead of the send time)."""

    def __init__(self, channel: str, receive_own_messages: bool = False,
                 preserve_timestamps: bool = False, **kwargs: Any):
        if receive_own_messages:
            raise CanInterfaceNotImplementedError("holonomic_ipc: no receive_own_messages")
        kwargs.pop("bitrate", None)                 # no wire: any bit rate
        super().__init__(channel=channel, **kwargs)
        self.channel_info = f"holonomic_ipc hub {channel}"
        self.preserve_timestamps = preserve_timestamps
        self._sock = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        try:
            self._sock.connect(str(channel))
        except OSError as exc:
            self._sock.close()
            raise CanOperationError(f"no holonomic_ipc hub at {channel} ({exc})") from exc
        self._backlog: collections.deque[Message] = collections.deque()
        self._tokens = itertools.count(1)
        self._send_lock = threading.Lock()

    def send(self, msg: Message, timeout: float | None = None) -> None:
        stamp = msg.timestamp if self.preserve_timestamps else time.time()
        try:
            with self._send_lock:
                self._sock.send(pack(msg, stamp))
        except OSError as exc:
            raise CanOperationError(f"holonomic_ipc: the hub is gone ({exc})") from exc

    def _recv_internal(self, timeout: float | None) -> tuple[Message | None, bool]:
        if self._backlog:
            return self._backlog.popleft(), False
        deadline = None if timeout is None else time.monotonic() + timeout
        while True:
            left = None if deadline is None else max(0.0, deadline - time.monotonic())
            if not select.select([self._sock], [], [], left)[0]:
                return None, False
            kind, msg = self._read()
            if kind == _FRAME:
                return msg, False

    def _read(self) -> tuple[int, Message]:
        packet = self._sock.recv(_MAX_PACKET)
        if not packet:
            raise CanOperationError("holonomic_ipc: the hub closed the bus")
        return unpack(packet, self.channel_info)

    def barrier(self, timeout: float = 10.0) -> None:
        """Return once every frame sent by any client before this call has
        reached this bus, the drives and the other clients' sockets (unless
        one of them has fallen a whole socket buffer behind); frames that
        arrive meanwhile are kept for ``recv``. Only on a bus that no other
        thread reads."""
        token = next(self._tokens)
        with self._send_lock:
            self._sock.send(_HEADER.pack(_BARRIER, 0, 0, 0.0, token))
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if left <= 0 or not select.select([self._sock], [], [], left)[0]:
                raise CanOperationError(f"holonomic_ipc: no barrier reply within {timeout} s")
            kind, msg = self._read()
            if kind == _FRAME:
                self._backlog.append(msg)
            elif kind == _BARRIER_DONE and msg.arbitration_id == token:
                return

    def fileno(self) -> int:
        return self._sock.fileno()

    def shutdown(self) -> None:
        super().shutdown()
        self._sock.close()


class BusHub:
    """The bus: joins the virtual ``channel`` of this process (the emulated
    drives) and the :class:`IpcBus` clients connecting to the Unix socket
    ``path``. Two threads: one serves the sockets, one forwards what the
    local buses send (a virtual bus cannot be waited on with select)."""

    def __init__(self, path: str, channel: str):
        self.path = path
        self._listener = socket.socket(socket.AF_UNIX, socket.SOCK_SEQPACKET)
        self._listener.bind(path)
        self._listener.listen(16)
        self._listener.setblocking(False)
        self._local = can.Bus(interface="virtual", channel=channel, preserve_timestamps=True)
        #: client socket -> datagrams waiting to be sent to it
        self._clients: dict[socket.socket, collections.deque[bytes]] = {}
        self._lock = threading.Lock()
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_r, False)
        os.set_blocking(self._wake_w, False)
        self._stop = threading.Event()
        self._threads = [threading.Thread(target=self._serve, name="bus-hub", daemon=True),
                         threading.Thread(target=self._pump, name="bus-hub-local", daemon=True)]

    def start(self) -> "BusHub":
        for thread in self._threads:
            thread.start()
        return self

    def stop(self) -> None:
        self._stop.set()
        self._wake()
        for thread in self._threads:
            if thread.is_alive():
                thread.join(timeout=2.0)
        for client in list(self._clients):
            client.close()
        self._listener.close()
        self._local.shutdown()
        os.close(self._wake_r)
        os.close(self._wake_w)

    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"\0")
        except BlockingIOError:
            pass                    # already awake

    def _pump(self) -> None:
        """Frames sent on the local virtual channel -> every client."""
        while not self._stop.is_set():
            msg = self._local.recv(timeout=0.2)
            if msg is None:
                continue
            packet = pack(msg, msg.timestamp)
            with self._lock:
                for queue in self._clients.values():
                    queue.append(packet)
            self._wake()

    def _serve(self) -> None:
        while not self._stop.is_set():
            self.serve_once(0.5)

    def serve_once(self, timeout: float) -> None:
        """One round of the hub's thread (by hand when not started): wait up
        to ``timeout`` [s] for a connection or a frame, forward what came."""
        with self._lock:
            clients = list(self._clients)
            waiting = [c for c in clients if self._clients[c]]
        readable, _, _ = select.select([self._listener, self._wake_r, *clients], waiting, [],
                                       timeout)
        for sock in readable:
            if sock is self._listener:
                self._accept()
            elif sock == self._wake_r:
                while True:
                    try:
                        if not os.read(self._wake_r, 4096):
                            break
                    except BlockingIOError:
                        break
            else:
                self._read_from(sock, drain_others=True)
        with self._lock:
            clients = list(self._clients)
        for sock in clients:
            self._flush(sock)

    def _accept(self) -> None:
        while True:
            try:
                client, _ = self._listener.accept()
            except BlockingIOError:
                return
            client.setblocking(False)
            with self._lock:
                self._clients[client] = collections.deque()

    def _drop(self, client: socket.socket) -> None:
        with self._lock:
            self._clients.pop(client, None)
        client.close()

    def _read_from(self, client: socket.socket, drain_others: bool) -> None:
        """Everything ``client`` has sent so far: frames to the others and
        the drives; a barrier is answered once every other client's frames
        sent before it are through too."""
        while True:
            try:
                packet = client.recv(_MAX_PACKET)
            except BlockingIOError:
                return
            except ConnectionResetError:
                # the client closed with frames of ours unread: Linux reports
                # that once, before the frames it sent last (still queued)
                continue
            except OSError:
                packet = b""
            if not packet:
                self._drop(client)
                return
            kind, msg = unpack(packet)
            if kind == _FRAME:
                self._local.send(msg)           # to the drives, stamp kept
                with self._lock:
                    for other, queue in self._clients.items():
                        if other is not client:
                            queue.append(packet)
            elif kind == _BARRIER:
                if drain_others:
                    with self._lock:
                        others = [c for c in self._clients if c is not client]
                    for other in others:
                        self._read_from(other, drain_others=False)
                    for other in others:
                        self._flush(other)
                done = _HEADER.pack(_BARRIER_DONE, 0, 0, 0.0, msg.arbitration_id)
                with self._lock:
                    if client in self._clients:
                        self._clients[client].append(done)

    def _flush(self, client: socket.socket) -> None:
        while True:
            with self._lock:
                queue = self._clients.get(client)
                if not queue:
                    return
                packet = queue[0]
            try:
                client.send(packet)
            except BlockingIOError:
                return
            except OSError:
                self._drop(client)
                return
            with self._lock:
                queue.popleft()
