"""What nodes say of themselves on /diagnostics is part of their healthy dynamics (issue 16 items 1
and 5), through the real monitor against real rclpy nodes in subprocesses.

A camera says ``ERROR waiting for device`` in its first seconds (its bring-up), then captures
only part of the time and says so in its own status (``OK capturing`` / ``OK idle``): its image
topic stops for a new mode it announced. A USBL receiver's fixes stop while the vehicle is on the
surface, its own status OK all along. A lifecycle sonar deactivates itself now and then, its
status updater stopping with it, and an aggregator republishes every status on
/diagnostics_agg, STALE once not heard for 3 s. None of this raises an alert. A PLC bridge
latches a new state each cycle; once its encoder drops out with a WARN each time, that is a
silence, the bridge its cause.
"""

from __future__ import annotations

import time

import pytest

from stream_viz.testing import wait_for
from tests.ros.test_dynamics import HEAD, _monitor, _no_alerts, _observe, _plugin

pytestmark = pytest.mark.ros

DIAG = """
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
def status(name, level, message):
    return DiagnosticStatus(level=bytes([level]), name=name, message=message, hardware_id="")
"""

# 5 Hz while capturing: 14 s capturing, 8 s idle, again; its status says which, ERROR for its
# first 6 s (opening its device).
CAMERA = HEAD + DIAG + """
n = Node("camera")
pub = n.create_publisher(String, "/image", 10)
diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
t0 = time.monotonic()
def capturing():
    t = time.monotonic() - t0
    return t >= 6.0 and (t - 6.0) % 22.0 < 14.0
def tick():
    if capturing():
        pub.publish(String(data="frame"))
def report():
    t = time.monotonic() - t0
    st = status("camera: camera_status", 2, "waiting for device") if t < 6.0 else \\
        status("camera: camera_status", 0, "capturing" if capturing() else "idle")
    diag.publish(DiagnosticArray(status=[st]))
n.create_timer(0.2, tick)
n.create_timer(1.0, report)
print("ready", flush=True)
rclpy.spin(n)
"""

# A lifecycle sonar: its pings and its own status while active; active 14 s, inactive 10 s.
SONAR = HEAD + DIAG + """
from rclpy.lifecycle import LifecycleNode
n = LifecycleNode("sonar")
pub = n.create_lifecycle_publisher(String, "/pings", 10)
diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
n.trigger_configure()
n.trigger_activate()
t0, active = time.monotonic(), True
def cycle():
    global active
    want = (time.monotonic() - t0) % 24.0 < 14.0
    if want != active:
        active = want
        (n.trigger_activate if want else n.trigger_deactivate)()
def report():
    if active:
        diag.publish(DiagnosticArray(status=[status("sonar: head", 0, "pinging")]))
n.create_timer(0.2, lambda: pub.publish(String(data="ping")))
n.create_timer(0.1, cycle)
n.create_timer(1.0, report)
print("ready", flush=True)
rclpy.spin(n)
"""

# A USBL receiver: fixes at 2 Hz while the vehicle is deep (14 s), none while it is on the surface
# (10 s), and its own status OK each second throughout: its quiet is its state, said by no mode.
USBL = HEAD + DIAG + """
n = Node("usbl")
pub = n.create_publisher(String, "/usbl_fix", 10)
diag = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
t0, fixes = time.monotonic(), [0]
def fix():
    if (time.monotonic() - t0) % 24.0 < 14.0:
        pub.publish(String(data="fix"))
        fixes[0] += 1
n.create_timer(0.5, fix)
def report():
    diag.publish(DiagnosticArray(status=[status("usbl: link", 0, f"{fixes[0]} fixes")]))
n.create_timer(1.0, report)
print("ready", flush=True)
rclpy.spin(n)
"""

# An aggregator: every status it heard, under /robot/, each second; STALE once not heard for 3 s.
AGGREGATOR = HEAD + DIAG + """
n = Node("aggregator")
out = n.create_publisher(DiagnosticArray, "/diagnostics_agg", 10)
heard = {}
def hear(msg):
    for st in msg.status:
        heard[st.name] = (time.monotonic(), st)
n.create_subscription(DiagnosticArray, "/diagnostics", hear, 10)
def publish():
    now, arr = time.monotonic(), DiagnosticArray()
    for name, (t, st) in sorted(heard.items()):
        stale = now - t > 3.0
        if stale:
            print("stale", name, flush=True)
        level, message = (3, "Stale") if stale else (st.level[0], st.message)
        arr.status.append(status("/robot/" + name, level, message))
    out.publish(arr)
n.create_timer(1.0, publish)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_what_nodes_say_of_their_modes_and_bring_up_raises_no_alert(children, tmp_path):
    children.python(CAMERA, name="camera")
    children.python(SONAR, name="sonar")
    children.python(USBL, name="usbl")
    aggregator = children.python(AGGREGATOR, name="aggregator")
    mon = _monitor(children, tmp_path)
    sample, seen = mon.collector.sample, []
    mon.collector.sample = lambda: (s := sample(), seen.extend(s.events))[0]  # the events it read
    try:
        wait_for(lambda: (mon.step(), {"node:/camera", "node:/sonar"} <= set(mon.seen))[1],
                 timeout=20, period=1.0)
        _observe(mon, 42.0)  # the camera idle once (from ~20 s), the sonar inactive once (~14-24 s)
        diags = [e for e in seen if e.kind == "diag"]
        assert any(e.member == "node:/camera" and e.data["level"] == 2 for e in diags), "no bring-up ERROR"
        assert any(e.member == "node:/sonar" and e.data["level"] == 3 for e in diags), "no STALE seen"
        log = (tmp_path / f"aggregator_{children.procs.index(aggregator)}.log").read_text()
        assert "stale sonar: head" in log
        _no_alerts(mon, "a camera's bring-up and modes, a sonar deactivated, a USBL on the surface")
        # The USBL's OK, its own, was heard after its fixes stopped (from ~14 s).
        assert _plugin(mon, "topic_rate").state["self_reports"]["node:/usbl"][0] > 20.0 + mon.started_at
        # The camera's idle was seen as its change of state; the sonar's STALE as its transition's.
        assert _plugin(mon, "topic_rate").state["transitions"].get("node:/camera"), "no mode change seen"
        assert "node:/sonar" in _plugin(mon, "diagnostics").state["transitions"]
    finally:
        mon.close()


# A PLC bridge: the belt encoder at 20 Hz, and parts present latched each 11 s (a new state each
# cycle: 10 s or more after the last). Once the file argv[1] exists, the encoder drops out for 2 s
# as each part arrives, with a WARN each time, as a chafed cable does.
BRIDGE = HEAD + """
n = Node("plc_bridge")
enc = n.create_publisher(String, "/encoder", 10)
parts = n.create_publisher(String, "/parts_present", LATCHED_QOS)
t0, out_until, k = time.monotonic(), [0.0], [0]
def tick():
    if time.monotonic() >= out_until[0]:
        enc.publish(String(data="counts"))
def part():
    k[0] += 1
    parts.publish(String(data=str(k[0] % 2)))
    if os.path.exists(sys.argv[1]):
        out_until[0] = time.monotonic() + 2.0
        n.get_logger().warn("Encoder signal lost: no counts from the belt encoder")
n.create_timer(0.05, tick)
n.create_timer(11.0, part)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_dropout_its_node_complains_of_is_no_change_of_state(children, tmp_path):
    flaky = tmp_path / "flaky"
    children.python(BRIDGE, str(flaky), name="bridge")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/plc_bridge" in mon.seen)[1], timeout=20, period=1.0)
        _observe(mon, 24.0)
        _no_alerts(mon, "a PLC bridge latching a new state each cycle")
        flaky.touch()
        found = []
        deadline = time.monotonic() + 26.0  # two parts arrive, each with a dropout
        while not found and time.monotonic() < deadline:
            _observe(mon, 1.0)
            found = [a for a in mon.store.alerts() if a.member == "topic:/encoder"]
        assert found, mon.store.alerts()
    finally:
        report = mon.close()
    assert report["root_causes"][0]["member"] == "node:/plc_bridge", report["root_causes"][:3]
