"""An output its node says it stopped (issue 16 item 1), through the real monitor against real
rclpy nodes in subprocesses.

Two trackers share one multi-threaded container, whose busy threads say nothing of one node.
Each publishes its track at 10 Hz while a target is in view: from its start, long enough to
settle the topic as continuous, then not for 10 s. The first logs "Track 1 lost" as its
target leaves, as trackers and collision avoiders do; the second stops without a word, which
a hang in that container looks like too. Only the second's quiet is a silence.
"""

from __future__ import annotations

import time

import pytest

from tests.ros.test_dynamics import CAMERA, HEAD, _monitor, _observe, _plugin, _settle

pytestmark = pytest.mark.ros

TRACKERS = HEAD + """
from rclpy.executors import MultiThreadedExecutor
flag = sys.argv[1]
def tracker(name, says):
    n = Node(name)
    pub = n.create_publisher(String, "/" + name + "/track", 10)
    st = {"on": True}
    def frame(msg):
        on = not os.path.exists(flag)
        if st["on"] and not on and says:
            n.get_logger().info("Track 1 lost")
        st["on"] = on
        if on:
            pub.publish(String(data="target"))
    n.create_subscription(String, "/image", frame, 10)
    return n
ex = MultiThreadedExecutor()
for n in (tracker("a_tracker", True), tracker("b_tracker", False)):
    ex.add_node(n)
print("ready", flush=True)
ex.spin()
"""

TOPICS = ("topic:/a_tracker/track", "topic:/b_tracker/track")


def test_a_stop_its_node_logged_is_no_silence_and_a_silent_one_is(children, tmp_path):
    flag = tmp_path / "gone"
    children.python(CAMERA, name="camera")
    children.python(TRACKERS, str(flag), name="trackers")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {"node:/a_tracker", "node:/b_tracker"}, "two trackers following their targets", 16.0)
        rhythms = _plugin(mon, "topic_rate").state["rhythms"]
        # both settled as continuous: a quiet is judged at its base limit, not at its own gaps
        assert all(rhythms[t].settled and not rhythms[t].gaps for t in TOPICS), [rhythms[t] for t in TOPICS]
        since = time.time()
        flag.touch()
        _observe(mon, 10.0)
        silent = {a.member for a in mon.store.alerts(since=since) if a.data.get("symptom") == "silence"}
        assert silent == {"topic:/b_tracker/track"}, mon.store.alerts(since=since)
    finally:
        mon.close()
