"""Incidents (issue 16, item 12) and intermittent faults (item 9): symptoms connected in the graph
and close in time form one incident; the diagnosis is the current incident's; a flapping symptom
is one episode and still ranks its root first."""

from __future__ import annotations

import numpy as np
import pytest

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.rca import RcaEngine, RcaSettings, analyze
from stream_viz.rca.incidents import (
    DOWN,
    MIXED,
    SELF,
    UP,
    ball,
    current,
    find_incidents,
    relation,
    steps,
)
from stream_viz.records import Alert

SENSOR, PERC, PLAN, CTRL = "node:/sensor", "node:/perception", "node:/planner", "node:/controller"
SCAN, OBJ, CMD = "topic:/scan", "topic:/objects", "topic:/cmd"
BATT, BATTERY = "node:/battery", "topic:/battery"
PROC = "process:42"


@pytest.fixture
def G():
    """sensor → /scan → perception → /objects → planner → /cmd → controller; perception runs in
    process 42; battery → /battery stands apart (nobody subscribes)."""
    g = new_graph()
    for m in (SENSOR, PERC, PLAN, CTRL, SCAN, OBJ, CMD, BATT, BATTERY, PROC):
        add_member(g, m)
    for a, b, kind in ((SENSOR, SCAN, "pub"), (SCAN, PERC, "sub"), (PERC, OBJ, "pub"), (OBJ, PLAN, "sub"),
                       (PLAN, CMD, "pub"), (CMD, CTRL, "sub"), (BATT, BATTERY, "pub")):
        add_flow_edge(g, a, b, kind)
    add_tree_edge(g, PROC, PERC)
    return g


def al(member, plugin, t, severity="error", **data):
    return Alert(member, plugin, float(t), severity, f"{plugin} on {member}", data)


def test_neighbours_and_hops(G):
    assert steps(G, PERC) == ({SCAN, PROC}, {OBJ, PROC})
    assert steps(G, PROC) == ({PERC}, {PERC})
    assert steps(G, "node:/unknown") == (set(), set())
    # how each member was reached: up only, down only, up then down (never down then up)
    assert ball(G, SCAN, 1) == {SCAN: {SELF: 0}, SENSOR: {UP: 1}, PERC: {DOWN: 1}}
    assert ball(G, SCAN, 2) == {SCAN: {SELF: 0, MIXED: 2}, SENSOR: {UP: 1}, PERC: {DOWN: 1}, OBJ: {DOWN: 2},
                                PROC: {DOWN: 2}}
    assert ball(G, PERC, 1) == {PERC: {SELF: 0}, SCAN: {UP: 1}, PROC: {UP: 1, DOWN: 1}, OBJ: {DOWN: 1}}
    assert ball(G, OBJ, 2) == {OBJ: {SELF: 0, MIXED: 2}, PERC: {UP: 1}, PLAN: {DOWN: 1}, SCAN: {UP: 2},
                               PROC: {UP: 2, MIXED: 2}, CMD: {DOWN: 2}}
    assert ball(G, BATTERY, 1, links={BATTERY: {SENSOR}}) == {BATTERY: {SELF: 0}, BATT: {UP: 1},
                                                             SENSOR: {UP: 1, DOWN: 1}}


def test_relation_of_two_walks_that_met():
    assert relation(SELF, UP) == {"ab"} and relation(UP, SELF) == {"ba"}  # the first is upstream
    assert relation(SELF, DOWN) == {"ba"} and relation(DOWN, UP) == {"ab"} and relation(UP, DOWN) == {"ba"}
    assert relation(UP, UP) == relation(UP, MIXED) == relation(SELF, MIXED) == {"fork"}  # a common cause
    assert relation(DOWN, DOWN) == relation(DOWN, MIXED) == relation(MIXED, MIXED) == set()  # head to head


DIAG, AGG, OTHER = "topic:/diagnostics", "node:/aggregator", "node:/other"


def test_publishers_of_one_topic_meet_head_to_head(G):
    """The sensor and the battery both publish /diagnostics: a fault of one does not reach the
    other through it, so their symptoms at the same time are two incidents; a symptom of the
    aggregator that reads it joins both (each is upstream of it); two readers of /scan share a
    cause and are one."""
    for m in (DIAG, AGG, OTHER):
        add_member(G, m)
    for a, b, kind in ((SENSOR, DIAG, "pub"), (BATT, DIAG, "pub"), (DIAG, AGG, "sub"), (SCAN, OTHER, "sub")):
        add_flow_edge(G, a, b, kind)
    for hops in (2, 3, 4, 5, 6):
        got = find_incidents(G, {SENSOR: [(0.0, 1.0)], BATT: [(0.0, 1.0)]}, hops, 15.0, 1.0)
        assert [i.members for i in got] == [[BATT], [SENSOR]], hops
        both = {SENSOR: [(0.0, 1.0)], BATT: [(0.0, 1.0)]}
        got = find_incidents(G, {**both, AGG: [(10.0, 11.0)]}, hops, 15.0, 11.0)
        assert [i.members for i in got] == [[AGG, BATT, SENSOR]], hops
        # the aggregator's symptom too far off in time joins neither
        got = find_incidents(G, {**both, AGG: [(40.0, 41.0)]}, hops, 15.0, 41.0)
        assert len(got) == 3, hops
        got = find_incidents(G, {PERC: [(0.0, 1.0)], OTHER: [(0.0, 1.0)]}, hops, 15.0, 1.0)
        assert [i.members for i in got] == [[OTHER, PERC]], hops
    # down the chain is no collider: the sensor reaches /objects in three hops
    assert len(find_incidents(G, {SENSOR: [(0.0, 1.0)], OBJ: [(0.0, 1.0)]}, 3, 15.0, 1.0)) == 1
    # the battery and the planner are six hops apart, through the sensor head to head at /diagnostics
    assert len(find_incidents(G, {BATT: [(0.0, 1.0)], PLAN: [(0.0, 1.0)]}, 6, 15.0, 1.0)) == 2

PAIRS = {(SCAN, OBJ): 2, (OBJ, CMD): 2, (SENSOR, OBJ): 3, (SCAN, CMD): 4, (SENSOR, CMD): 5}


@pytest.mark.parametrize("hops", [1, 2, 3, 4, 5])
def test_incidents_link_members_at_most_hops_apart(G, hops):
    for (a, b), apart in PAIRS.items():  # each pair alone, at the same time
        got = find_incidents(G, {a: [(0.0, 1.0)], b: [(0.0, 1.0)]}, hops, 15.0, 1.0)
        assert (len(got) == 1) == (apart <= hops), (a, b, hops)


def test_find_incidents_groups_by_graph_and_time(G):
    episodes = {SCAN: [(0.0, 5.0)], OBJ: [(8.0, 10.0)], BATTERY: [(3.0, 4.0)], CTRL: [(100.0, 100.0)]}
    got = find_incidents(G, episodes, hops=4, gap=15.0, now=100.0)
    assert [(i.id, i.members, i.start, i.end, i.ongoing) for i in got] == [
        (1, [OBJ, SCAN], 0.0, 10.0, False),  # two hops apart, 3 s apart: one incident
        (2, [BATTERY], 3.0, 4.0, False),  # at the same time, but not connected
        (3, [CTRL], 100.0, 100.0, True),  # connected to /objects, but 90 s later
    ]
    assert current(got) is got[2]
    # one hop allowed: /scan and /objects (two hops apart) are separate incidents
    assert [i.members for i in find_incidents(G, episodes, 1, 15.0, 100.0)] == [
        [SCAN], [BATTERY], [OBJ], [CTRL]]
    # a vanished member's open episode keeps its incident going, and joins what comes later ...
    lasting = {SCAN: [(0.0, float("inf"))], CTRL: [(100.0, 100.0)]}
    got = find_incidents(G, lasting, 6, 15.0, 100.0)
    assert [(i.members, i.end, i.ongoing) for i in got] == [([CTRL, SCAN], 100.0, True)]
    # ... within `reach` of it: longer after, it is a standing condition, and what comes is new
    got = find_incidents(G, lasting, 6, 15.0, 100.0, reach=60.0)
    assert [(i.members, i.end, i.ongoing) for i in got] == [([SCAN], 100.0, True), ([CTRL], 100.0, True)]
    assert [i.members for i in find_incidents(G, lasting, 6, 15.0, 100.0, reach=100.0)] == [[CTRL, SCAN]]
    # the other way round too: a downstream member dead since 0 s and its source's alert at 100 s
    got = find_incidents(G, {CTRL: [(0.0, float("inf"))], SCAN: [(100.0, 100.0)]}, 6, 15.0, 100.0, reach=60.0)
    assert len(got) == 2


def strengths(incidents, **by_first_member):
    for inc in incidents:
        inc.strength = by_first_member.get(inc.members[0], 0.0)
    return incidents


def test_the_current_incident_is_ongoing_new_and_stands_out(G):
    # the battery warns every 60 s (each its own episode: a recurring symptom); the fault at
    # 100-130 is still going on when the battery warns again at 125
    episodes = {BATTERY: [(0.0, 0.0), (60.0, 60.0), (125.0, 125.0)],
                SCAN: [(100.0, 130.0)], OBJ: [(101.0, 130.0)]}
    got = find_incidents(G, episodes, 4, 15.0, 130.0)
    assert [(i.members, i.recurring, i.ongoing) for i in got] == [
        ([BATTERY], False, False), ([BATTERY], True, False), ([OBJ, SCAN], False, True),
        ([BATTERY], True, True)]
    assert current(strengths(got, **{BATTERY: 0.9, OBJ: 0.5})).members == [OBJ, SCAN]
    # a newer symptom elsewhere whose best candidate stands out less does not displace an
    # ongoing fault ...
    got = find_incidents(G, {SCAN: [(100.0, 130.0)], BATTERY: [(125.0, 125.0)]}, 4, 15.0, 130.0)
    assert current(strengths(got, **{SCAN: 0.64, BATTERY: 0.4})).members == [SCAN]
    # ... one that stands out as much does when the incidents are as large: it is the newest ...
    assert current(strengths(got, **{SCAN: 0.64, BATTERY: 0.64})).members == [BATTERY]
    # ... not when the fault's cascade is larger
    got = find_incidents(G, {SCAN: [(100.0, 130.0)], OBJ: [(101.0, 130.0)], BATTERY: [(125.0, 125.0)]},
                         4, 15.0, 130.0)
    assert current(strengths(got, **{OBJ: 0.64, BATTERY: 0.64})).members == [OBJ, SCAN]
    assert current([]) is None
    # an incident nothing in which can be a cause (strength 0) is never the current one
    assert current(strengths(got, **{OBJ: 0.0, BATTERY: 0.3})).members == [BATTERY]
    old = find_incidents(G, {SCAN: [(10.0, 20.0)], BATTERY: [(125.0, 125.0)]}, 4, 15.0, 130.0)
    assert current(strengths(old, **{SCAN: 0.3, BATTERY: 0.0})).members == [SCAN]  # even when over


def test_a_blip_that_ended_does_not_displace_a_fault_whose_alerts_still_come(G):
    # /scan's fault alerts from 100 s to now (130); the battery's loud blip ended at 112, within
    # the episode gap, its process evidence (a hint) going on to 121: the fault is current
    episodes = {SCAN: [(100.0, 130.0)], BATTERY: [(110.0, 112.0)], BATT: [(111.0, 121.0)]}
    alerted = {SCAN: [(100.0, 130.0)], BATTERY: [(110.0, 112.0)]}
    got = find_incidents(G, episodes, 4, 15.0, 130.0, alerted=alerted)
    assert [(i.members, i.ongoing, i.lasting) for i in got] == [
        ([SCAN], True, True), ([BATT, BATTERY], True, False)]
    assert current(strengths(got, **{SCAN: 0.3, BATT: 0.9})).members == [SCAN]
    # its alerts still coming too (at 125): the one that stands out more
    alerted[BATTERY] = episodes[BATTERY] = [(110.0, 125.0)]
    got = find_incidents(G, episodes, 4, 15.0, 130.0, alerted=alerted)
    assert current(strengths(got, **{SCAN: 0.3, BATT: 0.9})).members == [BATT, BATTERY]


def test_a_line_said_once_does_not_displace_a_fault_still_said(G):
    # /scan's rate has been down since 100 s, alerted every 5 s; at 127 the battery node logs
    # one ERROR line (a hiccup), clearer than a rate warning, and says no more
    fault = [al(SCAN, "topic_rate", t, "warn") for t in (100, 105, 110, 115, 120, 125, 130)]
    line = al(BATT, "rosout", 127, symptom="log")
    r = analyze(G, [*fault, line], RcaSettings(), None)
    assert [(i.members, i.once, i.current) for i in r.incidents] == [
        ([SCAN], False, True), ([BATT], True, False)]
    assert r.root_causes[0].member == SENSOR
    # said again (a state, not an event), it stands out more: its incident is current
    r = analyze(G, [*fault, line, al(BATT, "rosout", 129, symptom="log")], RcaSettings(), None)
    assert [(i.members, i.once, i.current) for i in r.incidents] == [
        ([SCAN], False, False), ([BATT], False, True)]
    # once, but news: /scan's fault has stood unchanged for longer than `led_max`
    end = 100 + int(RcaSettings().led_max) + 30
    late = al(BATT, "rosout", end + 2, symptom="log")
    r = analyze(G, [*fault, *(al(SCAN, "topic_rate", t, "warn") for t in range(135, end + 1, 5)), late],
                RcaSettings(), None)
    assert [(i.members, i.once, i.current) for i in r.incidents] == [
        ([SCAN], False, False), ([BATT], True, True)]


def test_a_new_incident_after_an_old_one_stood_unchanged_is_current(G):
    # /scan's publisher died at 0 s and its subscriber warned from 5 s on (a larger incident,
    # still going on); a new one begins at 100 s, elsewhere, as clear: once the old one stood
    # unchanged for `reach` (its newest episode began at 5 s), the new one is the news
    episodes = {SCAN: [(0.0, float("inf"))], OBJ: [(5.0, 130.0)], BATTERY: [(100.0, 130.0)]}
    got = find_incidents(G, episodes, 4, 15.0, 130.0)
    assert [i.members for i in got] == [[OBJ, SCAN], [BATTERY]]
    assert current(strengths(got, **{OBJ: 0.64, BATTERY: 0.64})).members == [OBJ, SCAN]
    assert current(strengths(got, **{OBJ: 0.64, BATTERY: 0.4}), reach=60.0).members == [BATTERY]
    # not when the old one changed within `reach` before (its cascade still growing at 50 s) ...
    episodes[OBJ] = [(50.0, 130.0)]
    got = find_incidents(G, episodes, 4, 15.0, 130.0, reach=60.0)
    assert current(strengths(got, **{OBJ: 0.64, BATTERY: 0.4}), reach=60.0).members == [OBJ, SCAN]
    # ... nor when the new one is over and the old goes on
    got = find_incidents(G, {**episodes, OBJ: [(5.0, 130.0)], BATTERY: [(100.0, 101.0)]}, 4, 15.0, 130.0)
    assert current(strengths(got, **{OBJ: 0.64, BATTERY: 0.9}), reach=60.0).members == [OBJ, SCAN]


def test_an_older_unrelated_incident_does_not_take_the_first_place(G):
    # The controller logged errors long ago (an old incident, loud: 10 errors); now the sensor
    # crashes. Before: one ranking of everything in the window put the controller first.
    old = [al(CTRL, "rosout", k) for k in range(0, 50, 5)]
    crash = [al(SENSOR, "member_gone", 300, "fatal"), al(SCAN, "topic_rate", 301), al(OBJ, "topic_rate", 302)]
    r = analyze(G, old + crash, RcaSettings(), None)
    assert r.root_causes[0].member == SENSOR and CTRL not in [rc.member for rc in r.root_causes]
    assert [(i.members, i.current) for i in r.incidents] == [([CTRL], False), ([SENSOR, OBJ, SCAN], True)]
    assert r.incidents[0].root_causes[0].member == CTRL
    rep = r.to_report()["incidents"]
    assert [(i["id"], i["start"], i["end"], i["ongoing"], i["current"]) for i in rep] == [
        (1, 0.0, 45.0, False, False), (2, 300.0, 302.0, True, True)]
    assert rep[1]["root_causes"] == r.to_report()["root_causes"]


def test_a_recurring_symptom_elsewhere_does_not_take_the_first_place(G):
    battery = [al(BATTERY, "topic_rate", t, "warn") for t in (0, 60, 120, 180)]
    fault = [al(SCAN, "topic_rate", t) for t in range(150, 200, 5)]
    r = analyze(G, battery + fault, RcaSettings(), None)
    assert r.root_causes[0].member == SENSOR and BATT not in [rc.member for rc in r.root_causes]
    assert sum(i.members == [BATTERY] for i in r.incidents) == 4


def test_an_ended_upstream_episode_leaves_the_later_fault_its_own_incident(G):
    old = [al(SCAN, "topic_rate", t) for t in (0, 5, 10)]
    fault = [al(PERC, "rosout", 100), al(PERC, "rosout", 101)]
    r = analyze(G, old + fault, RcaSettings(), None)
    assert [rc.member for rc in r.root_causes] == [PERC]
    assert r.root_causes[0].evidence["upstream"] == 0.0


def test_process_evidence_nothing_alerted_on_is_no_incident(G):
    # A process's metrics changed for 10 s (a hint for the ranking) and nothing alerted: no
    # incident, no cause, then or later beside an unrelated alert.
    eng = RcaEngine(RcaSettings(), watchlist=None)
    assert eng.update(G, [], {PROC: 1.0}, t=10.0).root_causes == []
    assert eng.update(G, [], {}, t=20.0).incidents == []
    res = eng.update(G, [al(PLAN, "rosout", 100)], t=100.0)
    assert [rc.member for rc in res.root_causes] == [PLAN]
    assert [(i.members, i.start, i.end, i.ongoing) for i in res.incidents] == [([PLAN], 100.0, 100.0, True)]


def flapping(t0=10.0, cycles=6, period=8.0, on=4.0):
    """The sensor's link drops for ``on`` s every ``period`` s: /scan alerts while it is down,
    /objects 1 s later, /cmd 2 s later; the planner logs errors all along (the loud victim)."""
    out = []
    for c in range(cycles):
        start = t0 + c * period
        for k in range(int(on)):
            t = start + k
            out += [al(SCAN, "topic_rate", t), al(OBJ, "topic_rate", t + 1), al(CMD, "topic_rate", t + 2)]
        out += [al(PLAN, "rosout", start + 2), al(PLAN, "rosout", start + 3)]
    return sorted(out, key=lambda a: a.t)


def test_a_flapping_fault_is_one_incident_and_ranks_its_root_first(G):
    r = analyze(G, flapping(), RcaSettings(), None)
    assert len(r.incidents) == 1 and r.incidents[0].start == 10.0 and r.incidents[0].end == 55.0
    top = r.root_causes[0]
    assert top.member == SENSOR
    assert top.trajectory == [CMD, PLAN, OBJ, PERC, SCAN, SENSOR]
    # The gaps break neither co-occurrence nor time lag: /scan-/objects and /objects-planner
    # match every alert within the tolerance (1), planner-/cmd after a 1 s shift (exp(-1/10));
    # the onsets (10, 11, 12, 12) put /scan-/objects and /objects-planner at lag 1 (5 of the 6
    # pairs are at least as far apart), planner-/cmd at lag 0 (1).
    assert top.evidence["cooccurrence"] == pytest.approx((2 + np.exp(-0.1)) / 3, abs=1e-4)
    assert top.evidence["timelag"] == pytest.approx((5 / 6 + 5 / 6 + 1) / 3, abs=1e-4)
    # the same with the drops longer than episode_gap: each drop its own incident, and the
    # current one (the last drop, still going on) ranks the sensor first as well
    r = analyze(G, flapping(period=40.0), RcaSettings(), None)
    assert len(r.incidents) == 6 and [i.recurring for i in r.incidents] == [False] + [True] * 5
    assert r.incidents[-1].current and r.root_causes[0].member == SENSOR


def test_a_symptom_downstream_does_not_begin_long_before_its_cause(G):
    """The planner (downstream of /scan) alerts from 0 s to 22 s: /scan's symptom from 20 s on
    did not cause it (it began more than the episode gap later), so they are two incidents; from
    10 s on it may have (its detection lagged). A later symptom downstream joins an earlier one
    upstream. Two readers of /scan (a common cause) join whichever began first."""
    def members(eps):
        return [i.members for i in find_incidents(G, eps, 4, 15.0, 32.0)]

    assert members({PLAN: [(0.0, 22.0)], SCAN: [(20.0, 32.0)]}) == [[PLAN], [SCAN]]
    assert members({PLAN: [(0.0, 22.0)], SCAN: [(10.0, 32.0)]}) == [[PLAN, SCAN]]
    assert members({SCAN: [(0.0, 22.0)], PLAN: [(20.0, 32.0)]}) == [[PLAN, SCAN]]
    add_member(G, OTHER)
    add_flow_edge(G, SCAN, OTHER, "sub")
    assert members({OTHER: [(0.0, 22.0)], PERC: [(20.0, 32.0)]}) == [[OTHER], [PERC]]
    assert members({PERC: [(0.0, 22.0)], OTHER: [(5.0, 32.0)]}) == [[OTHER, PERC]]
    assert members({OTHER: [(0.0, 22.0)], PERC: [(20.0, 32.0)], SCAN: [(0.0, 32.0)]}) == [[OTHER, PERC, SCAN]]


def test_metric_evidence_joins_the_nearest_alert_and_bridges_no_two(G):
    """Perception's process (42) also hosts a node that alerts 0-5 s; the sensor upstream alerts
    from 18 s (too late to explain it). The process's CPU evidence at 7 s could go with either:
    it joins the nearer, and does not make the two one incident."""
    add_member(G, OTHER)
    add_tree_edge(G, PROC, OTHER)
    eps = {OTHER: [(0.0, 5.0)], SENSOR: [(18.0, 25.0)], PROC: [(7.0, 8.0)]}
    alerted = {OTHER: eps[OTHER], SENSOR: eps[SENSOR]}
    got = find_incidents(G, eps, 4, 15.0, 25.0, alerted=alerted)
    assert [i.members for i in got] == [[OTHER, PROC], [SENSOR]]
    # as an alert (a plugin confirmed it), it is a symptom and links both
    got = find_incidents(G, eps, 4, 15.0, 25.0, alerted={**alerted, PROC: eps[PROC]})
    assert [i.members for i in got] == [[OTHER, SENSOR, PROC]]


def test_a_topic_that_carried_nothing_then_joins_nothing(G):
    """/scan carried no message (a teleop topic whose joystick is never held): the sensor's exit
    and the perception's symptom 5 s later are two incidents; when it carried up to the
    perception's symptom, one. Carrying again only after the perception's symptom began (a new
    session) does not make it the cause's path; a warning of the perception that its input lost
    the sensor links them whatever the topic carried."""
    from stream_viz.model.traffic import TRAFFIC

    eps = {SENSOR: [(0.0, 10.0)], PERC: [(5.0, 12.0)]}

    def members(spans, blamed=()):
        G.graph[TRAFFIC] = {SCAN: spans}
        return [i.members for i in find_incidents(G, eps, 4, 15.0, 12.0, blamed=blamed, lead=10.0)]

    assert members([]) == [[SENSOR], [PERC]]
    assert members([(-20.0, 6.0)]) == [[PERC, SENSOR]]
    assert members([(11.0, 20.0)]) == [[SENSOR], [PERC]]
    assert members([], blamed=[(PERC, 6.0, SENSOR)]) == [[PERC, SENSOR]]
    # blamed, but the one it blames began 11 s after it (more than the lead): not its cause
    eps[SENSOR] = [(16.0, 20.0)]
    assert members([], blamed=[(PERC, 6.0, SENSOR)]) == [[PERC], [SENSOR]]
    del G.graph[TRAFFIC]


def test_a_warning_that_an_input_lost_its_publisher_joins_the_publisher(G):
    from stream_viz.model.traffic import TRAFFIC

    G.graph[TRAFFIC] = {SCAN: []}  # measured, never carried
    exit_ = [al(SENSOR, "member_gone", t) for t in (0, 5, 10)]
    warn = [al(PERC, "graph_anomalies", t, "warn", symptom="no_publisher", topic=SCAN) for t in (6, 12)]
    r = analyze(G, exit_ + warn, RcaSettings(), None)
    assert [i.members for i in r.incidents] == [[PERC, SENSOR]]
    plain = [al(PERC, "graph_anomalies", t, "warn") for t in (6, 12)]
    r = analyze(G, exit_ + plain, RcaSettings(), None)
    assert [i.members for i in r.incidents] == [[SENSOR], [PERC]]


def test_a_member_whose_alerts_all_blame_a_publisher_is_related_by_them_alone(G):
    """Perception only warns that /scan lost the sensor (5-17 s); another node of its process
    logs errors from 27 s. The warnings say what they are about: the sensor's exit, not the
    other node's fault (the process would join them in any order)."""
    from stream_viz.model.traffic import TRAFFIC

    add_member(G, OTHER)
    add_tree_edge(G, PROC, OTHER)
    G.graph[TRAFFIC] = {SCAN: []}
    exit_ = [al(SENSOR, "member_gone", t) for t in (0, 5, 10)]
    other = [al(OTHER, "rosout", t) for t in (27, 33, 44)]
    warn = [al(PERC, "graph_anomalies", t, "warn", symptom="no_publisher", topic=SCAN) for t in (5, 11, 17)]
    r = analyze(G, exit_ + warn + other, RcaSettings(), None)
    assert [i.members for i in r.incidents] == [[PERC, SENSOR], [OTHER]]
    assert r.root_causes[0].member == OTHER
    # a warning that says nothing of what it is about: the process joins them
    plain = [al(PERC, "graph_anomalies", t, "warn") for t in (5, 11, 17)]
    r = analyze(G, exit_ + plain + other, RcaSettings(), None)
    assert [i.members for i in r.incidents] == [[SENSOR], [OTHER, PERC]]
