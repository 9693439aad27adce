"""``/system``: the system graph G_0 (ROS nodes and distributors, data-flow edges)."""

from __future__ import annotations

import weakref
from collections.abc import Collection, Mapping
from typing import Any

import networkx as nx
import numpy as np
import rerun as rr

from stream_viz.errors import ModelError
from stream_viz.model.graph import FLOW, copy_graph, flow_edges
from stream_viz.model.ids import kind_of, name_of
from stream_viz.viz import paths, style
from stream_viz.viz.graph_arrays import edge_array, graph_archetypes
from stream_viz.viz.layout import Layout, Pos, display_members, provisional, settle
from stream_viz.viz.layout_groups import short_label


def with_gone(G: nx.MultiDiGraph, gone: Collection[str]) -> nx.MultiDiGraph:
    """Return ``G`` plus the ``gone`` members it lacks (vanished before their edges were seen),
    marked ``gone``; ``G`` itself when it has them all."""
    extra = sorted(m for m in gone if m not in G and kind_of(m) in style.KIND_COLOR)
    if not extra:
        return G
    G = copy_graph(G)
    G.add_nodes_from((m, {"kind": kind_of(m), "label": name_of(m), "gone": True}) for m in extra)
    return G


def system_arrays(
    G: nx.MultiDiGraph,
    layout: Layout,
    gone: Collection[str] = (),
    status: Mapping[str, str] | None = None,
) -> dict[str, list]:
    """Return the plain arrays drawn at ``/system`` (ids, labels, colours, radii, positions, edges).

    Members of ``G`` with ``gone=True`` and members in ``gone`` are drawn grey with a suffix;
    ``status`` (member -> alert severity) colours alerted members by severity.
    """
    status = status or {}
    members = set(display_members(G)) | {m for m in gone if kind_of(m) in style.KIND_COLOR}
    members = sorted(m for m in members if kind_of(m) not in ("process", "host", "root"))
    missing = [m for m in members if m not in layout]
    if missing:
        raise ModelError(f"/system: the layout lacks {missing[:5]} (extend it with layout.provisional first)")
    ids, labels, colors, radii, positions = [], [], [], [], []
    for m in members:
        kind = kind_of(m)
        is_gone = (m in gone or bool(G.nodes[m].get("gone"))) if m in G else True
        label = short_label(G, m, layout.group_of.get(m)) + (style.GONE_SUFFIX if is_gone else "")
        if is_gone:
            color = style.GONE_COLOR
        elif m in status:
            color = style.SEVERITY_COLOR.get(status[m], style.KIND_COLOR[kind])
        else:
            color = style.KIND_COLOR[kind]
        ids.append(m)
        labels.append(label)
        colors.append(color)
        radii.append(style.KIND_RADIUS[kind])
        positions.append(layout.pos[m])
    keep = set(members)
    edges = sorted({(u, v) for u, v, _ in flow_edges(G) if u in keep and v in keep})
    return {"ids": ids, "labels": labels, "colors": colors, "radii": radii,
            "positions": positions, "edges": edges}


def drawn_status(status: Mapping[str, str], gone: Collection[str] = ()) -> frozenset[tuple[str, str]]:
    """Return the part of ``status`` (member -> severity) that colours ``/system``: members drawn
    there (not processes, hosts, the root) and not drawn as gone."""
    return frozenset((m, s) for m, s in status.items()
                     if m not in gone and kind_of(m) not in ("process", "host", "root"))


def signatures(G: nx.MultiDiGraph, gone: frozenset[str], colouring: frozenset) -> tuple[tuple, tuple]:
    """Return what ``/system`` and ``/process_tree`` are drawn from, comparable between samples:
    members, flow edges, ``gone``, ``colouring`` (`drawn_status`) and labels; tree edges and ``gone``.
    One pass over the adjacency dicts, not networkx's views, and no list of the edges: a large
    graph is compared every sample, and what is allocated here is walked by the garbage collector."""
    flow, tree = set(), set()
    for u, nbrs in G._succ.items():
        for v, keys in nbrs.items():
            for key, a in keys.items():
                if key == FLOW:
                    flow.add((u, v, a.get("kind")))
                else:
                    tree.add((u, v, key))
    labels = frozenset((m, a.get("label")) for m, a in G._node.items())
    return (frozenset(G._node), frozenset(flow), gone, colouring, labels), (frozenset(tree), gone)


def group_boxes(layout: Layout) -> dict[str, list[Pos]]:
    """Return entity path -> the two corners of each group's box (top-left, bottom-right).

    The viewer draws every entity of a graph view inside a rectangle captioned with its path: a
    group is an entity of two invisible corner nodes, so its rectangle is the group's box.
    """
    return {paths.group_path(layout.grouping, g): [(x0, y0), (x1, y1)]
            for g, (x0, y0, x1, y1) in sorted(layout.boxes.items())}


# The group entities each recording stream has drawn: a group that is gone is cleared.
_drawn_groups: weakref.WeakKeyDictionary[Any, set[str]] = weakref.WeakKeyDictionary()


def log_groups(rec: rr.RecordingStream, layout: Layout) -> None:
    """Log the groups' boxes (`group_boxes`); clear the ones drawn before that are gone."""
    boxes = group_boxes(layout)
    drawn = _drawn_groups.setdefault(rec, set())
    for path in sorted(drawn - set(boxes)):
        rec.log(path, rr.Clear(recursive=False))
    for path, corners in boxes.items():
        rec.log(path, rr.GraphNodes(["top_left", "bottom_right"], positions=corners, radii=[0.0, 0.0],
                                    colors=[(0, 0, 0, 0)] * 2, show_labels=False))
    _drawn_groups[rec] = set(boxes)


def system_view(
    G: nx.MultiDiGraph,
    layout: Layout | None = None,
    gone: Collection[str] = frozenset(),
    status: Mapping[str, str] | None = None,
) -> tuple[Layout, dict[str, list]]:
    """Return the layout and the arrays `log_system` draws (parameters as there)."""
    G = with_gone(G, gone)  # vanished before we ever saw their edges: still shown, as gone
    layout = settle(G, None) if layout is None else provisional(G, layout)
    return layout, system_arrays(G, layout, gone, status)


def log_system_arrays(rec: rr.RecordingStream, a: Mapping[str, list], layout: Layout) -> None:
    """Log arrays ``a`` (`system_view`) at ``/system`` and the layout's group boxes."""
    rec.log(paths.SYSTEM, *graph_archetypes(a, show_labels=True))
    log_groups(rec, layout)


GRAPH_FIELDS = ("ids", "labels", "colors", "radii", "positions", "edges")


def changed_fields(last: Mapping[str, Any] | None, a: Mapping[str, Any]) -> frozenset[str]:
    """Return the fields of arrays ``a`` that differ from ``last`` (the arrays a timeline shows);
    all of them when the members differ (every field is indexed by member, so none can stay)."""
    present = frozenset(f for f in GRAPH_FIELDS if f in a)
    if last is a:
        return frozenset()
    if last is None or last.get("ids") != a["ids"]:
        return present
    return frozenset(f for f in present if last.get(f) is not a[f] and last.get(f) != a[f])


def graph_update(a: Mapping[str, Any], fields: Collection[str],
                 show_labels: bool) -> list[rr.GraphNodes | rr.GraphEdges]:
    """Return the archetypes that log only ``fields`` of arrays ``a``: the viewer takes every
    field not logged from the latest row before on the timeline (latest-at)."""
    if "ids" in fields:
        nodes, edges = graph_archetypes(a, show_labels)
        return [nodes, edges] if "edges" in fields else [nodes]
    n = len(a["ids"])
    parts: dict[str, Any] = {}
    if "labels" in fields:
        parts["labels"] = a["labels"]
    if "colors" in fields:
        parts["colors"] = np.asarray(a["colors"], dtype=np.uint8).reshape(n, -1 if n else 3)
    if "radii" in fields:
        parts["radii"] = np.asarray(a["radii"], dtype=np.float32)
    if "positions" in fields:
        parts["positions"] = np.asarray(a["positions"], dtype=np.float32).reshape(n, 2)
    out: list[rr.GraphNodes | rr.GraphEdges] = [rr.GraphNodes.from_fields(**parts)] if parts else []
    if "edges" in fields:
        out.append(rr.GraphEdges(edge_array(a["edges"]), graph_type=rr.GraphType.Directed))
    return out


class DrawnGraph:
    """What one timeline shows at ``/system`` and the group boxes, so that the next log sends
    only what changed: an RCA iteration that recolours three members logs three colours' worth,
    not the graph (its ids, labels, positions and edges stay by latest-at).

    One per timeline a row is logged on; `forget` when the sink starts empty (a new file part).
    """

    def __init__(self) -> None:
        self.arrays: Mapping[str, Any] | None = None
        self.boxes: dict[str, list[Pos]] = {}

    def forget(self) -> None:
        self.arrays, self.boxes = None, {}

    def log(self, rec: Any, a: Mapping[str, Any], layout: Layout, show_labels: bool = True) -> frozenset[str]:
        """Log the fields of ``a`` and the boxes of ``layout`` this timeline does not show yet;
        return the fields logged."""
        fields = changed_fields(self.arrays, a)
        if fields:
            rec.log(paths.SYSTEM, *graph_update(a, fields, show_labels))
        boxes = group_boxes(layout)
        for path in sorted(set(self.boxes) - set(boxes)):
            rec.log(path, rr.Clear(recursive=False))
        for path, corners in boxes.items():
            if self.boxes.get(path) != corners:
                rec.log(path, rr.GraphNodes(["top_left", "bottom_right"], positions=corners, radii=[0.0, 0.0],
                                            colors=[(0, 0, 0, 0)] * 2, show_labels=False))
        self.arrays, self.boxes = a, boxes
        return fields


def log_system(
    rec: rr.RecordingStream,
    G: nx.MultiDiGraph,
    layout: Layout | None = None,
    gone: Collection[str] = frozenset(),
    status: Mapping[str, str] | None = None,
) -> Layout:
    """Log the system graph at ``/system`` at the stream's current time; return the layout used.

    Parameters
    ----------
    rec : RecordingStream
        Where to log.
    G : MultiDiGraph
        The model graph (or the ``seen`` union, whose vanished members carry ``gone=True``).
    layout : Layout, optional
        The layout (`settle`); without one ``G`` is laid out, members it lacks get provisional
        places (a new layout is returned).
    gone : collection of str
        Members to draw as gone (grey, label suffix), in addition to ``gone`` attributes.
    status : mapping, optional
        Member -> alert severity, to colour alerted members.
    """
    layout, a = system_view(G, layout, gone, status)
    log_system_arrays(rec, a, layout)
    return layout
