"""Real recordings written by the Recorder and read back from the .rrd file."""

from __future__ import annotations

import numpy as np
import pytest
from rerun.chunk import RrdReader
from stream_viz_blueprints.default import build_blueprint, save_blueprint

from stream_viz.errors import ConfigError, OutputError
from stream_viz.model import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import ROOT
from stream_viz.model.theta import make_theta
from stream_viz.records import Alert, Event
from stream_viz.viz import paths
from stream_viz.viz.recorder import Recorder
from tests.viz.rrd import rows, shown, strings

T0 = 1_700_000_000.0


def robot(rate: float = 10.0):
    """camera -> /image -> detector -> /objects -> planner; two processes under the root."""
    G = new_graph()
    for m in ["node:/camera", "node:/detector", "node:/planner", "topic:/image", "topic:/objects", ROOT]:
        add_member(G, m)
    add_member(G, "process:10", name="vision")
    add_member(G, "process:11", name="nav")
    add_flow_edge(G, "node:/camera", "topic:/image", "pub")
    add_flow_edge(G, "topic:/image", "node:/detector", "sub")
    add_flow_edge(G, "node:/detector", "topic:/objects", "pub")
    add_flow_edge(G, "topic:/objects", "node:/planner", "sub")
    add_tree_edge(G, ROOT, "process:10")
    add_tree_edge(G, ROOT, "process:11")
    add_tree_edge(G, "process:10", "node:/camera")
    add_tree_edge(G, "process:10", "node:/detector")
    add_tree_edge(G, "process:11", "node:/planner")
    G.nodes["topic:/image"]["theta"] = make_theta("topic", {"rate_hz": rate, "latency_ms": 2.0})
    G.nodes["process:10"]["theta"] = make_theta("process", {"cpu_percent": 5 * rate, "rss_mb": 100.0})
    return G


def test_a_structure_number_reads_the_graph_again_only_when_it_changes(tmp_path):
    # The monitor passes `Shadow.structure`: the same number, the same members and edges, so
    # only the colours and gone members are compared; a new number reads the structure again.
    rrd = tmp_path / "run.rrd"
    with Recorder(save=rrd) as r:
        assert r.system(robot(), t=T0, structure=1)
        assert not r.system(robot(), t=T0 + 1, structure=1)  # a new graph, the same structure
        r.alerts([Alert("topic:/image", "topic_rate", T0 + 2, "error", "rate fell to 3 Hz")])
        assert r.system(robot(), t=T0 + 2, structure=1)  # a colour changed
        G = robot()
        add_member(G, "node:/logger")
        add_flow_edge(G, "topic:/objects", "node:/logger", "sub")
        assert r.system(G, t=T0 + 3, structure=2)
    last = shown(rows(rrd)[paths.SYSTEM])
    assert "node:/logger" in last["GraphNodes:node_ids"]


def test_graph_metrics_alerts_and_blueprint_in_file(tmp_path):
    rrd = tmp_path / "run.rrd"
    with Recorder(save=rrd) as r:
        G = robot()
        assert r.system(G, t=T0)
        assert not r.system(G, t=T0 + 1)  # unchanged: not logged again
        r.metrics([(T0 + i, robot(rate=float(i))) for i in range(5)])
        r.alerts([Alert("topic:/image", "topic_rate", T0 + 3, "error", "rate fell to 3 Hz", {"value": 3.0}),
                  Alert("node:/planner", "rosout", T0 + 4, "fatal", "planner died")])
        r.changes([Event(T0 + 2.5, "param", "node:/camera", "info", "parameter of /camera: fps = 5.0",
                         {"changed": {"fps": "5.0"}, "deleted": []}),
                   Event(T0 + 2.6, "log", "node:/camera", "warn", "slow")])  # not a change
        G2 = robot()
        add_member(G2, "node:/camera", gone=True)
        assert r.system(G2, t=T0 + 5)  # status and gone changed
    reader = RrdReader(str(rrd))
    ents = set(reader.store().schema().entity_paths())
    assert {paths.SYSTEM, paths.PROCESS_TREE, paths.ALERTS, "/metrics/topic/image/theta",
            "/metrics/process/10/theta", "/metrics/topic/image/alerts"} <= ents
    data = rows(rrd)
    sys_rows = data[paths.SYSTEM]
    assert len(sys_rows) == 2
    first = sys_rows[0]
    last = shown(sys_rows)  # the second row logs only what changed: the viewer shows the rest
    assert "GraphNodes:node_ids" not in sys_rows[1] and "GraphNodes:positions" not in sys_rows[1]
    assert set(first["GraphNodes:node_ids"]) == {"node:/camera", "node:/detector", "node:/planner",
                                                "topic:/image", "topic:/objects"}
    edges = {(e["first"], e["second"]) for e in first["GraphEdges:edges"]}
    assert edges == {("node:/camera", "topic:/image"), ("topic:/image", "node:/detector"),
                     ("node:/detector", "topic:/objects"), ("topic:/objects", "node:/planner")}
    labels = dict(zip(last["GraphNodes:node_ids"], last["GraphNodes:labels"], strict=True))
    assert labels["node:/camera"] == "/camera (gone)" and labels["node:/detector"] == "/detector"
    colors = dict(zip(last["GraphNodes:node_ids"], last["GraphNodes:colors"], strict=True))
    assert colors["node:/camera"] != colors["node:/detector"]  # grey vs node blue
    assert colors["topic:/image"] != dict(zip(first["GraphNodes:node_ids"], first["GraphNodes:colors"],
                                              strict=True))["topic:/image"]  # alerted: severity colour
    # Process tree: root -> processes -> nodes.
    tree = data[paths.PROCESS_TREE][0]
    assert {(e["first"], e["second"]) for e in tree["GraphEdges:edges"]} >= {
        (ROOT, "process:10"), ("process:10", "node:/camera")}
    assert "vision (10)" in tree["GraphNodes:labels"]
    # Metrics: 5 rows, θ vector per row, rate_hz first column.
    theta = [row for row in data["/metrics/topic/image/theta"] if "Scalars:scalars" in row]
    assert [row["Scalars:scalars"][0] for row in theta] == [0.0, 1.0, 2.0, 3.0, 4.0]
    assert [row["time"] for row in theta] == [int((T0 + i) * 1e9) for i in range(5)]
    assert [row["Scalars:scalars"][0] for row in data["/metrics/process/10/theta"]
            if "Scalars:scalars" in row] == [0, 5, 10, 15, 20]
    # Alerts: text and levels.
    log = data[paths.ALERTS]
    assert [row["TextLog:text"][0] for row in log] == ["[topic_rate] topic:/image: rate fell to 3 Hz",
                                                    "[rosout] node:/planner: planner died"]
    assert [row["TextLog:level"][0] for row in log] == ["ERROR", "CRITICAL"]
    # Changes: the parameter set, at its time, in the same log panel as the alerts.
    changes = data[paths.CHANGES]
    assert [(row["TextLog:text"][0], row["time"]) for row in changes] == [
        ("[param] node:/camera: parameter of /camera: fps = 5.0", int((T0 + 2.5) * 1e9))]
    markers = [row for row in data["/metrics/topic/image/alerts"] if "Scalars:scalars" in row]
    assert [row["Scalars:scalars"] for row in markers] == [[3.0]]
    # The default blueprint travels in the file.
    (bp,) = reader.blueprints()
    assert bp.application_id == "stream_viz"
    names = strings(rrd, bp)
    assert {"System graph + RCA overlays", "Alerts", "Root causes", "Process tree"} <= names


def test_rca_overlays_per_iteration(tmp_path):
    rrd = tmp_path / "rca.rrd"
    G = robot()
    it1 = {"j": 1, "t": T0 + 10, "subgraph": ["topic:/objects"], "watchlist": ["node:/planner"],
           "edges": [], "alert": "topic:/objects"}
    it2 = {"j": 2, "t": T0 + 12, "subgraph": ["topic:/objects", "node:/planner"],
           "watchlist": ["node:/planner", "node:/detector"],
           "edges": [["topic:/objects", "node:/planner"]], "alert": "node:/planner"}
    rc = [{"member": "node:/detector", "score": 0.9,
           "trajectory": ["node:/planner", "topic:/objects", "node:/detector"]}]
    with Recorder(save=rrd) as r:
        r.system(G, t=T0)
        r.rca(G, it1, [])
        r.rca(G, it2, rc)
        r.metrics([(T0 + 13, G)])  # later data must not carry an rca_iteration
    data = rows(rrd)
    sub = {row["rca_iteration"]: row for row in data[paths.RCA_SUBGRAPH]}
    assert set(sub) == {1, 2}
    assert sub[1]["GraphNodes:node_ids"] == ["topic:/objects", "node:/planner"]
    assert sub[2]["GraphNodes:node_ids"] == ["topic:/objects", "node:/planner", "node:/detector"]
    assert [(e["first"], e["second"]) for e in sub[2]["GraphEdges:edges"]] == [
        ("topic:/objects", "node:/planner")]
    assert sub[2]["time"] == int((T0 + 12) * 1e9)
    # Same positions as /system.
    sys_pos = dict(zip(data[paths.SYSTEM][0]["GraphNodes:node_ids"],
                       map(tuple, data[paths.SYSTEM][0]["GraphNodes:positions"]), strict=True))
    for m, p in zip(sub[2]["GraphNodes:node_ids"], sub[2]["GraphNodes:positions"], strict=True):
        assert tuple(p) == sys_pos[m]
    # The system graph is there on the rca_iteration timeline too: logged in full at iteration 1,
    # not again at 2 (nothing changed), and iteration 2 shows it all by latest-at.
    assert {row.get("rca_iteration") for row in data[paths.SYSTEM]} == {None, 1}
    at2 = shown(data[paths.SYSTEM], paths.RCA_ITERATION, 2)
    assert at2["GraphNodes:node_ids"] == data[paths.SYSTEM][0]["GraphNodes:node_ids"]
    assert at2["GraphNodes:colors"] == data[paths.SYSTEM][0]["GraphNodes:colors"]
    assert len(at2["GraphEdges:edges"]) == 4
    traj = [row for row in data[paths.RCA_TRAJECTORY] if row["rca_iteration"] == 2]
    assert traj[0]["GraphNodes:node_ids"] == ["node:/detector", "topic:/objects", "node:/planner"]
    report = {row["rca_iteration"]: row["TextDocument:text"][0] for row in data[paths.RCA_REPORT]}
    assert "No root cause" in report[1] and "**`node:/detector`**" in report[2]
    theta = [row for row in data["/metrics/topic/image/theta"] if "Scalars:scalars" in row]
    assert theta and all(row.get("rca_iteration") is None for row in theta)


def test_unwritable_path_and_bad_viewer_fail_before_anything(tmp_path):
    with pytest.raises(OutputError, match="nope"):
        Recorder(save=tmp_path / "nope" / "x.rrd")
    with pytest.raises(OutputError, match=f"^recording {tmp_path}: is a folder$"):
        Recorder(save=tmp_path)
    with pytest.raises(ConfigError, match="--viewer 'firefox'"):
        Recorder(viewer="firefox")


def test_spawn_without_display_is_a_clear_error(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)  # the environment, not rerun, is changed
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    with pytest.raises(OutputError, match="needs a display"):
        Recorder(viewer="spawn")


def test_saved_blueprint_file(tmp_path):
    out = save_blueprint(tmp_path / "layout.rbl", watched=["topic:/image"])
    (bp,) = RrdReader(str(out)).blueprints()
    assert bp.application_id == "stream_viz"
    assert "θ topic:/image" in strings(out, bp)
    assert build_blueprint(timeline="rca_iteration") is not None


def test_nan_theta_rows_are_left_out(tmp_path):
    rrd = tmp_path / "nan.rrd"
    G = robot()
    G.nodes["topic:/image"]["theta"] = np.full(7, np.nan)
    with Recorder(save=rrd) as r:
        assert r.metrics([(T0, G)]) == 1  # only process:10 has θ
    assert "/metrics/topic/image/theta" not in rows(rrd)


def test_a_long_recording_is_saved_in_parts_that_each_open_alone(tmp_path):
    from stream_viz.rca.engine import RcaEngine
    from stream_viz.rca.settings import RcaSettings
    from stream_viz.records import Sample
    from stream_viz.viz.live import LiveView

    rrd = tmp_path / "long.rrd"
    G = robot()
    result = RcaEngine(RcaSettings(), watchlist=None).update(G, [])
    view = LiveView(save=rrd, metrics_every=1.0, part_s=10.0)
    for i in range(25):
        view.update(T0 + i, Sample(T0 + i, G.copy()), G, [], result)
    view.close()
    parts = [rrd, tmp_path / "long_1.rrd", tmp_path / "long_2.rrd"]
    assert view.recording_parts == parts
    times = []
    for p in parts:
        data = rows(p)
        # Each part has the graph (and the diagnosis of the moment, on the rca_iteration timeline).
        assert [row["time"] for row in data[paths.SYSTEM] if row.get("rca_iteration") is None] == [
            int((T0 + 10 * len(times)) * 1e9)]
        assert paths.PROCESS_TREE in data and paths.RCA_REPORT in data
        # The static series style (readable names) is in every part, not only the first.
        assert any("SeriesLines:names" in row for row in data["/metrics/topic/image/theta"]), p
        (bp,) = RrdReader(str(p)).blueprints()
        assert bp.application_id == "stream_viz"
        ts = sorted(row["time"] // 10**9 - int(T0)
                    for row in data["/metrics/topic/image/theta"] if "Scalars:scalars" in row)
        times.append(ts)
    # Every sample is in exactly one part, in order: 0-9, 10-19, 20-24.
    assert times == [list(range(0, 10)), list(range(10, 20)), list(range(20, 25))]
    # One recording: the viewer merges the parts.
    ids = {e.recording_id for p in parts for e in RrdReader(str(p)).recordings()}
    assert len(ids) == 1


def test_a_part_that_cannot_be_written_keeps_the_recording_in_the_current_file(tmp_path, capsys):
    rrd = tmp_path / "run.rrd"
    (tmp_path / "run_1.rrd").mkdir()  # the next part's path is taken by a directory
    with Recorder(save=rrd, part_s=5.0) as r:
        G = robot()
        r.system(G, T0)
        assert not r.part_due(T0)
        assert r.part_due(T0 + 5)
        assert r.next_part(T0 + 5, G) is None
        r.metrics([(T0 + 6, G)])
        assert not r.part_due(T0 + 60)  # no more parts tried
    assert "cannot start part" in capsys.readouterr().err
    assert r.parts == [rrd]
    theta = [row for row in rows(rrd)["/metrics/topic/image/theta"] if "Scalars:scalars" in row]
    assert [row["time"] for row in theta] == [int((T0 + 6) * 1e9)]
