"""The diagnosis where the eye lands: health lanes, the members shown first, the layout re-sent."""

from __future__ import annotations

from rerun.chunk import RrdReader

from stream_viz.model import add_member, add_tree_edge, new_graph
from stream_viz.records import Alert
from stream_viz.viz import paths
from stream_viz.viz.focus import diagnosis_members
from stream_viz.viz.health import HealthLanes, merge
from stream_viz.viz.recorder import Recorder
from tests.viz.rrd import rows, strings
from tests.viz.test_recording import T0, robot


def _alert(member: str, t: float, severity: str = "error") -> Alert:
    return Alert(member, "topic_rate", t, severity, "x")


def test_a_lane_holds_the_worst_recent_severity_then_turns_ok():
    lanes = HealthLanes(hold_s=10.0)
    got = merge(
        lanes.alerts([_alert("topic:/a", 0.0, "warn"), _alert("topic:/a", 4.0, "error"),
                      _alert("topic:/b", 5.0, "info")]),
        lanes.tick(12.0),  # /a's warn left the window at 10 (error still in); /b's info not yet
        lanes.alerts([_alert("topic:/a", 13.0, "warn")]),
        lanes.tick(30.0),
    )
    assert got == {
        "topic:/a": [(0.0, "warn"), (4.0, "error"), (14.0, "warn"), (23.0, "ok")],
        "topic:/b": [(5.0, "info"), (15.0, "ok")],
    }
    assert lanes.tick(40.0) == {}  # nothing left to change


def test_a_vanished_member_is_gone_until_it_returns():
    lanes = HealthLanes(hold_s=10.0)
    assert lanes.set_gone(1.0, ["node:/x"]) == {"node:/x": [(1.0, "gone")]}
    assert lanes.alerts([_alert("node:/x", 2.0, "fatal")]) == {}  # still gone
    assert lanes.set_gone(3.0, ["node:/x"]) == {}
    assert lanes.set_gone(5.0, []) == {"node:/x": [(5.0, "fatal")]}  # back, its alert still recent
    assert lanes.tick(20.0) == {"node:/x": [(12.0, "ok")]}


def test_the_diagnosis_lists_the_trajectory_from_the_root_cause_then_the_alerted():
    G = new_graph()
    for m in ["node:/a", "topic:/t", "node:/b", "node:/c", "process:7"]:
        add_member(G, m)
    add_tree_edge(G, "process:7", "node:/b")
    rc = [{"member": "node:/b", "trajectory": ["node:/a", "topic:/t", "node:/b"]}]
    status = {"node:/c": "warn", "topic:/t": "error", "process:9": "fatal"}
    assert diagnosis_members(G, rc, status) == {
        "node:/b": ["node:/b", "process:7"],  # the root cause; a node's plot shows its process's θ
        "node:/a": ["node:/a"], "topic:/t": ["topic:/t"],  # the first symptom, the alerted between
        "process:9": ["process:9"], "node:/c": ["node:/c"]}  # other alerted, most severe first
    assert list(diagnosis_members(G, rc, status, limit=2)) == ["node:/b", "node:/a"]
    long = [{"member": "node:/r", "trajectory": ["node:/s", "topic:/1", "node:/m", "topic:/2", "node:/r"]}]
    assert list(diagnosis_members(G, long, {"topic:/2": "warn"})) == [
        "node:/r", "node:/s", "topic:/2", "node:/m", "topic:/1"]  # the rest as the fault spread
    assert diagnosis_members(G) == {}


def test_lanes_and_the_diagnosis_layout_are_in_the_file(tmp_path):
    rrd = tmp_path / "diag.rrd"
    G = robot()
    it = {"j": 1, "t": T0 + 3, "subgraph": ["topic:/image"], "watchlist": [], "edges": [],
          "alert": "topic:/image"}
    rc = [{"member": "node:/camera", "score": 0.9, "trajectory": ["topic:/image", "node:/camera"]}]
    with Recorder(save=rrd) as r:
        r.system(G, t=T0)
        r.alerts([_alert("topic:/image", T0 + 3, "error")])
        r.system(G, t=T0 + 4)
        r.rca(G, it, rc)
        assert r.diagnosis == {"node:/camera": ["node:/camera", "process:10"],
                               "topic:/image": ["topic:/image"]}
        assert not r.focus(G, rc)  # same diagnosis: the layout is not sent again
        r.system(G, t=T0 + 30)  # the error is older than the hold: the lane turns ok
    lane = [row for row in rows(rrd)[paths.health_path("topic:/image")] if "StateChange:state" in row]
    assert [(row["time"], row["StateChange:state"]) for row in lane] == [
        (int((T0 + 3) * 1e9), ["error"]), (int((T0 + 18) * 1e9), ["ok"])]
    # The default layout, and the one that shows the diagnosis first (the store order is not fixed).
    layouts = [strings(rrd, bp) for bp in RrdReader(str(rrd)).blueprints()]
    assert len(layouts) == 2 and ["Diagnosis" in names for names in layouts].count(True) == 1
    names = next(names for names in layouts if "Diagnosis" in names)
    assert {"Diagnosis", "Health", "θ camera", "θ image", "Topics", "Processes"} <= names
    assert {"/metrics/process/10/**", "/metrics/node/camera/**", "/health/topic/image"} <= names


def test_a_host_ranked_first_is_drawn_through_the_nodes_it_explains():
    from stream_viz.viz import style
    from stream_viz.viz.layout import Layout
    from stream_viz.viz.rca import trajectory_arrays

    L = Layout(pos={"node:/cam": (0.0, 0.0), "topic:/img": (1.0, 0.0), "node:/imu": (0.0, 1.0),
                    "node:/det": (2.0, 0.0)})
    host = {"member": "host:b", "score": 0.5, "trajectory": ["topic:/img", "node:/cam", "host:b"],
            "evidence": {"host": "host:b", "explains_nodes": ["node:/cam", "node:/imu"]}}
    a = trajectory_arrays([host], L)
    assert a["ids"] == ["node:/cam", "topic:/img", "node:/imu"]
    assert a["colors"] == [style.ROOT_CAUSE_COLOR, style.TRAJECTORY_COLOR, style.ROOT_CAUSE_COLOR]
    assert a["edges"] == [("node:/cam", "topic:/img")]
    # A drawn root cause stays the only black one, whatever its evidence says.
    node = {**host, "member": "node:/cam", "trajectory": ["topic:/img", "node:/cam"]}
    b = trajectory_arrays([node], L)
    assert b["ids"] == ["node:/cam", "topic:/img"]
    assert b["colors"] == [style.ROOT_CAUSE_COLOR, style.TRAJECTORY_COLOR]
