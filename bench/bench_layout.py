"""Benchmark of the system-graph layout: readability and time, the old layout against the new.

Run: ``.venv/bin/python bench/bench_layout.py`` (needs Graphviz ``dot``: scripts/install). Prints two
tables (figures go to docs/viz.md with the commit they were measured on).

- readability: edge crossings and total edge length (straight edges, as the viewer draws them;
  scene units) and the drawing's width x height, on the demo robot, the warehouse AMR (both
  built from their specification, ``stream_viz.demo``, as a monitor would see them) and a
  generated 100-node system (``generate(100, seed=0)``). Layouts: ``old`` = `place` of the whole
  graph at once; ``old, discovered`` = `place` growing as members arrive in a shuffled order
  (seeded; what a live run did); ``dot`` = `layered` (namespace groups); ``dot, no groups``; and
  igraph's ``layout_sugiyama`` when the ``igraph`` package is installed (the other library
  measured; not a dependency).
- time: `layered` and `place` of generated systems of about 30, 300 and 1,000 drawn members
  (nodes, topics, services), best of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import os
import platform
import random
import subprocess
import time
from collections.abc import Callable

import networkx as nx

from stream_viz.demo.generated import generate
from stream_viz.demo.robots import robot_topology
from stream_viz.model.graph import flow_edges
from stream_viz.viz.layout import COL, ROW, display_members, layered, place, structure
from stream_viz.viz.layout_quality import edge_crossings, edge_length
from stream_viz.viz.sample import topology_graph

Pos = dict[str, tuple[float, float]]


def discovered(G: nx.MultiDiGraph, seed: int = 1, step: int = 3) -> Pos:
    """`place` grown as the members of ``G`` arrive ``step`` at a time in a shuffled order."""
    members = display_members(G)
    random.Random(seed).shuffle(members)
    rest = [m for m in G if m not in set(members)]
    layout = None
    for k in range(step, len(members) + step, step):
        layout = place(G.subgraph(members[:k] + rest).copy(), layout)
    return layout.pos


def sugiyama(G: nx.MultiDiGraph) -> Pos | None:
    """igraph's Sugiyama layout (layers turned left to right, our spacing), or None without igraph."""
    try:
        import igraph
    except ImportError:
        return None
    members, pairs = structure(G)
    index = {m: i for i, m in enumerate(members)}
    edges = [(index[u], index[v]) for u, v in pairs]
    coords = igraph.Graph(n=len(members), edges=edges, directed=True).layout_sugiyama().coords
    return {m: (y * COL, x * ROW) for m, (x, y) in zip(members, coords, strict=False)}


def quality(G: nx.MultiDiGraph, pos: Pos) -> tuple[int, float, float, float]:
    """Crossings, total edge length, width, height of ``pos``."""
    edges = [(u, v) for u, v, _ in flow_edges(G)]
    xs, ys = [p[0] for p in pos.values()], [p[1] for p in pos.values()]
    return edge_crossings(pos, edges), edge_length(pos, edges), max(xs) - min(xs), max(ys) - min(ys)


def system_of(members: int) -> nx.MultiDiGraph:
    """A generated system with about ``members`` drawn members (seed 0)."""
    n = max(3, members // 2)
    while True:
        G = topology_graph(generate(n, seed=0))
        if len(display_members(G)) >= members or n > 10 * members:
            return G
        n += max(1, n // 50)


def best(fn: Callable[[], object], repeat: int) -> float:
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t)
    return min(times)


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--sizes", default="30,300,1000", help="drawn members of the timed systems")
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    git = ["git", "rev-parse", "--short", "HEAD"]
    commit = subprocess.run(git, capture_output=True, text=True).stdout.strip()
    dot = subprocess.run(["dot", "-V"], capture_output=True, text=True).stderr.strip()
    print(f"commit {commit}; {platform.machine()} {os.cpu_count()} cores; "
          f"load {os.getloadavg()[0]:.1f}; {dot}")
    print(f"\n{'system':8} {'members':>7} {'layout':18} {'crossings':>9} {'edge length':>11} "
          f"{'width x height':>15}")
    systems = [("demo", topology_graph(robot_topology("demo"))),
               ("amr", topology_graph(robot_topology("amr"))),
               ("gen100", topology_graph(generate(100, seed=0)))]
    for name, G in systems:
        n = len(display_members(G))
        rows = [("old", place(G).pos), ("old, discovered", discovered(G)), ("dot", layered(G).pos),
                ("dot, no groups", layered(G, "none").pos), ("igraph sugiyama", sugiyama(G))]
        for label, pos in rows:
            if pos is None:
                continue
            c, length, w, h = quality(G, pos)
            print(f"{name:8} {n:7d} {label:18} {c:9d} {length:11.0f} {w:7.0f} x {h:5.0f}")
    print(f"\n{'members':>7} {'nodes':>5} {'dot (s)':>8} {'old (s)':>8}   (best of {args.repeat})")
    for size in (int(s) for s in args.sizes.split(",")):
        G = system_of(size)
        nodes = sum(1 for _, k in G.nodes(data="kind") if k == "node")
        t_dot = best(lambda G=G: layered(G), args.repeat)
        t_old = best(lambda G=G: place(G), args.repeat)
        print(f"{len(display_members(G)):7d} {nodes:5d} {t_dot:8.3f} {t_old:8.3f}", flush=True)


if __name__ == "__main__":
    main()
