"""The Rerun side of a run: one own ``RecordingStream`` going to a viewer and/or an ``.rrd`` file.

Viewer modes: ``spawn`` (native viewer, needs a display), ``serve`` (gRPC server + web viewer, on
loopback unless ``bind`` says otherwise; `stream_viz.viz.serve`), ``none``, or the gRPC URL of a
running viewer (``rerun+http://host:port/proxy``). With
``save`` the same stream is also written to a file (sinks are teed), default blueprint included.
A long run is saved in parts (``run.rrd``, ``run_1.rrd``, …; one recording id, so the viewer
merges them): Rerun keeps an index entry for every chunk written to a file until it is closed,
so one file per run would grow the monitor's memory for as long as it runs.
"""

from __future__ import annotations

import os
import sys
import uuid
from collections.abc import Callable, Collection, Iterable, Mapping, Sequence
from pathlib import Path
from typing import Any

import networkx as nx
import rerun as rr
import rerun.blueprint as rrb

from stream_viz.errors import ConfigError, OutputError, StreamVizError
from stream_viz.output import check_writable
from stream_viz.records import SEVERITY_RANK, Alert, Event
from stream_viz.viz import paths, style
from stream_viz.viz.alerts import log_alerts
from stream_viz.viz.changes import log_changes
from stream_viz.viz.condensed import CONDENSE_ABOVE, DrawnCondensed, is_condensed
from stream_viz.viz.focus import diagnosis_members
from stream_viz.viz.health import Change, FileEvents, HealthLanes, log_health
from stream_viz.viz.hosts_view import DrawnHosts
from stream_viz.viz.layout import Layout, settle
from stream_viz.viz.metrics import MetricBatch, log_metrics
from stream_viz.viz.process_tree import log_process_tree
from stream_viz.viz.rca import log_rca, log_report
from stream_viz.viz.screenshot import rerun_executable
from stream_viz.viz.serve import DEFAULT_BIND, DEFAULT_GRPC_PORT, DEFAULT_WEB_PORT, WebViewerServer
from stream_viz.viz.system import DrawnGraph, drawn_status, signatures, system_view, with_gone

VIEWER_MODES = ("spawn", "serve", "none")
GRPC_SCHEMES = ("rerun://", "rerun+http://", "rerun+https://")
TELEMETRY_ENV = "STREAM_VIZ_RERUN_TELEMETRY"  # set to 1 to allow Rerun's usage analytics


def disable_rerun_telemetry(enabled: bool | None = None) -> bool:
    """Turn Rerun's usage analytics and OpenTelemetry tracing off for this process and its children.

    Rerun's analytics skip any process whose environment has ``CI`` set (and are forced on by
    ``FORCE_RERUN_ANALYTICS=1``); its tracing runs only with ``TELEMETRY_ENABLED=true``. Both are
    inherited by a spawned viewer. ``enabled`` (default: env ``STREAM_VIZ_RERUN_TELEMETRY=1``)
    leaves Rerun's own settings alone. Returns whether telemetry was left enabled.
    """
    if enabled is None:
        enabled = os.environ.get(TELEMETRY_ENV, "").strip().lower() in ("1", "true", "yes", "on")
    if not enabled:
        os.environ.setdefault("CI", "1")
        os.environ.setdefault("TELEMETRY_ENABLED", "false")
    return enabled


def _check_sinks(viewer: str, save: str | Path | None) -> Path | None:
    """Check a `Recorder`'s viewer mode and recording path before anything is opened; return the path.

    Raises `ConfigError` for an unknown viewer mode, `OutputError` for a recording that cannot be
    written or a ``spawn`` that cannot open a window.
    """
    if viewer not in VIEWER_MODES and not viewer.startswith(GRPC_SCHEMES):
        raise ConfigError(
            f"--viewer {viewer!r}: expected spawn, serve, none or a gRPC URL such as "
            f"rerun+http://127.0.0.1:{DEFAULT_GRPC_PORT}/proxy")
    path = check_writable(save, "recording") if save is not None else None
    if viewer == "spawn":
        if not has_display():
            raise OutputError("--viewer spawn needs a display (DISPLAY/WAYLAND_DISPLAY unset); "
                              "use --viewer serve and open the printed URL, or --save FILE.rrd")
        if rerun_executable() is None:
            raise OutputError("--viewer spawn: the 'rerun' viewer executable is not on PATH")
    return path


def _default_layout() -> Callable[..., rrb.Blueprint]:
    from stream_viz_blueprints.default import build_blueprint

    return build_blueprint


def part_path(path: Path, n: int) -> Path:
    """Return the path of part ``n`` of a recording saved at ``path`` (part 0 is ``path`` itself)."""
    return path if n == 0 else path.with_name(f"{path.stem}_{n}{path.suffix}")


def has_display() -> bool:
    """Return True if a native window can be opened (X11/Wayland on Linux; always elsewhere)."""
    if not sys.platform.startswith("linux"):
        return True
    return bool(os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY"))


def _stderr(msg: str) -> None:
    print(msg, file=sys.stderr, flush=True)


class Tee:
    """The logging calls the ``log_*`` functions make, sent to every stream (viewer, file)."""

    def __init__(self, streams: Sequence[rr.RecordingStream]) -> None:
        self.streams = list(streams)

    def _each(self, method: str, *args: Any, **kwargs: Any) -> None:
        for stream in self.streams:
            getattr(stream, method)(*args, **kwargs)

    def log(self, *args: Any, **kwargs: Any) -> None:
        self._each("log", *args, **kwargs)

    def send_columns(self, *args: Any, **kwargs: Any) -> None:
        self._each("send_columns", *args, **kwargs)

    def set_time(self, *args: Any, **kwargs: Any) -> None:
        self._each("set_time", *args, **kwargs)

    def disable_timeline(self, *args: Any, **kwargs: Any) -> None:
        self._each("disable_timeline", *args, **kwargs)


class Recorder:
    """A recording stream of a STREAM run and what it has drawn so far.

    Parameters
    ----------
    app_id : str
        Rerun application id (a saved ``.rbl`` must use the same).
    viewer : str
        ``spawn``, ``serve``, ``none`` or a gRPC URL (``rerun+http://127.0.0.1:9876/proxy``).
    save : Path, optional
        Also write the recording (with its default blueprint) to this ``.rrd``.
    memory_limit : str
        Memory limit of the spawned viewer / the served gRPC buffer.
    web_port, grpc_port : int, optional
        Ports of ``serve`` (web viewer, gRPC) and ``spawn`` (gRPC).
    bind : str
        Address ``serve`` listens on, page and data alike: ``127.0.0.1`` (this machine only),
        ``0.0.0.0`` (every interface) or one interface's address.
    blueprint : rrb.Blueprint or callable, optional
        Default layout: a fixed ``rrb.Blueprint``, or a function ``(diagnosis=…) -> rrb.Blueprint``
        called again (and its layout sent again) when the diagnosis's members change;
        `stream_viz_blueprints.default.build_blueprint` if not given.
    telemetry : bool, optional
        Allow Rerun's usage analytics (default off; see `disable_rerun_telemetry`).
    part_s : float
        Start a new file part every this many seconds of the ``time`` timeline (0: one file).
    announce : callable
        Where to tell the user the viewer URL (default: stderr).
    grouping : str
        Groups of the system graph drawn as boxes: ``namespace`` (default), ``process`` or ``none``.
    condensed : str
        The condensed system graph ``/condensed`` (`stream_viz.viz.condensed`) and its tab, shown
        first: ``auto`` once the graph has more than ``condense_above`` members, ``on``, ``off``.
    file_events_s : float
        Seconds of ``time`` the file's alerts and health-lane changes are gathered for before
        they are written (the viewer gets them at once): every write of an entity is a chunk
        with a fixed cost in the ``.rrd`` (its schema, an index entry in the footer), and an
        alerting member gets a marker and a lane change every few seconds. 0: at once.
    """

    def __init__(
        self,
        app_id: str = "stream_viz",
        viewer: str = "none",
        save: str | Path | None = None,
        memory_limit: str = "512MiB",
        web_port: int | None = None,
        grpc_port: int | None = None,
        blueprint: rrb.Blueprint | Callable[..., rrb.Blueprint] | None = None,
        telemetry: bool | None = None,
        part_s: float = 0.0,
        announce: Callable[[str], None] = _stderr,
        grouping: str = "namespace",
        bind: str = DEFAULT_BIND,
        file_events_s: float = 60.0,
        condensed: str = "auto",
        condense_above: int = CONDENSE_ABOVE,
    ) -> None:
        self.save = _check_sinks(viewer, save)  # before anything is opened (and monitoring starts)
        disable_rerun_telemetry(telemetry)
        self.viewer, self.app_id, self.url = viewer, app_id, None
        if blueprint is None:
            blueprint = _default_layout()
        self._layout = None if isinstance(blueprint, rrb.Blueprint) else blueprint
        self.blueprint = blueprint if self._layout is None else self._layout()
        self.diagnosis: dict[str, list[str]] = {}  # what the layout shows first (`focus`)
        self.health = HealthLanes()
        self.parts: list[Path] = [self.save] if self.save is not None else []
        self.part_s = part_s if self.save is not None else 0.0
        self._part_t0: float | None = None
        self._last_rca: tuple[Any, ...] | None = None  # shown again at the top of a new part
        self._last_report: tuple[str, float | None] | None = None
        self._report_shown: str | None = None  # the text `report` last logged, if nothing since
        self.layout: Layout | None = None
        self.grouping = grouping
        self.server: WebViewerServer | None = None
        self.status: dict[str, str] = {}
        self._system_sig: Any = None
        # The /system arrays last drawn and what they were drawn from: (G, gone, colouring status).
        self._drawn: tuple[nx.MultiDiGraph, frozenset[str], frozenset, dict[str, list]] | None = None
        self._tree_sig: Any = None
        # (structure, the graph) of the last `system` call given a structure number
        self._structure: tuple[int, nx.MultiDiGraph] | None = None
        # What each timeline shows of /system: the next log sends only what changed.
        self._drawn_time, self._drawn_rca = DrawnGraph(), DrawnGraph()
        self._drawn_hosts = DrawnHosts()  # /hosts/<host>: each computer's part of /system
        self._drawn_hosts_rca = DrawnHosts()  # the same on the rca_iteration timeline
        is_condensed(condensed, 0, condense_above)  # an unknown mode fails here, before the run
        self.condensed, self.condense_above = condensed, condense_above
        self.condensed_on = False  # once on, stays on: a tab that comes and goes would confuse
        self._condensed = DrawnCondensed()  # /condensed, on `time`
        self._causes: Sequence[Mapping[str, Any]] = ()  # the last root causes (the condensed focus)
        self._t: float | None = None  # the last `time` of `system`
        self._gone: frozenset[str] = frozenset()
        self.hosts: list[str] = []  # the computers the layout has a tab for (several only)
        self._rca_j: int | None = None  # the last iteration on the rca_iteration timeline
        self.file_events_s = file_events_s
        self._events = FileEvents()  # the file's alerts and lane changes not written yet
        self._closed = False
        self.enabled = viewer != "none" or self.save is not None
        self._open(memory_limit, web_port, grpc_port, bind)
        if viewer == "serve":
            announce(f"Rerun web viewer: {self.url}")
            if self.server is not None and not self.server.loopback:
                announce(f"  served on {bind}: from another machine, put this machine's address "
                         "in place of 127.0.0.1, twice (the page and its ?url=)")
        elif viewer == "spawn":
            announce(f"Rerun viewer spawned, streaming to {self.url}")

    def _open(self, memory_limit: str, web_port: int | None, grpc_port: int | None, bind: str) -> None:
        """Open the streams: one to the viewer, one to the file, both of one recording id.

        The file's sink is swapped for the next part without touching the viewer's connection (a
        swap flushes the old sinks, which blocks for seconds on a viewer that went away).
        """
        rid = str(uuid.uuid4())
        self._live = self._stream(rid) if self.viewer != "none" else None
        self._file = self._stream(rid) if self.save is not None else None
        # Nothing to send to: no stream at all (a disabled one buffers nothing, but warns on
        # every flush and disconnect at exit: noise on a headless monitor's terminal).
        self.rec = Tee([s for s in (self._live, self._file) if s is not None])
        # One sink alone, for the metrics (the file takes them in longer batches than the viewer).
        self._only = {"live": Tee([self._live] if self._live is not None else []),
                      "file": Tee([self._file] if self._file is not None else [])}
        try:
            if self._live is not None:
                self.url = self._connect(self._live, memory_limit, web_port, grpc_port, bind)
            if self._file is not None:
                self._file.set_sinks(rr.FileSink(str(self.save)), default_blueprint=self.blueprint)
        except (RuntimeError, OSError, ValueError) as e:
            if self.server is not None:
                self.server.stop()
            raise OutputError(f"--viewer {self.viewer}: could not start the Rerun sink: {e}") from e

    def _connect(self, live: rr.RecordingStream, memory_limit: str, web_port: int | None,
                 grpc_port: int | None, bind: str) -> str:
        """Point the viewer's stream at its viewer; return the URL to tell the user."""
        bp = self.blueprint
        if self.viewer == "spawn":
            port = grpc_port or DEFAULT_GRPC_PORT
            live.spawn(port=port, connect=False, memory_limit=memory_limit, hide_welcome_screen=True)
            url = f"rerun+http://127.0.0.1:{port}/proxy"
            live.set_sinks(rr.GrpcSink(url), default_blueprint=bp)
            return url
        if self.viewer == "serve":
            self.server = WebViewerServer(bind, web_port or DEFAULT_WEB_PORT,
                                          grpc_port or DEFAULT_GRPC_PORT, memory_limit)
            live.set_sinks(rr.GrpcSink(self.server.grpc_url), default_blueprint=bp)
            return self.server.url
        live.set_sinks(rr.GrpcSink(self.viewer), default_blueprint=bp)
        return self.viewer

    def _stream(self, recording_id: str) -> rr.RecordingStream:
        stream = rr.RecordingStream(self.app_id, recording_id=recording_id)
        stream.set_log_time_enabled(False)  # our own `time` timeline is the clock
        return stream

    # -- time -----------------------------------------------------------------------------------
    def set_time(self, t: float) -> None:
        """Set the ``time`` timeline (wall clock seconds) for what is logged next."""
        self.rec.set_time(paths.TIME, timestamp=float(t))

    # -- file parts -----------------------------------------------------------------------------
    def part_due(self, t: float) -> bool:
        """Return True if the current file part spans ``part_s`` seconds at time ``t``."""
        if not self.part_s:
            return False
        if self._part_t0 is None:
            self._part_t0 = t
        return t - self._part_t0 >= self.part_s

    def next_part(self, t: float, G: nx.MultiDiGraph | None = None) -> Path | None:
        """Close the current file part and go on in the next one; return its path.

        The new part gets the default blueprint, the system graph ``G`` and the last diagnosis
        again, so it opens on its own too. A part that cannot be opened is reported and the
        current file goes on (nothing is lost, only the memory bound): returns None.
        """
        if self.save is None or self._file is None:
            return None
        path = part_path(self.save, len(self.parts))
        self.send_events()  # the events of a part end in that part
        if not self._switch_file(path):
            return None
        self.parts.append(path)
        self._part_t0 = t
        self._replay(t, G)
        return path

    def _switch_file(self, path: Path) -> bool:
        """Point the file's stream at ``path``; False (reported, no more parts) if it cannot be opened."""
        try:
            self._file.flush(timeout_sec=5.0)
            sink = rr.FileSink(str(check_writable(path, "recording")))
            self._file.set_sinks(sink, default_blueprint=self.blueprint)
        except (StreamVizError, RuntimeError, OSError, ValueError) as e:
            _stderr(f"stream-viz: recording goes on in {self.parts[-1]}; cannot start part {path}: {e}")
            self.part_s = 0.0
            return False
        return True

    def _replay(self, t: float, G: nx.MultiDiGraph | None) -> None:
        """Log again what a new part must show to open on its own: the system, the last diagnosis."""
        style.forget_styled(self.rec)  # static styles are not carried over to a new sink
        style.forget_styled(self._only["file"])
        self._drawn_time.forget()  # nor is anything drawn before
        self._drawn_hosts.forget()
        self._drawn_rca.forget()
        self._drawn_hosts_rca.forget()
        self._condensed.forget()
        self._report_shown = None
        lanes = {m: [(t, s)] for m, s in self.health.state.items()}
        if lanes:
            log_health(self._only["file"], lanes)
        if G is not None:
            self.system(G, t, force=True)
        if self._last_rca is not None:
            self.rca(*self._last_rca)
        if self._last_report is not None:
            self.report(*self._last_report)

    # -- entities -------------------------------------------------------------------------------
    def system(self, G: nx.MultiDiGraph, t: float | None = None, gone: Collection[str] = (),
               force: bool = False, structure: int | None = None) -> bool:
        """Log ``/system`` (and ``/process_tree``) if the graph, gone set or alert status changed,
        and ``/condensed`` (large systems) if that or the diagnosis changed.

        ``structure``: a number that changes whenever ``G``'s members or edges do
        (`stream_viz.model.shadow.Shadow.structure`); while it is the same, ``G``'s structure is
        not read again. Returns True if ``/system`` was logged.
        """
        if t is not None:
            self.set_time(t)
            self._t = t
        logged = self._system(G, t, gone, force, structure)
        self._condense(G)
        return logged

    def _condense(self, G: nx.MultiDiGraph) -> None:
        """Log ``/condensed`` when it is on (or turns on now: the layout gets its tab) and what it
        is drawn from changed: the system's signature, the alerts, the root causes."""
        if not self.condensed_on:
            members = len(self._drawn[3]["ids"]) if self._drawn is not None else 0
            if not is_condensed(self.condensed, members, self.condense_above):
                return
            self.condensed_on = True
            self._send_layout()
        causes = tuple((rc["member"], tuple(rc.get("trajectory") or ())) for rc in self._causes[:3])
        key = (self._system_sig, frozenset(self.status.items()), causes)
        structure = self._structure[0] if self._structure is not None and self._structure[1] is G else None
        self._condensed.log(self.rec, G, self.grouping, self._gone, self.status, self._causes, key,
                            structure)

    def _system(self, G: nx.MultiDiGraph, t: float | None, gone: Collection[str], force: bool,
                structure: int | None = None) -> bool:
        gone_all = frozenset(gone) | {m for m, a in G._node.items() if a.get("gone")}  # dicts: every sample
        self._gone = gone_all
        if t is not None:
            self._lanes(self.health.set_gone(t, gone_all), t)
        colouring = drawn_status(self.status, gone_all)
        if structure is None:
            self._structure = None
            sig, tree_sig = signatures(G, gone_all, colouring)
        else:  # the number stands for the members, edges and labels: nothing of them kept or read
            self._structure = (structure, G)
            sig, tree_sig = (structure, gone_all, colouring), (structure, gone_all)
        if tree_sig != self._tree_sig or force:
            log_process_tree(self.rec, G)
            self._tree_sig = tree_sig
        settled = self.layout is not None and self.layout.pending is None
        unchanged = sig == self._system_sig and self._drawn is not None
        if unchanged and settled and not force:
            self._drawn = (G, gone_all, colouring, self._drawn[3])
            return False  # nothing drawn changed and no new structure is waiting to settle
        # Laid out again only once a changed structure has settled (`settle`, once per sample).
        layout = settle(with_gone(G, gone_all), self.layout, grouping=self.grouping)
        if unchanged and layout is self.layout and not force:
            self._drawn = (G, gone_all, colouring, self._drawn[3])
            return False
        self.layout, arrays = system_view(G, layout, gone_all, self.status)
        self._drawn_time.log(self.rec, arrays, self.layout)
        hosts = self._drawn_hosts.log(self.rec, G, arrays)
        if hosts != self.hosts:
            self.hosts = hosts
            self._send_layout()
        self._system_sig, self._drawn = sig, (G, gone_all, colouring, arrays)
        return True

    @property
    def has_live(self) -> bool:
        """True if there is a viewer (not only a file)."""
        return self._live is not None

    @property
    def has_file(self) -> bool:
        """True if the recording is written to a file."""
        return self._file is not None

    def metrics(self, batch: Iterable[Any] | MetricBatch, to: str = "all") -> int:
        """Send a batch of ``(t, G)`` samples' θ (processes, topics); return the number of rows.

        ``to``: ``all`` (viewer and file), ``live`` (the viewer only: the batch's rows not sent
        to it yet) or ``file`` (the file only).
        """
        if to == "all":
            return log_metrics(self.rec, batch)
        return log_metrics(self._only[to], batch, unsent=to == "live")

    def alerts(self, alerts: Sequence[Alert]) -> int:
        """Log alerts (text log + markers); alerted members get their severity's colour in ``/system``."""
        for a in sorted(alerts, key=lambda a: a.t):
            if SEVERITY_RANK.get(a.severity, -1) >= SEVERITY_RANK["warn"]:
                self.status[a.member] = a.severity
        alerts = list(alerts)
        lanes = self.health.alerts(alerts)
        if self._file is None or self.file_events_s <= 0:
            log_health(self.rec, lanes)
            return log_alerts(self.rec, alerts)
        if self._live is not None:
            log_health(self._only["live"], lanes)
            log_alerts(self._only["live"], alerts)
        self._events.add(alerts, lanes)
        self._events_due(max((a.t for a in alerts), default=None))
        return len(alerts)

    def _lanes(self, changes: dict[str, list[Change]], t: float) -> None:
        """Log health-lane changes: to the viewer at once, to the file with the alerts."""
        if self._file is None or self.file_events_s <= 0:
            log_health(self.rec, changes)
            return
        if self._live is not None:
            log_health(self._only["live"], changes)
        self._events.add((), changes)
        self._events_due(t)

    def _events_due(self, t: float | None) -> None:
        first = self._events.first_t
        if t is not None and first is not None and t - first >= self.file_events_s:
            self.send_events()

    def send_events(self) -> int:
        """Write the file's pending alerts and lane changes (one chunk per entity); return #alerts."""
        alerts, lanes = self._events.take()
        if lanes:
            log_health(self._only["file"], lanes)
        return log_alerts(self._only["file"], alerts) if alerts else 0

    def changes(self, events: Sequence[Event]) -> int:
        """Log the changes of configuration among ``events`` (``/changes``)."""
        return log_changes(self.rec, events)

    def rca(self, G: nx.MultiDiGraph, iteration: Mapping[str, Any],
            root_causes: Sequence[Mapping[str, Any]] = (), gone: Collection[str] = (),
            incidents: Sequence[Mapping[str, Any]] = ()) -> None:
        """Log one RCA iteration (overlays + report, with the incidents) on both timelines.

        ``/system`` is drawn with the arrays of the last `system` call when ``G`` is that call's
        graph, unchanged since (the caller calls `system` after changing ``G``), and no alert
        changed a colour since.
        """
        self._last_rca, self._last_report = (G, iteration, root_causes, gone, incidents), None
        self._report_shown = None  # log_rca logs its own report
        gone_all = frozenset(gone) | {m for m, a in G._node.items() if a.get("gone")}  # dicts: every sample
        drawn = self._drawn
        same = (drawn is not None and drawn[0] is G and drawn[1] == gone_all
                and drawn[2] == drawn_status(self.status, gone_all))
        j = int(iteration["j"])
        if self._rca_j is not None and j <= self._rca_j:
            self._drawn_rca.forget()  # latest-at before j is not what was logged last: log it all
            self._drawn_hosts_rca.forget()
        self._rca_j = j
        layout = log_rca(self.rec, G, self.layout, iteration, root_causes, gone=sorted(gone_all),
                         status=self.status, incidents=incidents, system=drawn[3] if same else None,
                         drawn=self._drawn_rca, hosts=self._drawn_hosts_rca)
        if layout is not self.layout:
            self.layout, self._drawn = layout, None  # the arrays drawn before have other places
        self._causes = root_causes
        if self.condensed_on:
            # On `time` at the last sample's time if later: a row at the iteration's (earlier)
            # time would stay hidden behind the row `system` logged for that sample.
            t_it = float(iteration["t"])
            self.set_time(max(t_it, self._t or t_it))
            self._condense(G)
            self.set_time(t_it)
        self.focus(G, root_causes)

    def focus(self, G: nx.MultiDiGraph, root_causes: Sequence[Mapping[str, Any]]) -> bool:
        """Send the layout again if the diagnosis's members changed (top trajectory, alerted).

        Only with a layout function (`Recorder` ``blueprint``); the new layout becomes the
        viewer's active and default one, and the file's. Returns True if it was sent.
        """
        if self._layout is None:
            return False
        diagnosis = diagnosis_members(G, root_causes, self.status)
        if diagnosis == self.diagnosis:
            return False
        self.diagnosis = diagnosis
        self._send_layout()
        return True

    def _send_layout(self) -> None:
        """Build the layout for the current diagnosis and computers; make it the viewer's and the
        file's active and default one. A layout function is given ``hosts`` only when there are
        several computers and ``condensed`` only when it is on (one written before these existed
        still works without them)."""
        if self._layout is None:
            return
        extra: dict[str, Any] = {"hosts": self.hosts} if self.hosts else {}
        if self.condensed_on:
            extra["condensed"] = True
        self.blueprint = self._layout(diagnosis=self.diagnosis, **extra)
        for stream in (self._live, self._file):
            if stream is not None:
                stream.send_blueprint(self.blueprint, make_active=True, make_default=True)

    def report(self, markdown: str, t: float | None = None) -> None:
        """Log a markdown report at ``/rca/report``."""
        self._last_report = (markdown, t)
        if markdown == self._report_shown:
            return  # the viewer shows this text by latest-at already: a row more adds nothing
        if t is not None:
            self.set_time(t)
        log_report(self.rec, markdown)
        self._report_shown = markdown

    # -- end ------------------------------------------------------------------------------------
    def flush(self, timeout: float = 5.0) -> None:
        """Write the pending events and flush pending data to the sinks; never raises (a vanished
        viewer must not stop a run)."""
        try:
            self.send_events()
        except Exception as e:
            _stderr(f"stream-viz: writing the pending alerts to the recording: {e}")
        for stream in self._file_first():
            try:
                stream.flush(timeout_sec=timeout)
            except Exception as e:
                _stderr(f"stream-viz: flushing the Rerun recording: {e}")

    def close(self, timeout: float = 5.0) -> None:
        """Flush and disconnect, so the ``.rrd`` gets its footer. Safe to call twice."""
        if self._closed:
            return
        self._closed = True
        self.flush(timeout)
        for stream in self._file_first():
            try:
                stream.disconnect()
            except Exception as e:
                _stderr(f"stream-viz: closing the Rerun recording: {e}")
        if self.server is not None:
            self.server.stop()  # the served page goes with the run

    def _file_first(self) -> list[rr.RecordingStream]:
        # The file is the record: it is finished before a viewer that may have gone away is waited for.
        return [s for s in (self._file, self._live) if s is not None]

    def __enter__(self) -> Recorder:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
