"""The graph views' arrays as Rerun archetypes, and what /system is compared by between samples."""

from __future__ import annotations

import numpy as np
import rerun as rr

from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.rca.cooccurrence import cooccurrence
from stream_viz.viz.graph_arrays import edge_array, graph_archetypes
from stream_viz.viz.system import drawn_status, signatures


def _arrow(batch):
    return batch.as_arrow_array()


def test_numpy_archetypes_log_the_same_arrow_data_as_lists():
    a = {"ids": ["node:/a", "topic:/t", "node:/b"], "labels": ["a", "t", "b (gone)"],
         "colors": [(66, 133, 244), (245, 166, 35), (150, 150, 150)], "radii": [16.0, 9.0, 16.0],
         "positions": [(0.0, 1.0), (2.5, 3.0), (4.0, -1.0)],
         "edges": [("node:/a", "topic:/t"), ("topic:/t", "node:/b")]}
    nodes, edges = graph_archetypes(a, show_labels=True)
    ref_nodes = rr.GraphNodes(a["ids"], labels=a["labels"], colors=a["colors"], radii=a["radii"],
                              positions=a["positions"], show_labels=True)
    ref_edges = rr.GraphEdges(a["edges"], graph_type=rr.GraphType.Directed)
    for f in ("node_ids", "labels", "colors", "radii", "positions", "show_labels"):
        assert _arrow(getattr(nodes, f)).equals(_arrow(getattr(ref_nodes, f))), f
    for f in ("edges", "graph_type"):
        assert _arrow(getattr(edges, f)).equals(_arrow(getattr(ref_edges, f))), f


def test_empty_arrays_give_empty_archetypes():
    a = {"ids": [], "colors": [], "radii": [], "positions": [], "edges": []}
    nodes, edges = graph_archetypes(a, show_labels=False)
    assert nodes.labels is None
    assert len(_arrow(nodes.node_ids)) == 0 and len(_arrow(edges.edges)) == 0
    assert edge_array([]).shape == (0, 2)


def _graph():
    G = new_graph()
    for m in ("process:1", "node:/a", "node:/b", "topic:/t"):
        add_member(G, m)
    add_tree_edge(G, "process:1", "node:/a")
    add_flow_edge(G, "node:/a", "topic:/t", "pub")
    add_flow_edge(G, "topic:/t", "node:/b", "sub")
    return G


def test_drawn_status_keeps_the_members_system_colours():
    status = {"process:1": "error", "node:/a": "warn", "node:/b": "fatal"}
    assert drawn_status(status) == {("node:/a", "warn"), ("node:/b", "fatal")}
    assert drawn_status(status, gone={"node:/b"}) == {("node:/a", "warn")}


def test_signatures_split_flow_and_tree_edges():
    G = _graph()
    sig, tree = signatures(G, frozenset(), frozenset())
    assert sig[1] == {("node:/a", "topic:/t", "pub"), ("topic:/t", "node:/b", "sub")}
    assert tree == (frozenset({("process:1", "node:/a", 1)}), frozenset())
    G.nodes["node:/a"]["label"] = "A"
    assert signatures(G, frozenset(), frozenset())[0] != sig  # a new label is drawn
    assert signatures(G, frozenset(), frozenset())[1] == tree


def test_cooccurrence_asked_again_gives_the_same_result():
    a, b = [10.0, 11.0, 12.0, 20.0], np.array([13.0, 14.0, 15.0, 23.0])
    first = cooccurrence(a, b)
    assert first.offset == 3.0 and first.matched == 1.0
    assert cooccurrence(list(a), b.copy()) == first
    assert cooccurrence(a, b, tolerance=0.5) != cooccurrence(a, b + 0.7, tolerance=0.5)
