"""What `stream-viz agent` costs its computer: CPU and bytes published per second over the number
of ROS processes it watches.

Starts N real rclpy processes (one idle node each) on a private domain, waits until the agent
maps all N, then runs the agent's sample-and-publish step every ``--period`` for ``--seconds``
and measures this process's CPU time over that window (all its threads: the DDS participant's
discovery and sending too), the main thread's CPU time in the step itself, and the size of each
published report (CDR). The children are
started in batches so start-up does not swamp a shared machine.

    .venv/bin/python bench/bench_agent.py --processes 10 50 200 --seconds 30
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from stream_viz.collect.agent import Agent
from stream_viz.testing import claim_domain, ros_env, shm_clean, wait_for

CHILD = ("import sys, rclpy\n"
         "rclpy.init()\n"
         "n = rclpy.create_node(sys.argv[1])\n"
         "rclpy.spin(n)\n")


def start(n: int, env: dict[str, str], batch: int = 10) -> list[subprocess.Popen]:
    kids = []
    for i in range(n):
        kids.append(subprocess.Popen([sys.executable, "-c", CHILD, f"bench_node_{i}"], env=env,
                                     stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True))
        if (i + 1) % batch == 0:
            time.sleep(1.0)
    return kids


def stop(kids: list[subprocess.Popen]) -> None:
    for k in kids:
        k.kill()
    for k in kids:
        k.wait()


def measure(n: int, seconds: float, period: float, settle: float) -> dict[str, float]:
    domain = claim_domain()
    env = ros_env(domain)
    os.environ.update(env)
    kids = start(n, env)
    try:
        with Agent(domain, period) as agent:
            wait_for(lambda: len(agent.sample().participants) >= n, timeout=60 + n, period=1.0)
            for _ in range(int(settle / period)):  # discovery of N participants calms down
                agent.step()
                time.sleep(period)
            sizes, step_cpu = [], 0.0
            c0, t0 = time.process_time(), time.monotonic()
            due = t0
            while time.monotonic() - t0 < seconds:
                s0 = time.thread_time()
                agent.step()
                step_cpu += time.thread_time() - s0
                sizes.append(agent.last_size)
                due += period
                time.sleep(max(0.0, due - time.monotonic()))
            cpu, wall = time.process_time() - c0, time.monotonic() - t0
            procs = len(agent.sample().processes)
    finally:
        stop(kids)
        shm_clean()
    return {"processes": n, "tracked": procs, "cpu_percent": 100.0 * cpu / wall,
            "step_percent": 100.0 * step_cpu / wall,
            "bytes_per_s": statistics.mean(sizes) / period, "report_bytes": statistics.median(sizes)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--processes", type=int, nargs="+", default=[10, 50, 200])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--period", type=float, default=1.0)
    ap.add_argument("--settle", type=float, default=15.0, help="seconds after discovery, unmeasured")
    a = ap.parse_args()
    print("| ROS processes | processes in the report (with ancestors) | agent CPU, all threads (% of a "
          "core) | of which the sample-and-publish step | bytes/s published | report (bytes) |")
    print("|---|---|---|---|---|---|")
    for n in a.processes:
        r = measure(n, a.seconds, a.period, a.settle)
        print(f"| {r['processes']} | {r['tracked']} | {r['cpu_percent']:.2f} | {r['step_percent']:.2f} "
              f"| {r['bytes_per_s']:.0f} | {r['report_bytes']:.0f} |", flush=True)


if __name__ == "__main__":
    main()
