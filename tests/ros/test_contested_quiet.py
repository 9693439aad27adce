"""A quiet its publisher's change of state explains is healthy until a node that reads the topic
complains of it (issue 16 items 1 and 3), through the real monitor against real rclpy nodes in
subprocesses.

A lidar (a lifecycle node) publishes ``/scan`` at 10 Hz; a row follower reads it and, while it
drives, WARNs "No scan on /scan for N s" when the scan stops. Deactivated while the follower
stands (a planned deactivation), the quiet is the lidar's state: no alert. Deactivated again
while it drives (someone typed ``ros2 lifecycle set`` on the wrong terminal), the same transition
comes with its reader's complaint: the quiet is a silence, the alert quotes the reader, and the
lidar is ranked first.
"""

from __future__ import annotations

import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _no_alerts, _observe, _observe_until, _settle

pytestmark = pytest.mark.ros

# Inactive while the file given as its argument exists, active otherwise.
LIDAR = HEAD + """
from rclpy.lifecycle import LifecycleNode
off = sys.argv[1]
n = LifecycleNode("lidar")
pub = n.create_lifecycle_publisher(String, "/scan", 10)
n.create_timer(0.1, lambda: pub.publish(String(data="scan")))
n.trigger_configure()
n.trigger_activate()
active = [True]
def watch():
    want = not os.path.exists(off)
    if want != active[0]:
        active[0] = want
        n.get_logger().info("Laser emission " + ("on" if want else "off (standby)"))
        (n.trigger_activate if want else n.trigger_deactivate)()
n.create_timer(0.1, watch)
print("ready", flush=True)
rclpy.spin(n)
"""

# Complains of a missing scan only while the file given as its argument exists (it drives).
FOLLOWER = HEAD + """
driving = sys.argv[1]
n = Node("row_follower")
last = [time.monotonic(), 0.0]
def scan(msg):
    last[0] = time.monotonic()
n.create_subscription(String, "/scan", scan, 10)
def follow():
    now = time.monotonic()
    if os.path.exists(driving) and now - last[0] > 2.0 and now - last[1] > 3.0:
        last[1] = now
        n.get_logger().warn(f"No scan on /scan for {now - last[0]:.1f} s: speed limited to 0.25 m/s")
n.create_timer(0.1, follow)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_deactivation_its_reader_complains_of_is_a_silence_of_the_deactivated_node(children, tmp_path):
    off, driving = tmp_path / "off", tmp_path / "driving"
    children.python(LIDAR, str(off), name="lidar")
    children.python(FOLLOWER, str(driving), name="follower")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {"node:/lidar", "node:/row_follower", "topic:/scan"}, "a lidar and its reader")

        off.touch()  # planned: the follower stands, says nothing
        _observe(mon, 8.0)
        off.unlink()
        _observe(mon, 4.0)
        _no_alerts(mon, "a deactivation nobody complained of")

        driving.touch()
        _observe(mon, 3.0)
        t0 = time.time()
        off.touch()  # by hand, while it drives

        def silence(alerts):
            return [a for a in alerts if a.member == "topic:/scan" and a.data.get("symptom") == "silence"]

        found = silence(_observe_until(mon, t0, silence, 20.0))
        assert found, f"no silence of /scan: {mon.store.alerts(since=t0)}"
        said = "/row_follower, which reads it, complains: No scan on /scan"
        assert said in found[0].message, found[0].message
        top = mon.engine.result().root_causes
        assert top and top[0].member == "node:/lidar", top[:3]
    finally:
        mon.close()
