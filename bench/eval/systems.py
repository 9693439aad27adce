"""The systems under test and their ground truth: which nodes a member stands for, true root causes."""

from __future__ import annotations

from collections.abc import Mapping

from stream_viz.demo.topology import DEMO, Topology
from stream_viz.model.ids import make_id

# From this size on, generated systems run at 0.5-1 Hz with 25 nodes per process: at the demo's
# 2-5 Hz and 8 per process a 500-node system alone saturates 2 cores (docs/demo.md).
LARGE = 300


def system_topology(name: str, seed: int = 0) -> Topology:
    """``demo``, ``amr`` (the warehouse AMR) or ``gen<N>`` (a generated layered system of N nodes, seeded)."""
    if name == "demo":
        return DEMO
    if name == "amr":
        from stream_viz.demo.amr.topology import AMR

        return AMR
    if name.startswith("gen"):
        from stream_viz.demo.generated import generate

        n = int(name[3:])
        if n >= LARGE:
            return generate(n, seed=seed, rate=(0.5, 1.0), nodes_per_process=25)
        return generate(n, seed=seed)
    raise ValueError(f"unknown system {name!r}: demo, amr or gen<N>")


def expand_map(topo: Topology, process_names: Mapping[str, str]) -> dict[str, list[str]]:
    """Member → the nodes it stands for: a node itself, a topic its publishers, a process its nodes."""
    out: dict[str, list[str]] = {make_id("node", n): [make_id("node", n)] for n in topo.node_names()}
    for src, dst, kind in sorted(topo.edges()):
        if kind == "pub":
            out.setdefault(dst, []).append(src)
    for proc, group in process_names.items():
        out[proc] = [make_id("node", n.name) for n in topo.group(group).nodes]
    return out


def truth_sets(topo: Topology, target: str) -> tuple[set[str], set[str]]:
    """(strict, process-level) truth: the target node; every node of the target's process."""
    target = "/" + target.removeprefix("node:").lstrip("/")
    group = topo.group(topo.group_of(target))
    return {make_id("node", target)}, {make_id("node", n.name) for n in group.nodes}


def pick_targets(topo: Topology, k: int) -> list[str]:
    """``k`` nodes with the most downstream nodes (faults there propagate; the hard case)."""
    succ: dict[str, set[str]] = {}
    for src, dst, _ in topo.edges():
        succ.setdefault(src, set()).add(dst)

    def downstream(n: str) -> int:
        seen, stack = {n}, [n]
        while stack:
            for x in succ.get(stack.pop(), ()):
                if x not in seen:
                    seen.add(x)
                    stack.append(x)
        return sum(1 for x in seen if x.startswith("node:")) - 1

    nodes = [make_id("node", n) for n in topo.node_names() if n != topo.diag_monitor()]
    return sorted(nodes, key=lambda n: (-downstream(n), n))[:k]


def sink_watchlist(topo: Topology) -> set[str]:
    """What a user would name as important: the system's outputs (sink nodes, their inputs, unread topics)."""
    edges = topo.edges()
    read = {src for src, _, kind in edges if kind == "sub"}
    out: set[str] = set()
    for n in topo.nodes():
        nid = make_id("node", n.name)
        pubs = [make_id("topic", p.topic) for p in n.pubs]
        if not any(t in read for t in pubs):
            out.add(nid)
            out.update(make_id("topic", sub.topic) for sub in n.subs)
            out.update(pubs)
    return out


def fault_reach(topo: Topology, target: str, process_names: Mapping[str, str]) -> set[str]:
    """The members a fault of ``target`` can show on (its alerts there count as detecting it).

    Every node of the target's process and that process (each pid it ran as), and every member
    downstream of those nodes in the data flow; a server's clients count as downstream of it
    (they wait for its answers).
    """
    group = topo.group_of("/" + target.removeprefix("node:").lstrip("/"))
    start = {make_id("node", n.name) for n in topo.group(group).nodes}
    succ: dict[str, set[str]] = {}
    for src, dst, kind in topo.edges():
        a, b = (dst, src) if kind == "send" else (src, dst)
        succ.setdefault(a, set()).add(b)
    seen, stack = set(start), list(start)
    while stack:
        for x in succ.get(stack.pop(), ()):
            if x not in seen:
                seen.add(x)
                stack.append(x)
    return seen | {p for p, g in process_names.items() if g == group}
