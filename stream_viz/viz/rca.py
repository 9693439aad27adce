"""``/rca/...``: per RCA iteration j, G_j and W_j and the top fault trajectory over the system graph,
and the ranked root causes (of the current incident, and every incident) as a markdown report."""

from __future__ import annotations

import itertools
import time
from collections.abc import Mapping, Sequence
from typing import Any

import networkx as nx
import rerun as rr

from stream_viz.errors import ModelError
from stream_viz.model.ids import kind_of
from stream_viz.viz import paths, style
from stream_viz.viz.graph_arrays import graph_archetypes
from stream_viz.viz.hosts_view import DrawnHosts
from stream_viz.viz.layout import Layout
from stream_viz.viz.system import DrawnGraph, system_view


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
    direction the fault spread (root cause -> … -> first symptom), the root cause black.

    A root cause the graph does not draw (a host: computers are not in ``/system``) is shown
    through the nodes it explains (``evidence.explains_nodes``), black as the cause."""
    if not root_causes:
        return {"ids": [], "colors": [], "radii": [], "positions": [], "edges": []}
    top = root_causes[0]
    path = list(reversed(top.get("trajectory") or [top["member"]]))
    roots = {top["member"]}
    if top["member"] not in layout.pos:
        roots |= set((top.get("evidence") or {}).get("explains_nodes") or ())
    ids = list(dict.fromkeys(m for m in [*path, *sorted(roots)] if m in layout.pos))
    colors = [style.ROOT_CAUSE_COLOR if m in roots else style.TRAJECTORY_COLOR for m in ids]
    keep = set(ids)
    edges = [(u, v) for u, v in itertools.pairwise(path) if u in keep and v in keep and u != v]
    return {"ids": ids, "colors": colors, "radii": [_radius(m) * 1.1 for m in ids],
            "positions": [layout.pos[m] for m in ids], "edges": edges}


def report_markdown(
    root_causes: Sequence[Mapping[str, Any]],
    iteration: Mapping[str, Any] | None = None,
    top: int = 10,
    incidents: Sequence[Mapping[str, Any]] = (),
) -> str:
    """Return the markdown report: the current incident's ranked root causes with their
    trajectories, the candidates it cannot tell apart, and every incident (report JSON form)."""
    lines = ["# Root-cause analysis", ""]
    if iteration is not None:
        lines += [f"Iteration j = {iteration.get('j')}: subgraph of {len(iteration.get('subgraph', []))} "
                  f"members, watchlist of {len(iteration.get('watchlist', []))}"
                  + (f", last alert on `{iteration['alert']}`" if iteration.get("alert") else "") + ".", ""]
    now = next((inc for inc in incidents if inc.get("current")), None)
    if now is not None and len(incidents) > 1:
        lines += [f"Root causes of incident {now['id']} ({_status(now)}, {len(now['members'])} symptomatic "
                  f"members); {len(incidents) - 1} other incident(s) below.", ""]
    if not root_causes:
        lines.append("No root cause found yet.")
    else:
        lines += ["| rank | root cause | score | trajectory (first symptom → cause) |", "|---|---|---|---|"]
        for i, rc in enumerate(root_causes[:top], 1):
            traj = " → ".join(f"`{m}`" for m in rc.get("trajectory") or [rc["member"]])
            lines.append(f"| {i} | **`{rc['member']}`** | {float(rc.get('score', 0.0)):.3f} | {traj} |")
        if len(root_causes) > top:
            lines += ["", f"… and {len(root_causes) - top} more."]
        lines += (_alike_notes(root_causes[:top]) + _awaited_notes(root_causes[:top])
                  + _blocked_notes(root_causes[:top]) + _implied_notes(root_causes[:top])
                  + _host_notes(root_causes[:top]))
    if len(incidents) > 1:
        lines += ["", "## Incidents (times UTC)", "",
                  "| incident | symptomatic members | from | to | top root cause |", "|---|---|---|---|---|"]
        for inc in incidents:
            name = f"**{inc['id']} (current)**" if inc.get("current") else str(inc["id"])
            causes = inc.get("root_causes") or []
            first = f"`{causes[0]['member']}`" if causes else "–"
            until = "ongoing" if inc.get("ongoing") else _clock(inc["end"])
            lines.append(f"| {name} | {len(inc['members'])} | {_clock(inc['start'])} | {until} | {first} |")
    return "\n".join(lines)


def _status(inc: Mapping[str, Any]) -> str:
    return f"since {_clock(inc['start'])} UTC, ongoing" if inc.get("ongoing") else (
        f"{_clock(inc['start'])}–{_clock(inc['end'])} UTC, over")


def _clock(t: float) -> str:
    return time.strftime("%H:%M:%S", time.gmtime(float(t)))


def _alike_notes(root_causes: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per group of candidates the diagnosis cannot tell apart (same process, same own
    changes): the fault is in that process, not necessarily in the first of them."""
    out, seen = [], set()
    for rc in root_causes:
        ev = rc.get("evidence") or {}
        alike = ev.get("indistinguishable_from") or []
        group = tuple(sorted({rc["member"], *alike}))
        if not alike or group in seen:
            continue
        seen.add(group)
        names = ", ".join(f"`{m}`" for m in group)
        out.append(f"{names} run in `{ev.get('process', '?')}` and changed alike: the symptoms cannot "
                   "tell them apart (the fault is in that process).")
    return ["", *out] if out else []


def _awaited_notes(root_causes: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per candidate told from its process's other nodes by clients waiting on it."""
    out = []
    for rc in root_causes:
        ev = rc.get("evidence") or {}
        if ev.get("awaited_by"):
            clients = ", ".join(f"`{m}`" for m in ev["awaited_by"])
            out.append(f"`{rc['member']}` runs in `{ev.get('process', '?')}` with other candidates; "
                       f"{clients} waited on it as its symptoms began, which tells it from them.")
    return ["", *out] if out else []


def _blocked_notes(root_causes: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per stalled process whose likeliest blocker is told apart from its fellows."""
    out, seen = [], set()
    for rc in root_causes:  # best first: the first of a process is its likeliest
        ev = rc.get("evidence") or {}
        p = ev.get("process")
        if ev.get("blocked") is None or p in seen:
            continue
        seen.add(p)
        if not ev.get("indistinguishable_from"):
            out.append(f"`{rc['member']}` is the likeliest of `{p}`'s stalled nodes to have blocked its "
                       f"executor ({float(ev['blocked']):.0%}): its next message was due as they stopped.")
    return ["", *out] if out else []


def _implied_notes(root_causes: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per candidate with no symptom of its own: what made it a suspect."""
    out = []
    for rc in root_causes:
        ev = rc.get("evidence") or {}
        by = ", ".join(f"`{m}`" for m in ev.get("symptoms") or [])
        if ev.get("implied") == "executor":
            out.append(f"`{rc['member']}` shows nothing of its own; the executor it shares with {by} "
                       "stopped, and a callback of any node it runs may have blocked it.")
        elif ev.get("implied") == "server":
            out.append(f"`{rc['member']}` shows nothing of its own; it serves {by}, whose symptoms "
                       "their inputs do not explain: it may be what they wait for.")
    return ["", *out] if out else []


def _host_notes(root_causes: Sequence[Mapping[str, Any]]) -> list[str]:
    """One line per host ranked as a cause: whose symptoms it explains."""
    out = []
    for rc in root_causes:
        ev = rc.get("evidence") or {}
        if ev.get("host"):
            nodes = ", ".join(f"`{n}`" for n in ev.get("explains_nodes") or [])
            out.append(f"`{rc['member']}` went wrong ({', '.join(ev.get('plugins') or [])}) before anything "
                       f"else on it, and none of its processes is to blame: it explains {nodes}.")
    return ["", *out] if out else []


def log_report(rec: rr.RecordingStream, markdown: str) -> None:
    """Log the report at ``/rca/report`` (TextDocument, markdown) at the current time."""
    rec.log(paths.RCA_REPORT, rr.TextDocument(markdown, media_type=rr.MediaType.MARKDOWN))


def _log_overlay(rec: rr.RecordingStream, path: str, a: dict[str, list]) -> None:
    if not a["ids"]:
        rec.log(path, rr.Clear(recursive=False))
        return
    rec.log(path, *graph_archetypes(a, show_labels=False))


def log_rca(
    rec: rr.RecordingStream,
    G: nx.MultiDiGraph,
    layout: Layout | None,
    iteration: Mapping[str, Any],
    root_causes: Sequence[Mapping[str, Any]] = (),
    gone: Sequence[str] = (),
    status: Mapping[str, str] | None = None,
    incidents: Sequence[Mapping[str, Any]] = (),
    system: Mapping[str, list] | None = None,
    drawn: DrawnGraph | None = None,
    hosts: DrawnHosts | None = None,
) -> Layout:
    """Log RCA iteration ``j`` on both timelines (``time`` = its ``t``, ``rca_iteration`` = ``j``).

    The system graph is logged on the ``rca_iteration`` timeline (so it shows when stepping
    through the iterations; on ``time`` it is `Recorder.system`'s), then the overlays
    ``/rca/subgraph`` (G_j, W_j) and ``/rca/trajectory`` (top trajectory) at the same positions,
    and the report. Returns the (possibly extended) layout.

    Parameters
    ----------
    iteration : mapping
        ``{"j", "t", "subgraph": [...], "watchlist": [...], "edges": [[u, v], ...], "alert": member}``.
    root_causes : sequence of mapping
        Ranked best first, ``{"member", "score", "trajectory": [...]}`` (report JSON form).
    incidents : sequence of mapping
        Every incident (report JSON form), listed in the report.
    system : mapping, optional
        The ``/system`` arrays of ``G`` with ``layout``, ``gone`` and ``status`` (`system_view`),
        when the caller has them: not computed again.
    drawn : DrawnGraph, optional
        What the ``rca_iteration`` timeline shows of ``/system`` so far (iterations logged in
        order): only what changed since is logged. Without it the graph is logged in full.
    hosts : DrawnHosts, optional
        The same for each computer's ``/hosts/<host>`` (several computers): the per-host tabs
        show each iteration's graph too. Without it they are left to the ``time`` timeline.
    """
    rec.set_time(paths.RCA_ITERATION, sequence=int(iteration["j"]))
    try:
        if system is None or layout is None:
            layout, system = system_view(G, layout, gone, status)
        # On `time` the graph is Recorder.system's: this copy is for stepping through iterations.
        rec.disable_timeline(paths.TIME)
        (drawn or DrawnGraph()).log(rec, system, layout)
        if hosts is not None:
            hosts.log(rec, G, system)
        rec.set_time(paths.TIME, timestamp=float(iteration["t"]))
        _log_overlay(rec, paths.RCA_SUBGRAPH, subgraph_arrays(iteration, layout))
        _log_overlay(rec, paths.RCA_TRAJECTORY, trajectory_arrays(root_causes, layout))
        log_report(rec, report_markdown(root_causes, iteration, incidents=incidents))
    finally:
        # Later data (metrics, /system updates) must not inherit this iteration number.
        rec.disable_timeline(paths.RCA_ITERATION)
        rec.set_time(paths.TIME, timestamp=float(iteration["t"]))
    return layout
