"""A crashed container's last words (issue 16 item 2), through the real monitor against real
rclpy nodes in a subprocess.

Three nodes share one process and one executor; the shopper detector logs every 2 s. The gap
detector reloads an empty table (an INFO line) and its next lookup fails: the process aborts,
as a C++ component container does on an exception out of a callback (std::terminate), its nodes
still listed. The crash alert says the gap detector logged last as its process died, and the
RCA ranks it first, alone, where its siblings tied before.
"""

from __future__ import annotations

import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _no_alerts, _observe, _observe_until

pytestmark = pytest.mark.ros

CONTAINER = HEAD + """
from rclpy.executors import SingleThreadedExecutor
flag = sys.argv[1]
gaps, shoppers, labels = Node("gap_detector"), Node("shopper_detector"), Node("label_reader")
facings = [4, 6, 3]
gap_pub = gaps.create_publisher(String, "/gaps", 10)
def look():
    if os.path.exists(flag) and facings:
        facings.clear()
        gaps.get_logger().info("Reloaded planogram (0 bays)")
    if not facings:
        os.abort()  # the lookup's exception out of a C++ callback: std::terminate
    gap_pub.publish(String(data=str(facings[0])))
gaps.create_timer(0.2, look)
shopper_pub = shoppers.create_publisher(String, "/shoppers", 10)
shoppers.create_timer(0.2, lambda: shopper_pub.publish(String(data="none")))
shoppers.create_timer(2.0, lambda: shoppers.get_logger().info("Person track lost"))
label_pub = labels.create_publisher(String, "/labels", 10)
labels.create_timer(0.2, lambda: label_pub.publish(String(data="label")))
ex = SingleThreadedExecutor()
for n in (gaps, shoppers, labels):
    ex.add_node(n)
print("ready", flush=True)
ex.spin()
"""

NODES = ("node:/gap_detector", "node:/shopper_detector", "node:/label_reader")


def test_the_node_that_logged_as_its_container_died_ranks_first(children, tmp_path):
    flag = tmp_path / "planogram"
    children.python(CONTAINER, str(flag), name="perception")
    mon = _monitor(children, tmp_path)
    try:
        deadline = time.monotonic() + 20
        while not set(NODES) <= set(mon.seen) and time.monotonic() < deadline:
            _observe(mon, 1.0)
        _observe(mon, 14.0)
        _no_alerts(mon, "a perception container")
        since = time.time()
        flag.touch()
        alerts = _observe_until(mon, since, lambda found: any(a.plugin == "member_gone" for a in found), 15.0)
        _observe(mon, 4.0)  # its outputs' silences too
        gone = [a for a in mon.store.alerts(since=since)
                if a.plugin == "member_gone" and a.data.get("symptom") == "exit"]
        assert {a.member for a in gone} == set(NODES), alerts
        said = gone[0].data["last_words"]
        assert said["node"] == "node:/gap_detector" and said["text"] == "Reloaded planogram (0 bays)", said
        assert 'its last words, /gap_detector: "Reloaded planogram (0 bays)"' in gone[0].message
        causes = mon.engine.result().root_causes
        assert causes[0].member == "node:/gap_detector", causes[:3]
        assert causes[1].score < causes[0].score, causes[:3]
        assert "indistinguishable_from" not in causes[0].evidence, causes[:3]
    finally:
        mon.close()
