"""What the monitor shows: feeds each sample, its alerts and the diagnosis to a Rerun `Recorder`."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import networkx as nx

from stream_viz.records import Alert, Sample
from stream_viz.viz.condensed import CONDENSE_ABOVE
from stream_viz.viz.metrics import MetricBatch
from stream_viz.viz.rca import report_markdown
from stream_viz.viz.recorder import Recorder
from stream_viz.viz.serve import ServeAt


class LiveView:
    """Logs the system when it changes, metrics in batches, alerts, and each new RCA iteration.

    Parameters
    ----------
    viewer : str
        ``spawn``, ``serve``, ``none`` or a gRPC URL.
    save : Path, optional
        Also write the recording here.
    metrics_every : float
        Seconds of metric samples sent in one ``send_columns`` batch (at least).
    max_chunks_per_s : float
        Upper bound on metric chunks per second sent to the viewer: a batch is one chunk per
        member, so a large system batches longer (`metrics_batch_s`).
    file_chunks_per_s : float
        The same for the file, lower: every chunk costs the ``.rrd`` a fixed overhead (its schema,
        an index entry Rerun keeps in memory until the file is closed), so the file takes longer
        batches than the viewer and stays small (a batch ends at a part's end, though).
    part_s : float
        Seconds per file part of the recording (0: one file); parts bound that index.
    serve_at : ServeAt, optional
        Address and ports of a ``serve``d viewer (default: loopback, 9090 and 9876).
    grouping : str
        The system graph's boxes: ``namespace``, ``process`` or ``none``.
    condensed, condense_above
        The condensed system graph (`stream_viz.viz.condensed`): ``auto`` above
        ``condense_above`` members, ``on``, ``off``.
    """

    def __init__(self, viewer: str = "none", save: Path | None = None, metrics_every: float = 5.0,
                 max_chunks_per_s: float = 20.0, part_s: float = 0.0, file_chunks_per_s: float = 5.0,
                 serve_at: ServeAt | None = None, grouping: str = "namespace",
                 condensed: str = "auto", condense_above: int = CONDENSE_ABOVE) -> None:
        at = serve_at or ServeAt()
        self.rec = Recorder(viewer=viewer, save=save, part_s=part_s, bind=at.bind, web_port=at.web_port,
                            grpc_port=at.grpc_port, grouping=grouping,
                            condensed=condensed, condense_above=condense_above)
        self.metrics_every, self.max_chunks_per_s = metrics_every, max_chunks_per_s
        self.file_chunks_per_s = file_chunks_per_s
        self._batch = MetricBatch()
        self._iterations = 0
        self._causes: list[Any] = []  # the root causes last logged

    @property
    def url(self) -> str | None:
        """The served web viewer's address (``serve``), else None."""
        return self.rec.url

    @property
    def recording_parts(self) -> list[Path]:
        """The recording's files so far (``run.rrd``, ``run_1.rrd``, …; empty without ``save``)."""
        return list(self.rec.parts)

    def update(
        self, t: float, sample: Sample, seen: nx.MultiDiGraph, alerts: list[Alert], result: Any,
        structure: int | None = None,
    ) -> None:
        """Log one monitor tick (nothing when there is no viewer and no file to log to);
        ``structure`` as `Recorder.system` takes it."""
        if not self.rec.enabled:
            return
        if self.rec.part_due(t):
            self._flush_metrics()  # the samples of a part end in that part
            self.rec.next_part(t, seen)
        self.rec.set_time(t)
        if alerts:
            self.rec.alerts(alerts)  # before the graph, so alerted members are coloured now
        if sample.events:
            self.rec.changes(sample.events)
        self.rec.system(seen, t, structure=structure)
        self._batch.add(t, sample.graph)
        self._send_metrics(t)
        # The report form of the result costs O(iterations × members): build it only on change.
        if len(result.iterations) == self._iterations and result.root_causes == self._causes:
            return
        report = result.to_report()
        causes, incidents = report["root_causes"], report["incidents"]
        new = report["iterations"][self._iterations:]
        for it in new:
            self.rec.rca(seen, dated(it, t), causes, incidents=incidents)
        self._iterations = len(report["iterations"])
        if not new and report["iterations"]:
            self.rec.report(report_markdown(causes, report["iterations"][-1], incidents=incidents), t)
        self._causes = result.root_causes

    def _send_metrics(self, t: float) -> None:
        """Send the metrics that are due: to the viewer every `metrics_batch_s` of
        ``max_chunks_per_s``, to the file every one of ``file_chunks_per_s``."""
        members = len(self._batch)
        if not self.rec.has_file:
            if t - self._batch.first_t >= metrics_batch_s(members, self.metrics_every, self.max_chunks_per_s):
                self._flush_metrics()
            return
        live_due = metrics_batch_s(members, self.metrics_every, self.max_chunks_per_s)
        if self.rec.has_live and self._batch.unsent_t is not None and t - self._batch.unsent_t >= live_due:
            self.rec.metrics(self._batch, to="live")
            self._batch.mark_sent()
        if t - self._batch.first_t >= metrics_batch_s(members, self.metrics_every, self.file_chunks_per_s):
            self._flush_metrics()

    def _flush_metrics(self) -> None:
        """Send every pending row (the viewer: those it has not had) and start a new batch."""
        if not self._batch:
            return
        if self.rec.has_live and self.rec.has_file:
            if self._batch.unsent_t is not None:
                self.rec.metrics(self._batch, to="live")
            self.rec.metrics(self._batch, to="file")
        else:
            self.rec.metrics(self._batch)
        self._batch.clear()

    def close(self) -> None:
        """Send what is pending and close the recording (the ``.rrd`` gets its footer)."""
        try:
            self._flush_metrics()
        finally:
            self.rec.close()


def dated(iteration: dict[str, Any], t: float) -> dict[str, Any]:
    """Return the iteration with a time: iteration 0 has none of its own (``t`` 0), and drawn at
    1970 it would stretch the viewer's time axis over fifty years."""
    return iteration if iteration.get("t") else {**iteration, "t": t}


def metrics_batch_s(members: int, shortest: float, max_chunks_per_s: float) -> float:
    """Return how many seconds of metrics to send at once: ``members`` chunks per batch stay
    within ``max_chunks_per_s``, and a batch covers at least ``shortest`` seconds."""
    return max(shortest, members / max_chunks_per_s) if max_chunks_per_s > 0 else shortest


def save_diagnosis(path: Path, G: nx.MultiDiGraph, alerts: list[Alert], result: Any) -> None:
    """Write an offline diagnosis (``stream-viz analyze --save``) as a recording."""
    rec = Recorder(viewer="none", save=path)
    try:
        t0 = min((a.t for a in alerts), default=0.0)
        rec.system(G, t0)
        rec.alerts(alerts)
        report = result.to_report()
        for it in report["iterations"]:
            rec.rca(G, dated(it, t0), report["root_causes"], incidents=report["incidents"])
    finally:
        rec.close()
