"""Cameras on one trigger and the synchronizer that matches them (issue 16 items 1 and 4),
through the real monitor against real rclpy nodes in subprocesses.

Three cameras in one process stamp each 5 Hz frame with the trigger's time; a stitcher in
another process publishes a panorama for each set whose stamps are equal, and WARNs when it
drops unmatched ones. The right camera's trigger is lost (its stamps 41 ms later): every camera
goes on at 5 Hz, the panorama stops. The monitor says the right camera's stamps left its group
and ranks that camera first, not the stitcher whose output stopped.
"""

from __future__ import annotations

import time

import pytest

from stream_viz.testing import wait_for
from tests.ros.test_dynamics import HEAD, _monitor, _observe, _observe_until, _settle

pytestmark = pytest.mark.ros

CAMERAS = HEAD + """
import math
import rclpy.executors
from sensor_msgs.msg import Image
from builtin_interfaces.msg import Time
trigger = sys.argv[1]
qos = rclpy.qos.qos_profile_sensor_data
nodes, pubs = [], []
for side in ("left", "center", "right"):
    n = Node(side)
    nodes.append(n)
    pubs.append(n.create_publisher(Image, f"/{side}/image_raw", qos))
def grab():
    edge = math.floor(time.time() / 0.2) * 0.2
    for side, pub in zip(("left", "center", "right"), pubs):
        t = edge + (0.041 if side == "right" and os.path.exists(trigger) else 0.0)
        m = Image(height=1, width=4, encoding="mono8", step=4, data=bytes(4))
        m.header.stamp = Time(sec=int(t), nanosec=int(round((t - int(t)) * 1e9)))
        pub.publish(m)
nodes[0].create_timer(0.2, grab)
ex = rclpy.executors.SingleThreadedExecutor()
for n in nodes:
    ex.add_node(n)
print("ready", flush=True)
ex.spin()
"""

STITCHER = HEAD + """
from sensor_msgs.msg import Image
n = Node("stitcher")
pub = n.create_publisher(Image, "/panorama", 10)
sets, last_warn = {}, [0.0]
def cb(side):
    def take(m):
        key = (m.header.stamp.sec, m.header.stamp.nanosec)
        got = sets.setdefault(key, {})
        got[side] = m
        if len(got) == 3:
            pub.publish(Image(header=m.header, height=1, width=12, encoding="mono8", step=12, data=bytes(12)))
            del sets[key]
        for k in [k for k in sets if k[0] < m.header.stamp.sec - 1]:
            del sets[k]
            if time.monotonic() - last_warn[0] > 5.0:
                last_warn[0] = time.monotonic()
                n.get_logger().warn("Dropped unmatched images: no set within slop 0.015 s")
    return take
for side in ("left", "center", "right"):
    n.create_subscription(Image, f"/{side}/image_raw", cb(side), rclpy.qos.qos_profile_sensor_data)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_camera_whose_stamps_leave_its_trigger_group_is_ranked_first(children, tmp_path):
    trigger = tmp_path / "drift"
    children.python(CAMERAS, str(trigger), name="cameras")
    children.python(STITCHER, name="stitcher")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {"node:/right", "node:/stitcher"}, "three triggered cameras and a stitcher")

        t0 = time.time()
        trigger.touch()
        _observe_until(mon, t0, lambda alerts: any(a.data.get("symptom") == "desync" for a in alerts), 20.0)
        _observe(mon, 3.0)
        after = mon.store.alerts(since=t0)
        desync = {a.member for a in after if a.data.get("symptom") == "desync"}
        assert desync == {"topic:/right/image_raw"}, [(a.member, a.message) for a in after]
        top = mon.engine.result().root_causes
        assert top and top[0].member == "node:/right", [(c.member, c.score) for c in top[:3]]
    finally:
        mon.close()


# A ros2_control-like loop at 50 Hz stamps what it publishes with its cycle's time: the joint
# states every other cycle, an arm controller's state every other cycle from its trajectory's
# start, only during a trajectory (3 s, then 2 s idle; every other one starts an odd cycle).
ARM = HEAD + """
import threading
from sensor_msgs.msg import JointState
from builtin_interfaces.msg import Time
from std_msgs.msg import Header
n = Node("controller_manager")
joints = n.create_publisher(JointState, "/joint_states", 10)
state = n.create_publisher(JointState, "/arm_controller/controller_state", 10)
def stamped(t):
    stamp = Time(sec=int(t), nanosec=int((t - int(t)) * 1e9))
    return JointState(header=Header(stamp=stamp), name=["a"], position=[0.0])
def loop():
    cycle, start = 0, None
    while rclpy.ok():
        t = time.time()
        cycle += 1
        if cycle % 2 == 0:
            joints.publish(stamped(t))
        phase = (cycle // 50) % 5  # seconds of the 5 s period: moving in the first 3
        if phase < 3 and (start is not None or cycle % 2 == (cycle // 250) % 2):
            start = cycle if start is None else start
            if (cycle - start) % 2 == 0:
                state.publish(stamped(t))
        elif phase >= 3:
            start = None
        time.sleep(max(0.0, 0.02 - (time.time() - t)))
threading.Thread(target=loop, daemon=True).start()
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_burst_on_other_ticks_of_a_shared_loop_is_no_desync(children, tmp_path):
    children.python(ARM, name="arm")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/controller_manager" in mon.seen)[1], timeout=20, period=1.0)
        shares = []  # the arm state's share of the joint states' stamps, a sample at a time
        end = time.monotonic() + 40.0
        while time.monotonic() < end:
            _observe(mon, 1.0)
            got = mon.seen.nodes["topic:/joint_states"].get("stamp_partners") or {}
            shares.append(got.get("topic:/arm_controller/controller_state"))
        # They shared their stamps in some bursts and none in others ...
        assert any(x is not None and x >= 0.8 for x in shares), shares
        assert any(x is not None and x <= 0.1 for x in shares), shares
        # ... and neither is out of sync for it.
        assert [a for a in mon.store.alerts() if a.data.get("symptom") == "desync"] == [], mon.store.alerts()
    finally:
        mon.close()
