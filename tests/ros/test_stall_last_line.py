"""A stalled container's last line (issue 16 item 2), through the real monitor against real
rclpy nodes in a subprocess.

Two camera drivers share one process and one executor: the visible camera at 20 Hz, the thermal
one at 9 Hz, whose shutter check (a 1 Hz timer that publishes nothing) runs a flat field
correction now and then. Told to, it logs "Running flat field correction (shutter)" and its
serial read never returns: both cameras stop. By when each next frame was due the 20 Hz camera
would have blocked the executor; the thermal camera logged after every frame of them both, so
its callback ran last, and the RCA ranks it first, alone.
"""

from __future__ import annotations

import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _no_alerts, _observe, _observe_until

pytestmark = pytest.mark.ros

CONTAINER = HEAD + """
from rclpy.executors import SingleThreadedExecutor
flag = sys.argv[1]
cam, thermal = Node("camera"), Node("thermal_camera")
cam_pub = cam.create_publisher(String, "/camera/image", 10)
cam.create_timer(0.05, lambda: cam_pub.publish(String(data="frame")))
thermal_pub = thermal.create_publisher(String, "/thermal/image", 10)
thermal.create_timer(1 / 9, lambda: thermal_pub.publish(String(data="frame")))
def shutter():
    if os.path.exists(flag):
        thermal.get_logger().info("Running flat field correction (shutter)")
        while True:  # the serial read without a timeout
            time.sleep(1.0)
thermal.create_timer(1.0, shutter)
ex = SingleThreadedExecutor()
for n in (cam, thermal):
    ex.add_node(n)
print("ready", flush=True)
ex.spin()
"""

NODES = ("node:/camera", "node:/thermal_camera")


def test_the_node_that_logged_as_its_executor_stopped_ranks_first(children, tmp_path):
    flag = tmp_path / "ffc"
    children.python(CONTAINER, str(flag), name="cameras")
    mon = _monitor(children, tmp_path)
    try:
        deadline = time.monotonic() + 20
        while not set(NODES) <= set(mon.seen) and time.monotonic() < deadline:
            _observe(mon, 1.0)
        _observe(mon, 14.0)
        _no_alerts(mon, "a camera container")
        since = time.time()
        flag.touch()
        silent = {"topic:/camera/image", "topic:/thermal/image"}
        alerts = _observe_until(mon, since, lambda found: silent <= {a.member for a in found}, 15.0)
        _observe(mon, 3.0)
        thermal = [a for a in mon.store.alerts(since=since) if a.member == "topic:/thermal/image"]
        assert thermal and thermal[0].data.get("logged_at", 0) >= since, alerts
        causes = mon.engine.result().root_causes
        assert causes[0].member == "node:/thermal_camera", causes[:3]
        assert causes[0].evidence.get("blocked") == 1.0, causes[:3]
        assert causes[1].score < causes[0].score, causes[:3]
    finally:
        mon.close()
