"""The symptom plugin API (version 1): what a plugin is, and what it sees on each call.

A plugin is a subclass of `Plugin` with a ``name``, the member ``kinds`` it looks at, default
``settings`` (the type of each default is the type a config value must have; checked by
`stream_viz.settings.check_plugin_settings`) and a ``check``
method that yields `stream_viz.records.Alert` objects for one sample. The `PluginContext` it is
called with answers what a check asks: the watched members, θ now and in the past, the graph
questions (`PluginContext.nodes_of`, `PluginContext.publishers`, ...), and makes the alerts.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Hashable, Iterable, Iterator, Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any, ClassVar, TypeVar

import networkx as nx
import numpy as np

from stream_viz.errors import PluginError
from stream_viz.model import queries
from stream_viz.model.diff import GraphDiff
from stream_viz.model.graph import FLOW
from stream_viz.model.history import History
from stream_viz.model.ids import kind_of, make_id
from stream_viz.model.theta import SCHEMAS
from stream_viz.records import Alert, Event

API_VERSION = 1
F = TypeVar("F", bound=Callable[..., Any])
T = TypeVar("T")
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
    learned : dict
        Private to the plugin, JSON values only: what it learned of this robot's healthy
        behaviour (a rate mode) that holds in later runs. Saved in the run's database at its end;
        a run started with ``--healthy RUN.sqlite`` begins with that run's.
    primed : Mapping
        What ``learned`` was when the run started (read-only; empty when it started from
        nothing): what the healthy run showed, apart from what this run adds.
    expected_rates : dict
        Topic id to the rate (Hz) the configuration expects.
    plugin : str
        The plugin's name (filled into alerts made with `alert`).
    kinds : tuple of str
        The member kinds the plugin declared (what `watched` yields; empty: any).
    """

    t: float
    graph: nx.MultiDiGraph
    watch: frozenset[str]
    history: History
    events: list[Event] = field(default_factory=list)
    diff: GraphDiff = field(default_factory=GraphDiff)
    settings: dict[str, Any] = field(default_factory=dict)
    state: dict[str, Any] = field(default_factory=dict)
    learned: dict[str, Any] = field(default_factory=dict)
    primed: Mapping[str, Any] = field(default_factory=lambda: MappingProxyType({}))
    expected_rates: dict[str, float] = field(default_factory=dict)
    plugin: str = ""
    kinds: tuple[str, ...] = ()
    # Watched members per kind, sorted; computed once per sample and shared by all plugins.
    by_kind: dict[str, list[str]] | None = field(default=None, repr=False)
    # Every member per kind, in the graph's order; likewise once per sample for all plugins.
    of_kind: dict[str, list[str]] | None = field(default=None, repr=False)

    # -- the members to check -------------------------------------------------------------------
    def watched(self, kind: str | None = None) -> Iterator[str]:
        """Yield the watched members of ``kind`` present in the graph, sorted.

        Without ``kind``: those of every kind the plugin declared in ``kinds``, kind by kind.

        Raises
        ------
        PluginError
            ``kind`` is not one the plugin declared.
        """
        if kind is not None and self.kinds and kind not in self.kinds:
            raise PluginError(f"plugin {self.plugin!r} asked for watched {kind!r} members but declares "
                              f"kinds = {self.kinds!r}; add {kind!r} to them")
        if self.by_kind is None:
            self.by_kind = watched_by_kind(self.graph, self.watch)
        for k in self.kinds if kind is None else (kind,):
            yield from self.by_kind.get(k, ())

    def members(self, kind: str) -> Iterator[str]:
        """Yield every member of ``kind`` in the graph, watched or not, in the graph's order."""
        # Plugins ask this over every member each sample: the graph is grouped by kind once.
        if self.of_kind is None:
            self.of_kind = members_by_kind(self.graph)
        return iter(self.of_kind.get(kind, ()))

    # -- what a member is and measures ----------------------------------------------------------
    @staticmethod
    def kind(member: str) -> str:
        """Return the kind of a member id (``node``, ``topic``, ``process``, ...), in the graph or not."""
        return kind_of(member)

    def attr(self, member: str, key: str, default: Any = None) -> Any:
        """Return the attribute ``key`` of ``member`` (``alive``, ``pid``, ``qos``, ...); ``default``
        when the member or the attribute is missing."""
        attrs = self.graph._node.get(member)  # a dict look-up: asked for every member each sample
        return default if attrs is None else attrs.get(key, default)

    def value(self, member: str, attr: str) -> float:
        """Return θ[attr] of ``member`` now; NaN when unknown or not measured."""
        attrs = self.graph._node.get(member)
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

    # -- graph questions (`stream_viz.model.queries`; missing members give empty answers) -------
    def nodes_of(self, process: str, *, by_pid: bool = False) -> list[str]:
        """Return the nodes ``process`` hosts, sorted (``by_pid``: also those whose ``pid`` is its
        pid; scans every member, for rare events)."""
        return queries.nodes_of_process(self.graph, process, by_pid=by_pid)

    def process_of(self, node: str) -> str | None:
        """Return the process hosting ``node``, or None when unknown."""
        return queries.process_of_node(self.graph, node)

    def publishers(self, topic: str) -> list[str]:
        """Return the nodes publishing ``topic``, sorted."""
        return queries.publishers(self.graph, topic)

    def subscribers(self, topic: str) -> list[str]:
        """Return the nodes subscribing to ``topic``, sorted."""
        return queries.subscribers(self.graph, topic)

    def published_topics(self, node: str) -> list[str]:
        """Return the topics ``node`` publishes, sorted."""
        return queries.published_topics(self.graph, node)

    def subscribed_topics(self, node: str) -> list[str]:
        """Return the topics ``node`` subscribes to, sorted."""
        return queries.subscribed_topics(self.graph, node)

    def servers(self, service: str) -> list[str]:
        """Return the nodes serving ``service`` (or the action ``service``), sorted."""
        return queries.servers(self.graph, service)

    def clients(self, service: str) -> list[str]:
        """Return the client nodes of ``service`` (or of the action ``service``), sorted."""
        return queries.clients(self.graph, service)

    def called_servers(self, node: str) -> list[str]:
        """Return the nodes whose services or actions ``node`` calls, sorted."""
        return queries.called_servers(self.graph, node)

    def flow_edge(self, source: str, target: str) -> dict[str, Any]:
        """Return the attributes of the data-flow edge ``source → target`` (``kind``, ``qos``, ...);
        empty when there is none."""
        data = self.graph.get_edge_data(source, target, FLOW)
        return {} if data is None else data

    # -- what plugins keep between calls ---------------------------------------------------------
    def since_last_call(self) -> float:
        """Seconds since this plugin's previous call (inf on the first): a topic whose newest
        message is older than that had no message since, so this sample is no new observation."""
        since = self.t - self.state.get("_t_prev", -math.inf)
        self.state["_t_prev"] = self.t
        return since

    def structural(self, compute: Callable[[], T], recheck_s: float = math.inf, key: str = "",
                   token: Hashable = None) -> T:
        """Return ``compute()``, redone only when the graph, the watchlist or ``token`` changed, or
        every ``recheck_s``: an analysis of the structure alone stays cheap on 1,000 members. ``key``
        names the analysis when a plugin keeps several; ``token`` is what else it depends on (the
        graph's ``qos_version``: a QoS changed in place)."""
        slot = ("_structural", key)
        cached = self.state.get(slot)
        if cached is not None and not self.diff and cached[0] == self.watch and self.t < cached[1] \
                and cached[3] == token:
            return cached[2]
        out = compute()
        self.state[slot] = (self.watch, self.t + recheck_s, out, token)
        return out

    def topic_ids(self, names: Iterable[str]) -> set[str]:
        """Return the topic member ids of topic names or ids (a setting such as ``ignore_topics``)."""
        return {n if n.startswith("topic:") else make_id("topic", n) for n in names}

    # -- the answer -----------------------------------------------------------------------------
    def alert(self, member: str, severity: str, message: str, **data: Any) -> Alert:
        """Return an alert of this plugin at ``t``."""
        return Alert(member=member, plugin=self.plugin, t=self.t, severity=severity, message=message,
                     data=data)


class Plugin:
    """Base class of symptom plugins.

    Subclasses set ``name``, ``kinds`` and ``settings`` and implement `check`. One instance
    lives for the whole run; keep per-run data in ``ctx.state`` (or on ``self``).

    Attributes
    ----------
    name : str
        Unique; the config's ``[plugins.<name>]`` table and the alerts' ``plugin``.
    kinds : tuple of str
        The member kinds the plugin checks: ``ctx.watched()`` yields the watched members of these.
    settings : dict
        Defaults; a configured value must have the default's type.
    uses : tuple of functions
        The shared helpers it calls that read ``ctx.settings`` (marked with `reads_settings`, such
        as `stream_viz.detect.baseline.rise`): a plugin whose ``settings`` lack a key one of them
        reads is refused when it loads, not found wanting at run time.
    api_version : int
        The plugin API it was written for (`API_VERSION`).
    """

    name: ClassVar[str] = ""
    kinds: ClassVar[tuple[str, ...]] = ()
    settings: ClassVar[dict[str, Any]] = {}
    uses: ClassVar[tuple[Callable[..., Any], ...]] = ()
    api_version: ClassVar[int] = API_VERSION

    def check(self, ctx: PluginContext) -> Iterable[Alert]:
        """Return (or yield) the alerts for the sample in ``ctx``."""
        raise NotImplementedError


def reads_settings(*keys: str) -> Callable[[F], F]:
    """Mark a shared helper with the keys of ``ctx.settings`` it reads.

    A plugin that lists the helper in ``uses`` must have these keys in its ``settings``
    (`missing_settings`, checked when the plugin loads).
    """
    def mark(helper: F) -> F:
        helper.settings_read = frozenset(keys)  # type: ignore[attr-defined]
        return helper
    return mark


def missing_settings(plugin: type[Plugin]) -> dict[str, list[str]]:
    """Return setting key → the helpers in ``plugin.uses`` that read it, for the keys its
    ``settings`` lack (empty when nothing is missing)."""
    out: dict[str, list[str]] = {}
    for helper in plugin.uses:
        for key in sorted(getattr(helper, "settings_read", ()) - plugin.settings.keys()):
            out.setdefault(key, []).append(f"{helper.__module__}.{helper.__qualname__}")
    return out


def watched_by_kind(G: nx.MultiDiGraph, watch: Iterable[str]) -> dict[str, list[str]]:
    """Return kind → sorted watched members present in ``G``."""
    out: dict[str, list[str]] = {}
    kinds = G.nodes(data="kind")
    for m in sorted(watch):
        if m in G:
            out.setdefault(kinds[m], []).append(m)
    return out


def members_by_kind(G: nx.MultiDiGraph) -> dict[str, list[str]]:
    """Return kind → every member of that kind in ``G``, in the graph's order (the attribute
    ``kind``)."""
    out: dict[str, list[str]] = {}
    for m, attrs in G._node.items():  # the attribute dicts, not a data view: every member
        out.setdefault(attrs.get("kind"), []).append(m)
    return out


def record_history(history: History, G: nx.MultiDiGraph, t: float) -> None:
    """Append θ of every member of ``G`` that has one to ``history`` at ``t``."""
    for m, theta in G.nodes(data="theta"):
        if theta is not None:
            history.add(m, t, np.asarray(theta, dtype=float))
