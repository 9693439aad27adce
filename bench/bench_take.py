"""The collector's cost per message taken, side by side in one run (issue 16 items 4 and 8).

Three subscriptions on one topic with two publishers receive the same messages; each round the
publishers send a burst, then each subscription is drained in turn (the order rotates) and the
drain's CPU time (``time.thread_time``) is divided by the messages it took:

* ``before``: what the drain did before publisher gids and message ages: rclpy's
  ``take_message`` (raw) and `TopicWindow.add` of ``(received, source, size, sequence)``;
* ``after``: `TopicMonitor.drain` now: rcl's take with the publisher gid (`RclTake`), the
  header stamp read from the bytes, `TopicWindow.add` with the gid and the message age;
* ``fallback``: `TopicMonitor.drain` without gids (rclpy's take), the stamp still read.

Messages are ``sensor_msgs/Imu`` (a Header first: the stamp is read) or ``std_msgs/String``.
Medians over the rounds; the machine is shared, compare the ratios.

    .venv/bin/python bench/bench_take.py --rounds 40 --burst 400
"""

from __future__ import annotations

import argparse
import statistics
import time

import rclpy
from rclpy.context import Context
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy

from stream_viz.collect.topics import OBSERVE_QOS, TopicMonitor, import_type
from stream_viz.collect.window import TopicWindow
from stream_viz.testing import claim_domain

TYPES = {"imu": "sensor_msgs/msg/Imu", "string": "std_msgs/msg/String"}


def _before(sub, window: TopicWindow) -> int:
    """The drain loop of one topic before gids and ages (stream_viz/collect/topics.py at 51b9e05)."""
    handle, add, n = sub.handle, window.add, 0
    with handle:
        take, msg_type = handle.take_message, sub.msg_type
        while (got := take(msg_type, True)) is not None:
            msg, info = got
            n += 1
            add(info["received_timestamp"], info["source_timestamp"], len(msg),
                info.get("publication_sequence_number"))
    return n


def run(kind: str, rounds: int, burst: int) -> dict[str, float]:
    type_name = TYPES[kind]
    cls = import_type(type_name)
    ctx = Context()
    rclpy.init(args=[], context=ctx, domain_id=claim_domain())
    try:
        pubs = [Node(f"pub{i}", context=ctx).create_publisher(
            cls, "/bench", QoSProfile(depth=burst, reliability=ReliabilityPolicy.RELIABLE)) for i in range(2)]
        after = TopicMonitor(Node("after", context=ctx), gids=True)
        fallback = TopicMonitor(Node("fallback", context=ctx), gids=False)
        for tm in (after, fallback):
            tm.update({"/bench": [type_name]})
        before_sub = Node("before", context=ctx).create_subscription(cls, "/bench", lambda _m: None,
                                                                       OBSERVE_QOS, raw=True)
        before_window = TopicWindow()
        time.sleep(1.5)  # discovery
        assert after.rcl is not None and after.rcl.available, after.rcl and after.rcl.why
        drains = {"before": lambda: _before(before_sub, before_window),
                  "after": lambda: _take_all(after), "fallback": lambda: _take_all(fallback)}
        cost: dict[str, list[float]] = {k: [] for k in drains}
        msg = cls()
        for r in range(rounds):
            for i in range(burst):
                if kind == "imu":
                    msg.header.stamp.sec, msg.header.stamp.nanosec = int(time.time()), i
                pubs[i % 2].publish(msg)
            time.sleep(0.3)
            names = list(drains)
            names = names[r % 3:] + names[: r % 3]
            for name in names:
                t0 = time.thread_time()
                n = drains[name]()
                dt = time.thread_time() - t0
                if n:
                    cost[name].append(dt / n)
        assert after.rcl.available, after.rcl.why
        return {k: 1e6 * statistics.median(v) for k, v in cost.items() if v}
    finally:
        ctx.try_shutdown()


def _take_all(tm: TopicMonitor) -> int:
    before = tm.taken
    tm.drain()
    return tm.taken - before


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--rounds", type=int, default=40)
    ap.add_argument("--burst", type=int, default=400)
    args = ap.parse_args()
    for kind in TYPES:
        us = run(kind, args.rounds, args.burst)
        print(f"{TYPES[kind]}: {args.rounds} rounds of {args.burst} messages from 2 publishers")
        for k, v in us.items():
            print(f"   {k:8s} {v:6.2f} µs per message")
        print(f"   after / before = {us['after'] / us['before']:.2f}, "
              f"fallback / before = {us['fallback'] / us['before']:.2f}")


if __name__ == "__main__":
    main()
