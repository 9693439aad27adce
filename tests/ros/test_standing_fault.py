"""A fault on top of a standing one (issue 16 item 12), through the real monitor against real
rclpy nodes in subprocesses.

A camera's process dies early and stays dead, its detector warning that its input lost its
publisher and going on with predictions: an incident that goes on. Longer than `led_max` later
the planner below them is killed. That is a new incident and the current one, the planner
first, while the camera's stays listed, ongoing, the camera first.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from stream_viz.config import load_config
from stream_viz.monitor import Monitor
from stream_viz.progress import Progress
from tests.ros.test_dynamics import HEAD, _no_alerts, _observe, _observe_until

pytestmark = pytest.mark.ros

LED_MAX = 20.0  # the default 60 s, shortened so the test waits less

CONFIG = f"""
[monitor]
period = 1.0

[watchlist]
mode = "all"

[rca]
led_max = {LED_MAX}
"""

# 10 Hz frames; SIGUSR1: the process dies with exit code 1 (a driver's fatal error).
CAMERA = HEAD + """
n = Node("camera")
pub = n.create_publisher(String, "/image", 10)
n.create_timer(0.1, lambda: pub.publish(String(data="frame")))
signal_ = __import__("signal")
signal_.signal(signal_.SIGUSR1, lambda *a: os._exit(1))
print("ready", flush=True)
rclpy.spin(n)
"""

# Tracks objects: at 5 Hz, predicted from the newest frame, frames or not.
DETECTOR = HEAD + """
n = Node("detector")
pub = n.create_publisher(String, "/objects", 10)
n.create_subscription(String, "/image", lambda m: None, 10)
n.create_timer(0.2, lambda: pub.publish(String(data="box")))
print("ready", flush=True)
rclpy.spin(n)
"""

# Plans at 5 Hz with the newest detections, or none.
PLANNER = HEAD + """
n = Node("planner")
pub = n.create_publisher(String, "/plan", 10)
n.create_subscription(String, "/objects", lambda m: None, 10)
n.create_timer(0.2, lambda: pub.publish(String(data="path")))
print("ready", flush=True)
rclpy.spin(n)
"""


def _gone(member: str):
    return lambda found: any(a.member == member and a.plugin == "member_gone" for a in found)


def test_a_fault_long_after_a_standing_one_is_the_current_incident(children, tmp_path):
    camera = children.python(CAMERA, name="camera")
    children.python(DETECTOR, name="detector")
    planner = children.python(PLANNER, name="planner")
    cfg = tmp_path / "stream-viz.toml"
    cfg.write_text(CONFIG)
    mon = Monitor(load_config(cfg), db=tmp_path / "alerts.sqlite", viewer="none", plugin_timeout_s=10.0,
                  domain_id=int(children.env["ROS_DOMAIN_ID"]), progress=Progress(open(os.devnull, "w")))
    try:
        members = {"node:/camera", "node:/detector", "node:/planner"}
        deadline = time.monotonic() + 20
        while not members <= set(mon.seen) and time.monotonic() < deadline:
            _observe(mon, 1.0)
        _observe(mon, 14.0)
        _no_alerts(mon, "a camera, a detector and a planner")
        since = time.time()
        os.kill(camera.pid, signal.SIGUSR1)
        assert _gone("node:/camera")(_observe_until(mon, since, _gone("node:/camera"), 15.0))
        # The detector warns once discovery dropped the dead camera (its lease, some 20 s).
        def warned(found):
            return any(a.member == "node:/detector" for a in found)

        assert warned(orphaned := _observe_until(mon, since, warned, 40.0)), orphaned
        assert mon.engine.result().root_causes[0].member == "node:/camera"
        _observe(mon, LED_MAX + 5.0)  # the camera's incident stands unchanged for longer than led_max
        killed = time.time()
        os.kill(planner.pid, signal.SIGKILL)
        assert _gone("node:/planner")(_observe_until(mon, killed, _gone("node:/planner"), 15.0))
        _observe(mon, 3.0)
        r = mon.engine.result()
        (now,) = [i for i in r.incidents if i.current]
        assert now.root_causes[0].member == "node:/planner" and r.root_causes[0].member == "node:/planner", (
            [(i.members, i.current) for i in r.incidents], r.root_causes[:3])
        assert "node:/camera" not in now.members
        (old,) = [i for i in r.incidents if "node:/camera" in i.members]
        assert old.ongoing and old.root_causes[0].member == "node:/camera", old.root_causes[:3]
    finally:
        mon.close()
