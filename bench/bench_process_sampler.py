"""The process sampler's two ways to read a tracked process, side by side: /proc files vs psutil.

Real processes (Python children with a few threads and open files, like rclpy nodes), each
sampled by both samplers in alternation in one run; the figure is main-thread CPU time per
process per sample and the ratio. The metrics are the same (``tests/robust/test_system.py``).

    .venv/bin/python bench/bench_process_sampler.py --processes 10 --rounds 300
"""

from __future__ import annotations

import argparse
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from stream_viz.collect.processes import ProcessSampler

CHILD = ("import threading, time, tempfile\n"
         "files = [tempfile.TemporaryFile() for _ in range(20)]\n"
         "for _ in range(4): threading.Thread(target=time.sleep, args=(600,), daemon=True).start()\n"
         "time.sleep(600)\n")


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--processes", type=int, default=10)
    ap.add_argument("--rounds", type=int, default=300)
    args = ap.parse_args(argv)
    kids = [subprocess.Popen([sys.executable, "-c", CHILD]) for _ in range(args.processes)]
    try:
        time.sleep(1.0)
        pids = [k.pid for k in kids]
        # Ancestors read every time, so both read the same processes every round.
        samplers = {"procfs": ProcessSampler(ancestors_every=1, procfs=True),
                    "psutil": ProcessSampler(ancestors_every=1, procfs=False)}
        cost: dict[str, list[float]] = {k: [] for k in samplers}
        n = 0
        for _ in range(args.rounds):
            for name, s in samplers.items():
                t0 = time.thread_time()
                out = s.sample(pids)
                cost[name].append(time.thread_time() - t0)
                n = len(out.processes)
        print(f"{args.processes} children + their ancestors = {n} processes, {args.rounds} rounds")
        us = {k: 1e6 * statistics.median(v) / n for k, v in cost.items()}
        for k, v in us.items():
            print(f"{k:7s} {v:6.1f} µs per process per sample (median)")
        print(f"procfs / psutil = {us['procfs'] / us['psutil']:.2f}")
    finally:
        for k in kids:
            k.kill()
    return 0


if __name__ == "__main__":
    sys.exit(main())
