"""The detect step of the tick: the watchlist policy, process-anomaly evidence and the plugins."""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from stream_viz.detect.plugin_set import PluginSet
from stream_viz.detect.problems import PluginProblem
from stream_viz.detect.process import anomalous_processes, with_nodes
from stream_viz.detect.watchlist import CONFIGURED, PROCESS_ANOMALY, Watchlist, initial_watchlist
from stream_viz.model.history import History
from stream_viz.records import Alert, Sample


@dataclass(frozen=True)
class Detection:
    """What detection found in one sample.

    Attributes
    ----------
    alerts : list of Alert
        The plugins' valid alerts (before the store folds repeats into episodes).
    problems : list of PluginProblem
        What went wrong in the plugins on this sample.
    evidence : dict
        Metric anomaly strength in [0, 1] per member: process monitoring's anomalous processes
        and the nodes they host.
    evidence_changed : bool
        Whether ``evidence`` differs from the previous sample's.
    """

    alerts: list[Alert] = field(default_factory=list)
    problems: list[PluginProblem] = field(default_factory=list)
    evidence: dict[str, float] = field(default_factory=dict)
    evidence_changed: bool = False

    @property
    def new_evidence(self) -> dict[str, float] | None:
        """``evidence`` when it changed, else None (what `RcaEngine.update` takes: an unchanged
        sample with no alerts then costs no rerank)."""
        return self.evidence if self.evidence_changed else None


class Detector:
    """Finds the symptoms in each sample: keeps the watchlist's policy part up to date, computes
    process monitoring's evidence and runs the plugins on the watched members.

    Parameters
    ----------
    plugins : PluginSet
        The detection plugins.
    watchlist : Watchlist
        The run's ``W_j``; the detector adds ``W_0`` and process-anomaly members to it.
    settings : WatchlistConfig or mapping
        ``mode`` and ``members`` (`initial_watchlist`).
    expected_rates : mapping, optional
        Expected topic rates (Hz) by topic, for the plugins.
    own_process : str, optional
        The monitor's own process id (default: this process): never a symptom.
    """

    def __init__(self, plugins: PluginSet, watchlist: Watchlist, settings: Any,
                 expected_rates: Mapping[str, float] | None = None, own_process: str | None = None) -> None:
        self.plugins = plugins
        self.watchlist = watchlist
        self.settings = settings
        self.expected_rates = dict(expected_rates or {})
        self.own_process = own_process or f"process:{os.getpid()}"
        self.evidence: dict[str, float] = {}  # the last sample's
        self._samples = 0

    def detect(self, sample: Sample, history: History) -> Detection:
        """Detect on ``sample`` (``history`` already holds its θ)."""
        self._samples += 1
        # [plugins.process_resources] tunes this evidence and the plugin alike (detect/process.py).
        rule = self.plugins.settings_of("process_resources")
        bursts = self.plugins.primed_by("process_resources").get("bursts")  # carried from a healthy run
        found = anomalous_processes(sample.graph, history, rule, bursts) if self._samples > 1 else set()
        # The monitor is an ancestor of what it starts (the demo): its own footprint is no symptom.
        procs = found - {self.own_process}
        anomalous = with_nodes(sample.graph, found) - {self.own_process}
        # W_0 as the paper says: configured members and process monitoring; "auto"/"all" modes
        # keep adding members as they appear.
        self.watchlist.add(initial_watchlist(sample.graph, self.settings, None), CONFIGURED)
        self.watchlist.add(anomalous, PROCESS_ANOMALY)
        fired, problems = self.plugins.run(
            sample.t, sample.graph, self.watchlist, history, sample.events, sample.diff, self.expected_rates,
        )
        alerts = [a for a in fired if a.member != self.own_process]
        # Process-metric anomalies count as evidence too, not only as watchlist entries: on the
        # process, which the RCA shares among its nodes (a change of a node's own it is not).
        evidence = {m: 1.0 for m in sorted(procs)}
        changed = evidence != self.evidence
        self.evidence = evidence
        return Detection(alerts, problems, evidence, changed)
