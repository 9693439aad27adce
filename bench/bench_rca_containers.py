"""The RCA's cost when a stopped executor implies its container's nodes: base against this tree.

A hang in a composed container (one single-threaded executor for many nodes) silences every
output of the container with its thread idle (`topic_rate`'s data ``executor_idle``). The RCA
then makes each of the container's nodes without a symptom of its own a weak candidate
(`IMPLIED_FELLOW`), and settles each one (its walk upstream, the sibling rule). This times that
case, which `bench_rca.py`'s systems (one node per process, no ``executor_idle``) never raise.

The system: `bench_rca.layered_graph` (``--members`` members, half nodes), its nodes packed in
order into processes of ``--container`` nodes. The fault: a node of the upper half hangs its
container. Alerts: half of the container's nodes' topics silent with ``executor_idle`` (the other
half publish on demand and show nothing), every topic downstream of them silent, plus unrelated
warnings, at least ``--alerts`` in all. Timed: `analyze` over all alerts, every candidate ranked
(process CPU, the median of ``--repeats``, a garbage collection before each), per container size.

    .venv/bin/python bench/bench_rca_containers.py                   # this tree
    .venv/bin/python bench/bench_rca_containers.py --base 0c7bd65    # A/B, alternating rounds
"""

from __future__ import annotations

import argparse
import gc
import json
import os
import random
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))
from bench_rca import layered_graph  # noqa: E402  (bench/ on the path first)
from bench_rca_update import unworktree, worktree  # noqa: E402
from bench_scale_ab import code_path  # noqa: E402

SIZES = (1, 10, 30, 60)  # nodes per container; 1: no container at all


def system(members: int, container: int, n_alerts: int, seed: int = 7):
    """The graph, its alerts and the hung container's quiet nodes (see the module's docstring)."""
    import networkx as nx  # the tree under test's imports, not this file's

    from stream_viz.model.graph import add_member, add_tree_edge
    from stream_viz.rca.causal import effects, is_node, outputs
    from stream_viz.records import Alert

    rng = random.Random(seed)
    G = layered_graph(members, rng)
    nodes = sorted((m for m in G if is_node(G, m)), key=lambda m: (int(m.split("/l")[1].split("/")[0]), m))
    procs: dict[str, list[str]] = {}
    for i, n in enumerate(nodes):
        p = f"process:{1000 + i // container}"
        if p not in G:
            add_member(G, p)
        add_tree_edge(G, p, n)
        procs.setdefault(p, []).append(n)
    upper = [n for n in nodes if int(n.split("/l")[1].split("/")[0]) < 5]
    hung = procs[next(p for p, ns in procs.items() if upper[len(upper) // 2] in ns)]
    t0 = 1000.0
    quiet = set(hung[1::2])  # on-demand publishers: nothing of theirs is seen to stop
    alerts: list[Alert] = []
    idle_topics = {t for n in hung if n not in quiet for t in outputs(G, n)}
    for t in sorted(idle_topics):
        alerts.append(Alert(t, "topic_rate", t0 + rng.random(), "warn", "silent", {"executor_idle": True}))
    down = set().union(*(nx.descendants(G, t) for t in idle_topics)) - idle_topics if idle_topics else set()
    downstream = sorted(m for m in down if not is_node(G, m) and m.startswith("topic:"))
    for t in downstream:
        alerts.append(Alert(t, "topic_rate", t0 + 1 + rng.random() * 3, "warn", "silent"))
    others = [m for m in nodes if m not in hung and not (set(effects(G, m)) & down)]
    while len(alerts) < n_alerts and others:
        m = rng.choice(others)
        alerts.append(Alert(m, "rosout", t0 - 20 + rng.random() * 60, "warn", "noise"))
    return G, sorted(alerts, key=lambda a: a.t), quiet


def measure(members: int, n_alerts: int, repeats: int) -> list[dict]:
    from stream_viz.rca import RcaSettings, analyze

    out = []
    for size in SIZES:
        G, alerts, quiet = system(members, size, n_alerts)
        times, report = [], None
        for _ in range(repeats):
            gc.collect()
            t = time.process_time()
            report = analyze(G, alerts, RcaSettings(top_k=1000), None)
            times.append(time.process_time() - t)
        ranked = [rc.member for rc in report.root_causes]
        out.append({"container": size, "members": G.number_of_nodes(), "alerts": len(alerts),
                    "quiet": len(quiet), "ms": 1e3 * statistics.median(times), "candidates": len(ranked),
                    "quiet_ranked": len(quiet & set(ranked)), "top": ranked[:3]})
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--members", type=int, default=2000)
    ap.add_argument("--alerts", type=int, default=500)
    ap.add_argument("--repeats", type=int, default=5)
    ap.add_argument("--base", help="an earlier commit: A/B, alternating, each in its own process")
    ap.add_argument("--rounds", type=int, default=2)
    ap.add_argument("--child", type=Path, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        args.child.write_text(json.dumps(measure(args.members, args.alerts, args.repeats)))
        return 0
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=ROOT, capture_output=True, text=True)
    print(f"commit {head.stdout.strip()}, {os.cpu_count()} cores, load average {os.getloadavg()[0]:.1f}; "
          f"{' '.join(sys.argv)}")
    with tempfile.TemporaryDirectory(prefix="bench_rca_containers_") as d:
        tmp = Path(d)
        trees = {"this": ROOT} | ({"base": worktree(args.base, tmp / "base")} if args.base else {})
        got: dict[str, list[list[dict]]] = {k: [] for k in trees}
        try:
            for i in range(args.rounds if args.base else 1):
                for name in (sorted(trees) if i % 2 == 0 else sorted(trees, reverse=True)):
                    out = tmp / f"{name}_{i}.json"
                    subprocess.run([sys.executable, str(Path(__file__).resolve()),
                                    "--members", str(args.members), "--alerts", str(args.alerts),
                                    "--repeats", str(args.repeats), "--child", str(out)],
                                   env=dict(os.environ, PYTHONPATH=code_path(trees[name], tmp)),
                                   cwd=trees[name], check=True)
                    got[name].append(json.loads(out.read_text()))
        finally:
            if args.base:
                unworktree(trees["base"])
    tail = (" | this / base | candidates base → this | quiet ones ranked base → this" if args.base
            else " | candidates | quiet ones ranked")
    print("| nodes per container | members | alerts | quiet nodes in the hung one | "
          + " | ".join(f"{k} ms" for k in got) + tail + " |")
    print("|---:|---:|---:|---:|" + "---:|" * len(got) + ("---:|---|---|" if args.base else "---:|---:|"))
    for j, size in enumerate(SIZES):
        row = {k: [r[j] for r in v] for k, v in got.items()}
        ms = {k: statistics.fmean(r["ms"] for r in rs) for k, rs in row.items()}
        r0 = row["this"][0]
        cells = [str(size), str(r0["members"]), str(r0["alerts"]), str(r0["quiet"]),
                 *(f"{ms[k]:.1f}" for k in got)]
        if args.base:
            b0 = row["base"][0]
            cells += [f"{ms['this'] / ms['base']:.2f}", f"{b0['candidates']} → {r0['candidates']}",
                      f"{b0['quiet_ranked']} → {r0['quiet_ranked']}"]
        else:
            cells += [str(r0["candidates"]), str(r0["quiet_ranked"])]
        print("| " + " | ".join(cells) + " |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
