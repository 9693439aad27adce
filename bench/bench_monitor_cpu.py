"""Where the monitor's CPU goes on a demo robot: per thread, then per pipeline stage.

The real demo robot (12 rclpy nodes in 7 processes; ``--robot amr``: the AMR, 22 nodes in 13; its
own ROS_DOMAIN_ID) and the real
in-process `Monitor` (default config, 1 sample/s). Phase 1 measures CPU time per thread with no
profiler (the monitor's main loop, the topic drain thread, the native rclpy / Fast DDS threads);
phase 2 runs the same loop with each stage of the main loop timed by the main thread's CPU
clock. Compare the rows as shares of one run: the machine is shared and noisy.

    .venv/bin/python bench/bench_monitor_cpu.py                 # viewer off, 60 s per phase
    .venv/bin/python bench/bench_monitor_cpu.py --save --seconds 30   # with the .rrd written
"""

from __future__ import annotations

import argparse
import gc
import importlib
import json
import os
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

from stream_viz.testing import own_domain

# (label, module, attribute) of the stages of Monitor.step: an imported function is wrapped in
# the module that calls it, a method on its class.
STAGES = [
    ("Monitor.step (all)", "stream_viz.monitor", "Monitor.step"),
    ("collector.sample (graph, pids, psutil, topic stats)", "stream_viz.collect.collector",
     "Collector.sample"),
    ("  read_graph (ROS graph API)", "stream_viz.collect.collector", "read_graph"),
    ("  PidResolver.resolve (node -> pid)", "stream_viz.collect.pidmap", "PidResolver.resolve"),
    ("  ProcessSampler.sample (psutil)", "stream_viz.collect.processes", "ProcessSampler.sample"),
    ("  TopicMonitor.stats (drain + window metrics)", "stream_viz.collect.topics", "TopicMonitor.stats"),
    ("    TopicMonitor.drain (take every message)", "stream_viz.collect.topics", "TopicMonitor.drain"),
    ("    TopicWindow.metrics", "stream_viz.collect.window", "TopicWindow.metrics"),
    ("  build_model", "stream_viz.collect.collector", "build_model"),
    ("  diff", "stream_viz.collect.collector", "diff"),
    ("remember (the seen graph)", "stream_viz.model.shadow", "remember"),
    ("History.add", "stream_viz.model.history", "History.add"),
    ("anomalous_processes", "stream_viz.detect.detector", "anomalous_processes"),
    ("initial_watchlist", "stream_viz.detect.detector", "initial_watchlist"),
    ("PluginSet.run (main thread's part)", "stream_viz.detect.plugin_set", "PluginSet.run"),
    ("AlertStore.add", "stream_viz.detect.store", "AlertStore.add"),
    ("AlertStore.add_snapshot", "stream_viz.detect.store", "AlertStore.add_snapshot"),
    ("RcaEngine.update", "stream_viz.rca.engine", "RcaEngine.update"),
    ("LiveView.update (Rerun)", "stream_viz.viz.live", "LiveView.update"),
    ("Monitor._status", "stream_viz.monitor", "Monitor._status"),
]


class StageClock:
    """Main-thread CPU time per stage: each stage's function wrapped with `time.thread_time`.

    A profiler would inflate code made of many small Python calls (networkx) against code made of
    few C calls (numpy, rclpy); a wrapper per stage costs the same small amount for each.
    """

    def __init__(self) -> None:
        self.cpu: dict[str, float] = {}
        self._main = threading.get_ident()
        self._undo: list[tuple[object, str, object]] = []

    def wrap(self, label: str, module: str, attr: str) -> None:
        owner: object = importlib.import_module(module)
        *path, name = attr.split(".")
        for p in path:
            owner = getattr(owner, p)
        fn = owner.__dict__[name] if isinstance(owner, type) else getattr(owner, name)
        clock, main, cpu = time.thread_time, self._main, self.cpu

        def timed(*a, **kw):
            if threading.get_ident() != main:
                return fn(*a, **kw)
            t0 = clock()
            try:
                return fn(*a, **kw)
            finally:
                cpu[label] = cpu.get(label, 0.0) + clock() - t0

        self._undo.append((owner, name, fn))
        setattr(owner, name, timed)

    def restore(self) -> None:
        for owner, name, fn in reversed(self._undo):
            setattr(owner, name, fn)
        self._undo.clear()


def graph_read_cost(col, reads: int = 200) -> str:
    """Main-thread CPU of one ROS graph read with the nodes' /rosout gids read each time (what
    every sample did before `GidCache`) and with the collector's cache (what it does now)."""
    from stream_viz.collect.rosgraph import GidCache, read_graph

    def cost(gids_for_each) -> float:
        t0 = time.thread_time()
        for _ in range(reads):
            read_graph(col.node, own=col.own, qos=col.qos, gids=gids_for_each())
        return 1e3 * (time.thread_time() - t0) / reads

    fresh, cached = cost(GidCache), cost(lambda: col.gids)
    return (f"graph read: {fresh:.2f} ms with the /rosout gids read, {cached:.2f} ms with them "
            f"cached ({reads} reads each)")


def full_collection_cost() -> str:
    """Main-thread CPU of one full garbage collection with the start-up objects frozen (as the
    monitor runs) and unfrozen (as it ran before `gc.freeze`)."""
    def cost() -> float:
        t0 = time.thread_time()
        gc.collect()
        return 1e3 * (time.thread_time() - t0)

    frozen = min(cost() for _ in range(3))
    n_frozen = gc.get_freeze_count()
    gc.unfreeze()
    try:
        walked = min(cost() for _ in range(3))
    finally:
        gc.freeze()
    return (f"full garbage collection: {walked:.1f} ms walking everything, {frozen:.1f} ms with "
            f"the {n_frozen} start-up objects frozen")


def thread_cpu(proc: psutil.Process) -> dict[int, float]:
    return {t.id: t.user_time + t.system_time for t in proc.threads()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=60.0, help="length of each phase")
    ap.add_argument("--warmup", type=float, default=15.0, help="s of monitoring before measuring")
    ap.add_argument("--save", action="store_true", help="write the .rrd (Rerun cost included)")
    ap.add_argument("--config", type=Path, help="a stream-viz config file (default: the defaults)")
    ap.add_argument("--no-stages", action="store_true", help="phase 1 only (per thread)")
    ap.add_argument("--fault", metavar="KIND:NODE", help="inject this demo fault right after the warm-up "
                    "(e.g. errlog:/controller): the cost while alerts flow and the RCA works")
    ap.add_argument("--json", type=Path, help="also write phase 1's figures here (bench_cpu_ab.py)")
    ap.add_argument("--robot", default="demo", help="the demo robot to monitor (demo, amr)")
    args = ap.parse_args(argv)

    domain = own_domain()
    from stream_viz.config import load_config
    from stream_viz.demo.faults import FaultSpec
    from stream_viz.demo.robot import Robot
    from stream_viz.demo.robots import robot_topology
    from stream_viz.monitor import Monitor

    tmp = Path(tempfile.mkdtemp(prefix="bench_monitor_cpu_"))
    robot = Robot(env=dict(os.environ), topology=robot_topology(args.robot), run_dir=tmp / "robot")
    me = psutil.Process()
    robot.start()
    try:
        robot.wait_ready(timeout=120)
        mon = Monitor(load_config(args.config), db=tmp / "a.sqlite",
                      save=tmp / "r.rrd" if args.save else None, viewer="none", domain_id=domain)
        try:
            mon.run(args.warmup, threading.Event())
            if args.fault:
                kind, _, target = args.fault.partition(":")
                robot.inject(FaultSpec(kind, target, 0.0))
            py_threads = {t.native_id: t.name for t in threading.enumerate()}
            # Phase 1: CPU per thread, no profiler.
            c0, w0, s0 = thread_cpu(me), time.monotonic(), mon.samples
            mon.run(args.seconds, threading.Event())
            c1, wall, n = thread_cpu(me), time.monotonic() - w0, mon.samples - s0
            groups: dict[str, float] = {}
            for tid, c in c1.items():
                name = py_threads.get(tid, "native (rclpy / Fast DDS)")
                if name == "MainThread":
                    name = "main loop (Monitor.step)"
                groups[name] = groups.get(name, 0.0) + c - c0.get(tid, 0.0)
            total = sum(groups.values())
            print(f"monitor on the {args.robot} robot: {wall:.0f} s, {n} samples, viewer off, .rrd "
                  f"{'on' if args.save else 'off'}, fault {args.fault or 'none'}, "
                  f"load {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores")
            print(f"{'thread':42s} {'CPU s':>7s} {'% core':>7s} {'share':>6s}")
            for name, c in sorted(groups.items(), key=lambda x: -x[1]):
                print(f"{name:42s} {c:7.2f} {100 * c / wall:6.2f}% {100 * c / total:5.0f}%")
            print(f"{'all':42s} {total:7.2f} {100 * total / wall:6.2f}%")
            if args.json:
                args.json.write_text(json.dumps({"wall_s": wall, "samples": n, "cpu_s": groups,
                                                 "total_pct": 100 * total / wall,
                                                 "load": os.getloadavg()[0],
                                                 "code": sys.modules["stream_viz"].__file__}))
            if args.no_stages:
                return 0
            print()
            print(graph_read_cost(mon.collector))
            print(full_collection_cost())
            # Phase 2: the main loop's stages, by the main thread's CPU clock around each.
            clock = StageClock()
            for label, module, attr in STAGES:
                clock.wrap(label, module, attr)
            s1 = mon.samples
            try:
                mon.run(args.seconds, threading.Event())
            finally:
                clock.restore()
            n2 = max(1, mon.samples - s1)
            step = clock.cpu.get(STAGES[0][0], 0.0)
            print(f"\nstages of Monitor.step, main-thread CPU ({1000 * step / n2:.2f} ms per sample "
                  "= 100 %):")
            for label, _, _ in STAGES:
                c = clock.cpu.get(label, 0.0)
                if c:
                    print(f"{label:52s} {100 * c / step:5.1f} % {1000 * c / n2:6.2f} ms")
        finally:
            mon.close()
    finally:
        robot.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
