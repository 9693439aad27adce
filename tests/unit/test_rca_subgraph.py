"""Dynamic subgraph allocation on a literal graph: the exact sets after each alert."""

from __future__ import annotations

from dataclasses import dataclass

import pytest

from stream_viz.model.graph import add_flow_edge, add_member, new_graph
from stream_viz.rca.subgraph import SubgraphState, grow, initial_state
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


@dataclass(frozen=True)
class Run:
    """``G_j`` with ``W_j`` beside it, grown as the RCA engine grows them."""

    state: SubgraphState
    watchlist: frozenset[str]

    members = property(lambda self: self.state.members)
    edges = property(lambda self: self.state.edges)
    j = property(lambda self: self.state.j)
    last = property(lambda self: self.state.last)

    def iterations(self):
        return self.state.iterations()


def start(w0):
    return Run(initial_state(w0), frozenset(w0))


def step(G, run, alert, policy):
    state, added = grow(G, run.state, alert, run.watchlist, policy)
    return run if state is run.state else Run(state, run.watchlist | added)


def sets(run):
    return set(run.members), set(run.edges), set(run.watchlist)


def test_downstream_is_the_papers_rule(G):
    st = start({T1})
    assert st.j == 0 and sets(st) == (set(), set(), {T1})
    st = step(G, st, al(T1, 1), "downstream")
    assert st.j == 1 and sets(st) == ({T1}, set(), {T1, B})
    same = step(G, st, al(C, 2), "downstream")  # c is not watched: no growth
    assert same is st
    st = step(G, st, al(B, 3), "downstream")
    assert sets(st) == ({T1, B}, {(T1, B)}, {T1, B, T2})
    assert step(G, st, al(A, 4), "downstream") is st  # a is upstream, never watched downstream
    st = step(G, st, al(T2, 5), "downstream")
    assert sets(st) == ({T1, B, T2}, {(T1, B), (B, T2)}, {T1, B, T2, C})
    st = step(G, st, al(C, 6), "downstream")
    assert sets(st) == ({T1, B, T2, C}, {(T1, B), (B, T2), (T2, C)}, {T1, B, T2, C})
    assert step(G, st, al(C, 7), "downstream") is st  # changes nothing: no new iteration
    its = st.iterations()
    assert [it.j for it in its] == [0, 1, 2, 3, 4]
    assert [it.alert_member for it in its] == [None, T1, B, T2, C]
    assert [it.t for it in its] == [0.0, 1, 3, 5, 6]
    assert its[2].members == frozenset({T1, B}) and its[2].edges == frozenset({(T1, B)})
    assert its[2].watchlist == frozenset({T1, B, T2})
    assert its[0].members == frozenset() and its[0].watchlist == frozenset({T1})


def test_downstream_adds_only_incoming_edges(G):
    # b alerts first, then /t1: the paper adds ((x, m), 0) with x ∈ M_j only, so (/t1, b) is missing.
    st = step(G, start({B, T1}), al(B, 1), "downstream")
    st = step(G, st, al(T1, 2), "downstream")
    assert set(st.edges) == set()
    # upstream/both also add the outgoing edge of the new member to the subgraph
    st2 = step(G, step(G, start({B, T1}), al(B, 1), "both"), al(T1, 2), "both")
    assert set(st2.edges) == {(T1, B)}


def test_upstream_walks_against_data_flow_through_a_silent_publisher(G):
    st = step(G, start({C}), al(C, 1), "upstream")
    assert sets(st) == ({C}, set(), {C, T2})
    st = step(G, st, al(T2, 2), "upstream")
    # /t2 is passive: its publisher b and b's input /t1 are watched (b may be silent: hung)
    assert sets(st) == ({C, T2}, {(T2, C)}, {C, T2, B, T1})
    st = step(G, st, al(T1, 3), "upstream")
    assert sets(st) == ({C, T2, T1}, {(T2, C)}, {C, T2, B, T1, A, D})
    st = step(G, st, al(B, 4), "upstream")
    assert sets(st) == ({C, T2, T1, B}, {(T2, C), (T1, B), (B, T2)}, {C, T2, B, T1, A, D})
    # the paper's downstream rule never leaves c here
    down = step(G, start({C}), al(C, 1), "downstream")
    assert sets(down) == ({C}, set(), {C})
    assert step(G, down, al(T2, 2), "downstream") is down


def test_both_and_service_direction(G):
    st = step(G, start({T1}), al(T1, 1), "both")
    assert sets(st) == ({T1}, set(), {T1, B, A, D})
    # a client's cause is its server (the reply flows back); downstream follows the send edge too
    up = step(G, start({P}), al(P, 1), "upstream")
    assert set(up.watchlist) == {P, S}
    down = step(G, start({P}), al(P, 1), "downstream")
    assert set(down.watchlist) == {P, S}
    srv = step(G, start({S}), al(S, 1), "upstream")
    assert set(srv.watchlist) == {S}


def test_outside_watch_additions_are_recorded_by_the_next_iteration(G):
    st = Run(initial_state({T1}), frozenset({T1, C}))  # C watched from outside after iteration 0
    assert set(st.watchlist) == {T1, C} and st.j == 0
    state, added = grow(G, st.state, al(C, 1), st.watchlist, "downstream", pending={C})
    st = Run(state, st.watchlist | added)
    assert st.j == 1 and st.last.watchlist == frozenset({T1, C})
    assert st.last.added_watch == frozenset({C})


def test_unknown_member_grows_without_edges(G):
    st = step(G, start({"node:/ghost"}), al("node:/ghost", 1), "both")
    assert sets(st) == ({"node:/ghost"}, set(), {"node:/ghost"})
