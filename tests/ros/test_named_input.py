"""A node's ERROR that names the node it reads from points at that node (issue 16 item 3),
through the real monitor against real rclpy nodes in subprocesses.

A localiser (a lifecycle node) publishes its pose at 5 Hz; a controller reads it and, when the
pose is stale, logs "Robot pose is … s old (localizer)". The localiser deactivates itself (a
misread configuration): its silence follows a lifecycle transition, which alone would be healthy
dynamics. The controller's ERRORs name the localiser, which the controller reads from: its alert
says so (data ``names``), the silence its reader complains of is a symptom after all (its alert
quotes the controller), and the localiser is ranked first, not the controller that complained.
"""

from __future__ import annotations

import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _observe, _observe_until, _settle

pytestmark = pytest.mark.ros

# Deactivates itself once the file given as its argument exists.
LOCALIZER = HEAD + """
from rclpy.lifecycle import LifecycleNode
trigger = sys.argv[1]
n = LifecycleNode("localizer")
pub = n.create_lifecycle_publisher(String, "/pose", 10)
n.create_timer(0.2, lambda: pub.publish(String(data="pose")))
n.trigger_configure()
n.trigger_activate()
done = []
def watch():
    if not done and os.path.exists(trigger):
        done.append(1)
        n.get_logger().info("laser model parameters invalid: deactivating")
        n.trigger_deactivate()
n.create_timer(0.1, watch)
print("ready", flush=True)
rclpy.spin(n)
"""

CONTROLLER = HEAD + """
n = Node("controller")
last = [None, 0.0]
def pose(msg):
    last[0] = time.monotonic()
n.create_subscription(String, "/pose", pose, 10)
def control():
    now = time.monotonic()
    if last[0] is not None and now - last[0] > 1.5 and now - last[1] > 2.0:
        last[1] = now
        n.get_logger().error(f"Robot pose is {now - last[0]:.1f} s old (localizer): localization lost")
n.create_timer(0.1, control)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_an_error_naming_the_node_it_reads_from_ranks_that_node_first(children, tmp_path):
    trigger = tmp_path / "deactivate"
    children.python(LOCALIZER, str(trigger), name="localizer")
    children.python(CONTROLLER, name="controller")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {"node:/localizer", "node:/controller"}, "a localiser and its controller")

        t0 = time.time()
        trigger.touch()
        _observe_until(mon, t0, bool, 20.0)
        _observe(mon, 3.0)
        after = mon.store.alerts(since=t0)
        assert after, "the controller's ERRORs raised nothing"
        assert {a.member for a in after} == {"node:/controller", "topic:/pose"}, after
        said = [a for a in after if a.member == "node:/controller"]
        assert all(a.data.get("names") == ["node:/localizer"] for a in said), [a.data for a in said]
        quiet = [a for a in after if a.member == "topic:/pose"]
        assert all("/controller, which reads it, complains" in a.message for a in quiet), quiet
        top = mon.engine.result().root_causes
        assert top and top[0].member == "node:/localizer", top[:3]
    finally:
        mon.close()
