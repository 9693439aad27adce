"""The collector against real rclpy nodes in subprocesses (several nodes per process, a crash)."""

from __future__ import annotations

import os
import signal
import sys
import time

import psutil
import pytest

from stream_viz.collect.collector import Collector
from stream_viz.model.graph import flow_edges
from stream_viz.model.queries import predecessors
from stream_viz.model.theta import theta_dict
from stream_viz.testing import wait_for

pytestmark = pytest.mark.ros

HAVE_ACTIONS = True
try:
    import test_msgs.action  # noqa: F401  (ros-jazzy-test-msgs: the only action type around)
except ImportError:
    HAVE_ACTIONS = False

# One process, six nodes: a 20 Hz topic, a service + client, an action server + client,
# /rosout warnings and a /diagnostics ERROR.
MANY = """
import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from std_msgs.msg import String
from std_srvs.srv import Trigger
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
HAVE_ACTIONS = {have_actions}
rclpy.init()
talker = Node('talker', namespace='/ns')
listener = Node('listener')
server = Node('server')
diag = Node('diag_pub')
nodes = [talker, listener, server, diag]
pub = talker.create_publisher(String, '/chatter', 10)
listener.create_subscription(String, '/chatter', lambda m: None, 10)
server.create_service(Trigger, '/trig', lambda req, res: res)
listener.create_client(Trigger, '/trig')
talker.create_timer(0.05, lambda: pub.publish(String(data='hello')))
talker.create_timer(0.5, lambda: talker.get_logger().warn('battery low'))
dpub = diag.create_publisher(DiagnosticArray, '/diagnostics', 10)
def send_diag():
    st = DiagnosticStatus(level=DiagnosticStatus.ERROR, name='diag_pub: motor', message='overheat',
                          hardware_id='motor1', values=[KeyValue(key='temp', value='99')])
    dpub.publish(DiagnosticArray(status=[st]))
diag.create_timer(0.5, send_diag)
if HAVE_ACTIONS:
    from rclpy.action import ActionClient, ActionServer
    from test_msgs.action import Fibonacci
    fs, fc = Node('fib_server'), Node('fib_client')
    ActionServer(fs, Fibonacci, '/fib', lambda goal: Fibonacci.Result())
    ActionClient(fc, Fibonacci, '/fib')
    nodes += [fs, fc]
ex = SingleThreadedExecutor()
for n in nodes:
    ex.add_node(n)
print('ready', flush=True)
ex.spin()
"""

VICTIM = """
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
n = Node('victim')
p = n.create_publisher(String, '/victim_out', 10)
n.create_timer(0.1, lambda: p.publish(String(data='v')))
rclpy.spin(n)
"""


def _ids(G, kinds=("node", "topic", "service", "action")):
    return {m for m, k in G.nodes(data="kind") if k in kinds}


def test_collector_real_system(children, ros_domain):
    many = children.python(MANY.replace("{have_actions}", str(HAVE_ACTIONS)), name="many")
    victim = children.python(VICTIM, name="victim")
    want_nodes = {"node:/ns/talker", "node:/listener", "node:/server", "node:/diag_pub", "node:/victim"}
    if HAVE_ACTIONS:
        want_nodes |= {"node:/fib_server", "node:/fib_client"}
    want = want_nodes | {"topic:/chatter", "topic:/diagnostics", "topic:/victim_out", "service:/trig"}
    if HAVE_ACTIONS:
        want.add("action:/fib")
    want_edges = {
        ("node:/ns/talker", "topic:/chatter", "pub"), ("topic:/chatter", "node:/listener", "sub"),
        ("node:/listener", "node:/server", "send"), ("node:/diag_pub", "topic:/diagnostics", "pub"),
        ("node:/victim", "topic:/victim_out", "pub"),
    }
    if HAVE_ACTIONS:
        want_edges.add(("node:/fib_client", "node:/fib_server", "send"))
    with Collector(ros_domain) as col:
        def complete():
            # Discovery is eventual: an action's client endpoints can arrive after its server's.
            s = col.sample()
            G = s.graph
            ok = _ids(G) == want and all(G.nodes[n]["pid_status"] == "confirmed" for n in want_nodes)
            ok = ok and set(flow_edges(G)) == want_edges
            return s if ok else None
        try:
            s = wait_for(complete, timeout=20, period=0.3)
        except TimeoutError:
            got = col.sample().graph
            pytest.fail(f"model never complete: have {sorted(_ids(got))} {sorted(flow_edges(got))}, "
                        f"want {sorted(want)} {sorted(want_edges)}")
        # complete() demanded exact members and edges: our own observer, /rosout, parameter
        # services and action internals are hidden.
        G = s.graph
        assert G.edges["node:/listener", "node:/server", 0]["services"] == ["/trig"]
        if HAVE_ACTIONS:
            assert G.edges["node:/fib_client", "node:/fib_server", 0]["actions"] == ["/fib"]
        # Node -> pid, several nodes in one process.
        for n in want_nodes - {"node:/victim"}:
            assert G.nodes[n]["pid"] == many.pid, n
        assert G.nodes["node:/victim"]["pid"] == victim.pid
        # Process tree: node -> its process -> pytest (us) -> ... -> a top.
        path = ["node:/ns/talker"]
        while True:
            up = predecessors(G, path[-1], layer=1)
            if not up:
                break
            assert len(up) == 1
            path.append(up[0])
        assert path[1:3] == [f"process:{many.pid}", f"process:{os.getpid()}"]
        assert path[-1] == "root" or G.nodes[path[-1]].get("name")
        qos = G.nodes["topic:/chatter"]["qos"]
        assert {(q["node"], q["role"], q["reliability"], q["durability"]) for q in qos} == {
            ("/ns/talker", "pub", "reliable", "volatile"), ("/listener", "sub", "reliable", "volatile")}

        # Rate of the 20 Hz topic once the window has filled, and the log/diag events.
        time.sleep(2.5)
        s = col.sample()
        rate = theta_dict("topic", s.graph.nodes["topic:/chatter"]["theta"])["rate_hz"]
        assert 12.0 <= rate <= 28.0, rate
        # Jazzy's wheels give both rcl paths: no fallback to say (messages were taken, and checked)
        assert col.limits() == {}
        proc = theta_dict("process", s.graph.nodes[f"process:{many.pid}"]["theta"])
        assert proc["rss_mb"] > 10 and proc["threads"] >= 1
        logs = [e for e in s.events if e.kind == "log"]
        assert any(e.member == "node:/ns/talker" and e.level == "warn" and e.text == "battery low"
                   for e in logs), logs
        diags = [e for e in s.events if e.kind == "diag"]
        assert any(e.member == "node:/diag_pub" and e.level == "error" and e.data["hardware_id"] == "motor1"
                   and e.data["values"] == {"temp": "99"} for e in diags), diags

        # A SIGKILLed node stays ~20 s in DDS: the collector must notice from the OS within 2 samples.
        os.killpg(victim.pid, signal.SIGKILL)
        time.sleep(0.3)
        exits = []
        for _ in range(2):
            s = col.sample()
            exits += [e for e in s.events if e.kind == "exit"]
            if exits:
                break
            time.sleep(0.5)
        assert {e.member for e in exits} == {"node:/victim", f"process:{victim.pid}"}
        assert all(e.level == "error" for e in exits)
        if "node:/victim" in s.graph:  # still listed by DDS: kept, marked dead
            assert s.graph.nodes["node:/victim"]["alive"] is False
            assert s.graph.nodes[f"process:{victim.pid}"]["alive"] is False
        s = col.sample()
        assert not [e for e in s.events if e.kind == "exit"]  # reported once
        assert s.graph.nodes["node:/ns/talker"]["alive"] is True


PHOENIX = """
import rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
n = Node('phoenix')
p = n.create_publisher(String, '/ashes', 10)
n.create_timer(0.1, lambda: p.publish(String(data='v')))
try:
    rclpy.spin(n)
except KeyboardInterrupt:
    pass
"""


def test_a_node_restarted_under_its_name_is_found_in_its_new_process(children, ros_domain):
    """The /rosout gids are read only when due: a restart must still move the node to its new pid."""
    first = children.python(PHOENIX, name="phoenix")
    with Collector(ros_domain) as col:
        def on(pid):
            def check():
                s = col.sample()
                node = s.graph.nodes.get("node:/phoenix")
                return s if node is not None and node["pid"] == pid else None
            return check
        wait_for(on(first.pid), timeout=20, period=0.3)
        # No periodic read from here on: what finds the new process is the exit and the change.
        col.gids.every_s = 3600.0
        # Steady state: the graph's /rosout endpoints are not read every sample.
        reads = col.gids.reads
        for _ in range(4):
            col.sample()
            time.sleep(0.3)
        assert col.gids.reads == reads
        # Restarted at once under the same name (a launch respawn): found in the new process.
        children.end(first)
        second = children.python(PHOENIX, name="phoenix")
        s = wait_for(on(second.pid), timeout=15, period=0.5)
        assert s.graph.nodes["node:/phoenix"]["pid_status"] == "confirmed"


# An action server whose goals take 0.3 s, and a client that sends one after the other: the
# server's status array lists every goal it remembers, so it grows past the first bytes the
# collector copies of most messages.
GOALS = """
import os, sys, time, rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from test_msgs.action import Fibonacci
rclpy.init()
server, client = Node("mover"), Node("mission")
def execute(goal):
    time.sleep(0.3)
    goal.succeed()
    return Fibonacci.Result()
ActionServer(server, Fibonacci, "/move", execute)
ac = ActionClient(client, Fibonacci, "/move")
ex = MultiThreadedExecutor()
ex.add_node(server)
ex.add_node(client)
import threading
threading.Thread(target=ex.spin, daemon=True).start()
ac.wait_for_server()
while not os.path.exists(sys.argv[1]):  # the test says when the monitor follows the status topic
    time.sleep(0.05)
for k in range(6):
    sent = ac.send_goal_async(Fibonacci.Goal(order=k))
    while not sent.done():
        time.sleep(0.01)
    done = sent.result().get_result_async()
    while not done.done():
        time.sleep(0.01)
    print("goal done", k, flush=True)
    time.sleep(0.7)
time.sleep(60)
"""


@pytest.mark.skipif(not HAVE_ACTIONS, reason="test_msgs (ros-jazzy-test-msgs) is not installed")
def test_every_goal_that_ends_is_a_goal_event_of_its_server(children, ros_domain, tmp_path):
    go = tmp_path / "go"
    proc = children.python(GOALS, str(go), name="goals")
    events = []
    with Collector(ros_domain) as col:
        # The first goal is sent once the collector follows the status topic (and a sample later,
        # its subscription matched): a goal that ended before then is not seen, by design.
        status = "/move/_action/status"
        wait_for(lambda: (events.extend(col.sample().events), status in col.topics._watches)[1],
                 timeout=20, period=0.5)
        for _ in range(2):
            time.sleep(0.5)
            events += col.sample().events
        go.touch()
        end = time.monotonic() + 40.0
        while time.monotonic() < end and len([e for e in events if e.kind == "goal"]) < 6:
            events += col.sample().events
            time.sleep(0.5)
    goals = [e for e in events if e.kind == "goal"]
    errors = [e.text for e in events if e.kind == "observe_error"]
    log_path = children.workdir / f"goals_{children.procs.index(proc)}.log"
    wait_for(lambda: "goal done 5" in log_path.read_text(), timeout=10)
    assert [(e.member, e.data["action"], e.data["status"]) for e in goals] == [
        ("node:/mover", "/move", "succeeded")] * 6, (goals, errors)
    assert errors == []


# A server whose one goal executes for 8 s, sent before anyone looks.
LONG_GOAL = """
import time, rclpy
from rclpy.action import ActionClient, ActionServer
from rclpy.executors import MultiThreadedExecutor
from rclpy.node import Node
from test_msgs.action import Fibonacci
rclpy.init()
server, client = Node("follower"), Node("mission")
def execute(goal):
    time.sleep(8.0)
    goal.succeed()
    return Fibonacci.Result()
ActionServer(server, Fibonacci, "/leg", execute)
ac = ActionClient(client, Fibonacci, "/leg")
ex = MultiThreadedExecutor()
ex.add_node(server)
ex.add_node(client)
import threading
threading.Thread(target=ex.spin, daemon=True).start()
ac.wait_for_server()
ac.send_goal_async(Fibonacci.Goal(order=1))
print("sent", flush=True)
time.sleep(60)
"""


@pytest.mark.skipif(not HAVE_ACTIONS, reason="test_msgs (ros-jazzy-test-msgs) is not installed")
def test_a_goal_executing_before_the_collector_looked_ends_as_a_goal_event(children, ros_domain, tmp_path):
    # The status array is latched: the collector's reader gets the executing goal when it matches,
    # so the end is a change it sees (a volatile reader got the end first and could not date it).
    proc = children.python(LONG_GOAL, name="leg")
    log_path = children.workdir / f"leg_{children.procs.index(proc)}.log"
    wait_for(lambda: "sent" in log_path.read_text(), timeout=20)
    time.sleep(1.0)  # executing before the collector starts
    events = []
    with Collector(ros_domain) as col:
        end = time.monotonic() + 20.0
        while time.monotonic() < end and not any(e.kind == "goal" for e in events):
            events += col.sample().events
            time.sleep(0.5)
    goals = [(e.member, e.data["action"], e.data["status"]) for e in events if e.kind == "goal"]
    assert goals == [("node:/follower", "/leg", "succeeded")], goals


# A node that adds a publisher when told (a file appears) and removes it when told again.
GROWER = """
import os, sys, time, rclpy
from rclpy.node import Node
from std_msgs.msg import String
rclpy.init()
n = Node('grower')
def wait(path):
    while not os.path.exists(path):
        time.sleep(0.05)
wait(sys.argv[1] + '/add')
p = n.create_publisher(String, '/grown', 10)
wait(sys.argv[1] + '/remove')
n.destroy_publisher(p)
time.sleep(60)
"""


def test_the_graph_is_read_again_when_it_changed_and_only_then(children, ros_domain, tmp_path):
    """The graph change signal (rcl's graph guard condition) is set up on a real node; the graph's
    structure is read again when a publisher comes or goes, seen at the first sample after the
    graph shows it (or the one after: the signal follows the graph's update), and reused between."""
    children.python(GROWER, str(tmp_path), name="grower")
    with Collector(ros_domain) as col:
        assert col.structure.signal.available, col.structure.signal.why
        col.structure.every_s = 3600.0  # the backstop read aside: only the signal reads again
        wait_for(lambda: "node:/grower" in col.sample().graph, timeout=20, period=0.3)
        listed, modelled, reads = [], [], []
        for i in range(36):
            if i in (8, 22):
                (tmp_path / ("add" if i == 8 else "remove")).touch()
            listed.append(any(t == "/grown" for t, _ in col.node.get_topic_names_and_types()))
            modelled.append("topic:/grown" in col.sample().graph)
            reads.append(col.structure.reads)
            time.sleep(0.25)
    pattern = "".join("LM"[m] if g else "-m"[m] for g, m in zip(listed, modelled, strict=True))
    assert pattern.startswith("-" * 8) and pattern.endswith("-" * 6), pattern  # came, and went
    assert "M" * 6 in pattern, pattern
    # The model follows the graph within a sample (either may see a change first).
    for i, m in enumerate(modelled):
        assert m in listed[max(0, i - 1): i + 2], (i, pattern, reads)
    # 36 samples: read again at each change (a change can take a few graph updates), not each sample.
    assert reads[-1] - reads[0] <= 8, (reads, pattern)
    assert reads[-1] > reads[0], (reads, pattern)


CONTAINED = """
import rclpy
from std_msgs.msg import String
rclpy.init()
n = rclpy.create_node('contained')
pub = n.create_publisher(String, '/contained/out', 10)
n.create_timer(0.1, lambda: pub.publish(String(data='x')))
rclpy.spin(n)
"""


def test_a_node_in_a_container_s_pid_namespace_is_mapped_to_its_process(children, ros_domain, tmp_path):
    """A container with its own PID namespace and the host's network (Docker's default with
    ``--network host``): the node's GUID carries its PID in there (1), not ours. The collector
    maps it to its process as we see it, confirmed, and notices from the OS when it is killed."""
    script = tmp_path / "contained.py"
    script.write_text(CONTAINED)
    outer = children.run(["unshare", "-r", "-p", "--fork", "--mount-proc", sys.executable, str(script)],
                         name="container")
    try:
        proc = wait_for(lambda: [c for c in psutil.Process(outer.pid).children(recursive=True)
                                 if c.name().startswith("python")], timeout=10)[0]
    except (TimeoutError, psutil.Error):
        pytest.skip(f"cannot start a process in a new PID namespace here: {children.workdir}")
    with Collector(ros_domain) as col:
        def mapped():
            G = col.sample().graph
            return G if G.nodes.get("node:/contained", {}).get("pid_status") == "confirmed" else None
        G = wait_for(mapped, timeout=20, period=0.3)
        assert G.nodes["node:/contained"]["pid"] == proc.pid, (proc.pid, G.nodes["node:/contained"])
        proc.kill()
        exits = wait_for(lambda: [e for e in col.sample().events if e.kind == "exit"], timeout=5, period=0.3)
        # (its container's `unshare` may end in the same sample: the namespace's init is gone)
        assert {"node:/contained", f"process:{proc.pid}"} <= {e.member for e in exits}, exits
        assert [e.level for e in exits if e.member == "node:/contained"] == ["error"], exits


WITHOUT_ROSOUT = """
import rclpy
from std_msgs.msg import String
rclpy.init()
n = rclpy.create_node('quiet_one', enable_rosout=False)
pub = n.create_publisher(String, '/quiet/out', 10)
n.create_timer(0.1, lambda: pub.publish(String(data='x')))
rclpy.spin(n)
"""


def test_a_node_without_rosout_is_mapped_to_its_process(children, ros_domain):
    """A node created with ``enable_rosout=False`` (as ``--disable-rosout-logs`` does) has no
    /rosout publisher to map it by; its /parameter_events publisher carries the same prefix."""
    quiet = children.python(WITHOUT_ROSOUT, name="quiet")
    with Collector(ros_domain) as col:
        def mapped():
            G = col.sample().graph
            return G if G.nodes.get("node:/quiet_one", {}).get("pid_status") == "confirmed" else None
        G = wait_for(mapped, timeout=20, period=0.3)
    assert G.nodes["node:/quiet_one"]["pid"] == quiet.pid
