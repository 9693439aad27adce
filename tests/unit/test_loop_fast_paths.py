"""The main loop's fast paths (record and show steps) against the straightforward definitions they
replace, on small literal graphs and seeded random ones: the same answers, exactly."""

from __future__ import annotations

import random

import networkx as nx
import numpy as np

from stream_viz.model.graph import (
    FLOW,
    add_flow_edge,
    add_member,
    add_tree_edge,
    copy_graph,
    graph_over,
    new_graph,
)
from stream_viz.model.history import History
from stream_viz.model.seen import missing_among, missing_edges, remember
from stream_viz.viz.system import signatures

A, B, T = "node:/a", "node:/b", "topic:/t"


def _missing_by_definition(seen: nx.MultiDiGraph, G: nx.MultiDiGraph) -> list[tuple]:
    return [(u, v, k, a) for u, v, k, a in seen.edges(keys=True, data=True) if not G.has_edge(u, v, k)]


def _signatures_by_definition(G: nx.MultiDiGraph, gone: frozenset, colouring: frozenset) -> tuple:
    flow, tree = set(), set()
    for u, v, key, kind in G.edges(keys=True, data="kind"):
        if key == FLOW:
            flow.add((u, v, kind))
        else:
            tree.add((u, v, key))
    return ((frozenset(G.nodes), frozenset(flow), gone, colouring, frozenset(G.nodes(data="label"))),
            (frozenset(tree), gone))


def _graph(edges: list[tuple[str, str, int]]) -> nx.MultiDiGraph:
    g = new_graph()
    for u, v, k in edges:
        for m in (u, v):
            if m not in g:
                add_member(g, m)
        g.add_edge(u, v, key=k, kind="pub")
    return g


def test_missing_edges_literal():
    seen = _graph([(A, T, 0), (T, B, 0), (A, B, 1), ("process:1", A, 1)])
    live = _graph([(A, T, 0), (A, B, 1)])
    assert [e[:3] for e in missing_edges(seen, live)] == [(T, B, 0), ("process:1", A, 1)]
    assert missing_edges(seen, seen) == []
    assert [e[:3] for e in missing_edges(seen, new_graph())] == [(A, T, 0), (A, B, 1), (T, B, 0),
                                                                  ("process:1", A, 1)]
    # Another key between the same two members is missing too; the attribute dict is seen's own.
    live.add_edge(T, B, key=1)
    got = missing_edges(seen, live)
    assert [e[:3] for e in got] == [(T, B, 0), ("process:1", A, 1)]
    assert got[0][3] is seen.edges[T, B, 0]


def test_missing_edges_equals_the_definition_on_random_graphs():
    rng = random.Random(7)
    members = [f"node:/n{i}" for i in range(12)]
    for _ in range(200):
        pool = [(rng.choice(members), rng.choice(members), rng.randrange(3)) for _ in range(30)]
        seen, live = _graph(pool), _graph([e for e in pool if rng.random() < 0.8])
        assert missing_edges(seen, live) == _missing_by_definition(seen, live)
        assert missing_edges(live, seen) == _missing_by_definition(live, seen)


def test_missing_among_literal_and_on_random_graphs():
    seen = _graph([(A, T, 0), (T, B, 0), (A, B, 1), ("process:1", A, 1)])
    live = _graph([(A, T, 0)])
    # Only the candidates, in seen's order; one seen lacks and one live has are left out.
    got = missing_among(seen, live, {("process:1", A, 1), (T, B, 0), (B, A, 0), (A, T, 0)})
    assert [e[:3] for e in got] == [(T, B, 0), ("process:1", A, 1)]
    assert got[0][3] is seen.edges[T, B, 0]
    rng = random.Random(9)
    members = [f"node:/n{i}" for i in range(12)]
    for _ in range(200):
        pool = [(rng.choice(members), rng.choice(members), rng.randrange(3)) for _ in range(30)]
        seen, live = _graph(pool), _graph([e for e in pool if rng.random() < 0.8])
        every = {e[:3] for e in seen.edges(keys=True)}
        assert missing_among(seen, live, every) == _missing_by_definition(seen, live)
        some = {e for e in every if rng.random() < 0.5}
        want = [e for e in _missing_by_definition(seen, live) if e[:3] in some]
        assert missing_among(seen, live, some) == want


def test_signatures_equal_the_definition():
    g = new_graph()
    for m in (A, B, T, "process:1"):
        add_member(g, m)
    add_flow_edge(g, A, T, "pub")
    add_flow_edge(g, T, B, "sub")
    add_tree_edge(g, "process:1", A)
    g.add_edge(B, A, key=FLOW)  # a flow edge without a kind
    g.nodes[B]["label"] = "/b (2)"
    gone, colouring = frozenset({B}), frozenset({(A, "warn")})
    assert signatures(g, gone, colouring) == _signatures_by_definition(g, gone, colouring)
    flow = signatures(g, gone, colouring)[0][1]
    assert flow == {(A, T, "pub"), (T, B, "sub"), (B, A, None)}


def test_history_add_all_equals_add_one_by_one():
    rng = np.random.default_rng(3)
    one, many = History(maxlen=20), History(maxlen=20)
    for step in range(45):  # rings grow from 16 to 20 and wrap
        t = float(step)
        rows = [("topic:/a", rng.normal(size=4)), ("process:1", rng.normal(size=6)),
                ("topic:/b", [1.0, float(step), 2.0, 3.0])]  # a list: converted as `add` does
        if step == 30:
            rows.append(("topic:/a", rng.normal(size=5)))  # another layout: a new ring
        if step % 7 == 0:
            rows.append(("node:/late", np.arange(3, dtype=np.int64) + step))  # not a float array
        for m, theta in rows:
            one.add(m, t, theta)
        many.add_all(t, iter(rows))
    assert sorted(one) == sorted(many)
    for m in one:
        t1, v1 = one.series(m)
        t2, v2 = many.series(m)
        assert np.array_equal(t1, t2) and np.array_equal(v1, v2) and v1.dtype == v2.dtype


def _layout_of(G: nx.MultiDiGraph) -> tuple:
    """Everything a copy must reproduce, orders included."""
    return (G.graph, list(G._node.items()),
            [(u, list((v, list(k.items())) for v, k in nbrs.items())) for u, nbrs in G._succ.items()],
            [(v, list((u, list(k.items())) for u, k in nbrs.items())) for v, nbrs in G._pred.items()])


def _check_copy(G: nx.MultiDiGraph) -> None:
    H = copy_graph(G)
    assert _layout_of(H) == _layout_of(G.copy())
    for u, nbrs in H._succ.items():
        for v, keys in nbrs.items():
            assert H._pred[v][u] is keys  # one key dict for both directions, as networkx keeps it
            for k, attrs in keys.items():
                assert attrs is not G._succ[u][v][k]  # copied: marking H's edge gone leaves G alone
    for n, attrs in H._node.items():
        assert attrs is not G._node[n]
    H.add_edge(A, "node:/new", key=0)  # a working graph
    assert "node:/new" not in G and H.has_edge(A, "node:/new", 0)


def test_copy_graph_equals_networkx_copy_literal():
    g = new_graph()
    g.graph["name"] = "robot"
    for m in (T, B, A, "process:1"):  # not sorted: the order is kept
        add_member(g, m, theta=np.array([1.0, 2.0]))
    add_flow_edge(g, A, T, "pub", qos={"reliability": "reliable"})
    add_flow_edge(g, T, B, "sub")
    g.add_edge(A, T, key=3, kind="other")
    add_tree_edge(g, "process:1", A)
    add_tree_edge(g, "process:1", B)
    _check_copy(g)
    _check_copy(new_graph())


def test_copy_graph_equals_networkx_copy_on_random_graphs():
    rng = random.Random(11)
    members = [f"node:/n{i}" for i in range(10)]
    for _ in range(100):
        g = new_graph()
        for m in rng.sample(members, 7):
            g.add_node(m, kind="node", x=rng.random())
        for _ in range(25):
            u, v = rng.choice(members), rng.choice(members)
            g.add_edge(u, v, key=rng.randrange(3), w=rng.random())  # may add u, v without attributes
        _check_copy(g)


def test_graph_over_shares_the_attributes_and_remember_leaves_the_live_graph_alone():
    g = new_graph()
    for m in (T, B, A, "process:1"):
        add_member(g, m, pid=1)
    add_flow_edge(g, A, T, "pub")
    add_flow_edge(g, T, B, "sub")
    add_tree_edge(g, "process:1", A)
    H = graph_over(g)
    assert _layout_of(H) == _layout_of(g.copy())
    assert all(H._node[m] is g._node[m] for m in g)
    assert all(H._pred[v][u] is keys and keys is not g._succ[u][v] and keys[k] is g._succ[u][v][k]
               for u, nbrs in H._succ.items() for v, keys in nbrs.items() for k in keys)
    # A member and an edge gone while another edge between the same two members stays.
    g.add_edge(A, T, key=2, kind="other")
    live = g.copy()
    live.remove_edge(A, T, key=2)
    live.remove_node(B)
    before = _layout_of(live)
    seen = remember(g, live, 5.0)
    assert _layout_of(live) == before  # nothing of the live graph changed
    assert seen.edges[A, T, 2]["gone"] is True and seen.nodes[B]["gone_at"] == 5.0
    assert "gone" not in seen.edges[A, T, 0] and seen.nodes[A] is live.nodes[A]


def test_members_by_kind_keeps_the_graph_order_and_plugins_read_it():
    from stream_viz.detect.api import PluginContext, members_by_kind

    g = new_graph()
    for m in (T, B, "process:1", A, "topic:/s"):
        add_member(g, m)
    g.add_node("x")  # no kind
    assert members_by_kind(g) == {"topic": [T, "topic:/s"], "node": [B, A], "process": ["process:1"],
                                  None: ["x"]}
    ctx = PluginContext(t=1.0, graph=g, watch=frozenset(), history=History())
    for kind in ("node", "topic", "process", "service"):
        by_definition = [m for m, a in g.nodes(data=True) if a.get("kind") == kind]
        assert list(ctx.members(kind)) == by_definition


def test_shadow_with_the_samples_diffs_equals_without():
    from stream_viz.model.diff import diff
    from stream_viz.model.shadow import Shadow

    rng = random.Random(5)
    members = [f"node:/n{i}" for i in range(8)]
    pool = [(rng.choice(members), rng.choice(members), rng.randrange(2)) for _ in range(20)]
    with_diff, without = Shadow(forget_gone_s=3.0), Shadow(forget_gone_s=3.0)
    prev = new_graph()
    for step in range(60):
        G = _graph([e for e in pool if rng.random() < (0.97 if step % 10 else 0.7)])
        for m in G:
            G.nodes[m]["theta"] = np.array([float(step)])
        t = float(step)
        assert with_diff.record(G, t, diff(prev, G)) == without.record(G, t)
        assert _layout_of(with_diff.seen) == _layout_of(without.seen)
        prev = G
    assert sorted(with_diff.history) == sorted(without.history)


def _gone_of(G: nx.MultiDiGraph) -> frozenset:
    return frozenset(m for m, a in G.nodes(data=True) if a.get("gone")) | frozenset(
        (u, v, k) for u, v, k, a in G.edges(keys=True, data=True) if a.get("gone"))


def test_shadow_structure_changes_exactly_when_the_seen_structure_does():
    # The show step reads the seen graph's structure again only when `Shadow.structure` changed:
    # an unchanged number must mean the same members, edges, labels and gone ones.
    from stream_viz.model.diff import diff
    from stream_viz.model.shadow import Shadow

    rng = random.Random(11)
    members = [f"node:/n{i}" for i in range(8)]
    pool = [(rng.choice(members), rng.choice(members), rng.randrange(2)) for _ in range(20)]
    sh, prev, before = Shadow(forget_gone_s=3.0), new_graph(), None
    changes = same = 0
    for step in range(80):
        if step % 7:  # the steady state: the same structure again, in a new graph as every sample
            G = _graph(sorted(prev.edges(keys=True)))
        else:
            G = _graph([e for e in pool if rng.random() < 0.8])
        sh.record(G, float(step), diff(prev, G))
        number = sh.structure
        now = (signatures(sh.seen, frozenset(), frozenset()), _gone_of(sh.seen))
        if before is not None and number == before[0]:
            assert now == before[1], step
            same += 1
        elif before is not None:
            changes += 1
        before, prev = (number, now), G
    assert same > 40 and changes > 5, (same, changes)


def test_shadow_structure_literal():
    from stream_viz.model.diff import diff
    from stream_viz.model.shadow import Shadow

    sh = Shadow(forget_gone_s=5.0)
    one, two = _graph([(A, B, 0)]), _graph([(A, B, 0)])
    sh.record(one, 0.0, diff(new_graph(), one))
    first = sh.structure
    sh.record(two, 1.0, diff(one, two))  # the same structure again
    assert sh.structure == first
    lost = _graph([])
    lost.add_node(A)
    sh.record(lost, 2.0, diff(two, lost))  # B and the edge gone
    assert sh.structure == first + 1
    again = _graph([])
    again.add_node(A)
    sh.record(again, 3.0, diff(lost, again))  # still gone: no change
    assert sh.structure == first + 1
    sh.record(again, 9.0, diff(again, again))  # B forgotten after 5 s
    assert B not in sh.seen and sh.structure == first + 2
