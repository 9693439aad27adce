"""A computer starved by work outside the robot: the monitor names the computer, not a node.

Real rclpy children, real CPU hogs (plain Python processes, no ROS) and the real ``stream-viz
monitor``. The robot needs most of a core to keep its rate; the hogs take every core from it.
"""

from __future__ import annotations

import os
import socket
import subprocess
import sys
import time

import psutil
import pytest

from tests.robust.common import QuotaGroup, monitor_cmd, report

pytestmark = pytest.mark.ros

# A sensor whose 100 Hz output costs ~7 ms of CPU a message (70 % of a core), and a consumer.
BUSY_SENSOR = """
import time, rclpy
from rclpy.executors import SingleThreadedExecutor
from std_msgs.msg import String
rclpy.init()
a = rclpy.create_node("lidar"); b = rclpy.create_node("mapper")
pub = a.create_publisher(String, "/scan", 10)
out = b.create_publisher(String, "/map", 10)
b.create_subscription(String, "/scan", lambda m: out.publish(m), 10)
def tick():
    end = time.thread_time() + 0.007
    while time.thread_time() < end:
        pass
    pub.publish(String(data="scan"))
a.create_timer(0.01, tick)
ex = SingleThreadedExecutor(); ex.add_node(a); ex.add_node(b)
try:
    ex.spin()
except (KeyboardInterrupt, Exception):
    pass
"""

HOG = "while True:\n    pass\n"
HOGS_FROM_S = 22.0  # after detection's warm-up: every baseline learned on the quiet computer


def test_a_computer_starved_by_work_outside_the_robot_is_the_root_cause(children, tmp_path):
    children.python(BUSY_SENSOR, name="sensor")
    rep = tmp_path / "r.json"
    monitor = subprocess.Popen(monitor_cmd("--duration", "50", "--report", str(rep)), env=children.env,
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    hogs: list[subprocess.Popen] = []
    try:
        time.sleep(HOGS_FROM_S)
        # Four busy processes a core, each in its own session (so the kernel's autogroups share
        # the CPUs among them and the robot alike): the sensor gets about a fifth of a core.
        hogs = [subprocess.Popen([sys.executable, "-c", HOG], start_new_session=True)
                for _ in range(4 * (psutil.cpu_count() or 1))]
        _, err = monitor.communicate(timeout=120)
    finally:
        for p in hogs:
            p.kill()
        if monitor.poll() is None:
            monitor.kill()
    assert monitor.returncode == 0, err
    r = report(rep)
    host = f"host:{socket.gethostname()}"
    t0 = min(a["t"] for a in r["alerts"]) if r["alerts"] else None
    saturated = [a for a in r["alerts"] if a["member"] == host and a["plugin"] == "host_state"]
    assert saturated, [(a["member"], a["message"]) for a in r["alerts"]]
    assert "tasks waited for a CPU" in saturated[0]["message"]
    assert "outside the robot's processes" in saturated[0]["message"]
    slowed = [a for a in r["alerts"] if a["member"] in ("topic:/scan", "topic:/map", "node:/lidar")]
    # Not a miss of ours: the hogs must have slowed the sensor for the test to mean anything.
    assert slowed, ("the hogs did not slow the sensor", [(a["member"], a["message"]) for a in r["alerts"]])
    causes = [c["member"] for c in r["root_causes"]]
    assert causes[0] == host, (causes, [(a["member"], a["t"] - t0, a["message"]) for a in r["alerts"]])
    first, *rest = r["root_causes"]
    assert "node:/lidar" in first["evidence"]["explains_nodes"]
    assert all(c["score"] < first["score"] for c in rest)  # the slowed nodes below it, not tied


def test_a_container_at_its_cpu_quota_is_the_root_cause(children, tmp_path):
    """The robot runs in a container held to one CPU (a cgroup quota, as ``docker --cpus 1``) on a
    machine with cores to spare; a build started in the container takes most of that CPU. The
    machine's cores are half idle and no task waits for one: only the quota says the container
    is saturated, and it is the root cause of the sensor's slowing."""
    try:
        group = QuotaGroup(1.0, f"stream-viz-test-{os.getpid()}")
    except OSError as e:
        pytest.skip(f"cannot make a cgroup with a CPU quota here: {e}")
    hogs: list[subprocess.Popen] = []
    try:
        group.add(children.python(BUSY_SENSOR, name="sensor").pid)
        rep = tmp_path / "r.json"
        monitor = subprocess.Popen(monitor_cmd("--duration", "50", "--report", str(rep)), env=children.env,
                                   stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            time.sleep(HOGS_FROM_S)
            hogs = [subprocess.Popen([sys.executable, "-c", HOG]) for _ in range(2)]
            for p in hogs:
                group.add(p.pid)
            _, err = monitor.communicate(timeout=120)
        finally:
            if monitor.poll() is None:
                monitor.kill()
    finally:
        for p in hogs:
            p.kill()
            p.wait()
        group.close()
    assert monitor.returncode == 0, err
    r = report(rep)
    host = f"host:{socket.gethostname()}"
    said = [(a["member"], a["message"]) for a in r["alerts"]]
    saturated = [a for a in r["alerts"] if a["member"] == host and a["plugin"] == "host_state"]
    assert saturated, said
    assert "of 1 CPUs" in saturated[0]["message"], saturated[0]["message"]  # the quota, not the cores
    slowed = [a for a in r["alerts"] if a["member"] in ("topic:/scan", "topic:/map", "node:/lidar")]
    assert slowed, ("the build did not slow the sensor", said)
    causes = [c["member"] for c in r["root_causes"]]
    assert causes[0] == host, (causes, said)
