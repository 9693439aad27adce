"""Everything seen during a run: the live model plus members and edges that vanished, marked gone."""

from __future__ import annotations

from collections.abc import Collection

import networkx as nx

from stream_viz.model.graph import graph_over


def remember(seen: nx.MultiDiGraph, G: nx.MultiDiGraph, t: float,
             missing: list[tuple[str, str, int, dict]] | None = None) -> nx.MultiDiGraph:
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
    missing : list of (u, v, key, attributes), optional
        ``missing_edges(seen, G)`` when the caller found it faster (`missing_among`); None:
        searched here.

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
    edges = missing_edges(seen, G) if missing is None else missing
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


def missing_among(seen: nx.MultiDiGraph, G: nx.MultiDiGraph,
                  edges: Collection[tuple[str, str, int]]) -> list[tuple[str, str, int, dict]]:
    """Return those of ``edges`` that ``seen`` has and ``G`` lacks, as `missing_edges` does (in
    ``seen``'s edge order, with ``seen``'s attribute dicts), looking at ``edges`` only.

    Parameters
    ----------
    seen, G : MultiDiGraph
        Two graphs (not modified).
    edges : collection of (u, v, key)
        The candidates; those ``seen`` lacks are left out.

    Returns
    -------
    list of tuple
        ``[e for e in missing_edges(seen, G) if e[:3] in edges]``.
    """
    have, live = seen._succ, G._succ
    found = [(u, v, k) for u, v, k in edges
             if k in have.get(u, {}).get(v, ()) and k not in live.get(u, {}).get(v, ())]
    if len(found) > 1:  # seen's order: its members', then each member's neighbours', then keys'
        at = {m: i for i, m in enumerate(seen._node)}
        found.sort(key=lambda e: (at[e[0]], list(have[e[0]]).index(e[1]), list(have[e[0]][e[1]]).index(e[2])))
    return [(u, v, k, have[u][v][k]) for u, v, k in found]


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
