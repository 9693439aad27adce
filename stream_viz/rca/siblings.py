"""Nodes that share a process (a component container, one executor): which one changed first.

Nodes in one process share its evidence (its CPU, memory, exit) and, on a single-threaded
executor, its thread: one node's blocking callback starves its siblings, whose outputs go
silent too. So the process's own evidence cannot tell them apart; their *own* changes can —
alerts on the node itself, symptoms of its outputs, metric evidence on the node. Among the
candidate nodes of one process, the node whose own change came first (beyond the tolerance),
or at the same time but stronger, excuses its siblings in the hypothesis test (as a causal
parent would): on one executor it can be their cause. A node with no own change at all is
excused by any sibling that has one. Nodes whose own changes are the same (in time, strength
and kind), and whose inputs explain them as much, cannot be told apart, and the verdict says so —
unless a client calling one of them complained meanwhile (``awaited``): a process burning CPU
while a client times out on one of its servers points at that server. In a stall of their
executor it does not: every service of the process stops answering alike.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Protocol

import networkx as nx

from stream_viz.model.queries import process_of_node
from stream_viz.rca.causal import causes_in

INF = float("inf")
EPS = 1e-9


HOPS = 6  # how far upstream a stalled node's inputs are followed to a fellow (a few topics/nodes)


class OwnChange(Protocol):
    """What `judge` reads of a candidate (`stream_viz.rca.symptoms.NodeView` has it)."""

    own_onset: float
    own_anomaly: float
    own_kinds: set[str]
    upstream: float
    implied: bool
    logged: float
    exited: float
    executor_stopped: bool
    awaited: list[str]


@dataclass
class Verdict:
    """A candidate among its process's candidates.

    ``process``: the process it shares; ``excuse``: how strongly a sibling that changed first
    (or more) explains it, in [0, 1]; ``indistinguishable``: siblings whose own changes are the
    same as its own and explained as much by their inputs (empty when it is excused).
    """

    process: str
    excuse: float = 0.0
    indistinguishable: list[str] = field(default_factory=list)


def _close(a: float, b: float, tol: float) -> bool:
    return a == b or abs(a - b) <= tol  # two INF (untimed) onsets are close too


def _before(a: OwnChange, b: OwnChange, tol: float) -> bool:
    """True when ``a``'s own change came before ``b``'s, or with it but stronger or wider."""
    if a.own_anomaly <= 0:
        return False
    if b.own_anomaly <= 0 or a.own_onset < b.own_onset - tol:
        return True
    if not _close(a.own_onset, b.own_onset, tol):
        return False
    if abs(a.own_anomaly - b.own_anomaly) > EPS:
        return a.own_anomaly > b.own_anomaly
    return len(a.own_kinds) > len(b.own_kinds)


def stalls(G: nx.MultiDiGraph, views: Mapping[str, OwnChange], tol: float) -> dict[str, set[str]]:
    """Return node → the fellow nodes of its process that stopped with it, for one common cause.

    Nodes of one process whose outputs went silent together (own onsets within ``tol``) are one
    stall of their executor when at least two of them are independent: neither is fed, through
    the data flow, by another of them (a lidar and an IMU driver that share nothing but the
    thread); or when an output's alert said its executor stopped while its input arrived
    (``executor_stopped``: a pipeline of filters in one container, each fed by the one before).
    Then the data flow between them explains nothing — a hung merger starves the
    drivers that feed it — and only their own log lines at the stall tell them apart. The nodes
    of a process seen to die (``exited``) are fellows too: each output of theirs stops when the
    process ends, however late its silence is noticed.
    """
    by_process: dict[str, list[str]] = {}
    for n, v in views.items():
        if not v.implied and (p := process_of_node(G, n)) is not None:
            by_process.setdefault(p, []).append(n)
    out: dict[str, set[str]] = {}
    parents: dict[str, list[str]] = {}  # the walks upstream of one group cross the same members
    for nodes in by_process.values():
        silent = [n for n in nodes if "output" in views[n].own_kinds]
        if silent:
            start = min(views[n].own_onset for n in silent)
            group = {n for n in silent if _close(views[n].own_onset, start, tol)}
            free = (n for n in group if not _fed_by(G, n, group - {n}, parents))
            # A lone node is no stall; two independent ones are enough to tell, the rest not walked.
            if len(group) > 1 and (any(views[n].executor_stopped for n in group)
                                   or len(list(itertools.islice(free, 2))) == 2):
                for n in group:
                    out[n] = group - {n}
        dead = {n for n in nodes if views[n].exited < INF}
        if len(dead) >= 2:
            for n in dead:
                out[n] = out.get(n, set()) | (dead - {n})
    return out


def _spoke(v: OwnChange, tol: float) -> bool:
    """True when ``v`` logged by the time its outputs stopped: it ran while a stall starved the
    others (a starved node cannot log)."""
    return v.logged <= v.own_onset + tol


def _fed_by(G: nx.MultiDiGraph, n: str, others: set[str],
            parents: dict[str, list[str]] | None = None) -> bool:
    """True when one of ``others`` is upstream of ``n`` within `HOPS` causal steps.

    ``parents`` (member → `causes`) is filled and reused across calls on the same graph."""
    parents = {} if parents is None else parents
    seen, frontier = {n}, [n]
    for _ in range(HOPS):
        nxt: dict[str, None] = {}  # each member once: two paths to it lead to the same parents
        for m in frontier:
            nxt.update((p, None) for p in causes_in(G, m, parents) if p not in seen)
        frontier = list(nxt)
        if any(p in others for p in frontier):
            return True
        seen.update(frontier)
        if not frontier:
            break
    return False


def _same(a: OwnChange, b: OwnChange, tol: float) -> bool:
    """Same own change, and explained as much by their inputs (else the data flow tells them
    apart), and both or neither waited on by a complaining client (else the one it called)."""
    return (_close(a.own_onset, b.own_onset, tol) and abs(a.own_anomaly - b.own_anomaly) <= EPS
            and len(a.own_kinds) == len(b.own_kinds) and abs(a.upstream - b.upstream) <= EPS
            and bool(a.awaited) == bool(b.awaited))


def judge(G: nx.MultiDiGraph, views: Mapping[str, OwnChange], tol: float,
          stalled: Mapping[str, set[str]] | None = None) -> dict[str, Verdict]:
    """Return a `Verdict` for every candidate that shares its process with another candidate.

    Fellows of one stall or one dead process (``stalled``, from `stalls`) are told apart only by
    their own log lines (a node that logs was running, one that wrote its last words before the
    crash): whatever else came with the stall (silent outputs, a stale diagnostic) is its
    consequence on all.

    Parameters
    ----------
    G : MultiDiGraph
        The model (the process tree says which process hosts a node).
    views : mapping
        Candidate node → its own change (`OwnChange`); implied candidates (a server suspected
        only because of its client) take no part.
    tol : float
        Seconds counted as simultaneous.
    stalled : mapping, optional
        Node → the fellows of its stall.
    """
    stalled = stalled or {}
    groups: dict[str, list[str]] = {}
    for n, v in views.items():
        p = None if v.implied else process_of_node(G, n)
        if p is not None:
            groups.setdefault(p, []).append(n)
    out: dict[str, Verdict] = {}
    for p, nodes in groups.items():
        if len(nodes) < 2:
            continue
        for n in nodes:
            v = views[n]
            verdict = Verdict(p)
            for m in nodes:
                if m == n:
                    continue
                w = views[m]
                if m in stalled.get(n, ()):
                    if _spoke(w, tol) and not _spoke(v, tol):
                        verdict.excuse = max(verdict.excuse, w.own_anomaly * (1.0 - w.upstream))
                    elif _spoke(w, tol) == _spoke(v, tol):
                        verdict.indistinguishable.append(m)
                elif _before(w, v, tol):
                    # a sibling explained by its own inputs explains its siblings less
                    verdict.excuse = max(verdict.excuse, w.own_anomaly * (1.0 - w.upstream))
                elif _same(w, v, tol):
                    verdict.indistinguishable.append(m)
            if verdict.excuse > 0:
                verdict.indistinguishable = []
            verdict.indistinguishable.sort()
            out[n] = verdict
    return out
