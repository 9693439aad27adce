"""Benchmark of the Rerun side: logging cost per sample and .rrd size per hour of monitoring.

Run: ``.venv/bin/python bench/bench_viz.py [--minutes 5]``. Prints a table (figures go to docs/viz.md).

- cost per sample: one 1 Hz tick = set θ on every process/topic, batch the metrics (sent every
  ``--batch`` samples with ``send_columns``), re-log ``/system`` only when the graph changed (here:
  once, plus once per simulated change every 60 s); wall time of our logging calls (change check,
  layout, SDK calls; not the copy of the graph), written to a real .rrd file. Systems: the demo
  robot (12 nodes, 21 topics, 2 services, 7 processes) and a
  synthetic 1,000-node system (1,000 topics, 50 processes).
- size: the demo robot monitored at 1 Hz for ``--minutes`` simulated minutes (alerts and RCA
  iterations included), extrapolated linearly to one hour.
"""

from __future__ import annotations

import argparse
import os
import platform
import tempfile
import time
from pathlib import Path

import numpy as np

from stream_viz.model.graph import add_member
from stream_viz.records import Alert
from stream_viz.viz.layout import place
from stream_viz.viz.recorder import Recorder
from stream_viz.viz.sample import chain_graph, demo_graph, set_theta

T0 = 1_700_000_000.0


def run(G, seconds: int, batch: int, path: Path, change_every: int = 60, rca: bool = False) -> dict:
    """Simulate ``seconds`` of 1 Hz monitoring of ``G``; return timings and the file size."""
    rng = np.random.default_rng(0)
    t_log = t_system = 0.0
    n_system = 0
    pending = []
    r = Recorder(save=path)
    for i in range(seconds):
        t = T0 + i
        set_theta(G, rng)
        if i and i % change_every == 0:  # a member appears now and then
            add_member(G, f"topic:/extra_{i}")
        snapshot = (t, G.copy())  # the collector hands over a new graph per sample: not timed
        start = time.perf_counter()
        if r.system(G, t=t):
            n_system += 1
            t_system += time.perf_counter() - start
        pending.append(snapshot)
        if len(pending) >= batch:
            r.metrics(pending)
            pending = []
        if rca and i % 30 == 29:
            r.alerts([Alert("topic:/objects", "topic_rate", t, "error", "rate dropped", {"value": 0.0})])
            j = i // 30 + 1
            r.rca(G, {"j": j, "t": t, "subgraph": ["topic:/objects", "node:/planner"],
                      "watchlist": ["node:/controller"], "edges": [["topic:/objects", "node:/planner"]],
                      "alert": "topic:/objects"},
                  [{"member": "node:/detector", "score": 0.9,
                    "trajectory": ["node:/planner", "topic:/objects", "node:/detector"]}])
        t_log += time.perf_counter() - start
    if pending:
        r.metrics(pending)
    start = time.perf_counter()
    r.close()
    t_close = time.perf_counter() - start
    return {"per_sample_ms": 1e3 * t_log / seconds, "system_ms": 1e3 * t_system / max(n_system, 1),
            "n_system": n_system, "bytes": path.stat().st_size, "close_s": t_close}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--minutes", type=float, default=5.0, help="simulated minutes of the demo robot")
    ap.add_argument("--batch", type=int, default=10, help="samples per metrics batch")
    args = ap.parse_args()
    secs = int(args.minutes * 60)
    print(f"machine: {platform.machine()} {platform.processor() or ''}, {os.cpu_count()} cores, "
          f"Python {platform.python_version()}, {platform.system()} {platform.release()}")
    with tempfile.TemporaryDirectory() as d:
        rows = []
        G = demo_graph()
        res = run(G, secs, args.batch, Path(d) / "demo.rrd", rca=True)
        per_hour = res["bytes"] / secs * 3600
        rows.append(("demo robot (12 nodes, 21 topics, 7 procs)", secs, res, per_hour))
        for batch in (1, 60):
            r2 = run(demo_graph(), secs, batch, Path(d) / f"demo_b{batch}.rrd", rca=True)
            rows.append((f"demo robot, batch of {batch}", secs, r2, r2["bytes"] / secs * 3600))
        big = chain_graph(1000, fan=2, procs=50)
        t = time.perf_counter()
        place(big)
        layout_ms = 1e3 * (time.perf_counter() - t)
        res = run(big, 60, args.batch, Path(d) / "big.rrd")
        rows.append(("1,000 nodes + 1,000 topics, 50 procs", 60, res, res["bytes"] / 60 * 3600))
    print(f"metrics batch: {args.batch} samples (1 Hz)\n")
    print("| system | simulated s | log cost per sample (ms) | /system log (ms, times) | close (s) "
          "| .rrd MB/h at 1 Hz |")
    print("|---|---|---|---|---|---|")
    for name, s, r, ph in rows:
        print(f"| {name} | {s} | {r['per_sample_ms']:.2f} | {r['system_ms']:.1f} ({r['n_system']}) "
              f"| {r['close_s']:.2f} | {ph / 1e6:.1f} |")
    print(f"\nfirst layout of the 1,000-node system: {layout_ms:.0f} ms")


if __name__ == "__main__":
    main()
