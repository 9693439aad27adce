"""Of a container's nodes, the one that began to warn as the process's CPU rose ranks first
(issue 16 item 2: the diagnosis names the process and tells its nodes apart when it can),
through the real monitor against real rclpy nodes.

A perception container runs a label reader and a gap detector on one multi-threaded executor.
The gap detector has logged a WARN every few seconds since it started (a standing warning); at
SIGUSR1 the label reader's model falls back to the CPU: it logs a WARN and one of its threads
takes a core. The process's CPU alert names the reader, and the RCA ranks it first, alone.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _observe, _observe_until, _settle

pytestmark = pytest.mark.ros

READER, DETECTOR = "node:/label_reader", "node:/gap_detector"

CONTAINER = HEAD + """
import hashlib, threading
from rclpy.executors import MultiThreadedExecutor
reader, detector = Node("label_reader"), Node("gap_detector")
labels = reader.create_publisher(String, "/labels", 10)
gaps = detector.create_publisher(String, "/gaps", 10)
reader.create_timer(0.2, lambda: labels.publish(String(data="label")))
detector.create_timer(0.2, lambda: gaps.publish(String(data="gap")))
detector.create_timer(4.0, lambda: detector.get_logger().warn("planogram has 3 bays without facings"))
def burn():
    buf = b"x" * 2**20
    while True:
        hashlib.sha256(buf).digest()
def fall_back(*_):
    reader.get_logger().warn("GPU plugin failed: CL_OUT_OF_RESOURCES; falling back to CPU inference")
    threading.Thread(target=burn, daemon=True).start()
__import__("signal").signal(__import__("signal").SIGUSR1, fall_back)
ex = MultiThreadedExecutor(num_threads=2)
ex.add_node(reader)
ex.add_node(detector)
print("ready", flush=True)
ex.spin()
"""


def test_the_container_node_that_began_to_warn_as_its_cpu_rose_ranks_first(children, tmp_path):
    box = children.python(CONTAINER, name="perception")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {READER, DETECTOR}, "a perception container with a standing warning")
        since = time.time()
        os.kill(box.pid, signal.SIGUSR1)
        alerts = _observe_until(mon, since, lambda found: any(
            a.plugin == "process_resources" for a in found), 25.0)
        cpu = [a for a in alerts if a.plugin == "process_resources"]
        assert {a.member for a in cpu} == {READER, DETECTOR}, alerts
        # The reader began to warn with the rise; the detector has warned all along.
        assert all(a.data.get("names") == [READER] for a in cpu), [a.data for a in cpu]
        assert "/label_reader began to warn: GPU plugin failed" in cpu[0].message
        _observe(mon, 2.0)
        top = mon.engine.result().root_causes
        assert top and top[0].member == READER, [(rc.member, rc.score, rc.evidence) for rc in top[:3]]
        assert "indistinguishable_from" not in top[0].evidence, top[0].evidence
        assert top[0].score > next(rc.score for rc in top if rc.member == DETECTOR)
    finally:
        mon.close()
