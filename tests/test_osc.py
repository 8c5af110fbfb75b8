"""OSC control with a real python-osc client: parameter changes, actions, time-tagged
bundles at their sample, bad messages reported once and ignored; live on JACK's dummy
driver."""

import time

import numpy as np
import pytest
from pythonosc.osc_bundle_builder import OscBundleBuilder
from pythonosc.osc_message_builder import OscMessageBuilder
from pythonosc.udp_client import SimpleUDPClient

from jassy import Event, Graph, JassyError, render
from jassy.engines.osc import OscControl, parse_address
from ugens import Gain, ImpactForce

FS = 48000


def graph():
    hit = ImpactForce(name="hit", duration=0.001)
    return Graph(Gain(hit, name="g", gain=1.0), haptic=hit)


def wait_for(predicate, seconds=3.0):
    end = time.monotonic() + seconds
    while not predicate() and time.monotonic() < end:
        time.sleep(0.01)
    assert predicate(), "timed out waiting for the OSC server"


def bundle(at, *messages):
    b = OscBundleBuilder(at)
    for address, args in messages:
        m = OscMessageBuilder(address=address)
        for a in args:
            m.add_arg(a)
        b.add_content(m.build())
    return b.build()


def test_messages_become_events_and_bundles_keep_their_sample_time():
    g, events, reports = graph(), [], []
    origin = time.time()
    control = OscControl(g, events.append, origin=origin, port=0, report=reports.append).start()
    try:
        client = SimpleUDPClient(*control.address)
        client.send_message("/g/gain", [0.5, 0.01])
        client.send_message("/hit/impact", ["impulse", 0.02])
        client.send_message("/event", ["hit", "impact", "impulse", 0.03])
        at = origin + 3600.0 + 1234.5 / FS  # a time tag an hour ahead, between two samples
        client.send(bundle(at, ("/hit/impact", ["impulse", 0.04]), ("/g/gain", [0.25])))
        wait_for(lambda: len(events) == 5)
    finally:
        control.stop()
    assert [e.action for e in events] == ["set", "impact", "impact", "impact", "set"]
    # OSC floats are 32-bit
    first = events[0]
    assert (first.time, first.node, first.args) == (0.0, "g", {"gain": 0.5}) and first.ramp == pytest.approx(
        0.01
    )
    assert events[1].args["impulse"] == pytest.approx(0.02) and events[2].args["impulse"] == pytest.approx(
        0.03
    )
    # OSC time tags are 32.32 fixed point: 2^-32 s, far below a sample
    assert abs(events[3].time - (3600.0 + 1234.5 / FS)) < 1e-6 and events[3].time == events[4].time
    assert reports == []
    # the scheduled impact, rendered, starts at the sample after its time (as any score event)
    shifted = [Event(e.time - 3600.0, e.node, e.action, e.args) for e in events[3:4]]
    force = render(graph(), shifted, 0.1, FS, 64, limiter=False).haptic[0]
    assert np.flatnonzero(force)[0] == 1235


def test_bad_messages_are_reported_once_and_ignored():
    g, events, reports = graph(), [], []
    control = OscControl(g, events.append, origin=time.time(), port=0, report=reports.append).start()
    try:
        client = SimpleUDPClient(*control.address)
        for _ in range(2):
            client.send_message("/nope/gain", 1.0)  # unknown node
            client.send_message("/g/gian", 1.0)  # unknown parameter
            client.send_message("/g/gain", "loud")  # wrong type
            client.send_message("/hit/impact", ["impulse", -1.0])  # out of range
            client.send_message("/event", [1, 2])  # malformed
        client.send_message("/g/gain", 0.3)  # and the stream goes on
        wait_for(lambda: control.received == 11)
    finally:
        control.stop()
    assert len(events) == 1 and events[0].args["gain"] == pytest.approx(0.3)
    assert len(reports) == 5 and len(set(reports)) == 5
    assert "unknown node 'nope'" in reports[0] and "no parameter 'gian'" in reports[1]


def test_address_option():
    assert parse_address("127.0.0.1:9000") == ("127.0.0.1", 9000)
    assert parse_address(":57120") == ("127.0.0.1", 57120)
    with pytest.raises(JassyError, match="--osc: expected HOST:PORT"):
        parse_address("localhost:http")


def test_live_engine_plays_an_osc_impact(jack):
    from jassy.engines.live import LiveEngine

    live = LiveEngine(graph(), [], FS, 64, ring_blocks=3, monitor_seconds=2.0)
    live.start()
    control = OscControl(live.graph, live.post, origin=time.time(), port=0).start()
    try:
        time.sleep(0.2)
        SimpleUDPClient(*control.address).send_message("/hit/impact", ["impulse", 0.01])
        wait_for(lambda: control.received == 1)
        time.sleep(0.3)
    finally:
        control.stop()
        live.stop()
    heard, _ = live.monitor()
    assert np.max(np.abs(heard[0])) > 0.0  # the impact reached the device


def test_cli_play_with_osc(jack, capsys):
    import socket

    from jassy.apps.cli import main

    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    assert main(["play", "bar", "--duration", "0.3", "-q", "--osc", f"127.0.0.1:{port}"]) == 0
    assert f"OSC on 127.0.0.1:{port}" in capsys.readouterr().out
    assert main(["play", "bar", "--duration", "0.3", "--osc", "127.0.0.1:nope"]) == 2
    assert "--osc: expected HOST:PORT" in capsys.readouterr().err
