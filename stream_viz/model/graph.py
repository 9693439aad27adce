"""Building the model graph: members with kinds and θ, flow edges (layer 0), tree edges (layer i ≥ 1).

The graph is a ``networkx.MultiDiGraph``; the edge key is the layer ``i`` of the paper's
``((u, v), i)``, and the edge attribute ``kind`` says what it is (``pub``, ``sub``, ``send``,
``tree``). Member attributes: ``kind``, ``active``, ``label`` and any extra plain data
(``pid``, ``type``, ``qos`` …); ``theta`` holds the attribute vector when one is known.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import networkx as nx

from stream_viz.errors import ModelError
from stream_viz.model.ids import kind_of, name_of

ACTIVE_KINDS = frozenset({"node"})
PASSIVE_KINDS = frozenset({"topic", "service", "action", "process", "host", "root"})
# Allowed (source kind class, target kind class) per layer-0 edge kind, data-flow direction.
FLOW_KINDS = {"pub": ("active", "passive"), "sub": ("passive", "active"), "send": ("active", "active")}
# The graph's layers, the edge key of ``((u, v), i)``: data flow, then the trees T_i (i ≥ 1).
FLOW = 0
PROCESS_TREE = 1


def new_graph() -> nx.MultiDiGraph:
    """Return an empty model graph."""
    return nx.MultiDiGraph()


def copy_graph(G: nx.MultiDiGraph) -> nx.MultiDiGraph:
    """Return a copy of ``G`` equal to ``G.copy()``: the same members, edges, attributes and
    orders (of the members, each adjacency and each attribute dict), attribute dicts copied
    (shallow), each edge's key dict shared by its two adjacencies.

    ``G.copy()`` adds the edges one by one through `add_edge` (views, checks); at 2,000 members
    that is ~20 ms, paid every sample the seen graph holds a member the live one lacks. This
    builds the dicts directly; a graph of another class (other dict factories) is copied by
    networkx.
    """
    if type(G) is not nx.MultiDiGraph:
        return G.copy()
    H = nx.MultiDiGraph()
    H.graph.update(G.graph)
    succ, pred, node = H._succ, H._pred, H._node
    for n, attrs in G._node.items():  # as add_nodes_from: the member order, then its adjacencies
        succ[n], pred[n], node[n] = {}, {}, attrs.copy()
    for u, nbrs in G._succ.items():  # as add_edges_from over G's edges, in their order
        out = succ[u]
        for v, keys in nbrs.items():
            out[v] = pred[v][u] = {k: attrs.copy() for k, attrs in keys.items()}
    return H


def graph_over(G: nx.MultiDiGraph) -> nx.MultiDiGraph:
    """Return a new graph of ``G``'s members and edges, in ``G``'s orders, that shares ``G``'s
    attribute dicts: `copy_graph` without copying the attributes. Members and edges added to it
    and its structure are its own; changing an attribute of one of ``G``'s members changes it in
    both, so treat those as read-only (the model's graphs are, once built)."""
    if type(G) is not nx.MultiDiGraph:
        return copy_graph(G)
    H = nx.MultiDiGraph()
    H.graph.update(G.graph)
    succ, pred, node = H._succ, H._pred, H._node
    for n, attrs in G._node.items():
        succ[n], pred[n], node[n] = {}, {}, attrs
    for u, nbrs in G._succ.items():
        out = succ[u]
        for v, keys in nbrs.items():
            out[v] = pred[v][u] = dict(keys)  # its own key dict: an edge added to H is not G's
    return H


def add_member(G: nx.MultiDiGraph, member: str, **attrs: Any) -> None:
    """Add ``member`` (or update its attributes); its kind is taken from the id.

    Parameters
    ----------
    G : MultiDiGraph
        The model graph.
    member : str
        A member id such as ``node:/camera``.
    **attrs
        Extra plain attributes (``pid``, ``type``, ``theta`` …).
    """
    kind = kind_of(member)
    G.add_node(member, kind=kind, active=kind in ACTIVE_KINDS, label=name_of(member), **attrs)


def is_active(G: nx.MultiDiGraph, member: str) -> bool:
    """Return True if ``member`` is an active member (a component, i.e. a ROS node)."""
    return bool(G.nodes[member]["active"])


def add_flow_edge(G: nx.MultiDiGraph, src: str, dst: str, kind: str, **attrs: Any) -> None:
    """Add a layer-0 edge ``((src, dst), 0)`` of ``kind`` ``pub``, ``sub`` or ``send``.

    Both members must exist; the kinds must match the paper's
    ``E_pub = M_A × M_P``, ``E_sub = M_P × M_A``, ``E_send = M_A × M_A``.
    """
    if kind not in FLOW_KINDS:
        raise ModelError(f"unknown flow edge kind {kind!r}")
    want_src, want_dst = FLOW_KINDS[kind]
    for member, want in ((src, want_src), (dst, want_dst)):
        if member not in G:
            raise ModelError(f"edge {src} -> {dst}: member {member!r} is not in the graph")
        if is_active(G, member) != (want == "active"):
            raise ModelError(f"{kind} edge {src} -> {dst}: {member} must be {want}")
    G.add_edge(src, dst, key=FLOW, kind=kind, **attrs)


def add_tree_edge(G: nx.MultiDiGraph, parent: str, child: str, layer: int = PROCESS_TREE) -> None:
    """Add a tree edge ``((parent, child), layer)``; layers ≥ 1 are rooted trees (parent → child)."""
    if layer <= FLOW:
        raise ModelError(f"tree edges live on layers >= 1, not {layer}")
    for member in (parent, child):
        if member not in G:
            raise ModelError(f"tree edge {parent} -> {child}: member {member!r} is not in the graph")
    G.add_edge(parent, child, key=layer, kind="tree")


def flow_edges(G: nx.MultiDiGraph) -> Iterator[tuple[str, str, str]]:
    """Yield ``(src, dst, kind)`` for every layer-0 edge."""
    for u, v, key, kind in G.edges(keys=True, data="kind"):
        if key == FLOW:
            yield u, v, kind


def members_of_kind(G: nx.MultiDiGraph, kind: str) -> list[str]:
    """Return the members of ``kind``, sorted."""
    return sorted(m for m, k in G.nodes(data="kind") if k == kind)
