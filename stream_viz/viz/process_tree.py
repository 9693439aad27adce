"""``/process_tree``: the process tree T_1 (virtual root -> processes -> ROS nodes)."""

from __future__ import annotations

import networkx as nx
import rerun as rr

from stream_viz.model.graph import PROCESS_TREE
from stream_viz.model.ids import ROOT, kind_of, name_of
from stream_viz.model.queries import tree
from stream_viz.viz import paths, style
from stream_viz.viz.graph_arrays import graph_archetypes
from stream_viz.viz.layout import tree_layout


def _label(G: nx.MultiDiGraph, m: str) -> str:
    data = G.nodes[m]
    if kind_of(m) == "process":
        name = data.get("name") or data.get("exe") or ""
        return f"{name} ({name_of(m)})" if name else f"pid {name_of(m)}"
    return str(data.get("label") or name_of(m))


def process_tree_arrays(G: nx.MultiDiGraph, layer: int = PROCESS_TREE) -> dict[str, list]:
    """Return the plain arrays drawn at ``/process_tree`` (ids, labels, colours, radii, positions, edges)."""
    T = tree(G, layer)
    pos = tree_layout(T, ROOT)
    ids = sorted(T)
    colors = [style.GONE_COLOR if G.nodes[m].get("gone") else style.KIND_COLOR.get(kind_of(m), (0, 0, 0))
              for m in ids]
    return {
        "ids": ids,
        "labels": [_label(G, m) + (style.GONE_SUFFIX if G.nodes[m].get("gone") else "") for m in ids],
        "colors": colors,
        "radii": [style.KIND_RADIUS.get(kind_of(m), 10.0) for m in ids],
        "positions": [pos[m] for m in ids],
        "edges": sorted(T.edges()),
    }


def log_process_tree(rec: rr.RecordingStream, G: nx.MultiDiGraph, layer: int = PROCESS_TREE) -> None:
    """Log tree ``T_layer`` (default the process tree) at ``/process_tree`` at the current time."""
    a = process_tree_arrays(G, layer)
    rec.log(paths.PROCESS_TREE, *graph_archetypes(a, show_labels=True))
