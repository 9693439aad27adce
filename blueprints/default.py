"""The default Rerun layout of a STREAM recording, built in code and sent with the recording.

Change it by editing `build_blueprint` (or passing your own ``rrb.Blueprint`` to
``stream_viz.viz.recorder.Recorder(blueprint=...)``), or save it as an ``.rbl`` with
`save_blueprint`, rearrange it in the viewer and save it from there (see docs/viz.md).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
from pathlib import Path

import rerun.blueprint as rrb

from stream_viz.model.ids import name_of
from stream_viz.viz import paths

APP_ID = "stream_viz"


def metric_views(watched: Iterable[str]) -> list[rrb.TimeSeriesView]:
    """Return one time-series view per watched member (all its θ series and its alert markers)."""
    views = []
    for member in dict.fromkeys(watched):
        views.append(rrb.TimeSeriesView(origin=paths.metrics_path(member), name=f"θ {member}"))
    return views


def diagnosis_view(diagnosis: Mapping[str, Sequence[str]]) -> rrb.Container:
    """Return the Diagnosis tab: the members' health lanes above one θ plot per member.

    ``diagnosis`` maps a member to the members whose θ and alert markers its plot shows (a node:
    itself and its process; `stream_viz.viz.focus.diagnosis_members`), in the order shown.
    """
    lanes = rrb.StateTimelineView(origin=paths.HEALTH, name="Health",
                                  contents=[paths.health_path(m) for m in diagnosis])
    # Small plots: a legend listing every θ attribute would cover them (the title names the member,
    # by its last name part: a namespaced name is cut off in a plot this narrow).
    plots = [rrb.TimeSeriesView(origin=paths.METRICS, name=f"θ {short_name(m)}",
                                contents=[f"{paths.metrics_path(x)}/**" for x in shown],
                                plot_legend=rrb.PlotLegend(visible=False))
             for m, shown in diagnosis.items()]
    return rrb.Vertical(lanes, rrb.Grid(*plots, grid_columns=3), row_shares=[2, 3], name="Diagnosis")


def short_name(member: str) -> str:
    """Return the last part of a member's name (``node:/amr1/amcl`` -> ``amcl``)."""
    return name_of(member).rstrip("/").rsplit("/", 1)[-1] or name_of(member)


def metrics_tabs(watched: Iterable[str] = (), diagnosis: Mapping[str, Sequence[str]] | None = None,
                 hosts: bool = False) -> rrb.Tabs:
    """Return the metrics panel: the diagnosis first (when there is one), every member's health,
    then the watched members' plots, or one plot per kind (topics, processes; ``hosts``: the
    computers' own CPU and memory too)."""
    tabs: list[rrb.View | rrb.Container] = [diagnosis_view(diagnosis)] if diagnosis else []
    tabs.append(rrb.StateTimelineView(origin=paths.HEALTH, name="Health"))
    tabs += metric_views(watched) or [
        rrb.TimeSeriesView(origin=f"{paths.METRICS}/topic", name="Topics"),
        rrb.TimeSeriesView(origin=f"{paths.METRICS}/process", name="Processes"),
        *([rrb.TimeSeriesView(origin=f"{paths.METRICS}/host", name="Hosts")] if hosts else []),
    ]
    # The eye lands on the first tab: the diagnosis, else the per-kind plots (health is sparse).
    return rrb.Tabs(*tabs, active_tab=0 if diagnosis else 1, name="Metrics")


def build_blueprint(
    watched: Iterable[str] = (),
    timeline: str = paths.TIME,
    paused: bool | None = None,
    collapse_panels: bool = False,
    diagnosis: Mapping[str, Sequence[str]] | None = None,
    hosts: Sequence[str] = (),
    condensed: bool = False,
) -> rrb.Blueprint:
    """Return the default layout.

    Top, full width: the system graph with the RCA overlays (one GraphView of ``/system``,
    ``/rca/subgraph`` and ``/rca/trajectory``); with several computers, beside it a tab per host
    (its part of the graph, ``/hosts/<host>``); a large system's condensed graph (``/condensed``)
    in a tab before it, shown first. Below: metrics (`metrics_tabs`), report / process
    tree, alert log.

    Parameters
    ----------
    watched : iterable of str
        Members (ids) given their own metric plot; without any, one plot per kind (topics, processes).
    diagnosis : mapping, optional
        The members of the current diagnosis (`diagnosis_view`): their tab comes first.
    timeline : str
        The timeline the time panel shows: ``time`` (live, default) or ``rca_iteration``
        (step through the RCA iterations; metrics are on ``time`` only).
    paused : bool, optional
        Start paused; default: paused on ``rca_iteration``, following live on ``time``.
    collapse_panels : bool
        Hide the side and time panels (for screenshots).
    hosts : sequence of str
        The computers of the model (several): a graph tab and a metrics tab for them.
    condensed : bool
        A tab with the condensed system graph (`stream_viz.viz.condensed`), first and active:
        at 1,000 nodes the full graph's labels cannot be read without zooming.
    """
    if paused is None:
        paused = timeline == paths.RCA_ITERATION
    graph = rrb.GraphView(
        origin="/",
        # group boxes and overlays under the labels
        contents=[*(f"{r}/**" for r in paths.GROUP_ROOTS), paths.RCA_SUBGRAPH, paths.RCA_TRAJECTORY,
                  paths.SYSTEM],
        name="System graph + RCA overlays",
    )
    tabs: list[rrb.View] = [graph, *(rrb.GraphView(origin=paths.host_graph_path(h), name=f"Host {h}")
                                     for h in hosts)]
    if condensed:
        tabs.insert(0, rrb.GraphView(origin=paths.CONDENSED, name="Condensed system graph"))
    if len(tabs) > 1:
        graph = rrb.Tabs(*tabs, active_tab=0, name="System")
    bottom = rrb.Horizontal(
        metrics_tabs(watched, diagnosis, hosts=bool(hosts)),
        rrb.Tabs(
            rrb.TextDocumentView(origin=paths.RCA_REPORT, name="Root causes"),
            rrb.GraphView(origin=paths.PROCESS_TREE, name="Process tree"),
        ),
        rrb.TextLogView(origin="/", contents=[paths.ALERTS, paths.CHANGES], name="Alerts"),
        column_shares=[3, 2, 2] if diagnosis else [2, 2, 2],  # a diagnosis: plots side by side
    )
    return rrb.Blueprint(
        rrb.Vertical(graph, bottom, row_shares=[3, 2]),
        # Collapsed: the play controls and the time stay, the streams tree is one click away and
        # its third of the height goes to the metrics.
        rrb.TimePanel(timeline=timeline, play_state="paused" if paused else "following", state="collapsed"),
        # The graph needs the width; the blueprint and selection panels are one click away.
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        collapse_panels=collapse_panels,
    )


def save_blueprint(path: str | Path, app_id: str = APP_ID, **kwargs) -> Path:
    """Write `build_blueprint` (``kwargs`` passed on) as an ``.rbl`` for ``app_id``; return the path.

    Open it with ``rerun recording.rrd layout.rbl``; the app id must match the recording's.
    """
    path = Path(path)
    build_blueprint(**kwargs).save(app_id, str(path))
    return path
