"""A callback that blocks a single-threaded container is told from the siblings it starves
(issue 16 item 2), through the real monitor against a real rclpy container in a subprocess.

A sensor container spins one SingleThreadedExecutor for three drivers: a camera at 2 Hz, a lidar
at 10 Hz and an IMU at 100 Hz. The camera's frame callback blocks (a read without a timeout)
before it publishes: every output of the container stops. Its fellows' silences say when each
next message was due; the camera's was due as the others stopped, and a 2 Hz frame due just then
is far likelier than an IMU sample, due every 10 ms whatever happens. The camera ranks first, told
apart (`evidence.blocked`), not tied with the lidar and the IMU.
"""

from __future__ import annotations

import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _observe, _settle

pytestmark = pytest.mark.ros

CAMERA, LIDAR, IMU = "node:/camera", "node:/lidar", "node:/imu"

# The camera's callback blocks for good once the file given as its argument exists.
CONTAINER = HEAD + """
import threading
from rclpy.executors import SingleThreadedExecutor
trigger = sys.argv[1]
nodes = []
def driver(name, topic, period, blocks=False):
    n = Node(name)
    pub = n.create_publisher(String, topic, 10)
    def tick():
        if blocks and os.path.exists(trigger):
            threading.Event().wait()
        pub.publish(String(data=name))
    n.create_timer(period, tick)
    nodes.append(n)
driver("camera", "/image", 0.5, blocks=True)
driver("lidar", "/scan", 0.1)
driver("imu", "/imu", 0.01)
ex = SingleThreadedExecutor()
for n in nodes:
    ex.add_node(n)
print("ready", flush=True)
ex.spin()
"""


def test_the_callback_that_blocked_a_container_ranks_its_node_first(children, tmp_path):
    trigger = tmp_path / "block"
    children.python(CONTAINER, str(trigger), name="sensors")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {CAMERA, LIDAR, IMU}, "a sensor container")

        t0 = time.time()
        trigger.touch()
        silent: set[str] = set()
        deadline = time.monotonic() + 30.0
        while time.monotonic() < deadline and not {"topic:/image", "topic:/scan", "topic:/imu"} <= silent:
            _observe(mon, 1.0)
            silent = {a.member for a in mon.store.alerts(since=t0) if a.plugin == "topic_rate"}
        assert {"topic:/image", "topic:/scan", "topic:/imu"} <= silent, mon.store.alerts(since=t0)
        _observe(mon, 2.0)
        top = mon.engine.result().root_causes
        assert top and top[0].member == CAMERA, [(rc.member, rc.score, rc.evidence) for rc in top[:3]]
        ev = top[0].evidence
        assert "indistinguishable_from" not in ev and ev["blocked"] > 0.6, ev
        assert {rc.member for rc in top[1:3]} == {LIDAR, IMU}
    finally:
        mon.close()
