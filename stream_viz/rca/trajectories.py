"""Fault trajectories and the ranking of root-cause candidates (paper §3.3.3, our reading).

A root cause is a fault that causes others and is caused by none. Candidates are nodes (active
members); symptoms of passive members are charged to their publishers (`symptoms`). Ranking in
two stages:

1. For every candidate, cheaply: the hypothesis test over the topology (``ht`` = anomaly ×
   (1 − anomaly of its causal parents at its onset)), its direct evidence (alerts on the node
   itself or its process, weighted by severity and plugin kind) and metric evidence.
2. For the ``shortlist`` best: the fault trajectory — the path from the first detected symptom
   (or, when that is not downstream of the candidate, the farthest symptom it explains) back to the
   candidate, against data flow, through silent passive members where needed — and the average
   strength of its dependencies: symptom co-occurrence (1-D ICP) and time lag against the lag
   distribution of all alerting pairs. ``coverage`` (the share of symptoms downstream of the
   candidate) rewards a cause that explains others.

The score is ``ht`` times the support: the weighted mean (weights from the settings) of
``0.5 + 0.5·coverage`` (topology), direct evidence, metric evidence (left out when none was given
at all), co-occurrence and time lag (0 when the trajectory has no dependency: the candidate
explains no other symptom).
"""

from __future__ import annotations

import itertools
from collections.abc import Collection, Container, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Any

import networkx as nx
import numpy as np

from stream_viz.model.queries import process_of_node
from stream_viz.model.traffic import TRAFFIC, idle, measured
from stream_viz.rca.causal import is_node, path_back, trace
from stream_viz.rca.charge import pointed_nodes
from stream_viz.rca.cooccurrence import cooccurrence
from stream_viz.rca.episodes import Evidence
from stream_viz.rca.hosts import lift_hosts
from stream_viz.rca.settings import RcaSettings
from stream_viz.rca.symptoms import (
    NodeView,
    Symptoms,
    began_after,
    collect_symptoms,
    gone_members,
    node_views,
)
from stream_viz.rca.timelag import LagDistribution
from stream_viz.records import Alert


@dataclass
class RootCause:
    """A ranked candidate: ``trajectory`` runs from the first symptom to ``member``."""

    member: str
    score: float
    trajectory: list[str]
    evidence: dict[str, Any] = field(default_factory=dict)

    def to_report(self) -> dict[str, Any]:
        """The root cause in the report JSON (docs/contracts.md)."""
        return {"member": self.member, "score": self.score, "trajectory": list(self.trajectory),
                "evidence": self.evidence}


@dataclass
class Context:
    """What every ranker needs, built once per ranking."""

    G: nx.MultiDiGraph
    settings: RcaSettings
    symptoms: Symptoms
    views: dict[str, NodeView]
    has_evidence: bool
    first: str | None = None  # the first detected symptom (alert of iteration 1)
    _lags: LagDistribution | None = None
    # effects per member (`causal.effects_in`): the candidates' traces cross the same members
    _children: dict[str, list[str]] = field(default_factory=dict, repr=False)
    # (effect, cause) → (co-occurrence strength, causal lag): trajectories share their pairs
    _pairs: dict[tuple[str, str], tuple[float, float]] = field(default_factory=dict, repr=False)

    @property
    def lags(self) -> LagDistribution:
        if self._lags is None:
            self._lags = LagDistribution(self.symptoms.onset, self.settings.tolerance)
        return self._lags


def make_context(
    G: nx.MultiDiGraph,
    alerts: Iterable[Alert],
    settings: RcaSettings,
    members: Iterable[str] | None = None,
    evidence: Mapping[str, float | Evidence] | None = None,
    first: str | None = None,
    gone: Collection[str] | None = None,
    symptoms: Symptoms | None = None,
) -> Context:
    """Collect symptoms (of ``members`` only, when given: ``M_j``) and the per-node views.

    ``first`` is the first detected symptom, where trajectories start (default: the member of
    the earliest alert); ``gone`` the vanished members (default: those marked in ``G``);
    ``symptoms`` those of ``alerts`` when the caller has them already.
    """
    s = symptoms or collect_symptoms(alerts, settings, members, gone_members(G) if gone is None else gone)
    if first is not None and first not in s.times:
        first = None
    return Context(G, settings, s, node_views(G, s, settings, evidence), bool(evidence), first)


@dataclass
class Trajectory:
    """A candidate's trajectory with its dependency strengths and the symptoms it explains."""

    path: list[str]
    explained: list[str]
    cooccurrence: float | None
    timelag: float | None
    coverage: float


def _series(ctx: Context, m: str) -> np.ndarray:
    return ctx.symptoms.times[m]


def trajectory_of(ctx: Context, c: str) -> Trajectory:
    """Trace ``c``'s fault trajectory and score its dependencies (module docstring, stage 2)."""
    s, settings = ctx.symptoms, ctx.settings
    onset = ctx.views[c].onset if c in ctx.views else np.inf
    cost, back = trace(ctx.G, c, s.times, settings.max_trajectory, ctx._children, _closed(ctx, onset))
    v = ctx.views.get(c)
    if v is not None and not (v.direct or v.charged):
        cost = _unblocked(ctx, c, cost, back)
    # A symptom that began before the candidate's own (beyond the tolerance) is not its effect.
    since = onset - settings.tolerance if np.isfinite(onset) else -np.inf  # metric evidence only: no time
    home = process_of_node(ctx.G, c) if is_node(ctx.G, c) else None
    explained = [m for m in cost if m in s.times and s.onset[m] >= since and not _before(ctx, c, m)
                 and not _shared(ctx, home, c, m)]
    coverage = len(explained) / len(s.times) if s.times else 0.0
    first = ctx.first or s.first
    own = ctx.views[c].own if c in ctx.views else []
    # The run's first symptom starts the path, unless it is a sibling's share of their process's.
    if (first is not None and first in cost and first != c and first not in own
            and not _shared(ctx, home, c, first)):
        start = first
    elif explained:  # the farthest symptom it explains: the whole propagation is shown
        start = max(explained, key=lambda m: (cost[m], -s.onset[m], m))
    else:
        start = c
    path = path_back(back, start, c)
    # Dependencies: consecutive symptomatic members on the path (effect first, then its cause).
    alerting = [m for m in path if m in s.times]
    # A candidate with no symptom of its own that a complaint names (a localiser deactivated, its
    # readers' ERRORs naming it) stands at its trajectory's end as the first who named it.
    if c not in s.times and (named := _named_by(ctx, c, own)) and named not in alerting:
        alerting.append(named)
    co, lag = [], []
    for effect, cause in itertools.pairwise(alerting):
        pair = ctx._pairs.get((effect, cause))
        if pair is None:
            pair = ctx._pairs[effect, cause] = (
                cooccurrence(
                    _series(ctx, cause), _series(ctx, effect), settings.tolerance, settings.max_offset,
                    settings.icp_iterations,
                ).strength,
                ctx.lags.lag(s.onset[cause], s.onset[effect]).causal,
            )
        co.append(pair[0])
        lag.append(pair[1])
    return Trajectory(
        path,
        explained,
        float(np.mean(co)) if co else None,
        float(np.mean(lag)) if lag else None,
        coverage,
    )


def _named_by(ctx: Context, c: str, own: list[str]) -> str | None:
    """The earliest of ``own`` (the symptoms charged to ``c``) whose alerts name ``c``, or None."""
    s = ctx.symptoms
    by = [m for (m, name) in s.named if m in own and c in pointed_nodes(ctx.G, m, [name])]
    return min(by, key=lambda m: (s.onset[m], m)) if by else None


def _unblocked(ctx: Context, c: str, cost: dict[str, float], back: dict[str, str]) -> dict[str, float]:
    """The members of ``cost`` that ``c``'s trace reached crossing no measured topic without a
    symptom: all that metric evidence alone (no alert of ``c``) can explain, as the walk upstream
    judges it (`symptoms._excuse`)."""
    s, G = ctx.symptoms, ctx.G
    blocked: dict[str, bool] = {c: False}

    def crossed(m: str) -> bool:
        path = []
        while m not in blocked:
            path.append(m)
            m = back[m]
        b = blocked[m]
        for x in reversed(path):  # from the member after the known one to the asked one
            p = back[x]
            b = blocked[x] = b or (p != c and p not in s.times and not is_node(G, p) and measured(G, p))
        return b
    return {m: d for m, d in cost.items() if not crossed(m)}


@dataclass
class _Closed:
    """The topics without a symptom that carried no message while a candidate's symptoms began
    (``lo``–``hi``, as its walk upstream judges them: `symptoms._upstream`): nothing it did went
    along them. Asked member by member (`causal.trace`'s ``closed``), not built for every topic."""

    ctx: Context
    lo: float
    hi: float

    def __contains__(self, m: object) -> bool:
        ctx = self.ctx
        return isinstance(m, str) and m not in ctx.symptoms.times and idle(ctx.G, m, self.lo, self.hi)


def _closed(ctx: Context, onset: float) -> Container[str]:
    """`_Closed` for a candidate whose symptoms began at ``onset``; nothing for one without a time."""
    if not np.isfinite(onset) or TRAFFIC not in ctx.G.graph:
        return ()
    return _Closed(ctx, onset - ctx.settings.episode_gap, onset + ctx.settings.tolerance)


def _before(ctx: Context, c: str, m: str) -> bool:
    """True when ``m``'s symptom is known to have begun before the candidate ``c``'s own did, by
    their alerts' own word (`symptoms.began_after`: a stamp, a silence's last message): an effect
    comes after its cause, however they were sampled together."""
    v, s = ctx.views.get(c), ctx.symptoms
    latest = min(s.began_by.get(m, np.inf), s.vague.get(m, np.inf))
    return v is not None and began_after(v.began, v.vague, latest, ctx.settings.tolerance)


def _shared(ctx: Context, home: str | None, c: str, m: str) -> bool:
    """True when ``m`` is another node of ``c``'s process ``home`` whose symptoms are all the
    process's (its CPU, memory, exit): what they share is no effect of ``c`` reaching ``m`` through
    the data flow (docs/rca.md, *Nodes in one process*), so it is not among those ``c`` explains."""
    if home is None or m == c or m in ctx.symptoms.own_anomaly or not is_node(ctx.G, m):
        return False
    return process_of_node(ctx.G, m) == home


def _cheap(ctx: Context, v: NodeView) -> float:
    w = ctx.settings.weights
    parts = [(w["topology"], 1.0), (w["direct"], v.direct)]
    if ctx.has_evidence:
        parts.append((w["evidence"], v.evidence))
    return v.ht * _mean(parts)


def _mean(parts: list[tuple[float, float]]) -> float:
    total = sum(w for w, _ in parts)
    return sum(w * x for w, x in parts) / total if total > 0 else 0.0


def _evidence(v: NodeView, tr: Trajectory | None = None, **extra: Any) -> dict[str, Any]:
    out: dict[str, Any] = {
        "anomaly": round(v.anomaly, 4),
        "direct": round(v.direct, 4),
        "charged": round(v.charged, 4),
        "metric": round(v.evidence, 4),
        "upstream": round(v.upstream, 4),
        "hypothesis": round(v.ht, 4),
        "symptoms": list(v.own),
        "plugins": sorted(v.plugins),
    }
    if v.process is not None:  # it shares this process with other candidates
        out["process"] = v.process
    if v.indistinguishable:
        out["indistinguishable_from"] = list(v.indistinguishable)
    if v.process is not None and v.awaited:  # what told it apart from its siblings
        out["awaited_by"] = list(v.awaited)
    if v.blocked is not None:  # in a stall: how likely its callback blocked the executor
        out["blocked"] = round(v.blocked, 3)
    if v.implied:  # no symptom of its own: why it is a suspect at all
        out["implied"] = "executor" if "fellow" in v.own_kinds else "server"
    if tr is not None:
        out.update(
            coverage=round(tr.coverage, 4),
            cooccurrence=None if tr.cooccurrence is None else round(tr.cooccurrence, 4),
            timelag=None if tr.timelag is None else round(tr.timelag, 4),
            explains=len(tr.explained),
        )
    out.update(extra)
    return out


def _order(items: list[tuple[float, float, str]]) -> list[tuple[float, float, str]]:
    """Best first: score, then earlier onset, then member id (deterministic ties)."""
    return sorted(items, key=lambda x: (-x[0], x[1], x[2]))


def rank_trajectory(ctx: Context) -> list[RootCause]:
    """Our combined method: topology test, direct and metric evidence, trajectory strengths."""
    w = ctx.settings.weights
    pre = _order([(_cheap(ctx, v), v.onset, n) for n, v in ctx.views.items()])
    out = []
    for _, _, n in pre[: max(ctx.settings.shortlist, ctx.settings.top_k)]:
        v = ctx.views[n]
        tr = trajectory_of(ctx, n)
        parts = [(w["topology"], 0.5 + 0.5 * tr.coverage), (w["direct"], v.direct)]
        if ctx.has_evidence:
            parts.append((w["evidence"], v.evidence))
        # No dependency on the trajectory: it explains no other symptom, so nothing speaks for it
        # as a cause of others (a root cause causes others).
        parts.append((w["cooccurrence"], tr.cooccurrence or 0.0))
        parts.append((w["timelag"], tr.timelag or 0.0))
        # The hypothesis test (anomalous, and "caused by none": its causes were healthy when its
        # symptoms began) carries the score; the trajectory's support scales it. A victim's
        # trajectory can be strong too, so support alone must not outrank the test.
        out.append(RootCause(n, v.ht * _mean(parts), tr.path, _evidence(v, tr)))
    return finish(ctx, out)


def finish(ctx: Context, causes: list[RootCause]) -> list[RootCause]:
    """Sort best first (ties: earlier onset, then id), keep ``top_k``, round scores.

    A host whose own symptom explains its nodes' goes just above the first of them (`lift_hosts`).
    Candidates the evidence cannot tell apart (``indistinguishable``) share the best score among
    them: their trajectories differ only by where each sits in the data flow, which says nothing
    about which of them stalled.
    """
    best = {rc.member: rc.score for rc in causes}
    for rc in causes:
        v = ctx.views.get(rc.member)
        if v is not None and v.indistinguishable:
            rc.score = max([rc.score, *(best[m] for m in v.indistinguishable if m in best)])
    onset = {n: v.onset for n, v in ctx.views.items()}
    ranked = sorted(causes, key=lambda rc: (-rc.score, onset.get(rc.member, np.inf), rc.member))
    ranked = lift_hosts(ctx.G, ranked, ctx.symptoms, ctx.settings.tolerance)[: ctx.settings.top_k]
    for rc in ranked:
        rc.score = round(float(rc.score), 6)
    return ranked


def _with_trajectories(ctx: Context, scored: list[tuple[float, float, str]], name: str) -> list[RootCause]:
    out = []
    for score, _, n in _order(scored)[: ctx.settings.top_k]:
        tr = trajectory_of(ctx, n)
        out.append(RootCause(n, score, tr.path, _evidence(ctx.views[n], tr, method=name)))
    return finish(ctx, out)


def rank_hypothesis(ctx: Context) -> list[RootCause]:
    """Baseline: the topology hypothesis test alone (anomalous, parents healthy), as PyRCA's HT."""
    return _with_trajectories(ctx, [(v.ht, v.onset, n) for n, v in ctx.views.items()], "hypothesis")


def rank_count(ctx: Context) -> list[RootCause]:
    """Baseline: alert count × severity on the node, its process and (× charge) its outputs.

    GRANO's root-cause relevance; like BARO / n-sigma it ranks by how loud a member is.
    """
    rel = ctx.symptoms.relevance
    scored = []
    for n, v in ctx.views.items():
        own = (1.0 if m == n or m.startswith("process:") else ctx.settings.charge for m in v.own)
        # A symptom outside this ranking's relevance (not among its alerts) counts 0, not a KeyError.
        total = sum(rel.get(m, 0.0) * f for m, f in zip(v.own, own, strict=True))
        scored.append((total, v.onset, n))
    top = max((x for x, _, _ in scored), default=0.0) or 1.0
    return _with_trajectories(ctx, [(x / top, o, n) for x, o, n in scored], "count")
