"""Haptic figures of ``jassy bench live``: UDP frame pacing and the device loop's
position-in to force-out latency."""

from __future__ import annotations

import socket
import time

import numpy as np

from jassy.engines.hapticframes import FLAG_FINAL, FrameRecorder, HapticFrame
from jassy.engines.hapticsender import (
    CLOCK_OFFSET,
    LATE,
    LOGGED_SENDS,
    LOST,
    REALTIME,
    SEND_DROPPED,
    SENT,
    jitter,
)


def frame_stats(live, frames: list[HapticFrame], receiver_dropped: int | None = None) -> dict:
    """Inter-frame send times (p1/p50/p99, ms) from the sender's own log, frames sent,
    frames lost and where: skipped by the sender (it fell a haptic ring behind), refused
    by its socket (send buffer full), dropped by the kernel at the receiving socket
    (``receiver_dropped``, its buffer full) and any other sequence gap at the receiver;
    and frames sent more than 0.5 ms after their samples began to play."""
    control = live.tap.control
    spacing = jitter(live.tap.send_times, int(control[LOGGED_SENDS]))
    sequence = np.array([f.sequence for f in frames if not f.flags & FLAG_FINAL])
    gaps = int(np.sum(np.diff(sequence) - 1)) if sequence.size > 1 else 0
    skipped, refused = int(control[LOST]), int(control[SEND_DROPPED])
    # every lost frame is a sequence gap at the receiver, whatever the cause
    return {
        "udp_frames_sent": int(control[SENT]),
        "udp_frames_received": len(frames),
        "udp_frames_lost": gaps,
        "udp_frames_skipped_by_sender": skipped,
        "udp_frames_refused_at_send": refused,
        "udp_frames_dropped_at_receiver_socket": receiver_dropped,
        "udp_frames_lost_otherwise": gaps - skipped - refused - (receiver_dropped or 0),
        "udp_frames_late": int(control[LATE]),
        "udp_sender_realtime": bool(control[REALTIME]),
        "udp_final_frame": bool(frames and frames[-1].flags & FLAG_FINAL),
        "frame_interval_p1_ms": spacing["p1_ms"],
        "frame_interval_p50_ms": spacing["p50_ms"],
        "frame_interval_p99_ms": spacing["p99_ms"],
        "frame_interval_max_ms": spacing["max_ms"],
    }


def _sample_at(frames: list[HapticFrame], t: float, offset: float, rate: float) -> float:
    """The stream frame playing at local monotonic time t, from the frames' device times."""
    times = np.array([f.device_time for f in frames]) + offset
    k = max(int(np.searchsorted(times, t)) - 1, 0)
    return frames[k].sample_time + (t - times[k]) * rate


def loop_latency(
    presses: int = 10, sample_rate: float = 48000, block: int = 64, ring_blocks: float = 2.5
) -> dict:
    """Position in -> force out, in samples: a UDP pose touching the plate of the demo's
    scrape scene (a tap), from the moment it is sent to the first sample of the tap's
    force the device plays (monitor), mapped onto the stream clock by the UDP frames'
    device times; in the mode the live scenes use (callback where the graph allows).
    Needs a running (JACK) device; the caller provides it."""
    from jassy.engines.live import LiveEngine
    from jassy.engines.probeinput import PoseDriver, PoseReceiver, encode_pose
    from patches.demo import Probe, build_scene

    recorder = FrameRecorder(process=True)  # receiving here would hold this interpreter
    seconds = presses * 0.4 + 1.0
    live = LiveEngine(
        build_scene("scrape"),
        [],
        sample_rate,
        block,
        ring_blocks,
        monitor_seconds=seconds,
        haptic_udp=recorder.address,
        mode="auto",
    )
    live.start()
    probe = Probe(live.post, live=True)
    receiver = PoseReceiver(PoseDriver(probe))
    host, port = receiver.address.rsplit(":", 1)
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sent = []
    try:
        for k in range(presses):
            sock.sendto(encode_pose(3 * k, time.monotonic(), (0.1, 0.0, 0.01)), (host, int(port)))
            time.sleep(0.1 + 0.01 * (k % 3))  # presses fall at every phase of the block
            sent.append(time.monotonic())
            sock.sendto(encode_pose(3 * k + 1, sent[-1], (0.1, 0.0, -0.001)), (host, int(port)))
            time.sleep(0.15)
            sock.sendto(encode_pose(3 * k + 2, time.monotonic(), (0.1, 0.0, 0.01)), (host, int(port)))
            time.sleep(0.15)
    finally:
        sock.close()
        receiver.close()
        stats = live.stop()
    frames = [f for f in recorder.stop() if not f.flags & FLAG_FINAL]
    heard, _ = live.monitor()
    force = heard[-1]
    first = stats.frames_played - force.size  # stream frame of force[0]
    offset = float(live.tap.control[CLOCK_OFFSET])
    latencies, missed = [], 0
    for t in sent:
        s = _sample_at(frames, t, offset, sample_rate)
        after = np.flatnonzero((np.arange(force.size) + first >= s) & (force != 0))
        if after.size and first + after[0] - s < 0.1 * sample_rate:
            latencies.append(first + after[0] - s)
        else:  # no force within 100 ms of the touch: the tap never played
            missed += 1
    lat = np.array(latencies)
    return {
        "loop_presses": len(sent),
        "loop_missed": missed,
        "position_to_force_p50_samples": float(np.median(lat)) if lat.size else float("nan"),
        "position_to_force_max_samples": float(lat.max()) if lat.size else float("nan"),
        "loop_mode": stats.mode,
        "loop_engine_latency_samples": stats.latency * sample_rate,
    }
