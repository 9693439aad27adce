"""Time in the evidence (issue 16, item 10): episodes of alerts, metric evidence with since/until,
and an upstream episode that has ended no longer excusing a later fault downstream."""

from __future__ import annotations

import pytest

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.rca import RcaEngine, RcaSettings
from stream_viz.rca.episodes import INF, Evidence, merge, overlaps, stamp
from stream_viz.rca.symptoms import collect_symptoms, gone_members, node_views
from stream_viz.records import Alert

SENSOR, PERC, PLAN = "node:/sensor", "node:/perception", "node:/planner"
SCAN, OBJ = "topic:/scan", "topic:/objects"
PROC = "process:42"


def graph(sensor_gone: bool = False):
    """sensor → /scan → perception → /objects → planner; perception runs in process 42."""
    g = new_graph()
    for m in (PERC, PLAN, SCAN, OBJ, PROC):
        add_member(g, m)
    add_member(g, SENSOR, **({"gone": True} if sensor_gone else {}))
    add_flow_edge(g, SENSOR, SCAN, "pub")
    add_flow_edge(g, SCAN, PERC, "sub")
    add_flow_edge(g, PERC, OBJ, "pub")
    add_flow_edge(g, OBJ, PLAN, "sub")
    add_tree_edge(g, PROC, PERC)
    return g


def al(member, plugin, t, severity="error", **data):
    return Alert(member, plugin, float(t), severity, f"{plugin} on {member}", data)


def views(G, alerts, evidence=None, **settings):
    s = RcaSettings(**settings)
    return node_views(G, collect_symptoms(alerts, s, None, gone_members(G)), s, evidence)


def test_episodes_merge_runs_of_alerts_and_overlap_intervals():
    assert merge([0.0, 1.0, 2.0, 10.0, 11.0, 30.0], gap=5.0) == [(0.0, 2.0), (10.0, 11.0), (30.0, 30.0)]
    assert merge([], gap=5.0) == []
    eps = [(0.0, 2.0), (10.0, 11.0)]
    assert overlaps(eps, 2.0, 5.0) and overlaps(eps, 5.0, 10.0) and not overlaps(eps, 3.0, 9.0)


def test_stamp_gives_evidence_a_since_and_an_until():
    e = stamp({}, {PROC: 1.0}, 10.0)
    assert e == {PROC: Evidence(1.0, 10.0, None)}
    e = stamp(e, {PROC: 0.5}, 15.0)  # still holds: since stays
    assert e == {PROC: Evidence(0.5, 10.0, None)}
    e = stamp(e, {}, 20.0, keep=60.0)  # gone from the evidence: it ended now, and is kept
    assert e == {PROC: Evidence(0.5, 10.0, 20.0)}
    assert stamp(e, {}, 80.0, keep=60.0) == e  # within keep of its end
    assert stamp(e, {}, 80.5, keep=60.0) == {}
    e = stamp(e, {PROC: 1.0}, 30.0)  # a new episode
    assert e == {PROC: Evidence(1.0, 30.0, None)}
    assert stamp({}, {PROC: 0.7}, None) == {PROC: Evidence(0.7)}  # no time known: untimed
    assert Evidence(1.0, 10.0, 20.0).episode() == (10.0, 20.0)
    assert Evidence(1.0, 10.0).episode() == (10.0, INF) and Evidence(1.0).episode() is None


def test_flapping_alerts_are_one_episode_and_a_gone_member_s_episode_lasts():
    G = graph(sensor_gone=True)
    alerts = [al(SCAN, "topic_rate", t) for t in (0, 4, 12, 16, 24)] + [al(SENSOR, "member_gone", 3, "fatal")]
    s = collect_symptoms(alerts, RcaSettings(episode_gap=10.0), None, gone_members(G))
    assert s.episodes[SCAN] == [(0.0, 24.0)]
    assert s.episodes[SENSOR] == [(3.0, INF)]
    s = collect_symptoms(alerts, RcaSettings(episode_gap=5.0))
    assert s.episodes[SCAN] == [(0.0, 4.0), (12.0, 16.0), (24.0, 24.0)]


def test_an_ended_upstream_episode_does_not_excuse_a_later_fault_downstream():
    G = graph()
    old = [al(SCAN, "topic_rate", t) for t in (0, 5, 10)]  # /scan silent for a while, then fine
    fault = [al(PERC, "rosout", 100), al(PERC, "rosout", 101)]
    v = views(G, old + fault, window=0)
    # Before: /scan's onset (0) was before perception's (100), so it excused it fully (0.8).
    assert v[PERC].upstream == 0.0 and v[PERC].ht == pytest.approx(0.8)
    # The same /scan symptom still going on when perception's began excuses it.
    ongoing = old + [al(SCAN, "topic_rate", t) for t in (15, 25, 35, 45, 55, 65, 75, 85, 95)]
    v = views(G, ongoing + fault, window=0)
    assert v[PERC].upstream == pytest.approx(0.8) and v[PERC].ht == pytest.approx(0.8 * 0.2)
    # Ended less than episode_gap before: still the same episode of trouble.
    v = views(G, [al(SCAN, "topic_rate", 90), *fault], window=0)
    assert v[PERC].upstream == pytest.approx(0.8)


def test_a_crashed_node_reported_once_still_excuses_later_victims():
    alerts = [al(SENSOR, "member_gone", 0, "fatal"), al(PERC, "rosout", 60)]
    assert views(graph(sensor_gone=True), alerts)[PERC].upstream == 1.0  # the sensor is still gone
    assert views(graph(), alerts)[PERC].upstream == 0.0  # it came back: its episode ended at 0


def test_process_evidence_is_judged_in_time_like_an_alert():
    G = graph()  # metric evidence at full strength (metric=1.0): this is about its time
    fault = [al(PLAN, "rosout", 100)]
    # Untimed evidence (no since): it counts at any time, as before.
    assert views(G, fault, {PROC: 1.0}, metric=1.0)[PLAN].upstream == 1.0
    # Evidence that held from 30 to 50 does not excuse the planner's fault at 100 ...
    v = views(G, fault, {PROC: Evidence(1.0, 30.0, 50.0)}, metric=1.0)
    assert v[PLAN].upstream == 0.0
    assert v[PERC].onset == 30.0 and v[PERC].evidence == 1.0  # ... and has an onset, like an alert
    # ... evidence that still holds does.
    assert views(G, fault, {PROC: Evidence(1.0, 30.0)}, metric=1.0)[PLAN].upstream == 1.0
    # Evidence that began after the planner's fault is no cause of it.
    assert views(G, fault, {PROC: Evidence(1.0, 110.0)}, metric=1.0)[PLAN].upstream == 0.0


def test_a_process_burst_that_ended_does_not_date_a_node_s_later_change():
    G = graph()  # perception's process worked hard from 30 to 50 (a container's burst), then /scan
    burst = [al(PERC, "process_resources", t, "warn", process=PROC) for t in (32, 37, 42, 47)]
    later = [al(SCAN, "topic_rate", t) for t in (58, 63, 68)] + [al(OBJ, "topic_rate", t) for t in (60, 65)]
    ended = views(G, burst + later, {PROC: Evidence(1.0, 30.0, 50.0)}, metric=1.0)
    # /objects stopped after /scan went bad: the burst that had ended keeps /scan from nothing.
    assert ended[PERC].onset == 30.0 and ended[PERC].upstream == pytest.approx(0.8)  # /scan's error
    # A burst still going on when /scan went bad began the node's trouble: /scan came after.
    holds = views(G, burst + later, {PROC: Evidence(1.0, 30.0)}, metric=1.0)
    assert holds[PERC].upstream == 0.0
    # Without a measured end (its process's alerts alone), when it ended is not known.
    assert views(G, burst + later, metric=1.0)[PERC].upstream == 0.0
    # Perception's own log before /scan went bad dates it: /scan is no cause of it.
    own = views(G, [*burst, al(PERC, "rosout", 40), *later], {PROC: Evidence(1.0, 30.0, 50.0)}, metric=1.0)
    assert own[PERC].upstream == 0.0


def test_an_input_s_trouble_that_led_and_holds_explains_a_louder_complaint():
    G = graph()  # /objects warns (0.5) from 100; the planner then logs an error (0.8)
    warned = [al(OBJ, "topic_rate", t, "warn") for t in range(100, 130, 5)]
    led = views(G, [*warned, al(PLAN, "rosout", 116)], window=0)
    # It began 16 s before the planner's and still held: it explains the error as fully as it weighs.
    assert led[PLAN].upstream == pytest.approx(0.8) and led[PLAN].ht == pytest.approx(0.8 * 0.2)
    # In the same sample (within tolerance) it may be a coincidence: its own weight only.
    same = views(G, [*warned, al(PLAN, "rosout", 101)], window=0)
    assert same[PLAN].upstream == pytest.approx(0.5)
    # Standing for longer than led_max before: a standing condition, its own weight only.
    standing = [al(OBJ, "topic_rate", t, "warn") for t in range(0, 130, 5)]
    assert views(G, [*standing, al(PLAN, "rosout", 116)], window=0)[PLAN].upstream == pytest.approx(0.5)


def test_the_engine_stamps_evidence_with_the_update_time():
    G = graph()
    eng = RcaEngine(RcaSettings(metric=1.0), watchlist=None)
    eng.update(G, [], {PROC: 1.0}, t=10.0)
    eng.update(G, [], {}, t=20.0)  # the process is normal again
    res = eng.update(G, [al(PLAN, "rosout", 100)], t=100.0)
    planner = next(rc for rc in res.root_causes if rc.member == PLAN)
    assert planner.evidence["upstream"] == 0.0
    eng = RcaEngine(RcaSettings(metric=1.0), watchlist=None)
    # still anomalous when the planner's fault comes (since 60 s: within `led_max`)
    eng.update(G, [], {PROC: 1.0}, t=60.0)
    res = eng.update(G, [al(PLAN, "rosout", 100)], t=100.0)
    planner = next(rc for rc in res.root_causes if rc.member == PLAN)
    assert planner.evidence["upstream"] == 1.0 and res.root_causes[0].member == PERC


MISSION, CTRL, BRIDGE = "node:/mission", "node:/controller", "node:/bridge"
WP, SP, STATUS = "topic:/waypoints", "topic:/setpoints", "topic:/status"


def loop():
    """A feedback loop: mission → /waypoints → controller → /setpoints → bridge → /status → mission."""
    g = new_graph()
    for src, topic, dst in ((MISSION, WP, CTRL), (CTRL, SP, BRIDGE), (BRIDGE, STATUS, MISSION)):
        for m in (src, topic, dst):
            if m not in g:
                add_member(g, m)
        add_flow_edge(g, src, topic, "pub")
        add_flow_edge(g, topic, dst, "sub")
    return g


def test_a_cause_stamped_after_the_symptom_began_does_not_excuse_it():
    # The controller's setpoints stopped after 8.6 (20 Hz: by 8.65); the mission logged at 9.3 that
    # the vehicle had left its mode. One sample (t=10) holds both alerts.
    silence = al(SP, "topic_rate", 10, since=8.6, since_within=0.05)
    v = views(loop(), [silence, al(MISSION, "rosout", 10, since=9.3)])
    assert v[CTRL].upstream == 0.0  # the log came after; its own setpoints round the loop are none
    assert v[MISSION].upstream == pytest.approx(0.8 * 0.75)  # /setpoints, through the silent bridge
    assert v[CTRL].ht > v[MISSION].ht
    # Within the slack of two clocks, or a line without a stamp: it may be the cause, as before.
    v = views(loop(), [silence, al(MISSION, "rosout", 10, since=8.8)])
    assert v[CTRL].upstream == v[MISSION].anomaly > 0
    v = views(loop(), [silence, al(MISSION, "rosout", 10)])
    assert v[CTRL].upstream == v[MISSION].anomaly > 0
    # The next message was due by 9.6 at 1 Hz: the log at 9.3 may have stopped it.
    slow = al(SP, "topic_rate", 10, since=8.6, since_within=1.0)
    v = views(loop(), [slow, al(MISSION, "rosout", 10, since=9.3)])
    assert v[CTRL].upstream == v[MISSION].anomaly > 0


def test_a_node_s_own_output_reached_round_a_loop_is_no_cause_of_it():
    G = loop()
    add_member(G, "node:/elsewhere")  # a symptom off the loop: the walk round it goes on
    v = views(G, [al(SP, "topic_rate", 10), al("node:/elsewhere", "rosout", 10)])
    assert v[CTRL].upstream == 0.0 and v[CTRL].ht == v[CTRL].anomaly > 0


def test_a_candidate_does_not_explain_a_symptom_stamped_before_its_own_began():
    from stream_viz.rca.trajectories import make_context, trajectory_of

    # The setpoints stopped by 8.65 and the mission logged at 9.3; one sample (t=10) holds both.
    # Round the loop the setpoints are downstream of the mission, but began before its log did.
    silence = al(SP, "topic_rate", 10, since=8.6, since_within=0.05)
    ctx = make_context(loop(), [silence, al(MISSION, "rosout", 10, since=9.3)], RcaSettings())
    assert trajectory_of(ctx, MISSION).explained == [MISSION]
    assert SP in trajectory_of(ctx, CTRL).explained
    # A log within the slack of two clocks, or without a stamp, may still have come first.
    for log in (al(MISSION, "rosout", 10, since=8.8), al(MISSION, "rosout", 10)):
        ctx = make_context(loop(), [silence, log], RcaSettings())
        assert sorted(trajectory_of(ctx, MISSION).explained) == [MISSION, SP]
