"""Small literal model graphs for tests, the screenshot and the benchmark (no ROS needed)."""

from __future__ import annotations

import networkx as nx
import numpy as np

from stream_viz.demo.topology import NodeSpec, Topology
from stream_viz.model.graph import add_flow_edge, add_member, add_tree_edge, new_graph
from stream_viz.model.ids import ROOT, make_id, name_of
from stream_viz.model.theta import make_theta

# (node, process pid, published topics, subscribed topics)
ROBOT = [
    ("/camera", 101, ["/image", "/camera_info"], []),
    ("/lidar", 101, ["/scan"], []),
    ("/imu", 102, ["/imu"], []),
    ("/base_driver", 102, ["/odom", "/joint_states"], ["/cmd_vel"]),
    ("/detector", 103, ["/objects", "/detections_image"], ["/image", "/camera_info"]),
    ("/localization", 104, ["/pose", "/tf"], ["/scan", "/imu", "/odom"]),
    ("/mapper", 104, ["/map_updates"], ["/scan", "/pose"]),
    ("/map_server", 105, ["/map"], ["/map_updates"]),
    ("/planner", 105, ["/plan", "/costmap"], ["/map", "/pose", "/objects", "/goal"]),
    ("/controller", 106, ["/cmd_vel"], ["/plan", "/pose", "/tf"]),
    ("/teleop", 106, ["/goal"], ["/joint_states"]),
    ("/diagnostics_agg", 106, ["/diagnostics_agg"], ["/diagnostics"]),
]
SERVICES = [("/get_map", "/planner", "/map_server"), ("/set_mode", "/teleop", "/controller")]


def demo_graph(theta: bool = True, rng: np.random.Generator | None = None) -> nx.MultiDiGraph:
    """Return the demo-sized robot: 12 nodes, 21 topics, 2 services, 6 processes + the root."""
    rng = rng or np.random.default_rng(0)
    G = new_graph()
    add_member(G, ROOT)
    add_member(G, "process:1", name="launch")
    add_tree_edge(G, ROOT, "process:1")
    topics = sorted({t for _, _, pubs, subs in ROBOT for t in pubs + subs} | {"/diagnostics"})
    for t in topics:
        add_member(G, f"topic:{t}")
    for node, pid, pubs, subs in ROBOT:
        n = f"node:{node}"
        p = f"process:{pid}"
        if p not in G:
            add_member(G, p, name=f"robot_proc_{pid}")
            add_tree_edge(G, "process:1", p)
        add_member(G, n, pid=pid)
        add_tree_edge(G, p, n)
        for t in pubs:
            add_flow_edge(G, n, f"topic:{t}", "pub")
        for t in subs:
            add_flow_edge(G, f"topic:{t}", n, "sub")
    for srv, client, server in SERVICES:
        add_member(G, f"service:{srv}")
        add_flow_edge(G, f"node:{client}", f"node:{server}", "send", services=[f"service:{srv}"])
    if theta:
        set_theta(G, rng)
    return G


def set_theta(G: nx.MultiDiGraph, rng: np.random.Generator) -> None:
    """Put plausible random θ on the processes and topics of ``G`` (in place)."""
    for m, kind in G.nodes(data="kind"):
        if kind == "process":
            G.nodes[m]["theta"] = make_theta("process", {
                "cpu_percent": rng.uniform(1, 60), "rss_mb": rng.uniform(40, 400),
                "threads": rng.integers(4, 30), "ctx_switches_per_s": rng.uniform(10, 2000),
                "open_files": rng.integers(5, 60), "io_read_kBps": rng.uniform(0, 50),
                "io_write_kBps": rng.uniform(0, 50)})
        elif kind == "topic":
            G.nodes[m]["theta"] = make_theta("topic", {
                "rate_hz": rng.uniform(1, 30), "jitter_ms": rng.uniform(0, 5),
                "latency_ms": rng.uniform(0, 20), "bandwidth_kBps": rng.uniform(0, 5000),
                "drops_per_s": 0.0, "publishers": 1, "subscribers": G.out_degree(m)})


def chain_graph(n_nodes: int, fan: int = 2, procs: int = 50, rng: np.random.Generator | None = None
                ) -> nx.MultiDiGraph:
    """Return a large synthetic system: ``n_nodes`` nodes, one topic each, each topic read by
    ``fan`` later nodes, nodes spread over ``procs`` processes (for the benchmark)."""
    rng = rng or np.random.default_rng(0)
    G = new_graph()
    add_member(G, ROOT)
    for p in range(procs):
        add_member(G, f"process:{1000 + p}", name=f"proc{p}")
        add_tree_edge(G, ROOT, f"process:{1000 + p}")
    for i in range(n_nodes):
        add_member(G, f"node:/n{i}")
        add_member(G, f"topic:/t{i}")
        add_flow_edge(G, f"node:/n{i}", f"topic:/t{i}", "pub")
        add_tree_edge(G, f"process:{1000 + i % procs}", f"node:/n{i}")
    for i in range(n_nodes):
        for j in rng.choice(np.arange(i + 1, n_nodes), size=min(fan, n_nodes - i - 1), replace=False) \
                if i + 1 < n_nodes else []:
            add_flow_edge(G, f"topic:/t{i}", f"node:/n{int(j)}", "sub")
    set_theta(G, rng)
    return G


def topology_graph(topo: Topology) -> nx.MultiDiGraph:
    """Return the model graph a monitor would build for ``topo`` (a demo robot's specification):
    its nodes, topics and served services with their ``pub``/``sub``/``send`` edges, one process
    per group under the root (no θ). For the layout benchmark and tests, without running ROS."""
    G = new_graph()
    add_member(G, ROOT)
    servers = {s.name: n.name for n in topo.nodes() for s in n.services}
    for t in sorted(topo.topics()):
        add_member(G, make_id("topic", t))
    for s, node in sorted(servers.items()):
        add_member(G, make_id("service", s), servers=[node])
    for i, group in enumerate(topo.groups):
        proc = make_id("process", 1000 + i)
        add_member(G, proc, name=group.name)
        add_tree_edge(G, ROOT, proc)
        for spec in group.nodes:
            add_member(G, make_id("node", spec.name), pid=1000 + i)
            add_tree_edge(G, proc, make_id("node", spec.name))
    for u, v, kind in sorted(topo.edges()):
        if kind == "send":
            via = sorted(c.name for c in _spec(topo, u).clients if servers.get(c.name) == name_of(v))
            add_flow_edge(G, u, v, kind, services=via)
        else:
            add_flow_edge(G, u, v, kind)
    return G


def _spec(topo: Topology, node: str) -> NodeSpec:
    return next(n for n in topo.nodes() if n.name == name_of(node))
