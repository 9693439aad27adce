"""Samples of a system that is described, not run: what a collector would read, through the real
`build_model`, one sample a second, with an optional crash.

For measuring the monitor's own cost at sizes this machine cannot run (``bench/bench_replay.py``):
the readings (graph, node → pid, processes, topic windows) are made up from a `Topology` with
plausible noise, the model and the diff are the collector's. A ``crash`` kills one process: its
nodes stay listed, not alive, for ``listed_s`` (as DDS keeps a SIGKILLed participant), then leave;
the topics they fed, and every topic downstream that republishes on receipt, go silent.
"""

from __future__ import annotations

import random
from collections.abc import Iterator
from dataclasses import dataclass

from stream_viz.collect.build import build_model
from stream_viz.collect.readings import (
    Endpoint,
    GraphReading,
    NodeReading,
    PidInfo,
    ProcessReading,
    TopicStats,
)
from stream_viz.demo.topology import Topology
from stream_viz.model.diff import diff
from stream_viz.model.graph import new_graph
from stream_viz.model.ids import make_id
from stream_viz.records import Event, Sample

QOS = {"reliability": "reliable", "durability": "volatile", "history": "keep_last", "depth": 10,
       "deadline_ns": 0, "liveliness": "automatic", "liveliness_lease_ns": 0}
LAUNCHER_PID = 100
DIAGNOSTICS = ("/diagnostics", "diagnostic_msgs/msg/DiagnosticArray")


@dataclass(frozen=True)
class Crash:
    """Process ``group`` of the topology is killed at sample ``at``."""

    group: str
    at: int
    listed_s: int = 20


def silenced(topology: Topology, group: str) -> set[str]:
    """The topics that stop when ``group`` dies: its nodes' topics and, downstream, the topics of
    every node that publishes on receipt of a silenced topic."""
    dead = {n.name for n in topology.group(group).nodes}
    quiet = {p.topic for n in topology.nodes() if n.name in dead for p in n.pubs}
    grew = True
    while grew:
        grew = False
        for n in topology.nodes():
            for p in n.pubs:
                if p.topic not in quiet and p.trigger in quiet:
                    quiet.add(p.topic)
                    grew = True
    return quiet


def _gid(i: int) -> bytes:
    return i.to_bytes(16, "little")


def _reading(topology: Topology, gone: set[str]) -> GraphReading:
    r = GraphReading()
    gids = 0
    for n in topology.nodes():
        if n.name in gone:
            continue
        ns, _, name = n.name.rpartition("/")
        nr = NodeReading(n.name, name, ns or "/")
        nr.services = {s.name: [s.type] for s in n.services}
        nr.clients = {c.name: [c.type] for c in n.clients}
        r.nodes[n.name] = nr
        gids += 1
        r.rosout_gids[n.name] = _gid(gids)
        pubs = [(p.topic, p.type) for p in n.pubs]
        if n.diag_monitor:
            pubs.append(DIAGNOSTICS)
        for roles, (topic, type_) in [(r.publishers, e) for e in pubs] + [(r.subscribers, (s.topic, s.type))
                                                                           for s in n.subs]:
            gids += 1
            r.topics.setdefault(topic, [type_])
            roles.setdefault(topic, []).append(Endpoint(n.name, topic, type_, _gid(gids), QOS))
            if roles is r.publishers:
                r.publisher_gids.setdefault(topic, {})[_gid(gids)] = n.name
    return r


def samples(topology: Topology, n: int, crash: Crash | None = None, t0: float = 1.7e9,
            seed: int = 0) -> Iterator[Sample]:
    """Yield ``n`` samples of ``topology``, one a second from ``t0``, crashing as ``crash`` says.

    Parameters
    ----------
    topology : Topology
        The system (e.g. `stream_viz.demo.generated.generate`).
    n : int
        Number of samples.
    crash : Crash, optional
        The process to kill and when.
    seed : int
        Same seed, same noise.
    """
    rng = random.Random(seed)
    pids = {g.name: 1000 + i for i, g in enumerate(topology.groups)}
    rates = {p.topic: p.rate for node in topology.nodes() for p in node.pubs}
    rates[DIAGNOSTICS[0]] = 1.0
    quiet = silenced(topology, crash.group) if crash else set()
    dead = {nd.name for nd in topology.group(crash.group).nodes} if crash else set()
    prev = new_graph()
    for i in range(n):
        t = t0 + i
        since = i - crash.at if crash and i >= crash.at else None  # seconds since the crash
        gone = dead if since is not None and since >= crash.listed_s else set()
        reading = _reading(topology, gone)
        node_pids = {nd.name: PidInfo(pids[g.name], "confirmed") for g in topology.groups for nd in g.nodes
                     if nd.name not in gone}
        processes = {LAUNCHER_PID: ProcessReading(LAUNCHER_PID, None, "ros2", "ros2 launch system",
                                                  t0 - 10, metrics={"cpu_percent": 0.5, "rss_mb": 40.0})}
        for g in topology.groups:
            alive = not (since is not None and g.name == crash.group)
            if not alive and gone:
                continue
            cmdline = f"python3 -m {topology.entry} --group {g.name}"
            processes[pids[g.name]] = ProcessReading(
                pids[g.name], LAUNCHER_PID, "python3", cmdline, t0 - 5,
                metrics={"cpu_percent": 1.5 * len(g.nodes) * (1 + rng.gauss(0, 0.05)),
                         "rss_mb": 60.0 + 2 * len(g.nodes) + rng.gauss(0, 0.1), "threads": 6.0,
                         "ctx_switches_per_s": 50.0 * len(g.nodes) * (1 + rng.gauss(0, 0.05)),
                         "open_files": 20.0, "io_read_kBps": 0.0, "io_write_kBps": 0.0},
                alive=alive)
        stats = {topic: _topic_stats(rates.get(topic, 0.0), since if topic in quiet else None, rng)
                 for topic in reading.topics}
        G = build_model(reading, node_pids, processes, stats)
        events = _exit_events(t, topology, crash, pids) if since == 0 else []
        yield Sample(t, G, events, diff(prev, G))
        prev = G


def _topic_stats(rate: float, silent_s: int | None, rng: random.Random) -> TopicStats:
    """A topic's window metrics: its rate with a little noise, or fading out ``silent_s`` after
    its publisher stopped (the 3 s window empties, the newest message ages)."""
    if rate <= 0:  # subscribed, never published
        return TopicStats(True, metrics={"rate_hz": 0.0})
    if silent_s is not None:
        left = max(0.0, 1 - (silent_s + 1) / 3)
        m = {"rate_hz": rate * left, "age_s": silent_s + 1 / rate, "latency_ms": 1.0}
        if left:
            m["rate_recent_hz"] = 3 / (silent_s + 3 / rate)
        return TopicStats(True, metrics=m)
    r = rate * (1 + rng.gauss(0, 0.02))
    return TopicStats(True, metrics={
        "rate_hz": r, "rate_recent_hz": rate * (1 + rng.gauss(0, 0.05)), "jitter_ms": abs(rng.gauss(4, 1)),
        "latency_ms": abs(rng.gauss(1, 0.2)), "bandwidth_kBps": r * 0.016, "drops_per_s": 0.0,
        "age_s": rng.uniform(0, 1 / rate)})


def _exit_events(t: float, topology: Topology, crash: Crash, pids: dict[str, int]) -> list[Event]:
    """The collector's ``exit`` events of a killed process whose nodes DDS still lists."""
    pid = pids[crash.group]
    names = sorted(nd.name for nd in topology.group(crash.group).nodes)
    nodes = [make_id("node", name) for name in names]
    data = {"pid": pid, "process": make_id("process", pid), "nodes": nodes, "name": "python3",
            "still_listed": nodes}
    text = f"process {pid} (python3) exited with nodes {', '.join(names)}"
    return [Event(t, "exit", m, "error", text, data) for m in [*nodes, make_id("process", pid)]]
