"""From alerts to symptoms per member, and the per-node view the rankers share.

A symptom on a passive member (a topic's rate dropped) is charged to its publisher node(s) — with
several publishers, to those whose own traffic or evidence changed (`charge`); an alert on a
process to the nodes it hosts; an alert naming a server to that server. So every candidate is a
node, and a node whose output went silent is a candidate even when it raised no alert itself
(hang, degrade, delay). Symptoms have a time: episodes of alerts (`episodes`), and metric
evidence with a since/until; a cause excuses an effect only while its episode lasts.
"""

from __future__ import annotations

from collections.abc import Callable, Collection, Iterable, Iterator, Mapping
from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from stream_viz.model.queries import (
    called_servers,
    calling_clients,
    nodes_of_process,
    process_of_node,
    subscribed_topics,
)
from stream_viz.model.traffic import idle, measured
from stream_viz.rca import siblings
from stream_viz.rca.causal import causes_in, effects, is_node, outputs, publishers
from stream_viz.rca.charge import CARRIED, NAME_KEYS, charged_nodes, names_in, pointed_nodes, publisher_shares
from stream_viz.rca.episodes import Episode, Evidence, as_evidence, merge, overlaps
from stream_viz.rca.settings import RcaSettings
from stream_viz.records import Alert

INF = float("inf")
IMPLIED_SERVER = 0.5  # a server suspected only because a client of it stands unexplained
IMPLIED_FELLOW = 0.5  # a node suspected only because the executor it shares with a silent one stopped
UNEXPLAINED = 0.5  # a client whose inputs explain less than this makes its servers suspects
FOLLOWS = 0.1  # an output whose beat is within this fraction of its input's follows it one to one


@dataclass
class Symptoms:
    """Alerts in the analysis window, per member.

    ``times`` sorted unique alert times; ``onset`` first alert time; ``anomaly`` the strongest
    alert (severity weight × plugin factor) in [0, 1]; ``relevance`` the sum of severity weights
    (count × severity); ``plugins`` distinct plugin names; ``first`` the member of the earliest
    alert (the first symptom); ``episodes`` runs of alerts at most ``episode_gap`` apart (the
    last one open, end INF, for a member that is gone); ``own_anomaly``/``own_onset`` the same
    as ``anomaly``/``onset`` without the alerts a node got for its process (``data["process"]``)
    — but its process's death is its own when it logged last as it died (``last_words``);
    ``named`` the names alerts give of what to blame: ``(alert member, name)`` → (first time,
    strongest severity weight); ``logged`` when a member's own log lines (symptom ``log``) began
    to alert, or its last words' stamp — a node that logs is running, which a starved one is
    not; ``exited`` when a node's
    process was seen to die (an alert for its process with symptom ``exit``), ``killed`` those whose
    process was killed by a signal sent to it (data ``killed``: no input of theirs did that);
    ``latest`` the latest
    alert time; ``count`` how many alerts they come from; ``began`` when a member's symptom
    began by its own alerts' word (data ``since``: a host saturated for a while before it alerts,
    a topic's last message, a log line's stamp) and ``began_by`` the latest it can have begun
    (``since`` + data ``since_within``: a silence began by the next message due); ``vague`` the
    first time of its alerts that do not say (their symptom began up to ``tolerance`` before);
    ``culprits`` the publishers a topic's alerts name as the ones whose own messages are the
    symptom (data ``publishers``: stale stamps of one of ``/tf``'s publishers, one stopped), with
    the first time each was named;
    ``executor_stopped`` the members an alert said stopped with their publisher's executor (data
    ``executor_stopped``: its thread idle while its input arrives); ``executor_idle`` those an
    alert said went silent with their publisher's single-threaded executor idle, inputs or not
    (data ``executor_idle``); ``silence`` a silent member's
    newest message and its beat (data ``since``, ``since_within``: its next was due at their sum),
    of its newest silence; ``logged_at`` when a silent member's publisher last logged, any level
    (data ``logged_at``); ``carried`` the members every alert of which is a symptom the
    messages carry (`charge.CARRIED`: stale, out of sync, late).
    """

    times: dict[str, np.ndarray] = field(default_factory=dict)
    onset: dict[str, float] = field(default_factory=dict)
    anomaly: dict[str, float] = field(default_factory=dict)
    relevance: dict[str, float] = field(default_factory=dict)
    plugins: dict[str, set[str]] = field(default_factory=dict)
    first: str | None = None
    episodes: dict[str, list[Episode]] = field(default_factory=dict)
    own_anomaly: dict[str, float] = field(default_factory=dict)
    own_onset: dict[str, float] = field(default_factory=dict)
    named: dict[tuple[str, str], tuple[float, float]] = field(default_factory=dict)
    logged: dict[str, float] = field(default_factory=dict)
    exited: dict[str, float] = field(default_factory=dict)
    killed: set[str] = field(default_factory=set)
    began: dict[str, float] = field(default_factory=dict)
    began_by: dict[str, float] = field(default_factory=dict)
    vague: dict[str, float] = field(default_factory=dict)
    culprits: dict[str, dict[str, float]] = field(default_factory=dict)
    executor_stopped: set[str] = field(default_factory=set)
    executor_idle: set[str] = field(default_factory=set)
    silence: dict[str, tuple[float, float]] = field(default_factory=dict)
    logged_at: dict[str, float] = field(default_factory=dict)
    carried: set[str] = field(default_factory=set)
    latest: float = -INF
    count: int = 0


def gone_members(G: nx.MultiDiGraph) -> set[str]:
    """Return the members of ``G`` marked ``gone`` (vanished: their symptom lasts)."""
    return {m for m, d in G._node.items() if d.get("gone")}  # the attribute dicts: no data view


def collect_symptoms(
    alerts: Iterable[Alert],
    settings: RcaSettings,
    members: Iterable[str] | None = None,
    gone: Collection[str] = (),
) -> Symptoms:
    """Return the symptoms of ``alerts`` (only members in ``members`` when given, e.g. ``M_j``).

    Alerts older than ``settings.window`` seconds before the latest one are left out (window 0:
    none is). Unknown severities count as ``warn``. A member in ``gone`` has vanished: its last
    episode lasts (a crash is reported once, and stays a crash).
    """
    keep = None if members is None else set(members)
    chosen = [a for a in alerts if keep is None or a.member in keep]
    if not chosen:
        return Symptoms()
    if settings.window > 0:
        latest = max(a.t for a in chosen)
        chosen = [a for a in chosen if a.t >= latest - settings.window]
    sev = settings.severity
    warn = sev.get("warn", 0.5)
    direct = set(settings.direct_plugins)
    raw: dict[str, list[float]] = {}
    s = Symptoms()
    # Local names and one branch per member's first alert: this loop runs over every alert of
    # the window at every update.
    anomaly, relevance, plugins = s.anomaly, s.relevance, s.plugins
    own_anomaly, own_onset, logged, exited, named = s.own_anomaly, s.own_onset, s.logged, s.exited, s.named
    first_t, latest = INF, s.latest
    absent: set[str] = set()  # members with an alert whose symptom the messages do not carry
    for a in chosen:
        m, t, data = a.member, a.t, a.data
        if not (data and data.get("symptom") in CARRIED):
            absent.add(m)
        w = sev.get(a.severity, warn)
        factor = 1.0 if (a.plugin in direct or not m.startswith("node:")) else settings.charge
        x = min(1.0, w * factor)
        ts = raw.get(m)
        if ts is None:
            raw[m] = [t]
            anomaly[m] = max(0.0, x)
            relevance[m] = 0.0 + w
            plugins[m] = {a.plugin}
        else:
            ts.append(t)
            anomaly[m] = max(anomaly[m], x)
            relevance[m] += w
            plugins[m].add(a.plugin)
        if not (data and data.get("process")):  # not an alert a node got for its process
            own_anomaly[m] = max(own_anomaly.get(m, 0.0), x)
            own_onset[m] = min(own_onset.get(m, INF), t)
            if data and data.get("symptom") == "log":
                logged[m] = min(logged.get(m, INF), t)
        elif data.get("symptom") == "exit":
            exited[m] = min(exited.get(m, INF), t)
            if data.get("killed") is True:
                s.killed.add(m)
            said = data.get("last_words")
            if isinstance(said, dict) and said.get("node") == m:
                # It logged last as its process died: running then, the crash its own change.
                own_anomaly[m] = max(own_anomaly.get(m, 0.0), x)
                own_onset[m] = min(own_onset.get(m, INF), t)
                at = said.get("t")
                logged[m] = min(logged.get(m, INF), float(at) if isinstance(at, int | float) else t)
        if data and data.get("executor_stopped") is True:
            s.executor_stopped.add(m)
        if data and data.get("executor_idle") is True:
            s.executor_idle.add(m)
        if data and isinstance(data.get("publishers"), list) and m.startswith("topic:"):
            named_at = s.culprits.setdefault(m, {})
            for p in data["publishers"]:
                if isinstance(p, str):
                    named_at[p] = min(named_at.get(p, INF), t)
        if data and isinstance(since := data.get("since"), int | float):
            s.began[m] = min(s.began.get(m, INF), float(since), t)
            within = data.get("since_within", 0.0)
            within = float(within) if isinstance(within, int | float) and within > 0 else 0.0
            if within and float(since) > s.silence.get(m, (-INF,))[0]:  # its newest silence
                s.silence[m] = (float(since), within)
            if isinstance(said := data.get("logged_at"), int | float):
                s.logged_at[m] = max(s.logged_at.get(m, -INF), float(said))
            s.began_by[m] = min(s.began_by.get(m, INF), float(since) + within, t)
        else:
            s.vague[m] = min(s.vague.get(m, INF), t)
        if data and not data.keys().isdisjoint(NAME_KEYS):
            for name in names_in(data):
                t0, w0 = named.get((m, name), (INF, 0.0))
                named[(m, name)] = (min(t0, t), max(w0, w))
        if t < first_t:
            first_t, s.first = t, m
        latest = max(latest, t)
    s.latest = latest
    s.count = len(chosen)
    s.carried = set(raw) - absent
    for m, ts in raw.items():
        s.times[m] = np.asarray(sorted(set(ts)), dtype=float)  # np.unique costs more on short lists
        s.onset[m] = float(s.times[m][0])
        s.episodes[m] = merge(s.times[m], settings.episode_gap)
        if m in gone:
            s.episodes[m][-1] = (s.episodes[m][-1][0], INF)
    return s


@dataclass
class NodeView:
    """What the rankers know about one candidate node.

    ``direct``: its own alerts (and its process's); ``charged``: symptoms of its outputs, of the
    services it serves and of alerts naming it × ``charge``; ``evidence``: metric anomaly;
    ``anomaly`` the max of the three; ``onset`` when its own or charged symptoms (or timed
    evidence) began; ``upstream`` how anomalous its causal parents were while its symptoms began
    (within ``episode_gap`` before its onset up to ``tolerance`` after), or a sibling in its process
    that changed first (``sibling``); ``ht`` = anomaly × (1 − upstream), the hypothesis test.

    ``own_*``: the same without what it shares with its process (the process's alerts and
    metric evidence) — what tells it apart from its siblings; ``own_kinds`` which kinds of own
    change it has (``alert``, ``output``, ``named``, ``metric``). ``spans`` the episodes of its
    symptoms; ``untimed`` the strength of metric evidence without a time. ``implied``: a server
    suspected only because a client of it stands unexplained (it excuses nobody). ``process`` and
    ``indistinguishable``: the process it shares with other candidates, and those of them whose
    own changes are the same as its own. ``logged``: when its own log lines began to alert;
    ``exited``: when its process was seen to die; ``executor_stopped``: an output of its stopped
    with its executor, ``executor_idle``: one went silent with its executor idle (`Symptoms`).
    ``began``/``began_by``/``vague``: the earliest
    and latest its symptoms can have begun by their alerts' word, and the first time of those that
    do not say (`Symptoms`): what `began_after` compares. ``awaited``: the clients calling it
    that complained while its symptoms were on (`_await`). ``due``/``beat``/``last``: of its
    silent outputs, when the first next message was due and that output's beat, and its newest
    message (`siblings.blocked_first` reads them), ``logged_at`` when it last logged, any level,
    as its silence was seen (`siblings.ran_last`), and ``inputs`` the newest arrival and beat of
    each stopped input its outputs do not follow; ``blocked``: how likely its callback blocked
    the executor of a stall it is in (None: not told by that).
    """

    member: str
    direct: float = 0.0
    charged: float = 0.0
    evidence: float = 0.0
    anomaly: float = 0.0
    onset: float = INF
    upstream: float = 0.0
    ht: float = 0.0
    own: list[str] = field(default_factory=list)  # symptomatic members charged to it (itself first)
    plugins: set[str] = field(default_factory=set)
    own_direct: float = 0.0
    own_evidence: float = 0.0
    own_anomaly: float = 0.0
    own_onset: float = INF
    own_kinds: set[str] = field(default_factory=set)
    spans: list[Episode] = field(default_factory=list)
    metric_spans: list[Episode] = field(default_factory=list)  # those of ``spans`` from evidence
    untimed: float = 0.0
    implied: bool = False
    sibling: float = 0.0
    process: str | None = None
    indistinguishable: list[str] = field(default_factory=list)
    logged: float = INF
    exited: float = INF
    began: float = INF
    began_by: float = INF
    vague: float = INF
    executor_stopped: bool = False
    executor_idle: bool = False
    awaited: list[str] = field(default_factory=list)
    due: float = INF
    beat: float = 0.0
    last: float = -INF
    logged_at: float = -INF
    blocked: float | None = None
    inputs: list[tuple[float, float]] = field(default_factory=list)

    def active(self, t0: float, t1: float, own: bool = False) -> float:
        """Its anomaly when one of its symptoms held in ``[t0, t1]``; else its untimed evidence
        when it has no timed symptom at all; else 0. ``own``: only what it does not share with
        its process (asked by a node of the same process)."""
        x = self.own_anomaly if own else self.anomaly
        if overlaps(self.spans, t0, t1):
            return x
        return 0.0 if self.spans else min(self.untimed, x) if own else self.untimed

    def alerted(self, t0: float, t1: float, own: bool = False) -> float:
        """As `active`, from its alerts alone (its own, its process's, those charged to it): no
        metric evidence."""
        x = max(self.own_direct if own else self.direct, self.charged)
        if not x:
            return 0.0
        spans = [sp for sp in self.spans if sp not in self.metric_spans] if self.metric_spans else self.spans
        return x if overlaps(spans, t0, t1) else 0.0


def _clip(x: float) -> float:
    return float(min(1.0, max(0.0, x)))


Starts = tuple[float, float, float]  # began, began_by, vague (`NodeView`)


def _starts_of(s: Symptoms, m: str) -> Starts:
    return s.began.get(m, INF), s.began_by.get(m, INF), s.vague.get(m, INF)


def _start(v: NodeView, starts: Starts) -> None:
    v.began, v.began_by = min(v.began, starts[0]), min(v.began_by, starts[1])
    v.vague = min(v.vague, starts[2])


def _metric(v: NodeView, e: Evidence, own: bool) -> None:
    v.evidence = max(v.evidence, e.strength)
    ep = e.episode()
    if ep is None:
        v.untimed = max(v.untimed, e.strength)
    else:
        v.onset = min(v.onset, ep[0])
        v.spans.append(ep)
        v.metric_spans.append(ep)
        _start(v, (INF, INF, ep[0]))
    if own:
        v.own_evidence = max(v.own_evidence, e.strength)
        v.own_onset = min(v.own_onset, ep[0] if ep else INF)
        v.own_kinds.add("metric")


def _charge(v: NodeView, m: str, x: float, onset: float, spans: list[Episode], kind: str,
            starts: Starts | None = None) -> None:
    """Charge the symptom ``m`` (strength ``x``, from ``onset``; ``starts``: when it began by its
    alerts' word, default ``onset`` without a word) to ``v`` as its own change."""
    v.charged = max(v.charged, x)
    v.onset = min(v.onset, onset)
    _start(v, (INF, INF, onset) if starts is None else starts)
    v.own_onset = min(v.own_onset, onset)
    v.own_kinds.add(kind)
    v.spans += spans
    if m not in v.own:
        v.own.append(m)


def node_views(
    G: nx.MultiDiGraph,
    s: Symptoms,
    settings: RcaSettings,
    evidence: Mapping[str, float | Evidence] | None = None,
) -> dict[str, NodeView]:
    """Return a `NodeView` for every node with a symptom, a charged symptom or metric evidence.

    ``evidence``: metric anomaly per member (a node or a process; others excuse their
    subscribers only), a number in [0, 1] (no time) or `Evidence` with its since/until.
    """
    views: dict[str, NodeView] = {}
    ev_passive = _metric_views(G, views, evidence or {}, settings.metric)
    shared_by = _alert_views(G, views, s, settings.charge, settings.tolerance)
    _charge_shared(G, s, views, shared_by, settings)
    _fed_dues(G, s, views)
    stalled = siblings.stalls(G, views, settings.tolerance)
    _settle(G, views, views, s, ev_passive, settings, stalled)
    _imply_servers(G, s, views, ev_passive, settings)
    _imply_fellows(G, s, views, ev_passive, settings)
    _await(G, views, settings)
    for n, verdict in siblings.judge(G, views, settings.tolerance, stalled).items():
        v = views[n]
        v.process, v.sibling, v.indistinguishable = verdict.process, verdict.excuse, verdict.indistinguishable
        v.blocked = verdict.blocked
        v.upstream = max(v.upstream, v.sibling)
    for v in views.values():
        v.ht = v.anomaly * (1.0 - v.upstream)
    return views


def _view(views: dict[str, NodeView], n: str) -> NodeView:
    if n not in views:
        views[n] = NodeView(n)
    return views[n]


def _metric_views(
    G: nx.MultiDiGraph, views: dict[str, NodeView], evidence: Mapping[str, float | Evidence],
    weight: float,
) -> dict[str, Evidence]:
    """Put metric evidence, its strength × ``weight``, on the nodes it is about (a process's on
    its nodes, as shared); return the evidence of passive members (topics), which only excuses
    their subscribers."""
    ev_passive: dict[str, Evidence] = {}
    for m, x in evidence.items():
        e = as_evidence(x)
        e = Evidence(_clip(e.strength) * weight, e.since, e.until)
        if e.strength <= 0:
            continue
        if is_node(G, m):
            _metric(_view(views, m), e, own=True)
        elif m.startswith("process:"):
            for n in nodes_of_process(G, m):
                _metric(_view(views, n), e, own=False)
        else:
            ev_passive[m] = e
    return ev_passive


def _alert_views(
    G: nx.MultiDiGraph, views: dict[str, NodeView], s: Symptoms, charge: float, tolerance: float,
) -> list[tuple[str, list[str]]]:
    """Put the symptoms on nodes: a node's own, its process's (shared), a passive member's on its
    only publisher, a named member's on the nodes the name points at (from when the complaining
    node's symptoms began, `_waited_since`); return the passive members with several publishers
    (charged later, by `_charge_shared`)."""
    shared_by: list[tuple[str, list[str]]] = []
    for m, a in s.anomaly.items():
        if is_node(G, m):
            v = _view(views, m)
            v.direct = max(v.direct, a)
            v.onset = min(v.onset, s.onset[m])
            v.own.insert(0, m)
            v.plugins |= s.plugins[m]
            v.spans += s.episodes[m]
            _start(v, _starts_of(s, m))
            v.exited = min(v.exited, s.exited.get(m, INF))
            if m in s.own_anomaly:
                v.own_direct = max(v.own_direct, s.own_anomaly[m])
                v.own_onset = min(v.own_onset, s.own_onset[m])
                v.own_kinds.add("alert")
                v.logged = min(v.logged, s.logged.get(m, INF))
        elif m.startswith(("process:", "host:")) or m == "root":
            for n in nodes_of_process(G, m):
                v = _view(views, n)
                v.direct = max(v.direct, a)
                v.onset = min(v.onset, s.onset[m])
                v.own.append(m)
                v.plugins |= s.plugins[m]
                v.spans += s.episodes[m]
                # A host's or process's "since" is a sample's time (a run of high values): vague.
                _start(v, (INF, INF, min(s.began.get(m, INF), s.vague.get(m, INF))))
        else:
            nodes = charged_nodes(G, m)
            if len(nodes) > 1:
                shared_by.append((m, nodes))
            for n in nodes if len(nodes) == 1 else ():
                _charge(_view(views, n), m, a * charge, s.onset[m], s.episodes[m], "output", _starts_of(s, m))
                views[n].executor_stopped |= m in s.executor_stopped
                views[n].executor_idle |= m in s.executor_idle
                _beat(views[n], s, m)
    for (m, name), (t, w) in s.named.items():
        spans = [(max(a, t), b) for a, b in s.episodes[m] if b >= t]
        since = _waited_since(views.get(m), t, tolerance)
        if spans:
            spans[0] = (min(spans[0][0], since), spans[0][1])
        for n in pointed_nodes(G, m, [name]):
            _charge(_view(views, n), m, _clip(w * charge), since, spans, "named")
    return shared_by


def _beat(v: NodeView, s: Symptoms, m: str) -> None:
    """Note the silence of ``v``'s output ``m``: when its next message was due and its beat, and
    its newest message before it (what told when a stalled executor blocked, `siblings`)."""
    if m in s.silence:
        last, beat = s.silence[m]
        if last + beat < v.due:
            v.due, v.beat = last + beat, beat
        v.last = max(v.last, last)
    v.logged_at = max(v.logged_at, s.logged_at.get(m, -INF))


def _fed_dues(G: nx.MultiDiGraph, s: Symptoms, views: Mapping[str, NodeView]) -> None:
    """Read a silent node's stopped inputs. When its outputs follow one one to one (the same beat,
    within `FOLLOWS`) and its newest message came after the node's own newest output, move the
    node's due to it: its callback on that message never published (a filter in a container's
    pipeline whose predecessor published its last message). Another input (whose callback
    publishes nothing) goes to ``inputs``: its newest arrival may be where a callback blocked."""
    for n, v in views.items():
        if v.due == INF:
            continue
        for t in subscribed_topics(G, n):
            got = s.silence.get(t)
            if got is None:
                continue
            if abs(got[1] - v.beat) > FOLLOWS * v.beat:
                v.inputs.append(got)
            elif got[0] > v.last:
                v.due = min(v.due, got[0])


def _waited_since(client: NodeView | None, t: float, tolerance: float) -> float:
    """When the complaint a ``client`` made at ``t`` began: a client waits before it complains
    (a call times out), so its symptoms still going on at ``t`` (its outputs stalled meanwhile)
    date what it names from their start."""
    if client is None:
        return t
    return min([t, *(a for a, b in client.spans if a <= t <= b + tolerance)])


def _charge_shared(
    G: nx.MultiDiGraph, s: Symptoms, views: dict[str, NodeView], shared_by: list[tuple[str, list[str]]],
    settings: RcaSettings,
) -> None:
    """Charge the symptoms of members with several publishers: each publisher's share follows its
    own traffic or the evidence of its own around the symptom (`charge.publisher_shares`), judged
    on what was charged before any such member; a publisher the alerts named only later than the
    topic's first alert (its own stop came later: `/diagnostics` from a container's nodes) is
    charged from then."""
    gap = settings.episode_gap
    shares = {}
    for m, nodes in shared_by:
        lo, hi = s.onset[m] - gap, s.episodes[m][-1][1] + gap
        other = {n: max(v.direct, v.charged, v.evidence) if overlaps(v.spans, lo, hi) else v.untimed
                 for n in nodes if (v := views.get(n)) is not None}
        shares[m] = publisher_shares(G, m, nodes, other, s.culprits.get(m, ()), m in s.carried)
    for m, nodes in shared_by:
        for n in nodes:
            x = s.anomaly[m] * settings.charge * shares[m][n]
            if x <= 0:
                continue
            v = views.setdefault(n, NodeView(n))
            at = s.culprits.get(m, {}).get(n, -INF)
            if at > s.onset[m]:  # named later than the topic's first alert: its own stop is later
                _charge(v, m, x, at, [(max(a, at), b) for a, b in s.episodes[m] if b >= at], "output",
                        (INF, INF, at))
            else:
                _charge(v, m, x, s.onset[m], s.episodes[m], "output", _starts_of(s, m))


def _settle(
    G: nx.MultiDiGraph, these: Mapping[str, NodeView], views: dict[str, NodeView], s: Symptoms,
    ev_passive: dict[str, Evidence], settings: RcaSettings, stalled: Mapping[str, set[str]] | None = None,
) -> None:
    """Fill in the anomalies of ``these`` views, then their upstream excuse (which reads the
    anomalies of all ``views``), once every symptom is charged; fellows in a stall of their
    executor (``stalled``: node → fellows) do not excuse each other."""
    for v in these.values():
        v.anomaly = max(v.direct, v.charged, v.evidence)
        v.own_anomaly = max(v.own_direct, v.charged, v.own_evidence)
    # What can excuse at all: the walk upstream stops once it has passed all of them.
    sources = {m for m in s.anomaly if not m.startswith(("process:", "host:")) and m != "root"}
    sources |= set(views) | set(ev_passive)
    parents: dict[str, list[str]] = {}  # the candidates' walks upstream cross the same members
    for n, v in these.items():
        # A node killed by a signal (a person, a supervisor, the OOM killer) was not killed by its
        # inputs: nothing upstream excuses its death.
        v.upstream = 0.0 if n in s.killed else _upstream(
            G, n, v, s, views, ev_passive, settings, sources, (stalled or {}).get(n, set()), parents)


def _imply(
    G: nx.MultiDiGraph, s: Symptoms, views: dict[str, NodeView], ev_passive: dict[str, Evidence],
    settings: RcaSettings, suspects: Callable[[str, NodeView], Iterable[tuple[str, set[str]]]],
    weight: float, kind: str,
) -> None:
    """Make the members ``suspects(n, v)`` names for a view candidates, weakly (× ``weight``).

    ``suspects`` yields (suspect, its fellows in a stall of one executor, who do not excuse it);
    a suspect that already has a view (its own evidence, or an alert named it) is left as it is.
    """
    implied: dict[str, NodeView] = {}
    fellows: dict[str, set[str]] = {}
    for n, v in list(views.items()):
        for f, stalled_with in suspects(n, v):
            if f in views:
                continue
            fv = implied.setdefault(f, NodeView(f, implied=True))
            _charge(fv, n, v.own_anomaly * settings.charge * weight, v.own_onset, v.spans, kind,
                    (v.began, v.began_by, v.vague))
            fellows[f] = fellows.get(f, set()) | stalled_with
    views.update(implied)
    _settle(G, implied, views, s, ev_passive, settings, fellows)


def _imply_servers(
    G: nx.MultiDiGraph, s: Symptoms, views: dict[str, NodeView], ev_passive: dict[str, Evidence],
    settings: RcaSettings,
) -> None:
    """Make the silent servers of an unexplained client candidates (weakly: `IMPLIED_SERVER`).

    A client that waits on a server shows the server's fault as its own (error logs, stalled
    outputs) while the server's topics may look healthy; so a server nothing else speaks for
    becomes a candidate when a client of it has such symptoms of its own and its inputs do not
    explain them.
    """
    def servers(n: str, v: NodeView) -> Iterator[tuple[str, set[str]]]:
        # its own logs or outputs, not what it shares with its process (CPU, memory)
        if v.upstream < UNEXPLAINED and v.own_kinds & {"alert", "output"}:
            yield from ((srv, set()) for srv in called_servers(G, n))

    _imply(G, s, views, ev_passive, settings, servers, IMPLIED_SERVER, "client")


def _imply_fellows(
    G: nx.MultiDiGraph, s: Symptoms, views: dict[str, NodeView], ev_passive: dict[str, Evidence],
    settings: RcaSettings,
) -> None:
    """Make the other nodes of a stopped executor candidates (weakly: `IMPLIED_FELLOW`).

    An output gone silent while its publisher's single-threaded executor is idle (``executor_idle``)
    says a callback blocked that thread, and it may be any node's the thread runs: one whose
    callbacks publish nothing, or only on demand (a tracker saving its gallery), shows nothing of
    its own. Its fellows without a symptom become candidates, below the node whose outputs
    stopped; what else stopped with the executor does not excuse them.
    """
    def fellows(n: str, v: NodeView) -> Iterator[tuple[str, set[str]]]:
        p = None if v.implied or not v.executor_idle else process_of_node(G, n)
        if p is not None:
            group = set(nodes_of_process(G, p))
            yield from ((f, group - {f}) for f in group)

    _imply(G, s, views, ev_passive, settings, fellows, IMPLIED_FELLOW, "fellow")


def _await(G: nx.MultiDiGraph, views: Mapping[str, NodeView], settings: RcaSettings) -> None:
    """Mark the candidates a client was waiting on (``awaited``: those clients): a node that calls
    one complained (its own alert or stalled output) from the candidate's onset up to
    ``episode_gap`` later.
    Among nodes of one process with the same own changes, that tells the one being waited on
    apart (`siblings.judge`)."""
    for n, v in views.items():
        if v.implied or v.onset == INF:
            continue
        lo, hi = v.onset - settings.tolerance, v.onset + settings.episode_gap
        v.awaited = [q for q in calling_clients(G, n) if (c := views.get(q)) is not None
                     and c.own_kinds & {"alert", "output"} and lo <= c.own_onset <= hi]


SILENT_DECAY = 0.75  # an excuse found behind a silent node counts this much less per such node


def _upstream(
    G: nx.MultiDiGraph,
    n: str,
    v: NodeView,
    s: Symptoms,
    views: dict[str, NodeView],
    ev_passive: dict[str, Evidence],
    settings: RcaSettings,
    sources: set[str] | None = None,
    fellows: Collection[str] = (),
    parents: dict[str, list[str]] | None = None,
) -> float:
    """How anomalous ``n``'s causes were while ``n``'s symptoms began.

    A cause counts when one of its episodes met ``[onset − episode_gap, onset + tolerance]``:
    it began no later than the node's symptoms (+ tolerance) and had not long ended — an
    upstream episode that ended before does not excuse a later fault. A parent topic counts
    with its own symptom, and with the direct evidence of its other publishers (a crashed
    sensor whose topic nobody watches still excuses its subscriber). A parent with no symptom at
    all does not end the search: a fault crosses a node that raised nothing (its output merely
    went on late), so the walk goes on upstream through silent members, up to
    ``max_trajectory`` hops, each silent node passed weakening what is found behind it by
    `SILENT_DECAY` (a symptom that began more than ``tolerance`` before ``n``'s and still held
    when they began counts in full: `_led`); so does the walk from what ``n``'s silent siblings
    read (`_sibling_inputs`: composed nodes share data in memory). A symptom charged to ``n``
    never excuses it, nor through a topic its publisher sends, and a topic without a symptom of
    its own that carried no message in that
    time (`traffic.idle`: a teleop topic nobody publishes on) passes nothing but, as ``n``'s own
    input, its publishers' departure. A cause whose symptom is known to have begun after ``n``'s
    (`began_after`: a log line stamped after the next message of ``n``'s silent output was
    due) does not count.
    ``sources``: the members that can excuse at all (symptoms, candidates, evidence); the walk
    ends once it has passed every one of them. ``fellows``: nodes that stalled with ``n`` in one
    executor (`siblings.stalls`) — neither they nor the topics only they publish excuse it. A
    node of ``n``'s own process excuses it only with its own changes: what they share (the
    process's CPU, memory, exit) is one symptom of the process, and does not travel along the data
    flow between them. ``parents``: `causal.causes_in`'s memo.
    """
    parents = {} if parents is None else parents
    home = process_of_node(G, n)
    onset, latest = _present_start(v, settings.tolerance)  # latest: the latest it can have begun
    if onset < INF:
        lo, hi = onset - settings.episode_gap, onset + settings.tolerance
    else:  # evidence without a time: any time
        lo, hi = -INF, INF
    mine = set(outputs(G, n))
    left = None if sources is None else sources - mine - {n}
    worst = 0.0
    # Its own outputs, reached round a feedback loop, are no cause of it; nor is a symptom charged
    # to it (a client's complaint naming it is its evidence, however the walk comes round to it).
    seen = {n, *mine, *v.own}
    # Each step: (member, weight, bare): bare once the walk crossed a measured topic (`_excuse`).
    frontier = [(p, 1.0, False) for p in causes_in(G, n, parents) if p not in seen]
    inputs = {p for p, _, _ in frontier}
    frontier += [(p, w, False) for p, w in _sibling_inputs(G, n, home, seen, views, parents)]
    for _ in range(settings.max_trajectory):
        if left is not None and not left:
            break
        nxt: list[tuple[str, float, bool]] = []
        for p, w, bare in frontier:
            if p in seen:
                continue
            seen.add(p)
            if fellows and _among(G, p, fellows, parents):
                continue
            # A topic that carried no message then passes no fault: n's own input still shows
            # its publishers' departure (a subscriber warned its publisher died), no further.
            shut = p not in s.anomaly and not is_node(G, p) and idle(G, p, lo, hi)
            if shut and p not in inputs:
                continue
            if left is not None:
                left.discard(p)
            when = (lo, hi, latest, settings.tolerance)
            bare = bare or (not is_node(G, p) and measured(G, p))
            found = _excuse(G, p, n, s, views, ev_passive, when, home, parents, bare)
            # A symptom that led n's and still held is no coincidence behind the silent nodes: the
            # time it took is its way through them (a timeout, a control loop winding down). It
            # explains n as fully as n's own trouble weighs: one plugin's warning and another's
            # error are not on one scale (a transform gone, then "robot pose is not available").
            if found > 0 and _led(G, p, s, views, onset, settings, parents):
                w, found = 1.0, max(found, v.anomaly)
            worst = max(worst, w * found)
            if shut or found > 0 or w * SILENT_DECAY <= worst:
                continue  # an alerting member ends its path: the earlier ones are its own causes
            decay = w * SILENT_DECAY if is_node(G, p) else w
            nxt += [(q, decay, bare) for q in causes_in(G, p, parents) if q not in seen]
        if not nxt:
            break
        frontier = nxt
    return _clip(worst)


def _led(G: nx.MultiDiGraph, p: str, s: Symptoms, views: Mapping[str, NodeView], onset: float,
         settings: RcaSettings, parents: dict[str, list[str]]) -> bool:
    """True when ``p``'s symptom (a topic without one: a publisher's) began before ``onset`` by more
    than ``tolerance``, at most ``led_max``, and still held at ``onset``: it led, and was no
    coincidence of sampling nor a standing condition (a warning held for minutes)."""
    tolerance = settings.tolerance

    def led(first: float, spans: list[Episode]) -> bool:
        return (onset - settings.led_max <= first < onset - tolerance
                and overlaps(spans, onset - tolerance, onset + tolerance))
    if not np.isfinite(onset):
        return False
    if p in s.onset:
        return led(s.onset[p], s.episodes[p])
    if is_node(G, p):
        pv = views.get(p)
        return pv is not None and led(pv.onset, pv.spans)
    return any(q in views and led(views[q].onset, views[q].spans) for q in publishers(G, p, parents))


def _sibling_inputs(
    G: nx.MultiDiGraph, n: str, home: str | None, seen: Collection[str], views: Mapping[str, NodeView],
    parents: dict[str, list[str]],
) -> list[tuple[str, float]]:
    """The inputs of ``n``'s silent siblings (nodes of its process ``home`` with no symptom of
    their own), as a walk's frontier one silent node away (weight `SILENT_DECAY`).

    Composed nodes share data in memory: nav2's controller reads the costmap its sibling node
    keeps, MoveIt's move_group its private node's state. What that sibling subscribes to is, in
    effect, ``n``'s input though no edge of the graph says so. A sibling with symptoms of its own
    is left out: they may be ``n``'s effects, and `siblings.judge` weighs them; so is what the
    clients of ``n`` publish (two steps downstream of it): ``n``'s answers made it (nav2's
    controller reads the path the navigator publishes from its sibling planner's answer).
    """
    if home is None:
        return []
    silent = [q for q in nodes_of_process(G, home)
              if q != n and q not in seen and not (q in views and views[q].own)]
    if not silent:
        return []
    made = {e2 for e in effects(G, n) for e2 in effects(G, e)}
    return [(c, SILENT_DECAY) for q in silent for c in causes_in(G, q, parents)
            if c not in seen and c not in made]


def _among(G: nx.MultiDiGraph, p: str, fellows: Collection[str],
           parents: dict[str, list[str]] | None = None) -> bool:
    """True when ``p`` is one of ``fellows`` or a topic only they publish."""
    if p in fellows:
        return True
    pubs = [] if is_node(G, p) else publishers(G, p, parents)
    return bool(pubs) and all(q in fellows for q in pubs)


def _excuse(
    G: nx.MultiDiGraph,
    p: str,
    n: str,
    s: Symptoms,
    views: dict[str, NodeView],
    ev_passive: dict[str, Evidence],
    when: tuple[float, float, float, float],
    home: str | None = None,
    parents: dict[str, list[str]] | None = None,
    bare: bool = False,
) -> float:
    """How much the cause ``p`` of ``n`` was anomalous at some time in ``[lo, hi]``, not known to
    have begun after ``latest`` (``when``: lo, hi, latest, tolerance; `began_after`); a node of
    ``n``'s process ``home`` counts with its own changes only. A node behind a measured topic
    (``bare``, `traffic.measured`) counts with its alerts only: its metric evidence (a CPU burst no
    plugin confirmed) changed nothing it sends that the topic would not show. ``parents``:
    `causal.causes_in`'s memo."""
    lo, hi, latest, tolerance = when
    if is_node(G, p):  # a server it calls, or a node further upstream
        pv = views.get(p)
        fellow = home is not None and process_of_node(G, p) == home
        if pv is None or pv.implied or began_after(pv.began, pv.vague, latest, tolerance):
            return 0.0
        return pv.alerted(lo, hi, own=fellow) if bare else pv.active(lo, hi, own=fellow)
    worst = 0.0
    if p in s.anomaly and overlaps(s.episodes[p], lo, hi) \
            and not began_after(s.began.get(p, INF), s.vague.get(p, INF), latest, tolerance):
        worst = s.anomaly[p]
    e = ev_passive.get(p)
    if e is not None and e.meets(lo, hi):
        worst = max(worst, e.strength)
    mine = views[n].own if n in views else ()  # complaints naming n: its evidence, never its excuse
    for q in publishers(G, p, parents):
        qv = views.get(q)
        if (q == n or q in mine or qv is None or qv.implied
                or began_after(qv.began, qv.vague, latest, tolerance)):
            continue
        fellow = home is not None and process_of_node(G, q) == home
        if bare:
            worst = max(worst, qv.alerted(lo, hi, own=fellow))
            continue
        own = max(qv.own_direct, qv.own_evidence) if fellow else max(qv.direct, qv.evidence)
        worst = max(worst, own if overlaps(qv.spans, lo, hi) else (0.0 if qv.spans else qv.untimed))
    return worst


STAMPED_SLACK = 0.25  # s: two stamped starts, from the clocks of processes on one host


def _present_start(v: NodeView, tolerance: float) -> tuple[float, float]:
    """When ``v``'s present symptoms began, and the latest they can have begun.

    From its first symptom; but from its own change (an output, a log) when all it showed
    before that was what it shares with its process (CPU, memory: it has no own symptom earlier)
    and had ended, as measured (`Evidence` with an end), ``tolerance`` before: a burst of its
    container's work that ended does not date a later fault of the node, nor keep an input that
    went bad in between from explaining it.
    """
    cut = v.own_onset - tolerance
    first = v.onset, min(v.began_by, v.vague)
    if v.own_onset == INF or v.onset >= cut or not any(a < cut for a, _ in v.metric_spans):
        return first
    return (v.own_onset, v.own_onset) if all(b < cut for a, b in v.spans if a < cut) else first


def began_after(began: float, vague: float, latest: float, tolerance: float) -> bool:
    """True when a symptom is known to have begun after ``latest`` (+ `STAMPED_SLACK`): its
    alerts say when it began (``began``), and those that do not (first at ``vague``, begun up to
    ``tolerance`` before) came later too."""
    return began < INF and min(began, vague - tolerance) > latest + STAMPED_SLACK
