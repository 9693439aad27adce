"""Turn the plain readings (ROS graph, pids, processes, topic stats) into the model graph. Pure."""

from __future__ import annotations

from collections import defaultdict
from collections.abc import Callable

import networkx as nx

from stream_viz.collect.readings import GraphReading, PidInfo, ProcessReading, TopicStats
from stream_viz.collect.services import ServiceStats
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import ROOT, make_id
from stream_viz.model.theta import SCHEMAS, make_theta


def build_model(
    reading: GraphReading,
    pids: dict[str, PidInfo],
    processes: dict[int, ProcessReading],
    topic_stats: dict[str, TopicStats] | None = None,
    service_stats: dict[str, ServiceStats] | None = None,
    calls: dict[str, list[dict[str, object]]] | None = None,
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
        Topic → `TopicStats` (a topic missing here is ``measured=False``). Its messages/s per
        publisher gid become the topic attribute ``publisher_rates`` (node id → Hz, the gids
        mapped with ``reading.publisher_gids``) and add up to each node's θ ``sent_hz``; its mean
        message age per publisher gid, ``publisher_ages`` (node id → ms, where two or more have one);
        the topics carrying the same header stamps, ``stamp_partners`` (topic id → share).
    service_stats : dict, optional
        Service → `ServiceStats` of the services whose calls are observed (introspection).
    calls : dict, optional
        Service → its open calls as ``{"client", "server", "waited_s"}`` (node ids or None),
        the service attribute ``calls``.

    Returns
    -------
    MultiDiGraph
        Members with attributes and θ; layer 0 ``pub``/``sub``/``send`` edges; layer 1 the
        process tree (process → node, parent process → child, ``root`` over several tops).
    """
    G = new_graph()
    G.graph["qos_version"] = reading.qos_version  # a QoS changed in place: no member or edge did
    stats = topic_stats or {}
    counts: dict[str, dict[str, float]] = {n: dict.fromkeys(SCHEMAS["node"], 0.0) for n in reading.nodes}
    for c in counts.values():
        c["sent_hz"] = float("nan")  # until a measured topic of the node says
    for topic, types in sorted(reading.topics.items()):
        pubs, subs = reading.publishers.get(topic, []), reading.subscribers.get(topic, [])
        st = stats.get(topic, TopicStats(False, "not observed"))
        values = {k: v for k, v in st.metrics.items() if k in SCHEMAS["topic"]}
        values["publishers"], values["subscribers"] = float(len(pubs)), float(len(subs))
        qos = [{"node": e.node, "role": role, **e.qos} for role, eps in (("pub", pubs), ("sub", subs))
               for e in eps]
        attrs = {"type": types[0] if types else "", "qos": qos, "measured": st.measured}
        shares = _shares(st, sorted({e.node for e in pubs}), reading.publisher_gids.get(topic, {}))
        if st.by_publisher:
            attrs["publisher_rates"] = {make_id("node", n): hz for n, hz in shares.items()}
        ages = publisher_ages(st.age_by_publisher, reading.publisher_gids.get(topic, {}))
        if len(ages) > 1:  # whose stamps are late, where several publish (`/tf`)
            attrs["publisher_ages"] = {make_id("node", n): ms for n, ms in ages.items()}
        if st.stamp_partners:  # topics carrying its stamps: sensors triggered together (`stamp_partners`)
            attrs["stamp_partners"] = {make_id("topic", u): share for u, share in st.stamp_partners.items()}
        for n, hz in shares.items():
            if n in counts:
                sent = counts[n]["sent_hz"]
                counts[n]["sent_hz"] = hz if sent != sent else sent + hz
        if len(types) > 1:
            attrs["types"] = list(types)
        if not st.measured:
            attrs["reason"] = st.reason
        add_member(G, make_id("topic", topic), theta=make_theta("topic", values), **attrs)
    for fqn, nr in sorted(reading.nodes.items()):
        info = pids.get(fqn, PidInfo(None, "unknown"))
        proc = processes.get(info.pid) if info.pid is not None else None
        attrs = {"name": nr.name, "namespace": nr.namespace, "pid": info.pid, "pid_status": info.status,
                 "alive": proc.alive if proc is not None else True,
                 "instances": instances(nr.instances, reading.participants.get(fqn, 0))}
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
    _add_calls(G, reading, counts, service_stats or {}, calls or {})
    for fqn, c in counts.items():
        G.nodes[make_id("node", fqn)]["theta"] = make_theta("node", c)
    _add_process_tree(G, reading, pids, processes)
    return G


def instances(listed: int, participants: int) -> int:
    """How many nodes share a name: those DDS lists, but no more than the participants that
    publish its /rosout or /parameter_events when any do.

    A participant that ended can leave its node names in the graph cache without any endpoint
    (its last discovery-info sample arriving after its removal: a "ghost" that stays until the
    observer restarts); the node restarted under that name then lists twice, one process.

    Parameters
    ----------
    listed : int
        The name's entries in the node listing.
    participants : int
        Distinct GUID prefixes among its /rosout and /parameter_events publishers (0: unknown).
    """
    return min(listed, participants) if participants else listed


def publisher_rates(by_gid: dict[bytes, float], gid_nodes: dict[bytes, str]) -> dict[str, float]:
    """Return node fqn → messages/s from messages/s per publisher gid (a node's publishers of
    one topic add up); gids of no known publisher are left out."""
    return _per_node(by_gid, gid_nodes, lambda a, b: a + b)


def publisher_ages(by_gid: dict[bytes, float], gid_nodes: dict[bytes, str]) -> dict[str, float]:
    """Return node fqn → mean message age (ms) from the mean age per publisher gid (a node's
    publishers of one topic: the oldest); gids of no known publisher are left out."""
    return _per_node(by_gid, gid_nodes, max)


def _per_node(by_gid: dict[bytes, float], gid_nodes: dict[bytes, str],
              combine: Callable[[float, float], float]) -> dict[str, float]:
    out: dict[str, float] = {}
    for gid, x in by_gid.items():
        node = gid_nodes.get(gid)
        if node is not None:
            out[node] = combine(out[node], x) if node in out else x
    return out


def _shares(st: TopicStats, pubs: list[str], gid_nodes: dict[bytes, str]) -> dict[str, float]:
    """Messages/s each publisher node of a topic sent over the window; empty when unknown.

    From the publisher gids of the messages when there are some; a silent topic's publishers
    each sent none; the only publisher sent them all; several without gids: unknown.
    """
    rate = st.metrics.get("rate_hz")
    if rate is None or not pubs:
        return {}
    if st.by_publisher:
        rates = publisher_rates(st.by_publisher, gid_nodes)
        return {n: rates.get(n, 0.0) for n in pubs}
    if rate == 0 or len(pubs) == 1:
        return {n: rate for n in pubs}
    return {}


def _add_calls(G: nx.MultiDiGraph, reading: GraphReading, counts: dict[str, dict[str, float]],
               service_stats: dict[str, ServiceStats], calls: dict[str, list[dict[str, object]]]) -> None:
    """Service and action members (observed calls on services), ``send`` edges client → server."""
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
            values: dict[str, float] = {"servers": len(srv), "clients": len(cli)}
            extra: dict[str, object] = {}
            ss = service_stats.get(name) if kind == "service" else None
            if ss is not None:
                waited = [w for w, _, _ in ss.open_calls]
                values.update(calls_per_s=ss.calls_per_s, response_ms=ss.response_ms,
                              waiting=len(waited), wait_s=max(waited, default=0.0))
                extra = {"introspected": True, "calls": list(calls.get(name, []))}
            add_member(G, make_id(kind, name), type=(types[name] or [""])[0], servers=srv, clients=cli,
                       theta=make_theta(kind, values), **extra)
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
