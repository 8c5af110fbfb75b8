"""A graph of ugens with named outputs ``audio`` and ``haptic``.

The graph collects every ugen reachable from its outputs, names unnamed ones, checks that
required inputs are connected and that every cycle passes through a delay, and orders the
nodes topologically once. An edge into a delay ugen that lies on a cycle does not constrain
the order: such a delay emits from its past input first and ingests its current input
after the sub-block, so a loop through a delay of D samples is exact as long as no
sub-block exceeds D samples (:attr:`Graph.max_sub_block`). A delay not on a cycle is
ordered after its source like any other node.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

import numpy as np

from jassy.anytime import ModeBudget
from jassy.errors import PatchError
from jassy.ugen import UGen


def _as_list(outputs: UGen | Sequence[UGen] | None) -> list[UGen]:
    if outputs is None:
        return []
    if isinstance(outputs, UGen):
        return [outputs]
    return list(outputs)


class Graph:
    """Ugens wired together, ordered once, processed sub-block by sub-block."""

    def __init__(
        self,
        audio: UGen | Sequence[UGen],
        haptic: UGen | Sequence[UGen] | None = None,
        budget: ModeBudget | None = None,
    ):
        """``budget``: an anytime-synthesis mode budget shared by the graph's ModalBanks."""
        self.budget = budget
        self.audio = _as_list(audio)
        self.haptic = _as_list(haptic)
        if not self.audio:
            raise PatchError("outputs.audio: expected at least one node")
        if len(self.audio) > 2:
            raise PatchError(f"outputs.audio: expected 1 (mono) or 2 (stereo) nodes, got {len(self.audio)}")
        self.nodes: dict[str, UGen] = {}
        self._collect(self.audio + self.haptic)
        self._check_inputs()
        self._consumers = self._consumer_map()
        self.cycle_delays = [
            u for u in self.nodes.values() if u.is_delay and u.name in self._reachable(u.name)
        ]
        self.order = self._topological_order()
        self.delays = [u for u in self.order if u.is_delay]
        self._location_targets = {
            n: [u for u in self.downstream(n) if u.accepts_location] for n in self.nodes
        }
        self._struck = {n: self._first_resonators(n) for n in self.nodes}
        self.sample_rate: float | None = None

    # ------------------------------------------------------------------ building
    def _collect(self, roots: Iterable[UGen]) -> None:
        seen: list[UGen] = []
        stack = list(roots)
        while stack:
            node = stack.pop()
            if any(node is s for s in seen):
                continue
            seen.append(node)
            stack.extend(node.sources.values())
        counters: dict[str, int] = {}
        for node in seen:
            if node.name is not None:
                if node.name in self.nodes and self.nodes[node.name] is not node:
                    raise PatchError(f"node name {node.name!r} is used by two different ugens")
                self.nodes[node.name] = node
        is_tap = [node.is_tap for node in seen]
        for node, tap in zip(seen, is_tap, strict=True):
            if node.name is None and not tap:
                base = node.type_name.lower()
                while True:
                    counters[base] = counters.get(base, 0) + 1
                    candidate = f"{base}{counters[base]}"
                    if candidate not in self.nodes:
                        break
                node.name = candidate
                self.nodes[candidate] = node
        for node, tap in zip(seen, is_tap, strict=True):
            if node.name is None and tap:  # taps are named after their source: "node.output"
                node.name = f"{node.sources['source'].name}.{node.output}"
                self.nodes[node.name] = node

    def _check_inputs(self) -> None:
        for name, node in self.nodes.items():
            if node.variadic:
                if not node.sources and not node.optional_inputs:
                    raise PatchError(f"nodes.{name}: {node.type_name} needs at least one input")
                continue
            for inp in node.inputs:
                if inp not in node.sources and inp not in node.optional_inputs:
                    raise PatchError(f"nodes.{name}.{inp}: input not connected ({node.type_name} needs it)")

    def _topological_order(self) -> list[UGen]:
        """Kahn's algorithm on edges that are not into a delay; a leftover set is a cycle."""
        names = list(self.nodes)
        deps = {n: set() for n in names}
        for n, node in self.nodes.items():
            if any(node is d for d in self.cycle_delays):
                continue
            for src in node.sources.values():
                deps[n].add(src.name)
        order: list[str] = []
        ready = [n for n in names if not deps[n]]
        remaining = {n: set(d) for n, d in deps.items()}
        while ready:
            n = ready.pop(0)
            order.append(n)
            for m in names:
                if n in remaining[m]:
                    remaining[m].discard(n)
                    if not remaining[m] and m not in order and m not in ready:
                        ready.append(m)
        if len(order) != len(names):
            cyclic = sorted(set(names) - set(order))
            raise PatchError(
                "cycle without delay through nodes " + ", ".join(cyclic) + "; put a Delay node in the loop"
            )
        return [self.nodes[n] for n in order]

    def _consumer_map(self) -> dict[str, list[str]]:
        consumers: dict[str, list[str]] = {n: [] for n in self.nodes}
        for n, node in self.nodes.items():
            for src in node.sources.values():
                consumers[src.name].append(n)
        return consumers

    def _reachable(self, name: str) -> list[str]:
        """Names of the nodes fed, directly or indirectly, by node ``name``."""
        out: list[str] = []
        stack, seen = list(self._consumers[name]), set()
        while stack:
            m = stack.pop()
            if m in seen:
                continue
            seen.add(m)
            out.append(m)
            stack.extend(self._consumers[m])
        return out

    def _first_resonators(self, name: str) -> list[UGen]:
        """Location-accepting nodes fed by node ``name`` through no other such node."""
        out: list[UGen] = []
        stack, seen = list(self._consumers[name]), set()
        while stack:
            m = stack.pop()
            if m in seen:
                continue
            seen.add(m)
            if self.nodes[m].accepts_location:
                out.append(self.nodes[m])
            else:
                stack.extend(self._consumers[m])
        return out

    def struck_targets(self, name: str) -> list[UGen]:
        """The resonators (location-accepting nodes) whose force input an impact at node
        ``name`` drives: those it reaches without passing through another resonator (a
        bank fed by a struck bank hears that bank's output, not the impact)."""
        return self._struck[name]

    def downstream(self, name: str) -> list[UGen]:
        """Nodes fed (directly or indirectly) by node ``name``."""
        return [self.nodes[m] for m in self._reachable(name)]

    # ----------------------------------------------------------------- rendering
    def prepare(self, sample_rate: float, block: int) -> None:
        """Allocate every node for sub-blocks of at most ``block`` frames."""
        if block < 1:
            raise PatchError(f"block: expected an integer >= 1, got {block}")
        self.sample_rate = float(sample_rate)
        outputs: list[UGen] = []
        for node in self.audio + self.haptic:
            if not any(node is o for o in outputs):
                outputs.append(node)
        self.bus = np.zeros((len(outputs), block))
        rows = {id(node): i for i, node in enumerate(outputs)}
        self.bus_rows = np.array([rows[id(node)] for node in self.audio + self.haptic], dtype=np.int64)
        for node in self.order:
            node.prepare(sample_rate, block, self.bus[rows[id(node)]] if id(node) in rows else None)
        limit = block
        for d in self.cycle_delays:
            limit = min(limit, d.min_delay_samples())
        self.max_sub_block = limit
        #: What one sub-block runs, in order: every node's process, then delay commits; with
        #: a budget, its decision runs just before the first ModalBank.
        self.steps = [node.process for node in self.order] + [node.commit for node in self.delays]
        self.budgeted = [node for node in self.order if node.supports_budget]
        self.budget_renders = False  # the budget's step renders the banks (below)
        if self.budget is not None and self.budgeted:
            for node in self.budgeted:
                node.budgeted = True
            # the decision runs after everything the banks hear and before any bank (nodes
            # fed by no bank first: that keeps the order topological), so it can see the
            # force of the sub-block about to be rendered
            fed = {id(node) for bank in self.budgeted for node in [bank, *self.downstream(bank.name)]}
            early = [node.process for node in self.order if id(node) not in fed]
            late = [node.process for node in self.order if id(node) in fed]
            # when no bank hears a bank, the budget renders the banks itself, split only
            # where it decides (jassy.anytime.ModeBudget.step)
            total = sum(bank.model.n_modes for bank in self.budgeted)
            self.budget_renders = self.budget.decides(total) and not any(
                id(src) in fed for bank in self.budgeted for src in bank.sources.values()
            )
            if self.budget_renders:
                late = [node.process for node in self.order if id(node) in fed and not node.supports_budget]
            self.steps = early + [self.budget.step] + late + [node.commit for node in self.delays]

    def reset(self) -> None:
        for node in self.order:
            node.reset()

    def process(self, start: int, n: int) -> None:
        """Run every node for frames ``start .. start + n - 1`` (n <= max_sub_block).

        Output nodes write into rows of ``bus``; ``bus_rows`` lists the row of each audio
        channel, then of each haptic channel.
        """
        for step in self.steps:
            step(start, n)

    def location_targets(self, name: str) -> list[UGen]:
        """Ugens whose contact location follows impacts at node ``name``."""
        return self._location_targets[name]

    def summary(self) -> str:
        """Human-readable listing of nodes, connections and outputs."""
        lines = []
        for node in self.order:
            ins = ", ".join(f"{k}<-{v.name}" for k, v in node.sources.items())
            lines.append(f"  {node.name:<14} {node.type_name:<14} {ins}")
        lines.append(
            "  outputs: audio="
            + ",".join(u.name for u in self.audio)
            + " haptic="
            + (",".join(u.name for u in self.haptic) or "-")
        )
        return "\n".join(lines)
