"""The live pipeline: collect → detect → diagnose → show, one sample per period.

Everything the run produces is kept as it arrives (alerts committed to the database per sample,
recording streamed), so ending the run any way loses nothing already collected.
"""

from __future__ import annotations

import argparse
import gc
import os
import signal
import sys
import threading
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from stream_viz.collect.collector import Collector
from stream_viz.config import Config, load_config
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.detect.process import process_anomalies
from stream_viz.detect.store import AlertStore, default_db_path
from stream_viz.detect.watchlist import initial_watchlist
from stream_viz.live_view import LiveView
from stream_viz.model.graph import new_graph
from stream_viz.model.history import History
from stream_viz.model.seen import drop_gone, remember
from stream_viz.output import check_writable
from stream_viz.progress import Progress
from stream_viz.rca.engine import RcaEngine
from stream_viz.report import build_report, write_report


class Monitor:
    """One monitoring run: owns the collector, plugins, alert store, RCA engine and the view."""

    def __init__(
        self,
        config: Config,
        *,
        db: Path | None = None,
        save: Path | None = None,
        report: Path | None = None,
        viewer: str = "none",
        progress: Progress | None = None,
        domain_id: int | None = None,
    ) -> None:
        # Outputs are checked before anything starts: a typo must not cost a run.
        self.report_path = check_writable(report, "report") if report else None
        if save:
            check_writable(save, "recording")
        self.config = config
        self.progress = progress or Progress()
        self.db_path = Path(db) if db else default_db_path()
        self.store = AlertStore(self.db_path)
        self.started_at = time.time()
        self.store.set_meta("started_at", self.started_at)
        self.plugins = PluginSet.from_config(config)
        for problem in self.plugins.load_problems:
            self.progress.say(f"plugin problem: {problem}")
        self.store.add_problems(self.plugins.load_problems, t=self.started_at)
        self.view = LiveView(viewer=viewer, save=save, part_s=60.0 * config.monitor.recording_part_minutes)
        self.history = History(maxlen=config.monitor.history)
        self.engine = RcaEngine(config.rca, watchlist=set())
        self.seen = new_graph()
        self.external_watch: set[str] = set()
        self._unreadable: dict[str, str] = {}
        self._evidence: dict[str, float] = {}
        self.own_process = f"process:{os.getpid()}"
        self.n_alerts = 0  # the alerts themselves live in the database, not in memory
        self.samples = 0
        self.injected: Mapping[str, Any] | None = None
        self.collector = Collector(domain_id, topic_metrics=config.monitor.topic_metrics)
        self.collector.start()
        # Everything loaded so far (rclpy, numpy, networkx, Rerun, plugins: ~10^5 objects) lives
        # as long as the process: out of the collector's sight, a full collection no longer walks
        # it each time (40 ms vs 0.4 ms frozen on the demo, bench/bench_monitor_cpu.py). Garbage first,
        # so none is frozen; `close` unfreezes.
        gc.collect()
        gc.freeze()

    # -- one tick ---------------------------------------------------------------------------
    def step(self) -> None:
        """Take one sample and push it through detection, the RCA and the view."""
        sample = self.collector.sample()
        t = sample.t
        self.samples += 1
        self.seen = remember(self.seen, sample.graph, t)
        self._forget(t)
        for m, theta in sample.graph.nodes(data="theta"):
            if theta is not None:
                self.history.add(m, t, theta)
        if sample.diff or self.samples == 1:
            self.store.add_snapshot(t, self.seen)
        # A member we may not read stays unreadable: record it when that changes, not every tick.
        fresh = {m: why for m, why in sample.unreadable.items() if self._unreadable.get(m) != why}
        if fresh:
            self.store.add_unreadable(t, fresh)
        self._unreadable = dict(sample.unreadable)
        # [plugins.process_resources] tunes this evidence and the plugin alike (detect/process.py).
        rule = self.plugins.settings_of("process_resources")
        anomalous = process_anomalies(sample.graph, self.history, rule) if self.samples > 1 else set()
        anomalous.discard(self.own_process)
        added = self._watch_additions(sample.graph, anomalous) - self.external_watch
        if added:
            self.external_watch |= added
            self.engine.watch(added)
        fired, problems = self.plugins.run(
            t, sample.graph, self.engine.watchlist, self.history, sample.events, sample.diff,
            self.config.expected_rates,
        )
        # The store rate-limits an ongoing symptom (episodes); the RCA sees what the database
        # keeps, so `analyze` on the file reproduces the live diagnosis.
        # The monitor is an ancestor of what it starts (the demo): its own footprint is no symptom.
        alerts = self.store.add([a for a in fired if a.member != self.own_process])
        if problems:
            self.store.add_problems(problems, t=t)
            for p in problems:
                self.progress.say(f"plugin problem: {p}")
        self.n_alerts += len(alerts)
        # Process-metric anomalies count as evidence too, not only as watchlist entries.
        # Passed only when it changed: an unchanged sample with no alerts costs no rerank.
        evidence = {m: 1.0 for m in anomalous}
        changed = evidence != self._evidence
        self._evidence = evidence
        result = self.engine.update(self.seen, alerts, evidence if changed else None, t=t)
        self.view.update(t, sample, self.seen, alerts, result)
        self.progress.update(self._status(t, result))

    def _forget(self, t: float) -> None:
        # Long after a member vanished (longer than the RCA window by default) it can no longer
        # be a cause: drop it and its history, so a churning system does not grow the run.
        # The database keeps it (snapshots, alerts) for `analyze`.
        gone = drop_gone(self.seen, t, self.config.monitor.forget_gone_s)
        if gone:
            self.history.forget(set(self.seen))
            self.external_watch.difference_update(gone)

    def _watch_additions(self, G, anomalous: set[str]) -> set[str]:
        # W_0 as the paper says: configured members and process monitoring; "auto"/"all" modes
        # keep adding members as they appear.
        return anomalous | initial_watchlist(G, self.config.watchlist, None)

    def _status(self, t: float, result) -> str:
        kinds: dict[str, int] = {}
        for _, k in self.seen.nodes(data="kind"):
            kinds[k] = kinds.get(k, 0) + 1
        top = result.root_causes[0] if result.root_causes else None
        top_txt = f"top root cause: {top.member} ({top.score:.2f})" if top else "no root cause yet"
        return (
            f"[{t - self.started_at:6.1f}s] {kinds.get('node', 0)} nodes, {kinds.get('topic', 0)} topics, "
            f"{kinds.get('process', 0)} processes | {self.n_alerts} alerts | {top_txt}"
        )

    # -- the whole run ----------------------------------------------------------------------
    def run(
        self, duration: float | None, stop: threading.Event, on_tick: Callable[[], None] | None = None
    ) -> None:
        """Sample every period until ``duration`` passed or ``stop`` is set."""
        period = self.config.monitor.period
        end = None if duration is None else time.monotonic() + duration
        next_t = time.monotonic()
        while not stop.is_set():
            self.step()
            if on_tick:
                on_tick()
            next_t += period
            now = time.monotonic()
            if end is not None and now >= end:
                break
            wait = next_t - now if end is None else min(next_t, end) - now
            if wait < 0:  # fell behind: skip missed ticks rather than burst
                next_t = now
                wait = 0
            stop.wait(wait)

    def close(self, keep_view: bool = False) -> dict[str, Any]:
        """Stop observing, write the report, commit the database, flush the recording.

        Every step runs even when an earlier one fails (the first error is raised after all of
        them), so one broken output never costs the others. ``keep_view`` leaves the viewer
        connection open (a served web viewer keeps showing the run); close it with ``view.close()``.
        """
        ended_at = time.time()
        report: dict[str, Any] = {}

        def write() -> None:
            report.update(build_report(self.seen, self.store.alerts(), self.engine.result().to_report(),
                                       self.started_at, ended_at, self.injected))
            if self.report_path:
                write_report(self.report_path, report)

        def commit() -> None:
            self.store.set_meta("ended_at", ended_at)
            self.store.set_meta("watchlist", sorted(self.external_watch))
            if self.injected:
                self.store.set_meta("injected", dict(self.injected))
            self.store.close()

        steps = [self.collector.close, self.progress.done, write, commit, self.plugins.close, gc.unfreeze]
        if not keep_view:
            steps.append(self.view.close)
        first: BaseException | None = None
        for step in steps:
            try:
                step()
            except Exception as exc:  # the rest must still run
                first = first or exc
        if first is not None:
            raise first
        return report


def install_stop_handlers(stop: threading.Event) -> None:
    """SIGINT and SIGTERM end the run cleanly (the report is written, exit code 0)."""

    def handler(signum, frame) -> None:
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)


def run_monitor(args: argparse.Namespace) -> dict[str, Any]:
    """``stream-viz monitor``: attach to the system on ROS_DOMAIN_ID until --duration or a signal."""
    config = load_config(args.config)
    stop = threading.Event()
    install_stop_handlers(stop)
    viewer = args.viewer or "none"
    mon = Monitor(config, db=args.db, save=args.save, report=args.report, viewer=viewer)
    mon.progress.say(f"alert database: {mon.db_path}")
    try:
        mon.run(args.duration, stop)
    finally:
        report = mon.close(keep_view=viewer == "serve")
    _print_outputs(mon, args)
    linger(mon, viewer)
    return report


def linger(mon: Monitor, viewer: str) -> None:
    """A served web viewer dies with this process: on a terminal, keep it up until Ctrl-C."""
    try:
        if viewer == "serve" and sys.stdin.isatty():
            done = threading.Event()
            install_stop_handlers(done)
            mon.progress.say(f"the web viewer keeps serving at {mon.view.url} — Ctrl-C to exit")
            done.wait()
    finally:
        mon.view.close()


def say_recording(mon: Monitor) -> None:
    """Tell where the recording went (all its file parts) and how to open it."""
    parts = mon.view.rec.parts
    files = " ".join(str(p) for p in parts)
    more = f" in {len(parts)} parts" if len(parts) > 1 else ""
    mon.progress.say(f"recording{more}: {files}  (open with: rerun {files})")


def _print_outputs(mon: Monitor, args: argparse.Namespace) -> None:
    if args.save:
        say_recording(mon)
    if args.report:
        mon.progress.say(f"report: {args.report}")
