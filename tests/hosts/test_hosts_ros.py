"""Several computers on one machine (network + PID namespaces, discovery over UDP on a veth bridge).

Host ``a`` runs the monitor's collector (and a node of its own), ``b`` an agent and a node, ``c``
a node and no agent. The PIDs of the three hosts' nodes collide (each host's PID namespace
starts at 1); the model must still put every node on its own host and process.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import textwrap
import time

import pytest
from rerun.chunk import RrdReader

from stream_viz.testing import EXE, claim_domain
from stream_viz.testing_hosts import NODE, OBSERVER, Lab, Samples, inner, lab_env, why_not
from stream_viz.viz import paths, style
from tests.cli.test_cli import check_report
from tests.robust.test_host_load import BUSY_SENSOR, HOG, HOGS_FROM_S
from tests.viz import rrd

pytestmark = [pytest.mark.ros, pytest.mark.slow]

WHY_NOT = why_not()
if WHY_NOT:
    pytestmark.append(pytest.mark.skip(reason=f"cannot make network/PID namespaces here: {WHY_NOT}"))

@pytest.fixture
def lab(tmp_path):
    with Lab(tmp_path) as lab:
        yield lab


def _script(tmp_path, name, code):
    path = tmp_path / f"{name}.py"
    path.write_text(textwrap.dedent(code))
    return str(path)


def test_one_model_across_three_hosts_remote_crash_and_agent_killed(lab, tmp_path):
    env = lab_env(claim_domain())
    a, b, c = lab.add("a"), lab.add("b"), lab.add("c")
    node = _script(tmp_path, "node", NODE)
    nodes = {
        "planner": a.run([sys.executable, node, "planner", "cam"], env, tmp_path / "planner.log"),
        "cam": b.run([sys.executable, node, "cam"], env, tmp_path / "cam.log"),
        "imu": b.run([sys.executable, node, "imu"], env, tmp_path / "imu.log"),
        "lidar": c.run([sys.executable, node, "lidar"], env, tmp_path / "lidar.log"),
    }
    agent = b.run([EXE, "agent", "--period", "0.5"], env, tmp_path / "agent.log")
    samples = Samples(tmp_path / "samples.jsonl")
    observe = _script(tmp_path, "observe", OBSERVER)
    a.run([sys.executable, observe, str(samples.path)], env, tmp_path / "observe.log")

    def merged(s):
        m = s["members"]
        return (all(f"node:/{n}" in m for n in nodes) and m["node:/cam"].get("pid_status") == "confirmed"
                and m["node:/imu"].get("pid_status") == "confirmed" and "host" in m["node:/lidar"]
                and m["node:/planner"].get("pid_status") == "confirmed")

    s = samples.until(merged, 40.0)
    m, tree = s["members"], {tuple(e) for e in s["tree"]}
    # every node on its own host, a host level under the root
    host_c = m["node:/lidar"]["host"]  # no agent: named by its Fast DDS host id
    hosts = {n: m[f"node:/{n}"]["host"] for n in nodes}
    assert hosts == {"planner": "a", "cam": "b", "imu": "b", "lidar": host_c}
    assert host_c not in ("a", "b") and len(host_c) == 4
    assert {("root", "host:a"), ("root", "host:b")} <= tree
    assert m["host:b"]["agent"] == "reporting"
    # PIDs collide across the hosts' PID namespaces: the processes still differ
    cam_pid, imu_pid, planner_pid = (m[f"node:/{n}"]["pid"] for n in ("cam", "imu", "planner"))
    assert (f"process:b/{cam_pid}", "node:/cam") in tree and (f"process:b/{imu_pid}", "node:/imu") in tree
    assert (f"process:{planner_pid}", "node:/planner") in tree and m[f"process:{planner_pid}"]["host"] == "a"
    assert cam_pid < 100 and planner_pid < 100  # each host's own small PIDs
    # host c has no agent: its node is marked, never guessed
    lidar = m["node:/lidar"]
    assert lidar["pid"] is None and lidar["pid_status"] == "unknown"
    assert s["unreadable"]["node:/lidar"] == f"process unknown: no agent on host {host_c}"
    assert (f"host:{host_c}", "node:/lidar") in tree and m[f"host:{host_c}"]["agent"] == "none"

    # a crash on host b, seen from b's OS through its agent (DDS lists the node ~20 s more)
    os.kill(inner(nodes["cam"]), signal.SIGKILL)
    t_kill = time.time()
    s = samples.until(lambda s: any(e[:3] == ["exit", "node:/cam", "error"] for e in s["events"]), 10.0)
    exit_t = next(e[3] for e in s["events"] if e[1] == "node:/cam")
    assert exit_t - t_kill < 3.0
    assert {"exit", f"process:b/{cam_pid}", "error"} == set(next(
        e[:3] for e in s["events"] if e[1] == f"process:b/{cam_pid}"))
    assert s["members"]["node:/cam"]["alive"] is False

    # the agent killed mid-run: b's members become unknown, nothing else is lost
    os.kill(inner(agent), signal.SIGKILL)
    s = samples.until(lambda s: s["members"]["host:b"]["agent"] == "silent", 10.0)
    m = s["members"]
    assert m["node:/imu"]["pid_status"] == "unknown" and "silent" in s["unreadable"]["node:/imu"]
    assert "silent" in s["unreadable"][f"process:b/{imu_pid}"]
    assert m["node:/imu"]["host"] == "b" and f"process:b/{imu_pid}" in m  # kept, marked, not dropped
    assert m["node:/planner"]["pid_status"] == "confirmed" and "node:/planner" not in s["unreadable"]
    assert all(not k.startswith("process:") or "/" in k for k in s["unreadable"])  # no local one


def _two_hosts(lab, tmp_path, duration, warmup, planner_subs=("cam",), save=False):
    """Host a: the monitor and /planner; host b: /cam, /imu and an agent. Return b, its node
    processes and the monitor, once ``warmup`` seconds have passed."""
    env = lab_env(claim_domain())
    a, b = lab.add("a"), lab.add("b")
    node = _script(tmp_path, "node", NODE)
    a.run([sys.executable, node, "planner", *planner_subs], env, tmp_path / "planner.log")
    nodes = {n: b.run([sys.executable, node, n], env, tmp_path / f"{n}.log") for n in ("cam", "imu")}
    b.run([EXE, "agent", "--period", "0.5"], env, tmp_path / "agent.log")
    cfg = tmp_path / "c.toml"
    # The lab's hosts share this machine's CPU, loaded by whatever else runs: not the robot's.
    cfg.write_text("[monitor]\nperiod = 0.5\n[plugins.host_state]\ncpu_percent = 101.0\n")
    save_to = ["--save", str(tmp_path / "r.rrd")] if save else []
    monitor = a.run([EXE, "monitor", "--duration", str(duration), "--viewer", "none", "--config", str(cfg),
                     "--report", str(tmp_path / "r.json"), "--db", str(tmp_path / "a.sqlite"), *save_to],
                    env, tmp_path / "monitor.log")
    time.sleep(warmup)
    return b, nodes, monitor


def _report_of(monitor, tmp_path):
    assert monitor.wait(timeout=60) == 0, (tmp_path / "monitor.log").read_text()
    return json.loads((tmp_path / "r.json").read_text())


def test_a_crash_on_another_host_is_ranked_first_with_its_host_and_process(lab, tmp_path):
    _, nodes, monitor = _two_hosts(lab, tmp_path, 22, 12.0)  # discovery, agent reports, warm-up
    os.kill(inner(nodes["cam"]), signal.SIGKILL)
    report = _report_of(monitor, tmp_path)
    rows = {m["id"]: m for m in report["members"]}
    cam_row = rows["node:/cam"]
    assert cam_row["host"] == "host:b" and cam_row["process"] == f"process:b/{cam_row['pid']}"
    assert rows["node:/planner"]["host"] == "host:a" and rows["node:/imu"]["host"] == "host:b"
    assert rows["host:b"]["agent"] == "reporting" and rows["host:a"]["agent"] == "local"
    assert report["root_causes"], report["alerts"]
    assert report["root_causes"][0]["member"] == "node:/cam", report["root_causes"][:3]
    check_report(report)  # the schema knows the host fields and process:<host>/<pid>
    # offline, from the alert database alone: the same hosts and the same first cause
    offline = tmp_path / "offline.json"
    out = subprocess.run([EXE, "analyze", "--db", str(tmp_path / "a.sqlite"), "--report", str(offline)],
                         capture_output=True, text=True, timeout=120)
    assert out.returncode == 0, out.stderr
    again = json.loads(offline.read_text())
    assert again["root_causes"][0]["member"] == "node:/cam"
    assert {m["id"]: m.get("host") for m in again["members"]}["node:/cam"] == "host:b"


def test_a_computer_off_the_network_is_ranked_first_as_that_host(lab, tmp_path):
    """Host b drops off the network (its link down: everything on it still runs, out of sight):
    its agent falls silent with its nodes' topics; the diagnosis names the host, not one node."""
    b, _, monitor = _two_hosts(lab, tmp_path, 34, 22.0, ("cam", "imu"), save=True)  # rhythms learnt
    b.sh("ip link set eth0 down")
    report = _report_of(monitor, tmp_path)
    silent = [x for x in report["alerts"] if x["member"] == "host:b" and x["plugin"] == "host_state"]
    assert silent and "silent" in silent[0]["message"], report["alerts"]
    quiet = {x["member"] for x in report["alerts"] if x["plugin"] == "topic_rate"}
    assert quiet == {"topic:/cam/out", "topic:/imu/out"}, report["alerts"]  # b's topics, seen from a
    top = report["root_causes"][0]
    assert top["member"] == "host:b", report["root_causes"][:3]
    assert {"node:/cam", "node:/imu"} <= set(top["evidence"]["explains_nodes"])
    assert not [x for x in report["alerts"] if x["t"] < silent[0]["t"] - 2.0]  # nothing before
    check_report(report)
    # the viewer: the report names the host; the computers' own CPU and memory are plotted
    data = rrd.rows(tmp_path / "r.rrd")
    text = [row["TextDocument:text"][0] for row in data[paths.RCA_REPORT]][-1]
    assert "**`host:b`**" in text and "it explains `node:/cam`, `node:/imu`" in text, text
    # the trajectory overlay draws the host, which the graph has no place for, as its nodes in
    # the root cause's colour (a packed RGBA)
    traj = rrd.shown(data[paths.RCA_TRAJECTORY])
    root = int.from_bytes(bytes([*style.ROOT_CAUSE_COLOR, 255]), "big")
    colors = zip(traj["GraphNodes:node_ids"], traj["GraphNodes:colors"], strict=True)
    black = {m for m, c in colors if c == root}
    assert black == {"node:/cam", "node:/imu"}, traj
    for h in ("a", "b"):
        theta = data.get(paths.metrics_path(f"host:{h}", paths.THETA), [])
        assert [row for row in theta if "Scalars:scalars" in row], sorted(data)
    # one graph per computer, and a layout with a tab for each
    ids = {h: set(rrd.shown(data[paths.host_graph_path(h)])["GraphNodes:node_ids"]) for h in ("a", "b")}
    assert ids["b"] == {"node:/cam", "node:/imu", "topic:/cam/out", "topic:/imu/out"}
    assert ids["a"] == {"node:/planner", "topic:/planner/out", "topic:/cam/out", "topic:/imu/out"}
    # stepping through the RCA iterations, each host's tab shows its graph as well
    by_step = rrd.shown(data[paths.host_graph_path("b")], timeline=paths.RCA_ITERATION)
    assert set(by_step["GraphNodes:node_ids"]) == ids["b"]
    # (the reader's order of the blueprints sent is not the order they were sent in)
    layouts = [rrd.strings(tmp_path / "r.rrd", bp) for bp in RrdReader(str(tmp_path / "r.rrd")).blueprints()]
    assert any({"Host a", "Host b", "Hosts"} <= names for names in layouts), layouts


@pytest.mark.skipif((os.cpu_count() or 1) < 2 or shutil.which("taskset") is None,
                    reason="a computer of its own core needs 2 CPUs and `taskset`")
def test_a_saturated_remote_computer_is_ranked_first_as_that_host(lab, tmp_path):
    """Host b (one core of its own) is starved by work outside the robot: its agent reports its
    core full and the monitor on host a (the other core, not full) names host b, not a node."""
    env = lab_env(claim_domain())
    a, b = lab.add("a", cpus=[0]), lab.add("b", cpus=[1])
    a.run([sys.executable, _script(tmp_path, "node", NODE), "planner", "scan"], env, tmp_path / "planner.log")
    b.run([sys.executable, _script(tmp_path, "sensor", BUSY_SENSOR)], env, tmp_path / "sensor.log")
    b.run([EXE, "agent"], env, tmp_path / "agent.log")
    monitor = a.run([EXE, "monitor", "--duration", "50", "--viewer", "none",
                     "--report", str(tmp_path / "r.json"), "--db", str(tmp_path / "a.sqlite")],
                    env, tmp_path / "monitor.log")
    time.sleep(HOGS_FROM_S)
    hog = _script(tmp_path, "hog", HOG)
    for i in range(4):  # on b's core only
        b.run([sys.executable, hog], env, tmp_path / f"hog{i}.log")
    report = _report_of(monitor, tmp_path)
    alerts = [(x["member"], round(x["t"], 1), x["message"]) for x in report["alerts"]]
    saturated = [x["member"] for x in report["alerts"] if x["plugin"] == "host_state"
                 and "saturated: CPU" in x["message"]]
    # b first (a's core is full only if work outside the test takes it, as the machine's rest)
    assert saturated and saturated[0] == "host:b", alerts
    slowed = [x for x in report["alerts"] if x["member"] in ("topic:/scan", "topic:/map", "node:/lidar")]
    # Not a miss of ours: the hogs must have slowed the sensor for the test to mean anything.
    assert slowed, ("the hogs did not slow the sensor", alerts)
    top = report["root_causes"][0]
    assert top["member"] == "host:b", (report["root_causes"][:3], alerts)
    assert "node:/lidar" in top["evidence"]["explains_nodes"]
