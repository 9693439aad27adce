"""A fault travels along a topic only while it carries messages (`stream_viz.model.traffic`)."""

from __future__ import annotations

import pytest

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.shadow import Shadow
from stream_viz.model.theta import make_theta
from stream_viz.model.traffic import TRAFFIC, idle, note_traffic
from stream_viz.rca import RcaSettings, analyze
from stream_viz.rca.causal import trace
from stream_viz.records import Alert


def topics(rates):
    g = new_graph()
    for name, rate in rates.items():
        add_member(g, name, theta=make_theta("topic", {} if rate is None else {"rate_hz": rate}))
    return g


def test_note_traffic_keeps_spans_of_carrying_and_an_empty_entry_for_a_measured_idle_topic():
    spans = {}
    for t, rate in ((10.0, 5.0), (11.0, 5.0), (12.0, 0.0), (20.0, 2.0)):
        note_traffic(spans, topics({"topic:/a": rate, "topic:/idle": 0.0, "topic:/unknown": None}), t, 3.0)
    # 7–11 and 8–11 merge; 17–20 is a span of its own.
    assert spans == {"topic:/a": [(7.0, 11.0), (17.0, 20.0)], "topic:/idle": []}


def test_idle_is_known_only_for_a_measured_topic_without_a_span_in_the_interval():
    g = new_graph()
    g.graph[TRAFFIC] = {"topic:/a": [(7.0, 11.0)], "topic:/idle": []}
    assert idle(g, "topic:/a", 12.0, 20.0) and not idle(g, "topic:/a", 10.0, 20.0)
    assert idle(g, "topic:/idle", 0.0, 100.0)
    assert not idle(g, "topic:/unknown", 0.0, 100.0) and not idle(new_graph(), "topic:/a", 12.0, 20.0)


def test_the_shadow_records_traffic_in_the_seen_graph():
    shadow = Shadow()
    shadow.record(topics({"topic:/a": 5.0, "topic:/idle": 0.0}), 10.0)
    assert shadow.seen.graph[TRAFFIC] == {"topic:/a": [(7.0, 10.0)], "topic:/idle": []}


def test_trace_enters_a_closed_topic_only_from_its_publisher_and_stops_behind_it():
    # ui -> /teleop (closed) -> mux -> /cmd -> base: the ui's trace reaches mux (it sees its
    # publisher gone) and no further; mux's own trace goes on through /cmd.
    g = new_graph()
    for m in ("node:/ui", "topic:/teleop", "node:/mux", "topic:/cmd", "node:/base"):
        add_member(g, m)
    add_flow_edge(g, "node:/ui", "topic:/teleop", "pub")
    add_flow_edge(g, "topic:/teleop", "node:/mux", "sub")
    add_flow_edge(g, "node:/mux", "topic:/cmd", "pub")
    add_flow_edge(g, "topic:/cmd", "node:/base", "sub")
    cost, _ = trace(g, "node:/ui", (), 12, closed={"topic:/teleop"})
    assert set(cost) == {"node:/ui", "topic:/teleop", "node:/mux"}
    cost, _ = trace(g, "node:/mux", (), 12, closed={"topic:/teleop"})
    assert set(cost) == {"node:/mux", "topic:/cmd", "node:/base"}
    assert set(trace(g, "node:/ui", (), 12)[0]) == {"node:/ui", "topic:/teleop", "node:/mux", "topic:/cmd",
                                                    "node:/base"}


UI, TELEOP, MUX, CMD, BASE, ODOM, LOC, POSE, LIDAR, SCAN = (
    "node:/ui", "topic:/teleop", "node:/mux", "topic:/cmd", "node:/base", "topic:/odom",
    "node:/loc", "topic:/pose", "node:/lidar", "topic:/scan")


def robot(traffic: bool):
    """ui → /teleop → mux → /cmd → base → /odom → loc → /pose → ui (it shows the pose); lidar →
    /scan → loc. Each node in a process of its own. /teleop never carried a message (a joystick
    never held), when known."""
    g = new_graph()
    for k, m in enumerate((UI, MUX, BASE, LOC, LIDAR)):
        add_member(g, f"process:{k + 1}")
        add_member(g, m)
        add_tree_edge(g, f"process:{k + 1}", m)
    for m in (TELEOP, CMD, ODOM, POSE, SCAN):
        add_member(g, m)
    for src, dst in ((UI, TELEOP), (MUX, CMD), (BASE, ODOM), (LOC, POSE), (LIDAR, SCAN)):
        add_flow_edge(g, src, dst, "pub")
    for src, dst in ((TELEOP, MUX), (CMD, BASE), (ODOM, LOC), (SCAN, LOC), (POSE, UI)):
        add_flow_edge(g, src, dst, "sub")
    if traffic:
        g.graph[TRAFFIC] = {TELEOP: [], CMD: [(-100.0, 60.0)], ODOM: [(-100.0, 60.0)],
                            POSE: [(-100.0, 60.0)], SCAN: [(-100.0, 60.0)]}
    return g


def al(member, plugin, t, severity="error", **data):
    return Alert(member, plugin, float(t), severity, f"{plugin} on {member}", data)


def test_a_node_gone_while_its_topic_carried_nothing_explains_no_fault_beyond_it():
    # The operator's UI leaves uncleanly at 10 (its teleop topic never carried a message); the mux
    # warns its input lost its publisher; at 20 the lidar's rate falls, and the pose's with it:
    # one incident (the UI shows the pose).
    lost = {"symptom": "no_publisher", "topic": TELEOP}  # as graph_anomalies says it
    alerts = [al(UI, "member_gone", 10, symptom="exit"),
              *(al(MUX, "graph_anomalies", t, "warn", **lost) for t in (16, 22)),
              *(al(m, "topic_rate", t, "warn") for t in (20, 25, 30) for m in (SCAN, POSE))]
    unknown = {rc.member: rc for rc in analyze(robot(traffic=False), alerts, RcaSettings()).root_causes}
    # Unknown traffic: the UI's trajectory reaches the pose through the mux, the base, the odometry.
    assert unknown[UI].evidence["explains"] == 3  # itself, the mux, the pose
    ranked = {rc.member: rc for rc in analyze(robot(traffic=True), alerts, RcaSettings()).root_causes}
    assert ranked[UI].evidence["explains"] == 2  # itself and the mux that saw it go
    assert ranked[UI].trajectory == [MUX, TELEOP, UI] and ranked[UI].score < unknown[UI].score
    # The mux's warning is still the UI's departure, on its own input.
    assert ranked[MUX].evidence["upstream"] == pytest.approx(RcaSettings().severity["error"])
    # What it does not settle: the UI's exit (an error) still outranks the lidar's drop (a warn).
    assert ranked[LIDAR].score == pytest.approx(unknown[LIDAR].score)


def _recorder(measured: bool):
    """planner (process 7) → /plan → recorder (process 8, leaking); the recorder also calls the
    planner's service (a client waits on its server)."""
    g = new_graph()
    for m in ("node:/planner", "topic:/plan", "node:/recorder", "process:7", "process:8"):
        add_member(g, m)
    add_flow_edge(g, "node:/planner", "topic:/plan", "pub")
    add_flow_edge(g, "topic:/plan", "node:/recorder", "sub")
    add_tree_edge(g, "process:7", "node:/planner")
    add_tree_edge(g, "process:8", "node:/recorder")
    if measured:
        g.graph[TRAFFIC] = {"topic:/plan": [(0.0, 100.0)]}
    return g


def test_metric_evidence_behind_a_measured_topic_does_not_excuse_its_subscriber():
    from stream_viz.rca.episodes import Evidence

    leak = [Alert("node:/recorder", "process_resources", float(t), "warn", "memory growing", {})
            for t in (50, 55, 60)]
    burst = {"process:7": Evidence(1.0, 40.0, None)}  # the planner's CPU, no plugin confirming it
    # /plan measured and without a symptom: the planning burst changed nothing it sent.
    res = analyze(_recorder(measured=True), leak, RcaSettings(), evidence=burst)
    first = res.root_causes[0]
    assert first.member == "node:/recorder" and first.evidence["upstream"] == 0.0
    # Not measured, nothing says what it carried: the burst may have reached the recorder.
    res = analyze(_recorder(measured=False), leak, RcaSettings(), evidence=burst)
    assert res.root_causes[0].member == "node:/planner"
    # An alert of the planner (its own log) still excuses through the measured topic ...
    logged = [Alert("node:/planner", "rosout", 45.0, "error", "planning failed", {})]
    ranked = {rc.member: rc for rc in analyze(_recorder(measured=True), logged + leak, RcaSettings(),
                                              evidence=burst).root_causes}
    assert ranked["node:/recorder"].evidence["upstream"] > 0.0
    # ... and a server the recorder calls excuses it with its evidence (a slow reply shows on no topic).
    g = _recorder(measured=True)
    add_flow_edge(g, "node:/recorder", "node:/planner", "send")
    assert analyze(g, leak, RcaSettings(), evidence=burst).root_causes[0].member == "node:/planner"
