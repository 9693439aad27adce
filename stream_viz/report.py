"""The report JSON of docs/contracts.md (``stream-viz.report/v2``), written atomically."""

from __future__ import annotations

import json
import os
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import networkx as nx

from stream_viz.errors import OutputError
from stream_viz.model.graph import FLOW
from stream_viz.model.ids import make_id
from stream_viz.model.queries import process_of_node
from stream_viz.records import Alert

SCHEMA = "stream-viz.report/v2"


def build_report(
    G: nx.MultiDiGraph,
    alerts: Iterable[Alert],
    rca: Mapping[str, Any],
    started_at: float,
    ended_at: float,
    injected: Mapping[str, Any] | None = None,
    problems: Iterable[Mapping[str, Any]] = (),
    limits: Mapping[str, str] | None = None,
    healthy_from: str | None = None,
) -> dict[str, Any]:
    """Return the report dict for the model ``G``, the alerts and the RCA's ``to_report()`` output.

    Parameters
    ----------
    G : MultiDiGraph
        The model (every member seen during the run; vanished ones carry ``gone=True``).
    alerts : iterable of Alert
        Every alert stored during the run, in time order.
    rca : mapping
        ``{"iterations": [...], "root_causes": [...], "incidents": [...]}`` as the RCA engine
        reports them (`RcaResult.to_report`).
    started_at, ended_at : float
        Unix seconds.
    injected : mapping, optional
        What the demo injected (``fault``, ``target``, ``t``).
    problems : iterable of mapping, optional
        The store's problems (`AlertStore.problems`); the plugins' go in the report, so a reader
        knows when a plugin failed or was disabled and its symptoms could not be seen.
    limits : mapping, optional
        What the collector could not do or see, and why (`Collector.limits`: a fallback, a
        local process never discovered); absent from the report when empty.
    healthy_from : str, optional
        The database of the healthy run this one started from (``--healthy``): what it showed
        as normal was not alerted on here.
    """
    members = []
    for m, attrs in sorted(G.nodes(data=True)):
        row: dict[str, Any] = {"id": m, "kind": attrs["kind"]}
        if attrs["kind"] == "node":
            row["pid"] = attrs.get("pid")
        if "host" in attrs:  # several computers (collect/hosts.py)
            row["host"] = make_id("host", attrs["host"])
            if attrs["kind"] == "node":
                row["process"] = process_of_node(G, m)
        if attrs["kind"] == "host":
            row["agent"] = attrs.get("agent", "none")
        if attrs.get("gone"):
            row["gone"] = True
        members.append(row)
    edges = [
        {"src": u, "dst": v, "kind": kind}
        for u, v, key, kind in sorted(G.edges(keys=True, data="kind"), key=lambda e: (e[2], e[0], e[1]))
        if key == FLOW
    ]
    report: dict[str, Any] = {
        "schema": SCHEMA,
        "started_at": started_at,
        "ended_at": ended_at,
        "members": members,
        "edges": edges,
        "alerts": [
            {"member": a.member, "plugin": a.plugin, "severity": a.severity, "t": a.t, "message": a.message}
            for a in alerts
        ],
        "iterations": list(rca.get("iterations", [])),
        "root_causes": list(rca.get("root_causes", [])),
        "incidents": list(rca.get("incidents", [])),
        "problems": [{"t": p["t"], "plugin": p["plugin"], "kind": p["kind"], "where": p["where"],
                      "message": p["message"], "count": p["count"]} for p in problems if p["plugin"]],
    }
    if injected:
        report["injected"] = dict(injected)
    if limits:
        report["collector_limits"] = dict(limits)
    if healthy_from:
        report["healthy_from"] = healthy_from
    return report


def write_report(path: Path, report: Mapping[str, Any]) -> None:
    """Write ``report`` as JSON to ``path`` via a temporary file, so a reader never sees half a file."""
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        tmp.write_text(json.dumps(report, indent=1, default=_default))
        os.replace(tmp, path)
    except OSError as exc:
        raise OutputError(f"report {path}: {exc.strerror or exc}") from exc


def _default(value: Any) -> Any:
    if hasattr(value, "tolist"):
        return value.tolist()
    if isinstance(value, set | frozenset | tuple):
        return sorted(value) if isinstance(value, set | frozenset) else list(value)
    raise TypeError(f"not JSON serialisable: {type(value).__name__}")
