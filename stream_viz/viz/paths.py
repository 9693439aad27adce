"""Rerun entity paths and timelines of a STREAM recording (docs/contracts.md), in one place."""

from __future__ import annotations

import rerun as rr

from stream_viz.model.ids import kind_of, name_of

# Timelines: wall clock (timestamp seconds) and the RCA iteration j (sequence).
TIME = "time"
RCA_ITERATION = "rca_iteration"

SYSTEM = "/system"  # G_0: GraphNodes + directed GraphEdges in one entity
PROCESS_TREE = "/process_tree"  # T_1 with the virtual root
METRICS = "/metrics"  # /metrics/<kind>/<member name>/theta: Scalars, one series per θ attribute
ALERTS = "/alerts"  # TextLog
CHANGES = "/changes"  # TextLog: changes of the system's configuration seen (parameters set at run time)
HEALTH = "/health"  # /health/<kind>/<member name>: StateChange lane (ok, a severity, gone)
RCA = "/rca"
RCA_SUBGRAPH = "/rca/subgraph"  # G_j and W_j, drawn over /system at the same positions
RCA_TRAJECTORY = "/rca/trajectory"  # top fault trajectory, same positions
RCA_REPORT = "/rca/report"  # TextDocument (markdown)
# Large systems: /system condensed around the diagnosis (groups as one disc each; alerted, gone
# and trajectory members and their neighbours in full); GraphNodes + GraphEdges in one entity.
CONDENSED = "/condensed"
HOSTS = "/hosts"  # /hosts/<host name>: one computer's part of /system (several computers only)
# Groups of /system drawn as boxes: one entity per group, two invisible corner nodes; the viewer
# captions each entity's rectangle with its path ("namespace/amr1", "process/navigation").
GROUP_ROOTS = ("/namespace", "/process", "/host")

THETA = "theta"  # leaf under a member's metric subtree: all its θ series (one entity: a small .rrd)
ALERT_MARKERS = "alerts"  # leaf under a member's metric subtree holding SeriesPoints markers


def member_path(member: str) -> str:
    """Return a member's entity sub-path: ``topic:/a/b`` -> ``topic/a/b``, ``process:7`` -> ``process/7``."""
    kind = kind_of(member)
    parts = [rr.escape_entity_path_part(p) for p in name_of(member).split("/") if p]
    return "/".join([kind, *parts]) if kind != "root" else "root"


def group_path(grouping: str, group: str) -> str:
    """Return the entity of a group's box: ``/namespace/amr1``, ``/process/<process name>``,
    ``/host/<host name>``."""
    root = {"process": GROUP_ROOTS[1], "host": GROUP_ROOTS[2]}.get(grouping, GROUP_ROOTS[0])
    parts = [rr.escape_entity_path_part(p) for p in group.split("/") if p]
    return "/".join([root, *parts])


def host_graph_path(host: str) -> str:
    """Return ``/hosts/<host name>``: the entity of one computer's part of the system graph."""
    return f"{HOSTS}/{rr.escape_entity_path_part(host)}"


def health_path(member: str) -> str:
    """Return ``/health/<kind>/<name>``: the member's health lane."""
    return f"{HEALTH}/{member_path(member)}"


def metrics_path(member: str, leaf: str | None = None) -> str:
    """Return ``/metrics/<kind>/<name>`` of a member, or of a leaf below it (`THETA`, `ALERT_MARKERS`)."""
    base = f"{METRICS}/{member_path(member)}"
    return f"{base}/{leaf}" if leaf else base
