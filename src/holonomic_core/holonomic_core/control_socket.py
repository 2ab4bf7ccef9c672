"""Control messages between our own processes: one pickled Python object per
packet of a ``SOCK_SEQPACKET`` Unix socket.

The ROS node and its control loop process, and the control loop and the
simulator's physics process (packages above this one, which this core does
not name), exchange their set-up, replies, logs and fault texts this way. A
sequenced-packet socket keeps each ``send`` one message (no length prefix,
no partial reads) and reports a peer that closed its end, or died (the
kernel closes a dead process's descriptors), as an empty packet:
end-of-file. Both ends are processes of this workspace started
by one another over a ``socket.socketpair``, so unpickling trusts the peer.

The cycle's data (commands, state records) does not go here: it travels as
fixed float64 records on pipes, which need no pickling.
"""

from __future__ import annotations

import pickle
import socket

#: the largest message [bytes] (a status with a long driver report); a
#: receiver reads at most this much of a packet
MAX_MESSAGE = 1 << 20


def send(sock: socket.socket, message) -> bool:
    """Send ``message`` (any picklable object) as one packet. False when the
    peer is gone or, on a non-blocking socket, its buffer is full: the
    sender never waits for the receiver (a control loop must not)."""
    try:
        sock.send(pickle.dumps(message, protocol=pickle.HIGHEST_PROTOCOL))
        return True
    except OSError:            # BrokenPipeError, ConnectionError, BlockingIOError, ...
        return False


def receive(sock: socket.socket, wait: bool = True):
    """The next message from ``sock``; None at end-of-file (the peer closed
    its end or died) or when the socket failed. Without ``wait``, or on a
    non-blocking socket, raises :class:`BlockingIOError` when no message is
    waiting (the caller polls). Messages are never None themselves."""
    try:
        data = sock.recv(MAX_MESSAGE, 0 if wait else socket.MSG_DONTWAIT)
    except BlockingIOError:
        raise
    except OSError:            # a reset or closed socket: the peer is gone
        return None
    return pickle.loads(data) if data else None
