"""Two parts of a collector sample, each side by side with what it replaced, in one run.

1. Reading a tracked process: the sampler's /proc path vs its psutil path, on real processes
   (Python children with threads and open files, like rclpy nodes, one thread working at 10 Hz
   as an executor does), in alternation. The metrics are the same (``tests/robust/test_system.py``)
   but for the /proc path's own: the running threads, counted by a probe of every thread every
   30th sample, and the one running thread's CPU and the main thread's read every sample. Also its
   cost with a probe at every sample, without the main thread's read (``nomain``), and the mean
   (the median misses the 30th samples).
2. Topic metrics of one sample: `TopicWindow` running sums (adds of one second of messages plus
   expire and metrics) vs `window_metrics`, the numpy computation over the window's records
   that every sample ran before (now the definition the sums are tested against), on
   the demo robot's topic rates (50, 20, 20, 15, 10 x4, 1 x3 Hz, 3 s window). Equal results
   (``tests/unit/test_collect_pure.py``).
3. Reading the three /proc files of a tracked process (``stat``, ``status``, ``io``):
   `read_file` (``os.open`` and one ``os.read``) vs a Python file object (``open(path, "rb",
   buffering=0)``, what the sampler used before), in alternation on the children of part 1.

Figures are main-thread CPU time (medians); compare the ratios, the machine is shared.

    .venv/bin/python bench/bench_collect_parts.py --processes 10 --rounds 300
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time

from stream_viz.collect import processes as sampler_module
from stream_viz.collect.processes import ProcessSampler, read_file
from stream_viz.collect.window import TopicWindow, window_metrics

CHILD = ("import threading, time, tempfile\n"
         "files = [tempfile.TemporaryFile() for _ in range(20)]\n"
         "for _ in range(4): threading.Thread(target=time.sleep, args=(600,), daemon=True).start()\n"
         "def spin():\n"
         "    while True:\n"
         "        sum(range(20000)); time.sleep(0.1)\n"
         "threading.Thread(target=spin, daemon=True).start()\n"
         "time.sleep(600)\n")
DEMO_RATES = (50, 20, 20, 15, 10, 10, 10, 10, 1, 1, 1)
WINDOW_NS = 3_000_000_000


def processes(n_children: int, rounds: int) -> None:
    kids = [subprocess.Popen([sys.executable, "-c", CHILD]) for _ in range(n_children)]
    try:
        time.sleep(1.0)
        pids = [k.pid for k in kids]
        # Ancestors read every time, so both read the same processes every round.
        samplers = {"procfs": ProcessSampler(ancestors_every=1, procfs=True),
                    "probe1": ProcessSampler(ancestors_every=1, procfs=True, probe_every=1),
                    "nomain": ProcessSampler(ancestors_every=1, procfs=True),
                    "psutil": ProcessSampler(ancestors_every=1, procfs=False)}
        measure_main = sampler_module._measure_main
        cost: dict[str, list[float]] = {k: [] for k in samplers}
        n = 0
        order = list(samplers.items())
        for i in range(rounds):
            for name, s in order[i % len(order):] + order[: i % len(order)]:  # no one always first
                sampler_module._measure_main = (lambda *a: None) if name == "nomain" else measure_main
                t0 = time.thread_time()
                n = len(s.sample(pids).processes)
                cost[name].append(time.thread_time() - t0)
        sampler_module._measure_main = measure_main
        us = {k: 1e6 * statistics.median(v) / n for k, v in cost.items()}
        mean = {k: 1e6 * statistics.fmean(v) / n for k, v in cost.items()}
        print(f"1. {n_children} children + their ancestors = {n} processes, {rounds} rounds"
              " (probe1: the /proc path probing every thread at every sample)")
        for k in us:
            print(f"   {k:7s} {us[k]:6.1f} µs per process per sample (median), {mean[k]:6.1f} (mean)")
        print(f"   procfs / psutil = {us['procfs'] / us['psutil']:.2f} (median), "
              f"{mean['procfs'] / mean['psutil']:.2f} (mean); "
              f"probe1 / psutil = {us['probe1'] / us['psutil']:.2f}; "
              f"procfs / nomain = {us['procfs'] / us['nomain']:.2f} (median), "
              f"{mean['procfs'] / mean['nomain']:.2f} (mean)")
        proc_files(pids, rounds)
    finally:
        for k in kids:
            k.kill()


def _file_object(path: str) -> bytes:
    with open(path, "rb", buffering=0) as f:
        return f.read()


def proc_files(pids: list[int], rounds: int) -> None:
    paths = [f"/proc/{pid}/{name}" for pid in pids for name in ("stat", "status", "io")]
    cost: dict[str, list[float]] = {"read_file": [], "file object": []}
    for _ in range(rounds):
        for name, read in (("read_file", read_file), ("file object", _file_object)):
            t0 = time.thread_time()
            for p in paths:
                read(p)
            cost[name].append(time.thread_time() - t0)
    us = {k: 1e6 * statistics.median(v) / len(pids) for k, v in cost.items()}
    print(f"3. the three /proc files of a process, {len(pids)} children, {rounds} rounds")
    for k, v in us.items():
        print(f"   {k:11s} {v:6.1f} µs per process")
    print(f"   read_file / file object = {us['read_file'] / us['file object']:.2f}")


def topic_metrics(rounds: int) -> None:
    t_end = 100 * 10**9
    streams = []
    for rate in DEMO_RATES:  # 3 s of records, then one more second arriving per sample
        step = 10**9 // rate
        times = range(t_end - 4 * 10**9, t_end, step)
        recs = [(t, t - 2_000_000, 500, i, None, None) for i, t in enumerate(times)]
        streams.append(recs)
    cost: dict[str, list[float]] = {"running sums": [], "fresh numpy": []}
    for _ in range(rounds):
        # Time only one sample's work: each stream's last second of adds, expire, metrics.
        windows = []
        for recs in streams:
            w = TopicWindow()
            for r in recs[: 3 * len(recs) // 4]:
                w.add(*r)
            windows.append(w)
        t0 = time.thread_time()
        for recs, w in zip(streams, windows, strict=True):
            for r in recs[3 * len(recs) // 4:]:
                w.add(*r)
            w.expire(t_end - WINDOW_NS)
            w.metrics(t_end, 0, WINDOW_NS, 1)
        cost["running sums"].append(time.thread_time() - t0)
        t0 = time.thread_time()
        for recs in streams:
            held = [r for r in recs if r[0] >= t_end - WINDOW_NS]
            window_metrics(held, t_end, 0, WINDOW_NS, 1)  # what the collector computed before
        cost["fresh numpy"].append(time.thread_time() - t0)
    us = {k: 1e6 * statistics.median(v) for k, v in cost.items()}
    print(f"2. topic metrics of one sample, {len(DEMO_RATES)} topics at the demo's rates, {rounds} rounds")
    for k, v in us.items():
        print(f"   {k:13s} {v:6.0f} µs per sample")
    print(f"   running sums / fresh numpy = {us['running sums'] / us['fresh numpy']:.2f}")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--processes", type=int, default=10)
    ap.add_argument("--rounds", type=int, default=300)
    args = ap.parse_args(argv)
    processes(args.processes, args.rounds)
    topic_metrics(args.rounds)
    return 0


if __name__ == "__main__":
    sys.exit(main())
