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
executor it does not: every service of the process stops answering alike. What tells the fellows
of a stall apart is when each one's next message was due (`blocked_first`): a callback that blocks
before it publishes stops the executor at its own node's due, before anyone else missed a beat.
"""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Protocol

import networkx as nx

from stream_viz.model.queries import process_of_node
from stream_viz.rca.causal import causes_in

INF = float("inf")
EPS = 1e-9


HOPS = 6  # how far upstream a stalled node's inputs are followed to a fellow (a few topics/nodes)
# A hang blocks the callback that publishes (a read, a lock, a call made before the message) this
# often; otherwise another callback (a subscription that only keeps state, a service).
OUTPUT_PRIOR = 0.7
LATE_S = 0.003  # a timer due while another callback runs waits for it (a few ms in rclpy)
BEAT_ERROR = 0.01  # a beat learned from a steady rate is off by up to this fraction
TELLS = 3.0  # a fellow this many times likelier to have blocked the executor tells it apart
LINE_S = 0.05  # a log line's stamp against a message's arrival: the writer's and our clocks' offset


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
    due: float
    beat: float
    last: float
    logged_at: float
    inputs: list[tuple[float, float]]


@dataclass
class Verdict:
    """A candidate among its process's candidates.

    ``process``: the process it shares; ``excuse``: how strongly a sibling that changed first
    (or more) explains it, in [0, 1]; ``indistinguishable``: siblings whose own changes are the
    same as its own and explained as much by their inputs (empty when it is excused);
    ``blocked``: in a stall, how likely its callback blocked the executor (`blocked_first`).
    """

    process: str
    excuse: float = 0.0
    indistinguishable: list[str] = field(default_factory=list)
    blocked: float | None = None


def _close(a: float, b: float, tol: float) -> bool:
    return a == b or abs(a - b) <= tol  # two INF (untimed) onsets are close too


def _before(a: OwnChange, b: OwnChange, tol: float) -> bool:
    """True when ``a``'s own change came before ``b``'s (`_stopped`), or with it but stronger or
    wider."""
    if a.own_anomaly <= 0:
        return False
    if b.own_anomaly <= 0 or _stopped(a) < _stopped(b) - tol:
        return True
    if not _close(_stopped(a), _stopped(b), tol):
        return False
    if abs(a.own_anomaly - b.own_anomaly) > EPS:
        return a.own_anomaly > b.own_anomaly
    return len(a.own_kinds) > len(b.own_kinds)


def stalls(G: nx.MultiDiGraph, views: Mapping[str, OwnChange], tol: float) -> dict[str, set[str]]:
    """Return node → the fellow nodes of its process that stopped with it, for one common cause.

    Nodes of one process whose outputs went silent together (within ``tol``: by the next message
    due of each one's first silent output, else by its own onset) are one
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
            start = min(_stopped(views[n]) for n in silent)
            group = {n for n in silent if _close(_stopped(views[n]), start, tol)}
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


def blocked_first(dues: Mapping[str, tuple[float, float, float]],
                  inputs: Mapping[str, Sequence[tuple[float, float]]] | None = None) -> dict[str, float]:
    """Return node → how likely its callback blocked the executor the nodes shared (sums to 1).

    ``dues``: node → (its newest message before the stall, when its next one was due, its beat),
    in seconds. A callback that blocks before it publishes stops the executor at its node's due:
    nobody else had missed a beat by then (each other due is later, within `LATE_S` and the
    beat's error), and each other due fell anywhere within its beat after it. So a node whose
    due fits is the blocker with a likelihood ∝ its beat: a slow node due just as the executor
    stopped is less of a chance than a fast one. Another callback (one that publishes nothing)
    may have blocked instead (1 − `OUTPUT_PRIOR`) anywhere from the newest message of them all
    to the first due: alike for every node, ∝ that window. Of fellows in step (one beat, due
    together: fed by one message, or timers in phase), the executor runs them in the same order
    every round: one that published after another in their last round cannot have blocked it.
    ``inputs``: node → (arrival, beat) of the newest message of each stopped input whose callback
    publishes nothing (not the one its outputs follow): one that arrived as the last of them all
    (within `LATE_S` of the newest message) is a callback that may have blocked at that arrival,
    weighed as a due that fits (a merger that blocks in its IMU callback).
    """
    if len(dues) < 2:
        return {}
    first = min(due for _, due, _ in dues.values())
    newest = max(last for last, _, _ in dues.values())
    window = max(0.0, first - newest) + LATE_S
    fit = {n for n, (_, due, beat) in dues.items() if due <= first + _slack(beat)}
    out = {}
    for n, (_, _, beat) in dues.items():
        beats = [beat] if n in fit and not any(_ahead(dues[m], dues[n]) for m in fit - {n}) else []
        beats += [b for at, b in (inputs or {}).get(n, ()) if newest - LATE_S <= at <= first + LATE_S]
        out[n] = OUTPUT_PRIOR * max([_weight(b) for b in beats], default=0.0) + (1 - OUTPUT_PRIOR) * window
    total = sum(out.values())
    return {n: x / total for n, x in out.items()}


def ran_last(dues: Mapping[str, tuple[float, float, float]], logged: Mapping[str, float]) -> str | None:
    """Return the node that logged after every message of the nodes of a stalled executor and by
    the first one due, or None when none or several did.

    ``dues``: node → (its newest message, its next one due, its beat), as `blocked_first`;
    ``logged``: node → when it last logged, any level. One thread runs their callbacks one at a
    time: a line stamped after the last message any of them sent came from the last callback that
    ran, and none ran after the executor stopped — a driver announcing the call that then blocks
    ("Running flat field correction"), which publishes nothing the timing could weigh.
    """
    if len(dues) < 2:
        return None
    newest = max(last for last, _, _ in dues.values())
    first = min(due for _, due, _ in dues.values())
    said = [n for n in dues if newest - LINE_S <= logged.get(n, -INF) <= first + LINE_S]
    return said[0] if len(said) == 1 else None


def _slack(beat: float) -> float:
    """How late after the first due a due at a beat of ``beat`` s still counts as first."""
    return LATE_S + BEAT_ERROR * beat


def _weight(beat: float) -> float:
    """The likelihood of a blocked callback due at a beat of ``beat`` s (with its slack)."""
    return beat + _slack(beat)


def _ahead(a: tuple[float, float, float], b: tuple[float, float, float]) -> bool:
    """True when fellow ``a`` runs before ``b`` on their executor: in step with it (the same beat,
    due together) and it published first in their last round."""
    return (abs(a[2] - b[2]) <= BEAT_ERROR * b[2] and abs(a[1] - b[1]) <= LATE_S and a[0] < b[0])


def _timing(views: Mapping[str, OwnChange], n: str, fellows: set[str],
            cache: dict[frozenset[str], dict[str, float]]) -> dict[str, float]:
    """`blocked_first` of ``n``'s stall with ``fellows`` — certainty for the one that logged last
    (`ran_last`) — empty when a fellow died, or has no silence with a beat: a crash stops every
    thread at once, and an untimed silence says nothing."""
    group = frozenset(fellows | {n})
    if group not in cache:
        vs = {m: views[m] for m in group}
        timed = all(v.exited == INF and v.due < INF and v.beat > 0 for v in vs.values())
        dues = {m: (v.last, v.due, v.beat) for m, v in vs.items()}
        runner = ran_last(dues, {m: v.logged_at for m, v in vs.items()}) if timed else None
        if runner is not None:  # it ran last: its callback is the one that blocked
            cache[group] = {m: float(m == runner) for m in group}
        else:
            cache[group] = blocked_first(dues, {m: v.inputs for m, v in vs.items()}) if timed else {}
    return cache[group]


def _stopped(v: OwnChange) -> float:
    """When ``v``'s own change began: its first silent output's next message due, if known (a
    slow output's silence is noticed later than a fast one's that stopped with it), else its
    own onset."""
    return min(v.due, v.own_onset)


def _spoke(v: OwnChange, tol: float) -> bool:
    """True when ``v`` logged by the time its outputs stopped or its process died: it ran while
    a stall starved the others (a starved node cannot log). A node that left with its process
    (its goodbye sent: no silence follows) may have no own change but the death."""
    return v.logged < INF and v.logged <= min(v.own_onset, v.exited) + tol


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
    return (_close(_stopped(a), _stopped(b), tol) and abs(a.own_anomaly - b.own_anomaly) <= EPS
            and len(a.own_kinds) == len(b.own_kinds) and abs(a.upstream - b.upstream) <= EPS
            and bool(a.awaited) == bool(b.awaited))


def judge(G: nx.MultiDiGraph, views: Mapping[str, OwnChange], tol: float,
          stalled: Mapping[str, set[str]] | None = None) -> dict[str, Verdict]:
    """Return a `Verdict` for every candidate that shares its process with another candidate.

    Fellows of one stall or one dead process (``stalled``, from `stalls`) are told apart by their
    own log lines (a node that logs was running, one that wrote its last words before the
    crash), then in a stall by when each one's next message was due (`blocked_first`: a fellow
    `TELLS` times likelier to have blocked the executor excuses the other by the ratio's
    complement): whatever else came with the stall (silent outputs, a stale diagnostic) is its
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
    timings: dict[frozenset[str], dict[str, float]] = {}
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
            odds = _timing(views, n, stalled[n], timings) if n in stalled else {}
            verdict.blocked = odds.get(n)
            for m in nodes:
                if m == n:
                    continue
                w = views[m]
                if m in stalled.get(n, ()):
                    if _spoke(w, tol) != _spoke(v, tol):  # only the one that logged was running
                        if _spoke(w, tol):
                            verdict.excuse = max(verdict.excuse, w.own_anomaly * (1.0 - w.upstream))
                    elif odds and odds[m] > 0 and odds[m] >= TELLS * odds[n]:  # m blocked them, likelier
                        verdict.excuse = max(verdict.excuse,
                                             (1.0 - odds[n] / odds[m]) * w.own_anomaly * (1.0 - w.upstream))
                    elif not odds or odds[n] < TELLS * odds[m]:
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
