"""Who a symptom is charged to (issue 16, items 3 and 8): the publishers of a multi-publisher topic
whose own traffic or evidence changed, and the server an alert names or a client waits on."""

from __future__ import annotations

import pytest

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.rca import RcaSettings, analyze
from stream_viz.rca.charge import LOW_SHARE, charged_nodes, named_nodes, names_in, publisher_shares
from stream_viz.rca.symptoms import IMPLIED_SERVER
from stream_viz.records import Alert

ODOM, LOC, NAV = "node:/odom", "node:/loc", "node:/nav"
TF, POSE, ODOM_T = "topic:/tf", "topic:/pose", "topic:/odom"
BT, PLANNER, GOALS = "node:/bt", "node:/planner", "node:/goals"
GOAL, CMD, PATH, SRV = "topic:/goal", "topic:/cmd", "topic:/path", "service:/planner/compute_path"
S = RcaSettings()
ERR = S.severity["error"]


def al(member, plugin, t, severity="error", **data):
    return Alert(member, plugin, float(t), severity, f"{plugin} on {member}", data)


def tf_graph(rates=None, loc_gone=False):
    """odom and loc both publish /tf (odom also /odom, loc also /pose); nav subscribes to /tf;
    loc runs in process 9."""
    g = new_graph()
    add_member(g, TF, **({"publisher_rates": rates} if rates is not None else {}))
    add_member(g, LOC, **({"gone": True} if loc_gone else {}))
    for m in (ODOM, NAV, POSE, ODOM_T, "process:9"):
        add_member(g, m)
    for node, topic in ((ODOM, TF), (LOC, TF), (ODOM, ODOM_T), (LOC, POSE)):
        add_flow_edge(g, node, topic, "pub")
    add_flow_edge(g, TF, NAV, "sub")
    add_tree_edge(g, "process:9", LOC)
    return g


def causes_of(G, alerts):
    r = analyze(G, alerts, RcaSettings(), None)
    return {rc.member: rc for rc in r.root_causes}, [rc.member for rc in r.root_causes]


def test_publisher_shares_follow_own_traffic_then_other_evidence():
    G = tf_graph({ODOM: 0.0, LOC: 50.0})
    assert publisher_shares(G, TF, [LOC, ODOM], {}) == {ODOM: 1.0, LOC: 0.0}
    G = tf_graph({ODOM: 30.0, LOC: 50.0})  # both publish: the rates do not tell
    assert publisher_shares(G, TF, [LOC, ODOM], {LOC: 0.5}) == {LOC: 1.0, ODOM: LOW_SHARE}
    assert publisher_shares(G, TF, [LOC, ODOM], {LOC: 0.5, ODOM: 0.2}) == {LOC: 1.0, ODOM: 1.0}
    assert publisher_shares(tf_graph(), TF, [LOC, ODOM], {}) == {LOC: 1.0, ODOM: 1.0}
    assert publisher_shares(tf_graph(loc_gone=True), TF, [LOC, ODOM], {}) == {LOC: 1.0, ODOM: 0.0}
    assert publisher_shares(tf_graph(), TF, [LOC], {}) == {LOC: 1.0}
    # the alerts name whose own messages are the symptom (stale stamps): before anything else
    assert publisher_shares(G, TF, [LOC, ODOM], {ODOM: 0.5}, {LOC}) == {LOC: 1.0, ODOM: 0.0}
    assert publisher_shares(G, TF, [LOC, ODOM], {}, {LOC, ODOM}) == {LOC: 1.0, ODOM: 1.0}


def test_a_multi_publisher_symptom_is_charged_to_the_publisher_its_alert_names():
    stale = al(TF, "message_age", 10, "warn", symptom="stale", publishers=[LOC])
    by, order = causes_of(tf_graph(), [stale])
    assert order == [LOC] and by[LOC].evidence["symptoms"] == [TF]


def test_a_multi_publisher_symptom_is_charged_equally_without_other_evidence():
    by, order = causes_of(tf_graph(), [al(TF, "topic_rate", 10)])
    assert by[ODOM].evidence["charged"] == by[LOC].evidence["charged"] == pytest.approx(ERR * S.charge)
    assert order == [LOC, ODOM]  # a tie, broken by id


def test_a_multi_publisher_symptom_is_charged_to_the_publisher_that_stopped():
    by, order = causes_of(tf_graph({ODOM: 0.0, LOC: 50.0}), [al(TF, "topic_rate", 10)])
    assert order == [ODOM]  # loc still publishes at its rate: the symptom is not its
    assert by[ODOM].evidence["symptoms"] == [TF]


def test_a_symptom_the_messages_carry_is_charged_to_the_publisher_that_sends_them():
    # A hot standby (ODOM's rate 0: it sends nothing until it takes over) beside the active one.
    G = tf_graph({ODOM: 0.0, LOC: 50.0})
    assert publisher_shares(G, TF, [LOC, ODOM], {}, carried=True) == {LOC: 1.0, ODOM: 0.0}
    assert publisher_shares(G, TF, [LOC, ODOM], {}, carried=False) == {LOC: 0.0, ODOM: 1.0}
    by, order = causes_of(G, [al(TF, "message_age", 10, "warn", symptom="stale")])
    assert order == [LOC] and by[LOC].evidence["symptoms"] == [TF]
    # A silence beside the stale messages: the absent messages are the one that stopped.
    _, order = causes_of(G, [al(TF, "message_age", 10, "warn", symptom="stale"),
                             al(TF, "topic_rate", 11, symptom="silence")])
    assert order == [ODOM]


def test_a_multi_publisher_symptom_follows_the_publishers_other_outputs_and_process():
    alerts = [al(TF, "topic_rate", 10), al(POSE, "topic_rate", 10)]
    by, order = causes_of(tf_graph(), alerts)
    assert order[0] == LOC
    assert by[LOC].evidence["charged"] == pytest.approx(ERR * S.charge)
    assert by[ODOM].evidence["charged"] == pytest.approx(ERR * S.charge * LOW_SHARE)
    alerts = [al(TF, "topic_rate", 10), al("process:9", "process_resources", 9, "warn")]
    by, order = causes_of(tf_graph(), alerts)
    assert order[0] == LOC and by[ODOM].evidence["charged"] == pytest.approx(ERR * S.charge * LOW_SHARE)
    # evidence of its own long before the topic's symptom does not count
    alerts = [al(POSE, "topic_rate", 10), al(TF, "topic_rate", 100)]
    by, _ = causes_of(tf_graph(), alerts)
    assert by[ODOM].evidence["charged"] == pytest.approx(ERR * S.charge)


def service_graph():
    """goals → /goal → bt → /cmd; bt calls the planner's /planner/compute_path; the planner
    publishes /path, which nobody in the fault touches."""
    g = new_graph()
    for m in (BT, GOALS, GOAL, CMD, PATH):
        add_member(g, m)
    add_member(g, PLANNER)
    add_member(g, SRV, servers=["/planner"], clients=["/bt"])
    add_flow_edge(g, GOALS, GOAL, "pub")
    add_flow_edge(g, GOAL, BT, "sub")
    add_flow_edge(g, BT, CMD, "pub")
    add_flow_edge(g, PLANNER, PATH, "pub")
    add_flow_edge(g, BT, PLANNER, "send", services=[SRV])
    return g


def test_names_resolve_to_nodes_and_to_the_servers_of_services():
    G = service_graph()
    assert named_nodes(G, "/planner") == named_nodes(G, "planner") == named_nodes(G, PLANNER) == [PLANNER]
    assert named_nodes(G, "/planner/compute_path") == named_nodes(G, SRV) == [PLANNER]
    G.remove_node(SRV)  # the service member unknown: the send edge that carries it says who serves it
    assert named_nodes(G, "/planner/compute_path") == [PLANNER]
    assert named_nodes(G, "/nobody") == [] and named_nodes(G, "topic:/cmd") == []
    assert charged_nodes(service_graph(), SRV) == [PLANNER] and charged_nodes(G, CMD) == [BT]
    assert names_in({"server": "/planner", "client": "/bt", "service": SRV, "names": ["/x", 3]}) == [
        "/planner", SRV, "/x"]


def test_a_silent_server_behind_a_complaining_client_ranks_first():
    # The client logs errors naming the service it waits for and its output stalls; the server's
    # own topic looks healthy. Before: the server was no candidate at all.
    alerts = [al(BT, "rosout", 10 + k, names=["/planner/compute_path"]) for k in range(4)]
    alerts += [al(CMD, "topic_rate", 11), al(CMD, "topic_rate", 16)]
    by, order = causes_of(service_graph(), alerts)
    assert order[:2] == [PLANNER, BT]
    assert by[PLANNER].evidence["charged"] == pytest.approx(ERR * S.charge)
    assert by[PLANNER].evidence["symptoms"] == [BT]
    assert by[BT].evidence["upstream"] == pytest.approx(ERR * S.charge)
    assert by[PLANNER].trajectory[-2:] == [BT, PLANNER]


def test_a_client_that_stalls_before_it_complains_still_points_at_its_server():
    # The client's output stops at 10 while its call is open; only at 13 does its call time out
    # and it logs an ERROR naming the server. The wait began with the stall: the server's named
    # symptom is dated from 10, so it excuses the client. Before: the client's stall at 10 came
    # "before" the server's symptom at 13 and the client ranked first.
    data = {"server": "/planner", "client": "/bt", "service": SRV}
    alerts = [al(CMD, "topic_rate", 10), al(CMD, "topic_rate", 15),
              al(BT, "rosout", 13, symptom="log"), al(BT, "services", 13, **data)]
    by, order = causes_of(service_graph(), alerts)
    assert order[:2] == [PLANNER, BT]
    assert by[BT].evidence["upstream"] == pytest.approx(ERR * S.charge)
    # An older episode of the client, ended long before the complaint, dates nothing.
    _, order = causes_of(service_graph(), [al(CMD, "topic_rate", -60), *alerts[1:]])
    assert order[0] == PLANNER


def test_a_services_alert_points_at_the_server():
    data = {"server": "/planner", "client": "/bt", "service": "/planner/compute_path"}
    for member in (SRV, BT):  # on the service, or on the client that waits
        alerts = [al(member, "services", 10, **data), al(CMD, "topic_rate", 12)]
        by, order = causes_of(service_graph(), alerts)
        assert order[0] == PLANNER, member
        assert by[PLANNER].evidence["charged"] == pytest.approx(ERR * S.charge)
    # a symptom on the service member alone (no data) goes to its server, in the client's incident
    r = analyze(service_graph(), [al(SRV, "services", 10), al(CMD, "topic_rate", 12)], RcaSettings(), None)
    assert len(r.incidents) == 1 and r.root_causes[0].member == PLANNER


def test_an_unnamed_server_of_an_unexplained_client_is_a_weaker_candidate():
    # Stalled output and error logs, nothing names the server: the client stays first, and the
    # server it calls is a candidate too (it may be what the client waits for).
    alerts = [al(BT, "rosout", 10), al(CMD, "topic_rate", 11)]
    by, order = causes_of(service_graph(), alerts)
    assert order == [BT, PLANNER]
    assert by[PLANNER].evidence["charged"] == pytest.approx(ERR * S.charge * IMPLIED_SERVER)
    assert by[PLANNER].evidence["implied"] == "server" and "implied" not in by[BT].evidence
    assert by[BT].evidence["upstream"] == 0.0  # a suspicion excuses nobody
    # A client explained by its input (the goals stopped) makes no suspect of its server.
    _, order = causes_of(service_graph(), [al(GOAL, "topic_rate", 9), *alerts])
    assert PLANNER not in order and order[0] == GOALS


def test_a_node_only_named_by_its_readers_errors_ranks_first():
    # A localiser deactivated: its silence is healthy to the rate rule, so it has no alert; its
    # readers (the navigator, then the controller) log ERRORs, the controller's naming it. The
    # named localiser takes its trajectory's dependency from the controller that named it.
    g = new_graph()
    for m in (LOC, NAV, BT, POSE, CMD):
        add_member(g, m)
    add_flow_edge(g, LOC, POSE, "pub")
    add_flow_edge(g, POSE, NAV, "sub")
    add_flow_edge(g, POSE, BT, "sub")
    add_flow_edge(g, NAV, CMD, "pub")
    follow = "action:/follow_path"  # the navigator waits on the controller's action
    add_member(g, follow, servers=["/nav"], clients=["/bt"])
    add_flow_edge(g, BT, NAV, "send", services=[follow])
    named = {"symptom": "log", "names": [LOC]}
    alerts = [al(BT, "rosout", 10.0, symptom="log"), al(NAV, "rosout", 10.2, **named),
              al(BT, "rosout", 20.0, symptom="log"), al(NAV, "rosout", 20.2, **named)]
    by, order = causes_of(g, alerts)
    assert order[0] == LOC, order
    assert by[LOC].trajectory[-1] == LOC and by[LOC].evidence["cooccurrence"] is not None


def test_what_a_servers_client_publishes_never_excuses_the_server_round_its_sibling():
    # nav2: the controller, composed with the planner, follows what the navigator publishes from
    # the planner's answer. The planner stops answering: the navigator's output stops first (its
    # last message before the complaint), and through the sibling it would excuse the planner.
    G = service_graph()
    ctrl = "node:/controller"
    add_member(G, ctrl)
    add_member(G, "process:3")
    add_tree_edge(G, "process:3", PLANNER)
    add_tree_edge(G, "process:3", ctrl)
    add_flow_edge(G, CMD, ctrl, "sub")
    data = {"server": "/planner", "client": "/bt", "service": "/planner/compute_path"}
    alerts = [al(CMD, "topic_rate", 12, since=6.0, since_within=3.0), al(BT, "rosout", 10, symptom="log"),
              al(BT, "services", 10, **data)]
    by, order = causes_of(G, alerts)
    assert order[:2] == [PLANNER, BT]
    assert by[PLANNER].evidence["upstream"] == 0.0
