"""What the recording leaves out to stay small, and that the viewer still shows it (issue 18):
θ rounded to what a person reads, runs of equal θ rows sent as their ends, /system per RCA
iteration logged as what changed. Pure functions, then real .rrd files read back."""

from __future__ import annotations

import numpy as np

from stream_viz.model.theta import make_theta
from stream_viz.records import Alert
from stream_viz.viz import paths
from stream_viz.viz.health import FileEvents
from stream_viz.viz.metrics import MANTISSA_BITS, MetricBatch, quantise, run_ends
from stream_viz.viz.recorder import Recorder
from stream_viz.viz.system import changed_fields
from tests.viz.rrd import rows, shown
from tests.viz.test_recording import T0, robot


def test_quantise_keeps_what_a_person_reads():
    rng = np.random.default_rng(7)
    x = np.concatenate([rng.lognormal(0, 4, 10_000), -rng.lognormal(0, 4, 1000)])
    q = quantise(x)
    assert np.all(np.abs(q - x) <= np.abs(x) * 2.0 ** -(MANTISSA_BITS + 1))
    # Three significant digits read the same, unless within the error of a rounding boundary of
    # the 3rd digit (at most 2**-13 of 1000 units of that digit: 0.13 of one).
    far = np.abs((np.abs(x) / 10 ** (np.floor(np.log10(np.abs(x))) - 2)) % 1 - 0.5) > 0.13
    assert [f"{v:.3g}" for v in q[far]] == [f"{v:.3g}" for v in x[far]]
    # Counts, zeros and the usual round values are exact; NaN and infinities stay.
    exact = np.array([0.0, 1.0, 2.0, 3.0, 60.0, 100.0, 1000.0, 4096.0, 0.5, -7.0])
    assert np.array_equal(quantise(exact), exact)
    odd = quantise(np.array([np.nan, np.inf, -np.inf]))
    assert np.isnan(odd[0]) and odd[1] == np.inf and odd[2] == -np.inf
    assert quantise(np.array([0.99999999]))[0] == 1.0  # rounds up across the exponent


def test_quantise_leaves_the_callers_rows_alone():
    x = np.array([[1.2345678, 2.0]])
    quantise(x)
    assert x[0, 0] == 1.2345678


def test_run_ends_keeps_the_ends_of_runs_of_equal_rows():
    nan = np.nan
    xs = np.array([[1, nan], [1, nan], [1, nan], [2, nan], [2, nan], [3, 0], [3, 0], [3, 0]])
    assert run_ends(xs).tolist() == [True, False, True, True, True, True, False, True]
    assert run_ends(xs[:2]).tolist() == [True, True]
    assert run_ends(np.ones((1, 3))).tolist() == [True]
    noisy = np.arange(12.0).reshape(6, 2)
    assert run_ends(noisy).all()


def test_a_batch_sends_the_viewer_its_rows_once_and_the_file_all_of_them():
    b = MetricBatch()
    for i in range(3):
        b.add(T0 + i, robot(rate=float(i)))
    assert b.columns(unsent=True)["topic:/image"][0].tolist() == [T0, T0 + 1, T0 + 2]
    b.mark_sent()
    assert b.columns(unsent=True) == {} and b.unsent_t is None
    b.add(T0 + 3, robot(rate=3.0))
    assert b.columns(unsent=True)["topic:/image"][0].tolist() == [T0 + 3]
    ts, xs = b.columns()["topic:/image"]
    assert ts.tolist() == [T0 + i for i in range(4)] and xs[:, 0].tolist() == [0.0, 1.0, 2.0, 3.0]
    for i in range(4, 40):  # grows past its first block
        b.add(T0 + i, robot(rate=float(i)))
    assert b.columns()["topic:/image"][1][:, 0].tolist() == [float(i) for i in range(40)]


def test_a_constant_metric_is_still_shown_at_every_time(tmp_path):
    """A process whose θ does not change for 8 samples, a topic whose rate steps at sample 6: the
    file holds the ends of each run, and the viewer's latest-at finds the value at every time."""
    rrd = tmp_path / "const.rrd"
    samples = []
    for i in range(10):
        G = robot(rate=10.0 if i < 6 else 20.0)
        G.nodes["process:10"]["theta"] = make_theta("process", {"cpu_percent": 12.3456789, "rss_mb": 100.0})
        samples.append((T0 + i, G))
    with Recorder(save=rrd) as r:
        r.metrics(samples)
    data = rows(rrd)
    proc = [row for row in data["/metrics/process/10/theta"] if "Scalars:scalars" in row]
    assert [row["time"] // 10**9 - int(T0) for row in proc] == [0, 9]  # the run's two ends
    topic = [row for row in data["/metrics/topic/image/theta"] if "Scalars:scalars" in row]
    # The step stays a step: 10 Hz up to sample 5 (its last row is sent), 20 Hz from sample 6.
    assert [(row["time"] // 10**9 - int(T0), row["Scalars:scalars"][0]) for row in topic] == [
        (0, 10.0), (5, 10.0), (6, 20.0), (9, 20.0)]
    for i in range(10):
        at = int((T0 + i) * 1e9)
        cpu = shown(data["/metrics/process/10/theta"], "time", at)["Scalars:scalars"][0]
        assert abs(cpu - 12.3456789) <= 12.3456789 * 2.0 ** -(MANTISSA_BITS + 1) and f"{cpu:.4g}" == "12.35"
        rate = shown(data["/metrics/topic/image/theta"], "time", at)["Scalars:scalars"][0]
        assert rate == (10.0 if i < 6 else 20.0)
    # Names and colours of the series are still there (static).
    assert "SeriesLines:names" in shown(data["/metrics/process/10/theta"])


def test_changed_fields():
    a = {"ids": ["a", "b"], "labels": ["a", "b"], "colors": [(1, 2, 3), (4, 5, 6)], "radii": [1.0, 1.0],
         "positions": [(0.0, 0.0), (1.0, 0.0)], "edges": [("a", "b")]}
    assert changed_fields(None, a) == set(a)
    assert changed_fields(a, a) == set()
    assert changed_fields(a, {**a, "colors": [(1, 2, 3), (9, 9, 9)]}) == {"colors"}
    assert changed_fields(a, {**a, "edges": []}) == {"edges"}
    assert changed_fields(a, {**a, "ids": ["a", "c"]}) == set(a)  # other members: everything again


def test_each_rca_iteration_shows_its_colours_with_the_graph_logged_once(tmp_path):
    """Iteration 2 comes after an alert recoloured /image: only the colours are logged on the
    rca_iteration timeline; iteration 1 still shows the old colours, 2 the new, both the graph."""
    rrd = tmp_path / "rca.rrd"
    G = robot()
    it = {"subgraph": ["topic:/image"], "watchlist": [], "edges": [], "alert": "topic:/image"}
    with Recorder(save=rrd) as r:
        r.system(G, t=T0)
        r.rca(G, {**it, "j": 1, "t": T0 + 1})
        r.alerts([Alert("topic:/image", "topic_rate", T0 + 2, "error", "rate fell", {"value": 3.0})])
        r.system(G, t=T0 + 2)
        r.rca(G, {**it, "j": 2, "t": T0 + 2})
        r.rca(G, {**it, "j": 3, "t": T0 + 3})  # nothing changed: nothing logged at /system
    sys_rows = rows(rrd)[paths.SYSTEM]
    on_rca = {row["rca_iteration"]: row for row in sys_rows if row.get("rca_iteration") is not None}
    assert set(on_rca) == {1, 2}
    assert all(row.get("time") is None for row in on_rca.values())  # on `time`, /system is system()'s
    assert {k for k in on_rca[2] if k.startswith("Graph")} == {"GraphNodes:colors"}
    one, two, three = (shown(sys_rows, paths.RCA_ITERATION, j) for j in (1, 2, 3))
    ids = one["GraphNodes:node_ids"]
    for view in (one, two, three):
        assert view["GraphNodes:node_ids"] == ids and len(view["GraphNodes:colors"]) == len(ids)
        assert len(view["GraphEdges:edges"]) == 4 and len(view["GraphNodes:positions"]) == len(ids)
    image = ids.index("topic:/image")
    assert one["GraphNodes:colors"][image] != two["GraphNodes:colors"][image]
    assert three["GraphNodes:colors"] == two["GraphNodes:colors"]
    # On `time` too: the alert's recolouring is one colours row after the graph.
    on_time = [row for row in sys_rows if row.get("time") is not None]
    assert shown(on_time, "time")["GraphNodes:colors"] == two["GraphNodes:colors"]
    assert shown(on_time, "time", int(T0 * 1e9))["GraphNodes:colors"] == one["GraphNodes:colors"]


def test_a_new_part_logs_the_graph_in_full_again(tmp_path):
    from stream_viz.viz.recorder import part_path

    rrd = tmp_path / "p.rrd"
    G = robot()
    it = {"subgraph": ["topic:/image"], "watchlist": [], "edges": [], "alert": "topic:/image"}
    with Recorder(save=rrd, part_s=5.0) as r:
        assert not r.part_due(T0)
        r.system(G, t=T0)
        r.rca(G, {**it, "j": 1, "t": T0 + 1})
        assert r.part_due(T0 + 6)
        r.next_part(T0 + 6, G)
    second = rows(part_path(rrd, 1))[paths.SYSTEM]
    for timeline in ("time", paths.RCA_ITERATION):
        view = shown(second, timeline)
        assert {"GraphNodes:node_ids", "GraphNodes:colors", "GraphNodes:positions",
                "GraphEdges:edges"} <= set(view)


def _alert(t: float, member: str = "topic:/image", severity: str = "error") -> Alert:
    return Alert(member, "topic_rate", t, severity, "rate fell", {"value": t - T0})


def test_file_events_gathers_alerts_and_lanes_in_time_order():
    ev = FileEvents()
    assert ev.first_t is None
    ev.add([_alert(T0 + 3)], {"topic:/image": [(T0 + 3, "error")]})
    ev.add([_alert(T0 + 1, "node:/cam")], {"topic:/image": [(T0 + 18, "ok")]})
    assert ev.first_t == T0 + 1
    alerts, lanes = ev.take()
    assert [a.t for a in alerts] == [T0 + 1, T0 + 3]
    assert lanes == {"topic:/image": [(T0 + 3, "error"), (T0 + 18, "ok")]}
    assert ev.take() == ([], {}) and ev.first_t is None


def test_alerts_go_to_the_file_in_few_chunks_and_are_all_shown(tmp_path):
    """An alert a second for 100 s: the file holds every marker, alert line and lane change,
    written every `file_events_s` (a chunk per entity), not a chunk per alert."""
    from rerun.chunk import RrdReader

    rrd = tmp_path / "alerts.rrd"
    G = robot()
    with Recorder(save=rrd, file_events_s=30.0) as r:
        for i in range(100):
            r.alerts([_alert(T0 + i)] if i < 80 else [])
            r.system(G, t=T0 + i)
    data = rows(rrd)
    markers = [row for row in data["/metrics/topic/image/alerts"] if "Scalars:scalars" in row]
    assert [row["time"] // 10**9 - int(T0) for row in markers] == list(range(80))
    assert [row["Scalars:scalars"][0] for row in markers] == [float(i) for i in range(80)]
    texts = [t for row in data[paths.ALERTS] for t in row.get("TextLog:text") or []]
    assert len(texts) == 80
    lane = data["/health/topic/image"]
    assert shown(lane, "time", int((T0 + 50) * 1e9))["StateChange:state"] == ["error"]
    assert shown(lane, "time")["StateChange:state"] == ["ok"]  # 15 s after the last alert
    chunks = [c.entity_path for c in RrdReader(str(rrd)).stream()]
    assert chunks.count("/metrics/topic/image/alerts") <= 6  # its style, then one per 30 s
    assert chunks.count(paths.ALERTS) <= 5


def test_a_new_part_holds_its_own_alerts(tmp_path):
    from stream_viz.viz.recorder import part_path

    rrd = tmp_path / "p.rrd"
    G = robot()
    with Recorder(save=rrd, part_s=10.0, file_events_s=60.0) as r:
        for i in range(15):
            if r.part_due(T0 + i):
                r.next_part(T0 + i, G)
            r.alerts([_alert(T0 + i)])
            r.system(G, t=T0 + i)
    first, second = rows(rrd), rows(part_path(rrd, 1))
    times = [[row["time"] // 10**9 - int(T0) for row in d["/metrics/topic/image/alerts"]
              if "Scalars:scalars" in row] for d in (first, second)]
    assert times == [list(range(10)), list(range(10, 15))]
    assert shown(second["/health/topic/image"], "time")["StateChange:state"] == ["error"]


def test_an_unchanged_report_is_logged_once_and_shown_later(tmp_path):
    rrd = tmp_path / "report.rrd"
    G = robot()
    it = {"subgraph": ["topic:/image"], "watchlist": [], "edges": [], "alert": "topic:/image"}
    with Recorder(save=rrd) as r:
        r.system(G, t=T0)
        r.rca(G, {**it, "j": 1, "t": T0 + 1})
        for i in range(2, 6):
            r.report("# Root-cause analysis\n\nsame", T0 + i)
        r.report("# Root-cause analysis\n\nnew", T0 + 6)
    report = [row for row in rows(rrd)[paths.RCA_REPORT] if "TextDocument:text" in row]
    on_time = [(row["time"] // 10**9 - int(T0), row["TextDocument:text"]) for row in report
               if row.get("rca_iteration") is None]
    assert [t for t, _ in on_time] == [2, 6]
    assert shown(report, "time", int((T0 + 5) * 1e9))["TextDocument:text"][0].endswith("same")
    assert shown(report, "time")["TextDocument:text"][0].endswith("new")
