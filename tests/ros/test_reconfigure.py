"""A node reconfigured at run time has a new normal (issue 16 item 1: parameter changes), through
the real monitor against real rclpy nodes in subprocesses.

A camera whose frame rate is a parameter is slowed from 10 Hz to 4 Hz, then to 0.5 Hz, by a
tuner (as a roboticist does with ``ros2 param set``); a relay forwards every frame. Neither the
camera's topic nor the relay's raises an alert: each learns its new rate. Then the camera drops
frames without any parameter change (a real degrade): that is still a rate drop.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from stream_viz.config import load_config
from stream_viz.monitor import Monitor
from stream_viz.progress import Progress
from stream_viz.testing import wait_for
from stream_viz.viz import paths
from tests.ros.test_dynamics import CONFIG, HEAD, _no_alerts, _observe, _plugin
from tests.viz.rrd import rows

pytestmark = pytest.mark.ros

# A camera whose rate is its parameter rate_hz (applied at once, as drivers do); SIGUSR1 makes it
# drop 3 of every 4 frames (a fault: no parameter changes).
CAMERA = HEAD + """
from rcl_interfaces.msg import SetParametersResult
n = Node("camera")
n.declare_parameter("rate_hz", 10.0)
n.declare_parameter("exposure", 0.01)
pub = n.create_publisher(String, "/image", 10)
count, lossy = [0], [False]
def tick():
    count[0] += 1
    if not lossy[0] or count[0] % 4 == 0:
        pub.publish(String(data="frame"))
timer = [n.create_timer(0.1, tick)]
def on_set(params):
    for p in params:
        if p.name == "rate_hz":
            timer[0].cancel()
            n.destroy_timer(timer[0])
            timer[0] = n.create_timer(1.0 / p.value, tick)
    return SetParametersResult(successful=True)
n.add_on_set_parameters_callback(on_set)
signal_ = __import__("signal")
signal_.signal(signal_.SIGUSR1, lambda *a: lossy.__setitem__(0, True))
print("ready", flush=True)
rclpy.spin(n)
"""

RELAY = HEAD + """
n = Node("relay")
pub = n.create_publisher(String, "/image_relayed", 10)
n.create_subscription(String, "/image", pub.publish, 10)
sink = Node("viewer")
sink.create_subscription(String, "/image_relayed", lambda m: None, 10)
from rclpy.executors import SingleThreadedExecutor
ex = SingleThreadedExecutor()
ex.add_node(n)
ex.add_node(sink)
print("ready", flush=True)
ex.spin()
"""

# Sets /camera's parameters at the times (s after its services are ready) given as name=value@t.
TUNER = HEAD + """
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
n = Node("tuner")
client = AsyncParameterClient(n, "/camera")
plan = [(float(a.split("@")[1]), a.split("=")[0], float(a.split("=")[1].split("@")[0])) for a in sys.argv[1:]]
t0 = []
def tune():
    if not t0:
        if client.services_are_ready():
            t0.append(time.monotonic())
        return
    while plan and time.monotonic() - t0[0] >= plan[0][0]:
        _, name, value = plan.pop(0)
        client.set_parameters([Parameter(name, value=value)])
        print("set", name, value, flush=True)
n.create_timer(0.1, tune)
rclpy.spin(n)
"""


def test_a_node_reconfigured_to_a_slower_rate_is_its_new_normal_and_a_degrade_is_not(children, tmp_path):
    camera = children.python(CAMERA, name="camera")
    children.python(RELAY, name="relay")
    cfg = tmp_path / "stream-viz.toml"
    cfg.write_text(CONFIG)
    mon = Monitor(load_config(cfg), db=tmp_path / "alerts.sqlite", viewer="none", save=tmp_path / "run.rrd",
                  domain_id=int(children.env["ROS_DOMAIN_ID"]), progress=Progress(open(os.devnull, "w")))
    try:
        wait_for(lambda: (mon.step(), {"node:/camera", "node:/relay"} <= set(mon.seen))[1],
                 timeout=20, period=1.0)
        # exposure changes nothing observable; rate_hz 10 -> 4 -> 0.5 -> 10 Hz
        tuner = children.python(TUNER, "exposure=0.02@5", "rate_hz=4.0@16", "rate_hz=0.5@36",
                                "rate_hz=10.0@60", name="tuner")
        _observe(mon, 90.0)
        log = (tmp_path / f"tuner_{children.procs.index(tuner)}.log").read_text()
        assert "set rate_hz 10.0" in log, log
        _no_alerts(mon, "a camera reconfigured from 10 Hz to 4 Hz, 0.5 Hz and back")
        state = _plugin(mon, "topic_rate").state
        # Both topics learned anew, the relay's from its input's change; back at 10 Hz, continuous.
        assert {"topic:/image", "topic:/image_relayed"} <= set(state["relearn"]), state["relearn"]
        image = state["rhythms"]["topic:/image"]
        assert image.settled and not image.gaps and image.rate > 8.0, image

        # A real degrade, no parameter changed: a rate drop of the camera's topic.
        t_fault = time.time()
        os.kill(camera.pid, signal.SIGUSR1)
        _observe(mon, 15.0)
        drops = [a for a in mon.store.alerts() if a.t > t_fault and a.data.get("symptom") == "rate_drop"]
        assert "topic:/image" in {a.member for a in drops}, mon.store.alerts()
    finally:
        mon.close()
    # The recording shows each change on the timeline, in the alerts' log panel.
    changes = [row["TextLog:text"][0] for row in rows(tmp_path / "run.rrd")[paths.CHANGES]]
    assert [c for c in changes if "rate_hz" in c] == [
        f"[param] node:/camera: parameter of /camera: rate_hz = {v}" for v in ("4.0", "0.5", "10.0")]
    assert "[param] node:/camera: parameter of /camera: exposure = 0.02" in changes
