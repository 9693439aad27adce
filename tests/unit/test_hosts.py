"""Several hosts, pure parts: the agent's report rows, the merge into the model, remote exits."""

from __future__ import annotations

import math

from stream_viz.collect.hostreport import HOST_STATUS, HostReport, decode, encode, host_of_prefix
from stream_viz.collect.hosts import (
    Received,
    merge_hosts,
    recently_left_prefixes,
    remote_exits,
    remote_pids,
    remote_restarts,
)
from stream_viz.collect.oomkills import OomKill
from stream_viz.collect.processes import cores_of, parse_pressure, pressure_percent
from stream_viz.collect.readings import PidInfo, ProcessReading
from stream_viz.model.graph import PROCESS_TREE, add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import pid_of
from stream_viz.model.queries import nodes_of_process, process_of_node, successors, tree
from stream_viz.model.theta import make_theta, theta_dict
from stream_viz.rca.engine import analyze
from stream_viz.rca.settings import RcaSettings
from stream_viz.records import Alert
from stream_viz.viz.hosts_view import host_arrays, hosts_of
from tests.unit.test_plugins import drive

OWN = 0x1111
REMOTE = 0x2222
PRE_LOCAL = "010f1111" + "0a00" + "0000" + "00000000"
PRE_B = "010f2222" + "0a00" + "1234" + "00000000"  # pid 10 on host b: collides with the local pid 10
PRE_C = "010f3333" + "0b00" + "0000" + "00000000"


def _report(alive: bool = True, seq: int = 1) -> HostReport:
    procs = {
        1: ProcessReading(1, None, "init", "", 100.0),
        10: ProcessReading(10, 1, "python", "python cam.py", 101.5, "robot",
                           {"cpu_percent": 12.5, "rss_mb": 40.0}, alive=alive),
    }
    return HostReport("b", REMOTE, seq, 0.5, {PRE_B: 10}, procs)


def test_report_rows_round_trip_host_processes_participants():
    rows = encode(_report())
    assert [r.name for r in rows] == [HOST_STATUS, "process 1", "process 10"]
    assert rows[0].hardware_id == "b" and dict(rows[0].values)["host_id"] == str(REMOTE)
    assert dict(rows[2].values)["participants"] == PRE_B
    back = decode(rows)
    assert (back.host, back.host_id, back.seq, back.period_s) == ("b", REMOTE, 1, 0.5)
    assert back.participants == {PRE_B: 10}
    p = back.processes[10]
    assert (p.ppid, p.name, p.cmdline, p.username, p.alive) == (1, "python", "python cam.py", "robot", True)
    assert p.metrics == {"cpu_percent": 12.5, "rss_mb": 40.0} and p.create_time == 101.5
    assert back.processes[1].ppid is None
    assert decode(encode(_report(alive=False))).processes[10].alive is False
    assert decode(rows[1:]) is None  # not an agent's array (an ordinary /diagnostics one)
    limited = _report()
    limited.machine = {"machine_mem_percent": 97.0, "mem_limit_mb": 200.0, "cpus": 1.5}
    assert decode(encode(limited)).machine == limited.machine


def test_host_of_prefix_reads_bytes_2_3():
    assert host_of_prefix(PRE_B) == REMOTE and host_of_prefix(PRE_LOCAL) == OWN


def _local_graph():
    """This host: process 1 (launch) → process 10 → node /planner; node /cam on host b; /lidar on c."""
    G = new_graph()
    for n in ("node:/planner", "node:/cam", "node:/lidar"):
        add_member(G, n, pid=None, pid_status="remote")
    for p in ("process:1", "process:10"):
        add_member(G, p, pid=pid_of(p), theta=make_theta("process", {"cpu_percent": 1.0}))
    add_tree_edge(G, "process:1", "process:10")
    add_tree_edge(G, "process:10", "node:/planner")
    G.nodes["node:/planner"].update(pid=10, pid_status="confirmed")
    pids = {"/planner": PidInfo(10, "confirmed", (10,), PRE_LOCAL),
            "/cam": PidInfo(None, "remote", prefix=PRE_B), "/lidar": PidInfo(None, "remote", prefix=PRE_C)}
    return G, pids


def test_merge_gives_the_tree_a_host_level_and_remote_processes_their_own_ids():
    G, pids = _local_graph()
    unknown = merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(50.0, _report())}, now=50.5)
    T = tree(G)
    assert sorted(T.successors("root")) == ["host:3333", "host:a", "host:b"]
    assert list(T.successors("host:a")) == ["process:1"]
    assert list(T.successors("host:b")) == ["process:b/1"]
    assert list(T.successors("process:b/1")) == ["process:b/10"]
    assert list(T.successors("process:b/10")) == ["node:/cam"]
    assert process_of_node(G, "node:/cam") == "process:b/10"
    assert process_of_node(G, "node:/planner") == "process:10"  # same pid, other host: no mix-up
    cam = G.nodes["node:/cam"]
    assert (cam["host"], cam["pid"], cam["pid_status"], cam["alive"]) == ("b", 10, "confirmed", True)
    assert G.nodes["node:/planner"]["host"] == "a" and G.nodes["process:10"]["host"] == "a"
    assert theta_dict("process", G.nodes["process:b/10"]["theta"])["cpu_percent"] == 12.5
    assert G.nodes["host:b"]["agent"] == "reporting" and G.nodes["host:3333"]["agent"] == "none"
    # host c has no agent: its node hangs under the host, marked, never guessed
    assert list(T.successors("host:3333")) == ["node:/lidar"]
    assert G.nodes["node:/lidar"]["pid"] is None and G.nodes["node:/lidar"]["pid_status"] == "unknown"
    assert unknown == {"node:/lidar": "process unknown: no agent on host 3333"}
    assert nodes_of_process(G, "host:b") == ["node:/cam"]
    assert nodes_of_process(G, "process:b/10", by_pid=True) == ["node:/cam"]
    assert nodes_of_process(G, "process:10", by_pid=True) == ["node:/planner"]


def test_a_silent_agent_marks_its_members_unknown_and_keeps_everything_else():
    G, pids = _local_graph()
    unknown = merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(40.0, _report())}, now=50.0)
    why = "process unknown: the agent on host b has been silent for 10 s"
    assert unknown == {"node:/cam": why, "process:b/1": why, "process:b/10": why,
                       "node:/lidar": "process unknown: no agent on host 3333"}
    assert G.nodes["host:b"]["agent"] == "silent"
    assert all(math.isnan(x) for x in G.nodes["process:b/10"]["theta"])  # unknown, not a stale value
    assert G.nodes["node:/cam"]["pid_status"] == "unknown" and "process:b/10" in G
    assert theta_dict("process", G.nodes["process:10"]["theta"])["cpu_percent"] == 1.0


def test_one_computer_is_a_host_member_with_its_own_theta():
    G, pids = _local_graph()
    pids = {"/planner": pids["/planner"]}
    G.remove_nodes_from(["node:/cam", "node:/lidar"])
    machine = {"machine_cpu_percent": 97.0, "cpu_pressure_percent": 40.0, "cpus": 2.0}
    assert merge_hosts(G, pids, (OWN, "a"), {}, now=1.0, machine=machine) == {}
    assert sorted(G.nodes(data="kind")) == [("host:a", "host"), ("node:/planner", "node"),
                                            ("process:1", "process"), ("process:10", "process"),
                                            ("root", "root")]
    assert successors(G, "root", layer=PROCESS_TREE) == ["host:a"]
    assert successors(G, "host:a", layer=PROCESS_TREE) == ["process:1"]
    assert G.nodes["node:/planner"]["host"] == "a" and G.nodes["process:10"]["host"] == "a"
    host = G.nodes["host:a"]
    assert (host["agent"], host["cpus"], host["host_id"]) == ("local", 2, f"{OWN:04x}")
    theta = theta_dict("host", host["theta"])
    assert (theta["machine_cpu_percent"], theta["cpu_pressure_percent"]) == (97.0, 40.0)
    assert "mem_limit_mb" not in host
    merge_hosts(G, pids, (OWN, "a"), {}, now=2.0, machine={**machine, "mem_limit_mb": 200.0})
    assert G.nodes["host:a"]["mem_limit_mb"] == 200.0


def test_without_its_own_host_id_the_monitor_takes_every_node_as_its_own():
    G, pids = _local_graph()
    assert merge_hosts(G, pids, (None, "a"), {}, now=50.0) == {}
    assert [m for m, k in G.nodes(data="kind") if k == "host"] == ["host:a"]
    assert G.nodes["host:a"]["host_id"] == "?" and G.nodes["node:/cam"]["host"] == "a"


def test_remote_exit_is_an_error_while_dds_still_lists_the_node():
    ev = remote_exits(5.0, "b", _report(), _report(alive=False, seq=2), {"/cam": PRE_B})
    assert [(e.member, e.kind, e.level) for e in ev] == [("node:/cam", "exit", "error"),
                                                          ("process:b/10", "exit", "error")]
    assert ev[0].data["host"] == "b" and ev[0].data["pid"] == 10
    assert remote_exits(5.0, "b", _report(), _report(seq=2), {"/cam": PRE_B}) == []
    gone = _report(seq=2)
    del gone.processes[10]
    ev = remote_exits(5.0, "b", _report(), gone, {})  # ended cleanly: DDS no longer lists /cam
    assert [(e.member, e.level) for e in ev] == [("process:b/10", "warn")]
    # /cam left the graph a sample before the report of its process's end: still its node
    ev = remote_exits(5.0, "b", _report(), gone, {}, {"/cam": PRE_B})
    assert [(e.member, e.level) for e in ev] == [("node:/cam", "warn"), ("process:b/10", "warn")]
    assert ev[0].data["nodes"] == ["node:/cam"] and ev[0].data["still_listed"] == []
    lost = _report(seq=2)  # the agent maps its participants again: /cam listed, its process left out
    del lost.processes[10]
    lost.participants = {}
    assert remote_exits(5.0, "b", _report(), lost, {"/cam": PRE_B}) == []
    # the start time first known from a later report (the one that carried it was missed)
    unknown_start = _report()
    unknown_start.processes[10].create_time = None
    assert remote_exits(5.0, "b", unknown_start, _report(seq=2), {"/cam": PRE_B}) == []
    reused = _report(seq=2)  # the pid taken by a new process
    reused.processes[10].create_time = 250.0
    assert [e.level for e in remote_exits(5.0, "b", _report(), reused, {"/cam": PRE_B})] == ["error"] * 2


def test_an_agent_s_oom_kill_travels_in_its_report_and_makes_the_exit_an_oom_kill():
    dead = _report(alive=False, seq=2)
    dead.ooms = {10: OomKill("/sys/fs/cgroup/memory/robot", 200 * 2**20)}
    row = encode(dead)[2]
    assert ("oom_kill", f"{200 * 2**20} /sys/fs/cgroup/memory/robot") in row.values
    back = decode(encode(dead))
    assert back.ooms == dead.ooms
    ev = remote_exits(5.0, "b", _report(), back, {"/cam": PRE_B})
    assert [(e.member, e.level) for e in ev] == [("node:/cam", "error"), ("process:b/10", "error")]
    assert ev[0].text == ("process 10 (python) on host b exited with nodes /cam: killed by the OOM killer at "
                          "its group's limit of 200 MB (cgroup /sys/fs/cgroup/memory/robot)")
    assert (ev[0].data["oom_kill"], ev[0].data["memory_limit_mb"]) == (True, 200.0)
    dead.ooms = {10: OomKill("/", None)}  # the machine's memory ran out: no limit of its own
    assert decode(encode(dead)).ooms == dead.ooms
    # a clean exit the OOM killer did not end is still a warning
    gone = _report(seq=2)
    del gone.processes[10]
    assert [e.level for e in remote_exits(5.0, "b", _report(), gone, {})] == ["warn"]


def test_an_agent_s_exit_codes_travel_in_its_report_and_say_how_the_process_ended():
    dead = _report(alive=False, seq=2)
    dead.exits = {10: 0, 77: -9}
    assert ("exits", "10=0 77=-9") in encode(dead)[0].values
    back = decode(encode(dead))
    assert back.exits == {10: 0, 77: -9}
    # exit(0) with its node still listed (no goodbye sent): no crash, an info
    ev = remote_exits(5.0, "b", _report(), back, {"/cam": PRE_B})
    assert [(e.member, e.level) for e in ev] == [("node:/cam", "info"), ("process:b/10", "info")]
    assert ev[0].text == "process 10 (python) on host b exited with code 0 with nodes /cam"
    assert ev[0].data["exit_code"] == 0
    back.exits = {10: -9}  # killed: the crash it looked like
    ev = remote_exits(5.0, "b", _report(), back, {"/cam": PRE_B})
    assert [e.level for e in ev] == ["error", "error"] and "was killed by SIGKILL" in ev[0].text
    assert ev[0].data["exit_code"] == -9
    # ended cleanly (DDS no longer lists /cam, the agent left it out): the code still says so
    gone = _report(seq=2)
    del gone.processes[10]
    gone.exits = {10: 3}
    ev = remote_exits(5.0, "b", _report(), gone, {})
    assert [(e.level, e.data["exit_code"]) for e in ev] == [("warn", 3)]
    assert "exited with code 3" in ev[0].text
    head = encode(_report())[0]
    assert "exits" not in dict(head.values) and decode([head]).exits == {}  # none known: none said


def test_tree_of_merge_is_a_tree():
    G, pids = _local_graph()
    merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(50.0, _report())}, now=50.5)
    parents = {}
    for u, v, k in G.edges(keys=True):
        if k == PROCESS_TREE:
            assert v not in parents, v
            parents[v] = u
    assert set(G) - set(parents) == {"root"}


def test_a_host_just_seen_waits_for_its_agent_before_it_is_named_by_its_id():
    G, pids = _local_graph()
    unknown = merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(50.0, _report())}, now=50.5,
                          first_seen={REMOTE: 49.0, 0x3333: 49.0})
    assert "host:3333" not in G and "node:/lidar" not in unknown
    assert G.nodes["node:/lidar"]["pid_status"] == "remote"  # as on one computer, for now
    merge_hosts(G, pids, (OWN, "a"), {}, now=53.0, first_seen={REMOTE: 49.0, 0x3333: 49.0})
    assert "host:3333" in G


def test_identity_left_out_for_known_processes_is_taken_from_the_report_before():
    rows = encode(_report(seq=2), known={1, 10})
    assert "cmdline" not in dict(rows[2].values) and "create_time" not in dict(rows[2].values)
    back = decode(rows, before=_report())
    assert (back.processes[10].cmdline, back.processes[10].create_time) == ("python cam.py", 101.5)
    assert back.processes[10].metrics == {"cpu_percent": 12.5, "rss_mb": 40.0}
    assert decode(rows).processes[10].create_time is None  # nothing before: unknown, not made up


def test_the_agents_own_cdr_is_what_rclpy_serializes():
    from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
    from rclpy.serialization import deserialize_message, serialize_message

    from stream_viz.collect.diagcdr import diagnostic_array

    rows = encode(_report())
    rows[1] = rows[1]._replace(message="ünïcode", values=[])  # odd lengths, padding, UTF-8
    msg = DiagnosticArray()
    msg.header.stamp.sec, msg.header.stamp.nanosec = 1700000000, 123456789
    msg.status = [DiagnosticStatus(level=bytes([r.level]), name=r.name, message=r.message,
                                   hardware_id=r.hardware_id,
                                   values=[KeyValue(key=k, value=v) for k, v in r.values]) for r in rows]
    raw = diagnostic_array(1700000000_123456789, rows)
    assert len(raw) == len(serialize_message(msg))  # the same layout (rclpy's padding bytes vary)
    assert deserialize_message(raw, DiagnosticArray) == msg


def test_the_viewer_draws_the_host_level_and_groups_nodes_by_host():
    from stream_viz.viz.layout_groups import member_groups
    from stream_viz.viz.paths import group_path
    from stream_viz.viz.process_tree import process_tree_arrays

    G, pids = _local_graph()
    merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(50.0, _report())}, now=50.5)
    a = process_tree_arrays(G)
    labels = dict(zip(a["ids"], a["labels"], strict=True))
    assert labels["host:b"] == "b" and labels["process:b/10"] == "python (b/10)"
    assert ("root", "host:b") in a["edges"] and ("host:b", "process:b/1") in a["edges"]
    groups = member_groups(G, ["node:/planner", "node:/cam", "node:/lidar"], by="host")
    assert groups == {}  # one node per host: no box of one
    add_member(G, "node:/imu", host="b")
    assert member_groups(G, ["node:/cam", "node:/imu", "node:/planner"], by="host") == {
        "node:/cam": "b", "node:/imu": "b"}
    assert group_path("host", "b") == "/host/b"


def test_a_remote_node_in_a_new_process_is_a_restart():
    G, pids = _local_graph()
    merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(50.0, _report())}, now=50.5)
    now = remote_pids(G, "a")
    assert now == {"node:/cam": ("b", 10)}  # /lidar: unknown process, /planner: this host
    ev = remote_restarts(51.0, {"node:/cam": ("b", 7)}, now)
    assert [(e.kind, e.member, e.level, e.data["old_pid"], e.data["pid"]) for e in ev] == [
        ("restart", "node:/cam", "warn", 7, 10)]
    assert remote_restarts(51.0, now, now) == []


# --------------------------------------------------------------------------- the host as a member


def test_the_hosts_own_theta_comes_in_the_report_and_from_this_computer():
    r = _report()
    r.machine = {"machine_cpu_percent": 97.0, "machine_mem_percent": 41.5}
    assert decode(encode(r)).machine == {"machine_cpu_percent": 97.0, "machine_mem_percent": 41.5}
    G, pids = _local_graph()
    merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(50.0, r)}, now=50.5,
                machine={"machine_cpu_percent": 12.0, "machine_mem_percent": 30.0})
    assert theta_dict("host", G.nodes["host:b"]["theta"])["machine_cpu_percent"] == 97.0
    assert theta_dict("host", G.nodes["host:a"]["theta"])["machine_mem_percent"] == 30.0
    G, pids = _local_graph()  # silent: the computer's θ unknown, how long said
    merge_hosts(G, pids, (OWN, "a"), {REMOTE: Received(40.0, r)}, now=50.0)
    assert math.isnan(theta_dict("host", G.nodes["host:b"]["theta"])["machine_cpu_percent"])
    assert G.nodes["host:b"]["silent_s"] == 10.0


def _hosts_model(cpu_b: float = 20.0, agent_b: str = "reporting", pressure_b: float = math.nan):
    """host a: process:10 → node:/planner (subscribes /cam/out); host b (2 CPUs): process:b/7 →
    node:/cam, process:b/8 → node:/imu (publish /cam/out, /imu/out)."""
    G = new_graph()
    add_member(G, "root", theta=make_theta("root", {}))
    for h, agent, cpu, waited in (("a", "local", 10.0, 0.0), ("b", agent_b, cpu_b, pressure_b)):
        add_member(G, f"host:{h}", theta=make_theta("host", {"machine_cpu_percent": cpu,
                                                             "cpu_pressure_percent": waited}),
                   agent=agent, cpus=2)
        add_tree_edge(G, "root", f"host:{h}")
    for proc, node, host in (("process:10", "node:/planner", "a"), ("process:b/7", "node:/cam", "b"),
                             ("process:b/8", "node:/imu", "b")):
        add_member(G, proc, theta=make_theta("process", {"cpu_percent": 5.0}), host=host, name="python")
        add_member(G, node, host=host)
        add_tree_edge(G, f"host:{host}", proc)
        add_tree_edge(G, proc, node)
    for topic, pub in (("topic:/cam/out", "node:/cam"), ("topic:/imu/out", "node:/imu")):
        add_member(G, topic)
        add_flow_edge(G, pub, topic, "pub")
        add_flow_edge(G, topic, "node:/planner", "sub")
    return G


def test_host_state_alerts_on_a_saturated_host_and_on_a_silent_agent():
    frames = [(float(t), _hosts_model(cpu_b=99.0 if t >= 5 else 20.0), []) for t in range(20)]
    got = drive("host_state", frames, full=True)
    assert [(a.t, a.member) for a in got] == [(float(t), "host:b") for t in range(15, 20)]
    assert got[0].data["since"] == 5.0 and "CPU 99 % in use for 10 s" in got[0].message
    assert "process:b/7 python 5 %" in got[0].message  # the busiest processes named
    assert drive("host_state", frames, settings={"saturated_s": 30.0}) == []
    # full since first seen: its normal; a gap of unknown values ends a run
    assert drive("host_state", [(float(t), _hosts_model(cpu_b=99.0), []) for t in range(20)]) == []
    gap = [(float(t), _hosts_model(cpu_b=math.nan if t == 10 else 99.0 if t >= 5 else 20.0), [])
           for t in range(20)]
    assert drive("host_state", gap) == []
    G = _hosts_model(agent_b="silent")
    G.nodes["host:b"]["silent_s"] = 4.0
    (a,) = drive("host_state", [(1.0, G, [])], full=True)
    assert (a.member, a.severity, a.data["symptom"]) == ("host:b", "warn", "agent_silent")
    assert "silent for 4 s" in a.message


def test_a_container_s_memory_near_its_limit_is_said_of_the_limit():
    def frame(t):
        G = _hosts_model()
        G.nodes["host:b"]["theta"] = make_theta("host", {"machine_mem_percent": 97.0 if t >= 5 else 40.0})
        G.nodes["host:b"]["mem_limit_mb"] = 200.0  # the agent's container: its memory is of its limit
        return (float(t), G, [])

    got = drive("host_state", [frame(t) for t in range(16)], full=True)
    assert [(a.t, a.member, a.data["symptom"]) for a in got] == [(15.0, "host:b", "host_memory")]
    assert "memory 97 % of its group's limit of 200 MB in use for 10 s" in got[0].message, got[0].message


def test_full_cpu_is_saturation_only_while_tasks_wait_for_it():
    def frames(waited):
        return [(float(t), _hosts_model(cpu_b=99.0 if t >= 5 else 20.0, pressure_b=waited), [])
                for t in range(20)]

    assert drive("host_state", frames(5.0)) == []  # every core busy, nobody waiting
    got = drive("host_state", frames(60.0), full=True)
    assert [a.t for a in got] == [float(t) for t in range(15, 20)]
    assert "tasks waited for a CPU 60 % of the time" in got[0].message
    # 2 CPUs at 99 %, the robot's two processes 5 % each: 1.88 CPUs used outside them
    assert "outside the robot's processes: 1.9 of 2 CPUs" in got[0].message


def test_cpu_pressure_is_the_share_of_time_some_task_waited():
    text = ("some avg10=1.00 avg60=0.50 avg300=0.10 total=5256010360\n"
            "full avg10=0.00 avg60=0.00 avg300=0.00 total=0\n")
    assert parse_pressure(text) == 5256010360 and parse_pressure("") is None
    assert pressure_percent(1_000_000, 1_500_000, 2.0) == 25.0  # 0.5 s waited in 2 s
    assert math.isnan(pressure_percent(None, 1, 1.0)) and math.isnan(pressure_percent(5, 1, 1.0))
    assert pressure_percent(0, 10_000_000, 1.0) == 100.0  # capped: totals read a little apart


def _rank(G, alerts):
    return [rc.member for rc in analyze(G, alerts, RcaSettings()).root_causes]


def test_a_host_out_of_sight_before_its_nodes_went_quiet_is_the_root_cause():
    G = _hosts_model(agent_b="silent")
    silent = [Alert("host:b", "host_state", t, "warn", "agent silent", {"symptom": "agent_silent"})
              for t in (10.0, 11.0, 12.0)]
    quiet = [Alert(f"topic:/{n}/out", "topic_rate", t, "error", "silent") for n in ("cam", "imu")
             for t in (10.5, 11.5)]
    ranked = _rank(G, silent + quiet)
    assert ranked[0] == "host:b" and set(ranked[1:3]) == {"node:/cam", "node:/imu"}
    # a topic of the host's quiet long before the agent went silent: not the host's doing
    early = [Alert("topic:/cam/out", "topic_rate", t, "error", "silent") for t in (2.0, 3.0, 4.0)]
    assert _rank(G, silent + early + quiet)[0] == "node:/cam"


def test_a_saturated_host_explains_its_slow_nodes_unless_one_of_its_processes_is_the_load():
    G = _hosts_model(cpu_b=99.0)
    hot = [Alert("host:b", "host_state", t, "warn", "saturated", {"symptom": "host_cpu", "since": 5.0})
           for t in (15.0, 16.0)]
    slow = [Alert("topic:/cam/out", "topic_rate", t, "warn", "rate down") for t in (8.0, 9.0, 15.0, 16.0)]
    assert _rank(G, hot + slow)[:2] == ["host:b", "node:/cam"]  # saturated since 5 s: before 8 s
    host, cam = analyze(G, hot + slow, RcaSettings()).root_causes[:2]
    assert abs(cam.score - host.score * 0.5) < 1e-6  # the explained node: below, never tied
    assert cam.evidence["explained_by"] == "host:b"
    assert host.evidence["explains_nodes"] == ["node:/cam", "node:/imu"]
    hog = [Alert("node:/imu", "process_resources", t, "warn", "cpu 190 %",
                 {"process": "process:b/8", "symptoms": ["cpu"]}) for t in (6.0, 7.0, 8.0)]
    assert "host:b" not in _rank(G, hot + slow + hog)[:1]
    # on one computer nothing changes: no host member, no lift
    assert "host:b" not in _rank(G, slow) and _rank(G, slow)[0] == "node:/cam"


def test_each_host_gets_its_nodes_and_what_they_use_from_the_system_graph():
    G = _hosts_model()
    a = {"ids": ["node:/cam", "node:/imu", "node:/planner", "topic:/cam/out", "topic:/imu/out"],
         "labels": ["cam", "imu", "planner", "cam/out", "imu/out"], "colors": [1, 2, 3, 4, 5],
         "radii": [1.0] * 5, "positions": [(0, 0), (0, 1), (2, 0), (1, 0), (1, 1)],
         "edges": [("node:/cam", "topic:/cam/out"), ("node:/imu", "topic:/imu/out"),
                   ("topic:/cam/out", "node:/planner"), ("topic:/imu/out", "node:/planner")]}
    b = host_arrays(G, a, "b")
    assert b["ids"] == ["node:/cam", "node:/imu", "topic:/cam/out", "topic:/imu/out"]
    assert b["colors"] == [1, 2, 4, 5] and b["positions"] == [(0, 0), (0, 1), (1, 0), (1, 1)]
    assert b["edges"] == [("node:/cam", "topic:/cam/out"), ("node:/imu", "topic:/imu/out")]
    a_part = host_arrays(G, a, "a")  # the planner and what it subscribes to; not b's nodes
    assert a_part["ids"] == ["node:/planner", "topic:/cam/out", "topic:/imu/out"]
    assert a_part["edges"] == [("topic:/cam/out", "node:/planner"), ("topic:/imu/out", "node:/planner")]
    assert hosts_of(G) == ["a", "b"]


def test_a_host_s_cpu_is_the_use_of_the_cores_its_robot_may_run_on():
    assert cores_of(4, [2, 1, 2]) == [1, 2]  # a cpuset of 2 of 4 cores
    assert cores_of(2, []) == [0, 1]  # none known: every core
    assert cores_of(2, [7]) == [0, 1]  # a core psutil does not list: every core


def test_recently_left_prefixes_keeps_a_node_that_left_for_a_while():
    left = recently_left_prefixes({}, {"/cam": "p1", "/imu": "p2"}, {"/imu": "p2"}, 10.0, keep_s=5.0)
    assert left == {"/cam": ("p1", 10.0)}
    assert recently_left_prefixes(left, {"/imu": "p2"}, {"/imu": "p2"}, 14.5, keep_s=5.0) == left
    assert recently_left_prefixes(left, {"/imu": "p2"}, {"/imu": "p2"}, 15.5, keep_s=5.0) == {}
    assert recently_left_prefixes(left, {"/imu": "p2"}, {"/imu": "p2", "/cam": "p3"}, 11.0) == {}  # back
