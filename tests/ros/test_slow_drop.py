"""A steady stream that loses one message in three (issue 16 item 11), through the real monitor
against a real rclpy node in a subprocess.

An IMU relay publishes at 50 Hz; told to, it sends two messages of every three (the flight
controller denied the interval it asked for), 33 Hz: above half its rate, which the deep drop
asks, far below its own spread. Held 10 s, that is a slow drop of its topic, and the RCA ranks
the relay first.
"""

from __future__ import annotations

import time

import pytest

from tests.ros.test_dynamics import HEAD, _monitor, _no_alerts, _observe, _observe_until

pytestmark = pytest.mark.ros

RELAY = HEAD + """
flag = sys.argv[1]
n = Node("imu_relay")
pub = n.create_publisher(String, "/imu", 10)
count = [0]
def tick():
    count[0] += 1
    if os.path.exists(flag) and count[0] % 3 == 0:
        return  # the stream at two thirds of its interval
    pub.publish(String(data="imu"))
n.create_timer(0.02, tick)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_steady_topic_at_two_thirds_of_its_rate_is_a_slow_drop(children, tmp_path):
    flag = tmp_path / "denied"
    children.python(RELAY, str(flag), name="relay")
    mon = _monitor(children, tmp_path)
    try:
        deadline = time.monotonic() + 20
        while "node:/imu_relay" not in mon.seen and time.monotonic() < deadline:
            _observe(mon, 1.0)
        _observe(mon, 20.0)
        _no_alerts(mon, "a 50 Hz relay")
        since = time.time()
        flag.touch()
        alerts = _observe_until(mon, since, lambda found: any(a.member == "topic:/imu" for a in found), 25.0)
        drops = [a for a in alerts if a.member == "topic:/imu"]
        assert drops and drops[0].data.get("symptom") == "rate_drop", alerts
        assert drops[0].t - since >= 10.0, (drops[0].t - since, drops[0].message)  # held slow_drop_s
        assert 28.0 < drops[0].data["rate_hz"] < 38.0, drops[0].message
        causes = mon.engine.result().root_causes
        assert causes[0].member == "node:/imu_relay", causes[:3]
    finally:
        mon.close()
