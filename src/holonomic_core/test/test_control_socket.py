"""The control messages' framing (holonomic_core.control_socket), shared by
the node <-> loop wire and the loop <-> physics process link: one message per
packet, end-of-file as None, a sender that never waits."""

from __future__ import annotations

import socket
import subprocess
import sys

import pytest

from holonomic_core.control_socket import MAX_MESSAGE, receive, send


@pytest.fixture
def pair():
    a, b = socket.socketpair(socket.AF_UNIX, socket.SOCK_SEQPACKET)
    yield a, b
    a.close()
    b.close()


def test_messages_arrive_whole_one_per_receive_in_order(pair):
    a, b = pair
    first = ("ready", {"friction": [0.9, 1.1]}, 3)
    # 200 kB: far above one pipe write (4 kB) and below MAX_MESSAGE (1 MiB)
    second = ("status", "x" * 200_000)
    assert send(a, first) and send(a, second)
    assert receive(b) == first
    assert receive(b) == second


def test_nothing_waiting_raises_when_not_waiting_and_end_of_file_is_none(pair):
    a, b = pair
    with pytest.raises(BlockingIOError):
        receive(b, wait=False)
    a.close()
    # the peer closed its end: end-of-file, not an exception
    assert receive(b) is None
    assert receive(b, wait=False) is None


def test_a_dead_peer_process_reads_as_end_of_file_and_refuses_sends(pair):
    a, b = pair
    # the kernel closes a dead process's descriptors: a child holding the
    # only other copy of b, killed, leaves a at end-of-file
    child = subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"],
                             pass_fds=(b.fileno(),))
    b.close()
    child.kill()
    child.wait()
    assert receive(a) is None
    assert send(a, ("stop",)) is False


def test_a_full_receiver_makes_a_non_blocking_send_fail_not_wait(pair):
    a, b = pair
    a.setblocking(False)
    message = ("log", "y" * 10_000)
    sent = 0
    # the socket buffer (a few hundred kB by default) fills in at most
    # MAX_MESSAGE / 10 kB sends; each refused send returns at once
    while send(a, message):
        sent += 1
        assert sent < MAX_MESSAGE // 10_000 * 10, "the buffer never filled"
    assert sent >= 1
    assert receive(b) == message


def test_a_socket_already_closed_reads_as_end_of_file(pair):
    a, b = pair
    b.close()
    # recv on a closed socket fails (EBADF): the link is gone, not a crash
    assert receive(b) is None
    assert send(b, ("stop",)) is False
