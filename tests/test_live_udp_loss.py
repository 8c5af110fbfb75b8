"""Where UDP haptic frames are lost: counted at the sender and at the receiving socket."""

import socket
from types import SimpleNamespace

import numpy as np
import pytest

from jassy.apps.bench_haptic import frame_stats
from jassy.engines.hapticframes import FLAG_FINAL, RECEIVE_BUFFER, FrameReceiver, encode
from jassy.engines.hapticsender import CONTROL_SLOTS, LOST, SEND_DROPPED, SENT, _send

pytestmark = pytest.mark.timeout(60)


def _frame(sequence: int, flags: int = 0) -> bytes:
    return encode(sequence, 48 * sequence, 0.0, flags, np.ones(1), np.zeros(0), 48000.0)


def test_receiver_counts_what_the_kernel_dropped():
    receiver = FrameReceiver(timeout=0.2)
    receiver.sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)  # overflows after a few
    host, port = receiver.address.rsplit(":", 1)
    tx = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent = 0
    received = []
    try:
        for _burst in range(3):  # bursts far larger than the buffer, drained in between
            for _ in range(400):
                tx.sendto(_frame(sent), (host, int(port)))
                sent += 1
            while (frame := receiver.receive(0.2)) is not None:
                received.append(frame.sequence)
        tx.sendto(_frame(sent), (host, int(port)))  # carries the count of the last burst's drops
        sent += 1
        received.append(receiver.receive(1.0).sequence)
    finally:
        tx.close()
        receiver.close()
    if receiver.dropped is None:
        pytest.skip("this OS does not report a socket's dropped datagrams (SO_RXQ_OVFL)")
    gaps = int(np.sum(np.diff(received) - 1))
    assert receiver.dropped > 0
    assert receiver.dropped == gaps == sent - len(received)


def test_receiver_asks_for_a_large_buffer():
    with open("/proc/sys/net/core/rmem_max") as fh:
        allowed = int(fh.read())
    receiver = FrameReceiver()
    try:  # Linux grants min(request, rmem_max) (all of it with CAP_NET_ADMIN) and reports twice
        # that; a socket that never asked reports rmem_default (~208 KiB), below this bound
        granted = receiver.sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
        assert granted >= 2 * min(RECEIVE_BUFFER, allowed)
    finally:
        receiver.close()


def test_refused_send_is_counted_not_raised():
    control = np.zeros(CONTROL_SLOTS)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.setblocking(False)
    try:  # broadcast without SO_BROADCAST: the kernel refuses (EACCES)
        assert not _send(sock, _frame(0), ("255.255.255.255", 9), control)
        receiver = FrameReceiver()
        host, port = receiver.address.rsplit(":", 1)
        assert _send(sock, _frame(1), (host, int(port)), control)
        assert receiver.receive(1.0).sequence == 1
        receiver.close()
    finally:
        sock.close()
    assert control[SEND_DROPPED] == 1 and control[SENT] == 1


def test_bench_splits_losses_by_cause():
    control = np.zeros(CONTROL_SLOTS)
    control[LOST], control[SEND_DROPPED], control[SENT] = 5, 2, 90
    live = SimpleNamespace(tap=SimpleNamespace(control=control, send_times=np.zeros(0)))
    sequence = [s for s in range(100) if not 10 <= s < 15 and s not in (20, 21, 30, 31, 32)]
    frames = [SimpleNamespace(sequence=s, flags=0) for s in sequence]
    frames.append(SimpleNamespace(sequence=100, flags=FLAG_FINAL))
    stats = frame_stats(live, frames, receiver_dropped=3)
    assert stats["udp_frames_lost"] == 10
    assert stats["udp_frames_skipped_by_sender"] == 5
    assert stats["udp_frames_refused_at_send"] == 2
    assert stats["udp_frames_dropped_at_receiver_socket"] == 3
    assert stats["udp_frames_lost_otherwise"] == 0
