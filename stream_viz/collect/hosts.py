"""Several computers, one model: the agents' reports merged into the monitor's sample.

Which host a node is on comes from its participant's GUID prefix (the Fast DDS host id, bytes
2–3), never from names. The process tree has a host level, on one computer too (a saturated
computer is a member the RCA can name): ``root → host:<name> → process tree → node``. This
computer's processes keep their ids (``process:<pid>``); another host's are
``process:<host>/<pid>`` (PIDs of different computers collide). Nodes and processes carry
``host``. A remote node's process comes from its host's agent; without one (or with an agent
silent for longer than ``stale_s``) the node hangs under its host with ``pid_status``
``unknown`` and is listed as unreadable ("process unknown: no agent on host X"), never guessed.

Time: a report is dated by when the monitor received it, never by the agent's clock, and the
agent's rates are measured on its own monotonic clock; so clock offsets between computers do
not enter process metrics, exits or staleness.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import networkx as nx

from stream_viz.collect.exitcodes import describe_exit, note_exit_code
from stream_viz.collect.hostreport import AGENT_TOPIC, HostReport, StatusRow, decode, host_of_prefix
from stream_viz.collect.naming import recently_left
from stream_viz.collect.processes import MachineSampler
from stream_viz.collect.readings import PidInfo, ProcessReading
from stream_viz.model.graph import PROCESS_TREE, add_member, add_tree_edge
from stream_viz.model.ids import ROOT, make_id
from stream_viz.model.queries import predecessors
from stream_viz.model.theta import SCHEMAS, make_theta
from stream_viz.records import Event

STALE_PERIODS = 3.0  # an agent is silent after this many of its periods without a report
STALE_MIN_S = 2.0
# A host seen for less than this without a report may still have an agent starting: its nodes
# wait (as on one computer, pid_status "remote") rather than enter the model under a provisional name.
AGENT_GRACE_S = 3.0
# A node that left the graph this long before its agent reported its process ended left with it
# (rclpy sends the goodbye, then the interpreter exits): an agent's period and a monitor's later.
REMOTE_LEFT_S = 5.0


@dataclass
class Received:
    """An agent's latest report and when the monitor received it (the monitor's clock)."""

    t: float
    report: HostReport

    def stale(self, now: float) -> bool:
        """True when the agent has been silent for longer than it may be."""
        return now - self.t > max(STALE_PERIODS * self.report.period_s, STALE_MIN_S)


def host_name(host_id: int, received: dict[int, Received], names: dict[int, str]) -> str:
    """The name of a host: its agent's (now or earlier), else its Fast DDS host id in hex."""
    if host_id in received:
        return received[host_id].report.host
    return names.get(host_id, f"{host_id:04x}")


def remote_id(host: str, pid: int) -> str:
    """The member id of process ``pid`` of another host: ``process:<host>/<pid>``."""
    return make_id("process", f"{host}/{pid}")


def merge_hosts(G: nx.MultiDiGraph, pids: dict[str, PidInfo], own: tuple[int | None, str],
                received: dict[int, Received], now: float, names: dict[int, str] | None = None,
                first_seen: dict[int, float] | None = None,
                machine: Mapping[str, float] | None = None) -> dict[str, str]:
    """Add the host level and the remote processes to the model ``G`` of one sample.

    Parameters
    ----------
    G : MultiDiGraph
        The model as `build_model` made it (this host's processes only).
    pids : dict
        Node fqn → `PidInfo` (``prefix`` says the host; status ``remote`` for another host's).
    own : (int or None, str)
        This host's Fast DDS host id (None: not known, every node is taken as this host's) and name.
    received : dict
        Host id → the agent's latest `Received` report.
    now : float
        The sample's time (the monitor's clock).
    names : dict, optional
        Host id → a name an agent gave earlier (kept after it went silent).
    first_seen : dict, optional
        Host id → when its first node was seen; a host without report younger than
        `AGENT_GRACE_S` is left out for now (default: all are old enough).
    machine : mapping, optional
        This computer's own host θ (`MachineSampler`); another host's comes in its agent's report.

    Returns
    -------
    dict
        Member id → why it is unknown (nodes and processes of hosts without a live agent).
    """
    names, first_seen = names or {}, first_seen or {}
    own_id, own_name = own
    node_host = {fqn: host_of_prefix(p.prefix) for fqn, p in pids.items()
                 if p.prefix and make_id("node", fqn) in G}
    # Without its own host id the monitor cannot tell another computer's nodes from its own.
    remote = set() if own_id is None else (
        {h for h in node_host.values() if h != own_id} | {h for h in received if h != own_id})
    _host_member(G, own_name, own_id, "local", machine or {})
    tops = [m for m, k in G.nodes(data="kind") if k == "process"
            and not predecessors(G, m, layer=PROCESS_TREE)]
    for m, k in list(G.nodes(data="kind")):
        if k == "process":
            G.nodes[m]["host"] = own_name
    for fqn, h in node_host.items():
        if h == own_id or own_id is None:
            G.nodes[make_id("node", fqn)]["host"] = own_name
    if ROOT in G:
        G.remove_edges_from([(ROOT, t, PROCESS_TREE) for t in list(G.successors(ROOT))])
    else:
        add_member(G, ROOT, theta=make_theta("root", {}))
    add_tree_edge(G, ROOT, make_id("host", own_name))
    for t in sorted(tops):
        if t != ROOT:
            add_tree_edge(G, make_id("host", own_name), t)
    unknown: dict[str, str] = {}
    for h in sorted(remote):
        name = host_name(h, received, names)
        nodes = sorted(fqn for fqn, nh in node_host.items() if nh == h)
        got = received.get(h)
        if got is None and h not in names and now - first_seen.get(h, -math.inf) < AGENT_GRACE_S:
            continue
        if got is None:
            why = f"process unknown: no agent on host {name}"
        elif got.stale(now):
            why = f"process unknown: the agent on host {name} has been silent for {now - got.t:.0f} s"
        else:
            why = ""
        if got is None:
            _host_member(G, name, h, "none", {})
        elif why:  # a silent agent: the computer's θ unknown, how long it has been silent said
            _host_member(G, name, h, "silent", {}, silent_s=round(now - got.t, 1))
        else:
            _host_member(G, name, h, "reporting", got.report.machine)
        add_tree_edge(G, ROOT, make_id("host", name))
        if got is not None:
            unknown.update(_add_processes(G, name, got.report, why))
        for fqn in nodes:
            unknown.update(_place_node(G, fqn, pids[fqn].prefix, name, got, why))
    return unknown


def _host_member(G: nx.MultiDiGraph, name: str, host_id: int | None, agent: str,
                 machine: Mapping[str, float], **attrs: Any) -> None:
    values = {k: v for k, v in machine.items() if k in SCHEMAS["host"]}
    if "cpus" in machine:
        attrs["cpus"] = round(machine["cpus"], 2)  # a quota's may be a fraction (1.5 CPUs)
    if "mem_limit_mb" in machine:  # the memory in use is of this limit (a container's)
        attrs["mem_limit_mb"] = round(machine["mem_limit_mb"], 1)
    add_member(G, make_id("host", name), theta=make_theta("host", values), agent=agent,
               host_id="?" if host_id is None else f"{host_id:04x}", **attrs)


def _add_processes(G: nx.MultiDiGraph, host: str, report: HostReport, why: str) -> dict[str, str]:
    """The report's processes under ``host:<host>`` (no θ when the report is stale)."""
    unknown = {}
    for pid, p in sorted(report.processes.items()):
        pid_id = remote_id(host, pid)
        measured = p.alive and not why
        values = {k: v for k, v in p.metrics.items() if k in SCHEMAS["process"]} if measured else {}
        attrs: dict[str, Any] = {"name": p.name, "cmdline": p.cmdline, "create_time": p.create_time,
                                 "pid": pid, "alive": p.alive, "host": host}
        if p.username is not None:
            attrs["username"] = p.username
        if why:
            attrs["unknown"] = why
            unknown[pid_id] = why
        add_member(G, pid_id, theta=make_theta("process", values), **attrs)
    for pid, p in sorted(report.processes.items()):
        parent = p.ppid if p.ppid in report.processes and p.ppid != pid else None
        add_tree_edge(G, make_id("host", host) if parent is None else remote_id(host, parent),
                      remote_id(host, pid))
    return unknown


def _place_node(G: nx.MultiDiGraph, fqn: str, prefix: str, host: str, got: Received | None,
                why: str) -> dict[str, str]:
    """Attach a remote node to its process (from the agent) or, unknown, to its host."""
    node = make_id("node", fqn)
    attrs = G.nodes[node]
    attrs["host"] = host
    pid = got.report.participants.get(prefix) if got is not None else None
    if pid is not None and pid in got.report.processes:
        attrs.update(pid=pid, pid_status="unknown" if why else "confirmed",
                     alive=got.report.processes[pid].alive)
        add_tree_edge(G, remote_id(host, pid), node)
    else:
        why = why or f"process unknown: the agent on host {host} does not list its participant"
        attrs.update(pid=None, pid_status="unknown")
        add_tree_edge(G, make_id("host", host), node)
    if why:
        attrs["process_unknown"] = why
        return {node: why}
    return {}


def remote_exits(t: float, host: str, before: HostReport, now: HostReport,
                 node_prefix: dict[str, str], left: Mapping[str, str] | None = None) -> list[Event]:
    """The ``exit`` events of processes alive in the agent's previous report and ended in this one,
    or left out of it once DDS no longer lists their nodes; as the collector's: nodes DDS still
    lists make it an error (no clean shutdown). The agent keeps a process that ended in its
    reports while DDS lists its nodes, so one left out while they are listed has not ended.

    ``node_prefix`` maps the node fqns listed now to their participant's GUID prefix, ``left``
    those that left the graph lately (`recently_left_prefixes`): a process's nodes too.
    """
    listed_prefixes = set(node_prefix.values())
    out = []
    for pid, p in sorted(before.processes.items()):
        after = now.processes.get(pid)
        if not p.alive or (after is not None and after.alive and _same_start(p, after)):
            continue
        prefixes = {pre for pre, q in before.participants.items() if q == pid}
        had = sorted({n for n, pre in node_prefix.items() if pre in prefixes}
                     | {n for n, pre in (left or {}).items() if pre in prefixes and n not in node_prefix})
        listed = [n for n in had if node_prefix.get(n) in listed_prefixes]
        still = bool(prefixes & listed_prefixes)
        if after is None and still and not set(now.participants) & prefixes:
            continue  # left out while the agent maps its participants again: not said to have ended
        level = "error" if still else ("warn" if prefixes else "info")
        nodes = [make_id("node", n) for n in had]
        proc = remote_id(host, pid)
        data = {"pid": pid, "host": host, "process": proc, "nodes": nodes, "name": p.name,
                "still_listed": [make_id("node", n) for n in listed]}
        code = now.exits.get(pid)  # where the agent reads exit codes
        level = note_exit_code(code, level, still, data)
        text = f"process {pid} ({p.name}) on host {host} {describe_exit(code)}" + (
            f" with nodes {', '.join(had)}" if had else "")
        if (oom := now.ooms.get(pid)) is not None:  # the agent read its memory group's OOM count
            level, text, data = oom.said(text, data)
        for m in [*nodes, proc]:
            out.append(Event(t, "exit", m, level, text, data))
    return out


def _same_start(p: ProcessReading, q: ProcessReading) -> bool:
    """Not a new process under the same pid. A start time only one of them knows says nothing:
    the monitor may have missed the report that carried it (sent when new and every tenth)."""
    return p.create_time is None or q.create_time is None or p.create_time == q.create_time


def remote_pids(G: nx.MultiDiGraph, own_name: str) -> dict[str, tuple[str, int]]:
    """Node id → (host, pid) of the nodes of other hosts whose process is known."""
    return {m: (d["host"], d["pid"]) for m, d in G.nodes(data=True)
            if d.get("kind") == "node" and d.get("host", own_name) != own_name and d.get("pid") is not None}


def remote_restarts(t: float, before: dict[str, tuple[str, int]],
                    now: dict[str, tuple[str, int]]) -> list[Event]:
    """``restart`` events of nodes of other hosts now in another process (as the collector's)."""
    out = []
    for m, (host, pid) in sorted(now.items()):
        old = before.get(m)
        if old is not None and old != (host, pid):
            out.append(Event(t, "restart", m, "warn",
                             f"node {m.partition(':')[2]} now runs in process {pid} on host {host} "
                             f"(was {old[1]} on host {old[0]})",
                             {"old_pid": old[1], "pid": pid, "host": host, "old_host": old[0]}))
    return out


def recently_left_prefixes(left: Mapping[str, tuple[str, float]], before: Mapping[str, str],
                           now: Mapping[str, str], t: float,
                           keep_s: float = REMOTE_LEFT_S) -> dict[str, tuple[str, float]]:
    """Return node → (its participant's GUID prefix, when it left) of the nodes that left the graph
    within ``keep_s`` before ``t`` (`naming.recently_left`): ``left`` the previous answer,
    ``before`` and ``now`` node → prefix of the previous sample and this one."""
    when = recently_left({n: t0 for n, (_, t0) in left.items()}, before, now, t, keep_s)
    return {n: (left[n][0] if n in left else before[n], t0) for n, t0 in when.items()}


class HostReports:
    """Reads the agents' reports (a raw best-effort subscription, drained at each sample) and
    merges them into the collector's model.

    Parameters
    ----------
    node : rclpy Node
        The observer node (it only subscribes).
    own : (int or None, str)
        This host's Fast DDS host id and name.
    """

    def __init__(self, node: Any, own: tuple[int | None, str]) -> None:
        from diagnostic_msgs.msg import DiagnosticArray

        from stream_viz.collect.agent import QOS

        self.own = own
        self.received: dict[int, Received] = {}
        self.names: dict[int, str] = {}
        self.first_seen: dict[int, float] = {}
        self.machine = MachineSampler()  # this computer's host θ
        self._pids: dict[str, tuple[str, int]] = {}  # remote node -> (host, pid) last sample
        self._prefixes: dict[str, str] = {}  # node -> its participant's prefix, last sample
        self._left: dict[str, tuple[str, float]] = {}  # `recently_left_prefixes`
        self._type = DiagnosticArray
        self._sub = node.create_subscription(DiagnosticArray, AGENT_TOPIC, lambda m: None, QOS)

    def take(self, now: float | None = None) -> dict[int, tuple[HostReport, HostReport]]:
        """Take every report waiting; return host id → (previous, newest) of hosts that sent one."""
        now = time.time() if now is None else now
        new: dict[int, tuple[HostReport, HostReport]] = {}
        while True:
            with self._sub.handle:
                got = self._sub.handle.take_message(self._type, False)
            if got is None:
                break
            msg = got[0] if isinstance(got, tuple) else got
            rows = _rows(msg)
            try:
                old = self.received.get(int(dict(rows[0].values).get("host_id", -1)) if rows else -1)
                report = decode(rows, old.report if old is not None else None)
            except (KeyError, ValueError):  # not an agent's report: nothing to merge
                continue
            if report is None or report.host_id == self.own[0]:
                continue
            self.received[report.host_id] = Received(now, report)
            self.names[report.host_id] = report.host
            if old is not None:
                first = new.get(report.host_id, (old.report,))[0]
                new[report.host_id] = (first, report)
        return new

    def apply(self, G: nx.MultiDiGraph, pids: dict[str, PidInfo],
              t: float) -> tuple[list[Event], dict[str, str]]:
        """Merge the reports into ``G``; return the remote exit events and the unknown members."""
        new = self.take(t)
        node_prefix = {fqn: p.prefix for fqn, p in pids.items() if p.prefix}
        for prefix in node_prefix.values():
            self.first_seen.setdefault(host_of_prefix(prefix), t)
        self._left = recently_left_prefixes(self._left, self._prefixes, node_prefix, t)
        self._prefixes = node_prefix
        left = {n: pre for n, (pre, _) in self._left.items()}
        events = []
        for _, (before, after) in sorted(new.items()):
            events += remote_exits(t, after.host, before, after, node_prefix, left)
        local = [p.pid for p in pids.values() if p.status in ("confirmed", "unverified") and p.pid]
        unknown = merge_hosts(G, pids, self.own, self.received, t, self.names,
                              self.first_seen, self.machine.sample(local))
        now = remote_pids(G, self.own[1])
        events += remote_restarts(t, self._pids, now)
        self._pids = now
        return events, unknown


def _rows(msg: Any) -> list[StatusRow]:
    return [StatusRow(s.level[0] if isinstance(s.level, bytes | bytearray) else int(s.level), s.name,
                      s.message, s.hardware_id, [(kv.key, kv.value) for kv in s.values])
            for s in msg.status]

