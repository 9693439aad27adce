"""Plugin evaluation cost per sample for 1,000 watched members (synthetic graph, all built-ins).

Builds a synthetic model: N/4 nodes in N/8 processes, N/4 topics (one publisher, two
subscribers each), then runs every built-in plugin on ``samples`` samples (history filled as the
monitor would, a few events per sample) and prints the cost per sample per plugin, isolated
(worker thread + deadline, the default) and inline, side by side; plus the alert store's cost
per batch on a real SQLite file.

Run: ``.venv/bin/python bench/bench_detect.py [--members 1000] [--samples 120]``
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time

import numpy as np

from stream_viz.detect.api import record_history
from stream_viz.detect.plugin_set import PluginSet
from stream_viz.detect.store import AlertStore
from stream_viz.model.diff import GraphDiff
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.history import History
from stream_viz.model.theta import make_theta
from stream_viz.records import Event


def synthetic(n: int, rng: np.random.Generator, t: int):
    """A model with about ``n`` members and noisy healthy θ."""
    G = new_graph()
    n_nodes = n // 4
    n_procs = max(1, n // 8)
    n_topics = n - n_nodes - n_procs
    for p in range(n_procs):
        add_member(G, f"process:{1000 + p}", pid=1000 + p, alive=True, theta=make_theta("process", {
            "cpu_percent": 5 + rng.normal(0, 1), "rss_mb": 80 + rng.normal(0, 0.3), "threads": 4}))
    for i in range(n_nodes):
        pid = 1000 + i % n_procs
        add_member(G, f"node:/n{i}", pid=pid, alive=True)
        add_tree_edge(G, f"process:{pid}", f"node:/n{i}")
    for j in range(n_topics):
        tid = f"topic:/t{j}"
        add_member(G, tid, qos=[], theta=make_theta("topic", {
            "rate_hz": 10 * (1 + rng.normal(0, 0.03)), "latency_ms": 2 + abs(rng.normal(0, 0.3)),
            "jitter_ms": 1 + abs(rng.normal(0, 0.2)), "drops_per_s": 0.0, "publishers": 1, "subscribers": 2}))
        add_flow_edge(G, f"node:/n{j % n_nodes}", tid, "pub")
        for k in (1, 2):
            add_flow_edge(G, tid, f"node:/n{(j + k) % n_nodes}", "sub")
    return G


def bench_plugins(n: int, samples: int, isolate: bool) -> tuple[dict[str, float], float, int]:
    rng = np.random.default_rng(0)
    ps = PluginSet.load(cwd_plugins=False, isolate=isolate, timeout_s=30.0)
    hist = History(maxlen=600)
    total = 0.0
    alerts_n = 0
    for t in range(samples):
        G = synthetic(n, rng, t)
        record_history(hist, G, float(t))
        events = [Event(float(t), "log", "node:/n1", "warn", "meh")]
        t0 = time.perf_counter()
        alerts, problems = ps.run(float(t), G, G.nodes, hist, events, GraphDiff())
        total += time.perf_counter() - t0
        alerts_n += len(alerts)
        assert not problems, problems
    per = {name: secs / max(calls, 1) for name, (calls, secs) in ps.timings().items()}
    ps.close()
    return per, total / samples, alerts_n


def bench_store(batches: int, per_batch: int) -> float:
    from stream_viz.records import Alert

    with tempfile.TemporaryDirectory() as d, AlertStore(os.path.join(d, "b.sqlite")) as st:
        t0 = time.perf_counter()
        for b in range(batches):
            st.add([Alert(f"node:/n{i}", "bench", float(b), "warn", "x", {"v": i}) for i in range(per_batch)])
        return (time.perf_counter() - t0) / batches


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=1000)
    ap.add_argument("--samples", type=int, default=120)
    args = ap.parse_args()
    print(f"machine: {platform.processor() or platform.machine()}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, load avg {os.getloadavg()[0]:.1f}")
    print(f"{args.members} watched members, {args.samples} samples (the first {10} s are warm-up)\n")
    iso, iso_total, n_alerts = bench_plugins(args.members, args.samples, isolate=True)
    inl, inl_total, _ = bench_plugins(args.members, args.samples, isolate=False)
    print(f"{'plugin':<20}{'isolated ms/sample':>20}{'inline ms/sample':>18}")
    for name in sorted(iso):
        print(f"{name:<20}{iso[name] * 1e3:>20.2f}{inl[name] * 1e3:>18.2f}")
    print(f"{'all (PluginSet.run)':<20}{iso_total * 1e3:>20.2f}{inl_total * 1e3:>18.2f}")
    print(f"\nalerts on the healthy synthetic system: {n_alerts}")
    for per_batch in (10, 200):
        print(f"alert store: {bench_store(200, per_batch) * 1e3:.2f} ms per committed batch of {per_batch}")


if __name__ == "__main__":
    main()
