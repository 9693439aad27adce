"""The samples file on literal samples: the delta records, real files read back, a SIGKILLed
writer, cut and foreign files, and a replay through the real monitor."""

from __future__ import annotations

import gzip
import json
import signal
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from stream_viz.collect.replay import ReplayCollector
from stream_viz.collect.samples_file import (
    FORMAT,
    SampleDecoder,
    SampleEncoder,
    SamplesReader,
    SamplesWriter,
    read_samples,
)
from stream_viz.config import Config
from stream_viz.errors import CollectError, SamplesError
from stream_viz.model.diff import diff
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.theta import SCHEMAS, make_theta
from stream_viz.records import Event, Sample


def _graph(rate: float, extra: bool = False, pid: int = 10, latency: float = float("nan")):
    G = new_graph()
    add_member(G, "process:10", pid=10, alive=True, theta=make_theta("process", {"cpu_percent": 5.0}))
    add_member(G, "node:/cam", pid=pid, qos=[{"node": "/cam", "depth": 10}])
    add_member(G, "topic:/img", theta=make_theta("topic", {"rate_hz": rate, "latency_ms": latency}))
    add_flow_edge(G, "node:/cam", "topic:/img", "pub")
    add_tree_edge(G, "process:10", "node:/cam")
    if extra:
        add_member(G, "node:/det", pid=10)
        add_flow_edge(G, "topic:/img", "node:/det", "sub")
    return G


def _samples() -> list[Sample]:
    log = Event(101.5, "log", "node:/cam", "error", "boom", {"logger": "cam", "line": 3})
    graphs = [_graph(10.0), _graph(10.0), _graph(9.0, pid=11), _graph(9.0, extra=True)]
    for G, version in zip(graphs, (0, 0, 0, 1), strict=True):
        G.graph["qos_version"] = version  # a QoS changed in place at the last
    out, prev = [], new_graph()
    for i, G in enumerate(graphs):
        out.append(Sample(100.0 + i, G, [log] if i == 1 else [], diff(prev, G),
                          {"topic:/img": "no messages"} if i >= 2 else {}))
        prev = G
    return out


def _same(a: Sample, b: Sample) -> None:
    assert b.t == a.t and b.events == a.events and b.unreadable == a.unreadable and b.diff == a.diff
    assert b.graph.graph == a.graph.graph
    assert list(b.graph.nodes) == list(a.graph.nodes)
    assert list(b.graph.edges(keys=True, data=True)) == list(a.graph.edges(keys=True, data=True))
    for m, attrs in a.graph.nodes(data=True):
        got = b.graph.nodes[m]
        plain = {k: v for k, v in attrs.items() if k != "theta"}
        assert {k: v for k, v in got.items() if k != "theta"} == plain
        assert ("theta" in got) == ("theta" in attrs)
        if "theta" in attrs:
            np.testing.assert_array_equal(got["theta"], attrs["theta"])  # NaN where NaN


def test_records_carry_only_what_changed_and_decode_to_the_samples():
    samples = _samples()
    enc = SampleEncoder()
    recs = [json.loads(json.dumps(enc.encode(s))) for s in samples]
    assert set(recs[0]) == {"t", "graph", "theta", "graph_attrs"}
    assert [m for m, _ in recs[0]["graph"]["members"]] == ["process:10", "node:/cam", "topic:/img"]
    assert recs[0]["graph"]["edges"] == [["process:10", "node:/cam", 1, {"kind": "tree"}],
                                         ["node:/cam", "topic:/img", 0, {"kind": "pub"}]]
    assert recs[0]["theta"]["topic:/img"][:3] == [10.0, None, None]  # NaN is null
    # same structure, same θ: only the time and the event
    assert recs[1] == {"t": 101.0, "events": [[101.5, "log", "node:/cam", "error", "boom",
                                               {"logger": "cam", "line": 3}]]}
    # one attribute and one θ changed; the unreadable members changed
    assert set(recs[2]) == {"t", "attrs", "theta", "unreadable"}
    assert recs[2]["attrs"] == {"node:/cam": {"kind": "node", "active": True, "label": "/cam", "pid": 11,
                                              "qos": [{"node": "/cam", "depth": 10}]}}
    assert list(recs[2]["theta"]) == ["topic:/img"]
    # a new member: the graph in full again, every θ with it; unreadable unchanged
    assert set(recs[3]) == {"t", "graph", "theta", "graph_attrs"}
    assert set(recs[3]["theta"]) == {"process:10", "topic:/img"}
    assert recs[3]["graph_attrs"] == {"qos_version": 1}
    dec = SampleDecoder()
    for s, r in zip(samples, recs, strict=True):
        _same(s, dec.decode(r))


def test_theta_that_goes_away_is_removed():
    a, b = _graph(10.0), _graph(10.0)
    del b.nodes["topic:/img"]["theta"]
    enc, dec = SampleEncoder(), SampleDecoder()
    dec.decode(enc.encode(Sample(1.0, a)))
    rec = enc.encode(Sample(2.0, b))
    assert rec["theta"] == {"topic:/img": None}
    assert "theta" not in dec.decode(rec).graph.nodes["topic:/img"]


def test_theta_of_another_schema_is_mapped_by_name():
    """A file written when a kind's θ had other attributes, or in another order."""
    topic = SCHEMAS["topic"]
    old = {"topic": [topic[1], topic[0], "retired_hz"], "process": list(SCHEMAS["process"])}
    dec = SampleDecoder(old)
    members = [["topic:/img", {"kind": "topic"}], ["process:10", {"kind": "process"}]]
    rec = {"t": 1.0, "graph": {"members": members, "edges": []},
           "theta": {"topic:/img": [2.5, 10.0, 7.0], "process:10": [1.0] * len(SCHEMAS["process"])}}
    G = dec.decode(rec).graph
    want = np.full(len(topic), np.nan)
    want[0], want[1] = 10.0, 2.5
    np.testing.assert_array_equal(G.nodes["topic:/img"]["theta"], want)
    np.testing.assert_array_equal(G.nodes["process:10"]["theta"], [1.0] * len(SCHEMAS["process"]))


def test_file_round_trip_with_header_and_notes(tmp_path):
    path = tmp_path / "s.jsonl.gz"
    w = SamplesWriter(path, {"stream_viz": "0.1.0", "started_at": 99.0})
    for s in _samples():
        w.write(s)
    w.note("end", {"ended_at": 104.0, "injected": {"fault": "crash"}})
    w.close()
    with gzip.open(path, "rt") as f:
        assert json.loads(f.readline()) == {"format": FORMAT, "stream_viz": "0.1.0", "started_at": 99.0,
                                            "theta": {k: list(v) for k, v in SCHEMAS.items()}}
    header, got, notes = read_samples(path)
    assert header["started_at"] == 99.0
    assert notes == {"end": {"ended_at": 104.0, "injected": {"fault": "crash"}}}
    for a, b in zip(_samples(), got, strict=True):
        _same(a, b)


WRITER = textwrap.dedent("""
    import sys
    from tests.unit.test_samples_file import _samples
    from stream_viz.collect.samples_file import SamplesWriter
    w = SamplesWriter(sys.argv[1], {})
    for s in _samples()[:3]:
        w.write(s)
    print('written', flush=True)
    sys.stdin.readline()  # killed here
""")


def test_a_killed_writer_leaves_every_complete_sample(tmp_path):
    path = tmp_path / "s.jsonl.gz"
    p = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], stdin=subprocess.PIPE,
                         stdout=subprocess.PIPE, text=True)
    try:
        assert p.stdout.readline().strip() == "written"
        p.send_signal(signal.SIGKILL)
        p.wait(10)
    finally:
        p.kill()
    with SamplesReader(path) as reader:
        got = list(reader)
        assert reader.truncated
    assert [s.t for s in got] == [100.0, 101.0, 102.0]
    _same(_samples()[2], got[2])


def test_a_file_cut_anywhere_reads_up_to_its_last_complete_sample(tmp_path):
    path = tmp_path / "s.jsonl"
    enc = SampleEncoder()
    lines = [json.dumps({"format": FORMAT})] + [json.dumps(enc.encode(s)) for s in _samples()]
    text = "\n".join(lines) + "\n"
    path.write_text(text[: len(text) - 10])  # plain JSON lines, the last one cut short
    with SamplesReader(path) as reader:
        assert [s.t for s in reader] == [100.0, 101.0, 102.0]
        assert reader.truncated
    data = gzip.compress(text.encode())
    (tmp_path / "cut.gz").write_bytes(data[: len(data) // 2])
    with SamplesReader(tmp_path / "cut.gz") as reader:
        n = len(list(reader))
        assert reader.truncated and n < 4


@pytest.mark.parametrize(
    ("content", "message"),
    [
        (b"", "empty, not a stream-viz samples file"),
        (b"\x89PNG\r\n\x1a\n\x00\x00", "line 1: not a stream-viz samples file"),
        (b'{"a": 1}\n', "line 1: not a stream-viz samples file (no header)"),
        (b'{"format": "stream-viz.samples/v9"}\n', "line 1: samples format 'stream-viz.samples/v9'"),
        (b'{"format": "stream-viz.samples/v1"}\n{"t": 1, "graph": {"members": [], "edges": []}}\nnot json\n',
         "line 3: not a sample record"),
        (b'{"format": "stream-viz.samples/v1"}\n{"t": 1, "graph": {"members": [], "edges": []}}\n'
         b'{"t": 2, "theta": {"topic:/x": [1.0]}}\n', "line 3: not a sample record (KeyError"),
        (b'{"format": "stream-viz.samples/v1"}\n{"graph": {}}\n', "line 2: not a sample record"),
        (b'{"format": "stream-viz.samples/v1", "theta": ["rate_hz"]}\n', "line 1: a malformed header"),
    ],
)
def test_foreign_and_broken_files_name_the_file_and_line(tmp_path, content, message):
    path = tmp_path / "bad.jsonl.gz"
    path.write_bytes(gzip.compress(content) if content.startswith(b"{") else content)
    with pytest.raises(SamplesError) as err:
        read_samples(path)
    assert str(err.value).startswith(str(path)) and message in str(err.value), str(err.value)


def test_a_missing_file_is_a_samples_error(tmp_path):
    with pytest.raises(SamplesError, match=r"missing\.jsonl\.gz: cannot read"):
        ReplayCollector(tmp_path / "missing.jsonl.gz")


def _gone_run() -> list[Sample]:
    """/cam's process dies at t = 105; DDS still lists the node, not alive."""
    out, prev = [], new_graph()
    for i in range(10):
        G = _graph(10.0, extra=True)
        if i >= 5:
            G.nodes["node:/cam"]["alive"] = G.nodes["process:10"]["alive"] = False
            G.nodes["topic:/img"]["theta"] = make_theta("topic", {"rate_hz": 0.0})
        out.append(Sample(100.0 + i, G, [], diff(prev, G)))
        prev = G
    return out


def write_file(path, samples: list[Sample]):
    """``samples`` written to a samples file at ``path`` (started at 99 s); return the path."""
    w = SamplesWriter(path, {"started_at": 99.0})
    for s in samples:
        w.write(s)
    w.close()
    return path


def test_the_replay_collector_returns_the_samples_then_stops(tmp_path):
    path = write_file(tmp_path / "s.jsonl.gz", _gone_run())
    source = ReplayCollector(path)
    source.start()
    assert source.header["started_at"] == 99.0
    ts = []
    while not source.done:
        assert source.next_t == 100.0 + len(ts)
        ts.append(source.sample().t)
    assert ts == [100.0 + i for i in range(10)] and source.next_t is None and not source.truncated
    with pytest.raises(CollectError, match="no samples left"):
        source.sample()
    source.close()


def test_a_replay_through_the_monitor_is_the_same_each_time(tmp_path):
    from stream_viz.monitor import Monitor

    path = write_file(tmp_path / "s.jsonl.gz", _gone_run())
    reports = []
    for i in range(2):
        source = ReplayCollector(path)
        mon = Monitor(Config(), db=tmp_path / f"{i}.sqlite", collector=source, started_at=99.0)
        t0 = time.monotonic()
        while not source.done:
            mon.step()
        reports.append(mon.close(ended_at=110.0))
        assert time.monotonic() - t0 < 30  # as fast as it goes: no waiting for the period
    live = reports[0]
    assert live["started_at"] == 99.0 and live["ended_at"] == 110.0
    assert any(a["member"] == "node:/cam" and a["plugin"] == "member_gone" for a in live["alerts"])
    assert live["root_causes"] and live["root_causes"][0]["member"] == "node:/cam"
    assert reports[1] == live
