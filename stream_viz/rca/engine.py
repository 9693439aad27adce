"""The RCA engine: alerts in, subgraph iterations and ranked root causes out, live or offline."""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import networkx as nx

from stream_viz.detect.watchlist import CONFIGURED, Watchlist
from stream_viz.rca.episodes import Evidence, stamp
from stream_viz.rca.incidents import Incident, diagnose
from stream_viz.rca.pagerank import rank_pagerank
from stream_viz.rca.settings import RcaSettings
from stream_viz.rca.subgraph import Iteration, SubgraphState, grow, initial_state
from stream_viz.rca.trajectories import (
    Context,
    RootCause,
    rank_count,
    rank_hypothesis,
    rank_trajectory,
)
from stream_viz.records import Alert

RANKERS: dict[str, Callable[[Context], list[RootCause]]] = {
    "trajectory": rank_trajectory,
    "pagerank": rank_pagerank,
    "hypothesis": rank_hypothesis,
    "count": rank_count,
}


@dataclass
class RcaResult:
    """The state of the diagnosis after an update.

    Attributes
    ----------
    iterations : list of Iteration
        ``G_0 … G_j``, in order.
    root_causes : list of RootCause
        Ranked, best first (at most ``top_k``).
    state : SubgraphState
        The current ``G_j`` (``W_j``: the engine's `RcaEngine.watchlist`).
    alerts : int
        Alerts seen so far; ``kept`` of them did not grow the subgraph.
    kept : int
    method, policy : str
        How it was computed.
    first_symptom : str or None
        The member of the earliest alert of the current incident (of ``M_j``, in the window).
    incidents : list of Incident
        Every incident in the window, oldest first, each ranked; ``root_causes`` is the
        current one's ranking.
    """

    iterations: list[Iteration]
    root_causes: list[RootCause]
    state: SubgraphState
    alerts: int = 0
    kept: int = 0
    method: str = "trajectory"
    policy: str = "both"
    first_symptom: str | None = None
    extra: dict[str, Any] = field(default_factory=dict)
    incidents: list[Incident] = field(default_factory=list)

    def to_report(self) -> dict[str, Any]:
        """The ``iterations``, ``root_causes`` and ``incidents`` parts of the report JSON
        (docs/contracts.md)."""
        members: set[str] = set()
        edges: set[tuple[str, str]] = set()
        watched: set[str] = set()
        its = []
        for it in self.iterations:
            members |= it.added_members
            edges |= it.added_edges
            watched |= it.added_watch
            its.append({
                "j": it.j,
                "t": it.t,
                "alert": it.alert_member,
                "plugin": it.plugin,
                "subgraph": sorted(members),
                "edges": [list(e) for e in sorted(edges)],
                "watchlist": sorted(watched),
            })
        return {
            "iterations": its,
            "root_causes": [rc.to_report() for rc in self.root_causes],
            "incidents": [inc.to_report() for inc in self.incidents],
            "rca": {"method": self.method, "policy": self.policy, "first_symptom": self.first_symptom,
                    "alerts": self.alerts, "kept": self.kept},
        }


class RcaEngine:
    """Incremental diagnosis: feed each sample's alerts to `update`; it grows ``G_j`` and reranks.

    Parameters
    ----------
    settings : RcaSettings
        Policy, method, weights …
    watchlist : Watchlist or set of str, optional
        ``W_0``. A `Watchlist` is the run's: others add to it (the detector: the configuration
        and process monitoring), the engine grows it. None watches every member of the graph
        passed to `update` (offline analysis without a recorded watchlist).
    """

    def __init__(self, settings: RcaSettings, watchlist: Watchlist | Iterable[str] | None = None) -> None:
        self.settings = settings
        self._watch_all = watchlist is None
        self.watchlist = watchlist if isinstance(watchlist, Watchlist) else Watchlist(watchlist or ())
        self.state = initial_state(self.watchlist)
        self.watchlist.commit()  # iteration 0 holds everything watched so far
        self._iterations: list[Iteration] = [self.state.last]
        self._alerts: list[Alert] = []
        self._kept = 0
        self._dropped = 0  # alerts pruned out of the window
        self._outside: dict[str, list[Alert]] = {}  # kept alerts per unwatched member (replay)
        self._evidence: dict[str, Evidence] = {}
        self._result = self._make_result([])

    @property
    def iterations(self) -> list[Iteration]:
        """All iterations so far."""
        return list(self._iterations)

    def result(self) -> RcaResult:
        """The result of the last update."""
        return self._result

    def update(
        self, G: nx.MultiDiGraph, alerts: Iterable[Alert],
        evidence: Mapping[str, float | Evidence] | None = None, t: float | None = None,
    ) -> RcaResult:
        """Feed new alerts (grow the subgraph in time order) and rerank.

        Parameters
        ----------
        G : MultiDiGraph
            The model now (best: every member seen, vanished ones kept).
        alerts : iterable of Alert
            Alerts since the last update.
        evidence : mapping, optional
            Metric anomaly strength in [0, 1] per member (nodes or processes), or `Evidence`
            with its own since/until; replaces the previous evidence when given (what is missing
            from it has ended).
        t : float, optional
            The time of this update (the sample's): evidence gets its since/until from it.
        """
        new = sorted(alerts, key=lambda a: a.t)
        before = self.state.last
        if self._watch_all and len(self.watchlist) != G.number_of_nodes():
            self.watchlist.add(G.nodes, CONFIGURED)
        if self._outside:  # members watched from outside since: their kept alerts first
            for m in [m for m in self._outside if m in self.watchlist]:
                # An earlier member's replay may have replayed this one's already (its iteration
                # records every pending addition).
                for k in self._outside.pop(m, ()):
                    self._feed(G, k)
        for a in new:
            self._feed(G, a)
        self._alerts.extend(new)
        self._prune()
        changed = bool(new) or evidence is not None or self.state.last is not before
        if evidence is not None:
            self._evidence = stamp(self._evidence, evidence, t, self.settings.window or float("inf"))
        if changed:
            first = self._iterations[1].alert_member if len(self._iterations) > 1 else None
            d = diagnose(G, self._alerts, self.settings, RANKERS[self.settings.method], self.state.members,
                         self._evidence, first, self._result.incidents)
            self._result = self._make_result(d.root_causes, d.first, d.incidents)
        else:
            r = self._result
            self._result = self._make_result(r.root_causes, r.first_symptom, r.incidents)
        return self._result

    def _feed(self, G: nx.MultiDiGraph, alert: Alert) -> None:
        """Grow with ``alert``; with ``replay``, also with kept alerts of members it made watched."""
        queue = deque([alert])
        while queue:
            a = queue.popleft()
            if a.member not in self.watchlist:
                self._kept += 1
                if self.settings.replay:
                    self._outside.setdefault(a.member, []).append(a)
                continue
            w = self.watchlist
            state, added = grow(G, self.state, a, w, self.settings.policy, w.pending)
            if state is self.state:
                continue
            self.state = state
            self.watchlist.commit(added)
            self._iterations.append(self.state.last)
            for m in sorted(self.state.last.added_watch):  # a set's order would vary between runs
                # Replayed at the current time so iteration times stay in order.
                queue.extend(replace(k, t=max(k.t, a.t)) for k in self._outside.pop(m, ()))

    def _prune(self) -> None:
        """With a window, alerts that can no longer count are dropped (their count stays)."""
        w = self.settings.window
        if w > 0 and self._alerts:
            latest = max(a.t for a in self._alerts[-64:])
            if self._alerts[0].t < latest - w:
                keep = [a for a in self._alerts if a.t >= latest - w]
                self._dropped += len(self._alerts) - len(keep)
                self._alerts = keep
                for m in list(self._outside):
                    self._outside[m] = [a for a in self._outside[m] if a.t >= latest - w]
                    if not self._outside[m]:
                        del self._outside[m]

    def _make_result(self, causes: list[RootCause], first: str | None = None,
                     incidents: list[Incident] | None = None) -> RcaResult:
        return RcaResult(
            incidents=list(incidents or ()),
            iterations=list(self._iterations),
            root_causes=causes,
            state=self.state,
            alerts=len(self._alerts) + self._dropped,
            kept=self._kept,
            method=self.settings.method,
            policy=self.settings.policy,
            first_symptom=first,
        )


def analyze(
    G: nx.MultiDiGraph,
    alerts: Iterable[Alert],
    settings: RcaSettings,
    watchlist: Iterable[str] | None = None,
    evidence: Mapping[str, float | Evidence] | None = None,
) -> RcaResult:
    """Rerun the diagnosis from scratch on ``alerts`` (offline; ``stream-viz analyze``).

    ``watchlist`` is ``W_0``; None watches every member of ``G``.
    """
    engine = RcaEngine(settings, watchlist)
    return engine.update(G, alerts, evidence)
