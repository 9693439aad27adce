"""The detect step on a literal graph: the watchlist it keeps, the plugins it runs, the evidence."""

from __future__ import annotations

from stream_viz.config import WatchlistConfig
from stream_viz.detect.api import Plugin
from stream_viz.detect.detector import Detector
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.detect.watchlist import CONFIGURED, PROCESS_ANOMALY, Watchlist
from stream_viz.model.graph import add_member, add_tree_edge, new_graph
from stream_viz.model.history import History
from stream_viz.model.theta import make_theta
from stream_viz.records import Alert, Sample

OWN = "process:1"  # the monitor's own process in these tests


class EveryWatched(Plugin):
    """Alerts every watched node and process: shows what the plugins were given."""

    name = "every"
    kinds = ("node", "process")

    def check(self, ctx):
        for kind in self.kinds:
            for m in ctx.watched(kind):
                yield ctx.alert(m, "warn", "watched")


def _graph():
    # process:1 (the monitor) hosts /camera; process:2 hosts /planner
    G = new_graph()
    for name, pid in (("/camera", 1), ("/planner", 2)):
        add_member(G, f"node:{name}", pid=pid)
        add_member(G, f"process:{pid}", pid=pid)
        add_tree_edge(G, f"process:{pid}", f"node:{name}")
    add_member(G, "topic:/scan")
    return G


def _sample(history, t, cpu2, cpu1=5.0):
    """The graph at ``t`` with process θ, and its θ added to ``history`` (the record step)."""
    G = _graph()
    for pid, cpu in ((1, cpu1), (2, cpu2)):
        theta = make_theta("process", {"cpu_percent": cpu, "rss_mb": 50.0})
        G.nodes[f"process:{pid}"]["theta"] = theta
        history.add(f"process:{pid}", t, theta)
    return Sample(t, G)


def test_the_detector_keeps_the_watchlist_runs_the_plugins_and_reports_the_evidence():
    watchlist, history = Watchlist(), History()
    plugins = PluginSet([(EveryWatched(), "every", "test")], isolate=False)
    det = Detector(plugins, watchlist, WatchlistConfig(mode="config", members=("topic:/scan",)),
                   own_process=OWN)
    calm = [det.detect(_sample(history, float(t), 5.0 + t % 3), history) for t in range(12)]
    # config mode: the configured members and every process; the monitor's own alerts dropped
    assert watchlist == {"topic:/scan", "process:1", "process:2"}
    assert watchlist.sources("process:2") == {CONFIGURED}
    assert calm[-1].alerts == [Alert("process:2", "every", 11.0, "warn", "watched")]
    assert calm[-1].problems == [] and calm[-1].evidence == {} and not calm[-1].evidence_changed
    # /planner's process spikes: the process is evidence (its nodes share it in the RCA), and it
    # and its node join the watchlist
    hot = det.detect(_sample(history, 12.0, 95.0), history)
    assert hot.evidence == {"process:2": 1.0}
    assert hot.evidence_changed and hot.new_evidence == hot.evidence and det.evidence == hot.evidence
    assert watchlist.sources("node:/planner") == {PROCESS_ANOMALY}
    assert watchlist.pending == {"topic:/scan", "process:1", "process:2", "node:/planner"}
    assert {a.member for a in hot.alerts} == {"process:2", "node:/planner"}
    again = det.detect(_sample(history, 13.0, 96.0), history)
    assert again.evidence == hot.evidence and not again.evidence_changed and again.new_evidence is None


def test_the_monitors_own_process_is_never_evidence():
    watchlist, history = Watchlist(), History()
    det = Detector(PluginSet([], isolate=False), watchlist, WatchlistConfig(mode="config"), own_process=OWN)
    for t in range(12):
        det.detect(_sample(history, float(t), 5.0, cpu1=5.0 + t % 3), history)
    hot = det.detect(_sample(history, 12.0, 5.0, cpu1=95.0), history)
    # the monitor's process is left out, as its alerts are (its nodes share its evidence: none)
    assert hot.evidence == {} and hot.alerts == []
