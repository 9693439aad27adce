"""The process-anomaly rule in one place: the plugin and the evidence read one settings table."""

from __future__ import annotations

import numpy as np

from stream_viz.detect.baseline import excursions
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.detect.process import SETTINGS, EvidenceRule, evidence_rule, process_anomalies
from stream_viz.model.graph import add_member, add_tree_edge, new_graph
from stream_viz.model.history import History
from stream_viz.model.theta import make_theta


def test_the_evidence_parameters_derive_from_the_plugin_settings():
    # The defaults give exactly the evidence's documented parameters.
    assert evidence_rule() == evidence_rule(SETTINGS) == EvidenceRule(
        k=5.0, cpu_min_rise=25.0, rss_min_rise_mb=100.0, growth_mb_per_s=1.0, growth_min_mb=20.0,
        trend_s=30.0, growth_samples=5, warmup=10, window=120, startup_s=120.0,
        burst_margin=2.0)
    tuned = evidence_rule({"k": 7.0, "cpu_min_rise": 40.0, "trend_s": 120.0, "warmup_s": 20.0,
                           "growth_min_samples": 6, "window": 60})
    assert (tuned.k, tuned.cpu_min_rise, tuned.trend_s, tuned.warmup, tuned.growth_samples, tuned.window) == (
        7.0, 40.0, 60.0, 20, 7, 60)


def _graph():
    G = new_graph()
    add_member(G, "process:2", pid=2)
    add_member(G, "node:/planner", pid=2)
    add_tree_edge(G, "process:2", "node:/planner")
    return G


def _run(cpus, settings, learned=None):
    """Feed ``cpus`` (one a second) to the evidence and the plugin with the same settings, the
    run started from ``learned`` (a run's ``PluginSet.learned()``, replaced by this run's)."""
    G, h = _graph(), History()
    ps = PluginSet.load(enable=["process_resources"], cwd_plugins=False,
                        settings={"process_resources": settings}, isolate=False)
    ps.prime(learned or {})
    evidence, alerts = [], []
    for t, cpu in enumerate(cpus):
        G.nodes["process:2"]["theta"] = make_theta("process", {"cpu_percent": cpu, "rss_mb": 50.0})
        h.add("process:2", float(t), G.nodes["process:2"]["theta"])
        bursts = ps.primed_by("process_resources").get("bursts")
        evidence.append(sorted(process_anomalies(G, h, ps.settings_of("process_resources"), bursts)))
        fired, problems = ps.run(float(t), G, G.nodes, h)
        assert problems == []
        alerts += [(a.t, a.member) for a in fired]
    if learned is not None:
        learned.clear()
        learned.update(ps.learned()[0])
    return evidence, alerts


def test_tuning_the_plugin_tunes_the_evidence():
    cpus = [5.0 + t % 3 for t in range(20)] + [60.0] * 6
    evidence, alerts = _run(cpus, {})
    # The evidence speaks on the first risen sample; the plugin once the rise has held 3 s
    # (cpu_hold_s: a burst of work is no rise) and then over 2 samples (confirm).
    assert evidence[19:] == [[]] + [["node:/planner", "process:2"]] * 6
    assert alerts == [(24.0, "node:/planner"), (25.0, "node:/planner")]
    # A floor above the rise silences both.
    evidence, alerts = _run(cpus, {"cpu_min_rise": 70.0})
    assert evidence == [[]] * len(cpus) and alerts == []


def test_excursions_of_a_series():
    t = np.arange(13.0)
    v = np.array([0, 9, 9, 0, 0, 9, 0, 9, 9, 0, 0, 9, 9.0])  # 1-2 a rise, 5-8 one with a dip, 11-12 now
    assert excursions(t, v, 5.0) == (1.0, 4.0)  # the 5-8 run lasted from 5 to 9
    assert excursions(t, v, 5.0, since=3.0) == (1.0, 4.0)
    assert excursions(t, v, 5.0, since=6.0) == (1.0, 0.0)  # the earlier ones began before `since`
    assert excursions(t, v, 5.0, since=11.5) == (0.5, 0.0)  # the current one counted from `since`
    assert excursions(t[:-2], v[:-2], 5.0) == (0.0, 0.0)  # not in a rise at the present
    v[12] = np.nan  # an unread sample is left out: the present is the last one read
    assert excursions(t, v, 5.0) == (0.0, 4.0)


def test_bursts_longer_than_a_few_seconds_are_the_rhythm_of_the_evidence_and_the_plugin():
    # An executor busy for 15 s every 60 s (a MultiThreadedExecutor spinning, a map re-inflated):
    # the first burst is a rise for both (the plugin once it held 3 s, confirmed over 2 samples);
    # the next two are its rhythm; a hog from 200 s on is a
    # rise for the evidence once it outlasts 2 × 15 s, for the plugin a sample later.
    cpus = [80.0 if t >= 20 and (t - 20) % 60 < 15 else 10.0 + t % 3 for t in range(200)] + [85.0] * 40
    evidence, alerts = _run(cpus, {})
    flagged = [t for t, e in enumerate(evidence) if e]
    assert flagged == [*range(20, 35), *range(231, 240)]
    assert [t for t, m in alerts if m == "node:/planner"] == [*range(24, 35), *range(232, 240)]


def test_bursts_of_a_healthy_run_are_the_rhythm_of_the_next_for_the_evidence_and_the_plugin():
    # The same executor's 15 s bursts in a run started from one that showed them: its first
    # burst is its rhythm too; a hog is a rise for the evidence once it outlasts 2 × 15 s.
    cpus = [80.0 if t >= 20 and (t - 20) % 60 < 15 else 10.0 + t % 3 for t in range(140)]
    learned = {}
    _run(cpus, {}, learned)
    assert learned == {"process_resources": {"bursts": {"node:/planner": 15.0}}}
    evidence, alerts = _run(cpus, {}, dict(learned))
    assert [t for t, e in enumerate(evidence) if e] == [] and alerts == []
    evidence, alerts = _run([10.0 + t % 3 for t in range(40)] + [85.0] * 40, {}, dict(learned))
    assert [t for t, e in enumerate(evidence) if e][:1] == [71]
    # The last burst of a run, no rise after it, is kept too.
    last = [10.0 + t % 3 for t in range(40)] + [80.0] * 28 + [10.0] * 5
    learned = {}
    _run(last, {}, learned)
    assert learned == {"process_resources": {"bursts": {"node:/planner": 28.0}}}


def test_settings_of_a_plugin_switched_off():
    ps = PluginSet.load(cwd_plugins=False, disable=["process_resources"],
                        settings={"process_resources": {"k": 6}, "rosout": {"min_level": "warn"}})
    assert "process_resources" not in ps.names
    assert ps.settings_of("process_resources") == {**SETTINGS, "k": 6.0, "alert_on": "nodes",
                                                   "warned_quiet_s": 60.0, "warned_lead_s": 10.0}
    assert ps.settings_of("rosout") == {"min_level": "warn", "watched_only": False, "startup_s": 10.0}
    assert ps.settings_of("nope") is None
