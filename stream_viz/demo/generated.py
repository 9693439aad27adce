"""Random layered data-flow systems of any size, as a :class:`Topology` the demo runner can start.

Layer 0 holds sources publishing on a timer; each later node subscribes to 1-3 topics of earlier
layers and republishes on receipt of the first (so a fault travels downstream); the last layer
holds sinks. About one node in ten serves a ``std_srvs/srv/Trigger`` service that a later node
calls periodically and needs fresh answers from before it publishes. Nodes are shuffled into
processes of ``nodes_per_process``; ``/system_monitor`` (the diagnostics publisher) joins the first.

With ``namespaces`` the system is split into subsystems as a real robot's is (``/perception``,
``/planning``, …): each node lives in one namespace, takes its inputs from its own namespace but
for a share ``cross`` of them, publishes ``<node>/out``, and its process hosts nodes of its
namespace only. Without (the default), the system and its random draws are as before.
"""

from __future__ import annotations

import math
import random

from stream_viz.demo.topology import ClientSpec, GroupSpec, NodeSpec, PubSpec, ServiceSpec, SubSpec, Topology
from stream_viz.errors import DemoError

MSG = "std_msgs/msg/Float64"
SRV = "std_srvs/srv/Trigger"
SUBSYSTEMS = ("perception", "localization", "mapping", "planning", "control", "drivers", "safety",
              "manipulation", "navigation", "fleet", "teleop", "docking")


def namespace_names(k: int) -> list[str]:
    """Return ``k`` subsystem namespaces: ``/perception``, …, then ``/perception_2``, …"""
    n = len(SUBSYSTEMS)
    return [f"/{SUBSYSTEMS[i % n]}" + (f"_{i // n + 1}" if i >= n else "") for i in range(k)]


def generate(n_nodes: int, seed: int = 0, nodes_per_process: int = 8,
             rate: tuple[float, float] = (2.0, 5.0), service_fraction: float = 0.1,
             layers: int | None = None, namespaces: int = 0, cross: float = 0.05) -> Topology:
    """Return a seeded random layered system of ``n_nodes`` nodes (plus ``/system_monitor``).

    Parameters
    ----------
    n_nodes : int
        Number of data-flow nodes (>= 3).
    seed : int
        Same seed, same system.
    nodes_per_process : int
        Nodes hosted by each process (the last one may hold fewer).
    rate : (float, float)
        Range of the sources' timer rates in Hz; downstream nodes inherit their trigger's rate.
    service_fraction : float
        Share of nodes serving a service that a downstream node calls.
    layers : int, optional
        Number of layers (default ``clamp(round(sqrt(n) / 2), 3, 12)``).
    namespaces : int
        Subsystems (namespaces) to split the nodes into; 0: none (flat names ``/n007_l0``).
    cross : float
        With ``namespaces``: the chance that a node's first input, and apart from it that its
        other inputs, may come from another namespace.
    """
    if n_nodes < 3:
        raise DemoError(f"a generated system needs at least 3 nodes, got {n_nodes}")
    if nodes_per_process < 1:
        raise DemoError(f"nodes_per_process must be >= 1, got {nodes_per_process}")
    rng = random.Random(seed)
    n_layers = layers or max(3, min(12, round(math.sqrt(n_nodes) / 2)))
    n_layers = min(n_layers, n_nodes)
    # every layer gets at least one node; the rest spread at random
    sizes = [1] * n_layers
    for _ in range(n_nodes - n_layers):
        sizes[rng.randrange(n_layers)] += 1
    names: list[list[str]] = []
    k = 0
    spaces = namespace_names(namespaces)
    ns_of: dict[str, str] = {}
    for li, size in enumerate(sizes):
        layer = [f"/n{k + i:03d}_l{li}" for i in range(size)]
        if spaces:  # node k in namespace k mod #namespaces: every namespace spans the layers
            layer = [f"{spaces[(k + i) % len(spaces)]}{n}" for i, n in enumerate(layer)]
            ns_of.update((n, spaces[(k + i) % len(spaces)]) for i, n in enumerate(layer))
        names.append(layer)
        k += size

    topic = {n: (f"{n}/out" if spaces else f"/t{n}") for layer in names for n in layer}
    src_rate: dict[str, float] = {}
    subs: dict[str, list[str]] = {}
    for li, layer in enumerate(names):
        for n in layer:
            if li == 0:
                src_rate[n] = round(rng.uniform(*rate), 1)
                continue
            pool = names[li - 1]
            if spaces and rng.random() >= cross:
                pool = [m for m in pool if ns_of[m] == ns_of[n]] or pool
            first = rng.choice(pool)
            earlier = [m for layer_ in names[:li] for m in layer_ if m != first]
            if spaces and rng.random() >= cross:  # other inputs from the node's own namespace
                earlier = [m for m in earlier if ns_of[m] == ns_of[n]]
            extra = rng.sample(earlier, min(len(earlier), rng.randrange(3)))
            subs[n] = [first, *extra]
            src_rate[n] = src_rate[first]

    # servers in layers < last; each called by one node of a later layer
    servers: dict[str, str] = {}  # client -> server
    candidates = [n for layer in names[:-1] for n in layer]
    for server in rng.sample(candidates, round(service_fraction * n_nodes)):
        li = int(server.rpartition("_l")[2])
        later = [m for layer in names[li + 1:] for m in layer if m not in servers]
        if spaces:  # a subsystem's services are called from within it
            later = [m for m in later if ns_of[m] == ns_of[server]] or later
        if later:
            servers[rng.choice(later)] = server

    nodes: list[NodeSpec] = []
    served = set(servers.values())
    for li, layer in enumerate(names):
        for n in layer:
            client = ()
            requires: tuple[str, ...] = ()
            if n in servers:
                period = round(rng.uniform(2.0, 5.0), 1)
                client = (ClientSpec(f"{servers[n]}/srv", SRV, period=period, timeout=period),)
                requires = (f"{servers[n]}/srv",)
            pubs = ()
            if li < n_layers - 1:
                trig = subs[n][0] if li else ""
                pubs = (PubSpec(topic[n], MSG, src_rate[n], trigger=topic[trig] if trig else "",
                                requires=requires, max_age=3 * client[0].period if client else 1.0),)
            nodes.append(NodeSpec(
                n, pubs=pubs,
                subs=tuple(SubSpec(topic[s], MSG) for s in subs.get(n, ())),
                services=(ServiceSpec(f"{n}/srv", SRV),) if n in served else (),
                clients=client))
    rng.shuffle(nodes)
    if spaces:  # a process hosts nodes of one namespace (as a subsystem's launch file starts them)
        nodes.sort(key=lambda nd: spaces.index(ns_of[nd.name]))
    groups = [GroupSpec(f"p{i // nodes_per_process:03d}", tuple(nodes[i:i + nodes_per_process]))
              for i in range(0, len(nodes), nodes_per_process)]
    groups[0] = GroupSpec(groups[0].name, (*groups[0].nodes, NodeSpec("/system_monitor", diag_monitor=True)))
    return Topology(f"generated_{n_nodes}_s{seed}", tuple(groups))
