"""``/rca/...``: per RCA iteration j, G_j and W_j and the top fault trajectory over the system graph,
and the ranked root causes as a markdown report."""

from __future__ import annotations

import itertools
from collections.abc import Mapping, Sequence
from typing import Any

import networkx as nx
import rerun as rr

from stream_viz.errors import ModelError
from stream_viz.model.ids import kind_of
from stream_viz.viz import paths, style
from stream_viz.viz.layout import Layout
from stream_viz.viz.system import log_system


def _radius(member: str) -> float:
    try:  # nodes a little larger than distributors, as in /system
        return style.OVERLAY_RADIUS * (1.0 if kind_of(member) == "node" else 0.8)
    except ModelError:  # a malformed id still gets drawn
        return style.OVERLAY_RADIUS


def subgraph_arrays(iteration: Mapping[str, Any], layout: Layout) -> dict[str, list]:
    """Return the plain arrays of the ``/rca/subgraph`` overlay: G_j red, W_j-only yellow, the
    alerted member dark red; members without a position (not in G_0) are left out. A watchlist
    covering most of the graph (the ``auto``/``all`` modes) is not drawn: it would carpet it."""
    sub = list(dict.fromkeys(iteration.get("subgraph", [])))
    watch = [m for m in dict.fromkeys(iteration.get("watchlist", [])) if m not in sub]
    if len(watch) > 0.5 * len(layout.pos):
        watch = []
    alert = iteration.get("alert")
    ids = [m for m in [*sub, *watch] if m in layout.pos]
    colors = [style.ALERT_COLOR if m == alert else
              (style.SUBGRAPH_COLOR if m in sub else style.WATCH_COLOR) for m in ids]
    keep = set(ids)
    edges = [(u, v) for u, v in (tuple(e) for e in iteration.get("edges", [])) if u in keep and v in keep]
    return {"ids": ids, "colors": colors, "radii": [_radius(m) for m in ids],
            "positions": [layout.pos[m] for m in ids], "edges": edges}


def trajectory_arrays(root_causes: Sequence[Mapping[str, Any]], layout: Layout) -> dict[str, list]:
    """Return the plain arrays of the ``/rca/trajectory`` overlay: the top trajectory, drawn in the
    direction the fault spread (root cause -> … -> first symptom), the root cause black."""
    if not root_causes:
        return {"ids": [], "colors": [], "radii": [], "positions": [], "edges": []}
    top = root_causes[0]
    path = list(reversed(top.get("trajectory") or [top["member"]]))
    ids = list(dict.fromkeys(m for m in path if m in layout.pos))
    colors = [style.ROOT_CAUSE_COLOR if m == top["member"] else style.TRAJECTORY_COLOR for m in ids]
    keep = set(ids)
    edges = [(u, v) for u, v in itertools.pairwise(path) if u in keep and v in keep and u != v]
    return {"ids": ids, "colors": colors, "radii": [_radius(m) * 1.1 for m in ids],
            "positions": [layout.pos[m] for m in ids], "edges": edges}


def report_markdown(
    root_causes: Sequence[Mapping[str, Any]],
    iteration: Mapping[str, Any] | None = None,
    top: int = 10,
) -> str:
    """Return the markdown report: the ranked root causes with their trajectories."""
    lines = ["# Root-cause analysis", ""]
    if iteration is not None:
        lines += [f"Iteration j = {iteration.get('j')}: subgraph of {len(iteration.get('subgraph', []))} "
                  f"members, watchlist of {len(iteration.get('watchlist', []))}"
                  + (f", last alert on `{iteration['alert']}`" if iteration.get("alert") else "") + ".", ""]
    if not root_causes:
        return "\n".join([*lines, "No root cause found yet."])
    lines += ["| rank | root cause | score | trajectory (first symptom → cause) |", "|---|---|---|---|"]
    for i, rc in enumerate(root_causes[:top], 1):
        traj = " → ".join(f"`{m}`" for m in rc.get("trajectory") or [rc["member"]])
        lines.append(f"| {i} | **`{rc['member']}`** | {float(rc.get('score', 0.0)):.3f} | {traj} |")
    if len(root_causes) > top:
        lines += ["", f"… and {len(root_causes) - top} more."]
    return "\n".join(lines)


def log_report(rec: rr.RecordingStream, markdown: str) -> None:
    """Log the report at ``/rca/report`` (TextDocument, markdown) at the current time."""
    rec.log(paths.RCA_REPORT, rr.TextDocument(markdown, media_type=rr.MediaType.MARKDOWN))


def _log_overlay(rec: rr.RecordingStream, path: str, a: dict[str, list]) -> None:
    if not a["ids"]:
        rec.log(path, rr.Clear(recursive=False))
        return
    rec.log(path,
            rr.GraphNodes(a["ids"], colors=a["colors"], radii=a["radii"], positions=a["positions"],
                          show_labels=False),
            rr.GraphEdges(a["edges"], graph_type=rr.GraphType.Directed))


def log_rca(
    rec: rr.RecordingStream,
    G: nx.MultiDiGraph,
    layout: Layout | None,
    iteration: Mapping[str, Any],
    root_causes: Sequence[Mapping[str, Any]] = (),
    gone: Sequence[str] = (),
    status: Mapping[str, str] | None = None,
) -> Layout:
    """Log RCA iteration ``j`` on both timelines (``time`` = its ``t``, ``rca_iteration`` = ``j``).

    The system graph is logged again at this iteration (so it shows when stepping on
    ``rca_iteration``), then the overlays ``/rca/subgraph`` (G_j, W_j) and ``/rca/trajectory`` (top
    trajectory) at the same positions, and the report. Returns the (possibly extended) layout.

    Parameters
    ----------
    iteration : mapping
        ``{"j", "t", "subgraph": [...], "watchlist": [...], "edges": [[u, v], ...], "alert": member}``.
    root_causes : sequence of mapping
        Ranked best first, ``{"member", "score", "trajectory": [...]}`` (report JSON form).
    """
    rec.set_time(paths.TIME, timestamp=float(iteration["t"]))
    rec.set_time(paths.RCA_ITERATION, sequence=int(iteration["j"]))
    try:
        layout = log_system(rec, G, layout, gone=gone, status=status)
        _log_overlay(rec, paths.RCA_SUBGRAPH, subgraph_arrays(iteration, layout))
        _log_overlay(rec, paths.RCA_TRAJECTORY, trajectory_arrays(root_causes, layout))
        log_report(rec, report_markdown(root_causes, iteration))
    finally:
        # Later data (metrics, /system updates) must not inherit this iteration number.
        rec.disable_timeline(paths.RCA_ITERATION)
    return layout
