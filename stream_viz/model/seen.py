"""Everything seen during a run: the live model plus members and edges that vanished, marked gone."""

from __future__ import annotations

import networkx as nx


def remember(seen: nx.MultiDiGraph, G: nx.MultiDiGraph, t: float) -> nx.MultiDiGraph:
    """Return the union of ``seen`` and the live model ``G`` at time ``t``.

    Members and edges of ``G`` take their current attributes (``gone`` cleared); those only in
    ``seen`` keep their last attributes with ``gone=True`` and ``gone_at`` (the first time they
    were missed). A crashed node leaves the live graph but stays a root-cause candidate.

    Parameters
    ----------
    seen : MultiDiGraph
        The union so far (not modified).
    G : MultiDiGraph
        The live model now.
    t : float
        Time of ``G``.
    """
    out = seen.copy()
    for m, attrs in out.nodes(data=True):
        if m not in G and not attrs.get("gone"):
            attrs["gone"], attrs["gone_at"] = True, t
    for u, v, k, attrs in out.edges(keys=True, data=True):
        if not G.has_edge(u, v, k) and not attrs.get("gone"):
            attrs["gone"], attrs["gone_at"] = True, t
    for m, attrs in G.nodes(data=True):
        if m in out:
            out.nodes[m].pop("gone", None)
            out.nodes[m].pop("gone_at", None)
        out.add_node(m, **attrs)
    for u, v, k, attrs in G.edges(keys=True, data=True):
        if out.has_edge(u, v, k):
            out.edges[u, v, k].pop("gone", None)
            out.edges[u, v, k].pop("gone_at", None)
        out.add_edge(u, v, key=k, **attrs)
    return out
