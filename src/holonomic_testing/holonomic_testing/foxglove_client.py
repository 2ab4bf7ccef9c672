"""An independent Foxglove WebSocket client for the tests.

Written from the protocol (foxglove/ws-protocol's spec: JSON ops
``serverInfo``/``advertise``/``subscribe``/``status``, binary Message Data
= opcode 0x01, uint32 subscription id, uint64 receive time, payload;
client Message Data = 0x01, uint32 channel id, payload) and from the
foxglove.FrameTransforms protobuf schema (FrameTransform: 1 timestamp,
2 parent_frame_id, 3 child_frame_id, 4 translation, 5 rotation; Vector3
x/y/z = 1/2/3, Quaternion x/y/z/w = 1..4, doubles). It uses only the
``websockets`` library: none of the server's code.
"""

from __future__ import annotations

import json
import math
import struct
import threading
import time

from websockets.sync.client import connect

SUBPROTOCOL = "foxglove.sdk.v1"


def _varint(data: bytes, i: int) -> tuple[int, int]:
    value, shift = 0, 0
    while True:
        byte = data[i]
        i += 1
        value |= (byte & 0x7F) << shift
        if not byte & 0x80:
            return value, i
        shift += 7


def protobuf_fields(data: bytes) -> dict[int, list]:
    """Field number -> values (int, float from fixed64 as double, bytes)."""
    fields: dict[int, list] = {}
    i = 0
    while i < len(data):
        key, i = _varint(data, i)
        number, wire = key >> 3, key & 7
        if wire == 0:
            value, i = _varint(data, i)
        elif wire == 1:
            value = struct.unpack_from("<d", data, i)[0]
            i += 8
        elif wire == 2:
            length, i = _varint(data, i)
            value = data[i:i + length]
            i += length
        elif wire == 5:
            value = struct.unpack_from("<f", data, i)[0]
            i += 4
        else:
            raise ValueError(f"wire type {wire}")
        fields.setdefault(number, []).append(value)
    return fields


def _doubles(data: bytes, count: int) -> tuple[float, ...]:
    fields = protobuf_fields(data)            # proto3: a zero field is absent
    return tuple(fields.get(n, [0.0])[0] for n in range(1, count + 1))


def decode_frame_transforms(data: bytes) -> dict[str, tuple]:
    """child frame -> (parent, (x, y, z), (qx, qy, qz, qw))."""
    out = {}
    for item in protobuf_fields(data).get(1, []):
        f = protobuf_fields(item)
        parent = f.get(2, [b""])[0].decode()
        child = f.get(3, [b""])[0].decode()
        out[child] = (parent, _doubles(f.get(4, [b""])[0], 3), _doubles(f.get(5, [b""])[0], 4))
    return out


def yaw_of(q) -> float:
    x, y, z, w = q
    return math.atan2(2 * (w * z + x * y), 1 - 2 * (y * y + z * z))


def pitch_angle(q) -> float:
    """Angle [rad] of a rotation about y (a wheel on its axle), in (-pi, pi]."""
    return 2.0 * math.atan2(q[1], q[3])


class FoxgloveClient:
    """Connects, reads serverInfo and the advertised channels, subscribes,
    and collects every message in a background thread."""

    def __init__(self, port: int, timeout: float = 20.0):
        # a long-lived connection closed by close()/drop(), not a with-block
        self.ws = connect(f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL],
                          max_size=None, open_timeout=timeout, legacy=True)
        self.server_info = None
        self.channels: dict[str, dict] = {}     # topic -> advertised channel
        self.statuses: list[dict] = []
        self._subscriptions: dict[int, str] = {}
        self.messages: dict[str, list[tuple[float, bytes]]] = {}
        self._lock = threading.Lock()
        self._closed = threading.Event()
        end = time.monotonic() + timeout
        while self.server_info is None or not self.channels:
            self._handle(self.ws.recv(timeout=max(0.1, end - time.monotonic())))
        self._thread = threading.Thread(target=self._receive, daemon=True)
        self._thread.start()

    def _handle(self, frame) -> None:
        if isinstance(frame, bytes):
            if frame[0] == 0x01:
                sub_id = struct.unpack_from("<I", frame, 1)[0]
                topic = self._subscriptions.get(sub_id)
                if topic is not None:
                    with self._lock:
                        self.messages.setdefault(topic, []).append(
                            (time.monotonic(), frame[13:]))
            return
        msg = json.loads(frame)
        if msg["op"] == "serverInfo":
            self.server_info = msg
        elif msg["op"] == "advertise":
            for channel in msg["channels"]:
                self.channels[channel["topic"]] = channel
        elif msg["op"] == "status":
            with self._lock:
                self.statuses.append(msg)

    def _receive(self) -> None:
        while not self._closed.is_set():
            try:
                frame = self.ws.recv(timeout=0.2)
            except TimeoutError:
                continue
            except Exception:       # closed
                return
            self._handle(frame)

    def wait_channels(self, *topics: str, timeout: float = 20.0) -> None:
        """Wait until the server has advertised ``topics`` (robots join one by one)."""
        end = time.monotonic() + timeout
        while not set(topics) <= set(self.channels):
            if time.monotonic() > end:
                raise TimeoutError(f"channels {set(topics) - set(self.channels)} not advertised")
            time.sleep(0.02)

    def subscribe(self, *topics: str) -> None:
        subs = []
        for topic in topics:
            sub_id = len(self._subscriptions) + 1
            self._subscriptions[sub_id] = topic
            subs.append({"id": sub_id, "channelId": self.channels[topic]["id"]})
        self.ws.send(json.dumps({"op": "subscribe", "subscriptions": subs}))

    def count(self, topic: str) -> int:
        with self._lock:
            return len(self.messages.get(topic, []))

    def latest(self, topic: str) -> bytes | None:
        with self._lock:
            found = self.messages.get(topic)
            return found[-1][1] if found else None

    def since(self, topic: str, t0: float) -> list[tuple[float, bytes]]:
        with self._lock:
            return [m for m in self.messages.get(topic, []) if m[0] >= t0]

    def wait_for(self, topic: str, count: int = 1, timeout: float = 10.0) -> bytes:
        end = time.monotonic() + timeout
        while self.count(topic) < count:
            if time.monotonic() > end:
                raise TimeoutError(f"{count} messages on {topic}: got {self.count(topic)}")
            time.sleep(0.02)
        return self.latest(topic)

    def transforms(self) -> dict[str, tuple]:
        data = self.latest("/tf")
        return decode_frame_transforms(data) if data else {}

    def json(self, topic: str):
        return json.loads(self.wait_for(topic))

    def publish_json(self, channel_id: int, topic: str, schema_name: str, message: dict,
                     advertise: bool = True) -> None:
        """Advertise a client channel (once) and send one JSON message on it."""
        if advertise:
            self.ws.send(json.dumps({"op": "advertise", "channels": [{
                "id": channel_id, "topic": topic, "encoding": "json",
                "schemaName": schema_name}]}))
        self.ws.send(b"\x01" + struct.pack("<I", channel_id) + json.dumps(message).encode())

    def drop(self) -> None:
        """Vanish mid-stream: close the TCP socket without a closing handshake."""
        self._closed.set()
        self.ws.socket.close()

    def close(self) -> None:
        self._closed.set()
        try:
            self.ws.close()
        except Exception:
            pass
        self._thread.join(2.0)
