"""From alerts to symptoms per member, and the per-node view the rankers share.

A symptom on a passive member (a topic's rate dropped) is charged to its publisher node(s); an
alert on a process to the nodes it hosts. So every candidate is a node, and a node whose output
went silent is a candidate even when it raised no alert itself (hang, degrade, delay).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field

import networkx as nx
import numpy as np

from stream_viz.model.queries import nodes_of_process
from stream_viz.rca.causal import causes, is_node, outputs, publishers
from stream_viz.rca.settings import RcaSettings
from stream_viz.records import Alert

INF = float("inf")


@dataclass
class Symptoms:
    """Alerts in the analysis window, per member.

    ``times`` sorted unique alert times; ``onset`` first alert time; ``anomaly`` the strongest
    alert (severity weight × plugin factor) in [0, 1]; ``relevance`` the sum of severity weights
    (count × severity); ``plugins`` distinct plugin names; ``first`` the member of the earliest
    alert (the first symptom).
    """

    times: dict[str, np.ndarray] = field(default_factory=dict)
    onset: dict[str, float] = field(default_factory=dict)
    anomaly: dict[str, float] = field(default_factory=dict)
    relevance: dict[str, float] = field(default_factory=dict)
    plugins: dict[str, set[str]] = field(default_factory=dict)
    first: str | None = None


def collect_symptoms(
    alerts: Iterable[Alert], settings: RcaSettings, members: Iterable[str] | None = None
) -> Symptoms:
    """Return the symptoms of ``alerts`` (only members in ``members`` when given, e.g. ``M_j``).

    Alerts older than ``settings.window`` seconds before the latest one are left out (window 0:
    none is). Unknown severities count as ``warn``.
    """
    keep = None if members is None else set(members)
    chosen = [a for a in alerts if keep is None or a.member in keep]
    if not chosen:
        return Symptoms()
    if settings.window > 0:
        latest = max(a.t for a in chosen)
        chosen = [a for a in chosen if a.t >= latest - settings.window]
    sev = settings.severity
    direct = set(settings.direct_plugins)
    raw: dict[str, list[float]] = {}
    s = Symptoms()
    first_t = INF
    for a in chosen:
        w = sev.get(a.severity, sev.get("warn", 0.5))
        factor = 1.0 if (a.plugin in direct or not a.member.startswith("node:")) else settings.charge
        raw.setdefault(a.member, []).append(a.t)
        s.anomaly[a.member] = max(s.anomaly.get(a.member, 0.0), min(1.0, w * factor))
        s.relevance[a.member] = s.relevance.get(a.member, 0.0) + w
        s.plugins.setdefault(a.member, set()).add(a.plugin)
        if a.t < first_t:
            first_t, s.first = a.t, a.member
    for m, ts in raw.items():
        s.times[m] = np.unique(np.asarray(ts, dtype=float))
        s.onset[m] = float(s.times[m][0])
    return s


@dataclass
class NodeView:
    """What the rankers know about one candidate node.

    ``direct``: its own alerts (and its process's); ``charged``: symptoms of its outputs ×
    ``charge``; ``evidence``: metric anomaly; ``anomaly`` the max of the three; ``onset`` when
    its own or charged symptoms began; ``upstream`` how anomalous its causal parents were no
    later than its onset (+ tolerance); ``ht`` = anomaly × (1 − upstream), the hypothesis test.
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


def _clip(x: float) -> float:
    return float(min(1.0, max(0.0, x)))


def node_views(
    G: nx.MultiDiGraph,
    s: Symptoms,
    settings: RcaSettings,
    evidence: Mapping[str, float] | None = None,
) -> dict[str, NodeView]:
    """Return a `NodeView` for every node with a symptom, a charged symptom or metric evidence."""
    views: dict[str, NodeView] = {}

    def view(n: str) -> NodeView:
        if n not in views:
            views[n] = NodeView(n)
        return views[n]

    ev_topic: dict[str, float] = {}
    for m, x in (evidence or {}).items():
        x = _clip(x)
        if x <= 0:
            continue
        if is_node(G, m):
            view(m).evidence = max(view(m).evidence, x)
        elif m.startswith("process:"):
            for n in nodes_of_process(G, m):
                view(n).evidence = max(view(n).evidence, x)
        else:
            ev_topic[m] = x
    for m, a in s.anomaly.items():
        if is_node(G, m):
            v = view(m)
            v.direct = max(v.direct, a)
            v.onset = min(v.onset, s.onset[m])
            v.own.insert(0, m)
            v.plugins |= s.plugins[m]
        elif m.startswith(("process:", "host:")) or m == "root":
            for n in nodes_of_process(G, m):
                v = view(n)
                v.direct = max(v.direct, a)
                v.onset = min(v.onset, s.onset[m])
                v.own.append(m)
                v.plugins |= s.plugins[m]
        else:
            for n in publishers(G, m):
                v = view(n)
                v.charged = max(v.charged, a * settings.charge)
                v.onset = min(v.onset, s.onset[m])
                v.own.append(m)
    tol = settings.tolerance
    for n, v in views.items():
        v.anomaly = max(v.direct, v.charged, v.evidence)
        v.upstream = _upstream(G, n, v, s, views, ev_topic, tol, settings.max_trajectory)
        v.ht = v.anomaly * (1.0 - v.upstream)
    return views


SILENT_DECAY = 0.75  # an excuse found behind a silent node counts this much less per such node


def _upstream(
    G: nx.MultiDiGraph,
    n: str,
    v: NodeView,
    s: Symptoms,
    views: dict[str, NodeView],
    ev_topic: dict[str, float],
    tol: float,
    max_hops: int = 12,
) -> float:
    """How anomalous ``n``'s causes were when (or before) ``n``'s symptoms began.

    A parent topic counts with its own symptom, and with the direct evidence of its other
    publishers (a crashed sensor whose topic nobody watches still excuses its subscriber). A
    parent with no symptom at all does not end the search: a fault crosses a node that raised
    nothing (its output merely went on late), so the walk goes on upstream through silent
    members, up to ``max_hops``, each silent node passed weakening what is found behind it by
    `SILENT_DECAY`.
    """
    before = v.onset + tol
    mine = set(outputs(G, n))
    worst = 0.0
    seen = {n}
    frontier: list[tuple[str, float]] = [(p, 1.0) for p in causes(G, n) if p not in mine]
    for _ in range(max_hops):
        nxt: list[tuple[str, float]] = []
        for p, w in frontier:
            if p in seen:
                continue
            seen.add(p)
            found = _excuse(G, p, n, s, views, ev_topic, before)
            worst = max(worst, w * found)
            if found > 0 or w * SILENT_DECAY <= worst:
                continue  # an alerting member ends its path: the earlier ones are its own causes
            decay = w * SILENT_DECAY if is_node(G, p) else w
            nxt += [(q, decay) for q in causes(G, p) if q not in seen]
        if not nxt:
            break
        frontier = nxt
    return _clip(worst)


def _excuse(
    G: nx.MultiDiGraph,
    p: str,
    n: str,
    s: Symptoms,
    views: dict[str, NodeView],
    ev_topic: dict[str, float],
    before: float,
) -> float:
    """How much the cause ``p`` of ``n`` was anomalous no later than ``before``."""
    if is_node(G, p):  # a server it calls, or a node further upstream
        pv = views.get(p)
        if pv is None:
            return 0.0
        if pv.onset <= before:
            return pv.anomaly
        return pv.evidence if pv.onset == INF else 0.0
    worst = s.anomaly[p] if p in s.anomaly and s.onset[p] <= before else 0.0
    worst = max(worst, ev_topic.get(p, 0.0))
    for q in publishers(G, p):
        qv = views.get(q)
        if q == n or qv is None:
            continue
        worst = max(worst, max(qv.direct, qv.evidence) if qv.onset <= before else qv.evidence)
    return worst
