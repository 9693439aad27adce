"""Incidents: symptoms connected in the graph and close in time, diagnosed one by one.

A robot's alert history mixes faults: an old one that has ended, a warning that recurs somewhere
else, the fault of now. Ranked together, a loud old symptom can take the first place of the
fault a user is looking at. So symptom episodes (`stream_viz.rca.episodes`) are grouped first:
two episodes belong to one incident when one fault could explain both (single linkage: a chain
of such pairs is one incident). In the graph, their members are joined by a path of at most
``incident_hops`` hops with no collider (`ball`, `relation`): one is upstream of the other, or
both are downstream of a member between them; two publishers of ``/diagnostics`` are not. In
time, the episodes are at most ``episode_gap`` apart, in an order one fault can give, the effect
beginning within ``led_max`` of its cause (`_linked`: a node dead for minutes, or a warning
that has stood that long, is a standing condition, no cause of a new symptom). Metric evidence
joins the incident of the alert closest to it and links no two.
Each incident is ranked on its own alerts; the diagnosis is the ranking of the *current*
incident.

The current incident is one with a candidate at all (not, say, the metric evidence of a process
that hosts no node); among those an ongoing one (its last episode ended less than
``episode_gap`` before the latest alert, or lasts: a node that vanished) if any; among those
one with an alerted symptom still holding (within ``LASTING_S`` of the latest alert: a blip that
ended 20 s ago does not displace a fault whose alerts still come) if any; among those,
one that is not a recurrence (an incident all of whose members had symptoms in incidents that
ended before it began) if any; among those one that is news (it began more than ``led_max``
after every other ongoing one last changed: those stand, known) if any; among those one that
is a state, not an event (not `once`: one sample's log lines, said once and not again, as a
loaded robot's hiccup logs; a symptom still said is what is still wrong) if any; among those
the one whose best candidate stands out most (the strongest
hypothesis test ``ht`` among its candidates, the same for every ranking method), so a minor
symptom elsewhere does not displace a fault that is still going on; ties: the one with more
symptomatic members (a lone symptom as clear as the fault's does not displace its cascade),
then the newest.
"""

from __future__ import annotations

from collections.abc import Callable, Container, Iterable, Mapping
from dataclasses import dataclass, field
from itertools import pairwise
from typing import Any

import networkx as nx

from stream_viz.model.graph import FLOW
from stream_viz.model.queries import clients, nodes_of_process, process_of_node, servers
from stream_viz.model.traffic import idle
from stream_viz.rca.causal import publishers
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
    ``once`` whether its alerts are one alert of log lines (an event, said once; set when ranked);
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
    once: bool = False
    strength: float = 0.0
    first: str | None = None
    current: bool = False
    root_causes: list[RootCause] = field(default_factory=list)
    key: tuple = field(default=(), repr=False, compare=False)  # what its ranking was made from

    @property
    def members(self) -> list[str]:
        """The symptomatic members, sorted."""
        return sorted(self.episodes)

    @property
    def changed(self) -> float:
        """When its newest episode began: the last time something new went wrong in it."""
        return max(a for eps in self.episodes.values() for a, _ in eps)

    def to_report(self) -> dict[str, Any]:
        """The incident in the report JSON (docs/contracts.md)."""
        return {"id": self.id, "members": self.members, "start": self.start, "end": self.end,
                "ongoing": self.ongoing, "current": self.current,
                "root_causes": [rc.to_report() for rc in self.root_causes]}


def steps(G: nx.MultiDiGraph, m: str) -> tuple[set[str], set[str]]:
    """Members one hop from ``m`` as ``(up, down)``: up where a fault comes from (a topic's
    publishers, a node's inputs, the servers it calls), down where it goes; what acts both ways is
    in both (a node's process and a process's nodes; not a process's parent: a launcher would join
    everything)."""
    if m not in G:
        return set(), set()
    up: set[str] = set()
    down: set[str] = set()
    # A service call (client → server in the flow) acts against it: the client waits on the server.
    for x, keys in G._succ[m].items():
        if FLOW in keys:
            (up if keys[FLOW].get("kind") == "send" else down).add(x)
    for x, keys in G._pred[m].items():
        if FLOW in keys:
            (down if keys[FLOW].get("kind") == "send" else up).add(x)
    kind = G.nodes[m].get("kind")
    both: set[str] = set()
    if kind == "node":
        p = process_of_node(G, m)
        if p is not None:
            both.add(p)
    elif kind == "process":
        both.update(nodes_of_process(G, m))
    return up | both, down | both


SELF, UP, DOWN, MIXED = "self", "up", "down", "mixed"  # how a walk reached a member (`ball`)


def ball(
    G: nx.MultiDiGraph,
    m: str,
    radius: int,
    links: Mapping[str, set[str]] | None = None,
    cache: dict[str, tuple[set[str], set[str]]] | None = None,
    shut: Callable[[str, bool], bool] | None = None,
) -> dict[str, dict[str, int]]:
    """Return what ``m`` reaches in at most ``radius`` hops without a collider: member → {how →
    fewest hops}.

    A walk goes up (against the data flow: ``x`` is then upstream of ``m``), then down (along
    it), never down then up: two publishers of one topic meet at it head to head, and a fault of
    one does not reach the other that way. How: `SELF` (``m``), `UP` (up only), `DOWN` (down
    only: ``x`` is downstream of ``m``) or `MIXED` (up, then down: ``x`` and ``m`` share an
    upstream member). Steps are `steps` plus ``links``, extra pairs that act both ways (an alert
    and the node it names). ``cache`` (member → its steps) is filled and reused across calls on
    the same graph. A member ``shut(member, going up)`` says true of is not entered there (a
    topic that carried no message at the time passes no fault, `stream_viz.model.traffic`).
    """
    links = links or {}
    cache = {} if cache is None else cache

    def step(x: str) -> tuple[set[str], set[str]]:
        if x not in cache:
            up, down = steps(G, x)
            extra = links.get(x, set())
            cache[x] = (up | extra, down | extra)
        return cache[x]

    seen: dict[str, dict[str, int]] = {m: {SELF: 0}}
    frontier = [(m, SELF)]
    for d in range(1, radius + 1):
        nxt = []
        for x, how in frontier:
            up_x, down_x = step(x)
            moves = [(y, {SELF: DOWN, UP: MIXED}.get(how, how)) for y in down_x]
            if how in (SELF, UP):
                moves += [(y, UP) for y in up_x]
            for y, h in moves:
                if shut is not None and shut(y, h == UP):
                    continue
                hows = seen.setdefault(y, {})
                if h not in hows:
                    hows[h] = d
                    nxt.append((y, h))
        frontier = nxt
    return seen


def relation(a: str, b: str) -> set[str]:
    """How two members whose walks met (each walk's how, `ball`) relate: ``{"ab"}`` (the first is
    upstream of the second), ``{"ba"}``, ``{"fork"}`` (both downstream of a member between them),
    or empty (head to head: neither reaches the other)."""
    if a == SELF:
        return {"ab"} if b == UP else {"ba"} if b == DOWN else {"fork"} if b == MIXED else set()
    if b == SELF:
        return {"ba"} if a == UP else {"ab"} if a == DOWN else {"fork"} if a == MIXED else set()
    if UP in (a, b):
        other = b if a == UP else a
        return {"fork"} if other in (UP, MIXED) else {"ba"} if a == UP else {"ab"}
    return set()


_HOWS = (SELF, UP, DOWN, MIXED)
_RELATION = {(a, b): frozenset(relation(a, b)) for a in _HOWS for b in _HOWS}


def _close(a: Episode, b: Episode, gap: float) -> bool:
    return a[0] <= b[1] + gap and b[0] <= a[1] + gap


def _linked(r: set[str], sa: float, sb: float, lead: float, reach: float = INF) -> bool:
    """Whether symptoms of two members so related (`relation`), beginning at ``sa`` and ``sb``,
    can be one fault's: a cause comes first (its detection may lag by ``lead``) and its effects
    begin within ``reach`` of it (one that began longer before is a standing condition), and
    two effects of a cause that shows nothing begin together."""
    return (("ab" in r and sa - lead <= sb <= sa + reach) or ("ba" in r and sb - lead <= sa <= sb + reach)
            or ("fork" in r and abs(sa - sb) <= lead))


def find_incidents(
    G: nx.MultiDiGraph,
    episodes: Mapping[str, list[Episode]],
    hops: int,
    gap: float,
    now: float,
    links: Mapping[str, set[str]] | None = None,
    alerted: Mapping[str, list[Episode]] | None = None,
    lead: float | None = None,
    blamed: Iterable[tuple[str, float, str]] = (),
    tolerance: float = 2.0,
    blamed_only: Container[str] = (),
    reach: float = INF,
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
    lead : float, optional
        Longest a symptom may begin before that of a member only upstream of it, and be linked
        to it (the upstream one's detection lagged); ``gap`` when not given.
    blamed : iterable, optional
        ``(member, alert time, member it blames)``: that alert's episode is linked to the blamed
        member's episodes close in time that began before it (or within ``lead`` after), as if
        upstream of it, whatever the graph holds (a subscriber warning that its input lost the
        publisher that left).
    tolerance : float, optional
        Seconds within which two times count as one (a topic carrying just after a symptom
        began still carried to it).
    blamed_only : container, optional
        Members related by their ``blamed`` pairs alone, not through the graph: all their alerts
        say what they are about.
    reach : float, optional
        Longest a symptom may begin after that of a member upstream of it and be linked to it
        through the graph: a node that died, or a warning that has stood for minutes, is a
        standing condition, no cause of a new symptom downstream (``blamed`` pairs have no limit:
        the alert says what it is about).
    """
    lead = gap if lead is None else lead
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

    # Two members are joined within `hops` exactly when walks from both (`ball`) of at most
    # half that length meet at one point, one of them there going up only; their episodes are
    # linked where close in time and in an order one fault can give (`_linked`; single linkage).
    radius = (hops + 1) // 2
    cache: dict[str, tuple[set[str], set[str]]] = {}
    at: dict[str, list[tuple[str, dict[str, int]]]] = {}
    hull = {m: (min(items[i][1][0] for i in idx), max(items[i][1][1] for i in idx))
            for m, idx in index.items()}
    for m, idx in index.items():
        if m in blamed_only:
            continue
        # Its causes carried to it before its symptom began; it carried to its effects while
        # its symptom lasted.
        lo = hull[m][0] - gap
        began = max(items[i][1][0] for i in idx) + tolerance
        hi = max(min(items[i][1][1], now) for i in idx)

        def shut(x: str, up: bool, lo: float = lo, began: float = began, hi: float = hi) -> bool:
            return x not in episodes and idle(G, x, lo, began if up else hi)

        for x, hows in ball(G, m, radius, links, cache, shut).items():
            at.setdefault(x, []).append((m, hows))
    rel: dict[tuple[str, str], set[str]] = {}
    for there in at.values():  # members in sorted order (`index`'s)
        for k, (a, ha) in enumerate(there):
            lo, hi = hull[a][0] - gap, hull[a][1] + gap
            for b, hb in there[k + 1:]:
                if hull[b][0] > hi or hull[b][1] < lo:
                    continue  # no two of their episodes close in time
                found = [_RELATION[wa, wb] for wa, da in ha.items() for wb, db in hb.items()
                         if da + db <= hops]
                if found:
                    rel.setdefault((a, b), set()).update(*found)
    pairs = [(i, j) for (a, b), r in rel.items() for i in index[a] for j in index[b]
             if _close(items[i][1], items[j][1], gap)
             and _linked(r, items[i][1][0], items[j][1][0], lead, reach)]
    for idx in index.values():  # a member's own episodes close in time
        idx = sorted(idx, key=lambda i: items[i][1][0])
        reach = items[idx[0]][1][1]  # the latest end so far
        for prev, i in pairwise(idx):
            if items[i][1][0] <= reach + gap:
                pairs.append((prev, i))
            reach = max(reach, items[i][1][1])
    for m, t, n in blamed:
        mine = [i for i in index.get(m, ()) if items[i][1][0] <= t <= items[i][1][1]]
        pairs += [(i, j) for i in mine for j in index.get(n, ()) if _close(items[i][1], items[j][1], gap)
                  and _linked({"ab"}, items[j][1][0], items[i][1][0], lead)]
    said = [alerted is None or ep in alerted.get(m, ()) for m, ep in items]
    for i, j in pairs:
        if said[i] and said[j]:
            parent[root(i)] = root(j)
    # Metric evidence joins the group of the alert closest to it in time, and bridges no two:
    # a process's CPU burst between two unrelated faults is a hint for either, not a link.
    near: dict[int, tuple[float, int]] = {}
    for i, j in pairs:
        for e, a in ((i, j), (j, i)):
            if not said[e] and said[a]:
                d = abs(items[e][1][0] - items[a][1][0])
                if e not in near or d < near[e][0]:
                    near[e] = (d, a)
    for e, (_, a) in near.items():
        parent[root(e)] = root(a)
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


def current(incidents: list[Incident], reach: float = INF) -> Incident | None:
    """Return the current incident (module docstring), or None when there is none.

    ``reach``: an incident that began longer than this after every other ongoing one last
    changed (its newest episode began) is news: those stand unchanged, known already.
    """
    if not incidents:
        return None
    live = [inc for inc in incidents if inc.strength > 0 and inc.ongoing]

    def news(inc: Incident) -> bool:
        return all(inc.start > o.changed + reach for o in live if o is not inc)

    return max(incidents, key=lambda inc: (inc.strength > 0, inc.ongoing, inc.lasting, not inc.recurring,
                                           news(inc), not inc.once, round(inc.strength, 9), len(inc.episodes),
                                           inc.start))


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
    # A subscriber's warning that its input lost its publishers, and the publishers: an idle input
    # passes no fault (`ball`), but its publishers' departure it does show.
    # A member whose every alert is such a warning is related by them alone: the warning says
    # what it is about.
    lost: list[Alert] = []
    said: set[str] = set()
    for a in alerts:
        if keep is None or a.member in keep:
            if a.data and a.data.get("symptom") == "no_publisher" and a.data.get("topic") in G:
                lost.append(a)
            else:
                said.add(a.member)
    orphaned = [(a.member, a.t, p) for a in lost for p in publishers(G, a.data["topic"])]
    only = {a.member for a in lost} - said
    incidents = find_incidents(G, episodes, settings.incident_hops, settings.episode_gap, now, links,
                               s.episodes, settings.incident_lead, orphaned, settings.tolerance, only,
                               settings.led_max)
    if not incidents:
        ctx = make_context(G, alerts, settings, keep, evidence, first, gone)
        return Diagnosis(ranker(ctx), [], ctx.symptoms.first)
    mine = _split(alerts, keep, incidents)
    known = {inc.key: inc for inc in previous if inc.key}
    for inc in incidents:
        own = mine[inc.id]
        inc.once = len(own) == 1 and (own[0].data or {}).get("symptom") == "log"
        # evidence without a time counts in every incident; timed evidence in its own
        ev_inc = {m: e for m, e in ev.items() if not e.timed or e.episode() in inc.episodes.get(m, ())}
        inc.key = (tuple(sorted((m, tuple(v)) for m, v in inc.episodes.items())), len(own),
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
    now_inc = current(incidents, settings.led_max)
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
