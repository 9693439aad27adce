"""The layered layout on tiny literal graphs, with exact expectations."""

from __future__ import annotations

from stream_viz.model import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import ROOT
from stream_viz.viz.layout import COL, ROW, flow_dag, place, service_servers, tree_layout
from stream_viz.viz.sample import demo_graph


def chain():
    """camera -pub-> /image -sub-> detector -pub-> /objects -sub-> planner -send-> map_server."""
    G = new_graph()
    for m in ["node:/camera", "node:/detector", "node:/planner", "node:/map_server",
              "topic:/image", "topic:/objects", "service:/get_map"]:
        add_member(G, m)
    add_flow_edge(G, "node:/camera", "topic:/image", "pub")
    add_flow_edge(G, "topic:/image", "node:/detector", "sub")
    add_flow_edge(G, "node:/detector", "topic:/objects", "pub")
    add_flow_edge(G, "topic:/objects", "node:/planner", "sub")
    add_flow_edge(G, "node:/planner", "node:/map_server", "send", services=["service:/get_map"])
    return G


def test_layers_follow_data_flow_and_service_sits_by_its_server():
    L = place(chain())
    assert L.layer == {"node:/camera": 0, "topic:/image": 1, "node:/detector": 2, "topic:/objects": 3,
                       "node:/planner": 4, "node:/map_server": 5}
    assert L.pos["node:/camera"] == (0.0, 0.0) and L.pos["node:/map_server"] == (5 * COL, 0.0)
    # The service is in the gap right of its server, not on a layer, and touches no edge.
    x, y = L.pos["service:/get_map"]
    assert x == 5 * COL + COL / 2 and 0 < y < ROW
    assert service_servers(chain()) == {"service:/get_map": ["node:/map_server"]}


def test_topic_between_publisher_and_subscribers_and_source_pulled_right():
    G = chain()
    add_member(G, "topic:/goal")  # no publisher: sits just before its subscriber
    add_flow_edge(G, "topic:/goal", "node:/planner", "sub")
    L = place(G)
    assert L.layer["topic:/goal"] == L.layer["node:/planner"] - 1 == 3


def test_cycle_broken_and_positions_stable_as_graph_grows():
    G = chain()
    add_member(G, "topic:/feedback")  # planner -> /feedback -> camera closes a loop
    add_flow_edge(G, "node:/planner", "topic:/feedback", "pub")
    add_flow_edge(G, "topic:/feedback", "node:/camera", "sub")
    D = flow_dag(G)
    assert len(D.edges) == 6  # one of the loop's 7 edges dropped, the rest kept
    L1 = place(G)
    add_member(G, "node:/logger")
    add_member(G, "topic:/log")
    add_flow_edge(G, "node:/detector", "topic:/log", "pub")
    add_flow_edge(G, "topic:/log", "node:/logger", "sub")
    L2 = place(G, L1)
    assert all(L2.pos[m] == p for m, p in L1.pos.items())  # nobody moved
    assert L2.layer["topic:/log"] == L1.layer["node:/detector"] + 1
    assert L2.layer["node:/logger"] == L2.layer["topic:/log"] + 1
    assert len(set(L2.pos.values())) == len(L2.pos)  # no two members on one spot
    assert "node:/logger" not in L1  # place() did not modify its input


def test_demo_layout_has_no_overlaps_and_every_member():
    G = demo_graph(theta=False)
    L = place(G)
    drawn = {m for m, k in G.nodes(data="kind") if k in ("node", "topic", "service")}
    assert set(L.pos) == drawn
    assert len(set(L.pos.values())) == len(L.pos)


def test_tree_layout_parent_centred_over_children():
    G = new_graph()
    for m in [ROOT, "process:1", "process:2", "node:/a", "node:/b"]:
        add_member(G, m)
    add_tree_edge(G, ROOT, "process:1")
    add_tree_edge(G, ROOT, "process:2")
    add_tree_edge(G, "process:1", "node:/a")
    add_tree_edge(G, "process:1", "node:/b")
    from stream_viz.model.queries import tree

    pos = tree_layout(tree(G, 1), ROOT, dx=10, dy=100)
    assert pos["node:/a"] == (0.0, 200.0) and pos["node:/b"] == (10.0, 200.0)
    assert pos["process:1"] == (5.0, 100.0) and pos["process:2"] == (20.0, 100.0)
    assert pos[ROOT] == (12.5, 0.0)


def test_watchlist_overlay_is_drawn_only_when_it_is_a_real_subset():
    from stream_viz.viz.layout import Layout
    from stream_viz.viz.rca import subgraph_arrays

    pos = {f"node:/n{i}": (float(i), 0.0) for i in range(6)}
    layout = Layout(layer={}, row={}, pos=pos, loose=set())
    it = {"j": 1, "t": 0.0, "subgraph": ["node:/n0"], "edges": [], "alert": "node:/n0",
          "watchlist": ["node:/n1", "node:/n2"]}
    assert subgraph_arrays(it, layout)["ids"] == ["node:/n0", "node:/n1", "node:/n2"]
    it["watchlist"] = sorted(pos)  # the auto mode watches everything: not drawn
    assert subgraph_arrays(it, layout)["ids"] == ["node:/n0"]


def test_services_named_as_the_collector_names_them_sit_beside_their_server():
    G = new_graph()
    for m in ("node:/planner", "node:/map_server", "service:/map_server/get_map"):
        add_member(G, m)
    G.nodes["service:/map_server/get_map"]["servers"] = ["/map_server"]
    add_flow_edge(G, "node:/planner", "node:/map_server", "send", services=["/map_server/get_map"])
    assert service_servers(G) == {"service:/map_server/get_map": ["node:/map_server"]}


def test_metrics_batch_grows_with_the_members_to_bound_chunks_per_second():
    from stream_viz.model.theta import SCHEMAS
    from stream_viz.viz.live import metrics_batch_s
    from stream_viz.viz.metrics import MetricBatch

    assert metrics_batch_s(25, 5.0, 20.0) == 5.0  # the demo: every 5 s
    assert metrics_batch_s(500, 5.0, 20.0) == 25.0  # 500 series: 20 chunks/s at most
    assert metrics_batch_s(500, 5.0, 0.0) == 5.0  # no bound
    # A batch keeps θ rows only: one row per process and topic per sample, no graph.
    G, batch = demo_graph(), MetricBatch()
    batch.add(10.0, G)
    batch.add(11.0, G)
    assert len(batch) == sum(1 for _, k in G.nodes(data="kind") if k in ("process", "topic")) == 25
    assert batch.first_t == 10.0
    ts, xs = batch.columns()["topic:/scan"]
    assert ts.tolist() == [10.0, 11.0] and xs.shape == (2, len(SCHEMAS["topic"]))
    batch.clear()
    assert len(batch) == 0 and batch.first_t is None
