"""What `stream-viz agent` costs its computer: CPU and bytes published per second over the number
of ROS processes it watches.

Starts N real rclpy processes (one idle node each) on a private domain, waits until the agent
maps all N, then runs the agent's sample-and-publish step every ``--period`` for ``--seconds``
and measures this process's CPU time over that window (all its threads: the DDS participant's
discovery and sending too), the main thread's CPU time in the step itself, and the size of each
published report (CDR). The children are
started in batches so start-up does not swamp a shared machine.

    .venv/bin/python bench/bench_agent.py --processes 10 50 100 --seconds 30

One ROS domain holds at most about 120 participants per computer (Fast DDS's port mapping leaves
room for about that many participant ids: ROS 2's documentation on ROS_DOMAIN_ID), so 200 ROS
processes cannot run on one computer in one domain; 100 is the largest size measured.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import time

from stream_viz.collect.agent import Agent
from stream_viz.testing import claim_domain, ros_env, shm_clean

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


def _mapped(agent: Agent, n: int, timeout: float = 180.0, steady: float = 40.0) -> int:
    """Wait until the agent maps all ``n`` processes, or the count has not grown for ``steady`` s;
    return the count (a loaded machine may discover fewer: the table says how many)."""
    best, since, deadline = 0, time.monotonic(), time.monotonic() + timeout
    while time.monotonic() < deadline:
        got = len(set(agent.sample().participants.values()))
        if got >= n:
            return got
        if got > best:
            best, since = got, time.monotonic()
        elif time.monotonic() - since > steady:
            break
        time.sleep(1.0)
    return best


def measure(n: int, seconds: float, period: float, settle: float) -> dict[str, float]:
    domain = claim_domain()
    env = ros_env(domain)
    os.environ.update(env)
    kids = start(n, env)
    try:
        with Agent(domain, period) as agent:
            mapped = _mapped(agent, n)
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
    return {"processes": n, "mapped": mapped, "tracked": procs, "cpu_percent": 100.0 * cpu / wall,
            "step_percent": 100.0 * step_cpu / wall,
            "bytes_per_s": statistics.mean(sizes) / period, "report_bytes": statistics.median(sizes)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--processes", type=int, nargs="+", default=[10, 50, 100])
    ap.add_argument("--seconds", type=float, default=30.0)
    ap.add_argument("--period", type=float, default=1.0)
    ap.add_argument("--settle", type=float, default=15.0, help="seconds after discovery, unmeasured")
    a = ap.parse_args()
    cols = ("ROS processes", "mapped by the agent", "processes in the report (with ancestors)",
            "agent CPU, all threads (% of a core)", "of which the sample-and-publish step",
            "bytes/s published", "report (bytes)")
    print("| " + " | ".join(cols) + " |")
    print("|" + "---|" * len(cols))
    for n in a.processes:
        r = measure(n, a.seconds, a.period, a.settle)
        row = (r["processes"], r["mapped"], r["tracked"], f"{r['cpu_percent']:.2f}",
               f"{r['step_percent']:.2f}", f"{r['bytes_per_s']:.0f}", f"{r['report_bytes']:.0f}")
        print("| " + " | ".join(map(str, row)) + " |", flush=True)


if __name__ == "__main__":
    main()
