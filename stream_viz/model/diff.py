"""Differences between two model snapshots: what appeared and what vanished."""

from __future__ import annotations

from dataclasses import dataclass, field

import networkx as nx


@dataclass(frozen=True)
class GraphDiff:
    """Members and edges ``(u, v, layer)`` that appeared or vanished between two snapshots."""

    added_members: frozenset[str] = field(default_factory=frozenset)
    removed_members: frozenset[str] = field(default_factory=frozenset)
    added_edges: frozenset[tuple[str, str, int]] = field(default_factory=frozenset)
    removed_edges: frozenset[tuple[str, str, int]] = field(default_factory=frozenset)

    def __bool__(self) -> bool:
        return bool(self.added_members or self.removed_members or self.added_edges or self.removed_edges)


def diff(old: nx.MultiDiGraph, new: nx.MultiDiGraph) -> GraphDiff:
    """Return what changed from ``old`` to ``new``.

    Parameters
    ----------
    old, new : MultiDiGraph
        Two model snapshots.
    """
    old_m, new_m = set(old.nodes), set(new.nodes)
    old_e, new_e = set(old.edges(keys=True)), set(new.edges(keys=True))
    return GraphDiff(
        frozenset(new_m - old_m), frozenset(old_m - new_m),
        frozenset(new_e - old_e), frozenset(old_e - new_e),
    )
