"""A multi-threaded executor's dispatching thread busy is no node's symptom; a runaway thread is
(issue 16 item 1: healthy dynamics), through the real monitor against real rclpy nodes.

rclpy's MultiThreadedExecutor spins its dispatch loop in the main thread and hands callbacks to
a pool of workers. When callbacks come faster than it hands them out (a flood of small messages;
on real robots also its loop spinning while callbacks wait for a worker, ros2/rclpy#1452), that
thread takes a core while the workers stay nearly idle. A mapper's container flooded so is not
alerted for its CPU; a planner's container, also multi-threaded, whose runaway thread burns a
core at the same time, is.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from stream_viz.model.theta import SCHEMAS
from tests.ros.test_dynamics import HEAD, _monitor, _observe, _observe_until, _settle

pytestmark = pytest.mark.ros

# Scans at 10 Hz; SIGUSR1: as fast as it can publish (a driver flooding its topic).
SOURCE = HEAD + """
n = Node("lidar")
pub = n.create_publisher(String, "/scan", 10)
fast = [False]
signal_ = __import__("signal")
signal_.signal(signal_.SIGUSR1, lambda *a: fast.__setitem__(0, True))
print("ready", flush=True)
while rclpy.ok():
    pub.publish(String(data="scan"))
    rclpy.spin_once(n, timeout_sec=0.0)
    time.sleep(0.0005 if fast[0] else 0.1)
"""

# A node with two small subscriptions of /scan and a timer, on a multi-threaded executor.
MAPPER = HEAD + """
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup as Group
from rclpy.executors import MultiThreadedExecutor
n = Node("mapper")
for _ in range(2):
    n.create_subscription(String, "/scan", lambda m: None, 10, callback_group=Group())
n.create_timer(0.1, lambda: None, callback_group=Group())
ex = MultiThreadedExecutor(num_threads=2)
ex.add_node(n)
print("ready", flush=True)
ex.spin()
"""

# A planner on a multi-threaded executor working ~2 % of a core; SIGUSR1: a runaway thread.
PLANNER = HEAD + """
import hashlib, threading
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.executors import MultiThreadedExecutor
n = Node("planner")
pub = n.create_publisher(String, "/plan", 10)
def plan():
    end = time.thread_time() + 0.002
    while time.thread_time() < end:
        pass
    pub.publish(String(data="plan"))
group = ReentrantCallbackGroup()
for _ in range(2):
    n.create_timer(0.1, plan, callback_group=group)
def burn():
    buf = b"x" * 2**20
    while True:
        hashlib.sha256(buf).digest()
signal_ = __import__("signal")
signal_.signal(signal_.SIGUSR1, lambda *a: threading.Thread(target=burn, daemon=True).start())
ex = MultiThreadedExecutor(num_threads=2)
ex.add_node(n)
print("ready", flush=True)
ex.spin()
"""

CPU = SCHEMAS["process"].index("cpu_percent")
MAIN = SCHEMAS["process"].index("main_cpu_percent")
DISPATCHING = SCHEMAS["process"].index("dispatching")


def test_a_busy_dispatching_thread_is_no_symptom_and_a_runaway_thread_is(children, tmp_path):
    source = children.python(SOURCE, name="lidar")
    children.python(MAPPER, name="mapper")
    planner = children.python(PLANNER, name="planner")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {"node:/lidar", "node:/mapper", "node:/planner"}, "three nodes at work")
        since = time.time()
        os.kill(source.pid, signal.SIGUSR1)
        os.kill(planner.pid, signal.SIGUSR1)
        alerts = _observe_until(mon, since, lambda found: any(
            a.member == "node:/planner" and a.plugin == "process_resources" for a in found), 25.0)
        _observe(mon, 5.0)  # the mapper's rise has held as long as the planner's then
        mapper = f"process:{mon.seen.nodes['node:/mapper']['pid']}"
        theta = mon.shadow.history.values(mapper, last=8)
        # The flood did raise the mapper's CPU past the 25 points a rise is alerted at (else this
        # test could not fail), its main thread most of it; one probe may miss the dispatch (a
        # worker under the threshold in its span), most do not.
        rise = theta[:, CPU] - 5.0
        assert max(rise) >= 25.0 and max(theta[:, MAIN]) >= max(rise) / 2, theta
        assert sum(theta[:, DISPATCHING] == 1.0) >= len(theta) / 2, theta
        cpu = [a for a in mon.store.alerts(since=since) if a.plugin == "process_resources"]
        assert "node:/planner" in {a.member for a in cpu}, alerts
        assert "node:/mapper" not in {a.member for a in cpu}, cpu
    finally:
        mon.close()
