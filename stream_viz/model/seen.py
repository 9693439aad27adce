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
