"""Incidents: symptoms connected in the graph and close in time, diagnosed one by one.

A robot's alert history mixes faults: an old one that has ended, a warning that recurs somewhere
else, the fault of now. Ranked together, a loud old symptom can take the first place of the
fault a user is looking at. So symptom episodes (`stream_viz.rca.episodes`) are grouped first:
two episodes belong to one incident when their members are at most ``incident_hops`` hops apart
(data flow in either direction, service calls, a node and its process, an alert and the node it
names) and the episodes are at most ``episode_gap`` apart in time (single linkage: a chain of
such pairs is one incident). Each incident is ranked on its own alerts; the diagnosis is the
ranking of the *current* incident.

The current incident is an ongoing one (its last episode ended less than ``episode_gap`` before
the latest alert, or lasts: a node that vanished) if any; among those, one that is not a
recurrence (an incident all of whose members had symptoms in incidents that ended before it
began) if any; among those the heaviest (the sum of its members' strongest anomalies), so a
minor symptom elsewhere does not displace a larger fault that is still going on; ties: the
newest.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import networkx as nx

from stream_viz.model.graph import FLOW
from stream_viz.model.queries import nodes_of_process, process_of_node
from stream_viz.rca.charge import pointed_nodes
from stream_viz.rca.episodes import INF, Episode, Evidence, as_evidence
from stream_viz.rca.settings import RcaSettings
from stream_viz.rca.symptoms import collect_symptoms, gone_members
from stream_viz.rca.trajectories import Context, RootCause, make_context
from stream_viz.records import Alert

Ranker = Callable[[Context], list[RootCause]]


@dataclass
class Incident:
    """One incident: its members' episodes in it, when, and its ranked root causes.

    ``end`` is the last alert (or evidence) time; ``ongoing`` whether it still goes on;
    ``recurring`` whether all its members had symptoms in incidents that ended before it began;
    ``weight`` the sum of its members' strongest anomalies; ``current`` whether the diagnosis is
    this incident's.
    """

    id: int
    episodes: dict[str, list[Episode]]
    start: float
    end: float
    ongoing: bool
    weight: float
    recurring: bool = False
    current: bool = False
    root_causes: list[RootCause] = field(default_factory=list)

    @property
    def members(self) -> list[str]:
        """The symptomatic members, sorted."""
        return sorted(self.episodes)

    def holds(self, member: str, t: float) -> bool:
        """True when ``member`` had a symptom episode of this incident at time ``t``."""
        return any(a <= t <= b for a, b in self.episodes.get(member, ()))

    def to_report(self) -> dict[str, Any]:
        """The incident in the report JSON (docs/contracts.md)."""
        return {"id": self.id, "members": self.members, "start": self.start, "end": self.end,
                "ongoing": self.ongoing, "current": self.current,
                "root_causes": [rc.to_report() for rc in self.root_causes]}


def neighbours(G: nx.MultiDiGraph, m: str) -> set[str]:
    """Members one hop from ``m``: data flow and service calls in either direction, a node's
    process and a process's nodes (not a process's parent: a launcher would join everything)."""
    if m not in G:
        return set()
    out = {x for x, keys in G._succ[m].items() if FLOW in keys}
    out |= {x for x, keys in G._pred[m].items() if FLOW in keys}
    kind = G.nodes[m].get("kind")
    if kind == "node":
        p = process_of_node(G, m)
        if p is not None:
            out.add(p)
    elif kind == "process":
        out.update(nodes_of_process(G, m))
    return out


def near(
    G: nx.MultiDiGraph, m: str, hops: int, targets: Iterable[str], links: Mapping[str, set[str]] | None = None
) -> set[str]:
    """Return the members of ``targets`` at most ``hops`` hops from ``m`` (`neighbours`, plus
    ``links``: extra one-hop pairs such as an alert and the node it names), ``m`` excluded."""
    want = set(targets)
    links = links or {}
    seen = {m}
    frontier = {m}
    for _ in range(hops):
        nxt = set()
        for x in frontier:
            nxt |= (neighbours(G, x) | links.get(x, set())) - seen
        if not nxt:
            break
        seen |= nxt
        frontier = nxt
    return (seen - {m}) & want


def _close(a: Episode, b: Episode, gap: float) -> bool:
    return a[0] <= b[1] + gap and b[0] <= a[1] + gap


def find_incidents(
    G: nx.MultiDiGraph,
    episodes: Mapping[str, list[Episode]],
    weight: Mapping[str, float],
    hops: int,
    gap: float,
    now: float,
    links: Mapping[str, set[str]] | None = None,
) -> list[Incident]:
    """Group symptom episodes into incidents (module docstring), oldest first, ids from 1.

    Parameters
    ----------
    G : MultiDiGraph
        The model.
    episodes : mapping
        Episodes per symptomatic member (ends INF while a state lasts).
    weight : mapping
        Strongest anomaly per member (an incident weighs the sum over its members).
    hops : int
        Farthest two members of one incident may be (per linked pair).
    gap : float
        Longest time between two episodes of one incident; an incident whose last episode ended
        longer ago than this before ``now`` is over.
    now : float
        The latest alert or evidence time.
    links : mapping, optional
        Extra one-hop pairs (member → members), e.g. an alert and the node it names.
    """
    items = [(m, ep) for m in sorted(episodes) for ep in episodes[m]]
    index: dict[str, list[int]] = {}
    for i, (m, _) in enumerate(items):
        index.setdefault(m, []).append(i)
    parent = list(range(len(items)))

    def root(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for m in index:
        for other in near(G, m, hops, index, links):
            for i in index[m]:
                for k in index[other]:
                    if _close(items[i][1], items[k][1], gap):
                        parent[root(i)] = root(k)
    groups: dict[int, list[int]] = {}
    for i in range(len(items)):
        groups.setdefault(root(i), []).append(i)
    out = []
    for members in groups.values():
        eps: dict[str, list[Episode]] = {}
        for i in members:
            eps.setdefault(items[i][0], []).append(items[i][1])
        start = min(a for v in eps.values() for a, _ in v)
        last = max(b for v in eps.values() for _, b in v)
        end = max(b if b < INF else max(a, now) for v in eps.values() for a, b in v)
        out.append(Incident(0, eps, start, end, last >= now - gap, sum(weight.get(m, 0.0) for m in eps)))
    out.sort(key=lambda inc: (inc.start, inc.members))
    for k, inc in enumerate(out, 1):
        inc.id = k
        before = set().union(*(o.episodes for o in out if o.end < inc.start))
        inc.recurring = bool(before) and set(inc.episodes) <= before
    return out


def current(incidents: list[Incident]) -> Incident | None:
    """Return the current incident (module docstring), or None when there is none."""
    if not incidents:
        return None
    return max(incidents, key=lambda inc: (inc.ongoing, not inc.recurring, round(inc.weight, 9), inc.start))


@dataclass
class Diagnosis:
    """The ranking of the current incident, every incident ranked, and the first symptom."""

    root_causes: list[RootCause]
    incidents: list[Incident]
    first: str | None


def diagnose(
    G: nx.MultiDiGraph,
    alerts: list[Alert],
    settings: RcaSettings,
    ranker: Ranker,
    members: Iterable[str] | None = None,
    evidence: Mapping[str, float | Evidence] | None = None,
    first: str | None = None,
) -> Diagnosis:
    """Find the incidents of ``alerts`` (of ``members`` only, when given: ``M_j``) and rank each.

    Every incident is ranked by ``ranker`` on its own alerts (those of its members during its
    episodes), with the metric evidence that has no time or held during it; the root causes of
    the current incident are the diagnosis. Without any incident (no alert, evidence without a
    time only) everything is ranked together, as one.

    Parameters
    ----------
    ranker : callable
        `Context` → ranked `RootCause` list (one of the engine's methods).
    first : str, optional
        The first detected symptom (where trajectories start when it is in the incident).
    """
    keep = None if members is None else set(members)
    s = collect_symptoms(alerts, settings, keep, gone_members(G))
    ev = {m: as_evidence(x) for m, x in (evidence or {}).items()}
    episodes = {m: list(eps) for m, eps in s.episodes.items()}
    weight = dict(s.anomaly)
    now = s.latest
    for m, e in ev.items():
        ep = e.episode()
        if ep is None or e.strength <= 0:
            continue
        episodes[m] = sorted([*episodes.get(m, []), ep])
        weight[m] = max(weight.get(m, 0.0), min(1.0, e.strength))
        now = max(now, ep[0] if ep[1] == INF else ep[1])
    links: dict[str, set[str]] = {}
    for m, name in s.named:
        for n in pointed_nodes(G, m, [name]):
            links.setdefault(m, set()).add(n)
            links.setdefault(n, set()).add(m)
    incidents = find_incidents(G, episodes, weight, settings.incident_hops, settings.episode_gap, now, links)
    now_inc = current(incidents)
    if now_inc is None:
        ctx = make_context(G, alerts, settings, keep, evidence, first)
        return Diagnosis(ranker(ctx), [], ctx.symptoms.first)
    chosen = [a for a in alerts if keep is None or a.member in keep]
    first_of: str | None = None
    for inc in incidents:
        mine = [a for a in chosen if inc.holds(a.member, a.t)]
        # evidence without a time counts in every incident; timed evidence in its own
        ev_inc = {m: e for m, e in ev.items() if not e.timed or e.episode() in inc.episodes.get(m, ())}
        ctx = make_context(G, mine, settings, None, ev_inc, first)
        inc.root_causes = ranker(ctx)
        if inc is now_inc:
            inc.current = True
            first_of = ctx.symptoms.first
    return Diagnosis(now_inc.root_causes, incidents, first_of)

