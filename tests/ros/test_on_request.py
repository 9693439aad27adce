"""A topic published on request is quiet while nobody asks; its server's hang shows at its client
(issue 16 items 1 and 3), through the real monitor against real rclpy nodes in subprocesses.

A detector publishes what it found once per call of its service; a task executive calls it every
3-4 s, pauses 25 s, and calls again. No alert. Then the detector hangs: the executive's calls time
out and it logs so, and the detector is ranked first.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from stream_viz.testing import wait_for
from tests.ros.test_dynamics import HEAD, _monitor, _no_alerts, _observe, _observe_until, _plugin

pytestmark = pytest.mark.ros

DETECTOR = HEAD + """
from std_srvs.srv import Trigger
n = Node("detector")
pub = n.create_publisher(String, "/detections", 10)
def detect(req, res):
    pub.publish(String(data="part"))
    res.success = True
    return res
n.create_service(Trigger, "/detect", detect)
print("ready", flush=True)
rclpy.spin(n)
"""

EXECUTIVE = HEAD + """
from std_srvs.srv import Trigger
n = Node("executive")
client = n.create_client(Trigger, "/detect")
client.wait_for_service()
k = 0
while True:
    k += 1
    fut = client.call_async(Trigger.Request())
    rclpy.spin_until_future_complete(n, fut, timeout_sec=2.0)
    if not fut.done():
        n.get_logger().error("service /detect timed out")
        client.remove_pending_request(fut)
    print("call", k, flush=True)
    end = time.monotonic() + (25.0 if k % 6 == 0 else 3.0 + k % 2)
    while time.monotonic() < end:
        rclpy.spin_once(n, timeout_sec=0.1)
"""


def test_a_topic_published_on_request_is_quiet_while_nobody_asks_and_its_hang_shows_at_the_client(
        children, tmp_path):
    detector = children.python(DETECTOR, name="detector")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/detector" in mon.seen)[1], timeout=20, period=1.0)
        executive = children.python(EXECUTIVE, name="executive")
        _observe(mon, 75.0)  # six calls 3-4 s apart, 25 s without one, calls again
        log = (tmp_path / f"executive_{children.procs.index(executive)}.log").read_text()
        assert "call 8" in log, log
        _no_alerts(mon, "a detector asked now and then")
        rhythm = _plugin(mon, "topic_rate").state["rhythms"]["topic:/detections"]
        assert rhythm.rate <= 1.0 or max(rhythm.runs) < 0.5, rhythm  # single answers

        # The detector hangs: the executive's calls time out, and the detector is the root cause.
        t_hang = time.time()
        os.killpg(detector.pid, signal.SIGSTOP)
        try:  # the next call comes within 25 s, and times out 2 s later
            _observe_until(mon, t_hang, lambda got: any(a.member == "node:/executive" for a in got), 40.0)
            _observe(mon, 2.0)
        finally:
            os.killpg(detector.pid, signal.SIGCONT)
        after = mon.store.alerts(since=t_hang)
        assert any(a.member == "node:/executive" for a in after), after
        top = mon.engine.result().root_causes
        assert top and top[0].member == "node:/detector", top[:3]
    finally:
        mon.close()
