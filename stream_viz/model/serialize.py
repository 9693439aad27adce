"""The model as plain JSON-able data (report members/edges, snapshots kept in the alert database)."""

from __future__ import annotations

import math
from typing import Any

import networkx as nx
import numpy as np

from stream_viz.model.graph import add_member, new_graph

_SKIP = {"kind", "active", "label", "theta"}


def theta_to_list(theta: np.ndarray) -> list[float | None]:
    """θ as JSON holds it: floats, None for NaN (not measured)."""
    return [None if math.isnan(x) else x for x in theta.tolist()]


def theta_from_list(row: list[float | None]) -> np.ndarray:
    """The inverse of `theta_to_list`."""
    return np.array([np.nan if x is None else x for x in row], dtype=float)


def _plain(value: Any) -> Any:
    if isinstance(value, np.ndarray):
        return theta_to_list(value)
    if isinstance(value, np.generic):
        return value.item()
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, list | tuple | set | frozenset):
        return [_plain(v) for v in value]
    return value


def to_data(G: nx.MultiDiGraph) -> dict[str, list[dict[str, Any]]]:
    """Return ``{"members": [...], "edges": [...]}`` in the report's form (docs/contracts.md).

    Each member has ``id``, ``kind`` and its extra attributes (``pid`` …); ``theta`` is kept as
    a list when present. Each edge has ``src``, ``dst``, ``kind`` and ``layer``.
    """
    members = []
    for m, attrs in sorted(G.nodes(data=True)):
        row = {"id": m, "kind": attrs["kind"]}
        row.update({k: _plain(v) for k, v in attrs.items() if k not in _SKIP})
        if "theta" in attrs:
            row["theta"] = _plain(attrs["theta"])
        members.append(row)
    edges = [
        {"src": u, "dst": v, "kind": d.get("kind", ""), "layer": k}
        | {a: _plain(x) for a, x in d.items() if a != "kind"}
        for u, v, k, d in sorted(G.edges(keys=True, data=True), key=lambda e: (e[2], e[0], e[1]))
    ]
    return {"members": members, "edges": edges}


def from_data(data: dict[str, Any]) -> nx.MultiDiGraph:
    """Rebuild a model graph from `to_data` output."""
    G = new_graph()
    for row in data.get("members", []):
        attrs = {k: v for k, v in row.items() if k not in ("id", "kind", "theta")}
        if row.get("theta") is not None:
            attrs["theta"] = theta_from_list(row["theta"])
        add_member(G, row["id"], **attrs)
    for e in data.get("edges", []):
        extra = {k: v for k, v in e.items() if k not in ("src", "dst", "kind", "layer")}
        G.add_edge(e["src"], e["dst"], key=int(e.get("layer", 0)), kind=e.get("kind", ""), **extra)
    return G
