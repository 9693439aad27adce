"""Pure parts of the collector on literal data: Fast DDS gids, build_model, window metrics, events."""

from __future__ import annotations

import math
from collections import Counter

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import Log
from rclpy.qos import qos_profile_unknown

from stream_viz.collect.build import build_model
from stream_viz.collect.fastdds import decode_gid
from stream_viz.collect.readings import (
    Endpoint,
    GraphReading,
    NodeReading,
    PidInfo,
    ProcessReading,
    TopicStats,
)
from stream_viz.collect.rosgraph import is_hidden, is_param_service
from stream_viz.collect.topics import log_event, logger_node
from stream_viz.collect.window import window_metrics
from stream_viz.model.graph import flow_edges
from stream_viz.model.theta import theta_dict


def test_decode_fastdds_gid():
    # A real /rosout gid of a process with pid 5117 = 0x13fd (bytes 4-5: fd 13, little-endian).
    gid = bytes.fromhex("010f78fdfd1355170000000000000603")
    info = decode_gid(gid)
    assert info.pid_low16 == 5117
    assert info.host_id == 0x78FD
    assert info.participant == 0
    assert info.prefix == "010f78fdfd13551700000000"
    # Participant index 2, pid low bits 0xffff; the entity id does not change the prefix.
    other = decode_gid([1, 15, 0, 1, 0xFF, 0xFF, 9, 9, 2, 0, 0, 0, 0, 0, 1, 3])
    assert (other.pid_low16, other.participant, other.host_id) == (0xFFFF, 2, 1)
    assert decode_gid(bytes.fromhex("010f78fdfd135517000000000000ff03")).prefix == info.prefix


def test_decode_rejects_other_vendors_and_short():
    assert decode_gid(bytes.fromhex("0110" + "00" * 14)) is None  # Cyclone DDS vendor id
    assert decode_gid(b"\x01\x0f\x00") is None


def test_hidden_and_param_names():
    assert is_hidden("/fib/_action/feedback") and is_hidden("/_stream_viz_observer_1")
    assert not is_hidden("/ns/talker") and not is_hidden("/ns_/a_b") and not is_hidden("/")
    assert is_hidden("_private") and is_hidden("rel/_x")
    assert is_param_service("/ns/talker/get_parameters", "/ns/talker")
    assert not is_param_service("/ns/talker/get_parameters", "/other")
    assert not is_param_service("/ns/talker/reset", "/ns/talker")


QOS = {"reliability": "reliable", "durability": "volatile", "history": "unknown", "depth": None}


def _reading() -> GraphReading:
    r = GraphReading()
    r.nodes = {
        "/cam": NodeReading("/cam", "cam", "/"),
        "/ns/det": NodeReading("/ns/det", "det", "/ns", clients={"/srv": ["std_srvs/srv/Trigger"]},
                               action_clients={"/go": ["pkg/action/Go"]}),
        "/srvnode": NodeReading("/srvnode", "srvnode", "/", services={"/srv": ["std_srvs/srv/Trigger"]},
                                action_servers={"/go": ["pkg/action/Go"]}),
        "/lost": NodeReading("/lost", "lost", "/"),
    }
    r.topics = {"/image": ["sensor_msgs/msg/Image"], "/odd": ["nobody_msgs/msg/Odd"]}
    r.publishers = {"/image": [Endpoint("/cam", "/image", "sensor_msgs/msg/Image", b"", QOS)],
                    "/odd": [Endpoint("/lost", "/odd", "nobody_msgs/msg/Odd", b"", QOS)]}
    r.subscribers = {"/image": [Endpoint("/ns/det", "/image", "sensor_msgs/msg/Image", b"", QOS)]}
    return r


def test_build_model_members_edges_tree():
    pids = {"/cam": PidInfo(100, "confirmed"), "/ns/det": PidInfo(100, "confirmed"),
            "/srvnode": PidInfo(200, "confirmed"), "/lost": PidInfo(None, "ambiguous", (5, 65541))}
    procs = {
        1: ProcessReading(1, None, name="init"),
        50: ProcessReading(50, 1, name="launch"),
        100: ProcessReading(100, 50, name="python", metrics={"cpu_percent": 12.5, "rss_mb": 80.0}),
        200: ProcessReading(200, 50, name="python", alive=False, metrics={"cpu_percent": 3.0}),
        7: ProcessReading(7, None, name="other-top"),
    }
    stats = {"/image": TopicStats(True, "", {"rate_hz": 30.0, "jitter_ms": 1.5}),
             "/odd": TopicStats(False, "message type nobody_msgs/msg/Odd is not installed")}
    G = build_model(_reading(), pids, procs, stats)
    assert set(G.nodes) == {
        "node:/cam", "node:/ns/det", "node:/srvnode", "node:/lost", "topic:/image", "topic:/odd",
        "service:/srv", "action:/go", "process:1", "process:50", "process:100", "process:200",
        "process:7", "root",
    }
    assert set(flow_edges(G)) == {
        ("node:/cam", "topic:/image", "pub"), ("topic:/image", "node:/ns/det", "sub"),
        ("node:/ns/det", "node:/srvnode", "send"), ("node:/lost", "topic:/odd", "pub"),
    }
    send = G.edges["node:/ns/det", "node:/srvnode", 0]
    assert send["services"] == ["/srv"] and send["actions"] == ["/go"]
    tree_edges = {(u, v) for u, v, k in G.edges(keys=True) if k == 1}
    assert tree_edges == {
        ("root", "process:1"), ("root", "process:7"), ("process:1", "process:50"),
        ("process:50", "process:100"), ("process:50", "process:200"),
        ("process:100", "node:/cam"), ("process:100", "node:/ns/det"), ("process:200", "node:/srvnode"),
    }
    assert G.nodes["node:/lost"]["pid"] is None
    assert G.nodes["node:/lost"]["pid_status"] == "ambiguous"
    assert G.nodes["node:/lost"]["pid_candidates"] == [5, 65541]
    assert G.nodes["node:/srvnode"]["alive"] is False and G.nodes["node:/cam"]["alive"] is True
    img = theta_dict("topic", G.nodes["topic:/image"]["theta"])
    assert (img["rate_hz"], img["jitter_ms"], img["publishers"], img["subscribers"]) == (30.0, 1.5, 1, 1)
    assert math.isnan(img["latency_ms"])
    assert G.nodes["topic:/odd"]["measured"] is False
    assert "not installed" in G.nodes["topic:/odd"]["reason"]
    assert G.nodes["topic:/image"]["qos"] == [{"node": "/cam", "role": "pub", **QOS},
                                             {"node": "/ns/det", "role": "sub", **QOS}]
    det = theta_dict("node", G.nodes["node:/ns/det"]["theta"])
    assert {k: det[k] for k in ("publishers", "subscriptions", "services", "clients")} == {
        "publishers": 0.0, "subscriptions": 1.0, "services": 0.0, "clients": 1.0}
    assert math.isnan(det["sent_hz"])  # publishes nothing measured
    # The only publisher of /image sent all of its 30 messages/s.
    assert theta_dict("node", G.nodes["node:/cam"]["theta"])["sent_hz"] == 30.0
    assert theta_dict("process", G.nodes["process:100"]["theta"])["cpu_percent"] == 12.5
    assert np.isnan(G.nodes["process:200"]["theta"]).all()  # dead: no metrics
    srv = theta_dict("service", G.nodes["service:/srv"]["theta"])
    assert (srv["servers"], srv["clients"]) == (1.0, 1.0)
    # not introspected: no calls observed
    assert all(math.isnan(srv[k]) for k in ("calls_per_s", "response_ms", "waiting", "wait_s"))
    assert "calls" not in G.nodes["service:/srv"]


def test_build_model_single_top_has_no_root():
    r = GraphReading(nodes={"/a": NodeReading("/a", "a", "/")})
    G = build_model(r, {"/a": PidInfo(10, "confirmed")},
                    {1: ProcessReading(1, None), 10: ProcessReading(10, 1)})
    assert "root" not in G
    assert {(u, v) for u, v, k in G.edges(keys=True) if k == 1} == {("process:1", "process:10"),
                                                                    ("process:10", "node:/a")}


def _both(buf, *args, **kw):
    """`window_metrics` (the definition) and `TopicWindow.metrics` (running sums) on ``buf``: equal."""
    from stream_viz.collect.window import TopicWindow

    w = TopicWindow()
    buf = [(*r, None, None)[:6] for r in buf]  # records without a publisher gid or a message age
    for r in buf:
        w.add(*r)
    want, got = window_metrics(buf, *args, **kw), w.metrics(*args, **kw)
    assert got.keys() == want.keys()
    assert all(got[k] == pytest.approx(want[k], rel=1e-9, abs=1e-9) for k in want), (got, want)
    return want


def test_window_metrics_literal():
    s = 1_000_000_000
    # 5 messages 0.5 s apart over a 3 s window, 1 ms latency, 100 bytes each, seq 1,2,4,5,6.
    buf = [(t * s // 2, t * s // 2 - 1_000_000, 100, q) for t, q in zip(range(1, 6), (1, 2, 4, 5, 6),
                                                                         strict=True)]
    m = _both(buf, now_ns=3 * s, created_ns=0, window_ns=3 * s, n_publishers=1)
    assert m["rate_hz"] == pytest.approx(5 / 3)
    assert m["latency_ms"] == pytest.approx(1.0)
    assert m["jitter_ms"] == pytest.approx(0.0)
    assert m["bandwidth_kBps"] == pytest.approx(500 / 3 / 1000)
    assert m["drops_per_s"] == pytest.approx(1 / 3)
    # Two publishers: drops cannot be attributed; a young subscription: no rate at all.
    assert "drops_per_s" not in _both(buf, 3 * s, 0, 3 * s, n_publishers=2)
    assert _both(buf, 3 * s, int(2.5 * s), 3 * s, 1) == {}
    # Silence after warm-up is a rate of 0, not unknown.
    assert _both([], 3 * s, 0, 3 * s, 1)["rate_hz"] == 0.0
    # The fast signals: the newest came 0.5 s ago; the last 4 intervals (of 5 messages) up to now: 2.5 s.
    assert m["age_s"] == pytest.approx(0.5)
    assert m["rate_recent_hz"] == pytest.approx(4 / 2.5)
    assert "rate_recent_hz" not in _both(buf[:3], 3 * s, 0, 3 * s, 1)  # 2 intervals: too few
    assert "age_s" not in _both([], 3 * s, 0, 3 * s, 1)


def test_window_metrics_recent_rate_sees_a_slowdown_the_window_hides():
    s = 1_000_000_000
    # 10 Hz for 2.5 s, then one message 0.4 s later: the window still says 9 Hz, recent 5.6 Hz.
    recv = [i * s // 10 for i in range(26)] + [29 * s // 10]
    buf = [(r, r, 10, None) for r in recv]
    m = _both(buf, now_ns=3 * s, created_ns=0, window_ns=3 * s, n_publishers=1)
    assert m["rate_hz"] == pytest.approx(27 / 3)
    assert m["rate_recent_hz"] == pytest.approx(5 / 0.9)
    assert m["age_s"] == pytest.approx(0.1)


def test_window_metrics_recent_rate_of_a_fast_topic_spans_half_a_second():
    s = 1_000_000_000
    # 500 Hz (2 ms apart) for 3 s, the publisher held up 30 ms just before now: the last 5 intervals
    # say ~150 Hz; over the last 0.5 s (RECENT_NS) the rate is ~470 Hz.
    recv = [i * 2_000_000 for i in range(1485)]
    buf = [(r, r, 10, None) for r in recv]
    now = recv[-1] + 30_000_000
    m = _both(buf, now_ns=now, created_ns=0, window_ns=3 * s, n_publishers=1)
    inside = sum(1 for r in recv if r > now - s // 2)
    assert m["rate_recent_hz"] == pytest.approx(inside / ((now - recv[-1 - inside]) / 1e9))
    assert 440 < m["rate_recent_hz"] < 500
    # Stopped for 0.6 s: nothing in the last 0.5 s, so the last 5 intervals again: it shows at once.
    m = _both(buf, now_ns=recv[-1] + 600_000_000, created_ns=0, window_ns=3 * s, n_publishers=1)
    assert m["rate_recent_hz"] == pytest.approx(5 / 0.610)


def test_log_events():
    nodes = {"/ns/talker", "/cam"}
    assert logger_node("ns.talker", nodes) == "/ns/talker"
    assert logger_node("ns.talker.child", nodes) == "/ns/talker"
    assert logger_node("ghost", nodes) == "/ghost"
    warn = Log(level=30, name="ns.talker", msg="low", stamp=Time(sec=5, nanosec=500_000_000))
    ev = log_event(warn, nodes)
    assert (ev.kind, ev.member, ev.level, ev.text, ev.t) == ("log", "node:/ns/talker", "warn", "low", 5.5)
    assert log_event(Log(level=50, name="cam", msg="x"), nodes).level == "fatal"
    assert log_event(Log(level=20, name="cam", msg="fine"), nodes) is None


def test_diag_events_member_and_levels():
    from stream_viz.collect.diagnostics import DiagnosticsReader
    from stream_viz.collect.naming import NodeNames

    msg = DiagnosticArray(status=[
        DiagnosticStatus(level=DiagnosticStatus.ERROR, name="cam: driver", hardware_id="usb1",
                         values=[KeyValue(key="fps", value="0")]),
        DiagnosticStatus(level=DiagnosticStatus.OK, name="other", hardware_id="hw"),
        DiagnosticStatus(level=DiagnosticStatus.STALE, name="nobody", hardware_id="x"),
    ])
    index = NodeNames({"/cam", "/agg"})
    evs = DiagnosticsReader().events("/diagnostics", msg, 1.0, None, index)  # publisher unknown
    assert [(e.member, e.level) for e in evs] == [
        ("node:/cam", "error"), ("topic:/diagnostics", "info"), ("topic:/diagnostics", "warn")]
    assert evs[0].data == {"name": "cam: driver", "hardware_id": "usb1", "level": 2, "values": {"fps": "0"},
                           "mapped_by": "name", "source": "/diagnostics", "publisher": None}
    # Published by /agg: the status that names /cam stays on /cam, the others go to /agg.
    by_agg = DiagnosticsReader().events("/diagnostics", msg, 1.0, "/agg", index)
    assert [(e.member, e.data["mapped_by"]) for e in by_agg] == [
        ("node:/cam", "name"), ("node:/agg", "publisher"), ("node:/agg", "publisher")]


def test_drain_period_lets_the_fastest_topic_fill_a_quarter_of_its_queue():
    from stream_viz.collect.topics import drain_period

    assert drain_period(0, 0.25, 1000, 0.02, 0.25) == 0.25  # nothing arrived: drain rarely
    assert drain_period(10, 0.25, 1000, 0.02, 0.25) == 0.25  # 40 Hz: 250 messages take 6 s
    assert drain_period(1000, 0.1, 1000, 0.02, 0.25) == 0.025  # 10 kHz: 250 messages in 25 ms
    assert drain_period(5000, 0.1, 1000, 0.02, 0.25) == 0.02  # faster still: the shortest
    assert drain_period(5, 0.0, 1000, 0.02, 0.25) == 0.25


class _Info:
    def __init__(self, name: str, gid: int) -> None:
        self.node_name, self.node_namespace, self.topic_type = name, "/", "rcl_interfaces/msg/Log"
        self.endpoint_gid, self.qos_profile = [gid] * 16, qos_profile_unknown


class _GraphNode:
    """Answers the graph calls GidCache makes (/rosout's publishers, /parameter_events'); counts
    them (``calls``: /rosout, ``param_calls``: /parameter_events)."""

    def __init__(self) -> None:
        self.pubs: dict[str, int] = {}
        self.params: dict[str, int] = {}
        self.calls = self.param_calls = 0

    def get_publishers_info_by_topic(self, topic: str) -> list[_Info]:
        assert topic in ("/rosout", "/parameter_events")
        if topic == "/parameter_events":
            self.param_calls += 1
            return [_Info(n.lstrip("/"), g) for n, g in self.params.items()]
        self.calls += 1
        return [_Info(n.lstrip("/"), g) for n, g in self.pubs.items()]


def _nodes(*names: str) -> dict[str, NodeReading]:
    return {n: NodeReading(n, n.lstrip("/"), "/") for n in names}


def test_gid_cache_reads_the_graph_only_when_due():
    from stream_viz.collect.rosgraph import GidCache

    g, cache = _GraphNode(), GidCache(every_s=5.0, settle_s=3.0)
    g.pubs = {"/a": 1, "/b": 2}
    assert cache.get(g, _nodes("/a", "/b"), 0.0) == {"/a": bytes([1] * 16), "/b": bytes([2] * 16)}
    for t in (1.0, 2.0, 4.9):  # nothing changed: no graph call
        cache.get(g, _nodes("/a", "/b"), t)
    assert g.calls == 1
    assert cache.get(g, _nodes("/a"), 5.0 - 1e-9) == {"/a": bytes([1] * 16)}  # a node left: filtered
    assert g.calls == 1
    cache.get(g, _nodes("/a", "/b"), 5.0)  # every_s passed
    assert g.calls == 2
    # A new node whose /rosout publisher is not discovered yet: read each call while settling.
    cache.get(g, _nodes("/a", "/b", "/c"), 6.0)
    cache.get(g, _nodes("/a", "/b", "/c"), 7.0)
    assert g.calls == 4
    g.pubs["/c"] = 3
    assert cache.get(g, _nodes("/a", "/b", "/c"), 8.0)["/c"] == bytes([3] * 16)
    assert g.calls == 5
    cache.get(g, _nodes("/a", "/b", "/c"), 8.5)  # complete again: no call
    assert g.calls == 5
    assert g.param_calls == 2  # /parameter_events only while a node had no /rosout gid (6.0, 7.0)
    # A node that never gets a gid (enable_rosout=False) is not re-read for after settling.
    cache.get(g, _nodes("/a", "/b", "/c", "/quiet"), 9.0)
    for t in (10.0, 11.0, 11.9):
        cache.get(g, _nodes("/a", "/b", "/c", "/quiet"), t)
    assert g.calls == 9
    for t in (12.0, 13.0):
        cache.get(g, _nodes("/a", "/b", "/c", "/quiet"), t)
    assert g.calls == 9
    # A process exited: the next call reads (a node may be back under its name, new gid).
    g.pubs["/a"] = 7
    cache.invalidate()
    assert cache.get(g, _nodes("/a", "/b", "/c", "/quiet"), 13.5)["/a"] == bytes([7] * 16)
    assert g.calls == 10
    # ... and is known by its /parameter_events publisher where it has one
    g.params["/quiet"] = 9
    cache.invalidate()
    assert cache.get(g, _nodes("/a", "/b", "/c", "/quiet"), 14.0)["/quiet"] == bytes([9] * 16)
    assert g.param_calls == 8


def test_parse_proc_stat_and_fields():
    from stream_viz.collect.processes import CLK_TCK, PAGE, parse_fields, parse_stat

    # proc(5): the name is in parentheses and may itself hold spaces and parentheses.
    line = (b"4242 (my (odd) name) S 17 4242 4242 0 -1 4194560 900 0 0 0 250 50 0 0 20 0 7 0 "
            b"123456 1000000 3000 18446744073709551615 1 1 0 0 0 0 0 0 0 0 0 0 17 1 0 0 0 0 0\n")
    st = parse_stat(line)
    assert st == (("S", 17, 300 / CLK_TCK, 7, 123456, 3000 * PAGE))
    status = b"Name:\tx\nvoluntary_ctxt_switches:\t15\nnonvoluntary_ctxt_switches:\t4\n"
    assert parse_fields(status, (b"voluntary_ctxt_switches", b"nonvoluntary_ctxt_switches")) == (15, 4)
    io = b"rchar: 1\nwchar: 2\nread_bytes: 4096\nwrite_bytes: 8192\ncancelled_write_bytes: 0\n"
    assert parse_fields(io, (b"read_bytes", b"write_bytes")) == (4096, 8192)


def test_read_file_returns_a_whole_file_longer_than_one_chunk_and_a_proc_file(tmp_path):
    from stream_viz.collect.processes import CHUNK, read_file

    long = tmp_path / "long"
    long.write_bytes(bytes(range(256)) * (2 * CHUNK // 256 + 3))
    assert read_file(str(long)) == long.read_bytes()
    exact = tmp_path / "exact"  # a last read of a full chunk, then an empty one
    exact.write_bytes(b"x" * CHUNK)
    assert read_file(str(exact)) == b"x" * CHUNK
    assert read_file("/proc/self/status").startswith(b"Name:")
    with pytest.raises(FileNotFoundError):
        read_file(str(tmp_path / "none"))


def test_topic_window_running_sums_equal_a_fresh_computation():
    from stream_viz.collect.window import TopicWindow

    rng = np.random.default_rng(7)
    s, w, held = 1_000_000_000, TopicWindow(), []
    t, seq = 10 * s, 0
    for step in range(400):
        for _ in range(int(rng.integers(0, 12))):  # a burst of arrivals, sometimes a lost one
            t += int(rng.integers(1_000_000, 200_000_000))
            seq += 1 + int(rng.random() < 0.1)
            rec = (t, t - int(rng.integers(0, 5_000_000)), int(rng.integers(0, 60_000)),
                   None if 150 <= step < 170 else seq,
                   None if step % 7 == 0 else bytes([int(rng.integers(0, 3))]) * 16,  # 3 publishers
                   None if step % 5 == 0 else int(rng.integers(-1_000_000, 400_000_000)))  # ages
            w.add(*rec)
            held.append(rec)
        now = t + int(rng.integers(0, s))
        w.expire(now - 3 * s)
        held = [r for r in held if r[0] >= now - 3 * s]
        assert list(w.buf) == held
        got, want = w.metrics(now, 0, 3 * s, 1), window_metrics(held, now, 0, 3 * s, 1)
        assert got.keys() == want.keys(), step
        per_gid = Counter(r[4] for r in held if r[4] is not None)
        assert w.publisher_rates(now, 0, 3 * s) == {g: n / 3 for g, n in per_gid.items()}, step
        aged = [(r[4], r[5]) for r in held if r[4] is not None and r[5] is not None]
        want_ages = {g: np.mean([a for h, a in aged if h == g]) / 1e6 for g in {h for h, _ in aged}}
        assert w.publisher_ages() == pytest.approx(want_ages, rel=1e-9), step
        for k in want:
            assert got[k] == pytest.approx(want[k], rel=1e-9, abs=1e-9), (step, k)


def _statuses(*goals: tuple[int, int]):
    from action_msgs.msg import GoalStatus, GoalStatusArray

    msg = GoalStatusArray()
    for uid, status in goals:
        s = GoalStatus(status=status)
        s.goal_info.goal_id.uuid = [uid] * 16
        msg.status_list.append(s)
    return msg


def test_goal_tracker_an_event_per_goal_that_ended_since_the_last_array():
    from stream_viz.collect.goals import GoalTracker

    g, topic = GoalTracker(), "/nav/follow/_action/status"
    # The first array lists a goal that ended before we looked: no time for its end, no event.
    assert g.events(topic, _statuses((1, 4)), 1_000_000_000, ["/nav/controller"]) == []
    assert g.events(topic, _statuses((1, 4), (2, 2)), 2_000_000_000, ["/nav/controller"]) == []  # executing
    (e,) = g.events(topic, _statuses((1, 4), (2, 6)), 3_500_000_000, ["/nav/controller"])
    assert (e.t, e.kind, e.member, e.level) == (3.5, "goal", "node:/nav/controller", "info")
    assert e.data == {"action": "/nav/follow", "goal": "02" * 16, "status": "aborted"}
    assert g.events(topic, _statuses((2, 6)), 4_000_000_000, ["/nav/controller"]) == []  # unchanged
    g.forget(set())
    assert g.events(topic, _statuses((3, 5)), 5_000_000_000, ["/nav/controller"]) == []  # first again


def test_goal_tracker_keeps_since_when_a_goal_executes_and_its_newest_feedback():
    from stream_viz.collect.goals import GoalTracker

    g, topic, fb = GoalTracker(), "/nav/follow/_action/status", "/nav/follow/_action/feedback"
    g.events(topic, _statuses((1, 1)), 1_000_000_000, ["/nav/controller"])  # accepted, not executing
    assert g.executing_since == {}
    g.events(topic, _statuses((1, 2)), 2_000_000_000, ["/nav/controller"])
    g.events(topic, _statuses((1, 2), (2, 2)), 3_000_000_000, ["/nav/controller"])  # a second one
    assert g.executing_since == {"/nav/follow": 2.0}
    g.fed(fb, 2.5)
    g.fed(fb, 2.4)  # an older newest (another window's): the newest stays
    assert g.feedback == {"/nav/follow": 2.5}
    g.events(topic, _statuses((1, 4), (2, 6)), 4_000_000_000, ["/nav/controller"])  # both ended
    assert g.executing_since == {} and g.feedback == {"/nav/follow": 2.5}
    g.events(topic, _statuses((3, 2)), 5_000_000_000, ["/nav/controller"])
    assert g.executing_since == {"/nav/follow": 5.0}
    g.forget(set())  # the server is gone
    assert g.executing_since == {} and g.feedback == {}


def test_import_type_finds_an_actions_feedback_message():
    from test_msgs.action import Fibonacci

    from stream_viz.collect.topics import import_type

    assert import_type("test_msgs/action/Fibonacci_FeedbackMessage") is Fibonacci.Impl.FeedbackMessage
    with pytest.raises(AttributeError, match="Nope"):
        import_type("test_msgs/action/Nope_FeedbackMessage")


def test_a_main_thread_dispatches_when_it_outworks_two_others_five_times():
    from stream_viz.collect.processes import dispatches

    # rclpy's multi-threaded executor at a light load, over 30 s (pid 1): its main thread 5 % of a
    # core, its two workers 0.3 % each; in a dispatch spin over 1 s, main 97 %, workers 0.8 % and
    # 0.3 % (under 1 % of the main thread's CPU, still over 0.1 % of a core).
    assert dispatches({}, {1: 1_500_000_000, 5: 90_000_000, 6: 90_000_000}, 30.0, 1)
    assert dispatches({1: 0, 5: 0, 6: 0}, {1: 970_000_000, 5: 8_000_000, 6: 3_000_000}, 1.0, 1)
    # Workers that do the work (main 3 %, workers 30 % each): the main thread does not dispatch.
    assert not dispatches({}, {1: 30_000_000, 5: 300_000_000, 6: 300_000_000}, 1.0, 1)
    # A runaway thread beside the main thread's executor is busier than the main thread.
    assert not dispatches({}, {1: 100_000_000, 5: 1_000_000_000, 6: 2_000_000}, 1.0, 1)
    # One other thread that ran (a single-threaded executor and a helper thread) is no pool; nor
    # is a second under 0.1 % of a core (a sleeper that woke).
    assert not dispatches({}, {1: 1_500_000_000, 5: 90_000_000}, 30.0, 1)
    assert not dispatches({}, {1: 970_000_000, 5: 8_000_000, 6: 900_000}, 1.0, 1)
    # The main thread did not run (the executor spun in another thread).
    assert not dispatches({}, {1: 0, 2: 1_500_000_000, 5: 90_000_000, 6: 90_000_000}, 30.0, 1)
    # 4.9x is not 5x.
    assert not dispatches({}, {1: 49_000_000, 5: 10_000_000, 6: 9_000_000}, 1.0, 1)


def test_a_dispatcher_seen_twice_still_dispatches_while_its_main_thread_leads(monkeypatch, tmp_path):
    from stream_viz.collect import processes
    from stream_viz.collect.processes import _probe_threads, _Tracked, leads

    assert leads({1: 0, 5: 0}, {1: 450_000_000, 5: 170_000_000}, 1)
    assert not leads({1: 0, 5: 0, 6: 0}, {1: 200_000_000, 5: 1_000_000_000, 6: 1_000}, 1)
    assert not leads({}, {1: 0, 5: 0}, 1)  # nothing ran
    # Probes of a process (pid 1) read from a fake /proc: the thread CPU times (ns) after each.
    light = {1: 970_000_000, 5: 8_000_000, 6: 3_000_000}  # main dispatching, two workers
    starved = {1: 450_000_000, 5: 170_000_000, 6: 0}  # one worker ran, main 2.6x it
    runaway = {1: 200_000_000, 5: 1_000_000_000, 6: 0}
    steps, at = [], {1: 0, 5: 0, 6: 0}
    monkeypatch.setattr(processes.os, "listdir", lambda path: ["1", "5", "6"])
    monkeypatch.setattr(processes, "read_file", lambda path: b"python")
    monkeypatch.setattr(processes, "_thread_ns", lambda pid, tid: at[tid])
    clock = iter(float(i) for i in range(100))
    monkeypatch.setattr(processes.time, "monotonic", lambda: next(clock))

    def probe(tr, used):
        for tid, ns in used.items():
            at[tid] += ns
        _probe_threads(1, tr)
        steps.append(tr.dispatching)

    tr = _Tracked(proc=None, info=None)
    probe(tr, {1: 0, 5: 0, 6: 0})  # the first probe: nothing to compare with
    for used in (starved, light, starved, light, starved, runaway, starved):
        probe(tr, used)
    assert steps[1:] == [0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0]


def test_threads_that_ran_are_above_a_core_share_and_a_share_of_the_busiest():
    from stream_viz.collect.processes import threads_that_ran

    before = {1: 1_000_000_000, 2: 5_000_000, 3: 0}
    # The executor worked 0.4 s; the main thread woke once (1.5 ms: over the core floor of 1 ms).
    assert threads_that_ran(before, {1: 1_400_000_000, 2: 6_500_000, 3: 0}, 1.0) == [1]
    # Two executor threads sharing the work both ran; a thread new since `before` counts from 0.
    assert threads_that_ran(before, {1: 1_300_000_000, 2: 255_000_000, 4: 30_000_000}, 1.0) == [
        1, 2, 4]
    # An rclpy multi-threaded executor at a light load, over 30 s: its main thread dispatches (5 % of
    # a core on a loaded machine), its two workers run the callbacks (0.2 % each): all three ran.
    assert threads_that_ran({}, {1: 1_500_000_000, 5: 60_000_000, 6: 60_000_000}, 30.0) == [1, 5, 6]
    # Nothing over 0.1 % of a core over 2 s: none ran.
    assert threads_that_ran(before, {1: 1_001_500_000, 2: 5_100_000}, 2.0) == []
    assert threads_that_ran({}, {}, 1.0) == []


def test_a_guid_pid_is_matched_against_each_process_s_own_pid():
    from stream_viz.collect.pidmap import candidates

    # ours → its own: 9736 is pid 7 in a container; 65543 has the low bits of 7 (a GUID keeps 16)
    inner = {1: 1, 7: 7, 9736: 7, 65543: 65543, 4242: 4242}
    assert candidates(7, inner) == [7, 9736, 65543]
    assert candidates(7, inner, exclude=7) == [9736, 65543]
    assert candidates(1, inner) == [1]
    assert candidates(4242, inner) == [4242]
    assert candidates(99, inner) == []


def test_with_a_discovery_server_the_observer_is_a_super_client_unless_told_not():
    from stream_viz.collect.collector import observe_as_super_client

    env = {"ROS_DOMAIN_ID": "3"}
    assert observe_as_super_client(env) and env == {"ROS_DOMAIN_ID": "3"}  # no server: untouched
    env = {"ROS_DISCOVERY_SERVER": "127.0.0.1:11811"}
    assert observe_as_super_client(env) and env["ROS_SUPER_CLIENT"] == "TRUE"
    env = {"ROS_DISCOVERY_SERVER": "127.0.0.1:11811", "ROS_SUPER_CLIENT": "False"}
    assert not observe_as_super_client(env) and env["ROS_SUPER_CLIENT"] == "False"  # the user's
    env = {"ROS_DISCOVERY_SERVER": " ", "ROS_SUPER_CLIENT": "False"}
    assert observe_as_super_client(env)  # set but empty: no server


def test_instances_are_the_listed_names_no_more_than_their_participants():
    from stream_viz.collect.build import instances

    assert instances(2, 1) == 1  # a ghost entry beside the node restarted under its name
    assert instances(2, 2) == 2  # two live processes, one name
    assert instances(2, 0) == 2  # no /rosout nor /parameter_events gid known: the listing
    assert instances(1, 0) == 1
