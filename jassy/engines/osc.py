"""OSC control of a running patch (after SDT's sdtOSC), over UDP with python-osc.

Addresses:

* ``/NODE/PARAM value [ramp]``: set a parameter (ramped over ``ramp`` s if given, else
  the node's ``smooth`` time);
* ``/NODE/ACTION key value ...``: an action of the node (e.g. ``/hit/impact impulse 0.5``);
* ``/event NODE ACTION key value ...``: the same, with the node and action as arguments
  (ACTION may be ``set``).

A message outside a bundle, or in a bundle whose time tag is "immediately" or already
past, applies as soon as possible. A bundle with a future time tag applies at the
sample of its time: engine time = time tag - ``origin`` (the wall-clock time, in Unix
seconds, of the engine's frame 0). Messages are checked like score events (node,
parameter or action, type and range); a bad one is reported once (each distinct
error, through ``report``) and ignored: it never stops the stream. Events reach the
engine through ``post`` (e.g. :meth:`jassy.engines.live.LiveEngine.post`).
"""

from __future__ import annotations

import socketserver
import sys
import threading
from collections.abc import Callable

from pythonosc import osc_bundle, osc_message
from pythonosc.parsing import osc_types

from jassy.errors import JassyError, PatchError, suggest
from jassy.events import Event
from jassy.graph import Graph
from jassy.scheduler import validate_event

DEFAULT_HOST = "127.0.0.1"


def parse_address(text: str, option: str = "--osc") -> tuple[str, int]:
    """(host, port) from ``HOST:PORT``, ``:PORT`` or ``PORT`` (host 127.0.0.1)."""
    host, _, port = text.rpartition(":")
    try:
        number = int(port)
    except ValueError:
        number = -1
    if not 0 < number < 65536:
        raise JassyError(f"{option}: expected HOST:PORT with a port in 1..65535, got {text!r}")
    return host or DEFAULT_HOST, number


def timed_messages(dgram: bytes) -> list[tuple[float | None, osc_message.OscMessage]]:
    """The messages of a datagram with their bundle's time tag (Unix s; None: at once)."""
    if osc_bundle.OscBundle.dgram_is_bundle(dgram):
        return _bundle_messages(osc_bundle.OscBundle(dgram))
    return [(None, osc_message.OscMessage(dgram))]


def _bundle_messages(bundle: osc_bundle.OscBundle) -> list[tuple[float | None, osc_message.OscMessage]]:
    tag = None if bundle.timestamp == osc_types.IMMEDIATELY else bundle.timestamp
    found: list[tuple[float | None, osc_message.OscMessage]] = []
    for content in bundle:
        if isinstance(content, osc_message.OscMessage):
            found.append((tag, content))
        else:
            found.extend(_bundle_messages(content))
    return found


def message_event(graph: Graph, address: str, args: list, time: float) -> Event:
    """The score event an OSC message stands for, validated; PatchError if it is bad."""
    where = f"OSC {address}"
    parts = [p for p in address.split("/") if p]
    if parts == ["event"]:
        if len(args) < 2 or not all(isinstance(a, str) for a in args[:2]):
            raise PatchError(f"{where}: expected NODE ACTION [key value ...], got {args!r}")
        node, action, pairs = args[0], args[1], args[2:]
        return validate_event(graph, Event(time, node, action, _pairs(pairs, where)), where)
    if len(parts) != 2:
        raise PatchError(f"{where}: expected /NODE/PARAM, /NODE/ACTION or /event")
    node_name, name = parts
    node = graph.nodes.get(node_name)
    if node is None:
        raise PatchError(
            f"{where}: unknown node {node_name!r}; nodes are {', '.join(graph.nodes)}"
            f"{suggest(node_name, graph.nodes)}"
        )
    if name in node.actions:
        return validate_event(graph, Event(time, node_name, name, _pairs(args, where)), where)
    if len(args) not in (1, 2):
        raise PatchError(f"{where}: expected a value and an optional ramp time (s), got {args!r}")
    ramp = args[1] if len(args) == 2 else None
    return validate_event(graph, Event(time, node_name, "set", {name: args[0]}, ramp=ramp), where)


def _pairs(args: list, where: str) -> dict:
    if len(args) % 2 or not all(isinstance(k, str) for k in args[::2]):
        raise PatchError(f"{where}: expected key value pairs, got {args!r}")
    return dict(zip(args[::2], args[1::2], strict=True))


def _report_to_stderr(text: str) -> None:
    print(f"jassy: OSC: {text}", file=sys.stderr, flush=True)


class OscControl:
    """A UDP OSC server posting the events of its messages to a running engine."""

    def __init__(
        self,
        graph: Graph,
        post: Callable[[Event], None],
        origin: float,
        host: str = DEFAULT_HOST,
        port: int = 9000,
        report: Callable[[str], None] = _report_to_stderr,
    ):
        self.graph = graph
        self.post = post
        self.origin = origin
        self.report = report
        self.reported: set[str] = set()
        self.received = 0
        control = self

        class Handler(socketserver.BaseRequestHandler):
            def handle(self) -> None:
                control.handle(self.request[0])

        try:
            self.server = socketserver.UDPServer((host, port), Handler)
        except OSError as exc:
            raise JassyError(f"--osc: cannot listen on {host}:{port} ({exc.strerror})") from None
        self.address = self.server.server_address
        self.thread = threading.Thread(target=self.server.serve_forever, name="jassy-osc", daemon=True)

    def start(self) -> OscControl:
        self.thread.start()
        return self

    def stop(self) -> None:
        self.server.shutdown()
        self.server.server_close()
        self.thread.join(timeout=2.0)

    def handle(self, dgram: bytes) -> None:
        """Post the events of one datagram; report (once) and drop whatever is bad."""
        try:
            messages = timed_messages(dgram)
        except (osc_bundle.ParseError, osc_message.ParseError, ValueError) as exc:
            self._report(f"cannot parse a datagram ({exc})")
            return
        for tag, message in messages:
            self.received += 1
            time = 0.0 if tag is None else max(tag - self.origin, 0.0)
            try:
                event = message_event(self.graph, message.address, list(message.params), time)
            except (PatchError, TypeError, ValueError) as exc:
                self._report(str(exc) if isinstance(exc, PatchError) else f"OSC {message.address}: {exc}")
                continue
            self.post(event)

    def _report(self, text: str) -> None:
        if text not in self.reported:
            self.reported.add(text)
            self.report(f"{text} (ignored)")
