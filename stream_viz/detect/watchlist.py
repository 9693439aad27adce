"""The initial watchlist ``W_0``: members named in the config, plus process monitoring.

After ``W_0`` the watchlist changes only through the RCA's subgraph growth.
"""

from __future__ import annotations

import fnmatch
from collections.abc import Iterable, Mapping
from typing import Any

import networkx as nx

from stream_viz.detect.process import process_anomalies  # the rule lives there; also imported from here
from stream_viz.model.history import History
from stream_viz.model.ids import kind_of

# `auto` watches every member up to here: the plugins cost ~44 ms a sample for 1,000 watched
# members inline under a load of 54 (docs/plugins.md), small beside a 500-node system's ~250 ms
# sample; a 300 limit left a 500-node system's topics unwatched, so a hang there raised nothing.
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
