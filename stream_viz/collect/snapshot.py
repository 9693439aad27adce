"""``stream-viz snapshot``: one look at the live system, as text for a person or as JSON."""

from __future__ import annotations

import json as _json
import math
import time
from collections.abc import Callable

import networkx as nx

from stream_viz.model.graph import flow_edges, members_of_kind
from stream_viz.model.ids import node_fqn
from stream_viz.model.queries import tree
from stream_viz.model.serialize import to_data
from stream_viz.model.theta import theta_dict
from stream_viz.records import Sample

KIND_ORDER = ("node", "topic", "service", "action", "process", "host", "root")


def _theta_text(kind: str, theta) -> str:
    if theta is None:
        return ""
    parts = [f"{k}={v:.3g}" for k, v in theta_dict(kind, theta).items() if not math.isnan(v)]
    return " ".join(parts)


def _member_line(G: nx.MultiDiGraph, m: str) -> str:
    a = G.nodes[m]
    extra = []
    if a["kind"] == "node":
        extra.append(f"pid={a.get('pid')} ({a.get('pid_status')})")
        if not a.get("alive", True):
            extra.append("DEAD")
    elif a["kind"] == "topic":
        extra.append(a.get("type", ""))
        if not a.get("measured", True):
            extra.append(f"not measured: {a.get('reason', '')}")
        rates = a.get("publisher_rates") or {}
        if len(rates) > 1:  # who sends what on a multi-publisher topic
            extra.append("from " + ", ".join(f"{n} {hz:.3g} Hz" for n, hz in rates.items()))
    elif a["kind"] in ("service", "action"):
        extra.append(a.get("type", ""))
    elif a["kind"] == "process":
        extra.append(a.get("name", ""))
        if not a.get("alive", True):
            extra.append("EXITED")
    th = _theta_text(a["kind"], a.get("theta"))
    return "  " + " ".join(x for x in (m, *extra, f"[{th}]" if th else "") if x)


def format_snapshot(sample: Sample) -> str:
    """Return a person-readable snapshot: members by kind with pid/θ, flow edges, the process tree."""
    G = sample.graph
    lines = [f"snapshot at {time.strftime('%Y-%m-%d %H:%M:%S', time.localtime(sample.t))}"]
    for kind in KIND_ORDER:
        ms = members_of_kind(G, kind)
        if ms:
            lines.append(f"{kind}s ({len(ms)}):")
            lines += [_member_line(G, m) for m in ms]
    edges = sorted(flow_edges(G))
    lines.append(f"edges ({len(edges)}):")
    for u, v, k in edges:
        d = G.edges[u, v, 0]
        via = d.get("services", []) + d.get("actions", [])
        lines.append(f"  {u} -{k}-> {v}" + (f" via {', '.join(via)}" if via else ""))
    T = tree(G, 1)
    if T.number_of_nodes():
        lines.append("process tree:")
        for top in sorted(n for n in T if T.in_degree(n) == 0):
            _tree_lines(G, T, top, 1, lines)
    if sample.unreadable:
        lines.append("unreadable:")
        lines += [f"  {m}: {why}" for m, why in sorted(sample.unreadable.items())]
    if sample.events:
        lines.append("events:")
        lines += [f"  [{e.level}] {e.kind} {e.member}: {e.text}" for e in sample.events]
    return "\n".join(lines)


def _tree_lines(G: nx.MultiDiGraph, T: nx.DiGraph, v: str, depth: int, lines: list[str]) -> None:
    a = G.nodes[v]
    label = v
    if a["kind"] == "process":
        label += f" {a.get('name', '')}"
    lines.append("  " * depth + label)
    for c in sorted(T.successors(v)):
        _tree_lines(G, T, c, depth + 1, lines)


DISCOVERY_QUIET_S = 1.0  # the node set unchanged this long ends discovery
DISCOVERY_EXTRA_S = 4.0  # past the settle time, more than one DDS announcement period (3 s)


def discover(read_names: Callable[[], frozenset[str]], min_s: float, *, quiet_s: float = DISCOVERY_QUIET_S,
             max_s: float | None = None, period_s: float = 0.1,
             clock: Callable[[], float] = time.monotonic,
             sleep: Callable[[float], None] = time.sleep) -> frozenset[str]:
    """Wait until discovery has settled and return the node names seen.

    Discovery ends after ``min_s`` once the names have been the same, and not empty, for
    ``quiet_s``; at the latest after ``max_s`` (``min_s + DISCOVERY_EXTRA_S``). A participant whose
    first announcements were lost is heard at its next periodic one, so a fixed wait can miss a
    whole running system on a loaded machine.
    """
    max_s = min_s + DISCOVERY_EXTRA_S if max_s is None else max_s
    start = clock()
    names, since = read_names(), start
    while (now := clock()) - start < max_s:
        if now - start >= min_s and names and now - since >= quiet_s:
            break
        sleep(period_s)
        seen = read_names()
        if seen != names:
            names, since = seen, clock()
    return names


def snapshot_main(json: bool, settle_s: float) -> str:
    """Observe the current ROS_DOMAIN_ID until discovery settles and return the snapshot text/JSON."""
    from stream_viz.collect.collector import Collector

    half = max(settle_s, 0.0) / 2
    with Collector() as c:
        discover(lambda: frozenset(node_fqn(ns, n) for n, ns in c.node.get_node_names_and_namespaces())
                 - {c.own}, half)
        c.sample()  # subscribes to the topics, primes cpu % and the per-second rates
        time.sleep(half)
        sample = c.sample()
    if json:
        return _json.dumps({"t": sample.t, **to_data(sample.graph), "unreadable": sample.unreadable,
                            "events": [e.__dict__ for e in sample.events]}, indent=1, default=str)
    return format_snapshot(sample)
