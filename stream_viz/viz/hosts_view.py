"""``/hosts/<host>``: the system graph of one computer, for the viewer's per-host tabs.

With several computers a user asks "what runs on the perception computer?": each host gets its
own graph entity with its nodes and the topics, services and actions they use, at their places
in ``/system`` and in its colours (the system graph is one entity, so a view cannot filter it).
Logged with ``/system`` on the ``time`` timeline, only the fields that changed.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import networkx as nx
import rerun as rr

from stream_viz.model.graph import FLOW
from stream_viz.model.ids import kind_of, name_of
from stream_viz.viz import paths
from stream_viz.viz.system import changed_fields, graph_update

FIELDS = ("ids", "labels", "colors", "radii", "positions")


def hosts_of(G: nx.MultiDiGraph) -> list[str]:
    """Return the names of the model's hosts, sorted; empty on one computer (its one host member
    would only repeat the whole system graph)."""
    hosts = sorted(name_of(m) for m, k in G.nodes(data="kind") if k == "host")
    return hosts if len(hosts) > 1 else []


def host_arrays(G: nx.MultiDiGraph, a: Mapping[str, list], host: str) -> dict[str, list]:
    """Return the part of ``/system``'s arrays ``a`` that runs on ``host``: its nodes, the members
    they exchange data with (topics, services, actions; a node of another host is left out) and
    the edges among those."""
    mine = {m for m in a["ids"] if m in G and G.nodes[m].get("host") == host and kind_of(m) == "node"}
    keep = set(mine)
    for n in mine:
        keep |= {x for x, keys in G._succ[n].items() if FLOW in keys and kind_of(x) != "node"}
        keep |= {x for x, keys in G._pred[n].items() if FLOW in keys and kind_of(x) != "node"}
    rows = [i for i, m in enumerate(a["ids"]) if m in keep]
    out: dict[str, list] = {f: [a[f][i] for i in rows] for f in FIELDS}
    out["edges"] = [(u, v) for u, v in a["edges"] if u in keep and v in keep and (u in mine or v in mine)]
    return out


class DrawnHosts:
    """What each ``/hosts/<host>`` entity shows, so that the next log sends only what changed;
    a host that left is cleared. `forget` when the sink starts empty (a new file part)."""

    def __init__(self) -> None:
        self.arrays: dict[str, Mapping[str, Any]] = {}

    def forget(self) -> None:
        self.arrays = {}

    def log(self, rec: Any, G: nx.MultiDiGraph, a: Mapping[str, list]) -> list[str]:
        """Log each host's part of arrays ``a``; return the hosts (empty on one computer)."""
        hosts = hosts_of(G)
        for h in sorted(set(self.arrays) - set(hosts)):
            rec.log(paths.host_graph_path(h), rr.Clear(recursive=False))
            del self.arrays[h]
        for h in hosts:
            sub = host_arrays(G, a, h)
            fields = changed_fields(self.arrays.get(h), sub)
            if fields:
                rec.log(paths.host_graph_path(h), *graph_update(sub, fields, show_labels=True))
            self.arrays[h] = sub
        return hosts
