"""Turn the plain readings (ROS graph, pids, processes, topic stats) into the model graph. Pure."""

from __future__ import annotations

from collections import defaultdict

import networkx as nx

from stream_viz.collect.readings import GraphReading, PidInfo, ProcessReading, TopicStats
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import ROOT, make_id
from stream_viz.model.theta import SCHEMAS, make_theta


def build_model(
    reading: GraphReading,
    pids: dict[str, PidInfo],
    processes: dict[int, ProcessReading],
    topic_stats: dict[str, TopicStats] | None = None,
) -> nx.MultiDiGraph:
    """Return the model graph of one sample.

    Parameters
    ----------
    reading : GraphReading
        Nodes, topics with their endpoints, services/actions per node.
    pids : dict
        Node fqn → `PidInfo` (a node missing here has pid None, status ``unknown``).
    processes : dict
        Pid → `ProcessReading` of the nodes' processes and their ancestors; ``alive=False`` ones
        are processes that ended while DDS still lists their nodes.
    topic_stats : dict, optional
        Topic → `TopicStats` (a topic missing here is ``measured=False``).

    Returns
    -------
    MultiDiGraph
        Members with attributes and θ; layer 0 ``pub``/``sub``/``send`` edges; layer 1 the
        process tree (process → node, parent process → child, ``root`` over several tops).
    """
    G = new_graph()
    stats = topic_stats or {}
    counts: dict[str, dict[str, float]] = {n: dict.fromkeys(SCHEMAS["node"], 0.0) for n in reading.nodes}
    for topic, types in sorted(reading.topics.items()):
        pubs, subs = reading.publishers.get(topic, []), reading.subscribers.get(topic, [])
        st = stats.get(topic, TopicStats(False, "not observed"))
        values = {k: v for k, v in st.metrics.items() if k in SCHEMAS["topic"]}
        values["publishers"], values["subscribers"] = float(len(pubs)), float(len(subs))
        qos = [{"node": e.node, "role": role, **e.qos} for role, eps in (("pub", pubs), ("sub", subs))
               for e in eps]
        attrs = {"type": types[0] if types else "", "qos": qos, "measured": st.measured}
        if len(types) > 1:
            attrs["types"] = list(types)
        if not st.measured:
            attrs["reason"] = st.reason
        add_member(G, make_id("topic", topic), theta=make_theta("topic", values), **attrs)
    for fqn, nr in sorted(reading.nodes.items()):
        info = pids.get(fqn, PidInfo(None, "unknown"))
        proc = processes.get(info.pid) if info.pid is not None else None
        attrs = {"name": nr.name, "namespace": nr.namespace, "pid": info.pid, "pid_status": info.status,
                 "alive": proc.alive if proc is not None else True, "instances": nr.instances}
        if info.status == "ambiguous":
            attrs["pid_candidates"] = list(info.candidates)
        add_member(G, make_id("node", fqn), **attrs)
    for topic in reading.topics:
        tid = make_id("topic", topic)
        for e in {e.node for e in reading.publishers.get(topic, [])}:
            add_flow_edge(G, make_id("node", e), tid, "pub")
            counts[e]["publishers"] += 1
        for e in {e.node for e in reading.subscribers.get(topic, [])}:
            add_flow_edge(G, tid, make_id("node", e), "sub")
            counts[e]["subscriptions"] += 1
    _add_calls(G, reading, counts)
    for fqn, c in counts.items():
        G.nodes[make_id("node", fqn)]["theta"] = make_theta("node", c)
    _add_process_tree(G, reading, pids, processes)
    return G


def _add_calls(G: nx.MultiDiGraph, reading: GraphReading, counts: dict[str, dict[str, float]]) -> None:
    """Service and action members, and ``send`` edges client node → server node."""
    for kind, srv_attr, cli_attr, label in (("service", "services", "clients", "services"),
                                            ("action", "action_servers", "action_clients", "actions")):
        servers: dict[str, list[str]] = defaultdict(list)
        clients: dict[str, list[str]] = defaultdict(list)
        types: dict[str, list[str]] = {}
        for fqn, nr in reading.nodes.items():
            for name, t in getattr(nr, srv_attr).items():
                servers[name].append(fqn)
                types.setdefault(name, list(t))
            for name, t in getattr(nr, cli_attr).items():
                clients[name].append(fqn)
                types.setdefault(name, list(t))
            if kind == "service":
                counts[fqn]["services"] += len(nr.services)
                counts[fqn]["clients"] += len(nr.clients)
        sends: dict[tuple[str, str], list[str]] = defaultdict(list)
        for name in sorted(set(servers) | set(clients)):
            srv, cli = sorted(set(servers[name])), sorted(set(clients[name]))
            add_member(G, make_id(kind, name), type=(types[name] or [""])[0], servers=srv, clients=cli,
                       theta=make_theta(kind, {"servers": len(srv), "clients": len(cli)}))
            for c in cli:
                for s in srv:
                    if c != s:
                        sends[(c, s)].append(name)
        for (c, s), names in sorted(sends.items()):
            cid, sid = make_id("node", c), make_id("node", s)
            if G.has_edge(cid, sid, 0):
                G.edges[cid, sid, 0][label] = names
            else:
                add_flow_edge(G, cid, sid, "send", **{label: names})


def _add_process_tree(G: nx.MultiDiGraph, reading: GraphReading, pids: dict[str, PidInfo],
                      processes: dict[int, ProcessReading]) -> None:
    """Tree T_1: parent process → child process → node; a virtual root over several tops."""
    for pid, p in sorted(processes.items()):
        attrs = {"name": p.name, "cmdline": p.cmdline, "create_time": p.create_time, "pid": pid,
                 "alive": p.alive}
        if p.username is not None:
            attrs["username"] = p.username
        if p.unreadable:
            attrs["unreadable"] = list(p.unreadable)
        values = {k: v for k, v in p.metrics.items() if k in SCHEMAS["process"]} if p.alive else {}
        add_member(G, make_id("process", pid), theta=make_theta("process", values), **attrs)
    tops = []
    for pid, p in sorted(processes.items()):
        if p.ppid is not None and p.ppid in processes and p.ppid != pid:
            add_tree_edge(G, make_id("process", p.ppid), make_id("process", pid))
        else:
            tops.append(make_id("process", pid))
    for fqn in reading.nodes:
        info = pids.get(fqn)
        if info is not None and info.pid in processes:
            add_tree_edge(G, make_id("process", info.pid), make_id("node", fqn))
    if len(tops) > 1:
        add_member(G, ROOT, theta=make_theta("root", {}))
        for t in tops:
            add_tree_edge(G, ROOT, t)
