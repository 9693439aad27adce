"""The RCA's fast paths (one-loop neighbours, memoised walks, the one-pass symptom collection,
sorted series kept) against the straightforward definitions they replace, on small literal
graphs and seeded random inputs: the same answers, exactly."""

from __future__ import annotations

import itertools
import random

import networkx as nx
import numpy as np
import pytest

from stream_viz.model.graph import FLOW, add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.queries import process_of_node
from stream_viz.rca import RcaSettings, siblings
from stream_viz.rca.causal import causes, causes_in, effects, effects_in, is_node, publishers, trace
from stream_viz.rca.charge import _servers_by_edge, names_in
from stream_viz.rca.cooccurrence import _series
from stream_viz.rca.episodes import merge
from stream_viz.rca.symptoms import INF, NodeView, Symptoms, collect_symptoms, gone_members
from stream_viz.records import Alert

A, B, C, S = "node:/a", "node:/b", "node:/c", "node:/srv"
T1, T2 = "topic:/t1", "topic:/t2"


@pytest.fixture
def G() -> nx.MultiDiGraph:
    """a → /t1 → b → /t2 → c; b and c call srv (``send`` client → server); a process tree edge
    and an edge without a kind (counts as ``pub``)."""
    g = new_graph()
    for m in (A, B, C, S, T1, T2, "process:1"):
        add_member(g, m)
    add_flow_edge(g, A, T1, "pub")
    add_flow_edge(g, T1, B, "sub")
    add_flow_edge(g, B, T2, "pub")
    add_flow_edge(g, T2, C, "sub")
    add_flow_edge(g, B, S, "send", services=["/srv"])
    add_flow_edge(g, C, S, "send", services=["/srv", "/other"])
    add_tree_edge(g, "process:1", A)
    g.add_edge(S, T2, key=FLOW)  # no kind: a publication
    return g


def _kind(kd: dict) -> str | None:
    return None if FLOW not in kd else kd[FLOW].get("kind", "pub")


def causes_ref(G, m):
    """The definition: predecessors over a non-``send`` layer-0 edge, then ``send`` successors."""
    if m not in G:
        return []
    return ([u for u, kd in G._pred[m].items() if _kind(kd) not in (None, "send")]
            + [v for v, kd in G._succ[m].items() if _kind(kd) == "send"])


def effects_ref(G, m):
    if m not in G:
        return []
    return ([v for v, kd in G._succ[m].items() if _kind(kd) not in (None, "send")]
            + [u for u, kd in G._pred[m].items() if _kind(kd) == "send"])


def test_causes_and_effects_are_the_definition(G):
    for m in [*G.nodes, "node:/absent"]:
        assert causes(G, m) == causes_ref(G, m)
        assert effects(G, m) == effects_ref(G, m)
    assert causes(G, B) == [T1, S]  # its input, and the server it waits for
    assert effects(G, S) == [T2, B, C]  # its unkinded output, and its clients
    assert causes(G, A) == []  # the process tree is no data flow


def test_memoised_neighbours_equal_the_plain_ones(G):
    parents: dict[str, list[str]] = {}
    children: dict[str, list[str]] = {}
    for m in [*G.nodes, *G.nodes, "node:/absent"]:  # twice: the second answers come from the memo
        assert causes_in(G, m, parents) == causes(G, m)
        assert effects_in(G, m, children) == effects(G, m)
        assert publishers(G, m, parents) == publishers(G, m)
    assert set(parents) == set(children) == {*G.nodes, "node:/absent"}


def test_is_node():
    g = new_graph()
    add_member(g, A)
    add_member(g, T1)
    g.add_node("x:/active", active=True)
    g.add_node("node:/passive", active=False)
    g.add_node("bare")
    assert [is_node(g, m) for m in (A, T1, "x:/active", "node:/passive", "bare", "node:/gone", "topic:/g")] \
        == [True, False, True, False, False, True, False]


def test_trace_with_a_shared_memo_is_the_same(G):
    children: dict[str, list[str]] = {}
    for c in (A, B, S, A):
        for symptomatic in (set(), {T1, C}, {T2}):
            for n in (1, 2, 5):
                assert trace(G, c, symptomatic, n, children) == trace(G, c, symptomatic, n)


def test_servers_by_edge_is_the_edge_view_scan(G):
    def ref(service):
        return sorted({v for _, v, k, d in G.edges(keys=True, data=True)
                       if k == FLOW and d.get("kind") == "send" and service in (d.get("services") or ())})

    for service in ("/srv", "/other", "/none"):
        assert _servers_by_edge(G, service) == ref(service)
    assert _servers_by_edge(G, "/other") == [S]


def fed_by_ref(G, n, others, hops=siblings.HOPS):
    """One of ``others`` within ``hops`` causal steps upstream of ``n`` (breadth first)."""
    dist = {n: 0}
    frontier = [n]
    while frontier:
        nxt = []
        for m in frontier:
            for p in causes(G, m):
                if p not in dist and dist[m] < hops:
                    dist[p] = dist[m] + 1
                    nxt.append(p)
        frontier = nxt
    return any(p in others for p in dist if p != n)


def chain(k: int) -> nx.MultiDiGraph:
    """n0 → t0 → n1 → t1 → … → n{k-1}, with a diamond n0 → t0b → n1."""
    g = new_graph()
    for i in range(k):
        add_member(g, f"node:/n{i}")
    for i in range(k - 1):
        add_member(g, f"topic:/t{i}")
        add_flow_edge(g, f"node:/n{i}", f"topic:/t{i}", "pub")
        add_flow_edge(g, f"topic:/t{i}", f"node:/n{i + 1}", "sub")
    add_member(g, "topic:/t0b")
    add_flow_edge(g, "node:/n0", "topic:/t0b", "pub")
    add_flow_edge(g, "topic:/t0b", "node:/n1", "sub")
    return g


def test_fed_by_with_memo_is_the_breadth_first_definition():
    g = chain(6)  # n0 is 10 causal steps above n5: beyond HOPS
    nodes = [f"node:/n{i}" for i in range(6)]
    parents: dict[str, list[str]] = {}
    for n in nodes:
        for k in range(len(nodes) + 1):
            for others in itertools.combinations([m for m in nodes if m != n], min(k, 2)):
                assert siblings._fed_by(g, n, set(others), parents) == fed_by_ref(g, n, set(others))
    assert siblings._fed_by(g, "node:/n2", {"node:/n0"})  # 4 steps: fed
    assert not siblings._fed_by(g, "node:/n5", {"node:/n0"})  # 10 steps: too far
    assert not siblings._fed_by(g, "node:/n3", set())


def stalls_ref(G, views, tol):
    """`siblings.stalls` as first written: every node of a group walked, lone nodes too (a lone
    node is one group of one: no stall)."""
    by_process: dict[str, list[str]] = {}
    for n, v in views.items():
        if not v.implied and (p := process_of_node(G, n)) is not None:
            by_process.setdefault(p, []).append(n)
    out: dict[str, set[str]] = {}
    for nodes in by_process.values():
        silent = [n for n in nodes if "output" in views[n].own_kinds]
        if silent:
            start = min(views[n].own_onset for n in silent)
            group = {n for n in silent if siblings._close(views[n].own_onset, start, tol)}
            if (len(group) > 1 and any(views[n].executor_stopped for n in group)) \
                    or len([n for n in group if not fed_by_ref(G, n, group - {n})]) >= 2:
                for n in group:
                    out[n] = group - {n}
        dead = {n for n in nodes if views[n].exited < INF}
        if len(dead) >= 2:
            for n in dead:
                out[n] = out.get(n, set()) | (dead - {n})
    return out


def random_stalls(seed: int) -> tuple[dict, dict]:
    """`stalls` and the definition on random processes over the chain's nodes, random silent
    outputs, onsets and exits."""
    rng = random.Random(seed)
    g = chain(6)
    nodes = [f"node:/n{i}" for i in range(6)]
    for n in nodes:
        p = f"process:{rng.randint(1, 3)}"
        add_member(g, p)
        add_tree_edge(g, p, n)
    views = {}
    for n in rng.sample(nodes, rng.randint(0, 6)):
        v = NodeView(n, own_onset=float(rng.choice((10, 11, 20))), implied=rng.random() < 0.1)
        if rng.random() < 0.7:
            v.own_kinds.add("output")
        if rng.random() < 0.3:
            v.exited = 12.0
        v.executor_stopped = rng.random() < 0.15
        views[n] = v
    return siblings.stalls(g, views, 2.0), stalls_ref(g, views, 2.0)


@pytest.mark.parametrize("seed", range(40))
def test_stalls_are_the_definition(seed):
    got, ref = random_stalls(seed)
    assert got == ref


def test_the_random_stalls_find_some():
    assert sum(bool(random_stalls(seed)[0]) for seed in range(40)) >= 5  # not only empty answers


def collect_ref(alerts, settings, members=None, gone=()):
    """`collect_symptoms` as first written (one dict look-up after another per alert)."""
    keep = None if members is None else set(members)
    chosen = [a for a in alerts if keep is None or a.member in keep]
    if not chosen:
        return Symptoms()
    if settings.window > 0:
        latest = max(a.t for a in chosen)
        chosen = [a for a in chosen if a.t >= latest - settings.window]
    sev = settings.severity
    direct = set(settings.direct_plugins)
    raw: dict[str, list[float]] = {}
    s = Symptoms()
    first_t = INF
    for a in chosen:
        w = sev.get(a.severity, sev.get("warn", 0.5))
        factor = 1.0 if (a.plugin in direct or not a.member.startswith("node:")) else settings.charge
        x = min(1.0, w * factor)
        raw.setdefault(a.member, []).append(a.t)
        s.anomaly[a.member] = max(s.anomaly.get(a.member, 0.0), x)
        s.relevance[a.member] = s.relevance.get(a.member, 0.0) + w
        s.plugins.setdefault(a.member, set()).add(a.plugin)
        data = a.data
        if not (data and data.get("process")):
            s.own_anomaly[a.member] = max(s.own_anomaly.get(a.member, 0.0), x)
            s.own_onset[a.member] = min(s.own_onset.get(a.member, INF), a.t)
            if data and data.get("symptom") == "log":
                s.logged[a.member] = min(s.logged.get(a.member, INF), a.t)
        elif data.get("symptom") == "exit":
            s.exited[a.member] = min(s.exited.get(a.member, INF), a.t)
        for name in names_in(data) if data else ():
            t0, w0 = s.named.get((a.member, name), (INF, 0.0))
            s.named[(a.member, name)] = (min(t0, a.t), max(w0, w))
        if a.t < first_t:
            first_t, s.first = a.t, a.member
        s.latest = max(s.latest, a.t)
    s.count = len(chosen)
    for m, ts in raw.items():
        s.times[m] = np.asarray(sorted(set(ts)), dtype=float)
        s.onset[m] = float(s.times[m][0])
        s.episodes[m] = merge(s.times[m], settings.episode_gap)
        if m in gone:
            s.episodes[m][-1] = (s.episodes[m][-1][0], INF)
    return s


def _same(a: Symptoms, b: Symptoms) -> None:
    assert a.times.keys() == b.times.keys()
    for m in a.times:
        assert a.times[m].tobytes() == b.times[m].tobytes()
    for f in ("onset", "anomaly", "relevance", "plugins", "first", "episodes", "own_anomaly", "own_onset",
              "named", "logged", "exited", "latest", "count"):
        x, y = getattr(a, f), getattr(b, f)
        assert x == y and type(x) is type(y), f
        if isinstance(x, dict):
            assert list(x) == list(y), f  # the same order too
            assert [type(v) for v in x.values()] == [type(v) for v in y.values()], f


@pytest.mark.parametrize("seed", range(40))
def test_collect_symptoms_is_the_definition(seed):
    rng = random.Random(seed)
    members = [A, B, T1, "process:1", "service:/srv"]
    datas = [{}, {"process": "process:1"}, {"process": "process:1", "symptom": "exit"}, {"symptom": "log"},
             {"server": "/srv"}, {"service": "/srv", "names": ["/a", 3, "/b"]}, {"names": "/c"},
             {"symptom": "log", "service": "/x"}]
    alerts = [Alert(rng.choice(members), rng.choice(("topic_rate", "rosout", "member_gone", "services")),
                    float(rng.randint(0, 40)), rng.choice(("info", "warn", "error", "fatal", "odd")), "m",
                    dict(rng.choice(datas)))
              for _ in range(rng.randint(0, 30))]
    settings = RcaSettings(window=rng.choice((0.0, 20.0)), severity={"info": 0, "warn": 0.5, "error": 0.8,
                                                                       "fatal": 1}, charge=0.8)
    keep = rng.choice((None, [A, T1, "service:/srv"]))
    gone = rng.choice(((), (A,)))
    _same(collect_symptoms(alerts, settings, keep, gone), collect_ref(alerts, settings, keep, gone))


@pytest.mark.parametrize("x", [
    [], [3.0], [1.0, 2.0, 5.0], [2.0, 1.0], [1.0, 1.0, 2.0], [0.0, -0.0, 1.0], [-0.0, 0.0],
    [1.0, np.nan, 2.0], [np.nan, np.nan], [1, 2, 3], np.array([[1.0, 2.0], [0.5, 3.0]]),
    np.arange(5, dtype=np.int64),
])
def test_series_is_numpy_unique(x):
    got, ref = _series(x), np.unique(np.asarray(x, dtype=float))
    assert got.dtype == ref.dtype and got.shape == ref.shape
    assert got.tobytes() == ref.tobytes()


@pytest.mark.parametrize("seed", range(20))
def test_series_is_numpy_unique_on_random_ticks(seed):
    rng = np.random.default_rng(seed)
    x = rng.integers(0, 6, rng.integers(0, 9)).astype(float)
    for y in (x, np.sort(x), np.unique(x)):
        assert _series(y).tobytes() == np.unique(y).tobytes()


def test_gone_members_is_the_data_view():
    g = new_graph()
    for m, gone in ((A, True), (B, False), (T1, None), (T2, 1), (C, 0)):
        add_member(g, m)
        if gone is not None:
            g.nodes[m]["gone"] = gone
    assert gone_members(g) == {m for m, x in g.nodes(data="gone") if x} == {A, T2}
