"""What receiving the topics costs Fast DDS itself, below stream-viz: a bare rclpy subscriber.

The demo robot runs (own ROS_DOMAIN_ID); for each case a fresh subscriber process takes raw
messages of every demo topic (as the collector does: best effort, volatile, depth 1000, drained
once a second) and reports the CPU of its non-Python threads over ``--seconds`` — Fast DDS's
receive threads (``dds.shm.*``, ``dds.udp.*``) and timers — per second and per message. Cases:
nothing subscribed, the default transports, SHM only, UDP only, reliable, depth 10.

    .venv/bin/python bench/bench_dds_receive.py --seconds 30
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

from stream_viz.testing import own_domain

SUBSCRIBER = r'''
import json, sys, threading, time
import psutil, rclpy
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from stream_viz.collect.topics import import_type
topics, secs, depth = json.loads(sys.argv[1]), float(sys.argv[2]), int(sys.argv[3])
reliable = sys.argv[4] == "1"
rclpy.init()
node = rclpy.create_node("bench_dds_receive")
qos = QoSProfile(depth=depth, durability=DurabilityPolicy.VOLATILE, history=HistoryPolicy.KEEP_LAST,
                 reliability=ReliabilityPolicy.RELIABLE if reliable else ReliabilityPolicy.BEST_EFFORT)
subs = [node.create_subscription(import_type(ty), t, lambda m: None, qos, raw=True)
        for t, ty in topics.items()]
def drain():
    k = 0
    for s in subs:
        with s.handle:
            while s.handle.take_message(s.msg_type, True) is not None:
                k += 1
    return k
time.sleep(5.0)
drain()
me, main = psutil.Process(), threading.get_native_id()
def native():
    return {t.id: t.user_time + t.system_time for t in me.threads() if t.id != main}
c0, t0, n = native(), time.monotonic(), 0
while time.monotonic() - t0 < secs:
    time.sleep(1.0)
    n += drain()
c1, wall = native(), time.monotonic() - t0
names = {}
for tid in c1:
    try:
        names[tid] = open(f"/proc/self/task/{tid}/comm").read().strip()
    except OSError:
        names[tid] = str(tid)
by_name = {}
for tid, c in c1.items():
    key = names[tid].rstrip("0123456789.") or names[tid]
    by_name[key] = by_name.get(key, 0.0) + c - c0.get(tid, 0.0)
print(json.dumps({"msgs_per_s": n / wall, "native_pct": 100 * sum(by_name.values()) / wall,
                  "threads": {k: round(100 * v / wall, 3) for k, v in by_name.items() if v > 0}}))
'''

CASES = [  # name, subscribe to topics?, env, depth, reliable
    ("nothing subscribed", False, {}, 1000, False),
    ("every topic, default transports", True, {}, 1000, False),
    ("every topic, SHM only", True, {"FASTDDS_BUILTIN_TRANSPORTS": "SHM"}, 1000, False),
    ("every topic, UDP only", True, {"FASTDDS_BUILTIN_TRANSPORTS": "UDPv4"}, 1000, False),
    ("every topic, reliable", True, {}, 1000, True),
    ("every topic, depth 10", True, {}, 10, False),
]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--seconds", type=float, default=30.0)
    args = ap.parse_args(argv)
    own_domain()
    from stream_viz.demo.robot import Robot
    from stream_viz.demo.topology import DEMO

    topics = DEMO.topics()
    robot = Robot(env=dict(os.environ), run_dir=Path(tempfile.mkdtemp(prefix="bench_dds_")) / "robot")
    robot.start()
    try:
        robot.wait_ready(timeout=120)
        print(f"bare rclpy subscriber, demo robot, {args.seconds:.0f} s per case, "
              f"load {os.getloadavg()[0]:.1f}")
        print(f"{'case':34s} {'msgs/s':>7s} {'% core':>7s} {'µs/msg':>7s}  threads (% core)")
        for name, sub, env, depth, reliable in CASES:
            out = subprocess.run(
                [sys.executable, "-c", SUBSCRIBER, json.dumps(topics if sub else {}), str(args.seconds),
                 str(depth), "1" if reliable else "0"],
                env=dict(os.environ, **env), capture_output=True, text=True, check=True)
            r = json.loads(out.stdout.strip().splitlines()[-1])
            per = 1e4 * r["native_pct"] / r["msgs_per_s"] if r["msgs_per_s"] else float("nan")
            print(f"{name:34s} {r['msgs_per_s']:7.1f} {r['native_pct']:6.2f}% {per:7.0f}  {r['threads']}",
                  flush=True)
    finally:
        robot.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
