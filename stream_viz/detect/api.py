"""The symptom plugin API (version 1): what a plugin is, and what it sees on each call.

A plugin is a subclass of `Plugin` with a ``name``, the member ``kinds`` it looks at, default
``settings`` (the type of each default is the type a config value must have; checked by
`stream_viz.settings.check_plugin_settings`) and a ``check``
method that yields `stream_viz.records.Alert` objects for one sample.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any, ClassVar

import networkx as nx
import numpy as np

from stream_viz.model.diff import GraphDiff
from stream_viz.model.history import History
from stream_viz.model.theta import SCHEMAS
from stream_viz.records import Alert, Event

API_VERSION = 1
_INDEX = {kind: {name: i for i, name in enumerate(names)} for kind, names in SCHEMAS.items()}


@dataclass
class PluginContext:
    """Everything one plugin call sees.

    Attributes
    ----------
    t : float
        Sample time (unix s).
    graph : MultiDiGraph
        The model at ``t``; θ in the member attribute ``theta`` (see ``SCHEMAS``).
    watch : frozenset of str
        The watchlist ``W_j``.
    history : History
        θ per member over the last samples (the current sample included when the caller
        recorded it first; use `past` to get only older samples).
    events : list of Event
        What the collector saw since the last sample.
    diff : GraphDiff
        Members and edges that appeared or vanished since the last sample.
    settings : dict
        The plugin's validated settings.
    state : dict
        Private to the plugin; persists between calls.
    expected_rates : dict
        Topic id to the rate (Hz) the configuration expects.
    plugin : str
        The plugin's name (filled into alerts made with `alert`).
    """

    t: float
    graph: nx.MultiDiGraph
    watch: frozenset[str]
    history: History
    events: list[Event] = field(default_factory=list)
    diff: GraphDiff = field(default_factory=GraphDiff)
    settings: dict[str, Any] = field(default_factory=dict)
    state: dict[str, Any] = field(default_factory=dict)
    expected_rates: dict[str, float] = field(default_factory=dict)
    plugin: str = ""
    # Watched members per kind, sorted; computed once per sample and shared by all plugins.
    by_kind: dict[str, list[str]] | None = field(default=None, repr=False)

    def watched(self, kind: str) -> Iterator[str]:
        """Yield the watched members of ``kind`` present in the graph, sorted."""
        if self.by_kind is None:
            self.by_kind = watched_by_kind(self.graph, self.watch)
        yield from self.by_kind.get(kind, ())

    def value(self, member: str, attr: str) -> float:
        """Return θ[attr] of ``member`` now; NaN when unknown or not measured."""
        attrs = self.graph.nodes.get(member)
        if attrs is None:
            return float("nan")
        theta = attrs.get("theta")
        i = _INDEX.get(attrs.get("kind", ""), {}).get(attr)
        if theta is None or i is None or i >= len(theta):
            return float("nan")
        return float(theta[i])

    def past(self, member: str, attr: str, last: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(times, values)`` of θ[attr] of ``member`` strictly before ``t``.

        ``last``: read only the newest samples (about this many), which keeps a call cheap when
        the history is long.
        """
        from stream_viz.model.ids import kind_of

        n = None if last is None else last + 1  # the present sample may be in the history
        times, values = self.history.series(member, n)
        if len(times) == 0:
            return times, times
        schema = SCHEMAS.get(kind_of(member), ())
        if attr not in schema:
            return np.zeros(0), np.zeros(0)
        values = values[:, schema.index(attr)]
        keep = times < self.t
        return times[keep], values[keep]

    def alert(self, member: str, severity: str, message: str, **data: Any) -> Alert:
        """Return an alert of this plugin at ``t``."""
        return Alert(member=member, plugin=self.plugin, t=self.t, severity=severity, message=message,
                     data=data)


class Plugin:
    """Base class of symptom plugins.

    Subclasses set ``name``, ``kinds`` and ``settings`` and implement `check`. One instance
    lives for the whole run; keep per-run data in ``ctx.state`` (or on ``self``).
    """

    name: ClassVar[str] = ""
    kinds: ClassVar[tuple[str, ...]] = ()
    settings: ClassVar[dict[str, Any]] = {}
    api_version: ClassVar[int] = API_VERSION

    def check(self, ctx: PluginContext) -> Iterable[Alert]:
        """Return (or yield) the alerts for the sample in ``ctx``."""
        raise NotImplementedError


def watched_by_kind(G: nx.MultiDiGraph, watch: Iterable[str]) -> dict[str, list[str]]:
    """Return kind → sorted watched members present in ``G``."""
    out: dict[str, list[str]] = {}
    kinds = G.nodes(data="kind")
    for m in sorted(watch):
        if m in G:
            out.setdefault(kinds[m], []).append(m)
    return out


def record_history(history: History, G: nx.MultiDiGraph, t: float) -> None:
    """Append θ of every member of ``G`` that has one to ``history`` at ``t``."""
    for m, theta in G.nodes(data="theta"):
        if theta is not None:
            history.add(m, t, np.asarray(theta, dtype=float))
