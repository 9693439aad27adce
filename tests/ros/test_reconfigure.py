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
from stream_viz.model.theta import SCHEMAS
from stream_viz.monitor import Monitor
from stream_viz.progress import Progress
from stream_viz.testing import wait_for
from stream_viz.viz import paths
from tests.ros.test_dynamics import CONFIG, HEAD, _monitor, _no_alerts, _observe, _plugin, _settle
from tests.viz.rrd import rows

pytestmark = pytest.mark.ros

def _serve(fault: str) -> str:
    """The end of a child script: its parameter callback set, SIGUSR1 sets the flag list
    ``fault`` (the fault, no parameter changed), then spin."""
    return f"""
n.add_on_set_parameters_callback(on_set)
signal_ = __import__("signal")
signal_.signal(signal_.SIGUSR1, lambda *a: {fault}.__setitem__(0, True))
print("ready", flush=True)
rclpy.spin(n)
"""


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
""" + _serve("lossy")

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
        # exposure changes nothing observable; rate_hz 10 -> 4 -> 0.5 -> 10 Hz, set to 4 twice
        tuner = children.python(TUNER, "exposure=0.02@5", "rate_hz=4.0@16", "rate_hz=4.0@26",
                                "rate_hz=0.5@36", "rate_hz=10.0@60", name="tuner")
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
    # The recording shows each change on the timeline, in the alerts' log panel; a value set to
    # what it was (4.0 at 26 s) is no change.
    changes = [row["TextLog:text"][0] for row in rows(tmp_path / "run.rrd")[paths.CHANGES]]
    assert [c for c in changes if "rate_hz" in c] == [
        f"[param] node:/camera: parameter of /camera: rate_hz = {v}" for v in ("4.0", "0.5", "10.0")]
    assert "[param] node:/camera: parameter of /camera: exposure = 0.02" in changes


# An encoder whose CPU follows its parameter quality (a share of each 0.1 s tick spent working);
# SIGUSR1 makes it spin a full core (a fault: no parameter changes).
ENCODER = HEAD + """
from rcl_interfaces.msg import SetParametersResult
n = Node("camera")
n.declare_parameter("quality", 0.0)
pub = n.create_publisher(String, "/image", 10)
share, hog = [0.0], [False]
def tick():
    end = time.thread_time() + (0.1 if hog[0] else share[0] * 0.1)  # CPU burned, however loaded
    while time.thread_time() < end:
        pass
    pub.publish(String(data="frame"))
n.create_timer(0.1, tick)
def on_set(params):
    for p in params:
        if p.name == "quality":
            share[0] = p.value
    return SetParametersResult(successful=True)
""" + _serve("hog")


def test_a_node_tuned_to_use_more_cpu_is_its_new_normal_and_a_hog_is_not(children, tmp_path):
    encoder = children.python(ENCODER, name="encoder")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/camera" in mon.seen)[1], timeout=20, period=1.0)
        # quality 0 -> 0.4 after the CPU baseline is learnt: ~2 % -> ~40 % of a core, for good
        children.python(TUNER, "quality=0.4@15", name="tuner")
        _observe(mon, 40.0)
        pid = mon.seen.nodes["node:/camera"]["pid"]
        cpu = mon.shadow.history.values(f"process:{pid}", last=5)[:, SCHEMAS["process"].index("cpu_percent")]
        assert min(cpu) > 25.0, cpu  # the change took effect
        _no_alerts(mon, "an encoder tuned to a higher quality")
        assert (f"process:{pid}", "cpu_percent") in _plugin(mon, "process_resources").state["_relearn"]

        t_fault = time.time()
        os.kill(encoder.pid, signal.SIGUSR1)  # a full core, no parameter changed: a CPU rise
        _observe(mon, 12.0)
        cpu_alerts = [a for a in mon.store.alerts() if a.t > t_fault and a.plugin == "process_resources"]
        assert "node:/camera" in {a.member for a in cpu_alerts}, mon.store.alerts()
    finally:
        mon.close()


# A camera working ~3 % of a core in its callback; SIGUSR1: its exposure is set (a parameter event,
# as from `ros2 param set`), and 1 s later a runaway worker thread burns a core beside its executor.
RUNAWAY = HEAD + """
import hashlib, threading
from rclpy.parameter import Parameter
n = Node("camera")
n.declare_parameter("exposure", 0.01)
pub = n.create_publisher(String, "/image", 10)
flag, step = [False], [0]
def burn():
    buf = b"x" * 2**20
    while True:
        hashlib.sha256(buf).digest()  # releases the GIL: the executor goes on
def tick():
    end = time.thread_time() + 0.003
    while time.thread_time() < end:
        pass
    pub.publish(String(data="frame"))
    if flag[0]:
        step[0] += 1
        if step[0] == 1:
            n.set_parameters([Parameter("exposure", value=0.02)])
        elif step[0] == 10:
            threading.Thread(target=burn, daemon=True).start()
n.create_timer(0.1, tick)
signal_ = __import__("signal")
signal_.signal(signal_.SIGUSR1, lambda *a: flag.__setitem__(0, True))
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_cpu_rise_beside_the_executor_is_no_parameter_change_s(children, tmp_path):
    # A parameter takes effect in the node's callbacks: a rise on another thread, a second after
    # a change, is a hog (the rule's unit test: test_plugins.py).
    camera = children.python(RUNAWAY, name="camera")
    mon = _monitor(children, tmp_path)
    try:
        _settle(mon, {"node:/camera"}, "a camera at work")  # the CPU baseline learnt
        sample, seen = mon.collector.sample, []
        mon.collector.sample = lambda: (s := sample(), seen.extend(s.events))[0]  # the events it read
        t_fault = time.time()
        os.kill(camera.pid, signal.SIGUSR1)
        _observe(mon, 12.0)
        pid = mon.seen.nodes["node:/camera"]["pid"]
        executor = mon.shadow.history.values(f"process:{pid}", last=5)[:, SCHEMAS["process"].index(
            "executor_cpu_percent")]
        assert max(executor) < 25.0, executor  # the rise was beside the executor
        assert any(e.kind == "param" and e.member == "node:/camera" for e in seen), seen
        cpu_alerts = [a for a in mon.store.alerts() if a.t > t_fault and a.plugin == "process_resources"]
        assert "node:/camera" in {a.member for a in cpu_alerts}, mon.store.alerts()
    finally:
        mon.close()
