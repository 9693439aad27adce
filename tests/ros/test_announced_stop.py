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

from stream_viz.testing import wait_for
from tests.ros.test_dynamics import (
    CAMERA,
    HEAD,
    _monitor,
    _no_alerts,
    _observe,
    _observe_until,
    _plugin,
    _settle,
)

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
        _settle(mon, {"node:/a_tracker", "node:/b_tracker"}, "two trackers following their targets", 12.0)
        # Both settled (a loaded machine's hiccup may add a short gap to either: it only lengthens
        # the quiet each is judged at); until then a stop is not judged at all.
        rhythms = _plugin(mon, "topic_rate").state["rhythms"]
        settled = lambda: (_observe(mon, 1.0), all(t in rhythms and rhythms[t].settled for t in TOPICS))[1]  # noqa: E731
        wait_for(settled, timeout=30, period=0.0)
        _no_alerts(mon, "two trackers following their targets")
        since = time.time()
        flag.touch()
        silent = lambda found: {a.member for a in found if a.data.get("symptom") == "silence"}  # noqa: E731
        _observe_until(mon, since, silent, 20.0)
        _observe(mon, 5.0)  # the other's quiet judged by then too (its limit a hiccup's gap longer at most)
        after = mon.store.alerts(since=since)
        assert silent(after) == {"topic:/b_tracker/track"}, after
    finally:
        mon.close()
