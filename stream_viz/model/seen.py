"""Everything seen during a run: the live model plus members and edges that vanished, marked gone."""

from __future__ import annotations

import networkx as nx

from stream_viz.model.graph import graph_over


def remember(seen: nx.MultiDiGraph, G: nx.MultiDiGraph, t: float,
             edges_kept: bool = False) -> nx.MultiDiGraph:
    """Return the union of ``seen`` and the live model ``G`` at time ``t``.

    Members and edges of ``G`` take their current attributes (no ``gone``; an attribute they no
    longer have is not carried over); those only in ``seen`` keep their last attributes with
    ``gone=True`` and ``gone_at`` (the first time they were missed). A crashed node leaves the
    live graph but stays a root-cause candidate.

    Parameters
    ----------
    seen : MultiDiGraph
        The union so far (not modified).
    G : MultiDiGraph
        The live model now.
    t : float
        Time of ``G``.
    edges_kept : bool
        The caller knows ``G`` has every edge of ``seen`` (``seen`` is the previous live model
        and the collector's diff removed no edge): they are not searched for.

    Returns
    -------
    MultiDiGraph
        A new graph that shares ``G``'s attribute dicts (`graph_over`; the gone members' and
        edges' are its own); or ``G`` itself when ``seen`` holds nothing ``G`` lacks (the steady
        state: no copy). Treat the result as read-only, like ``G``.
    """
    # Read through the adjacency dicts, not networkx's views: called every sample on every member
    # and edge, and in the steady state nothing is missing (a set comparison per node in C).
    live = G._node
    lost = seen._node.keys() - live.keys()
    nodes = [(m, a) for m, a in seen._node.items() if m in lost]
    edges = [] if edges_kept else missing_edges(seen, G)
    if not nodes and not edges:
        return G
    out = graph_over(G)  # G's attribute dicts: read-only, as G itself when nothing is gone
    for m, attrs in nodes:
        out.add_node(m, **attrs)
        if not attrs.get("gone"):
            out.nodes[m].update(gone=True, gone_at=t)
    for u, v, k, attrs in edges:
        out.add_edge(u, v, key=k, **attrs)
        if not attrs.get("gone"):
            out.edges[u, v, k].update(gone=True, gone_at=t)
    return out


def missing_edges(seen: nx.MultiDiGraph, G: nx.MultiDiGraph) -> list[tuple[str, str, int, dict]]:
    """Return the edges ``(u, v, key, attributes)`` of ``seen`` that ``G`` lacks, in ``seen``'s
    edge order: ``[e for e in seen.edges(keys=True, data=True) if not G.has_edge(*e[:3])]``.

    Parameters
    ----------
    seen, G : MultiDiGraph
        Two graphs (not modified).

    Returns
    -------
    list of tuple
        The missing edges with ``seen``'s attribute dicts (not copies).
    """
    live = G._succ
    out: list[tuple[str, str, int, dict]] = []
    for u, nbrs in seen._succ.items():
        there = live.get(u)
        if there is not None and nbrs.keys() <= there.keys() \
                and all(keys.keys() <= there[v].keys() for v, keys in nbrs.items()):
            continue  # every edge of u is in G: the common case, without a Python loop per edge
        for v, keys in nbrs.items():
            have = there.get(v, {}) if there is not None else {}
            out.extend((u, v, k, a) for k, a in keys.items() if k not in have)
    return out


def drop_gone(seen: nx.MultiDiGraph, t: float, keep_s: float) -> list[str]:
    """Remove from ``seen``, in place, the members gone for more than ``keep_s`` at ``t``.

    Bounds a long run on a churning system (restarted nodes come back under new process ids):
    without it the union grows with every member ever seen. Their edges go with them.

    Parameters
    ----------
    seen : MultiDiGraph
        The union from `remember` (modified).
    t : float
        Now.
    keep_s : float
        How long a vanished member stays (<= 0: for ever).

    Returns
    -------
    list of str
        The members removed, sorted.
    """
    if keep_s <= 0:
        return []
    old = sorted(m for m, a in seen.nodes(data=True) if a.get("gone") and t - a.get("gone_at", t) > keep_s)
    seen.remove_nodes_from(old)
    return old
