"""What the metrics view shows first: the members of the current diagnosis, with their processes."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import networkx as nx

from stream_viz.model.ids import kind_of
from stream_viz.model.queries import process_of_node
from stream_viz.records import SEVERITY_RANK

MAX_DIAGNOSIS = 6  # plots side by side in the Diagnosis tab; the rest are in the per-kind tabs


def diagnosis_members(
    G: nx.MultiDiGraph,
    root_causes: Sequence[Mapping[str, Any]] = (),
    status: Mapping[str, str] | None = None,
    limit: int = MAX_DIAGNOSIS,
) -> dict[str, list[str]]:
    """Return ``member -> members whose θ its plot shows``, most telling first.

    The top trajectory's ends (root cause, first symptom), its members with an alert, the rest of
    it in the order the fault spread, then the other alerted members (``status``: member ->
    severity), most severe first. A node has no θ of its own: its plot shows its process's
    (``process_of_node``) beside its alert markers. At most ``limit`` members.
    """
    status = status or {}
    top = root_causes[0] if root_causes else None
    path = list(reversed(top.get("trajectory") or [top["member"]])) if top else []
    alerted = sorted(status.items(), key=lambda kv: (-SEVERITY_RANK.get(kv[1], -1), kv[0]))
    order = [*path[:1], *path[-1:], *(m for m in path if m in status), *path, *(m for m, _ in alerted)]
    out: dict[str, list[str]] = {}
    for m in dict.fromkeys(order):
        if len(out) >= limit:
            break
        shown = [m]
        if m in G and kind_of(m) == "node" and (proc := process_of_node(G, m)) is not None:
            shown.append(proc)
        out[m] = shown
    return out
