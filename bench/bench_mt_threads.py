"""What an rclpy multi-threaded executor's threads use at a light load, against the thread rule.

A camera publishes a 10 Hz topic; a process with a `MultiThreadedExecutor` holds a detector of it
(``--work-ms`` of CPU a frame), a tracker of its detections and a 2 Hz status timer. Every
``--span`` seconds, each thread's CPU (its ``schedstat``, the middleware's threads aside as the
collector sets them aside) over the span, as % of a core, and which of them
`threads_that_ran` counts. The rule must count the dispatching main thread and the workers:
a multi-threaded executor is then told from a single-threaded one (docs/collector.md).

    .venv/bin/python bench/bench_mt_threads.py --spans 3 --span 30 --work-ms 0
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time

from stream_viz.collect.processes import MIDDLEWARE_THREADS, threads_that_ran

CAMERA = """
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
n = Node("camera")
pub = n.create_publisher(String, "/image", 10)
n.create_timer(0.1, lambda: pub.publish(String(data="frame")))
rclpy.spin(n)
"""

DETECTOR = """
import sys, time, rclpy
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
work = float(sys.argv[1]) / 1000.0
det, tracker = Node("detector"), Node("tracker")
out = det.create_publisher(String, "/detections", 10)
status = det.create_publisher(String, "/detector/status", 10)
def frame(msg):
    end = time.thread_time() + work
    while time.thread_time() < end:
        pass
    out.publish(String(data="pallet"))
det.create_subscription(String, "/image", frame, 10)
det.create_timer(0.5, lambda: status.publish(String(data="ok")))
tracks = tracker.create_publisher(String, "/tracks", 10)
tracker.create_subscription(String, "/detections", tracks.publish, 10)
ex = MultiThreadedExecutor()
ex.add_node(det)
ex.add_node(tracker)
ex.spin()
"""


def threads_ns(pid: int) -> dict[int, int]:
    """Thread id -> CPU time (ns) of ``pid``'s threads, the middleware's aside."""
    out = {}
    for name in os.listdir(f"/proc/{pid}/task"):
        try:
            with open(f"/proc/{pid}/task/{name}/comm") as f:
                if f.read().startswith(MIDDLEWARE_THREADS):
                    continue
            with open(f"/proc/{pid}/task/{name}/schedstat") as f:
                out[int(name)] = int(f.read().split()[0])
        except (OSError, ValueError):
            continue
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--spans", type=int, default=3)
    ap.add_argument("--span", type=float, default=30.0, help="seconds between two probes")
    ap.add_argument("--work-ms", type=float, default=0.0, help="CPU the detector uses a frame")
    ap.add_argument("--domain", default="87", help="ROS_DOMAIN_ID of the run (loopback only)")
    args = ap.parse_args()
    env = dict(os.environ, ROS_DOMAIN_ID=args.domain, ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST")
    procs = [subprocess.Popen([sys.executable, "-c", CAMERA], env=env),
             subprocess.Popen([sys.executable, "-c", DETECTOR, str(args.work_ms)], env=env)]
    pid = procs[1].pid
    try:
        time.sleep(10.0)  # start-up runs every thread
        print(f"work {args.work_ms:g} ms a frame, spans of {args.span:g} s; threads by CPU, % of a core")
        for _ in range(args.spans):
            before, t0 = threads_ns(pid), time.monotonic()
            time.sleep(args.span)
            now, span = threads_ns(pid), time.monotonic() - t0
            used = sorted(((ns - before.get(tid, 0)) / 1e9 / span * 100.0, tid) for tid, ns in now.items())
            working = [(p, tid) for p, tid in used if p >= 0.01][::-1]
            ran = threads_that_ran(before, now, span)
            print("  " + ", ".join(f"{p:.3f}" for p, _ in working)
                  + f" | busiest/second {working[0][0] / max(working[1][0], 1e-9):.1f}x"
                  + f" | counted running: {len(ran)}", flush=True)
    finally:
        for p in procs:
            p.kill()
            p.wait()


if __name__ == "__main__":
    main()
