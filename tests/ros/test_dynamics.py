"""Healthy dynamics are no fault, departures from them are (issue 16 items 1, 7, 9), through the
real monitor against real rclpy nodes in subprocesses.

A healthy system full of dynamics (a topic published in bursts, a latched topic published once,
a lifecycle node that deactivates and activates again, a job that ends with exit code 0, a
parameter changed every few seconds, a console that joins late) raises no alert; then the bursty
topic's publisher hangs for longer than its own gaps, and that is a silence. A relay of a
deactivated lifecycle publisher stops with its input (the input's quiet, no alert); the relay's
own hang is a silence. A detector that publishes only while its target is in view is quiet while
it goes on working (no alert); its deadlock is a silence, and so is a driver's output whose
reader thread died while its node goes on. A node started four times under one name is one
symptom of that node.
"""

from __future__ import annotations

import os
import signal
import time

import pytest

from stream_viz.config import load_config
from stream_viz.detect.store import AlertStore
from stream_viz.model.queries import process_of_node
from stream_viz.model.theta import SCHEMAS
from stream_viz.monitor import Monitor
from stream_viz.progress import Progress
from stream_viz.testing import wait_for

pytestmark = pytest.mark.ros

CONFIG = """
[monitor]
period = 1.0

[watchlist]
mode = "all"
"""

# Every child below starts with this.
HEAD = """
import os, sys, time, rclpy
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
rclpy.init()
LATCHED_QOS = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
"""

# 10 Hz for 2 s, then nothing for 5 s, again and again; its parameter is changed from outside.
BURSTS = HEAD + """
n = Node("detector")
n.declare_parameter("threshold", 0.5)
pub = n.create_publisher(String, "/detections", 10)
t0 = time.monotonic()
def tick():
    if (time.monotonic() - t0) % 7.0 < 2.0:
        pub.publish(String(data="pallet"))
n.create_timer(0.1, tick)
print("ready", flush=True)
rclpy.spin(n)
"""

# Published once (when the first subscriber, the monitor, is there), kept for late joiners.
LATCHED = HEAD + """
n = Node("map_server")
pub = n.create_publisher(String, "/map", LATCHED_QOS)
sent = []
def once():
    if not sent and pub.get_subscription_count():
        pub.publish(String(data="map"))
        sent.append(1)
n.create_timer(0.5, once)
print("ready", flush=True)
rclpy.spin(n)
"""

# A lifecycle node: its publisher is silent while inactive. Arguments: node name, topic, period
# (s), then active for ON s and inactive for OFF s, again and again.
LIFECYCLE = HEAD + """
from rclpy.lifecycle import LifecycleNode
name, topic, period, on, off = sys.argv[1], sys.argv[2], *map(float, sys.argv[3:6])
n = LifecycleNode(name)
pub = n.create_lifecycle_publisher(String, topic, 10)
n.create_timer(period, lambda: pub.publish(String(data="pose")))
n.trigger_configure()
n.trigger_activate()
t0, active = time.monotonic(), True
def cycle():
    global active
    want = (time.monotonic() - t0) % (on + off) < on
    if want != active:
        active = want
        (n.trigger_activate if want else n.trigger_deactivate)()
n.create_timer(0.1, cycle)
print("ready", flush=True)
rclpy.spin(n)
"""

# A one-shot job: publishes progress at 5 Hz for 15 s, then ends cleanly with exit code 0.
JOB = HEAD + """
n = Node("job")
pub = n.create_publisher(String, "/job_progress", 10)
n.create_timer(0.2, lambda: pub.publish(String(data="50%")))
end = time.monotonic() + 15.0
while time.monotonic() < end:
    rclpy.spin_once(n, timeout_sec=0.1)
n.destroy_node()
rclpy.shutdown()
print("done", flush=True)
sys.exit(0)
"""

LISTENER = HEAD + """
n = Node(sys.argv[1])
for topic in sys.argv[2:]:
    n.create_subscription(String, topic, lambda m: None, LATCHED_QOS if topic == "/map" else 10)
print("ready", flush=True)
rclpy.spin(n)
"""

# Sets /detector's parameter every 4 s through its parameter services (/parameter_events traffic).
TUNER = HEAD + """
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
n = Node("tuner")
client = AsyncParameterClient(n, "/detector")
k = [0]
def tune():
    if client.services_are_ready():
        k[0] += 1
        client.set_parameters([Parameter("threshold", value=0.5 + 0.1 * (k[0] % 3))])
        print("set", k[0], flush=True)
n.create_timer(4.0, tune)
rclpy.spin(n)
"""


def _monitor(children, tmp_path, db: str = "alerts.sqlite", healthy=None) -> Monitor:
    cfg = tmp_path / "stream-viz.toml"
    cfg.write_text(CONFIG)
    # A shared test machine can stall a thread for seconds: no plugin is cut off for it here.
    return Monitor(load_config(cfg), db=tmp_path / db, viewer="none", plugin_timeout_s=10.0,
                   domain_id=int(children.env["ROS_DOMAIN_ID"]), progress=Progress(open(os.devnull, "w")),
                   healthy=healthy)


def _observe(mon: Monitor, seconds: float) -> None:
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        t0 = time.monotonic()
        mon.step()
        time.sleep(max(0.0, 1.0 - (time.monotonic() - t0)))


def _settle(mon: Monitor, members: set[str], what: str, seconds: float = 15.0) -> None:
    """Step until ``members`` are seen (20 s at most), observe ``seconds`` (baselines learnt) and
    assert that ``what``, healthy, raised no alert."""
    wait_for(lambda: (mon.step(), members <= set(mon.seen))[1], timeout=20, period=1.0)
    _observe(mon, seconds)
    _no_alerts(mon, what)


def _observe_until(mon: Monitor, since: float, found, timeout: float) -> list:
    """Observe a second at a time until ``found`` holds of the alerts raised since ``since`` (wall
    time) or ``timeout`` s passed; return those alerts."""
    deadline = time.monotonic() + timeout
    alerts = mon.store.alerts(since=since)
    while time.monotonic() < deadline and not found(alerts):
        _observe(mon, 1.0)
        alerts = mon.store.alerts(since=since)
    return alerts


def _no_alerts(mon: Monitor, what: str) -> None:
    alerts = mon.store.alerts()
    assert alerts == [], f"{what} raised alerts:\n" + "\n".join(
        f"{a.member} {a.plugin} {a.severity}: {a.message}" for a in alerts)


def _silences_while_stopped(mon: Monitor, proc, member: str | None, timeout: float):
    """SIGSTOP ``proc`` and observe until a silence (of ``member``, or any) or ``timeout``; resume it."""
    os.killpg(proc.pid, signal.SIGSTOP)
    try:
        found = []
        deadline = time.monotonic() + timeout
        while not found and time.monotonic() < deadline:
            _observe(mon, 1.0)
            found = [a for a in mon.store.alerts() if a.data.get("symptom") == "silence"
                     and member in (None, a.member)]
    finally:
        os.killpg(proc.pid, signal.SIGCONT)
    return found


def _plugin(mon: Monitor, name: str):
    (p,) = [p for p in mon.plugins.plugins if p.name == name]
    return p


def test_healthy_dynamics_raise_no_alert_and_a_hang_past_the_own_gaps_is_a_silence(children, tmp_path):
    bursts = children.python(BURSTS, name="bursts")
    children.python(LATCHED, name="latched")
    children.python(LIFECYCLE, "dock", "/dock_pose", "0.2", "12", "8", name="lifecycle")
    job = children.python(JOB, name="job")
    children.python(LISTENER, "listener", "/detections", "/job_progress", "/dock_pose", name="listener")
    tuner = children.python(TUNER, name="tuner")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), {"node:/detector", "node:/job", "node:/dock"} <= set(mon.seen))[1],
                 timeout=20, period=1.0)
        _observe(mon, 16.0)
        console = children.python(LISTENER, "console", "/map", "/detections", name="console")  # joins late
        _observe(mon, 18.0)
        assert job.poll() == 0, "the job did not end cleanly"
        assert "node:/console" in mon.seen and mon.seen.nodes["node:/job"].get("gone")
        assert "set 3" in (tmp_path / f"tuner_{children.procs.index(tuner)}.log").read_text()
        assert console.poll() is None
        _no_alerts(mon, "healthy dynamics")
        # What was learned: /detections' 5 s gaps; /dock_pose's deactivation was seen as a change of
        # its node's state (a lifecycle transition), the cause of its quiet.
        rhythms = _plugin(mon, "topic_rate").state["rhythms"]
        gaps = rhythms["topic:/detections"].gaps
        assert len(gaps) >= 3 and all(4.5 <= g <= 7.5 for g in gaps), gaps
        assert _plugin(mon, "topic_rate").state["transitions"].get("node:/dock"), "no transition seen"

        # The burst publisher hangs: silent for longer than twice its longest gap is a silence.
        t_stop = time.time()
        found = _silences_while_stopped(mon, bursts, "topic:/detections", 30.0)
        assert found, f"no silence of the hung burst topic; alerts: {mon.store.alerts()}"
        a = found[0]
        assert a.severity == "error" and a.t > t_stop
        assert a.data["limit_s"] == pytest.approx(2 * max(gaps), abs=0.01)
        assert a.data["limit_s"] <= a.data["silent_s"] < a.data["limit_s"] + 3.0
    finally:
        mon.close()


# A relay forwards each message of its input (data computed from an input stops with it).
RELAY = HEAD + """
n = Node("pose_relay")
pub = n.create_publisher(String, "/pose_relayed", 10)
n.create_subscription(String, "/pose", pub.publish, 10)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_quiet_that_follows_its_input_is_the_inputs_and_a_hang_of_its_own_is_a_silence(children,
                                                                                        tmp_path):
    relay = children.python(RELAY, name="relay")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/pose_relay" in mon.seen)[1], timeout=20, period=1.0)
        # A lifecycle source active from its start for 16 s, inactive 8 s, then active again.
        source = children.python(LIFECYCLE, "pose_source", "/pose", "0.1", "16", "8", name="source")
        t0 = time.monotonic()
        _observe(mon, 26.0)  # on for 16 s (> warmup_s: continuous), off 8 s, on again
        assert source.poll() is None
        _no_alerts(mon, "a relay of a deactivated publisher")
        rhythms = _plugin(mon, "topic_rate").state["rhythms"]
        relayed = rhythms["topic:/pose_relayed"]
        assert relayed.settled and relayed.gaps == [], relayed  # the input's quiet, not learned

        # The relay itself hangs while its input goes on: that is a silence of its output.
        wait_for(lambda: time.monotonic() - t0 > 27.0, timeout=5, period=0.2)
        found = _silences_while_stopped(mon, relay, None, 10.0)
        assert [a.member for a in found] == ["topic:/pose_relayed"], mon.store.alerts()
    finally:
        mon.close()


# An action server that drives /cmd at 10 Hz while it executes a goal (14 s; > warmup_s, so /cmd
# is a continuous topic), then succeeds; a mission client sends a goal, waits for its result,
# pauses 8 s and sends the next (a controller and its goals, as a navigation stack has them).
CONTROLLER = HEAD + """
from rclpy.action import ActionServer
from test_msgs.action import Fibonacci
n = Node("controller")
pub = n.create_publisher(String, "/cmd", 10)
def execute(goal):
    end = time.monotonic() + 14.0
    while time.monotonic() < end:
        pub.publish(String(data="go"))
        time.sleep(0.1)
    goal.succeed()
    return Fibonacci.Result()
ActionServer(n, Fibonacci, "/follow", execute)
print("ready", flush=True)
rclpy.spin(n)
"""

MISSION = HEAD + """
from rclpy.action import ActionClient
from test_msgs.action import Fibonacci
n = Node("mission")
client = ActionClient(n, Fibonacci, "/follow")
client.wait_for_server()
while True:
    print("goal sent", flush=True)
    sent = client.send_goal_async(Fibonacci.Goal(order=1))
    rclpy.spin_until_future_complete(n, sent)
    done = sent.result().get_result_async()
    rclpy.spin_until_future_complete(n, done)
    print("goal done", flush=True)
    end = time.monotonic() + 8.0
    while time.monotonic() < end:
        rclpy.spin_once(n, timeout_sec=0.1)
"""


def test_a_controller_stopping_when_its_goal_ends_is_no_silence_and_its_hang_is(children, tmp_path):
    controller = children.python(CONTROLLER, name="controller")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/controller" in mon.seen)[1], timeout=20, period=1.0)
        _observe(mon, 2.0)  # the status topic is followed before the first goal
        mission = children.python(MISSION, name="mission")
        _observe(mon, 28.0)  # a goal of 14 s, a pause of 8 s, the next goal
        log_path = tmp_path / f"mission_{children.procs.index(mission)}.log"
        # A slow start of the mission moves its goals later: the hang below must fall in the second.
        deadline = time.monotonic() + 20.0
        while log_path.read_text().count("goal sent") < 2 and time.monotonic() < deadline:
            _observe(mon, 1.0)
        log = log_path.read_text()
        assert "goal done" in log and log.count("goal sent") >= 2, log
        _observe(mon, 2.0)
        _no_alerts(mon, "a controller whose goal ended")
        # The goal's end was seen (a `goal` event: the controller's only change of state).
        assert _plugin(mon, "topic_rate").state["transitions"].get("node:/controller"), "no goal end seen"
        assert _plugin(mon, "topic_rate").state["rhythms"]["topic:/cmd"].settled

        # The controller hangs in the middle of a goal: no goal ends, /cmd is silent.
        found = _silences_while_stopped(mon, controller, None, 10.0)
        assert [a.member for a in found] == ["topic:/cmd"], mon.store.alerts()
    finally:
        mon.close()


CAMERA = HEAD + """
n = Node("camera")
pub = n.create_publisher(String, "/image", 10)
n.create_timer(0.1, lambda: pub.publish(String(data="frame")))
print("ready", flush=True)
rclpy.spin(n)
"""

# Detectors of /image that publish only while their target is in view: 14 s in view (longer than
# warmup_s: the first window makes them look continuous), then 8 s out of it, again and again.
# /a_detector has a process of its own (single-threaded) and hangs in its callback once the file
# argv[1] exists; /b_detector shares a multi-threaded process with a tracker of its detections and
# publishes its status at 2 Hz besides; /c_detector shares a single-threaded process with a filter.
# Each detector works 2 ms on every frame: a multi-threaded executor's workers that used less than
# 0.1 % of a core each would look idle to the collector (docs/collector.md).
DETECTORS = HEAD + """
import threading
from rclpy.executors import MultiThreadedExecutor, SingleThreadedExecutor
t0 = time.monotonic()
def in_view():
    return (time.monotonic() - t0) % 22.0 < 14.0
def detector(name, hang=None):
    n = Node(name)
    pub = n.create_publisher(String, "/" + name + "/detections", 10)
    def frame(msg):
        if hang and os.path.exists(hang):
            threading.Event().wait()  # blocked for good, as a deadlock
        end = time.thread_time() + 0.002  # 2 ms of work a frame, in view or not, as a detector's
        while time.thread_time() < end:
            pass
        if in_view():
            pub.publish(String(data="pallet"))
    n.create_subscription(String, "/image", frame, 10)
    return n
if sys.argv[1] == "alone":
    n = detector("a_detector", hang=sys.argv[2])
    print("ready", flush=True)
    rclpy.spin(n)
elif sys.argv[1] == "single":
    det, filt = detector("c_detector"), Node("c_filter")
    out = filt.create_publisher(String, "/c_filter/image", 10)
    filt.create_subscription(String, "/image", out.publish, 10)
    ex = SingleThreadedExecutor()
    ex.add_node(det)
    ex.add_node(filt)
    print("ready", flush=True)
    ex.spin()
else:
    det, tracker = detector("b_detector"), Node("b_tracker")
    status = det.create_publisher(String, "/b_detector/status", 10)
    det.create_timer(0.5, lambda: status.publish(String(data="ok")))
    tracks = tracker.create_publisher(String, "/b_tracker/tracks", 10)
    tracker.create_subscription(String, "/b_detector/detections", tracks.publish, 10)
    ex = MultiThreadedExecutor()
    ex.add_node(det)
    ex.add_node(tracker)
    print("ready", flush=True)
    ex.spin()
"""


def test_a_detector_with_nothing_in_view_is_no_silence_and_its_hang_is(children, tmp_path):
    hang = tmp_path / "hang"
    children.python(CAMERA, name="camera")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/camera" in mon.seen)[1], timeout=20, period=1.0)
        children.python(DETECTORS, "alone", str(hang), name="a")
        children.python(DETECTORS, "shared", name="b")
        children.python(DETECTORS, "single", name="c")
        names = {"node:/a_detector", "node:/b_detector", "node:/c_detector"}
        wait_for(lambda: (mon.step(), names <= set(mon.seen))[1], timeout=20, period=1.0)
        _observe(mon, 48.0)  # two windows out of view
        # A topic's rhythm settles at its third gap (`min_gaps`): 22 s apart, and the detectors'
        # start on a loaded machine decides whether 48 s held two or three.
        rhythms = _plugin(mon, "topic_rate").state["rhythms"]
        topics = ("topic:/a_detector/detections", "topic:/b_detector/detections",
                  "topic:/c_detector/detections")
        settled = lambda: (_observe(mon, 1.0), all(rhythms[t].settled for t in topics))[1]  # noqa: E731
        wait_for(settled, timeout=30, period=0.0)
        _no_alerts(mon, "detectors with nothing in view")
        # Only the main thread runs callbacks in a single-threaded process, more do in a multi-threaded one.
        index, G = SCHEMAS["process"].index("running_threads"), mon.seen
        running = {n: G.nodes[process_of_node(G, f"node:/{n}_detector")]["theta"][index] for n in "abc"}
        assert running["a"] == running["c"] == 1 and running["b"] >= 2, running
        for topic in topics:
            # the 8 s quiets out of view learned as their own rhythm (a shorter hiccup of a loaded
            # machine may be learned beside them; none longer)
            gaps = rhythms[topic].gaps
            assert rhythms[topic].settled and any(7.0 <= g <= 10.0 for g in gaps), (topic, gaps)
            assert max(gaps) <= 10.0, (topic, gaps)

        # /a_detector deadlocks: its executor stops, and that is a silence of its detections
        # (judged on their learned rhythm: within twice the longest gap).
        hang.touch()
        limit = 2 * max(rhythms["topic:/a_detector/detections"].gaps)
        found = []
        deadline = time.monotonic() + limit + 12.0
        while not found and time.monotonic() < deadline:
            _observe(mon, 1.0)
            found = [a for a in mon.store.alerts() if a.data.get("symptom") == "silence"]
        assert [a.member for a in found] == ["topic:/a_detector/detections"], mon.store.alerts()
    finally:
        mon.close()


# A driver: its reader thread publishes /scan at 20 Hz, its node's timer its status at 2 Hz (on
# /diagnostics, OK whatever the reader does), and it takes /image (so its inputs arrive while /scan
# is quiet). Once the file argv[1] exists the reader thread dies on an exception; the node goes on.
DRIVER = HEAD + """
import threading
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
n = Node("lidar_driver")
scan = n.create_publisher(String, "/scan", 10)
status = n.create_publisher(DiagnosticArray, "/diagnostics", 10)
ok = DiagnosticArray(status=[DiagnosticStatus(level=bytes([0]), name="lidar_driver: device", message="ok")])
n.create_timer(0.5, lambda: status.publish(ok))
n.create_subscription(String, "/image", lambda m: None, 10)
def read():
    while rclpy.ok():
        time.sleep(0.05)
        if os.path.exists(sys.argv[1]):
            raise OSError("device reports an error")
        scan.publish(String(data="scan"))
threading.Thread(target=read, daemon=True).start()
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_dead_reader_thread_is_a_silence_while_its_node_works(children, tmp_path):
    dead = tmp_path / "dead"
    children.python(CAMERA, name="camera")
    children.python(DRIVER, str(dead), name="driver")
    mon = _monitor(children, tmp_path)
    try:
        names = {"node:/camera", "node:/lidar_driver"}
        wait_for(lambda: (mon.step(), names <= set(mon.seen))[1], timeout=20, period=1.0)
        _observe(mon, 20.0)
        _no_alerts(mon, "a driver at work")
        # Its OK status and its input go on, as a node withholding an output or vouching for its
        # quiet: the thread it lost says the quiet is no choice.
        dead.touch()
        found = []
        deadline = time.monotonic() + 15.0
        while not found and time.monotonic() < deadline:
            _observe(mon, 1.0)
            found = [a for a in mon.store.alerts() if a.data.get("symptom") == "silence"]
        assert [a.member for a in found] == ["topic:/scan"], mon.store.alerts()
        assert "lost a thread as it stopped" in found[0].message, found[0].message
    finally:
        mon.close()


LOOPER = HEAD + """
n = Node(sys.argv[1])
pub = n.create_publisher(String, "/" + sys.argv[1] + "_out", 10)
n.create_timer(0.1, lambda: pub.publish(String(data="x")))
end = time.monotonic() + 6.0
while time.monotonic() < end:
    rclpy.spin_once(n, timeout_sec=0.1)
if sys.argv[2] == "kill":
    os._exit(1)  # as a segfault: no goodbye to DDS, the node stays listed until its lease ends
raise RuntimeError("lost the device")  # exit code 1, after rclpy said goodbye to DDS
"""


def test_a_node_started_four_times_is_one_restart_loop_symptom_of_that_node(children, tmp_path):
    mon = _monitor(children, tmp_path)
    loops = {"looper_raise": "raise", "looper_kill": "kill"}
    started = dict.fromkeys(loops, 0)
    procs: dict = {}
    try:
        end = time.monotonic() + 55.0
        while time.monotonic() < end and (min(started.values()) < 4 or any(p.poll() is None for p in
                                                                             procs.values())):
            for name, how in loops.items():  # the supervisor: start it again once it has ended
                if started[name] < 4 and (name not in procs or procs[name].poll() is not None):
                    procs[name] = children.python(LOOPER, name, how, name=name)
                    started[name] += 1
            _observe(mon, 1.0)
        assert started == dict.fromkeys(loops, 4)
        _observe(mon, 3.0)
        gone = [a for a in mon.store.alerts() if a.plugin == "member_gone"]
        assert not [a for a in gone if a.member.startswith("process:")], gone
        for name in loops:
            eps = [e for e in mon.store.episodes(f"node:/{name}") if e.plugin == "member_gone"]
            assert len(eps) == 1, (name, eps, gone)
            assert eps[0].max_severity in ("error", "fatal"), (name, eps)
        # Each process said goodbye to DDS, then exited 1: four lives seen, three restarts. Each
        # end alone is a crash ("an uncaught exception"), and the episode's rows are those crash
        # errors or "restarted N times" (a row per 5 s, or when the severity rises).
        restarts = _plugin(mon, "member_gone").state["restarts"]
        assert len(restarts.get("node:/looper_raise", ())) == 3, restarts
        said = [a.message for a in gone if a.member == "node:/looper_raise"]
        assert any("restarted 3 times" in m or "an uncaught exception" in m for m in said), said
        # The killed ones stay listed until their lease ends: their successors were counted all
        # the same (as more instances of the name), though their alerts are rows only every 5 s.
        assert len(restarts.get("node:/looper_kill", ())) >= 2, restarts
    finally:
        mon.close()


def test_a_busy_monitor_still_sees_the_quiets_between_its_samples(children, tmp_path):
    # The monitor looks only every 7 s (a loaded machine): a 5 s quiet of the bursty topic falls
    # between two looks, and the samples may always land in a burst. The collector's longest
    # interval since its last look (gap_s) shows each quiet, so the rhythm learns them and the
    # topic is not taken for a continuous one whose next quiet would be a silence.
    children.python(BURSTS, name="bursts")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "topic:/detections" in mon.seen)[1], timeout=20, period=1.0)
        seen = []
        for _ in range(6):
            time.sleep(7.0)
            mon.step()
            seen.append(mon.seen.nodes["topic:/detections"]["theta"])
        gaps = [float(th[list(SCHEMAS["topic"]).index("gap_s")]) for th in seen]
        assert all(4.5 <= g <= 5.6 for g in gaps[1:]), gaps  # the first look may span a start
        r = _plugin(mon, "topic_rate").state["rhythms"]["topic:/detections"]
        assert len(r.gaps) >= 4 and all(g >= 4.5 for g in r.gaps), r.gaps
        assert mon.store.alerts() == []
    finally:
        mon.close()


# Three nodes on one single-threaded executor: a driver (/raw, 10 Hz), an IMU (/imu, 30 Hz) and a
# merger that republishes /raw on /merged and reads /imu. Once the file argv[2] exists, either the
# merger's IMU callback blocks for good (argv[1] "hang": the thread stops, every node with it) or the driver
# stops publishing while its timer and the IMU's go on (argv[1] "lost": a device lost).
SHARED_THREAD = HEAD + """
from rclpy.executors import SingleThreadedExecutor
mode, flag = sys.argv[1], sys.argv[2]
drv, imu, mer = Node("driver"), Node("imu"), Node("merger")
raw = drv.create_publisher(String, "/raw", 10)
def tick():
    if not (mode == "lost" and os.path.exists(flag)):
        raw.publish(String(data="r"))
drv.create_timer(0.1, tick)
ip = imu.create_publisher(String, "/imu", 10)
imu.create_timer(1 / 30, lambda: ip.publish(String(data="i")))
mp = mer.create_publisher(String, "/merged", 10)
mer.create_subscription(String, "/raw", mp.publish, 10)
def deskew(m):  # the merger's IMU callback: its output's last message can follow its inputs'
    while mode == "hang" and os.path.exists(flag):
        time.sleep(0.5)
mer.create_subscription(String, "/imu", deskew, 10)
ex = SingleThreadedExecutor()
for node in (drv, imu, mer):
    ex.add_node(node)
print("ready", flush=True)
ex.spin()
"""


@pytest.mark.parametrize("mode", ["hang", "lost"])
def test_a_stalled_executor_silences_its_nodes_together_and_the_rca_ties_them(children, tmp_path, mode):
    flag = tmp_path / "flag"
    children.python(SHARED_THREAD, mode, str(flag), name="sensors")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "node:/merger" in mon.seen)[1], timeout=20, period=1.0)
        _observe(mon, 14.0)  # > warmup_s: every topic continuous, the executor's CPU learned
        _no_alerts(mon, "three nodes on one thread")
        t0 = time.time()
        flag.touch()
        _observe(mon, 6.0)
        silent = {a.member for a in mon.store.alerts(since=t0) if a.data.get("symptom") == "silence"}
        causes = mon.engine.result().root_causes
        if mode == "hang":
            # The merger stopped the thread: all three go quiet at once. Its IMU callback publishes
            # nothing, so when each next message was due cannot single it out: it blocked at the
            # IMU's last arrival, the last thing the thread did, and stays in the first place, tied
            # with a node whose due was first (which one depends on the timers' phase). The merger
            # is not excused by its input.
            assert silent == {"topic:/raw", "topic:/imu", "topic:/merged"}, mon.store.alerts(since=t0)
            first = [c for c in causes if abs(c.score - causes[0].score) < 1e-6]
            box = {"node:/driver", "node:/imu", "node:/merger"}
            assert "node:/merger" in {c.member for c in first} <= box and len(first) >= 2, causes[:4]
            assert next(c for c in first if c.member == "node:/merger").evidence["upstream"] == 0.0
        else:
            # The thread goes on (the IMU publishes): the merger's quiet is its input's.
            assert silent == {"topic:/raw"}, mon.store.alerts(since=t0)
            assert causes and causes[0].member == "node:/driver", causes[:3]
    finally:
        flag.unlink(missing_ok=True)
        mon.close()


# 10 Hz for 1 s, then nothing for 2.5 s, again and again: /detections' gaps 2.5 s.
SHORT_BURSTS = BURSTS.replace("% 7.0 < 2.0", "% 3.5 < 1.0")


def _paused_once(children, tmp_path, bursts, db: str, healthy=None) -> list:
    """A monitor (its database ``db``, started from ``healthy``) until /detections' rhythm is
    settled, then /detector paused for 10 s and resumed: the silences it raised."""
    mon = _monitor(children, tmp_path, db, healthy)
    try:
        rhythms = _plugin(mon, "topic_rate").state.setdefault("rhythms", {})

        def settled():
            mon.step()
            return "topic:/detections" in rhythms and len(rhythms["topic:/detections"].gaps) >= 3

        wait_for(settled, timeout=30, period=1.0)
        paused = time.monotonic()
        os.killpg(bursts.pid, signal.SIGSTOP)
        try:
            _observe(mon, 10.0)  # past twice its gaps
        finally:
            os.killpg(bursts.pid, signal.SIGCONT)
        r = rhythms["topic:/detections"]
        # Its messages back (at its next burst, up to 2.5 s later): the pause ended.
        wait_for(lambda: (mon.step(), r.ended >= 10.0)[1], timeout=8, period=1.0)
        assert r.ended <= time.monotonic() - paused + 3.5, (r.ended, r.gaps)
        return [a for a in mon.store.alerts() if a.data.get("symptom") == "silence"]
    finally:
        mon.close()


def test_a_quiet_alerted_in_a_run_judged_healthy_is_no_silence_in_the_next(children, tmp_path):
    # The bursty detector, paused once for longer than twice its gaps: a silence. The user judges
    # that run healthy (the pause was the robot's own) and starts the next from its database: the
    # same pause is no silence there, though that run's own gaps are as short.
    bursts = children.python(SHORT_BURSTS, name="bursts")
    first = _paused_once(children, tmp_path, bursts, "first.sqlite")
    assert [a.member for a in first][:1] == ["topic:/detections"], first
    second = _paused_once(children, tmp_path, bursts, "second.sqlite", tmp_path / "first.sqlite")
    assert second == [], second
    store = AlertStore(tmp_path / "first.sqlite", readonly=True)
    try:
        assert store.get_meta("learned")["topic_rate"]["gaps"]["topic:/detections"] >= 10.0
    finally:
        store.close()


# A gap detector's findings every 2 s while the robot drives an aisle (14 s), none while it turns
# (16 s), again and again.
AISLES = HEAD + """
n = Node("gap_detector")
pub = n.create_publisher(String, "/gaps", 10)
t0 = time.monotonic()
def tick():
    if (time.monotonic() - t0) % 30.0 < 14.0:
        pub.publish(String(data="gap"))
n.create_timer(2.0, tick)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_a_slow_topics_first_pause_is_no_silence(children, tmp_path):
    # Seven messages in its first run are too few to say the topic never pauses (it settled as
    # continuous after 10 s, five messages, and its first pause was a silence).
    children.python(AISLES, name="aisles")
    children.python(LISTENER, "listener", "/gaps", name="listener")
    mon = _monitor(children, tmp_path)
    try:
        wait_for(lambda: (mon.step(), "topic:/gaps" in mon.seen)[1], timeout=20, period=1.0)
        _observe(mon, 45.0)
        _no_alerts(mon, "a slow topic pausing between aisles")
        r = _plugin(mon, "topic_rate").state["rhythms"]["topic:/gaps"]
        assert r.gaps and all(14.0 <= g <= 20.0 for g in r.gaps), r.gaps  # its pause, learned
    finally:
        mon.close()
