"""The record step of the tick: the run's shadow of the system — every member seen and θ history."""

from __future__ import annotations

import networkx as nx

from stream_viz.model.diff import GraphDiff
from stream_viz.model.graph import new_graph
from stream_viz.model.history import History
from stream_viz.model.seen import drop_gone, missing_among, missing_edges, remember
from stream_viz.model.traffic import TRAFFIC, note_traffic


class Shadow:
    """Everything a run has seen: the union of the live models (vanished members kept, marked
    gone) and the θ history of each member, both bounded.

    Parameters
    ----------
    history : int
        Samples of θ kept per member.
    forget_gone_s : float
        Seconds a vanished member stays (<= 0: the whole run).
    rate_window_s : float
        The collector's rate window: a topic's rate above 0 says it carried over that window
        (`stream_viz.model.traffic`, in the seen graph's ``graph["traffic"]``).
    """

    def __init__(self, history: int = 600, forget_gone_s: float = 600.0, rate_window_s: float = 3.0) -> None:
        self.seen: nx.MultiDiGraph = new_graph()
        self.history = History(maxlen=history)
        self.forget_gone_s = forget_gone_s
        self.rate_window_s = rate_window_s
        self.traffic: dict[str, list[tuple[float, float]]] = {}  # topic -> spans it carried in
        self._live: nx.MultiDiGraph | None = None  # the previous live model
        # The edges of the seen graph that are gone: with the sample's diff, the only ones the
        # live model can lack, so no sample searches every edge (after a crash: every sample).
        self._gone_edges: set[tuple[str, str, int]] = set()
        # Changes whenever the seen graph's members or edges change (which of them are gone
        # included): what is drawn from its structure alone is built again only then.
        self.structure = 0

    def record(self, G: nx.MultiDiGraph, t: float, diff: GraphDiff | None = None) -> list[str]:
        """Add the live model ``G`` at ``t`` (its members, its θ); return the members forgotten
        (sorted).

        ``diff`` is the sample's (what changed since the previous live model): the edges the seen
        graph has and ``G`` lacks are then among its gone ones and the diff's removed ones, and
        only those are looked at (not every edge, every sample).
        """
        if diff is not None and self._live is not None:
            missing = missing_among(self.seen, G, self._gone_edges | diff.removed_edges)
        else:
            missing = missing_edges(self.seen, G)
        self.seen = remember(self.seen, G, t, missing)
        self._live = G
        # Long after a member vanished (longer than the RCA window by default) it can no longer
        # be a cause: drop it and its history, so a churning system does not grow the run.
        # The database keeps it (snapshots, alerts) for `analyze`.
        gone = drop_gone(self.seen, t, self.forget_gone_s)
        if gone:
            self.history.forget(set(self.seen))
            for m in gone:
                self.traffic.pop(m, None)
        note_traffic(self.traffic, G, t, self.rate_window_s)
        self.seen.graph[TRAFFIC] = self.traffic
        self._gone_edges = {(u, v, k) for u, v, k, _ in missing if not gone or self.seen.has_edge(u, v, k)}
        if diff is None or diff or gone:  # an empty diff: the same live structure, the same gone
            self.structure += 1
        # The attribute dicts, not a data view: every member, every sample.
        self.history.add_all(t, ((m, a["theta"]) for m, a in G._node.items() if a.get("theta") is not None))
        return gone
