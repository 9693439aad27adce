"""The model on tiny literal graphs, with exact expectations."""

from __future__ import annotations

import numpy as np
import pytest

from stream_viz.errors import ModelError
from stream_viz.model import (
    ROOT,
    add_flow_edge,
    add_member,
    add_tree_edge,
    diff,
    kind_of,
    layer_subgraph,
    make_id,
    name_of,
    new_graph,
    predecessors,
    psi,
    successors,
)
from stream_viz.model.graph import FLOW, PROCESS_TREE
from stream_viz.model.ids import node_fqn, pid_of
from stream_viz.model.queries import (
    called_servers,
    clients,
    flow_predecessors,
    flow_successors,
    nodes_of_process,
    process_of_node,
    published_topics,
    publishers,
    servers,
    subscribed_topics,
    subscribers,
)
from stream_viz.model.serialize import from_data, to_data
from stream_viz.model.theta import make_theta, theta_dict


def robot():
    """camera -pub-> /image -sub-> detector -pub-> /objects -sub-> planner; planner -send-> map_server."""
    G = new_graph()
    for m in ["node:/camera", "node:/detector", "node:/planner", "node:/map_server",
              "topic:/image", "topic:/objects", "service:/get_map",
              "process:10", "process:11", "process:1", ROOT]:
        add_member(G, m)
    G.nodes["service:/get_map"].update(servers=["/map_server"], clients=["/planner"])
    add_flow_edge(G, "node:/camera", "topic:/image", "pub")
    add_flow_edge(G, "topic:/image", "node:/detector", "sub")
    add_flow_edge(G, "node:/detector", "topic:/objects", "pub")
    add_flow_edge(G, "topic:/objects", "node:/planner", "sub")
    add_flow_edge(G, "node:/planner", "node:/map_server", "send", services=["service:/get_map"])
    add_tree_edge(G, ROOT, "process:1")
    add_tree_edge(G, "process:1", "process:10")
    add_tree_edge(G, "process:1", "process:11")
    add_tree_edge(G, "process:10", "node:/camera")
    add_tree_edge(G, "process:10", "node:/detector")
    add_tree_edge(G, "process:11", "node:/planner")
    add_tree_edge(G, "process:11", "node:/map_server")
    return G


def test_ids_round_trip():
    assert make_id("node", "/ns/cam") == "node:/ns/cam"
    assert make_id("topic", "scan") == "topic:/scan"
    assert make_id("process", 42) == "process:42"
    assert make_id("root", "x") == "root"
    assert kind_of("service:/a/b") == "service" and name_of("service:/a/b") == "/a/b"
    assert kind_of(ROOT) == "root" and pid_of("process:42") == 42
    assert node_fqn("/", "cam") == "/cam" and node_fqn("/ns", "cam") == "/ns/cam"
    with pytest.raises(ModelError, match="malformed member id 'cam'"):
        kind_of("cam")
    with pytest.raises(ModelError, match="unknown member kind"):
        make_id("robot", "x")


def test_active_and_passive_are_disjoint():
    G = robot()
    active = {m for m, a in G.nodes(data="active") if a}
    assert active == {"node:/camera", "node:/detector", "node:/planner", "node:/map_server"}


def test_flow_edge_kinds_are_checked():
    G = robot()
    with pytest.raises(ModelError, match="topic:/image must be active"):
        add_flow_edge(G, "topic:/image", "node:/camera", "pub")
    with pytest.raises(ModelError, match="is not in the graph"):
        add_flow_edge(G, "node:/ghost", "topic:/image", "pub")


def test_predecessors_and_successors():
    G = robot()
    assert predecessors(G, "node:/detector") == ["topic:/image"]
    assert predecessors(G, "node:/detector", "active") == []
    assert successors(G, "node:/planner") == ["node:/map_server"]
    assert successors(G, "node:/planner", "passive") == []
    assert predecessors(G, "node:/map_server", "active") == ["node:/planner"]
    # Tree layer: a process's children are its nodes and child processes.
    assert successors(G, "process:1", layer=1) == ["process:10", "process:11"]
    assert predecessors(G, "node:/camera", layer=1) == ["process:10"]


def test_named_queries():
    G = robot()
    assert publishers(G, "topic:/image") == ["node:/camera"]
    assert subscribers(G, "topic:/image") == ["node:/detector"]
    assert published_topics(G, "node:/detector") == ["topic:/objects"]
    assert subscribed_topics(G, "node:/detector") == ["topic:/image"]
    assert servers(G, "service:/get_map") == ["node:/map_server"]
    assert clients(G, "service:/get_map") == ["node:/planner"]
    assert called_servers(G, "node:/planner") == ["node:/map_server"]
    assert nodes_of_process(G, "process:10") == ["node:/camera", "node:/detector"]
    assert nodes_of_process(G, "process:1") == []  # child processes are not its nodes
    assert process_of_node(G, "node:/planner") == "process:11"
    assert flow_successors(G, "node:/planner") == {"node:/map_server"}
    assert flow_predecessors(G, "topic:/objects") == {"node:/detector"}
    # Members missing from the graph: empty answers.
    assert publishers(G, "topic:/nothing") == [] and process_of_node(G, "node:/ghost") is None
    assert predecessors(G, "node:/ghost") == [] and nodes_of_process(G, "process:99") == []


def test_node_of_a_process_known_only_by_pid():
    G = robot()
    add_member(G, "node:/orphan", pid=11)
    assert process_of_node(G, "node:/orphan") == "process:11"
    assert nodes_of_process(G, "process:11") == ["node:/map_server", "node:/planner"]
    assert nodes_of_process(G, "process:11", by_pid=True) == ["node:/map_server", "node:/orphan",
                                                              "node:/planner"]
    assert (FLOW, PROCESS_TREE) == (0, 1)


def test_layer_subgraphs():
    G = robot()
    G0 = layer_subgraph(G, 0)
    assert set(G0.nodes) == {"node:/camera", "node:/detector", "node:/planner", "node:/map_server",
                             "topic:/image", "topic:/objects"}
    assert G0.number_of_edges() == 5
    T1 = layer_subgraph(G, 1)
    assert "topic:/image" not in T1 and T1.number_of_edges() == 7


def test_psi_matches_hand_sums():
    G = robot()
    theta = {
        "process:1": np.array([1.0, 100.0]),
        "process:10": np.array([20.0, 50.0]),
        "process:11": np.array([5.0, 30.0]),
    }
    out = psi(G, theta, layer=1)
    # ψ(p10) = its children are nodes without θ -> 0
    np.testing.assert_array_equal(out["process:10"], [0.0, 0.0])
    # ψ(p1) = (ψ(p10)+θ(p10)) + (ψ(p11)+θ(p11)) = [25, 80]
    np.testing.assert_array_equal(out["process:1"], [25.0, 80.0])
    # ψ(root) = ψ(p1)+θ(p1) = [26, 180]
    np.testing.assert_array_equal(out[ROOT], [26.0, 180.0])


def test_diff_reports_appeared_and_vanished():
    a = robot()
    b = robot()
    b.remove_node("node:/camera")
    add_member(b, "node:/lidar")
    d = diff(a, b)
    assert d.added_members == {"node:/lidar"}
    assert d.removed_members == {"node:/camera"}
    assert d.removed_edges == {("node:/camera", "topic:/image", 0), ("process:10", "node:/camera", 1)}
    assert not diff(a, robot())


def test_theta_schema_and_serialisation_round_trip():
    th = make_theta("topic", {"rate_hz": 10.0, "latency_ms": 2.5})
    assert theta_dict("topic", th)["rate_hz"] == 10.0
    assert np.isnan(theta_dict("topic", th)["jitter_ms"])
    with pytest.raises(ModelError, match="unknown attributes"):
        make_theta("topic", {"colour": 1})
    G = robot()
    G.nodes["node:/camera"]["pid"] = 10
    G.nodes["topic:/image"]["theta"] = th
    data = to_data(G)
    assert {"id": "node:/camera", "kind": "node", "pid": 10} in data["members"]
    assert {"src": "node:/camera", "dst": "topic:/image", "kind": "pub", "layer": 0} in data["edges"]
    H = from_data(data)
    assert set(H.edges(keys=True)) == set(G.edges(keys=True))
    assert H.nodes["topic:/image"]["theta"][0] == 10.0


def test_remember_keeps_vanished_members_marked_gone():
    from stream_viz.model.seen import remember

    a = robot()
    seen = remember(new_graph(), a, 1.0)
    assert set(seen.nodes) == set(a.nodes) and not any(g for _, g in seen.nodes(data="gone"))
    b = robot()
    b.remove_node("node:/camera")
    seen = remember(seen, b, 2.0)
    assert seen.nodes["node:/camera"]["gone"] is True and seen.nodes["node:/camera"]["gone_at"] == 2.0
    assert seen.edges["node:/camera", "topic:/image", 0]["gone"] is True
    assert "gone" not in seen.nodes["node:/detector"]
    seen = remember(seen, b, 3.0)
    assert seen.nodes["node:/camera"]["gone_at"] == 2.0  # first time missed, kept
    seen = remember(seen, robot(), 4.0)  # it came back
    assert "gone" not in seen.nodes["node:/camera"]
    assert "gone" not in seen.edges["node:/camera", "topic:/image", 0]
    # Live members carry their current attributes only: a reason that no longer holds goes.
    c = robot()
    c.nodes["topic:/image"]["reason"] = "cannot subscribe"
    seen = remember(seen, c, 5.0)
    assert seen.nodes["topic:/image"]["reason"] == "cannot subscribe"
    d = robot()
    seen = remember(seen, d, 6.0)
    assert seen.nodes["topic:/image"] == robot().nodes["topic:/image"]
    assert seen is d  # nothing gone: the live model itself, no copy


def test_drop_gone_forgets_members_vanished_longer_than_the_retention():
    from stream_viz.model.seen import drop_gone, remember

    b = robot()
    b.remove_node("node:/camera")
    seen = remember(remember(new_graph(), robot(), 1.0), b, 2.0)  # camera gone at 2.0
    assert drop_gone(seen, 500.0, 600.0) == [] and "node:/camera" in seen
    assert drop_gone(seen, 700.0, 0.0) == []  # 0: kept for the whole run
    assert drop_gone(seen, 700.0, 600.0) == ["node:/camera"]
    assert "node:/camera" not in seen and not seen.has_edge("node:/camera", "topic:/image")
    assert set(seen.nodes) == set(b.nodes)


def test_shadow_records_members_and_theta_and_forgets_the_long_gone():
    from stream_viz.model.shadow import Shadow

    sh = Shadow(history=3, forget_gone_s=10.0)
    a = robot()
    a.nodes["node:/camera"]["theta"] = np.array([1.0])
    a.nodes["topic:/image"]["theta"] = np.array([5.0, 0.0])
    assert sh.record(a, 1.0) == []
    b = robot()
    b.remove_node("node:/camera")
    b.nodes["topic:/image"]["theta"] = np.array([6.0, 0.0])
    for t in (2.0, 3.0, 4.0, 12.0):
        assert sh.record(b, t) == []  # gone at 2.0: kept 10 s
    assert sh.seen.nodes["node:/camera"]["gone"] is True and "node:/camera" in sh.history
    assert list(sh.history.times("topic:/image")) == [3.0, 4.0, 12.0]  # the last 3 samples
    assert sh.record(b, 12.5) == ["node:/camera"]  # 10.5 s gone: forgotten, with its history
    assert "node:/camera" not in sh.seen and "node:/camera" not in sh.history
    assert set(sh.seen) == set(b.nodes) and set(sh.history) == {"topic:/image"}
