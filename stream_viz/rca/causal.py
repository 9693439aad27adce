"""The model's layer 0 read in cause → effect direction, and fault-trajectory tracing on it.

Data flow is the direction faults propagate along ``pub`` (node → topic) and ``sub`` (topic →
node) edges. A ``send`` edge points from a service client to its server, but a fault propagates
the other way (the client waits for the server's reply), so in the causal reading a ``send``
edge is server → client. Edges marked ``gone`` still count: a crashed node stays a candidate.
"""

from __future__ import annotations

import heapq
from collections.abc import Container

import networkx as nx

from stream_viz.model.graph import FLOW

SILENT_COST = 2.0  # a hop through a member with no symptom costs more than one through a symptom


def causes(G: nx.MultiDiGraph, m: str) -> list[str]:
    """Members whose fault can propagate to ``m`` directly (its causal parents)."""
    if m not in G:
        return []
    return _along(G._pred[m], G._succ[m])


def effects(G: nx.MultiDiGraph, m: str) -> list[str]:
    """Members a fault of ``m`` can propagate to directly (its causal children)."""
    if m not in G:
        return []
    return _along(G._succ[m], G._pred[m])


def _along(flow: dict, against: dict) -> list[str]:
    """The neighbours over a layer-0 edge of ``flow`` that is not ``send``, then those over a
    ``send`` edge of ``against`` (adjacency dicts: neighbour → keydict; an edge's kind defaults
    to ``pub``). One plain loop, no call per neighbour: the RCA asks this thousands of times an
    update."""
    out = []
    for x, kd in flow.items():
        a = kd.get(FLOW)
        if a is not None and a.get("kind", "pub") != "send":
            out.append(x)
    for x, kd in against.items():
        a = kd.get(FLOW)
        if a is not None and a.get("kind", "pub") == "send":
            out.append(x)
    return out


def causes_in(G: nx.MultiDiGraph, m: str, memo: dict[str, list[str]]) -> list[str]:
    """`causes` of ``m``, kept in ``memo`` (member → causes) for the next call on the same,
    unchanged graph: the walks of one ranking cross the same members again and again. The list
    is shared: do not change it."""
    out = memo.get(m)
    if out is None:
        out = memo[m] = causes(G, m)
    return out


def effects_in(G: nx.MultiDiGraph, m: str, memo: dict[str, list[str]]) -> list[str]:
    """`effects` of ``m``, kept in ``memo`` as `causes_in` keeps causes."""
    out = memo.get(m)
    if out is None:
        out = memo[m] = effects(G, m)
    return out


def is_node(G: nx.MultiDiGraph, m: str) -> bool:
    """True for an active member (a ROS node); ids decide when ``m`` is not in ``G``."""
    d = G._node.get(m)  # one look-up, not `in` then a node view
    if d is not None:
        return bool(d.get("active", m.startswith("node:")))
    return m.startswith("node:")


def publishers(G: nx.MultiDiGraph, x: str, memo: dict[str, list[str]] | None = None) -> list[str]:
    """Active members feeding the passive member ``x`` (a topic's publishers); ``memo`` as in
    `causes_in`."""
    return [u for u in (causes(G, x) if memo is None else causes_in(G, x, memo)) if is_node(G, u)]


def outputs(G: nx.MultiDiGraph, n: str) -> list[str]:
    """Passive members the node ``n`` feeds (its published topics)."""
    return [v for v in effects(G, n) if not is_node(G, v)]


def trace(
    G: nx.MultiDiGraph, c: str, symptomatic: Container[str], max_len: int,
    children: dict[str, list[str]] | None = None, closed: Container[str] = (),
) -> tuple[dict[str, float], dict[str, str]]:
    """Dijkstra from ``c`` along causal edges (downstream), up to ``max_len`` members per path.

    Entering a member with a symptom costs 1, a silent one `SILENT_COST`, so a path through
    symptoms is preferred. Returns ``(cost, back)``: cost per reached member, and ``back[x]`` the
    member before ``x`` on its path from ``c`` — following ``back`` from a symptom leads
    upstream, to ``c``: that is the fault trajectory. ``children``: `effects_in`'s memo, shared
    by the traces of one ranking. ``closed``: topics that carried nothing at the time; the trace
    enters one only from ``c`` (its own output: its subscribers see it gone) and goes no further
    than the nodes behind it.
    """
    children = {} if children is None else children
    cost: dict[str, float] = {c: 0.0}
    hops: dict[str, int] = {c: 1}
    back: dict[str, str] = {}
    heap = [(0.0, c)]
    while heap:
        d, m = heapq.heappop(heap)
        if d > cost[m] or hops[m] >= max_len or (m != c and back.get(m) in closed):
            continue  # a node reached through a closed topic (its own input) goes no further
        for x in effects_in(G, m, children):
            if x in closed and m != c:
                continue
            nd = d + (1.0 if x in symptomatic else SILENT_COST)
            if nd < cost.get(x, float("inf")):
                cost[x], hops[x], back[x] = nd, hops[m] + 1, m
                heapq.heappush(heap, (nd, x))
    return cost, back


def path_back(back: dict[str, str], start: str, c: str) -> list[str]:
    """The trajectory from ``start`` (a symptom) back to ``c`` using ``back`` from `trace`."""
    path = [start]
    while path[-1] != c:
        path.append(back[path[-1]])
    return path
