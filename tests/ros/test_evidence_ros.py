"""Evidence from real robots against real rclpy nodes in subprocesses (issue 16 items 3–6, 8).

Each run starts healthy (no alert of the plugin under test may come then), then the test creates
a flag file and the child turns sick in one way: header stamps lagging 300 ms, a service server
answering slowly, one of two publishers of a topic slowing down. The QoS and diagnostics runs are
sick from the start (a misconfigured subscription, an updater-style ERROR status).
"""

from __future__ import annotations

import math
import time

import pytest

from stream_viz.model.theta import theta_dict
from stream_viz.rca import RcaSettings, analyze
from stream_viz.testing import wait_for
from tests.ros.test_plugins_ros import PERIOD, Run, _ready, _sick_after_healthy

pytestmark = pytest.mark.ros

FAST = {
    "message_age": {"warmup_s": 4.0, "refresh_s": 2.0},
    "services": {"warmup_s": 4.0, "refresh_s": 2.0},
}


@pytest.fixture
def run_of(ros_domain):
    runs = []

    def make(plugins, settings=None):
        r = Run(ros_domain, plugins, settings or FAST)
        runs.append(r)
        return r

    yield make
    for r in runs:
        r.close()


# Stamps 0.3 s old once the flag exists. With a second argument, a hot standby of that name: its
# publisher on the same topic, and nothing sent (until it would take over: never, here).
STAMPED = """
import os, sys
import rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from sensor_msgs.msg import Imu
flag, standby = sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None
rclpy.init()
n = Node(standby or 'imu_driver', namespace='/robot')
pub = n.create_publisher(Imu, '/robot/imu', 10)
def tick():
    m = Imu()
    lag = Duration(seconds=0.3) if os.path.exists(flag) else Duration()
    m.header.stamp, m.header.frame_id = (n.get_clock().now() - lag).to_msg(), 'imu'
    pub.publish(m)
n.create_timer(0.05, lambda: None if standby else tick())
rclpy.spin(n)
"""


def test_message_age_of_stamps_lagging_300ms(children, tmp_path, run_of):
    flag = tmp_path / "lag"
    children.python(STAMPED, str(flag), name="imu")
    run = run_of(["message_age"])
    _ready(run, "topic:/robot/imu")
    wait_for(lambda: (run.step(), not math.isnan(_theta(run, "topic:/robot/imu")["stamp_age_ms"]))[1],
             timeout=20, period=PERIOD)
    healthy = _theta(run, "topic:/robot/imu")
    assert 0.0 <= healthy["stamp_age_ms"] < 50.0, healthy  # stamped at publishing: only transport
    a = _sick_after_healthy(run, flag, "message_age", "topic:/robot/imu", healthy_s=6.0, symptom="stale")
    # seen while the 3 s window still holds fresh messages too: the mean is on its way to 300 ms
    assert a.severity == "warn" and 100.0 <= a.data["value_ms"] <= 400.0, a
    run.observe(3.5)  # the window has turned over
    sick = _theta(run, "topic:/robot/imu")
    # the data's age, beside a transport latency that did not change
    assert 280.0 <= sick["stamp_age_ms"] <= 400.0 and sick["latency_ms"] < 50.0, sick
    # the youngest is late too (it may be a hair older than the mean: both are ~300 ms plus jitter)
    assert 280.0 <= sick["stamp_age_recent_ms"] <= 400.0, sick


def test_late_messages_are_the_sending_publishers_not_a_hot_standbys(children, tmp_path, run_of):
    flag, topic = tmp_path / "lag", "topic:/robot/imu"
    children.python(STAMPED, str(flag), name="imu")
    children.python(STAMPED, str(flag), "standby", name="standby")
    run = run_of(["message_age"])
    _ready(run, "node:/robot/imu_driver", "node:/robot/standby")
    wait_for(lambda: (run.step(), "node:/robot/standby" in (run.G.nodes.get(topic, {})
                                                           .get("publisher_rates") or {}))[1],
             timeout=20, period=PERIOD)
    assert run.G.nodes[topic]["publisher_rates"]["node:/robot/standby"] == 0.0  # listed, idle
    a = _sick_after_healthy(run, flag, "message_age", topic, healthy_s=6.0, symptom="stale")
    top = analyze(run.G, [a], RcaSettings(), None).root_causes
    assert [rc.member for rc in top] == ["node:/robot/imu_driver"], top  # not the standby, which sent nothing


DEVICE_CLOCK = """
import os, sys
import rclpy
from rclpy.duration import Duration
from sensor_msgs.msg import LaserScan
flag = sys.argv[1]
rclpy.init()
n = rclpy.create_node('lidar_driver')
pub = n.create_publisher(LaserScan, '/scan', 10)
def tick():  # stamped by the device's own clock, 400 ms ahead; 300 ms late data after the flag
    m = LaserScan()
    lag = Duration(seconds=0.3) if os.path.exists(flag) else Duration()
    m.header.stamp = (n.get_clock().now() + Duration(seconds=0.4) - lag).to_msg()
    pub.publish(m)
n.create_timer(0.05, tick)
rclpy.spin(n)
"""


def test_a_device_clock_ahead_from_the_start_is_normal_and_its_late_data_is_not(children, tmp_path,
                                                                               run_of):
    flag = tmp_path / "lag"
    children.python(DEVICE_CLOCK, str(flag), name="lidar")
    run = run_of(["message_age"])
    _ready(run, "topic:/scan")
    run.observe(14.0)  # past learn_s (10 s) from its first stamped message
    assert run.alerts == [] and _theta(run, "topic:/scan")["stamp_age_ms"] < -300.0
    flag.write_text("1")
    found = run.until(lambda a: a.plugin == "message_age", 15.0)
    assert found and found[0].data["symptom"] == "stale", run.alerts


LOOPING = """
import os, sys, time
import rclpy
from builtin_interfaces.msg import Time
from sensor_msgs.msg import Imu
rclpy.init()
n = rclpy.create_node('log_player')
pub = n.create_publisher(Imu, '/mocap', 10)
loop, pause = float(sys.argv[1]), float(sys.argv[2])
while len(sys.argv) > 3 and not os.path.exists(sys.argv[3]):  # played from when the test says
    time.sleep(0.05)
t0 = time.time()
def tick():  # a recording played in loops: its stamps go back to the first loop's each time
    into = (time.time() - t0) % loop
    if into > loop - pause:
        return  # the player's pause at the end of a loop
    m = Imu()
    ns = int((t0 + into) * 1e9)
    m.header.stamp = Time(sec=ns // 10**9, nanosec=ns % 10**9)
    pub.publish(m)
n.create_timer(0.05, tick)
rclpy.spin(n)
"""


def test_a_looping_recording_is_no_stale_data(children, run_of):
    children.python(LOOPING, "7", "0", name="player")
    run = run_of(["message_age"])
    _ready(run, "topic:/mocap")
    resets, end = [], time.monotonic() + 24.0  # three loops, each 7 s older than the last
    while time.monotonic() < end:
        resets += [e for e in run.step().events if e.kind == "stamp_reset"]
        time.sleep(PERIOD)
    assert len(resets) >= 2 and all(e.member == "topic:/mocap" for e in resets), resets
    assert all(6.0 < e.data["back_s"] < 8.0 for e in resets), resets
    assert _theta(run, "topic:/mocap")["stamp_age_ms"] > 5000.0  # its data are old, and that is its time
    assert run.alerts == []


def test_a_recordings_pause_between_loops_is_a_silence_once(children, tmp_path, run_of):
    play = tmp_path / "play"
    children.python(LOOPING, "16", "2.5", str(play), name="player")  # 13.5 s of 10 Hz, 2.5 s of nothing
    run = run_of(["topic_rate", "message_age"])
    _ready(run, "node:/log_player")
    play.write_text("1")  # from the monitor's first look, so the topic has settled before a pause
    resets, end = [], time.monotonic() + 52.0  # three pauses
    while time.monotonic() < end:
        resets += [e.t for e in run.step().events if e.kind == "stamp_reset"]
        time.sleep(PERIOD)
    assert len(resets) >= 3, resets
    silences = [a.t for a in run.alerts if a.plugin == "topic_rate"]
    # the first pause of a continuous topic is a departure; ended by its stamps going back, it is
    # learned as the stream's loop, and the next pauses are within its rhythm
    assert silences and max(silences) < resets[0] + 1.0, (silences, resets)
    assert [a for a in run.alerts if a.plugin == "message_age"] == []


SIMULATED = """
import os, sys, time
import rclpy
from rclpy.duration import Duration
from rclpy.parameter import Parameter
from rclpy.executors import SingleThreadedExecutor
from builtin_interfaces.msg import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu
flag = sys.argv[1]
rclpy.init()
# A simulator at half real time whose clock starts at 1000 s; a driver on simulated time; a
# bridge stamping with the wall clock, as mixed systems do.
sim = rclpy.create_node('simulator')
clock = sim.create_publisher(Clock, '/clock', 10)
t0 = time.monotonic()
def tick():
    ns = int(1000e9 + 0.5 * (time.monotonic() - t0) * 1e9)
    clock.publish(Clock(clock=Time(sec=ns // 10**9, nanosec=ns % 10**9)))
sim.create_timer(0.01, tick)
drv = rclpy.create_node('imu_driver', parameter_overrides=[Parameter('use_sim_time', value=True)])
imu = drv.create_publisher(Imu, '/imu', 10)
def sample():
    if drv.get_clock().now().nanoseconds < 1000e9:
        return  # no /clock received yet
    m = Imu()
    lag = Duration(seconds=0.3) if os.path.exists(flag) else Duration()
    m.header.stamp = (drv.get_clock().now() - lag).to_msg()
    imu.publish(m)
drv.create_timer(0.05, sample)
bridge = rclpy.create_node('bridge')
wall = bridge.create_publisher(Imu, '/wall_imu', 10)
def bridged():
    m = Imu()
    m.header.stamp = bridge.get_clock().now().to_msg()
    wall.publish(m)
bridge.create_timer(0.05, bridged)
ex = SingleThreadedExecutor()
for n in (sim, drv, bridge):
    ex.add_node(n)
ex.spin()
"""


def test_message_age_on_simulated_time_is_no_clock_skew(children, tmp_path, run_of):
    # A robot in simulation stamps with /clock's time (1000 s, at half speed): its age is read on
    # that clock, a wall-stamped topic beside it on ours, and neither is a clock skew. Before:
    # every sim-stamped topic was "46 years behind", a warning on a healthy system.
    flag = tmp_path / "lag"
    children.python(SIMULATED, str(flag), name="sim")
    run = run_of(["message_age"])
    _ready(run, "topic:/imu", "topic:/wall_imu")
    wait_for(lambda: (run.step(), not math.isnan(_theta(run, "topic:/imu")["stamp_age_ms"]))[1],
             timeout=20, period=PERIOD)
    run.observe(2.0)
    for topic in ("topic:/imu", "topic:/wall_imu"):
        age = _theta(run, topic)["stamp_age_ms"]
        assert 0.0 <= age < 60.0, (topic, age)
    a = _sick_after_healthy(run, flag, "message_age", "topic:/imu", healthy_s=6.0, symptom="stale")
    assert 100.0 <= a.data["value_ms"] <= 400.0, a  # 300 ms of simulated time
    assert not [x for x in run.alerts if x.data.get("symptom") == "clock_skew"], run.alerts


SLOWING = """
import os, sys, time
import rclpy
from rclpy.parameter import Parameter
from rclpy.executors import SingleThreadedExecutor
from builtin_interfaces.msg import Time
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import Imu
flag = sys.argv[1]
rclpy.init()
# A simulator in real time that slows to 0.3 of it when the flag appears (a heavy scene); a driver
# on simulated time at 20 Hz of it; a bridge on our clock at 20 Hz, which drops to 4 Hz then.
sim = rclpy.create_node('simulator')
clock = sim.create_publisher(Clock, '/clock', 10)
st = {'ns': 0, 'k': 0}
def tick():
    st['ns'] += int(0.01e9 * (0.3 if os.path.exists(flag) else 1.0))
    clock.publish(Clock(clock=Time(sec=st['ns'] // 10**9, nanosec=st['ns'] % 10**9)))
sim.create_timer(0.01, tick)
drv = rclpy.create_node('imu_driver', parameter_overrides=[Parameter('use_sim_time', value=True)])
imu = drv.create_publisher(Imu, '/imu', 10)
drv.create_timer(0.05, lambda: imu.publish(Imu()))
bridge = rclpy.create_node('bridge')
wall = bridge.create_publisher(Imu, '/wall_imu', 10)
def bridged():
    st['k'] += 1
    if not os.path.exists(flag) or st['k'] % 5 == 0:
        wall.publish(Imu())
bridge.create_timer(0.05, bridged)
ex = SingleThreadedExecutor()
for n in (sim, drv, bridge):
    ex.add_node(n)
ex.spin()
"""


def test_a_slowed_simulation_is_no_rate_drop_of_what_runs_on_its_time(children, tmp_path, run_of):
    # The simulator slows to 0.3 of real time: the driver on its time publishes at 6 Hz on our
    # clock (its 20 Hz of simulated time, healthy); the bridge on our clock dropping to 4 Hz is a drop.
    flag = tmp_path / "slow"
    children.python(SLOWING, str(flag), name="sim")
    run = run_of(["topic_rate"], {"topic_rate": {"warmup_s": 4.0, "refresh_s": 2.0}})
    _ready(run, "topic:/imu", "topic:/wall_imu", "topic:/clock")
    assert ("topic:/clock", "node:/imu_driver") in run.G.edges()  # use_sim_time subscribes /clock
    wait_for(lambda: (run.step(), _theta(run, "topic:/clock")["sim_pace"] > 0.8)[1],
             timeout=20, period=PERIOD)
    a = _sick_after_healthy(run, flag, "topic_rate", "topic:/wall_imu", healthy_s=8.0, symptom="rate_drop")
    run.observe(4.0)
    assert 0.2 <= _theta(run, "topic:/clock")["sim_pace"] <= 0.4, _theta(run, "topic:/clock")
    assert _theta(run, "topic:/imu")["rate_hz"] < 9.0, _theta(run, "topic:/imu")  # slowed on our clock
    assert not [x for x in run.alerts if x.member == "topic:/imu"], run.alerts
    assert a.data["sim_pace_ratio"] == 1.0  # the bridge is on our clock


def _spin(nodes: str) -> str:
    """The end of a child script: spin ``nodes`` (a Python tuple's items) on one executor."""
    return f"""
from rclpy.executors import SingleThreadedExecutor
ex = SingleThreadedExecutor()
for n in ({nodes},):
    ex.add_node(n)
ex.spin()
"""


QOS = """
import rclpy
from rclpy.duration import Duration
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
rclpy.init()
talker, listener, watchdog = (rclpy.create_node(x) for x in ('talker', 'listener', 'watchdog'))
best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
pub = talker.create_publisher(String, '/chatter', best_effort)
status = talker.create_publisher(String, '/status', 10)  # no deadline offered
listener.create_subscription(String, '/chatter', lambda m: None,
                             QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
watchdog.create_subscription(String, '/status', lambda m: None,
                             QoSProfile(depth=10, deadline=Duration(seconds=0.1)))
talker.create_timer(0.05, lambda: (pub.publish(String(data='x')), status.publish(String(data='ok'))))
""" + _spin("talker, listener, watchdog")


def test_qos_incompatible_subscribers_reliable_and_deadline(children, run_of):
    children.python(QOS, name="qos")
    run = run_of(["qos_compat"])
    _ready(run, "node:/talker", "node:/listener", "node:/watchdog")
    found = run.until(lambda a: a.member == "node:/watchdog", 20.0)
    found += run.until(lambda a: a.member == "node:/listener", 10.0)
    by = {a.member: a for a in found}
    assert set(by) == {"node:/listener", "node:/watchdog"}, run.alerts
    assert by["node:/listener"].data["reasons"] == [
        "node:/talker: Best effort publisher and reliable subscription"]
    assert by["node:/watchdog"].data["reasons"] == [
        "node:/talker: Subscription deadline is less than publisher deadline"]
    assert all(a.severity == "error" and a.data["receives_nothing"] for a in by.values())
    assert not any(a.member == "node:/talker" for a in run.alerts)
    assert run.problems == []


RECREATED = """
import os, sys
import rclpy
from rclpy.qos import QoSProfile, ReliabilityPolicy
from std_msgs.msg import String
rclpy.init()
talker, listener = rclpy.create_node('talker'), rclpy.create_node('listener')
best_effort = QoSProfile(depth=10, reliability=ReliabilityPolicy.BEST_EFFORT)
pub = talker.create_publisher(String, '/chatter', best_effort)
state = {'sub': listener.create_subscription(String, '/chatter', lambda m: None, best_effort)}
def tick():
    pub.publish(String(data='x'))
    if os.path.exists(sys.argv[1]) and state['sub'] is not None:
        # configured again with a QoS parameter: the same node, topic and endpoint count
        listener.destroy_subscription(state['sub'])
        state['sub'] = None
        state['sub'] = listener.create_subscription(
            String, '/chatter', lambda m: None, QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE))
        os.remove(sys.argv[1])
talker.create_timer(0.05, tick)
""" + _spin("talker, listener")


def test_a_subscription_re_created_with_an_incompatible_qos_is_found(children, run_of, tmp_path):
    # The endpoint set of /chatter never changes, so only the periodic re-read of each topic's
    # QoS (QosCache.every_s, 5 s) can see the new one; qos_compat looks again at once (qos_version).
    flag = tmp_path / "reconfigure"
    children.python(RECREATED, str(flag), name="recreated")
    run = run_of(["qos_compat"])
    _ready(run, "node:/talker", "node:/listener")
    run.observe(3.0)
    assert [a for a in run.alerts if a.plugin == "qos_compat"] == []
    flag.touch()
    t0 = time.time()
    found = run.until(lambda a: a.member == "node:/listener", 25.0)
    assert found, f"no alert 25 s after the re-creation: {run.alerts}"
    assert found[0].data["reasons"] == ["node:/talker: Best effort publisher and reliable subscription"]
    assert found[0].t - t0 <= 5.0 + 3 * PERIOD + 2.0
    assert not flag.exists()  # the child did re-create it


DIAG = """
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
rclpy.init()
my_node = rclpy.create_node('my_node', namespace='/robot')
monitor = rclpy.create_node('monitor', namespace='/robot')
agg = rclpy.create_node('aggregator', namespace='/robot')
pub = monitor.create_publisher(DiagnosticArray, '/diagnostics', 10)
agg_pub = agg.create_publisher(DiagnosticArray, '/diagnostics_agg', 10)
def status(name):
    return DiagnosticStatus(level=DiagnosticStatus.ERROR, name=name, hardware_id='motor-ctrl-7',
                            message='overcurrent')
def tick():
    # as diagnostic_updater names it: "<node name>: <task>", published here by another node
    pub.publish(DiagnosticArray(status=[status('my_node: motor')]))
    # and as an aggregator republishes it: a copy, and its analyzer's summary
    agg_pub.publish(DiagnosticArray(status=[
        DiagnosticStatus(level=DiagnosticStatus.ERROR, name='/Robot/Motors', message='Error'),
        status('/Robot/Motors/my_node: motor')]))
monitor.create_timer(0.5, tick)
""" + _spin("my_node, monitor, agg")


def test_diagnostics_updater_status_mapped_to_its_node_by_name(children, run_of):
    children.python(DIAG, name="diag")
    run = run_of(["diagnostics"])
    _ready(run, "node:/robot/my_node", "node:/robot/monitor", "node:/robot/aggregator")
    # A status is told by its publisher's gid once the publisher's endpoint is discovered.
    wait_for(lambda: (run.step(), run.G.has_edge("node:/robot/monitor", "topic:/diagnostics"))[1],
             timeout=20, period=PERIOD)
    events = []

    def step_collect():
        events.extend(e for e in run.step().events if e.kind == "diag")
        return [a for a in run.alerts if a.plugin == "diagnostics"]

    found = wait_for(step_collect, timeout=20, period=PERIOD)
    # The alert can come from statuses taken while the members were awaited: collect a few more.
    wait_for(lambda: (step_collect(), len(events) >= 4)[1], timeout=10, period=PERIOD)
    a = found[0]
    assert (a.member, a.severity, a.data["mapped_by"]) == ("node:/robot/my_node", "error", "name"), a
    assert {x.member for x in run.alerts} == {"node:/robot/my_node"}  # not the monitor, not the aggregator
    assert events and all(e.data["source"] == "/diagnostics" for e in events)  # the copies were not counted
    assert {e.data["publisher"] for e in events} == {"node:/robot/monitor"}  # the gid told the publisher


STANDING = """
import os, sys
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
rclpy.init()
n = rclpy.create_node('gps_driver')
pub = n.create_publisher(DiagnosticArray, '/diagnostics', 10)
def tick():  # no fix indoors from the start (a standing WARN); the battery OK until the flag
    low = os.path.exists(sys.argv[1])
    pub.publish(DiagnosticArray(status=[
        DiagnosticStatus(level=DiagnosticStatus.WARN, name='gps_driver: fix', message='no fix'),
        DiagnosticStatus(level=DiagnosticStatus.WARN if low else DiagnosticStatus.OK,
                         name='gps_driver: battery', message='low' if low else 'ok')]))
n.create_timer(0.5, tick)
""" + _spin("n")


def test_a_standing_diagnostics_warning_is_normal_and_a_new_one_is_not(children, tmp_path, run_of):
    flag = tmp_path / "low"
    children.python(STANDING, str(flag), name="gps")
    run = run_of(["diagnostics"], {**FAST, "diagnostics": {"warn_hold_s": 6.0}})
    _ready(run, "node:/gps_driver")
    run.observe(14.0)  # past learn_s (10 s) from the first report
    assert [a for a in run.alerts if a.plugin == "diagnostics"] == []
    flag.write_text("1")
    t0 = time.time()
    run.observe(3.0)  # a new WARN counts once it has held warn_hold_s
    assert [a for a in run.alerts if a.plugin == "diagnostics"] == []
    found = run.until(lambda a: a.plugin == "diagnostics", 12.0)
    assert found and found[0].member == "node:/gps_driver" and found[0].severity == "warn", found
    assert found[0].t >= t0 + 5.0, found[0].t - t0
    assert [st["name"] for st in found[0].data["statuses"]] == ["gps_driver: battery"]


LEAVING = """
import os, sys, time
import rclpy
flag = sys.argv[1]
rclpy.init()
n = rclpy.create_node('localizer', namespace='/r2')
while not os.path.exists(flag):
    rclpy.spin_once(n, timeout_sec=0.1)
n.destroy_node()  # it leaves the graph at once, then its process fails
rclpy.shutdown()
sys.exit(1)
"""

REPORTER = """
import os, sys, time
import rclpy
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus
flag = sys.argv[1]
rclpy.init()
n = rclpy.create_node('diag', namespace='/tools')
pub = n.create_publisher(DiagnosticArray, '/diagnostics', 10)
def tick():  # an updater-style name of a namespaced node, flat; ERROR 3 s after it left
    lost = os.path.exists(flag) and time.time() - os.path.getmtime(flag) > 3.0
    pub.publish(DiagnosticArray(status=[DiagnosticStatus(
        level=DiagnosticStatus.ERROR if lost else DiagnosticStatus.OK, name='r2_localizer: pose',
        message='no pose' if lost else 'ok')]))
n.create_timer(0.5, tick)
""" + _spin("n")


def test_a_status_about_a_node_that_left_is_charged_to_it_not_its_publisher(children, tmp_path, run_of):
    flag = tmp_path / "gone"
    children.python(LEAVING, str(flag), name="localizer")
    children.python(REPORTER, str(flag), name="reporter")
    run = run_of(["diagnostics"])
    _ready(run, "node:/r2/localizer", "node:/tools/diag")
    run.observe(2.0)
    flag.write_text("1")
    wait_for(lambda: (run.step(), "node:/r2/localizer" not in run.G)[1], timeout=15, period=PERIOD)
    found = run.until(lambda a: a.plugin == "diagnostics", 15.0)
    assert found, "no diagnostics alert"
    assert (found[0].member, found[0].severity, found[0].data["mapped_by"]) == (
        "node:/r2/localizer", "error", "name")
    assert not any(a.member == "node:/tools/diag" for a in run.alerts)


SERVER = """
import os, sys, time
import rclpy
from rclpy.qos import qos_profile_system_default
from rclpy.service_introspection import ServiceIntrospectionState
from std_srvs.srv import Trigger
flag = sys.argv[1]
rclpy.init()
n = rclpy.create_node('planner')
def plan(req, resp):
    time.sleep(6.0 if os.path.exists(flag) else 0.05)
    resp.success = True
    return resp
srv = n.create_service(Trigger, '/plan', plan)
srv.configure_introspection(n.get_clock(), qos_profile_system_default, ServiceIntrospectionState.METADATA)
rclpy.spin(n)
"""

CLIENT = """
import rclpy
from std_srvs.srv import Trigger
rclpy.init()
n = rclpy.create_node('bt_navigator')
cli = n.create_client(Trigger, '/plan')
pending = [None]
def call():
    if cli.service_is_ready() and (pending[0] is None or pending[0].done()):
        pending[0] = cli.call_async(Trigger.Request())
n.create_timer(0.5, call)
rclpy.spin(n)
"""


def test_services_waiting_client_names_the_slow_server(children, tmp_path, run_of):
    flag = tmp_path / "slow"
    children.python(SERVER, str(flag), name="planner")
    children.python(CLIENT, name="bt")
    run = run_of(["services"])
    _ready(run, "node:/planner", "node:/bt_navigator", "service:/plan")
    wait_for(lambda: (run.step(), _theta(run, "service:/plan")["calls_per_s"] > 0)[1], timeout=20,
             period=PERIOD)
    a = _sick_after_healthy(run, flag, "services", "node:/bt_navigator", healthy_s=6.0, symptom="waiting")
    assert (a.data["service"], a.data["server"], a.data["client"]) == (
        "service:/plan", "node:/planner", "node:/bt_navigator"), a
    assert a.data["waited_s"] >= 2.0 and a.data["via"] == "introspection"
    assert 0 < _theta(run, "service:/plan")["wait_s"] < 7.0


def test_a_service_slow_from_its_first_call_is_not_waited_on(children, tmp_path, run_of):
    flag = tmp_path / "slow"
    flag.write_text("1")  # it answers in 6 s from the start: its normal
    children.python(SERVER, str(flag), name="planner")
    children.python(CLIENT, name="bt")
    run = run_of(["services"])
    _ready(run, "node:/planner", "node:/bt_navigator", "service:/plan")
    wait_for(lambda: (run.step(), _theta(run, "service:/plan")["waiting"] > 0)[1], timeout=20, period=PERIOD)
    answered, end = [], time.monotonic() + 16.0  # two calls of 6 s, the first before any answer
    while time.monotonic() < end:
        run.step()
        answered.append(_theta(run, "service:/plan")["response_ms"])
        time.sleep(PERIOD)
    assert max(x for x in answered if not math.isnan(x)) > 5000.0  # it was measured answering slowly
    assert [a for a in run.alerts if a.plugin == "services"] == []


ACTION_SERVER = """
import rclpy
from rclpy.action import ActionServer
from test_msgs.action import Fibonacci
rclpy.init()
n = rclpy.create_node('planner', namespace='/nav')
def execute(goal):
    goal.succeed()
    return Fibonacci.Result()
ActionServer(n, Fibonacci, 'compute_path', execute)
rclpy.spin(n)
"""

ACTION_CLIENT = """
import os, sys
import rclpy
from rclpy.action import ActionClient
from test_msgs.action import Fibonacci
flag = sys.argv[1]
rclpy.init()
n = rclpy.create_node('bt_navigator', namespace='/nav')
client = ActionClient(n, Fibonacci, 'compute_path')
def tick():
    if os.path.exists(flag):  # as Nav2's behaviour tree says it, the action named relative
        n.get_logger().error('Timed out while waiting for action server compute_path to acknowledge goal')
    elif client.server_is_ready():
        client.send_goal_async(Fibonacci.Goal(order=3))
n.create_timer(0.5, tick)
rclpy.spin(n)
"""


def test_an_action_client_logging_about_its_action_names_the_server(children, tmp_path, run_of):
    flag = tmp_path / "stuck"
    children.python(ACTION_SERVER, name="planner")
    children.python(ACTION_CLIENT, str(flag), name="bt")
    run = run_of(["services"])
    _ready(run, "node:/nav/planner", "node:/nav/bt_navigator", "action:/nav/compute_path")
    a = _sick_after_healthy(run, flag, "services", "node:/nav/bt_navigator", healthy_s=4.0, symptom="waiting")
    assert (a.severity, a.data["via"], a.data["service"], a.data["server"]) == (
        "error", "log", "action:/nav/compute_path", "node:/nav/planner"), a


FOLLOWER = """
import os, sys, time
import rclpy
from rclpy.action import ActionServer
from test_msgs.action import Fibonacci
flag = sys.argv[1]
rclpy.init()
n = rclpy.create_node('follower', namespace='/nav')
def execute(goal):  # 4 s a goal, feedback every 0.2 s; stuck (no feedback, no end) once flagged
    for k in range(20):
        while os.path.exists(flag):
            time.sleep(0.1)
        goal.publish_feedback(Fibonacci.Feedback(sequence=[k]))
        time.sleep(0.2)
    goal.succeed()
    return Fibonacci.Result()
ActionServer(n, Fibonacci, 'follow_path', execute)
rclpy.spin(n)
"""

MISSION = """
import rclpy
from rclpy.action import ActionClient
from test_msgs.action import Fibonacci
rclpy.init()
n = rclpy.create_node('mission', namespace='/nav')
client = ActionClient(n, Fibonacci, 'follow_path')
busy = []
def done(_f):
    busy.clear()
def accepted(f):
    f.result().get_result_async().add_done_callback(done)
def tick():  # a goal at a time, 2 s apart
    if not busy and client.server_is_ready():
        busy.append(1)
        client.send_goal_async(Fibonacci.Goal(order=3)).add_done_callback(accepted)
n.create_timer(2.0, tick)
rclpy.spin(n)
"""


def test_a_goal_executing_without_feedback_is_a_stall_of_its_action(children, tmp_path, run_of):
    flag = tmp_path / "stuck"
    children.python(FOLLOWER, str(flag), name="follower")
    children.python(MISSION, name="mission")
    run = run_of(["services"])
    _ready(run, "node:/nav/follower", "node:/nav/mission", "action:/nav/follow_path")
    # Two goals of 4 s with feedback: nothing; then the server stuck mid-goal.
    a = _sick_after_healthy(run, flag, "services", "action:/nav/follow_path", healthy_s=14.0,
                            symptom="goal_stalled", timeout=15.0)
    assert a.data["server"] == "node:/nav/follower" and a.data["quiet_s"] > 3.0, a
    assert a.member == "action:/nav/follow_path"


PUBLISHER = """
import os, sys, time
import rclpy
from std_msgs.msg import String
name, flag = sys.argv[1], sys.argv[2]
rclpy.init()
n = rclpy.create_node(name)
pub = n.create_publisher(String, '/cmd_vel', 10)
def tick():
    if os.path.exists(flag) and int(time.monotonic() * 10) % 5:
        return  # one tick in five: 2 Hz
    pub.publish(String(data=name))
n.create_timer(0.1, tick)
rclpy.spin(n)
"""


def test_publisher_rates_of_a_two_publisher_topic_show_which_one_slowed(children, tmp_path, run_of):
    flag = tmp_path / "slow"
    children.python(PUBLISHER, "teleop", str(tmp_path / "never"), name="teleop")
    children.python(PUBLISHER, "nav", str(flag), name="nav")
    run = run_of(["topic_rate"])  # the collector is what is tested here
    _ready(run, "node:/teleop", "node:/nav", "topic:/cmd_vel")

    def rates():
        run.step()
        return run.G.nodes["topic:/cmd_vel"].get("publisher_rates") or {}

    both = wait_for(lambda: (r := rates()) and len(r) == 2 and min(r.values()) > 7 and r, timeout=20,
                    period=PERIOD)
    assert all(7.0 <= hz <= 12.0 for hz in both.values()), both
    flag.touch()
    time.sleep(1.0)
    after = wait_for(lambda: (r := rates()) and r.get("node:/nav", 99) < 3.5 and r, timeout=15, period=PERIOD)
    assert 7.0 <= after["node:/teleop"] <= 12.0, after
    # the nodes' own output rates say the same
    assert _node(run, "node:/nav")["sent_hz"] < 3.5 <= 7.0 <= _node(run, "node:/teleop")["sent_hz"]


TRANSFORMS = """
import os, sys
import rclpy
from rclpy.duration import Duration
from geometry_msgs.msg import TransformStamped
name, flag = sys.argv[1], sys.argv[2]
rclpy.init()
n = rclpy.create_node(name)
pub = n.create_publisher(TransformStamped, '/tf', 10)
def tick():  # one of /tf's publishers; its stamps 1 s old once the flag exists (a frozen filter)
    m = TransformStamped()
    lag = Duration(seconds=1.0) if os.path.exists(flag) else Duration()
    m.header.stamp, m.header.frame_id, m.child_frame_id = (n.get_clock().now() - lag).to_msg(), 'map', name
    pub.publish(m)
n.create_timer(0.05, tick)
rclpy.spin(n)
"""


def test_stale_stamps_of_one_of_two_publishers_are_named(children, tmp_path, run_of):
    flag = tmp_path / "frozen"
    children.python(TRANSFORMS, "odometry", str(tmp_path / "never"), name="odometry")
    children.python(TRANSFORMS, "slam", str(flag), name="slam")
    run = run_of(["message_age"])
    _ready(run, "node:/odometry", "node:/slam", "topic:/tf")

    def ages():
        run.step()
        return run.G.nodes["topic:/tf"].get("publisher_ages") or {}

    both = wait_for(lambda: len(a := ages()) == 2 and a, timeout=20, period=PERIOD)
    assert all(-50.0 < ms < 50.0 for ms in both.values()), both
    a = _sick_after_healthy(run, flag, "message_age", "topic:/tf", healthy_s=6.0, symptom="stale")
    assert a.data["publishers"] == ["node:/slam"], a  # the other publisher's stamps are on time
    after = ages()
    assert after["node:/slam"] > 500.0 and after["node:/odometry"] < 50.0, after


def _theta(run, member):
    return theta_dict(run.G.nodes[member]["kind"], run.G.nodes[member]["theta"])


def _node(run, member):
    return _theta(run, member)


def test_without_rcl_gids_the_ages_are_still_measured(children, tmp_path, run_of):
    """Where the rcl take is unavailable (another rmw layout), rclpy takes: no publisher rates,
    the rest as before, header stamps included."""
    flag = tmp_path / "lag"
    flag.touch()
    children.python(STAMPED, str(flag), name="imu")
    run = run_of(["topic_rate"])
    run.collector.topics.rcl.available = False
    _ready(run, "topic:/robot/imu")
    wait_for(lambda: (run.step(), _theta(run, "topic:/robot/imu")["stamp_age_ms"] > 280)[1], timeout=20,
             period=PERIOD)
    th = _theta(run, "topic:/robot/imu")
    assert 15.0 <= th["rate_hz"] <= 25.0 and th["stamp_age_ms"] < 400.0, th
    assert "publisher_rates" not in run.G.nodes["topic:/robot/imu"]
    assert _node(run, "node:/robot/imu_driver")["sent_hz"] == th["rate_hz"]  # the only publisher
