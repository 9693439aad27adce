"""Dynamic subgraph allocation (paper §3.3.2): ``G_j = (M_j, E_j)`` and the watchlist ``W_j``.

On an alert for ``m ∈ W_j``:

- ``M_{j+1} = M_j ∪ {m}``
- ``E_{j+1} = E_j ∪ {((x, m), 0) ∈ E | x ∈ M_j}`` (``downstream``: exactly the paper); for
  ``upstream`` and ``both`` also ``{((m, x), 0) ∈ E | x ∈ M_j}``, because there the watchlist grows
  towards predecessors, and the edge from a newly alerting predecessor to the member it feeds
  would otherwise never enter ``E_j``.
- ``W_{j+1} = W_j ∪ {x | ((m, x), 0) ∈ E}`` (``downstream``: the paper); ``upstream`` adds the
  causal parents of ``m`` instead — its predecessors (for a ``send`` edge client → server: the
  server) and, when ``m`` is passive, also the parents of its publishers (`upstream_of`), so the
  search can pass a silent, hung publisher; ``both`` adds both sets.

Alerts for members outside ``W_j`` leave the subgraph as it is (the caller keeps them), and so
does an alert that would change nothing: only alerts that change ``M``, ``E`` or ``W`` make a new
iteration. Iterations store what they added and point to the previous one, so a long run costs
memory in proportion to the subgraph, not to the number of iterations times its size.

``W_j`` itself is the run's `stream_viz.detect.watchlist.Watchlist` (other parts add to it too):
`grow` reads it and returns what to add.
"""

from __future__ import annotations

from collections.abc import Iterable, Set
from dataclasses import dataclass, field

import networkx as nx

from stream_viz.model.queries import flow_predecessors, flow_successors
from stream_viz.rca.causal import causes, is_node
from stream_viz.records import Alert

Edge = tuple[str, str]


@dataclass(frozen=True, eq=False)
class Iteration:
    """One stage ``j`` of the subgraph: the alert that made it and the sets ``M_j``, ``E_j``, ``W_j``.

    ``members``, ``edges`` and ``watchlist`` are the full sets (computed from the ``added_*``
    deltas along ``prev``). Iteration 0 has no alert (``alert_member`` is None).
    """

    j: int
    t: float
    alert_member: str | None
    plugin: str | None
    added_members: frozenset[str] = frozenset()
    added_edges: frozenset[Edge] = frozenset()
    added_watch: frozenset[str] = frozenset()
    prev: Iteration | None = field(default=None, repr=False)

    def _collect(self, attr: str) -> frozenset:
        parts, it = [], self
        while it is not None:
            parts.append(getattr(it, attr))
            it = it.prev
        return frozenset().union(*parts)

    @property
    def members(self) -> frozenset[str]:
        """``M_j``."""
        return self._collect("added_members")

    @property
    def edges(self) -> frozenset[Edge]:
        """``E_j`` as ``(u, v)`` pairs (all layer 0)."""
        return self._collect("added_edges")

    @property
    def watchlist(self) -> frozenset[str]:
        """``W_j``."""
        return self._collect("added_watch")


@dataclass(frozen=True)
class SubgraphState:
    """The current ``G_j``; ``last`` is iteration ``j`` (earlier ones via ``prev``)."""

    members: frozenset[str]
    edges: frozenset[Edge]
    last: Iteration

    @property
    def j(self) -> int:
        """The current iteration index."""
        return self.last.j

    def iterations(self) -> list[Iteration]:
        """All iterations ``0 … j``, in order."""
        out, it = [], self.last
        while it is not None:
            out.append(it)
            it = it.prev
        return out[::-1]


def initial_state(watchlist: Iterable[str], t: float = 0.0) -> SubgraphState:
    """Return iteration 0: empty subgraph, watchlist ``W_0``."""
    it = Iteration(0, t, None, None, added_watch=frozenset(watchlist))
    return SubgraphState(frozenset(), frozenset(), it)


def upstream_of(G: nx.MultiDiGraph, m: str) -> set[str]:
    """What ``upstream`` watches after an alert on ``m``: its causal parents (predecessors; the
    server for a service client) and, when ``m`` is passive, the parents of its publishers — a
    silent topic is charged to its publisher, whose inputs are where to look next even when the
    publisher itself raises nothing (hang)."""
    parents = set(causes(G, m))
    if not is_node(G, m):
        for p in list(parents):
            if is_node(G, p):
                parents |= set(causes(G, p))
    parents.discard(m)
    return parents


def grow(
    G: nx.MultiDiGraph,
    state: SubgraphState,
    alert: Alert,
    watchlist: Set[str],
    policy: str = "downstream",
    pending: Set[str] = frozenset(),
) -> tuple[SubgraphState, frozenset[str]]:
    """Return the state after ``alert`` and the members it adds to the watchlist
    (``state`` itself and nothing when the alert changes nothing).

    Parameters
    ----------
    G : MultiDiGraph
        The full model; only layer-0 edges are used.
    state : SubgraphState
        ``G_j``.
    alert : Alert
        The alert; only its member matters for the growth.
    watchlist : set of str
        ``W_j``.
    policy : {"downstream", "upstream", "both"}
        Which neighbours of the alerting member join the watchlist (module docstring).
    pending : set of str
        Members of ``W_j`` added from outside since iteration ``j``: a new iteration records
        them with what it adds.

    Returns
    -------
    state : SubgraphState
        ``G_{j+1}``; its ``last`` is the new iteration.
    added : frozenset of str
        The members ``W_{j+1}`` has and ``W_j`` lacks.
    """
    m = alert.member
    if m not in watchlist:
        return state, frozenset()
    add_m = frozenset() if m in state.members else frozenset({m})
    new_edges = {(x, m) for x in flow_predecessors(G, m) if x in state.members}
    watch_add: set[str] = set()
    if policy in ("downstream", "both"):
        watch_add |= flow_successors(G, m)
    if policy in ("upstream", "both"):
        watch_add |= upstream_of(G, m)
        new_edges |= {(m, x) for x in flow_successors(G, m) if x in state.members}
    add_e = frozenset(new_edges - state.edges)
    add_w = frozenset(x for x in watch_add if x not in watchlist)
    if not (add_m or add_e or add_w):
        return state, frozenset()
    # The new iteration records the outside additions since the last one as its own.
    watched = add_w | frozenset(pending)
    it = Iteration(state.j + 1, alert.t, m, alert.plugin, add_m, add_e, watched, state.last)
    grown = SubgraphState(
        state.members | add_m if add_m else state.members,
        state.edges | add_e if add_e else state.edges,
        it,
    )
    return grown, add_w
