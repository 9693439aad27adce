"""A sick, churning, odd system: the real monitor keeps sampling and exits cleanly.

Assertions are on "the monitor keeps producing samples and exits 0 with its outputs", never on
timings (figures for the docs come from ``bench/bench_load.py``).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import sys
import time

import psutil
import pytest

from stream_viz.collect.processes import MachineSampler, ProcessSampler
from stream_viz.testing import TALKER, wait_for
from tests.robust.common import (
    MemoryLimitGroup,
    QuotaGroup,
    db_rows,
    monitor_cmd,
    report,
    run,
    sample_times,
    snapshot_has,
)

pytestmark = pytest.mark.ros

CHURN = """
import subprocess, sys, time, rclpy
rclpy.init()
host = rclpy.create_node("churn_host")
SHORT = "import rclpy, time; rclpy.init(); n = rclpy.create_node(sys.argv[1]); time.sleep(0.4)"
k, kids, nodes = 0, [], []
end = time.monotonic() + float(sys.argv[1])
while time.monotonic() < end:
    k += 1
    # A node appears and another vanishes every 0.1 s (600 per minute) in this process...
    nodes.append(rclpy.create_node(f"flicker_{k}"))
    if len(nodes) > 3:
        nodes.pop(0).destroy_node()
    # ...and a short-lived process with a node starts every 0.5 s (120 per minute).
    if k % 5 == 0:
        kids.append(subprocess.Popen([sys.executable, "-c", "import sys\\n" + SHORT, f"blink_{k}"]))
    kids = [p for p in kids if p.poll() is None]
    time.sleep(0.1)
print("made", k, "nodes", flush=True)
"""


def test_churning_nodes_and_processes(children, tmp_path):
    children.python(TALKER, name="talker")
    children.python(CHURN, "25", name="churn")
    rrd, rep, db = tmp_path / "m.rrd", tmp_path / "r.json", tmp_path / "a.sqlite"
    out = run(monitor_cmd("--duration", "20", "--save", str(rrd), "--report", str(rep), "--db", str(db)),
              children.env)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    r = report(rep)
    ids = {m["id"] for m in r["members"]}
    assert "node:/talker" in ids
    flickers = {i for i in ids if i.startswith("node:/flicker_") or i.startswith("node:/blink_")}
    assert len(flickers) >= 10, sorted(ids)  # it saw the churn (seen members are remembered)
    assert len(sample_times(rrd)) >= 8  # sampled all along (one per ~1 s period)
    assert len(db_rows(db, "SELECT id FROM snapshots")) >= 5  # the structure changed and was kept


def test_a_long_run_on_a_churning_system_forgets_what_vanished_long_ago(children, tmp_path):
    """The real monitor pipeline in this process: vanished members leave the model and its
    history after ``forget_gone_s``, so the run does not grow with every member ever seen."""
    from dataclasses import replace

    from stream_viz.config import load_config
    from stream_viz.monitor import Monitor
    from stream_viz.progress import Progress

    children.python(TALKER, name="talker")
    children.python(CHURN, "12", name="churn")
    cfg = load_config(None)
    cfg = replace(cfg, monitor=replace(cfg.monitor, forget_gone_s=3.0))
    mon = Monitor(cfg, db=tmp_path / "a.sqlite", viewer="none", domain_id=int(children.env["ROS_DOMAIN_ID"]),
                  progress=Progress(open(os.devnull, "w")))
    ever: set[str] = set()
    try:
        for _ in range(16):
            now = time.time()  # sample times are wall-clock times; the step's own length aside
            mon.step()
            ever |= set(mon.seen)
            old = [m for m, a in mon.seen.nodes(data=True) if a.get("gone") and now - a["gone_at"] > 5.0]
            assert old == [], old  # nothing stays much longer than the retention (a period of slack)
            assert set(mon.history) <= set(mon.seen), "history of forgotten members"
            time.sleep(1.0)
        assert "node:/talker" in mon.seen and not mon.seen.nodes["node:/talker"].get("gone")
        flickers = {m for m in ever if m.startswith(("node:/flicker_", "node:/blink_"))}
        assert len(flickers) >= 20  # it did see the churn ...
        assert len(flickers & set(mon.seen)) < len(flickers) / 2  # ... and forgot most of it
    finally:
        mon.close()


@pytest.mark.parametrize("procfs", [True, False], ids=["procfs", "psutil"])
def test_a_process_that_exits_between_listing_and_reading(children, procfs):
    """A process gone when read is reported as gone, never raised (real processes)."""
    p = children.run([sys.executable, "-c", "import time; time.sleep(60)"], name="short")
    s = ProcessSampler(procfs=procfs)
    first = s.sample([p.pid])
    assert p.pid in first.processes
    children.end(p, signal.SIGKILL)
    second = s.sample([p.pid])  # listed (as a node's pid) but gone when read
    assert p.pid in second.exited and p.pid not in second.processes
    assert "exited" in second.errors[p.pid]
    q = children.run([sys.executable, "-c", "pass"], name="gone")
    q.wait(10)
    third = ProcessSampler(procfs=procfs).sample([q.pid, 2**22 + 7])  # never tracked: ended / never existed
    assert set(third.errors) == {q.pid, 2**22 + 7} and third.processes == {}


@pytest.mark.skipif((os.cpu_count() or 1) < 2, reason="needs 2 CPUs")
def test_a_host_s_cpu_counts_the_cores_its_processes_may_run_on(children):
    """A robot held to one core (a cpuset, a taskset) by a busy loop of its own: that core is
    full, whatever the other cores do."""
    busy = children.run([sys.executable, "-c", "import os; os.sched_setaffinity(0, {1})\nwhile True: pass"],
                        name="busy")
    m = MachineSampler()
    wait_for(lambda: os.sched_getaffinity(busy.pid) == {1}, 5.0)
    m.sample([busy.pid])
    time.sleep(1.0)
    got = m.sample([busy.pid])
    assert got["cpus"] == 1.0 and got["machine_cpu_percent"] >= 80.0, got
    assert m.sample()["cpus"] == float(psutil.cpu_count())  # no process known: every core


def test_a_host_s_cpu_is_its_quota_s_use_when_a_cgroup_quota_binds(children):
    """A robot in a container held to half a CPU (a cgroup quota) by a busy loop of its own: the
    quota is full and its tasks wait for the next period, whatever the machine's cores do."""
    try:
        group = QuotaGroup(0.5, f"stream-viz-sampler-{os.getpid()}")
    except OSError as e:
        pytest.skip(f"cannot make a cgroup with a CPU quota here: {e}")
    busy = children.run([sys.executable, "-c", "while True: pass"], name="busy")
    try:
        group.add(busy.pid)
        m = MachineSampler()
        m.sample([busy.pid])
        time.sleep(1.0)
        got = m.sample([busy.pid])
    finally:
        children.end(busy, signal.SIGKILL)
        group.close()
    assert got["cpus"] == 0.5 and got["machine_cpu_percent"] >= 90.0, got
    assert got["cpu_pressure_percent"] >= 50.0, got  # throttled in most periods


# Once the file argv[1] exists: takes argv[2] MiB of memory, writes argv[3] MiB to the file argv[4]
# (page cache, synced), creates the file argv[5] and waits.
HOLD = """
import os, sys, time
while not os.path.exists(sys.argv[1]):
    time.sleep(0.05)
chunk = bytearray(int(sys.argv[2]) * 2**20)  # zero-filled: its pages are touched
with open(sys.argv[4], "wb") as f:
    for _ in range(int(sys.argv[3])):
        f.write(os.urandom(2**20))
    f.flush()
    os.fsync(f.fileno())
open(sys.argv[5], "w").close()
time.sleep(120)
"""


@pytest.mark.parametrize(("held", "written"), [(184, 0), (16, 184)])
def test_memory_in_use_is_the_container_s_share_of_its_limit(children, tmp_path, held, written):
    """A robot in a container limited to 200 MiB (``docker --memory``): the host's memory in use is
    the group's share of its limit, the machine's being far from full; file cache it wrote (which
    the kernel gives back before any OOM kill) does not count."""
    try:
        group = MemoryLimitGroup(200 * 2**20, f"stream-viz-mem-{os.getpid()}-{held}")
    except OSError as e:
        pytest.skip(f"cannot make a cgroup with a memory limit here: {e}")
    go, held_file = tmp_path / "go", tmp_path / "held"
    holder = children.run([sys.executable, "-c", HOLD, str(go), str(held), str(written),
                           str(tmp_path / "data"), str(held_file)], name="holder")
    try:
        group.add(holder.pid)
        go.touch()
        wait_for(held_file.exists, timeout=60, period=0.2)
        got = MachineSampler().sample([holder.pid])
    finally:
        children.end(holder, signal.SIGKILL)
        group.close()
    if written:  # 200 MiB charged to the group, nearly all of it cache
        assert got["machine_mem_percent"] < 90.0 and got.get("mem_limit_mb") in (None, 200.0), got
    else:
        assert got["mem_limit_mb"] == 200.0 and got["machine_mem_percent"] >= 90.0, got


# A node named argv[2] that, once the file argv[1] exists, ends with os._exit(argv[3]) (no ROS
# goodbye: DDS lists it until its lease ends, whatever the code) or, without argv[3], takes 10 MiB
# more every 20 ms until it is stopped.
HOG = """
import os, sys, time, rclpy
rclpy.init()
n = rclpy.create_node(sys.argv[2])
print("ready", flush=True)
while not os.path.exists(sys.argv[1]):
    rclpy.spin_once(n, timeout_sec=0.1)
if len(sys.argv) > 3:
    os._exit(int(sys.argv[3]))
chunks = []
while True:
    chunks.append(bytearray(10 * 2**20))  # zero-filled: its pages are touched
    time.sleep(0.02)
"""


@contextlib.contextmanager
def _two_nodes_limited(children, tmp_path):
    """Two nodes, ``hog`` and ``other``, in a container limited to 200 MiB (as ``docker --memory``);
    yields them and the file whose creation makes the hog eat memory past the limit."""
    try:
        group = MemoryLimitGroup(200 * 2**20, f"stream-viz-oom-{os.getpid()}")
    except OSError as e:
        pytest.skip(f"cannot make a cgroup with a memory limit here: {e}")
    go = tmp_path / "go"
    hog = children.python(HOG, str(go), "hog", name="hog")
    other = children.python(HOG, str(tmp_path / "never"), "other", name="other")
    try:
        group.add(hog.pid)
        group.add(other.pid)
        yield hog, other, go
    finally:
        children.end(hog, signal.SIGKILL)
        group.close()
    assert hog.wait(5) == -signal.SIGKILL


def _said_oom(by):
    """``other`` (killed from outside) exited as a crash, ``hog`` as killed by the OOM killer."""
    assert not by["node:/other"].data.get("oom_kill"), by["node:/other"]
    assert "OOM" not in by["node:/other"].text
    e = by["node:/hog"]
    assert e.level == "error" and e.data["oom_kill"] is True and e.data["memory_limit_mb"] == 200.0, e
    # "exited" where the exit code is not read (an agent), "was killed by SIGKILL" where it is
    said = ("exited", "was killed by SIGKILL")
    assert any(f"{how} with nodes /hog: killed by the OOM killer at its group's limit of 200 MB" in e.text
               for how in said), e.text
    assert e.data.get("exit_code", -9) == -9, e.data


def test_a_process_the_oom_killer_ended_is_said_so_and_another_kill_is_not(children, ros_domain, tmp_path):
    """Two nodes in a container limited to 200 MiB: one killed from outside (SIGKILL) exits as a
    crash; the other, past the limit, as killed by the OOM killer."""
    from stream_viz.collect.collector import Collector

    exits = []
    with _two_nodes_limited(children, tmp_path) as (_, other, go), Collector(ros_domain) as col:
        def confirmed():
            nodes = col.sample().graph.nodes
            return all(nodes.get(f"node:/{n}", {}).get("pid_status") == "confirmed" for n in ("hog", "other"))

        def ended():
            return [e for e in col.sample().events if e.kind == "exit"]
        wait_for(confirmed, timeout=20, period=0.3)
        other.kill()
        exits += wait_for(ended, timeout=10, period=0.3)
        go.touch()
        exits += wait_for(ended, timeout=20, period=0.3)
    _said_oom({e.member: e for e in exits})


def test_an_agent_says_a_process_of_its_host_the_oom_killer_ended(children, ros_domain, tmp_path):
    """The same on a computer of its own: its agent reads the OOM count, its report carries the kill
    (encoded and decoded as on the wire), and the monitor's exit event says it."""
    from stream_viz.collect.agent import Agent
    from stream_viz.collect.fastdds import decode_gid
    from stream_viz.collect.hostreport import decode, encode
    from stream_viz.collect.hosts import remote_exits
    from stream_viz.model.ids import node_fqn

    exits = []
    with _two_nodes_limited(children, tmp_path) as (hog, other, go), Agent(ros_domain, 0.5, "b") as agent:
        def prefixes():
            infos = agent.node.get_publishers_info_by_topic("/rosout")
            return {node_fqn(i.node_namespace, i.node_name): decode_gid(bytes(i.endpoint_gid)).prefix
                    for i in infos if i.node_name in ("hog", "other")}

        def mapped():
            r = decode(encode(agent.sample()))
            return r if {hog.pid, other.pid} <= set(r.participants.values()) else None
        before = wait_for(mapped, timeout=20, period=0.3)
        node_prefix = prefixes()

        def ended():
            nonlocal before
            now = decode(encode(agent.sample(), set(before.processes)), before)
            out, before = remote_exits(time.time(), "b", before, now, node_prefix), now
            return [e for e in out if e.member.startswith("node:")]
        other.kill()
        exits += wait_for(ended, timeout=10, period=0.3)
        go.touch()
        exits += wait_for(ended, timeout=20, period=0.3)
    _said_oom({e.member: e for e in exits})


def test_an_agent_says_how_a_process_of_its_host_ended(children, ros_domain, tmp_path):
    """On a computer of its own, a node whose process exits 0 without ROS's goodbye is no crash and
    one that exits 1 is: the agent reads the exit codes from the kernel and its report (encoded and
    decoded as on the wire) carries them to the monitor's exit events."""
    from stream_viz.collect.agent import Agent
    from stream_viz.collect.fastdds import decode_gid
    from stream_viz.collect.hostreport import decode, encode
    from stream_viz.collect.hosts import remote_exits
    from stream_viz.model.ids import node_fqn

    go = tmp_path / "go"
    ends = {name: children.python(HOG, str(go), name, code, name=name)
            for name, code in (("clean", "0"), ("failing", "1"))}
    exits = []
    with Agent(ros_domain, 0.5, "b") as agent:
        if agent.exits.reason is not None:
            pytest.skip(agent.exits.reason)

        def mapped():
            r = decode(encode(agent.sample()))
            return r if {p.pid for p in ends.values()} <= set(r.participants.values()) else None
        before = wait_for(mapped, timeout=20, period=0.3)
        infos = agent.node.get_publishers_info_by_topic("/rosout")
        node_prefix = {node_fqn(i.node_namespace, i.node_name): decode_gid(bytes(i.endpoint_gid)).prefix
                       for i in infos if i.node_name in ends}

        def both_ended():
            nonlocal before
            now = decode(encode(agent.sample(), set(before.processes)), before)
            exits.extend(e for e in remote_exits(time.time(), "b", before, now, node_prefix)
                         if e.member.startswith("node:"))
            before = now
            return len(exits) == 2
        go.touch()
        wait_for(both_ended, timeout=10, period=0.3)
    by = {e.member: e for e in exits}
    clean, failing = by["node:/clean"], by["node:/failing"]
    assert (clean.level, clean.data["exit_code"]) == ("info", 0), clean
    assert clean.text.endswith("on host b exited with code 0 with nodes /clean"), clean.text
    assert (failing.level, failing.data["exit_code"]) == ("error", 1), failing


RAISER = """
import os, sys, rclpy
rclpy.init()
n = rclpy.create_node("raiser")
def tick():
    if os.path.exists(sys.argv[1]):
        raise RuntimeError("calibration file is empty")
n.create_timer(0.1, tick)
print("ready", flush=True)
rclpy.spin(n)
"""


def test_an_agent_says_a_python_node_that_raised_ended_with_an_error(children, ros_domain, tmp_path):
    """On a computer of its own, a Python node's uncaught exception: rclpy sends its goodbye (DDS
    lists it no more), then the process exits 1. The monitor's exit event from the agent's report
    still names the node that left (`recently_left_prefixes`), and it is an error exit alone."""
    from stream_viz.collect.agent import Agent
    from stream_viz.collect.fastdds import decode_gid
    from stream_viz.collect.hostreport import decode, encode
    from stream_viz.collect.hosts import recently_left_prefixes, remote_exits
    from stream_viz.detect.exits import error_exits
    from stream_viz.model.ids import node_fqn

    go = tmp_path / "go"
    raiser = children.python(RAISER, str(go), name="raiser")
    with Agent(ros_domain, 0.5, "b") as agent:
        if agent.exits.reason is not None:
            pytest.skip(agent.exits.reason)

        def listed():
            infos = agent.node.get_publishers_info_by_topic("/rosout")
            return {node_fqn(i.node_namespace, i.node_name): decode_gid(bytes(i.endpoint_gid)).prefix
                    for i in infos if i.node_name == "raiser"}

        def mapped():
            r = decode(encode(agent.sample()))
            return r if raiser.pid in set(r.participants.values()) and listed() else None
        before = wait_for(mapped, timeout=20, period=0.3)
        prefixes, left, exits, state = listed(), {}, [], {}

        def ended():
            nonlocal before, prefixes, left
            now = decode(encode(agent.sample(), set(before.processes)), before)
            now_listed, t = listed(), time.time()  # after: a goodbye sent before the exit is in
            left, prefixes = recently_left_prefixes(left, prefixes, now_listed, t), now_listed
            exits.extend(remote_exits(t, "b", before, now, now_listed, {n: p for n, (p, _) in left.items()}))
            before = now
            return any(e.member == f"process:b/{raiser.pid}" for e in exits)
        go.touch()
        wait_for(ended, timeout=10, period=0.3)
    assert raiser.wait(timeout=5) == 1
    proc = next(e for e in exits if e.member == f"process:b/{raiser.pid}")
    said = (proc.data["exit_code"], proc.data["nodes"], proc.data["still_listed"])
    assert said == (1, ["node:/raiser"], []), proc
    decided = error_exits(exits, proc.t, state) + error_exits([], proc.t + 2.0, state)
    assert [(e.member, nodes) for e, nodes in decided] == [(proc.member, ["node:/raiser"])]


def test_ancestors_of_the_nodes_processes_are_read_every_fifth_sample(children):
    """The launch tree above the nodes (here: this test process) is read every 5th sample and
    stays in the tree without metrics in between; the given processes are read every time."""
    p = children.run([sys.executable, "-c", "import time; time.sleep(60)"], name="node_process")
    s = ProcessSampler(ancestors_every=5)
    me = os.getpid()
    read = []
    for _ in range(6):
        out = s.sample([p.pid])
        assert me in out.processes and out.processes[p.pid].metrics  # in the tree; the node's read
        read.append(bool(out.processes[me].metrics))
        time.sleep(0.05)
    assert read == [True, False, False, False, False, True]
    assert "cpu_percent" in out.processes[me].metrics  # a rate over the 5 samples since


OTHER_USER_NODE = """
import os, contextvars, numpy, rclpy, rclpy.executors, rclpy.qos, rclpy.node, rclpy.timer
from std_msgs.msg import String
# Everything imported as root (the interpreter lives under /root, closed to others), then become
# another user; the kernel also marks us non-dumpable. An observer without privileges may not
# read our /proc entries (fds, io, environ).
os.environ["ROS_LOG_DIR"] = "/tmp"
os.setgroups([]); os.setgid(65534); os.setuid(65534)
rclpy.init()
n = rclpy.create_node("stranger")
pub = n.create_publisher(String, "/stranger_out", 10)
n.create_timer(0.2, lambda: pub.publish(String(data="x")))
try:
    rclpy.spin(n)
except (KeyboardInterrupt, Exception):
    pass
"""


def test_a_process_of_another_user_we_may_not_read(children, tmp_path):
    if os.geteuid() != 0 or shutil.which("setpriv") is None:
        pytest.skip("needs root and setpriv to run a node as another user and a monitor without privileges")
    # Fast DDS shared memory does not cross users, nor (as found here) does LOCALHOST discovery:
    # UDP and subnet discovery, on this test run's own domain id.
    env = dict(children.env, FASTDDS_BUILTIN_TRANSPORTS="UDPv4", ROS_AUTOMATIC_DISCOVERY_RANGE="SUBNET")
    script = tmp_path / "stranger.py"
    script.write_text(OTHER_USER_NODE)
    node = children.run([sys.executable, str(script)], name="stranger", env=env)
    wait_for(lambda: psutil.Process(node.pid).uids().real == 65534, timeout=20, period=0.2)
    rep, db = tmp_path / "r.json", tmp_path / "a.sqlite"
    # The monitor as root without any capability: it cannot read another user's process.
    cmd = ["setpriv", "--inh-caps=-all", "--bounding-set=-all", "--",
           *monitor_cmd("--duration", "12", "--report", str(rep), "--db", str(db))]
    out = run(cmd, env)
    assert out.returncode == 0, out.stderr
    assert "Traceback" not in out.stderr
    r = report(rep)
    assert "node:/stranger" in {m["id"] for m in r["members"]}
    assert {"src": "node:/stranger", "dst": "topic:/stranger_out", "kind": "pub"} in r["edges"]
    # What could not be read is recorded, named, with why.
    denied = db_rows(db, "SELECT place, message FROM problems WHERE kind = 'unreadable'")
    assert any(place == f"process:{node.pid}" and "access denied" in msg for place, msg in denied), denied


HIDE = """
import sys
class _Hide:
    # This monitor runs as if the package were not installed.
    def find_spec(self, name, path=None, target=None):
        if name == "test_msgs" or name.startswith("test_msgs."):
            raise ModuleNotFoundError(f"No module named {name!r}", name=name)
        return None
sys.meta_path.insert(0, _Hide())
"""

ODD_TYPE = """
import rclpy
from test_msgs.msg import BasicTypes
rclpy.init()
n = rclpy.create_node("odd_talker")
pub = n.create_publisher(BasicTypes, "/odd", 10)
n.create_timer(0.1, lambda: pub.publish(BasicTypes(int32_value=7)))
try:
    rclpy.spin(n)
except (KeyboardInterrupt, Exception):
    pass
"""


def test_a_topic_whose_type_package_is_not_installed(children, tmp_path):
    pytest.importorskip("test_msgs.msg", reason="the publisher needs ros-jazzy-test-msgs")
    site = tmp_path / "hide"
    site.mkdir()
    (site / "sitecustomize.py").write_text(HIDE)
    children.python(ODD_TYPE, name="odd")
    env = dict(children.env, PYTHONPATH=str(site))
    check = run([sys.executable, "-c", "import test_msgs.msg"], env)
    assert check.returncode != 0 and "test_msgs" in check.stderr  # hidden from the monitor indeed
    rep, db = tmp_path / "r.json", tmp_path / "a.sqlite"
    out = run(monitor_cmd("--duration", "8", "--report", str(rep), "--db", str(db)), env)
    assert out.returncode == 0, out.stderr
    r = report(rep)
    assert {"src": "node:/odd_talker", "dst": "topic:/odd", "kind": "pub"} in r["edges"]
    denied = dict(db_rows(db, "SELECT place, message FROM problems WHERE kind = 'unreadable'"))
    assert "test_msgs/msg/BasicTypes is not installed" in denied.get("topic:/odd", ""), denied


FAST = """
import sys, time, rclpy
from std_msgs.msg import UInt64
rclpy.init()
n = rclpy.create_node("fast_talker")
pub = n.create_publisher(UInt64, "/fast", 100)
count = [0]
def tick():
    count[0] += 1
    pub.publish(UInt64(data=count[0]))
n.create_timer(1e-4, tick)  # 10 kHz asked for
t0 = time.monotonic()
try:
    while rclpy.ok():
        rclpy.spin_once(n, timeout_sec=0.01)
        if time.monotonic() - t0 >= 5:
            print(f"rate {count[0] / (time.monotonic() - t0):.0f}", flush=True)
            count[0], t0 = 0, time.monotonic()
except (KeyboardInterrupt, Exception):
    pass
"""

BIG = """
import rclpy
from sensor_msgs.msg import Image
rclpy.init()
n = rclpy.create_node("big_camera")
pub = n.create_publisher(Image, "/big_image", 2)
img = Image(height=1080, width=1920, encoding="rgb8", step=1920 * 3)
img.data = bytes(1920 * 1080 * 3)  # 6.2 MB per message
n.create_timer(0.2, lambda: pub.publish(img))
try:
    rclpy.spin(n)
except (KeyboardInterrupt, Exception):
    pass
"""


def test_a_very_fast_topic_and_very_large_messages(children, tmp_path):
    fast = children.python(FAST, name="fast")
    children.python(BIG, name="big")
    rrd, rep, db = tmp_path / "m.rrd", tmp_path / "r.json", tmp_path / "a.sqlite"
    cmd = monitor_cmd("--duration", "16", "--save", str(rrd), "--report", str(rep), "--db", str(db))
    p = children.run(cmd, name="monitor")
    wait_for(lambda: p.poll() is not None, timeout=120, period=0.5)
    log = (tmp_path / "monitor_2.log").read_text()
    assert p.returncode == 0, log
    ids = {m["id"] for m in report(rep)["members"]}
    assert {"topic:/fast", "topic:/big_image", "node:/fast_talker", "node:/big_camera"} <= ids
    assert len(sample_times(rrd)) >= 8  # kept sampling under the load
    assert snapshot_has(db, "topic:/big_image")
    rates = [float(ln.split()[1]) for ln in (tmp_path / "fast_0.log").read_text().splitlines()
             if ln.startswith("rate ")]
    print(f"\\n/fast publisher reached {rates} Hz (10 kHz asked for)")
    assert fast.poll() is None


def test_procfs_reads_what_psutil_reads(children):
    """The /proc fast path and psutil agree on a real busy process with threads and files."""
    code = ("import threading, time, tempfile\n"
            "files = [tempfile.TemporaryFile() for _ in range(7)]\n"
            "data = bytearray(50_000_000)\n"
            "def burn():\n    while True: sum(range(10000))\n"
            "for _ in range(2): threading.Thread(target=burn, daemon=True).start()\n"
            "time.sleep(60)\n")
    p = children.run([sys.executable, "-c", code], name="busy")
    fast, slow = ProcessSampler(procfs=True), ProcessSampler(procfs=False)
    wait_for(lambda: psutil.Process(p.pid).num_fds() >= 10, timeout=10)
    for s in (fast, slow):
        s.sample([p.pid])
    time.sleep(1.0)
    fast.sample([p.pid])  # the threads counted: the main thread's CPU is read from the next sample
    time.sleep(1.0)
    a, b = fast.sample([p.pid]).processes[p.pid], slow.sample([p.pid]).processes[p.pid]
    assert a.metrics.keys() - {"running_threads", "dispatching", "main_cpu_percent"} == b.metrics.keys() == {
        "cpu_percent", "rss_mb", "threads", "ctx_switches_per_s", "open_files", "io_read_kBps",
        "io_write_kBps"}
    # /proc only: the two burners ran; the main thread sleeps, so it dispatches nothing.
    assert a.metrics["running_threads"] == 2 and a.metrics["dispatching"] == 0.0
    assert a.metrics["main_cpu_percent"] < 5.0
    assert a.metrics["threads"] == b.metrics["threads"] == 3
    assert a.metrics["open_files"] == b.metrics["open_files"]
    assert abs(a.metrics["rss_mb"] - b.metrics["rss_mb"]) < 2 and a.metrics["rss_mb"] > 50
    assert 50 < a.metrics["cpu_percent"] < 210
    assert abs(a.metrics["cpu_percent"] - b.metrics["cpu_percent"]) < 30
    assert (a.ppid, a.name, a.create_time) == (b.ppid, b.name, b.create_time)


def test_the_one_running_thread_is_measured_as_the_executor(children):
    """A process whose only working thread is not its main one (an executor spun in a thread): the
    sampler finds it and follows its CPU; a blocked thread uses none, and a probe of the threads
    that finds none ran keeps it (probed every sample here). The main thread wakes once as the
    executor's last callback runs (as a lock's holder would): a thread that ran a little beside the
    executor is not a second executor thread."""
    code = ("import threading, time\n"
            "stop = threading.Event()\n"
            "def busy(s):\n"
            "    end = time.thread_time() + s\n"  # CPU burned, however loaded the machine
            "    while time.thread_time() < end: pass\n"
            "def work():\n"
            "    while not stop.is_set():\n"
            "        busy(0.02); time.sleep(0.03)\n"
            "    busy(0.3)\n"
            "    threading.Event().wait()\n"  # blocked for good, as a deadlocked callback
            "threading.Thread(target=work, name='spin', daemon=True).start()\n"
            "time.sleep(5); stop.set(); time.sleep(60)\n")
    p = children.run([sys.executable, "-c", code], name="spinner")
    sampler = ProcessSampler(procfs=True, probe_every=1)
    seen = []
    for _ in range(8):
        seen.append(sampler.sample([p.pid]).processes[p.pid].metrics)
        time.sleep(1.0)
    assert [m.get("running_threads") for m in seen[3:6]] == [1.0, 1.0, 1.0], seen
    assert 15 < seen[4]["executor_cpu_percent"] < 70, seen  # ~40 % asked for
    assert seen[-1]["executor_cpu_percent"] < 1.0, seen  # blocked
    assert seen[-1]["running_threads"] == 1.0, seen  # still that executor's process
