"""Where the monitor's CPU goes on the demo robot: per thread, then per pipeline stage.

The real demo robot (12 rclpy nodes in 7 processes, its own ROS_DOMAIN_ID) and the real
in-process `Monitor` (default config, 1 sample/s). Phase 1 measures CPU time per thread with no
profiler (the monitor's main loop, the topic drain thread, the native rclpy / Fast DDS threads);
phase 2 runs the same loop under cProfile and splits the main loop into its stages. Compare the
rows as shares of one run: the machine is shared and noisy.

    .venv/bin/python bench/bench_monitor_cpu.py                 # viewer off, 60 s per phase
    .venv/bin/python bench/bench_monitor_cpu.py --save --seconds 30   # with the .rrd written
"""

from __future__ import annotations

import argparse
import cProfile
import os
import pstats
import sys
import tempfile
import threading
import time
from pathlib import Path

import psutil

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

# (label, file suffix, function name) of the stages of Monitor.step, as cProfile names them.
STAGES = [
    ("collector.sample (graph, pids, psutil, topic stats)", "collect/collector.py", "sample"),
    ("  read_graph (ROS graph API)", "collect/rosgraph.py", "read_graph"),
    ("  ProcessSampler.sample (psutil)", "collect/processes.py", "sample"),
    ("  TopicMonitor.stats (window metrics)", "collect/topics.py", "stats"),
    ("  build_model", "collect/build.py", "build_model"),
    ("  diff", "model/diff.py", "diff"),
    ("remember (the seen graph)", "model/seen.py", "remember"),
    ("History.add", "model/history.py", "add"),
    ("process_anomalies", "detect/watchlist.py", "process_anomalies"),
    ("initial_watchlist", "detect/watchlist.py", "initial_watchlist"),
    ("PluginSet.run (all plugins)", "detect/registry.py", "run"),
    ("AlertStore.add", "detect/store.py", "add"),
    ("AlertStore.add_snapshot", "detect/store.py", "add_snapshot"),
    ("RcaEngine.update", "rca/engine.py", "update"),
    ("LiveView.update (Rerun)", "stream_viz/live_view.py", "update"),
    ("Monitor._status", "stream_viz/monitor.py", "_status"),
]


def thread_cpu(proc: psutil.Process) -> dict[int, float]:
    return {t.id: t.user_time + t.system_time for t in proc.threads()}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=60.0, help="length of each phase")
    ap.add_argument("--warmup", type=float, default=15.0, help="s of monitoring before measuring")
    ap.add_argument("--save", action="store_true", help="write the .rrd (Rerun cost included)")
    args = ap.parse_args(argv)

    from rosenv import claim_domain

    domain = claim_domain()
    os.environ.update(ROS_DOMAIN_ID=str(domain), ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    os.environ.pop("ROS_LOCALHOST_ONLY", None)
    from stream_viz.config import load_config
    from stream_viz.demo.robot import Robot
    from stream_viz.monitor import Monitor

    tmp = Path(tempfile.mkdtemp(prefix="bench_monitor_cpu_"))
    robot = Robot(env=dict(os.environ), run_dir=tmp / "robot")
    me = psutil.Process()
    robot.start()
    try:
        robot.wait_ready(timeout=120)
        mon = Monitor(load_config(None), db=tmp / "a.sqlite", save=tmp / "r.rrd" if args.save else None,
                      viewer="none", domain_id=domain)
        try:
            mon.run(args.warmup, threading.Event())
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
            print(f"monitor on the demo robot: {wall:.0f} s, {n} samples, viewer off, .rrd "
                  f"{'on' if args.save else 'off'}, load {os.getloadavg()[0]:.1f}, {os.cpu_count()} cores")
            print(f"{'thread':42s} {'CPU s':>7s} {'% core':>7s} {'share':>6s}")
            for name, c in sorted(groups.items(), key=lambda x: -x[1]):
                print(f"{name:42s} {c:7.2f} {100 * c / wall:6.2f}% {100 * c / total:5.0f}%")
            print(f"{'all':42s} {total:7.2f} {100 * total / wall:6.2f}%")
            # Phase 2: the main loop's stages under cProfile (inflated; read the shares).
            prof = cProfile.Profile()
            prof.enable()
            mon.run(args.seconds, threading.Event())
            prof.disable()
            stats = pstats.Stats(prof).stats
            step = _cum(stats, "stream_viz/monitor.py", "step")
            print(f"\nstages of Monitor.step under cProfile ({step:.2f} s in step = 100 %):")
            for label, path, fn in STAGES:
                c = _cum(stats, path, fn)
                if c:
                    print(f"{label:52s} {100 * c / step:5.1f} %")
        finally:
            mon.close()
    finally:
        robot.stop()
    return 0


def _cum(stats: dict, path: str, fn: str) -> float:
    return sum(v[3] for (f, _, name), v in stats.items() if name == fn and f.endswith(path))


if __name__ == "__main__":
    sys.exit(main())
