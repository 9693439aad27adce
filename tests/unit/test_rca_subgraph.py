"""Dynamic subgraph allocation on a literal graph: the exact sets after each alert."""

from __future__ import annotations

import pytest

from stream_viz.model.graph import add_flow_edge, add_member, new_graph
from stream_viz.rca.subgraph import grow, initial_state, watch
from stream_viz.records import Alert

A, D, B, C, P, S = "node:/a", "node:/d", "node:/b", "node:/c", "node:/p", "node:/s"
T1, T2 = "topic:/t1", "topic:/t2"


@pytest.fixture
def G():
    # a ─┐
    #    ├─> /t1 ─> b ─> /t2 ─> c        p ─send─> s   (p calls the service of s)
    # d ─┘
    g = new_graph()
    for m in (A, D, B, C, P, S, T1, T2):
        add_member(g, m)
    add_flow_edge(g, A, T1, "pub")
    add_flow_edge(g, D, T1, "pub")
    add_flow_edge(g, T1, B, "sub")
    add_flow_edge(g, B, T2, "pub")
    add_flow_edge(g, T2, C, "sub")
    add_flow_edge(g, P, S, "send")
    return g


def al(member: str, t: float) -> Alert:
    return Alert(member, "test", t, "error", "x")


def sets(state):
    return set(state.members), set(state.edges), set(state.watchlist)


def test_downstream_is_the_papers_rule(G):
    st = initial_state({T1})
    assert st.j == 0 and sets(st) == (set(), set(), {T1})
    st = grow(G, st, al(T1, 1), "downstream")
    assert st.j == 1 and sets(st) == ({T1}, set(), {T1, B})
    same = grow(G, st, al(C, 2), "downstream")  # c is not watched: no growth
    assert same is st
    st = grow(G, st, al(B, 3), "downstream")
    assert sets(st) == ({T1, B}, {(T1, B)}, {T1, B, T2})
    assert grow(G, st, al(A, 4), "downstream") is st  # a is upstream, never watched downstream
    st = grow(G, st, al(T2, 5), "downstream")
    assert sets(st) == ({T1, B, T2}, {(T1, B), (B, T2)}, {T1, B, T2, C})
    st = grow(G, st, al(C, 6), "downstream")
    assert sets(st) == ({T1, B, T2, C}, {(T1, B), (B, T2), (T2, C)}, {T1, B, T2, C})
    assert grow(G, st, al(C, 7), "downstream") is st  # changes nothing: no new iteration
    its = st.iterations()
    assert [it.j for it in its] == [0, 1, 2, 3, 4]
    assert [it.alert_member for it in its] == [None, T1, B, T2, C]
    assert [it.t for it in its] == [0.0, 1, 3, 5, 6]
    assert its[2].members == frozenset({T1, B}) and its[2].edges == frozenset({(T1, B)})
    assert its[2].watchlist == frozenset({T1, B, T2})
    assert its[0].members == frozenset() and its[0].watchlist == frozenset({T1})


def test_downstream_adds_only_incoming_edges(G):
    # b alerts first, then /t1: the paper adds ((x, m), 0) with x ∈ M_j only, so (/t1, b) is missing.
    st = grow(G, initial_state({B, T1}), al(B, 1), "downstream")
    st = grow(G, st, al(T1, 2), "downstream")
    assert set(st.edges) == set()
    # upstream/both also add the outgoing edge of the new member to the subgraph
    st2 = grow(G, grow(G, initial_state({B, T1}), al(B, 1), "both"), al(T1, 2), "both")
    assert set(st2.edges) == {(T1, B)}


def test_upstream_walks_against_data_flow_through_a_silent_publisher(G):
    st = grow(G, initial_state({C}), al(C, 1), "upstream")
    assert sets(st) == ({C}, set(), {C, T2})
    st = grow(G, st, al(T2, 2), "upstream")
    # /t2 is passive: its publisher b and b's input /t1 are watched (b may be silent: hung)
    assert sets(st) == ({C, T2}, {(T2, C)}, {C, T2, B, T1})
    st = grow(G, st, al(T1, 3), "upstream")
    assert sets(st) == ({C, T2, T1}, {(T2, C)}, {C, T2, B, T1, A, D})
    st = grow(G, st, al(B, 4), "upstream")
    assert sets(st) == ({C, T2, T1, B}, {(T2, C), (T1, B), (B, T2)}, {C, T2, B, T1, A, D})
    # the paper's downstream rule never leaves c here
    down = grow(G, initial_state({C}), al(C, 1), "downstream")
    assert sets(down) == ({C}, set(), {C})
    assert grow(G, down, al(T2, 2), "downstream") is down


def test_both_and_service_direction(G):
    st = grow(G, initial_state({T1}), al(T1, 1), "both")
    assert sets(st) == ({T1}, set(), {T1, B, A, D})
    # a client's cause is its server (the reply flows back); downstream follows the send edge too
    up = grow(G, initial_state({P}), al(P, 1), "upstream")
    assert set(up.watchlist) == {P, S}
    down = grow(G, initial_state({P}), al(P, 1), "downstream")
    assert set(down.watchlist) == {P, S}
    srv = grow(G, initial_state({S}), al(S, 1), "upstream")
    assert set(srv.watchlist) == {S}


def test_outside_watch_additions_are_recorded_by_the_next_iteration(G):
    st = watch(initial_state({T1}), {C})
    assert set(st.watchlist) == {T1, C} and st.j == 0
    st = grow(G, st, al(C, 1), "downstream")
    assert st.j == 1 and st.last.watchlist == frozenset({T1, C})
    assert st.last.added_watch == frozenset({C})


def test_unknown_member_grows_without_edges(G):
    st = grow(G, initial_state({"node:/ghost"}), al("node:/ghost", 1), "both")
    assert sets(st) == ({"node:/ghost"}, set(), {"node:/ghost"})
