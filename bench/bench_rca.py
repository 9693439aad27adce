"""Benchmark of the RCA: time of one analysis update vs graph size and alert count, and (on the
same synthetic faults) how often each ranking method puts the injected cause first.

Random layered graphs: nodes in layers, each publishing 1–2 topics and subscribing to 1–3 topics of
the layer before. A fault at a random node propagates downstream (alerts on its topics and its
descendants' topics, later the further away), some victims log errors loudly, plus unrelated noise.

Run: ``.venv/bin/python bench/bench_rca.py`` (``--quick`` for the small sizes only).
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import statistics
import time

import networkx as nx

from stream_viz.model.graph import add_flow_edge, add_member, new_graph
from stream_viz.rca import RcaEngine, RcaSettings, analyze
from stream_viz.rca.causal import effects, is_node
from stream_viz.records import Alert


def layered_graph(n_members: int, rng: random.Random, layers: int = 10) -> nx.MultiDiGraph:
    """About ``n_members`` members, half nodes, half topics, in ``layers`` layers."""
    G = new_graph()
    n_nodes = max(layers, n_members // 2)
    per = n_nodes // layers
    topics_prev: list[str] = []
    k = 0
    for layer in range(layers):
        topics_here: list[str] = []
        for i in range(per):
            node = f"node:/l{layer}/n{i}"
            add_member(G, node)
            for _ in range(rng.randint(1, 2)):
                t = f"topic:/l{layer}/t{k}"
                k += 1
                add_member(G, t)
                add_flow_edge(G, node, t, "pub")
                topics_here.append(t)
            for t in rng.sample(topics_prev, min(len(topics_prev), rng.randint(1, 3))):
                add_flow_edge(G, t, node, "sub")
        topics_prev = topics_here
    return G


def fault(G: nx.MultiDiGraph, n_alerts: int, rng: random.Random, kind: str) -> tuple[str, list[Alert]]:
    """A fault at a random node of the upper half; ``n_alerts`` alerts, as described above."""
    nodes = [m for m in G if is_node(G, m) and int(m.split("/l")[1].split("/")[0]) < 5]
    root = rng.choice(nodes)
    t0 = 1000.0
    dist = {root: 0}
    frontier = [root]
    while frontier:  # breadth-first: hop count = delay
        nxt = []
        for m in frontier:
            for x in effects(G, m):
                if x not in dist:
                    dist[x] = dist[m] + 1
                    nxt.append(x)
        frontier = nxt
    topics = [m for m in dist if not is_node(G, m)]
    victims = [m for m in dist if is_node(G, m) and m != root]
    alerts: list[Alert] = []
    if kind == "crash":
        alerts.append(Alert(root, "member_gone", t0, "fatal", "gone"))
    loud = rng.sample(victims, min(3, len(victims)))
    others = [m for m in G if m not in dist and is_node(G, m)]  # unrelated nodes log warnings
    # each symptom starts about when the fault reaches it (0.5 s per hop + up to 1 s detection),
    # then repeats; victims log errors louder than anything else
    onset = {m: t0 + 0.5 * dist[m] + rng.random() for m in topics + loud}
    for m in sorted(topics, key=dist.get)[: n_alerts // 2]:
        alerts.append(Alert(m, "topic_rate", onset[m], "error", "rate"))
    while len(alerts) < n_alerts:
        r = rng.random()
        if r < 0.5 and topics:
            m = rng.choice(topics)
            alerts.append(Alert(m, "topic_rate", onset[m] + rng.random() * 30, "error", "rate"))
        elif r < 0.9 and loud:
            m = rng.choice(loud)
            alerts.append(Alert(m, "rosout", onset[m] + 1 + rng.random() * 30, "error", "log"))
        elif others:
            m = rng.choice(others)
            alerts.append(Alert(m, "rosout", t0 - 20 + rng.random() * 60, "warn", "noise"))
    return root, sorted(alerts[:n_alerts], key=lambda a: a.t)


def timed(fn, repeats: int) -> float:
    """Median wall time of ``fn()`` in ms."""
    out = []
    for _ in range(repeats):
        t = time.perf_counter()
        fn()
        out.append((time.perf_counter() - t) * 1000)
    return statistics.median(out)


def bench_speed(sizes: list[int], counts: list[int]) -> None:
    print("\n## Time of one analysis update (ms, median)\n")
    print("| members | alerts | analyze trajectory | analyze pagerank | live update +10 alerts |")
    print("|---:|---:|---:|---:|---:|")
    ppr = RcaSettings(method="pagerank")
    for n in sizes:
        rng = random.Random(n)
        G = layered_graph(n, rng)
        for a in counts:
            _, alerts = fault(G, a, rng, "hang")
            reps = 5 if n * a <= 1_000_000 else 1
            tr = timed(lambda G=G, alerts=alerts: analyze(G, alerts, RcaSettings(), None), reps)
            pr = timed(lambda G=G, alerts=alerts: analyze(G, alerts, ppr, None), reps)

            def live(G=G, alerts=alerts):
                eng = RcaEngine(RcaSettings(), None)
                eng.update(G, alerts[:-10])
                t = time.perf_counter()
                eng.update(G, alerts[-10:])
                return (time.perf_counter() - t) * 1000

            lv = statistics.median(live() for _ in range(reps))
            print(f"| {G.number_of_nodes()} | {a} | {tr:.1f} | {pr:.1f} | {lv:.1f} |", flush=True)


def bench_accuracy(n: int, n_alerts: int, trials: int) -> None:
    print(f"\n## Synthetic faults: injected cause ranked first / in the top 3 ({trials} trials per kind, "
          f"~{n} members, {n_alerts} alerts)\n")
    methods = ("trajectory", "hypothesis", "pagerank", "count")
    print("| fault | " + " | ".join(methods) + " |")
    print("|---|" + "---|" * len(methods))
    for kind in ("crash", "hang"):
        hits = {m: [0, 0] for m in methods}
        for i in range(trials):
            rng = random.Random(1000 + i)
            G = layered_graph(n, rng)
            root, alerts = fault(G, n_alerts, rng, kind)
            for m in methods:
                ranked = [rc.member for rc in analyze(G, alerts, RcaSettings(method=m), None).root_causes]
                hits[m][0] += ranked[:1] == [root]
                hits[m][1] += root in ranked[:3]
        cells = [f"{h[0]}/{trials} · {h[1]}/{trials}" for h in hits.values()]
        print(f"| {kind} | " + " | ".join(cells) + " |", flush=True)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="100 and 1,000 members only")
    args = p.parse_args()
    print(f"machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}, "
          f"networkx {nx.__version__}, load average {os.getloadavg()[0]:.1f}")
    sizes = [100, 1000] if args.quick else [100, 1000, 10000]
    counts = [100, 1000] if args.quick else [100, 1000, 10000]
    bench_speed(sizes, counts)
    bench_accuracy(200, 300, 10 if args.quick else 30)


if __name__ == "__main__":
    main()
