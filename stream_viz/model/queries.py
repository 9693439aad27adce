"""Queries over the model graph: the paper's §3.2.3 and the named questions every step asks.

Plugins (through their context), the watchlist, the RCA, the report and the viewer ask these
instead of walking edge keys themselves: the layers have names (`FLOW`, `PROCESS_TREE`), and so
do the questions (the nodes of a process, the publishers of a topic, the servers of a service).
Each takes the graph first; members missing from the graph give empty answers, not errors.
"""

from __future__ import annotations

from typing import Literal

import networkx as nx

from stream_viz.model.graph import FLOW, PROCESS_TREE
from stream_viz.model.ids import make_id, pid_of

Which = Literal["all", "active", "passive"]


def _keep(G: nx.MultiDiGraph, member: str, which: Which) -> bool:
    if which == "all":
        return True
    return G.nodes[member]["active"] == (which == "active")


def predecessors(G: nx.MultiDiGraph, member: str, which: Which = "all", layer: int = FLOW) -> list[str]:
    """Return the members ``m`` with an edge ``((m, member), layer)``, sorted.

    Parameters
    ----------
    G : MultiDiGraph
        The model graph.
    member : str
        The member asked about.
    which : {"all", "active", "passive"}
        Keep all predecessors, only active ones (nodes) or only passive ones.
    layer : int
        The edge layer (`FLOW`: data flow; i ≥ 1: tree ``T_i``).
    """
    if member not in G:
        return []
    return sorted(u for u, keys in G._pred[member].items() if layer in keys and _keep(G, u, which))


def successors(G: nx.MultiDiGraph, member: str, which: Which = "all", layer: int = FLOW) -> list[str]:
    """Return the members ``m`` with an edge ``((member, m), layer)``, sorted (see `predecessors`)."""
    if member not in G:
        return []
    return sorted(v for v, keys in G._succ[member].items() if layer in keys and _keep(G, v, which))


def flow_successors(G: nx.MultiDiGraph, member: str) -> set[str]:
    """Return the members ``x`` with a data-flow edge ``((member, x), FLOW)`` (unsorted, fast)."""
    if member not in G:
        return set()
    return {v for v, keys in G._succ[member].items() if FLOW in keys}


def flow_predecessors(G: nx.MultiDiGraph, member: str) -> set[str]:
    """Return the members ``x`` with a data-flow edge ``((x, member), FLOW)`` (unsorted, fast)."""
    if member not in G:
        return set()
    return {u for u, keys in G._pred[member].items() if FLOW in keys}


def _by_edge_kind(G: nx.MultiDiGraph, member: str, kind: str, incoming: bool) -> list[str]:
    if member not in G:
        return []
    adj = G._pred[member] if incoming else G._succ[member]
    return sorted(x for x, keys in adj.items() if FLOW in keys and keys[FLOW].get("kind") == kind)


def publishers(G: nx.MultiDiGraph, topic: str) -> list[str]:
    """Return the nodes that publish ``topic`` (its ``pub`` edges), sorted."""
    return _by_edge_kind(G, topic, "pub", incoming=True)


def subscribers(G: nx.MultiDiGraph, topic: str) -> list[str]:
    """Return the nodes that subscribe to ``topic`` (its ``sub`` edges), sorted."""
    return _by_edge_kind(G, topic, "sub", incoming=False)


def published_topics(G: nx.MultiDiGraph, node: str) -> list[str]:
    """Return the topics ``node`` publishes, sorted."""
    return _by_edge_kind(G, node, "pub", incoming=False)


def subscribed_topics(G: nx.MultiDiGraph, node: str) -> list[str]:
    """Return the topics ``node`` subscribes to, sorted."""
    return _by_edge_kind(G, node, "sub", incoming=True)


def _endpoint_nodes(G: nx.MultiDiGraph, member: str, attr: str) -> list[str]:
    if member not in G:
        return []
    return sorted(make_id("node", n) for n in G.nodes[member].get(attr) or ())


def servers(G: nx.MultiDiGraph, service: str) -> list[str]:
    """Return the nodes that serve ``service`` (or the action ``service``), sorted."""
    return _endpoint_nodes(G, service, "servers")


def clients(G: nx.MultiDiGraph, service: str) -> list[str]:
    """Return the nodes that are clients of ``service`` (or of the action ``service``), sorted."""
    return _endpoint_nodes(G, service, "clients")


def called_servers(G: nx.MultiDiGraph, node: str) -> list[str]:
    """Return the nodes ``node`` calls (its ``send`` edges client → server), sorted."""
    return _by_edge_kind(G, node, "send", incoming=False)


def calling_clients(G: nx.MultiDiGraph, node: str) -> list[str]:
    """Return the nodes that call ``node`` (``send`` edges client → server into it), sorted."""
    return _by_edge_kind(G, node, "send", incoming=True)


def nodes_of_process(G: nx.MultiDiGraph, process: str, *, by_pid: bool = False) -> list[str]:
    """Return the nodes ``process`` hosts (its node children in `PROCESS_TREE`), sorted; for a
    ``host:`` member every node below it.

    ``by_pid`` also counts nodes whose ``pid`` attribute is the process's pid (a node the
    collector could not attach to the tree, e.g. its process ended between two reads); it
    scans every member, so it is for rare events, not for every sample.
    """
    out: set[str] = set()
    if process in G and G.nodes[process].get("kind") == "host":  # a host takes all its nodes with it
        return sorted(m for m in nx.descendants(tree(G), process) if G.nodes[m].get("kind") == "node")
    if process in G:
        out.update(c for c, keys in G._succ[process].items()
                   if PROCESS_TREE in keys and G.nodes[c].get("kind") == "node")
    if by_pid:
        pid, host = pid_of(process), G.nodes[process].get("host") if process in G else None
        out.update(m for m, d in G.nodes(data=True)
                   if d.get("kind") == "node" and d.get("pid") == pid and d.get("host") == host)
    return sorted(out)


def process_of_node(G: nx.MultiDiGraph, node: str) -> str | None:
    """Return the process that hosts ``node`` (its parent in `PROCESS_TREE`, else the process of
    its ``pid`` attribute when that is in the graph), or None when unknown."""
    if node not in G:
        return None
    attrs = G._node  # the RCA asks this for every candidate, several times an update: no node views
    for u, keys in G._pred[node].items():
        if PROCESS_TREE in keys and attrs[u].get("kind") == "process":
            return u
    pid = attrs[node].get("pid")
    if isinstance(pid, int) and not isinstance(pid, bool):
        proc = make_id("process", pid)
        if proc in G and G.nodes[proc].get("host") == G.nodes[node].get("host"):
            return proc
    return None


def layer_subgraph(G: nx.MultiDiGraph, layer: int = FLOW) -> nx.MultiDiGraph:
    """Return the edge-induced subgraph of one layer (``G_0`` or ``T_i``) as a copy."""
    edges = [(u, v, k) for u, v, k in G.edges(keys=True) if k == layer]
    return G.edge_subgraph(edges).copy()


def tree(G: nx.MultiDiGraph, layer: int = PROCESS_TREE) -> nx.DiGraph:
    """Return tree ``T_layer`` as a simple DiGraph (parent → child), member attributes kept."""
    return nx.DiGraph(layer_subgraph(G, layer))
