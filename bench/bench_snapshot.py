"""Benchmark the collector: one full snapshot against graph size, its CPU share at 1 Hz, topic-metric cost.

Real rclpy nodes in child processes (several nodes per process, each with the usual parameter
services); the collector runs in this process. Prints a table; figures go into docs/collector.md.

    .venv/bin/python bench/bench_snapshot.py                   # 50, 200, 1000 nodes
    .venv/bin/python bench/bench_snapshot.py --sizes 50 --watch 20
"""

from __future__ import annotations

import argparse
import os
import signal
import statistics
import subprocess
import sys
import textwrap
import time
from pathlib import Path

CHILD = textwrap.dedent("""
    import sys, rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import String
    from std_srvs.srv import Trigger
    first, count, rate, topics = (int(sys.argv[1]), int(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4]))
    rclpy.init()
    ex = SingleThreadedExecutor()
    nodes = []
    for i in range(first, first + count):
        n = Node(f'n{i}', namespace=f'/g{i // 10}')
        pub = n.create_publisher(String, f'/t{i}', 10)
        n.create_subscription(String, f'/t{max(i - 1, 0)}', lambda m: None, 10)
        if i % 5 == 0:
            n.create_service(Trigger, f'/s{i}', lambda req, res: res)
        if i % 5 == 1:
            n.create_client(Trigger, f'/s{i - 1}')
        if rate > 0 and i < topics:
            msg = String(data='x' * 64)
            n.create_timer(1.0 / rate, lambda p=pub, m=msg: p.publish(m))
        ex.add_node(n)
        nodes.append(n)
    print('ready', flush=True)
    ex.spin()
""")


def spawn(total: int, per_proc: int, rate: float, topics: int, env: dict[str, str]) -> list[subprocess.Popen]:
    procs = []
    for first in range(0, total, per_proc):
        procs.append(subprocess.Popen(
            [sys.executable, "-c", CHILD, str(first), str(min(per_proc, total - first)), str(rate),
             str(topics)],
            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True))
    return procs


def end(procs: list[subprocess.Popen]) -> None:
    for p in procs:
        try:
            os.killpg(p.pid, signal.SIGINT)
        except ProcessLookupError:
            pass
    for p in procs:
        try:
            p.wait(10)
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            p.wait(5)


def wait_nodes(col, want: int, timeout: float) -> float:
    t0 = time.monotonic()
    while time.monotonic() - t0 < timeout:
        n = sum(1 for _, k in col.sample().graph.nodes(data="kind") if k == "node")
        if n >= want * 0.95:  # at 1,000 nodes a few stragglers may take minutes (reported in the table)
            return time.monotonic() - t0
        time.sleep(1.0)
    raise TimeoutError(f"only {n} of {want} nodes discovered in {timeout} s")


def bench_snapshot(domain: int, sizes: list[int], env: dict[str, str], settle_s: float = 2.0) -> list[str]:
    from stream_viz.collect.collector import Collector
    from stream_viz.collect.rosgraph import read_graph

    rows = []
    for size in sizes:
        per_proc = 10 if size <= 50 else (20 if size <= 200 else 50)
        procs = spawn(size, per_proc, 0.0, 0, env)
        try:
            with Collector(domain, topic_metrics=True) as col:
                settle = wait_nodes(col, size, timeout=60 + size * 0.2)
                # Let late endpoints arrive and the nodes' discovery calm down, sampling at 1 Hz as
                # the monitor does (its caches fill as they would: the QoS of new topics is read
                # within a budget a sample).
                t_end = time.monotonic() + settle_s
                while time.monotonic() < t_end:
                    col.sample()
                    time.sleep(max(0.0, min(1.0, t_end - time.monotonic())))
                walls, cpus, graph_ms, kept_ms = [], [], [], []
                reads0 = col.structure.reads
                for _ in range(7):
                    w0, c0 = time.perf_counter(), time.process_time()
                    s = col.sample()
                    walls.append((time.perf_counter() - w0) * 1e3)
                    cpus.append((time.process_time() - c0) * 1e3)
                    # Side by side: the structure read in full (a fresh cache), then as the
                    # collector does (read again only when the graph changed); QoS and gids cached.
                    g0 = time.perf_counter()
                    read_graph(col.node, own=col.own, qos=col.qos, gids=col.gids)
                    g1 = time.perf_counter()
                    read_graph(col.node, own=col.own, qos=col.qos, gids=col.gids, structure=col.structure)
                    graph_ms.append((g1 - g0) * 1e3)
                    kept_ms.append((time.perf_counter() - g1) * 1e3)
                    time.sleep(0.3)
                reads = col.structure.reads - reads0  # of 14 calls, those that read in full
                qos_ms = qos_read_ms(col, s.graph)
                G = s.graph
                kinds = {}
                for _, k in G.nodes(data="kind"):
                    kinds[k] = kinds.get(k, 0) + 1
                rows.append(
                    f"| {size} ({kinds.get('node', 0)} seen) | {len(procs)} | {kinds.get('topic', 0)} | "
                    f"{kinds.get('service', 0)} | "
                    f"{G.number_of_edges()} | {settle:.1f} | {statistics.median(walls):.1f} | "
                    f"{statistics.median(cpus):.1f} | {statistics.median(graph_ms):.1f} | "
                    f"{statistics.median(kept_ms):.1f} | {reads} of 14 | "
                    f"{qos_ms:.2f} | {stale_cycle_s(col, kinds.get('topic', 0), qos_ms):.0f} | "
                    f"{os.getloadavg()[0]:.1f} |")
                print(rows[-1], flush=True)
        finally:
            end(procs)
    return rows


def qos_read_ms(col, G, n: int = 30) -> float:
    """Median ms of one topic's QoS read (its publishers' and subscriptions' endpoint info)."""
    from stream_viz.model.ids import name_of

    topics = sorted(m for m, k in G.nodes(data="kind") if k == "topic")[:n]
    times = []
    for t in topics:
        name = name_of(t)
        t0 = time.perf_counter()
        col.node.get_publishers_info_by_topic(name)
        col.node.get_subscriptions_info_by_topic(name)
        times.append((time.perf_counter() - t0) * 1e3)
    return statistics.median(times) if times else float("nan")


def stale_cycle_s(col, topics: int, read_ms: float) -> float:
    """Seconds at 1 Hz for `QosCache.refresh_stale` to read every topic again: its ``every_s``
    plus the samples it needs at the reads its ``stale_budget_s`` allows (one at least)."""
    per_sample = max(1, int(col.qos.stale_budget_s * 1e3 // read_ms) + 1)  # the read that crosses it
    return col.qos.every_s + topics / per_sample


def cpu_share(domain: int, env: dict[str, str], size: int, rate: float, topics: int, metrics: bool,
              seconds: float) -> tuple[float, int]:
    """Collector CPU (% of one core, all its threads) while sampling at 1 Hz for ``seconds``."""
    from stream_viz.collect.collector import Collector

    procs = spawn(size, 10, rate, topics, env)
    try:
        with Collector(domain, topic_metrics=metrics) as col:
            wait_nodes(col, size, timeout=60)
            col.sample()
            time.sleep(2.0)
            taken0 = col.topics.taken
            c0, w0 = time.process_time(), time.monotonic()
            next_t = w0
            while time.monotonic() - w0 < seconds:
                col.sample()
                next_t += 1.0
                time.sleep(max(0.0, next_t - time.monotonic()))
            cpu = (time.process_time() - c0) / (time.monotonic() - w0) * 100.0
            msgs = int((col.topics.taken - taken0) / (time.monotonic() - w0))
            return cpu, msgs
    finally:
        end(procs)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--domain", type=int, default=int(os.environ.get("BENCH_DOMAIN", "57")))
    ap.add_argument("--sizes", type=int, nargs="*", default=[50, 200, 1000])
    ap.add_argument("--watch", type=float, default=20.0, help="seconds of 1 Hz sampling per CPU run")
    ap.add_argument("--skip-cpu", action="store_true", help="only the snapshot table")
    ap.add_argument("--settle", type=float, default=2.0,
                    help="seconds sampled at 1 Hz after 95 %% of the nodes are seen, before timing")
    a = ap.parse_args()
    env = dict(os.environ, ROS_DOMAIN_ID=str(a.domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    env.pop("ROS_LOCALHOST_ONLY", None)
    os.environ.update(env)
    print("## Full snapshot against graph size (median of 7 samples)")
    print("| nodes | processes | topics | services | edges | discovery s | sample wall ms | "
          "sample CPU ms | graph read ms | graph read unchanged ms | structure reads | "
          "QoS read ms a topic | stale QoS cycle s at 1 Hz | load |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    if a.sizes:
        bench_snapshot(a.domain, a.sizes, env, a.settle)
    if a.skip_cpu:
        return
    print("\n## Collector CPU share at 1 Hz, 50 nodes in 5 processes")
    print("| topic metrics | published msgs/s taken | collector CPU % of one core |")
    print("|---|---|---|")
    for metrics, rate, topics in ((False, 0.0, 0), (True, 0.0, 0), (True, 20.0, 50)):
        cpu, msgs = cpu_share(a.domain, env, 50, rate, topics, metrics, a.watch)
        print(f"| {'on' if metrics else 'off'} ({rate:g} Hz x {topics} topics) | {msgs} | {cpu:.2f} |",
              flush=True)
    print("\n## Topic-metric cost: 1,000 msgs/s (50 topics x 20 Hz) vs none")
    off, _ = cpu_share(a.domain, env, 50, 20.0, 50, False, a.watch)
    on, msgs = cpu_share(a.domain, env, 50, 20.0, 50, True, a.watch)
    print(f"| metrics off: {off:.2f} % | metrics on: {on:.2f} % | {msgs} msgs/s taken | "
          f"cost per 1,000 msgs/s: {(on - off) / max(msgs, 1) * 1000:.2f} % of one core |")
    fastdds = Path(sys.executable).with_name("fastdds")
    if fastdds.exists():
        subprocess.run([str(fastdds), "shm", "clean"], capture_output=True, timeout=60, check=False)


if __name__ == "__main__":
    main()
