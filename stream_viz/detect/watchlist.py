"""The watchlist ``W_j``: the `Watchlist` of a run, and the policy of its initial part ``W_0``
(members named in the config, the watch modes, plus process monitoring).

After ``W_0`` the RCA's subgraph growth adds to it, and so do the watch policy and process
monitoring as members appear or turn anomalous.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Mapping, Set
from typing import Any

import networkx as nx

from stream_viz.detect.process import process_anomalies
from stream_viz.model.history import History
from stream_viz.model.ids import kind_of

# `auto` watches every member up to here: the plugins' cost for 1,000 watched members is small
# beside a 500-node system's sample (docs/plugins.md, docs/robustness.md); a lower limit left a
# 500-node system's topics unwatched, so a hang there raised nothing.
AUTO_LIMIT = 2000


def match_members(G: nx.MultiDiGraph, patterns: Iterable[str]) -> set[str]:
    """Return the members matching any pattern.

    A pattern with a kind (``node:/camera*``) matches member ids; one without
    (``/camera*``) matches the names of members of any kind. ``*``, ``?`` and ``[..]`` as in
    shell globs.
    """
    out: set[str] = set()
    members = list(G.nodes)
    for pat in patterns:
        if ":" in pat or pat == "root":
            out.update(fnmatch.filter(members, pat))
        else:
            out.update(m for m in members if fnmatch.fnmatchcase(m.partition(":")[2], pat))
    return out


def _get(settings: Any, key: str, default: Any) -> Any:
    if isinstance(settings, Mapping):
        return settings.get(key, default)
    return getattr(settings, key, default)


def initial_watchlist(G: nx.MultiDiGraph, settings: Any, history: History | None = None,
                      *, auto_limit: int = AUTO_LIMIT) -> set[str]:
    """Return ``W_0``.

    Parameters
    ----------
    G : MultiDiGraph
        The model.
    settings : WatchlistConfig or mapping
        ``mode`` (``auto``, ``all`` or ``config``) and ``members`` (ids or patterns).
    history : History, optional
        θ history for process monitoring.
    auto_limit : int
        ``auto`` watches everything up to this many members.

    Notes
    -----
    ``all`` (and ``auto`` on a graph of at most ``auto_limit`` members) watches every member.
    Otherwise: the configured members, every process (process monitoring is cheap and is what
    finds anomalous members), and the processes/nodes `process_anomalies` flags; ``auto`` also
    every node (the candidates: a crash, an error log or a resource alert lands on the nodes of
    a process, and an alert on an unwatched member never starts the diagnosis), topics and
    services joining as the subgraph grows.
    """
    mode = _get(settings, "mode", "auto")
    if mode == "all" or (mode == "auto" and G.number_of_nodes() <= auto_limit):
        return set(G.nodes)
    watch = match_members(G, _get(settings, "members", ()))
    kinds = ("process", "node") if mode == "auto" else ("process",)
    watch.update(m for m in G.nodes if kind_of(m) in kinds)
    if history is not None:
        watch |= process_anomalies(G, history)
    return watch


CONFIGURED = "configured"  # the config's members and the watch mode (`initial_watchlist`)
PROCESS_ANOMALY = "process_anomaly"  # flagged by process monitoring (`process_anomalies`)
GROWTH = "rca"  # added by the RCA's subgraph growth (`stream_viz.rca.subgraph.grow`)
SOURCES = (CONFIGURED, PROCESS_ANOMALY, GROWTH)


class Watchlist(Set[str]):
    """The watchlist ``W_j`` of a run: the members whose alerts grow the diagnosis, and where
    each came from. Reads as a set of member ids.

    One object for the whole run: the detector adds ``W_0`` and process-anomaly members as they
    show up (`add`), the RCA engine adds what its subgraph growth watches (`commit`), the
    plugins read it.

    Parameters
    ----------
    members : iterable of str
        ``W_0``, recorded by the RCA's iteration 0 (so not `pending`).
    source : str
        Where they came from (one of `SOURCES`).

    Notes
    -----
    ``W_j`` only grows, as in the paper, so the RCA's iterations never lose a member;
    `forget` drops where a long-gone member came from, not the member.
    """

    def __init__(self, members: Iterable[str] = (), source: str = CONFIGURED) -> None:
        self._members: set[str] = set(members)
        self._by_source: dict[str, set[str]] = {s: set() for s in SOURCES}
        self._by_source[source] |= self._members
        self._pending: set[str] = set()

    def __contains__(self, member: object) -> bool:
        return member in self._members

    def __iter__(self):
        return iter(self._members)

    def __len__(self) -> int:
        return len(self._members)

    @classmethod
    def _from_iterable(cls, it: Iterable[str]) -> frozenset[str]:
        return frozenset(it)  # set operations give plain sets, not another run's watchlist

    def __repr__(self) -> str:
        return f"Watchlist({sorted(self._members)!r})"

    @property
    def pending(self) -> frozenset[str]:
        """Members added from outside the RCA since its last iteration (the next one records them)."""
        return frozenset(self._pending)

    @property
    def external(self) -> frozenset[str]:
        """Members watched for the configuration, the watch mode or a process anomaly, less the
        forgotten ones: what a run saves as its ``W_0`` for ``stream-viz analyze``."""
        return frozenset(self._by_source[CONFIGURED] | self._by_source[PROCESS_ANOMALY])

    def sources(self, member: str) -> frozenset[str]:
        """Where ``member`` came from (empty when not watched, or forgotten)."""
        return frozenset(s for s, ms in self._by_source.items() if member in ms)

    def add(self, members: Iterable[str], source: str = CONFIGURED) -> frozenset[str]:
        """Watch ``members`` from outside the RCA; return those not watched before (now pending)."""
        fresh = set(members) - self._by_source[source]
        if not fresh:
            return frozenset()
        self._by_source[source] |= fresh
        new = fresh - self._members
        self._members |= new
        self._pending |= new
        return frozenset(new)

    def commit(self, grown: Iterable[str] = ()) -> None:
        """An RCA iteration was made: it recorded the pending additions, and ``grown`` (what its
        subgraph growth watches) joins ``W_j``."""
        grown = set(grown) - self._members
        self._members |= grown
        self._by_source[GROWTH] |= grown
        self._pending.clear()

    def forget(self, gone: Iterable[str]) -> None:
        """Drop where ``gone`` members came from: a member back after being forgotten is new to
        the watch policy, and it is no longer saved as watched from outside."""
        gone = set(gone)
        if gone:
            for ms in self._by_source.values():
                ms -= gone
