"""The layered layout on tiny literal graphs, with exact expectations."""

from __future__ import annotations

import pytest

from stream_viz.model import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import ROOT
from stream_viz.viz.layout import (
    COL,
    ROW,
    Layout,
    flow_dag,
    layered,
    place,
    provisional,
    service_servers,
    settle,
    structure,
    tree_layout,
)
from stream_viz.viz.layout_dot import dot_executable
from stream_viz.viz.layout_groups import member_groups, short_label
from stream_viz.viz.layout_quality import edge_crossings, edge_length
from stream_viz.viz.sample import demo_graph
from stream_viz.viz.system import group_boxes, system_arrays


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


# -- the layout by Graphviz dot, settling, groups, and how readable a layout is ---------------------

needs_dot = pytest.mark.skipif(dot_executable() is None, reason="no Graphviz dot (scripts/install)")


def built(members, edges):
    """A graph with ``members`` added in the given order, then ``edges`` (u, v, kind) in order."""
    G = new_graph()
    for m in members:
        add_member(G, m)
    for u, v, kind, *extra in edges:
        add_flow_edge(G, u, v, kind, **(extra[0] if extra else {}))
    return G


@needs_dot
def test_the_same_system_gets_the_same_positions_whatever_the_discovery_order():
    G1 = chain()
    members = list(reversed(list(G1.nodes)))
    edges = [(u, v, d["kind"], {k: x for k, x in d.items() if k != "kind"})
             for u, v, d in reversed(list(G1.edges(data=True)))]
    G2 = built(members, edges)
    assert list(G2.nodes) != list(G1.nodes)
    L1, L2 = layered(G1), layered(G2)
    assert L1.pos == L2.pos and len(L1.pos) == 7


@needs_dot
def test_dot_lays_data_out_left_to_right_with_the_service_beside_its_server():
    L = layered(chain())
    x = {m: p[0] for m, p in L.pos.items()}
    flow = ["node:/camera", "topic:/image", "node:/detector", "topic:/objects", "node:/planner",
            "node:/map_server"]
    assert [x[m] for m in flow] == sorted(x[m] for m in flow) and len(set(x[m] for m in flow)) == 6
    assert x["service:/get_map"] > x["node:/map_server"]  # the next layer right of its server
    assert abs(L.pos["service:/get_map"][1] - L.pos["node:/map_server"][1]) < ROW
    assert len(set(L.pos.values())) == len(L.pos)


@needs_dot
def test_settle_relayouts_only_once_a_changed_structure_stayed_the_same():
    G = chain()
    L0 = settle(G, None)
    assert settle(G, L0) is L0  # unchanged: the very same layout
    add_member(G, "node:/logger")
    add_flow_edge(G, "topic:/objects", "node:/logger", "sub")
    L1 = settle(G, L0, after=3)
    assert all(L1.pos[m] == p for m, p in L0.pos.items())  # nobody moved
    right = max(p[0] for p in L0.pos.values())
    assert L1.pos["node:/logger"][0] > right and L1.key == L0.key and L1.pending_n == 1
    L2 = settle(G, L1, after=3)
    assert L2.pos == L1.pos and L2.pending_n == 2
    L3 = settle(G, L2, after=3)  # the third sample of the same structure: laid out again
    assert L3.key == structure(G) and L3.pending is None
    assert L3.pos == layered(G).pos and L3.pos["node:/logger"][0] < right + COL
    # a structure that changes again restarts the count
    add_member(G, "topic:/log")
    add_flow_edge(G, "node:/logger", "topic:/log", "pub")
    assert settle(G, L3, after=3).pending_n == 1


def test_a_new_member_waits_in_a_provisional_column_right_of_everything():
    L = Layout(pos={"node:/a": (0.0, 0.0), "topic:/t": (100.0, 40.0)}, boxes={"/x": (0, 0, 300.0, 50)})
    G = built(["node:/a", "topic:/t", "node:/c", "node:/b"], [])
    out = provisional(G, L)
    assert out.pos["node:/b"] == (300.0 + COL, 0.0) and out.pos["node:/c"] == (300.0 + COL, ROW / 2)
    assert "node:/b" not in L.pos and provisional(built(["node:/a"], []), L) is L


def test_namespace_groups_need_a_node_and_labels_drop_the_group_prefix():
    G = built(["node:/amr1/amcl", "topic:/amr1/scan", "topic:/amr1/camera/image", "topic:/diagnostics",
               "topic:/t/a", "topic:/t/b", "node:/solo/x"], [])
    groups = member_groups(G, sorted(G))
    assert groups == {"node:/amr1/amcl": "/amr1", "topic:/amr1/scan": "/amr1",
                      "topic:/amr1/camera/image": "/amr1"}  # /t has no node, /solo one member
    assert short_label(G, "topic:/amr1/camera/image", "/amr1") == "camera/image"
    assert short_label(G, "topic:/diagnostics", None) == "/diagnostics"
    pos = {m: (float(i), 0.0) for i, m in enumerate(sorted(G))}
    L = Layout(pos=pos, group_of=groups, boxes={"/amr1": (0.0, -10.0, 50.0, 10.0)})
    a = system_arrays(G, L)
    assert dict(zip(a["ids"], a["labels"], strict=True))["topic:/amr1/scan"] == "scan"
    assert dict(zip(a["ids"], a["labels"], strict=True))["topic:/t/a"] == "/t/a"
    assert group_boxes(L) == {"/namespace/amr1": [(0.0, -10.0), (50.0, 10.0)]}


def test_process_groups_are_named_after_the_hosting_process():
    G = built(["node:/a", "node:/b", "node:/c", "topic:/t", "process:7", "process:8"], [])
    G.nodes["process:7"]["name"] = "navigation"
    for n in ("node:/a", "node:/b"):
        add_tree_edge(G, "process:7", n)
    add_tree_edge(G, "process:8", "node:/c")
    assert member_groups(G, ["node:/a", "node:/b", "node:/c", "topic:/t"], "process") == {
        "node:/a": "navigation", "node:/b": "navigation"}  # pid 8 hosts one node: no box


@needs_dot
def test_a_namespace_is_one_box_around_its_members_and_nothing_else():
    G = built(["node:/r/a", "topic:/r/t", "node:/r/b", "node:/c", "topic:/u"],
              [("node:/r/a", "topic:/r/t", "pub"), ("topic:/r/t", "node:/r/b", "sub"),
               ("node:/c", "topic:/u", "pub"), ("topic:/u", "node:/r/b", "sub")])
    L = layered(G)
    (x0, y0, x1, y1), = L.boxes.values()
    inside = {m for m, (x, y) in L.pos.items() if x0 < x < x1 and y0 < y < y1}
    assert inside == {"node:/r/a", "topic:/r/t", "node:/r/b"}


def test_crossings_and_length_of_straight_edges():
    pos = {"a": (0.0, 0.0), "b": (2.0, 2.0), "c": (0.0, 2.0), "d": (2.0, 0.0), "e": (3.0, 4.0)}
    assert edge_crossings(pos, [("a", "b"), ("c", "d")]) == 1  # an X
    assert edge_crossings(pos, [("a", "b"), ("b", "a"), ("a", "d")]) == 0  # one pair; a shared end
    assert edge_crossings(pos, [("a", "c"), ("b", "d")]) == 0  # parallel
    assert edge_length(pos, [("a", "e"), ("e", "a"), ("a", "d")]) == 7.0  # 5 once, plus 2


@needs_dot
def test_the_amr_recording_has_its_namespace_box_short_labels_and_overlays_on_the_members(tmp_path):
    from stream_viz.demo.robots import robot_topology
    from stream_viz.viz import paths
    from stream_viz.viz.recorder import Recorder
    from stream_viz.viz.sample import topology_graph
    from tests.viz.rrd import rows

    G = topology_graph(robot_topology("amr"))
    it = {"j": 1, "t": 12.0, "subgraph": ["topic:/amr1/scan"], "watchlist": [], "edges": [],
          "alert": "topic:/amr1/scan"}
    rc = [{"member": "node:/amr1/scan_merger", "score": 1.0,
           "trajectory": ["topic:/amr1/scan", "node:/amr1/scan_merger"]}]
    with Recorder(save=tmp_path / "amr.rrd") as r:
        r.system(G, t=10.0)
        r.rca(G, it, rc)
    data = rows(tmp_path / "amr.rrd")
    system = data[paths.SYSTEM][0]
    pos = dict(zip(system["GraphNodes:node_ids"], map(tuple, system["GraphNodes:positions"]), strict=True))
    labels = dict(zip(system["GraphNodes:node_ids"], system["GraphNodes:labels"], strict=True))
    assert labels["node:/amr1/scan_merger"] == "scan_merger"
    assert labels["topic:/diagnostics"] == "/diagnostics"
    box = data["/namespace/amr1"][0]
    (x0, y0), (x1, y1) = box["GraphNodes:positions"]
    inside = {m for m, (x, y) in pos.items() if x0 < x < x1 and y0 < y < y1}
    assert inside == {m for m in pos if m.split(":", 1)[1].startswith("/amr1/")}
    traj = next(row for row in data[paths.RCA_TRAJECTORY] if row.get("rca_iteration") == 1)
    for m, p in zip(traj["GraphNodes:node_ids"], traj["GraphNodes:positions"], strict=True):
        assert tuple(p) == pos[m]


@needs_dot
def test_no_two_labels_overlap_in_the_dot_layout_of_the_amr():
    from stream_viz.demo.robots import robot_topology
    from stream_viz.viz.layout_dot import BOX_H, BOX_PAD, CHAR_W
    from stream_viz.viz.sample import topology_graph

    G = topology_graph(robot_topology("amr"))
    L = layered(G)
    boxes = []
    for m, (x, y) in L.pos.items():
        w = CHAR_W * len(short_label(G, m, L.group_of.get(m))) + BOX_PAD
        boxes.append((m, x - w / 2, y - BOX_H / 2, x + w / 2, y + BOX_H / 2))
    for i, (a, ax0, ay0, ax1, ay1) in enumerate(boxes):
        for b, bx0, by0, bx1, by1 in boxes[i + 1:]:
            assert ax1 <= bx0 or bx1 <= ax0 or ay1 <= by0 or by1 <= ay0, (a, b)


def test_a_group_that_is_gone_is_cleared_and_the_others_logged_again(tmp_path):
    import rerun as rr

    from stream_viz.viz.system import log_groups
    from tests.viz.rrd import rows

    rec = rr.RecordingStream("stream_viz_test")
    rec.save(str(tmp_path / "g.rrd"))
    rec.set_time("time", timestamp=1.0)
    log_groups(rec, Layout(boxes={"/a": (0.0, 0.0, 1.0, 1.0), "/b": (2.0, 0.0, 3.0, 1.0)}))
    rec.set_time("time", timestamp=2.0)
    log_groups(rec, Layout(boxes={"/b": (2.0, 0.0, 4.0, 1.0)}))
    rec.flush()
    rec.disconnect()
    data = rows(tmp_path / "g.rrd")
    assert [sorted(k for k in row if k.startswith(("Clear", "GraphNodes:positions"))) for row in
            data["/namespace/a"]] == [["GraphNodes:positions"], ["Clear:is_recursive"]]
    assert [row["GraphNodes:positions"] for row in data["/namespace/b"]] == [
        [[2.0, 0.0], [3.0, 1.0]], [[2.0, 0.0], [4.0, 1.0]]]
