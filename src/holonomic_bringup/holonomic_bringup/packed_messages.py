"""Publishing a fixed-layout message at 1 kHz without building it each time.

The node republishes odometry, joint states and /tf every control cycle (up
to 1 kHz). Through rclpy each publish converts the Python message field by
field into C and serializes it, for three topics a large part of a core at
1 kHz. But these messages have a fixed layout for a given robot -- the frame and joint names
and the array lengths never change -- so only their numbers change from one
cycle to the next.

:class:`PackedMessage` serializes a template message once, with the ROS
middleware's own serializer (``rclpy.serialization``). It finds where each
changing number lands in those bytes by giving every such field a marker
value first. Each publish then writes the cycle's numbers into a copy of the
bytes (one ``struct.pack_into`` per run of adjacent fields) and hands rclpy
the serialized message (``Publisher.publish(bytes)``), which skips the
conversion and the serialization.

It checks itself when built: sample numbers packed this way must
deserialize to the message holding the same numbers (compared as messages:
the serializer does not write the alignment padding after a string, so
those bytes are arbitrary). A middleware whose encoding does not fit (a
marker not found exactly once, fields out of order, a different result)
puts it in the plain mode, which sets the same fields on the message object
and publishes it as before. Either way the subscribers receive the same
message.
"""

from __future__ import annotations

import copy
import re
import struct

from rclpy.serialization import deserialize_message, serialize_message

#: ROS field type -> struct format character (little-endian CDR, as every
#: ROS 2 middleware on the CPUs robots use writes it)
_FORMATS = {"double": "d", "float64": "d", "int32": "i", "uint32": "I"}
_PATH = re.compile(r"(\w+)(?:\[(\d+)\])?$")


def _split(path: str) -> list[tuple[str, int | None]]:
    """'transforms[0].header.stamp.sec' -> [('transforms', 0), ('header', None), ...]."""
    parts = []
    for part in path.split("."):
        m = _PATH.match(part)
        if m is None:
            raise ValueError(f"not a field path: {path!r}")
        parts.append((m.group(1), None if m.group(2) is None else int(m.group(2))))
    return parts


def _field_format(msg, path: str) -> str:
    """The struct format character of the number at ``path`` in ``msg``."""
    obj = msg
    parts = _split(path)
    for name, index in parts[:-1]:
        obj = getattr(obj, name)
        if index is not None:
            obj = obj[index]
    name, index = parts[-1]
    ros_type = type(obj).get_fields_and_field_types()[name]
    if index is not None:            # double[36] or sequence<double>
        ros_type = re.sub(r"^sequence<(\w+)>$|^(\w+)\[\d+\]$",
                          lambda m: m.group(1) or m.group(2), ros_type)
    if ros_type not in _FORMATS:
        raise ValueError(f"{path}: type {ros_type} is not packed")
    return _FORMATS[ros_type]


def _setter(path: str):
    """A function (msg, value) -> None that sets the number at ``path``."""
    parts = _split(path)

    def set_value(msg, value) -> None:
        obj = msg
        for name, index in parts[:-1]:
            obj = getattr(obj, name)
            if index is not None:
                obj = obj[index]
        name, index = parts[-1]
        if index is None:
            setattr(obj, name, value)
        else:
            getattr(obj, name)[index] = value
    return set_value


def _marker(fmt: str, k: int):
    """The k-th marker value of a field of format ``fmt``: numbers no
    template holds (zeros, ones, small variances, ASCII names)."""
    if fmt == "d":
        return -1.2345678901234567e-211 * (k + 1)
    return 0x7E000000 + k            # fits int32 and uint32


class PackedMessage:
    """``template`` (a message whose strings and array lengths are final)
    published with only the numbers at ``paths`` changing; ``paths`` in the
    message's field order, e.g. ``("header.stamp.sec", "header.stamp.nanosec",
    "pose.pose.position.x", "pose.covariance[0]")``.

    :meth:`publish` takes the numbers in the order of ``paths``: int for
    int32/uint32 fields, float for double fields (seconds, metres, radians
    ... whatever the field holds). ``packed`` says which mode the self-check
    chose (see the module docstring)."""

    def __init__(self, publisher, template, paths: tuple[str, ...]):
        self._publisher = publisher
        self._msg = copy.deepcopy(template)
        #: the message type, e.g. 'nav_msgs/msg/Odometry'
        self.type_name = "{}/msg/{}".format(type(template).__module__.split(".")[0],
                                            type(template).__name__)
        self._paths = tuple(paths)
        self._formats = [_field_format(self._msg, p) for p in self._paths]
        self._setters = [_setter(p) for p in self._paths]
        self._bytes, self._runs = None, None
        #: why the plain mode was chosen (None: packed)
        self.why_plain: str | None = None
        try:
            self._runs, template_bytes = self._layout()
            self._bytes = bytearray(template_bytes)
            self._check()
        except ValueError as exc:
            self._runs, self._bytes, self.why_plain = None, None, str(exc)

    @property
    def packed(self) -> bool:
        """True: publishes serialized bytes; False: the message object."""
        return self._runs is not None

    def _filled(self, values):
        msg = copy.deepcopy(self._msg)
        for set_value, value in zip(self._setters, values):
            set_value(msg, value)
        return msg

    def _serialized(self, values) -> bytes:
        return serialize_message(self._filled(values))

    def _layout(self) -> tuple[list, bytes]:
        """Where the fields land: runs of adjacent fields, each
        (struct, byte offset, first field, end field); and the template's bytes."""
        markers = [_marker(f, k) for k, f in enumerate(self._formats)]
        marked = self._serialized(markers)
        offsets = []
        for path, fmt, value in zip(self._paths, self._formats, markers):
            pattern = struct.pack("<" + fmt, value)
            if marked.count(pattern) != 1:
                raise ValueError(f"{path}: its marker appears {marked.count(pattern)} times")
            offsets.append(marked.index(pattern))
        if offsets != sorted(offsets):
            raise ValueError("the fields are not in the serialized order")
        # one struct per run of adjacent fields: struct's pad bytes would
        # overwrite the constant bytes between them with zeros
        runs, first = [], 0
        for k in range(1, len(offsets) + 1):
            if k == len(offsets) or offsets[k] != offsets[k - 1] + struct.calcsize(
                    "<" + self._formats[k - 1]):
                runs.append((struct.Struct("<" + "".join(self._formats[first:k])),
                             offsets[first], first, k))
                first = k
        return runs, self._serialized([0 if f != "d" else 0.0 for f in self._formats])

    def _check(self) -> None:
        sample = [(k * 7919 + 1) if f != "d" else (k + 1) * -0.123456789 + 1e-3 * k
                  for k, f in enumerate(self._formats)]
        if deserialize_message(self.pack(sample), type(self._msg)) != self._filled(sample):
            raise ValueError("packed bytes differ from the middleware's serialization")

    def pack(self, values) -> bytes:
        """The serialized message holding ``values`` (packed mode only)."""
        buffer = self._bytes
        for run, offset, first, end in self._runs:
            run.pack_into(buffer, offset, *values[first:end])
        return bytes(buffer)

    def publish(self, values) -> None:
        """Publish the template with ``values`` at ``paths``."""
        if self._runs is not None:
            self._publisher.publish(self.pack(values))
        else:
            msg = self._msg
            for set_value, value in zip(self._setters, values):
                set_value(msg, value)
            self._publisher.publish(msg)
