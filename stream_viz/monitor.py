"""The live pipeline, one tick per period: sample → record → detect → store → diagnose → show.

Each step has one owner: the `Collector` samples the system, the `Shadow` records what was seen
and its θ history, the `Detector` finds symptoms on the `Watchlist`, the `AlertStore` keeps them,
the `RcaEngine` diagnoses, the `LiveView` shows. Everything the run produces is kept as it
arrives (alerts committed to the database per sample, recording streamed), so ending the run any
way loses nothing already collected.
"""

from __future__ import annotations

import gc
import threading
import time
from collections.abc import Callable, Iterable, Mapping
from pathlib import Path
from typing import Any

import networkx as nx

from stream_viz.collect.collector import Collector
from stream_viz.collect.samples_file import SamplesWriter, run_header
from stream_viz.config import Config
from stream_viz.detect.detector import Detector
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.detect.store import AlertStore, default_db_path, learned_of
from stream_viz.detect.watchlist import Watchlist
from stream_viz.errors import StoreError
from stream_viz.model.history import History
from stream_viz.model.shadow import Shadow
from stream_viz.output import check_writable
from stream_viz.progress import Progress
from stream_viz.rca.engine import RcaEngine, RcaResult
from stream_viz.report import build_report, write_report
from stream_viz.viz.live import LiveView
from stream_viz.viz.serve import ServeAt


class Monitor:
    """One monitoring run: the owner of each step of the tick, and the run's outputs.

    Attributes
    ----------
    watchlist : Watchlist
        ``W_j``: what the plugins watch and the RCA grows from.
    evidence : dict
        The last sample's metric evidence (process monitoring's anomalous members).
    recording_parts : list of Path
        The files of the recording so far (empty without ``save``).
    seen, history
        Every member seen (vanished ones kept until forgotten) and their θ history.

    A replay (``stream-viz replay``) passes its ``collector`` (the recorded samples), the run's
    ``started_at`` and a longer ``plugin_timeout_s``; ``samples`` writes every sample collected.
    ``healthy``, the database of an earlier run of the same robot that the user calls healthy,
    starts each plugin from what it learned there (``ctx.learned``); every run saves its own.
    """

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
        serve_at: ServeAt | None = None,
        group_by: str = "namespace",
        condensed: str | None = None,
        samples: Path | None = None,
        collector: Any = None,
        started_at: float | None = None,
        plugin_timeout_s: float | None = None,
        healthy: Path | None = None,
    ) -> None:
        # Outputs are checked before anything starts: a typo must not cost a run.
        self.report_path = check_writable(report, "report") if report else None
        if save:
            check_writable(save, "recording")
        if samples:
            check_writable(samples, "samples file")
        learned = learned_of(healthy) if healthy else {}
        self.config = config
        self.progress = progress or Progress()
        self.db_path = Path(db) if db else default_db_path()
        self.store = AlertStore(self.db_path)
        self.started_at = time.time() if started_at is None else started_at
        try:
            self.store.begin_run(self.started_at)
        except StoreError:
            self.store.close()
            raise
        timeout = {"timeout_s": plugin_timeout_s} if plugin_timeout_s else {}
        self.plugins = PluginSet.from_config(config, **timeout)
        self._say_problems(self.plugins.load_problems)
        self.store.add_problems(self.plugins.load_problems, t=self.started_at)
        self.healthy_from = str(healthy) if healthy else None
        if healthy:
            primed = self.plugins.prime(learned)
            self.store.set_meta("healthy_from", str(healthy))
            self.progress.say(f"starting from what the healthy run {healthy} showed: "
                              f"{', '.join(primed) or 'nothing any plugin learned'}")
        self.view = LiveView(viewer=viewer, save=save, part_s=60.0 * config.monitor.recording_part_minutes,
                             serve_at=serve_at, grouping=group_by,
                             condensed=condensed or config.monitor.condensed,
                             condense_above=config.monitor.condense_above)
        self.shadow = Shadow(history=config.monitor.history, forget_gone_s=config.monitor.forget_gone_s)
        self.watchlist = Watchlist()
        self.detector = Detector(self.plugins, self.watchlist, config.watchlist, config.expected_rates)
        self.engine = RcaEngine(config.rca, watchlist=self.watchlist)
        self.n_alerts = 0  # the alerts themselves live in the database, not in memory
        self.samples = 0
        self.injected: Mapping[str, Any] | None = None
        # A replay passes its own collector (the recorded samples) in place of the live one.
        self.collector = collector or Collector(domain_id, topic_metrics=config.monitor.topic_metrics)
        self.collector.start()
        self._limits: dict[str, str] = {}
        self._say_limits()
        self.samples_file = SamplesWriter(samples, run_header(config, self.started_at)) if samples else None
        # Everything loaded so far (rclpy, numpy, networkx, Rerun, plugins) lives as long as the
        # process: frozen, a full collection no longer walks it each time (cost in
        # docs/evaluation.md, "Cost"). Garbage first, so none is frozen; `close` unfreezes.
        gc.collect()
        gc.freeze()

    # -- one tick ---------------------------------------------------------------------------
    def step(self) -> None:
        """One tick: sample → record → detect → store → diagnose → show."""
        sample = self.collector.sample()
        if self.samples_file:
            self.samples_file.write(sample)
        self.samples += 1
        forgotten = self.shadow.record(sample.graph, sample.t, sample.diff)
        self.watchlist.forget(forgotten)
        found = self.detector.detect(sample, self.shadow.history)
        # The store rate-limits an ongoing symptom (episodes); the RCA sees what the database
        # keeps, so `analyze` on the file reproduces the live diagnosis.
        alerts = self.store.add_sample(sample, self.shadow.seen, found.alerts, found.problems)
        result = self.engine.update(self.shadow.seen, alerts, found.new_evidence, t=sample.t)
        self.view.update(sample.t, sample, self.shadow.seen, alerts, result, self.shadow.structure)
        self._tell(sample.t, alerts, found.problems, result)
        self._say_limits()

    # -- what the run has so far (public: the evaluation reads it) -------------------------------
    @property
    def seen(self) -> nx.MultiDiGraph:
        """Every member seen so far, vanished ones marked gone (until forgotten)."""
        return self.shadow.seen

    @property
    def history(self) -> History:
        """θ history per member."""
        return self.shadow.history

    @property
    def evidence(self) -> dict[str, float]:
        """The last sample's metric evidence (member → strength in [0, 1])."""
        return self.detector.evidence

    @property
    def recording_parts(self) -> list[Path]:
        """The recording's files so far (``run.rrd``, ``run_1.rrd``, …; empty without ``save``)."""
        return self.view.recording_parts

    def _tell(self, t: float, alerts: list, problems: list, result: RcaResult) -> None:
        self.n_alerts += len(alerts)
        self._say_problems(problems)
        self.progress.update(self._status(t, result))

    def _say_limits(self) -> None:
        """Say each new fallback of the collector once (another rmw or ROS release may lack what
        it reads through rcl); the database keeps them (meta ``collector_limits``)."""
        limits = getattr(self.collector, "limits", dict)()  # a replay's collector has none
        new = {k: v for k, v in limits.items() if self._limits.get(k) != v}
        for what, why in new.items():
            self.progress.say(f"collector: no {what}: {why}")
        # A limit that turned out not to hold is taken back, so the database and report keep no
        # false claim (a process that created its nodes late was named undiscovered).
        gone = {k: v for k, v in getattr(self.collector, "retracted", dict)().items()
                if k in self._limits and k not in limits}
        for what, why in gone.items():
            self.progress.say(f"collector: {what} after all: {why}")
            del self._limits[what]
        if new or gone:
            self._limits.update(new)
            self.store.set_meta("collector_limits", self._limits)

    def _say_problems(self, problems: Iterable[Any]) -> None:
        for p in problems:
            self.progress.say(f"plugin problem: {p}")

    def _status(self, t: float, result: RcaResult) -> str:
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

    def close(self, keep_view: bool = False, ended_at: float | None = None) -> dict[str, Any]:
        """Stop observing, write the report, commit the database, flush the recording.

        Every step runs even when an earlier one fails (the first error is raised after all of
        them), so one broken output never costs the others. ``keep_view`` leaves the viewer
        connection open (a served web viewer keeps showing the run); close it with ``view.close()``.
        ``ended_at`` is now unless given (a replay: the recorded run's end).
        """
        ended_at = time.time() if ended_at is None else ended_at
        report: dict[str, Any] = {}

        def write() -> None:
            report.update(build_report(self.seen, self.store.alerts(), self.engine.result().to_report(),
                                       self.started_at, ended_at, self.injected, self.store.problems(),
                                       self._limits, self.healthy_from))
            if self.report_path:
                write_report(self.report_path, report)

        def commit() -> None:
            learned, problems = self.plugins.learned(ended_at)
            self._say_problems(problems)
            self.store.add_problems(problems, t=ended_at)
            self.store.set_meta("learned", learned)
            self.store.set_meta("ended_at", ended_at)
            self.store.set_meta("watchlist", sorted(self.watchlist.external))
            if self.injected:
                self.store.set_meta("injected", dict(self.injected))
            self.store.close()

        def end_samples() -> None:
            if self.samples_file:
                self.samples_file.note("end", {"ended_at": ended_at, "injected": self.injected})
                self.samples_file.close()

        steps = [self.collector.close, end_samples, self.progress.done, write, commit, self.plugins.close,
                 gc.unfreeze]
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

