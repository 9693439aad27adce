"""A Python node's uncaught exception is a crash, a stop is not (issue 16 items 1 and 2), through
the real monitor against real rclpy nodes in subprocesses.

In Jazzy, rclpy destroys a node on the way out of an uncaught exception: DDS gets its goodbye,
and the process exits with code 1. Plain ``rclpy.spin`` code ends so on SIGTERM too (rclpy's
``ExternalShutdownException``), and with SIGINT re-raised on Ctrl-C. Two tools sent SIGTERM
together (a supervisor stopping its processes) and one sent SIGINT alone raise nothing; the
camera whose callback raises is a crash, its subscriber's input lost its publisher, and the RCA
ranks the camera first.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _no_alerts, _observe, _observe_until

pytestmark = pytest.mark.ros

# Plain `rclpy.spin`: an exception in a callback, or Ctrl-C, ends it with code 1.
CAMERA = HEAD + """
flag = sys.argv[1]
n = Node("camera")
pub = n.create_publisher(String, "/image", 10)
def grab():
    if os.path.exists(flag):
        raise RuntimeError("device returned an empty frame")
    pub.publish(String(data="frame"))
n.create_timer(0.1, grab)
print("ready", flush=True)
rclpy.spin(n)
"""

DETECTOR = HEAD + """
n = Node("detector")
pub = n.create_publisher(String, "/detections", 10)
n.create_subscription(String, "/image", lambda m: pub.publish(String(data="none")), 10)
print("ready", flush=True)
rclpy.spin(n)
"""

# A tool an operator runs and stops: argument its node name.
TOOL = """
import signal
# Python's own Ctrl-C handler, as from a terminal, set before rclpy.init() chains to it: a child
# of a shell's background job (a CI run so) inherits SIGINT ignored.
signal.signal(signal.SIGINT, signal.default_int_handler)
""" + HEAD + """
n = Node(sys.argv[1])
n.create_subscription(String, "/detections", lambda m: None, 10)
print("ready", flush=True)
rclpy.spin(n)
"""

NODES = {"node:/camera", "node:/detector", "node:/teleop", "node:/joy_mapper", "node:/recorder"}


def test_an_uncaught_exception_is_a_crash_and_a_stop_is_not(children, tmp_path):
    flag = tmp_path / "empty_frames"
    children.python(CAMERA, str(flag), name="camera")
    children.python(DETECTOR, name="detector")
    tools = [children.python(TOOL, name, name=name) for name in ("teleop", "joy_mapper", "recorder")]
    mon = _monitor(children, tmp_path)
    try:
        deadline = time.monotonic() + 20
        while not NODES <= set(mon.seen) and time.monotonic() < deadline:
            _observe(mon, 1.0)
        _observe(mon, 12.0)
        _no_alerts(mon, "a camera, its detector and three tools")
        # Two tools stopped together by SIGTERM exit 1; the third, Ctrl-C'd alone, by SIGINT.
        for p in tools[:2]:
            os.killpg(p.pid, signal.SIGTERM)
        assert [p.wait(timeout=15) for p in tools[:2]] == [1, 1]
        _observe(mon, 5.0)
        os.killpg(tools[2].pid, signal.SIGINT)
        assert tools[2].wait(timeout=15) == -signal.SIGINT
        _observe(mon, 6.0)
        _no_alerts(mon, "tools stopped (two together with code 1, one alone by SIGINT)")
        since = time.time()
        flag.touch()
        lost_input = lambda found: any(a.plugin == "graph_anomalies" for a in found)  # noqa: E731
        alerts = _observe_until(mon, since, lost_input, 20.0)
        crash = [a for a in alerts if a.plugin == "member_gone"]
        assert [(a.member, a.data["symptom"], a.data["after_goodbye"]) for a in crash] == [
            ("node:/camera", "exit", True)], alerts
        assert "exited with code 1" in crash[0].message and "uncaught exception" in crash[0].message
        lost = [a for a in alerts if a.plugin == "graph_anomalies"]
        assert {a.member for a in lost} == {"node:/detector"}, lost
        assert "since its publisher /camera died" in lost[0].message
        causes = mon.engine.result().root_causes
        assert causes[0].member == "node:/camera", causes[:3]
    finally:
        mon.close()
