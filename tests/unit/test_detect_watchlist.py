"""W_0: config patterns, process monitoring, modes; and the pure baseline helpers."""

from __future__ import annotations

import numpy as np

from stream_viz.config import WatchlistConfig
from stream_viz.detect.baseline import robust, slope
from stream_viz.detect.process import process_anomalies
from stream_viz.detect.watchlist import (
    CONFIGURED,
    GROWTH,
    PROCESS_ANOMALY,
    Watchlist,
    initial_watchlist,
    match_members,
)
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.history import History
from stream_viz.model.theta import make_theta


def _graph(n_extra=0):
    G = new_graph()
    for name, pid in (("/camera_left", 1), ("/camera_right", 1), ("/planner", 2)):
        add_member(G, f"node:{name}", pid=pid)
    add_member(G, "topic:/camera/image")
    add_flow_edge(G, "node:/camera_left", "topic:/camera/image", "pub")
    for pid in (1, 2):
        add_member(G, f"process:{pid}", pid=pid)
    add_tree_edge(G, "process:1", "node:/camera_left")
    add_tree_edge(G, "process:1", "node:/camera_right")
    add_tree_edge(G, "process:2", "node:/planner")
    for i in range(n_extra):
        add_member(G, f"topic:/extra{i}")
    return G


def test_match_members():
    G = _graph()
    assert match_members(G, ["node:/camera*"]) == {"node:/camera_left", "node:/camera_right"}
    assert match_members(G, ["/camera*"]) == {"node:/camera_left", "node:/camera_right",
                                              "topic:/camera/image"}
    assert match_members(G, ["node:/planner", "process:?"]) == {"node:/planner", "process:1", "process:2"}
    assert match_members(G, ["node:/nothing"]) == set()


def _history(cpu_last):
    h = History()
    for t in range(20):
        for pid in (1, 2):
            cpu = 5.0 + (t % 3) if not (pid == 2 and t == 19) else cpu_last
            h.add(f"process:{pid}", float(t), make_theta("process", {"cpu_percent": cpu, "rss_mb": 50.0}))
    return h


def test_process_anomalies_flag_the_process_and_its_nodes():
    G = _graph()
    assert process_anomalies(G, _history(6.0)) == set()
    assert process_anomalies(G, _history(90.0)) == {"process:2", "node:/planner"}
    # compared with the last `window` samples only: 5 are too few to judge (warm-up 10)
    assert process_anomalies(G, _history(90.0), {"window": 5}) == set()


def test_history_keeps_maxlen_and_reads_the_last_samples():
    h = _history(6.0)
    assert list(h.times("process:1", 3)) == [17.0, 18.0, 19.0]
    assert h.values("process:2", 2).shape == (2, len(make_theta("process", {})))
    assert len(h.times("process:1", 100)) == 20 and len(h.times("nothing", 3)) == 0
    short = History(maxlen=4)
    for t in range(10):
        short.add("m", float(t), np.array([t]))
    assert list(short.times("m")) == [6.0, 7.0, 8.0, 9.0]


def test_initial_watchlist_modes():
    small, big = _graph(), _graph(n_extra=2100)
    assert initial_watchlist(small, WatchlistConfig(mode="auto"), None) == set(small.nodes)
    assert initial_watchlist(_graph(n_extra=1000), WatchlistConfig(mode="auto"), None) == set(
        _graph(n_extra=1000).nodes)  # a 500-node robot's ~1,000 members are all watched
    assert initial_watchlist(big, {"mode": "all"}, None) == set(big.nodes)
    # Above the limit, auto: every process and every node (and configured members), no topic.
    nodes = {"node:/camera_left", "node:/camera_right", "node:/planner"}
    assert initial_watchlist(big, WatchlistConfig(mode="auto"), None) == nodes | {"process:1", "process:2"}
    cfg = WatchlistConfig(mode="config", members=("node:/camera_l*",))
    assert initial_watchlist(big, cfg, None) == {"node:/camera_left", "process:1", "process:2"}
    assert initial_watchlist(big, cfg, _history(90.0)) == {"node:/camera_left", "process:1", "process:2",
                                                           "node:/planner"}
    assert initial_watchlist(small, {"mode": "config", "members": []}, None) == {"process:1", "process:2"}


def test_watchlist_keeps_its_members_their_sources_and_the_pending_additions():
    w = Watchlist({"node:/a"})  # W_0: iteration 0 records it, so nothing is pending
    assert w == {"node:/a"} and w.pending == frozenset() and w.sources("node:/a") == {CONFIGURED}
    assert w.add({"node:/a", "node:/b"}, CONFIGURED) == {"node:/b"}
    assert w.add({"process:1", "node:/b"}, PROCESS_ANOMALY) == {"process:1"}
    assert w == {"node:/a", "node:/b", "process:1"} and w.pending == {"node:/b", "process:1"}
    assert w.sources("node:/b") == {CONFIGURED, PROCESS_ANOMALY}
    w.commit({"topic:/t", "node:/a"})  # an RCA iteration recorded the pending additions
    assert w.pending == frozenset() and w.sources("topic:/t") == {GROWTH}
    assert w.sources("node:/a") == {CONFIGURED}  # already watched: not counted as grown
    assert w.external == {"node:/a", "node:/b", "process:1"}
    assert w.add({"topic:/t"}, CONFIGURED) == frozenset()  # watched already: not pending
    assert w.external == {"node:/a", "node:/b", "process:1", "topic:/t"}
    # Forgetting drops where a member came from, not the member (W_j only grows).
    w.forget({"process:1", "topic:/t"})
    assert "process:1" in w and w.sources("process:1") == frozenset()
    assert w.external == {"node:/a", "node:/b"}
    assert w.add({"process:1"}, PROCESS_ANOMALY) == frozenset()  # back: watched from outside again
    assert w.external == {"node:/a", "node:/b", "process:1"}
    assert w | {"x"} == {"node:/a", "node:/b", "process:1", "topic:/t", "x"}


def test_robust_and_slope():
    med, sigma, n = robust(np.array([1.0, 2.0, 3.0, 100.0, np.nan]))
    assert (med, n) == (2.5, 4)
    assert np.isclose(sigma, 1.4826 * 1.0)
    assert slope(np.array([0.0, 1.0, 2.0]), np.array([1.0, 3.0, 5.0])) == 2.0
    assert np.isnan(slope(np.array([1.0]), np.array([1.0])))


def test_history_ring_matches_a_plain_bounded_queue():
    # the ring grows 16 → 32 → … → maxlen and then overwrites: same answers as a deque
    from collections import deque

    rng = np.random.default_rng(0)
    for maxlen in (1, 5, 16, 17, 40, 100):
        h, ref = History(maxlen=maxlen), deque(maxlen=maxlen)
        for i in range(3 * maxlen + 7):
            theta = rng.random(3)
            h.add("m", float(i), theta)
            ref.append((float(i), theta))
            for last in (None, 1, 7, 1000):
                want = list(ref)[-last:] if last else list(ref)
                assert list(h.times("m", last)) == [t for t, _ in want]
                assert np.array_equal(h.values("m", last), np.vstack([v for _, v in want]))
                t_, v_ = h.series("m", last)
                assert np.array_equal(t_, h.times("m", last)) and np.array_equal(v_, h.values("m", last))
    h = History(maxlen=4)
    h.add("m", 0.0, np.zeros(3))
    out = h.values("m")
    h.add("m", 1.0, np.ones(3))
    assert out.tolist() == [[0.0, 0.0, 0.0]]  # what was read is a copy, not a view of the ring


def _process_anomaly_by_definition(times, values, now, k=5.0, cpu_min_rise=25.0, rss_min_rise_mb=100.0,
                                   growth_mb_per_s=1.0, growth_min_mb=20.0, trend_s=30.0, warmup=10,
                                   window=120, startup_s=120.0):
    """The definition, with no shortcut: medians always computed. Memory counts as risen only
    when it rose lately (half the floor above the last ``trend_s``' lowest); growth from a
    process's first samples is its start-up until it was seen ``startup_s``."""
    from stream_viz.detect.process import _CPU, _RSS

    keep = times <= now
    times, values = times[keep], values[keep]
    if len(times) < warmup + 1:
        return []
    out = []
    for col, floor, what in ((_CPU, cpu_min_rise, "cpu"), (_RSS, rss_min_rise_mb, "memory")):
        med, sigma, _ = robust(values[:-1, col])
        cur = values[-1, col]
        lately = col != _RSS or cur - np.nanmin(values[times >= now - trend_s, _RSS]) >= floor / 2
        if np.isfinite(cur) and np.isfinite(med) and cur - med >= max(k * sigma, floor) and lately:
            out.append(what)
    recent = times >= now - trend_s
    early = values[: warmup + 1, _RSS]
    starting = (len(times) < window and times[-1] - times[0] < startup_s
                and np.nanmax(early, initial=-np.inf) - np.nanmin(early, initial=np.inf) >= growth_min_mb / 2)
    if recent.sum() >= 5 and not starting:
        s, span = slope(times[recent], values[recent, _RSS]), values[recent, _RSS]
        if np.isfinite(s) and s >= growth_mb_per_s and np.nanmax(span) - np.nanmin(span) >= growth_min_mb:
            out.append("memory_growth")
    return out


def test_process_anomaly_shortcut_agrees_with_the_definition():
    # The healthy-case shortcut (no median unless the value clears the floor above the minimum)
    # must never change the answer: random healthy, spiking, leaking and gappy series.
    from stream_viz.detect.process import _CPU, _RSS, process_anomaly

    rng = np.random.default_rng(7)
    dim = len(make_theta("process", {}))
    kinds = {"cpu": 0, "memory": 0, "memory_growth": 0, "none": 0}
    for _ in range(3000):
        n = int(rng.integers(5, 60))
        times = np.arange(n, dtype=float) * rng.choice([1.0, 3.0])  # 3 s apart: past the start-up
        values = np.full((n, dim), np.nan)
        values[:, _CPU] = rng.normal(rng.uniform(0, 50), rng.uniform(0, 15), n)
        values[:, _RSS] = rng.uniform(20, 300) + rng.normal(0, rng.uniform(0, 30), n)
        if rng.random() < 0.3:
            values[-1, _CPU] += rng.uniform(0, 120)
        if rng.random() < 0.3:
            values[-1, _RSS] += rng.uniform(0, 300)
        if rng.random() < 0.3:
            values[:, _RSS] += rng.uniform(0, 4) * times
        if rng.random() < 0.2:
            values[rng.random(n) < 0.3, int(rng.choice([_CPU, _RSS]))] = np.nan
        got = process_anomaly(times, values, times[-1])
        assert got == _process_anomaly_by_definition(times, values, times[-1])
        for what in got or ["none"]:
            kinds[what] += 1
    assert min(kinds.values()) > 50, kinds  # every outcome was exercised
