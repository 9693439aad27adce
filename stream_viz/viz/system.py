"""``/system``: the system graph G_0 (ROS nodes and distributors, data-flow edges)."""

from __future__ import annotations

from collections.abc import Collection, Mapping

import networkx as nx
import rerun as rr

from stream_viz.errors import ModelError
from stream_viz.model.graph import flow_edges
from stream_viz.model.ids import kind_of, name_of
from stream_viz.viz import paths, style
from stream_viz.viz.layout import Layout, display_members, place


def _label(G: nx.MultiDiGraph, m: str) -> str:
    if m in G:
        return str(G.nodes[m].get("label") or name_of(m))
    return name_of(m)


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
        raise ModelError(f"/system: the layout lacks {missing[:5]} (extend it with layout.place first)")
    ids, labels, colors, radii, positions = [], [], [], [], []
    for m in members:
        kind = kind_of(m)
        is_gone = (m in gone or bool(G.nodes[m].get("gone"))) if m in G else True
        label = _label(G, m) + (style.GONE_SUFFIX if is_gone else "")
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
        Positions so far; members not in it are placed (a new layout is returned).
    gone : collection of str
        Members to draw as gone (grey, label suffix), in addition to ``gone`` attributes.
    status : mapping, optional
        Member -> alert severity, to colour alerted members.
    """
    extra = [m for m in gone if m not in G and kind_of(m) in style.KIND_COLOR]
    if extra:  # vanished before we ever saw their edges: still shown, as gone
        G = G.copy()
        G.add_nodes_from((m, {"kind": kind_of(m), "label": name_of(m), "gone": True}) for m in extra)
    layout = place(G, layout)
    a = system_arrays(G, layout, gone, status)
    rec.log(
        paths.SYSTEM,
        rr.GraphNodes(a["ids"], labels=a["labels"], colors=a["colors"], radii=a["radii"],
                      positions=a["positions"], show_labels=True),
        rr.GraphEdges(a["edges"], graph_type=rr.GraphType.Directed),
    )
    return layout
