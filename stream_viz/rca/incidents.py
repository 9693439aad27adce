"""Incidents: symptoms connected in the graph and close in time, diagnosed one by one.

A robot's alert history mixes faults: an old one that has ended, a warning that recurs somewhere
else, the fault of now. Ranked together, a loud old symptom can take the first place of the
fault a user is looking at. So symptom episodes (`stream_viz.rca.episodes`) are grouped first:
two episodes belong to one incident when their members are at most ``incident_hops`` hops apart
(data flow in either direction, service calls, a node and its process, an alert and the node it
names, a service and its servers and clients, a host with a symptom and its nodes) and the
episodes are at most ``episode_gap`` apart in time (single linkage: a chain of such pairs is one
incident). Each incident is ranked on its own alerts; the diagnosis is the ranking of the
*current* incident.

The current incident is one with a candidate at all (not, say, the metric evidence of a process
that hosts no node); among those an ongoing one (its last episode ended less than
``episode_gap`` before the latest alert, or lasts: a node that vanished) if any; among those
one with an alerted symptom still holding (within ``LASTING_S`` of the latest alert: a blip that
ended 20 s ago does not displace a fault whose alerts still come) if any; among those,
one that is not a recurrence (an incident all of whose members had symptoms in incidents that ended before it
began) if any; among those the one whose best candidate stands out most (the strongest
hypothesis test ``ht`` among its candidates, the same for every ranking method), so a minor
symptom elsewhere does not displace a fault that is still going on; ties: the one with more
symptomatic members (a lone symptom as clear as the fault's does not displace its cascade),
then the newest.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import networkx as nx

from stream_viz.model.graph import FLOW
from stream_viz.model.queries import clients, nodes_of_process, process_of_node, servers
from stream_viz.rca.charge import pointed_nodes
from stream_viz.rca.episodes import INF, Episode, Evidence, as_evidence
from stream_viz.rca.settings import RcaSettings
from stream_viz.rca.symptoms import collect_symptoms, gone_members
from stream_viz.rca.trajectories import Context, RootCause, make_context
from stream_viz.records import Alert

Ranker = Callable[[Context], list[RootCause]]


LASTING_S = 10.0  # a symptom within this of the latest alert still holds (stored every 5 s)


@dataclass
class Incident:
    """One incident: its members' episodes in it, when, and its ranked root causes.

    ``end`` is the last alert (or evidence) time; ``ongoing`` whether it still goes on (its
    last episode ended less than the episode gap ago); ``lasting`` whether an alerted symptom of
    it held within `LASTING_S` of the latest alert;
    ``recurring`` whether all its members had symptoms in incidents that ended before it began;
    ``strength`` the strongest hypothesis test among its candidates and ``first`` the member of
    its earliest alert (set when it is ranked);
    ``current`` whether the diagnosis is this incident's; ``key`` what its ranking was made from
    (episodes, alerts, evidence, graph).
    """

    id: int
    episodes: dict[str, list[Episode]]
    start: float
    end: float
    ongoing: bool
    lasting: bool = False
    recurring: bool = False
    strength: float = 0.0
    first: str | None = None
    current: bool = False
    root_causes: list[RootCause] = field(default_factory=list)
    key: tuple = field(default=(), repr=False, compare=False)  # what its ranking was made from

    @property
    def members(self) -> list[str]:
        """The symptomatic members, sorted."""
        return sorted(self.episodes)

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


def ball(
    G: nx.MultiDiGraph,
    m: str,
    radius: int,
    links: Mapping[str, set[str]] | None = None,
    cache: dict[str, set[str]] | None = None,
    rim: bool = False,
) -> set[Any]:
    """Return the members at most ``radius`` hops from ``m`` (`neighbours`, plus ``links``: extra
    one-hop pairs such as an alert and the node it names), ``m`` included.

    With ``rim``, also the edges leaving the outermost of them, as sorted ``(u, v)`` pairs: two
    members are at most ``2 radius + 1`` hops apart exactly when their balls with rims share a
    member or an edge (its midpoint). ``cache`` (member → its one-hop members) is filled and
    reused across calls on the same graph.
    """
    links = links or {}
    cache = {} if cache is None else cache

    def step(x: str) -> set[str]:
        if x not in cache:
            cache[x] = neighbours(G, x) | links.get(x, set())
        return cache[x]

    seen: set[Any] = {m}
    frontier = {m}
    for _ in range(radius):
        nxt = set()
        for x in frontier:
            nxt |= step(x) - seen
        seen |= nxt
        frontier = nxt
    if rim:
        seen |= {(x, y) if x < y else (y, x) for x in frontier for y in step(x)}
    return seen


def _close(a: Episode, b: Episode, gap: float) -> bool:
    return a[0] <= b[1] + gap and b[0] <= a[1] + gap


def find_incidents(
    G: nx.MultiDiGraph,
    episodes: Mapping[str, list[Episode]],
    hops: int,
    gap: float,
    now: float,
    links: Mapping[str, set[str]] | None = None,
    alerted: Mapping[str, list[Episode]] | None = None,
) -> list[Incident]:
    """Group symptom episodes into incidents (module docstring), oldest first, ids from 1.

    Parameters
    ----------
    G : MultiDiGraph
        The model.
    episodes : mapping
        Episodes per symptomatic member (ends INF while a state lasts).
    hops : int
        Farthest two members of one incident may be (per linked pair).
    gap : float
        Longest time between two episodes of one incident; an incident whose last episode ended
        longer ago than this before ``now`` is over.
    now : float
        The latest alert or evidence time.
    links : mapping, optional
        Extra one-hop pairs (member → members), e.g. an alert and the node it names.
    alerted : mapping, optional
        The episodes that are alerts' (of ``episodes``): a group with none of them is no
        incident (metric evidence is a hint where something alerted, not a symptom of its own).
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

    # Two members are at most `hops` apart exactly when their balls of half that radius meet; the
    # episodes of the members whose balls hold one point are linked where close in time (a sweep
    # by start: single linkage of intervals).
    radius, odd = divmod(hops, 2)
    cache: dict[str, set[str]] = {}
    at: dict[Any, list[int]] = {}
    for m in index:
        for x in ball(G, m, radius, links, cache, rim=bool(odd)):
            at.setdefault(x, []).extend(index[m])
    for xs in at.values():
        if len(xs) < 2:
            continue
        xs.sort(key=lambda i: items[i][1][0])
        run, run_end = xs[0], items[xs[0]][1][1]
        for i in xs[1:]:
            start, end = items[i][1]
            if start <= run_end + gap:
                parent[root(i)] = root(run)
                run_end = max(run_end, end)
            else:
                run, run_end = i, end
    groups: dict[int, list[int]] = {}
    for i in range(len(items)):
        groups.setdefault(root(i), []).append(i)
    out = []
    for members in groups.values():
        if alerted is not None and not any(items[i][1] in alerted.get(items[i][0], ()) for i in members):
            continue
        eps: dict[str, list[Episode]] = {}
        for i in members:
            eps.setdefault(items[i][0], []).append(items[i][1])
        start = min(a for v in eps.values() for a, _ in v)
        last = max(b for v in eps.values() for _, b in v)
        end = max(b if b < INF else max(a, now) for v in eps.values() for a, b in v)
        # Lasting by its alerts: metric evidence (a hint, such as a process's CPU burst) keeps no
        # blip that ended current over a fault whose alerts still come.
        said = [items[i][1][1] for i in members
                if alerted is None or items[i][1] in alerted.get(items[i][0], ())]
        out.append(Incident(0, eps, start, end, last >= now - gap, max(said) >= now - LASTING_S))
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
    return max(incidents, key=lambda inc: (inc.strength > 0, inc.ongoing, inc.lasting, not inc.recurring,
                                           round(inc.strength, 9), len(inc.episodes), inc.start))


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
    previous: Iterable[Incident] = (),
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
    previous : iterable of Incident
        The last diagnosis's incidents: one whose episodes, alerts and evidence are unchanged
        (an incident that has ended), in a graph with the same members, keeps its ranking
        instead of being ranked again.
    """
    keep = None if members is None else set(members)
    gone = gone_members(G)
    s = collect_symptoms(alerts, settings, keep, gone)
    ev = {m: as_evidence(x) for m, x in (evidence or {}).items()}
    episodes = {m: list(eps) for m, eps in s.episodes.items()}
    now = s.latest
    for m, e in ev.items():
        ep = e.episode()
        if ep is None or e.strength <= 0:
            continue
        episodes[m] = sorted([*episodes.get(m, []), ep])
        now = max(now, ep[0] if ep[1] == INF else ep[1])
    # One hop beyond the flow edges: an alert and the nodes it names; a service (it has no edge)
    # and its servers and clients.
    pairs = [(m, n) for m, name in s.named for n in pointed_nodes(G, m, [name])]
    pairs += [(m, n) for m in episodes if m.startswith(("service:", "action:"))
              for n in (*servers(G, m), *clients(G, m))]
    # A host with a symptom of its own and the nodes on it (only then: a host would join everything).
    pairs += [(m, n) for m in episodes if m.startswith("host:") for n in nodes_of_process(G, m)]
    links: dict[str, set[str]] = {}
    for m, n in pairs:
        links.setdefault(m, set()).add(n)
        links.setdefault(n, set()).add(m)
    if not s.count:  # evidence alone, with nothing alerted, names no cause
        return Diagnosis([], [], None)
    incidents = find_incidents(G, episodes, settings.incident_hops, settings.episode_gap, now, links,
                               s.episodes)
    if not incidents:
        ctx = make_context(G, alerts, settings, keep, evidence, first, gone)
        return Diagnosis(ranker(ctx), [], ctx.symptoms.first)
    mine = _split(alerts, keep, incidents)
    known = {inc.key: inc for inc in previous if inc.key}
    for inc in incidents:
        # evidence without a time counts in every incident; timed evidence in its own
        ev_inc = {m: e for m, e in ev.items() if not e.timed or e.episode() in inc.episodes.get(m, ())}
        inc.key = (tuple(sorted((m, tuple(v)) for m, v in inc.episodes.items())), len(mine[inc.id]),
                   tuple(sorted(ev_inc.items())), G.number_of_nodes(), len(gone), first)
        if inc.key in known:  # unchanged since the last diagnosis (an incident that has ended)
            old = known[inc.key]
            inc.root_causes, inc.strength, inc.first = old.root_causes, old.strength, old.first
            continue
        whole = s if len(mine[inc.id]) == s.count else None  # all the alerts: symptoms as collected
        ctx = make_context(G, mine[inc.id], settings, None, ev_inc, first, gone, whole)
        inc.root_causes = ranker(ctx)
        inc.strength = max((v.ht for v in ctx.views.values()), default=0.0)
        inc.first = ctx.symptoms.first
    now_inc = current(incidents)
    assert now_inc is not None  # there are incidents
    now_inc.current = True
    return Diagnosis(now_inc.root_causes, incidents, now_inc.first)


def _split(alerts: list[Alert], keep: set[str] | None, incidents: list[Incident]) -> dict[int, list[Alert]]:
    """The alerts of each incident (by id): those of its members during its episodes."""
    owner: dict[str, list[tuple[float, float, int]]] = {}
    for inc in incidents:
        for m, eps in inc.episodes.items():
            owner.setdefault(m, []).extend((a, b, inc.id) for a, b in eps)
    out: dict[int, list[Alert]] = {inc.id: [] for inc in incidents}
    for a in alerts:
        if keep is not None and a.member not in keep:
            continue
        for lo, hi, k in owner.get(a.member, ()):
            if lo <= a.t <= hi:
                out[k].append(a)
                break
    return out
