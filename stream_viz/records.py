"""Plain records that cross module boundaries: what the collector sees, what plugins emit."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import networkx as nx

from stream_viz.model.diff import GraphDiff

# The one severity scale, least to most severe: alerts, log and diagnostic levels, episodes, the
# viewer's colours and the RCA's weights all use it.
SEVERITIES = ("info", "warn", "error", "fatal")
SEVERITY_RANK = {s: i for i, s in enumerate(SEVERITIES)}


@dataclass(frozen=True)
class Event:
    """Something the collector saw happen between two samples.

    ``kind`` is one of ``log`` (a /rosout line), ``diag`` (one /diagnostics status),
    ``exit`` (a process ended), ``restart`` (a node's process changed pid), ``goal`` (an action
    goal ended), ``param`` (a node's parameters changed), ``stamp_reset`` (a topic's header stamps
    went back: a recording looped, a simulation reset), ``observe_error`` (something could not
    be read). ``member`` is the member it concerns (``node:/x`` …);
    ``level`` is one of `SEVERITIES`; ``data`` holds the rest (logger name, status name …).
    """

    t: float
    kind: str
    member: str
    level: str
    text: str
    data: dict[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class Alert:
    """A symptom a plugin found: ``(member, plugin, t, severity, message, data)``."""

    member: str
    plugin: str
    t: float
    severity: str
    message: str
    data: dict[str, Any] = field(default_factory=dict)


@dataclass
class Sample:
    """One tick of the collector: the whole model at ``t`` (θ on members), events, and the diff."""

    t: float
    graph: nx.MultiDiGraph
    events: list[Event] = field(default_factory=list)
    diff: GraphDiff = field(default_factory=GraphDiff)
    # Members that could not be read this tick, with why (kept in the model, reported).
    unreadable: dict[str, str] = field(default_factory=dict)
