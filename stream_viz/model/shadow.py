"""The record step of the tick: the run's shadow of the system — every member seen and θ history."""

from __future__ import annotations

import networkx as nx

from stream_viz.model.diff import GraphDiff
from stream_viz.model.graph import new_graph
from stream_viz.model.history import History
from stream_viz.model.seen import drop_gone, remember


class Shadow:
    """Everything a run has seen: the union of the live models (vanished members kept, marked
    gone) and the θ history of each member, both bounded.

    Parameters
    ----------
    history : int
        Samples of θ kept per member.
    forget_gone_s : float
        Seconds a vanished member stays (<= 0: the whole run).
    """

    def __init__(self, history: int = 600, forget_gone_s: float = 600.0) -> None:
        self.seen: nx.MultiDiGraph = new_graph()
        self.history = History(maxlen=history)
        self.forget_gone_s = forget_gone_s
        self._live: nx.MultiDiGraph | None = None  # the previous live model
        # Changes whenever the seen graph's members or edges change (which of them are gone
        # included): what is drawn from its structure alone is built again only then.
        self.structure = 0

    def record(self, G: nx.MultiDiGraph, t: float, diff: GraphDiff | None = None) -> list[str]:
        """Add the live model ``G`` at ``t`` (its members, its θ); return the members forgotten
        (sorted).

        ``diff`` is the sample's (what changed since the previous live model): while the seen
        graph is that model itself (nothing gone), the edges it lacks are the diff's removed ones,
        so with none removed they are not searched for (every edge, every sample).
        """
        kept = diff is not None and self.seen is self._live and not diff.removed_edges
        self.seen = remember(self.seen, G, t, edges_kept=kept)
        self._live = G
        # Long after a member vanished (longer than the RCA window by default) it can no longer
        # be a cause: drop it and its history, so a churning system does not grow the run.
        # The database keeps it (snapshots, alerts) for `analyze`.
        gone = drop_gone(self.seen, t, self.forget_gone_s)
        if gone:
            self.history.forget(set(self.seen))
        if diff is None or diff or gone:  # an empty diff: the same live structure, the same gone
            self.structure += 1
        # The attribute dicts, not a data view: every member, every sample.
        self.history.add_all(t, ((m, a["theta"]) for m, a in G._node.items() if a.get("theta") is not None))
        return gone
