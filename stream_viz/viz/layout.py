"""Layouts computed by us (explicit positions): the layered system graph and the process tree.

The system graph is drawn left to right from sources to sinks like a good ``rqt_graph``: each
member of ``G_0`` gets a layer (longest path from the sources after breaking cycles, sources
pulled next to what they feed) and a row in its layer (near the mean row of its placed
neighbours). A placed member never moves, so the picture stays put while the graph grows.
Services have no layer-0 edges (a call is a ``send`` edge client -> server); each service is
drawn in the gap right of its server.
"""

from __future__ import annotations

from collections.abc import Iterable
from dataclasses import dataclass, field

import networkx as nx

from stream_viz.model.graph import FLOW, flow_edges
from stream_viz.model.ids import make_id

COL = 200.0  # horizontal distance between layers
ROW = 70.0  # vertical distance between rows
SERVICE_STEP = 36.0  # vertical distance between services stacked at one server
FLOW_KINDS = ("node", "topic", "action")  # members placed in layers
SIDE_KINDS = ("service",)  # members placed beside their server

Pos = tuple[float, float]


@dataclass
class Layout:
    """Positions of the system graph's members; grows with `place`, never moves a placed member."""

    layer: dict[str, int] = field(default_factory=dict)
    row: dict[str, int] = field(default_factory=dict)
    pos: dict[str, Pos] = field(default_factory=dict)
    # Services placed without a known server (they move once, when the server is known).
    loose: set[str] = field(default_factory=set)

    def copy(self) -> Layout:
        """Return an independent copy."""
        return Layout(dict(self.layer), dict(self.row), dict(self.pos), set(self.loose))

    def __contains__(self, member: str) -> bool:
        return member in self.pos


def display_members(G: nx.MultiDiGraph) -> list[str]:
    """Return the members drawn in the system graph (nodes, topics, actions, services), sorted."""
    return sorted(m for m, k in G.nodes(data="kind") if k in FLOW_KINDS or k in SIDE_KINDS)


def flow_dag(G: nx.MultiDiGraph) -> nx.DiGraph:
    """Return ``G_0`` among the layered members as a DAG, cycles broken deterministically.

    Members are ordered by the greedy feedback-arc-set heuristic of Eades, Lin and Smyth (sinks
    to the end, sources to the front, else the member with most out- minus in-edges, ties by id);
    edges pointing backwards in that order are dropped unless they close no cycle after all
    (they are still drawn, just not used to layer).
    """
    D = nx.DiGraph()
    D.add_nodes_from(m for m, k in G.nodes(data="kind") if k in FLOW_KINDS)
    D.add_edges_from((u, v) for u, v, _ in flow_edges(G) if u in D and v in D and u != v)
    H = D.copy()
    front: list[str] = []
    back: list[str] = []
    while H:
        changed = True
        while changed:
            changed = False
            for m in sorted(m for m in H if H.out_degree(m) == 0):
                back.append(m)
                H.remove_node(m)
                changed = True
            for m in sorted(m for m in H if H.in_degree(m) == 0):
                front.append(m)
                H.remove_node(m)
                changed = True
        if H:
            m = min(H, key=lambda m: (H.in_degree(m) - H.out_degree(m), m))
            front.append(m)
            H.remove_node(m)
    rank = {m: i for i, m in enumerate(front + back[::-1])}
    dropped = sorted((u, v) for u, v in D.edges if rank[u] > rank[v])
    D.remove_edges_from(dropped)
    for u, v in dropped:  # keep every dropped edge that closes no cycle after all
        if not nx.has_path(D, v, u):
            D.add_edge(u, v)
    return D


def _as_id(kind: str, name: str) -> str:
    return name if name.startswith(f"{kind}:") else make_id(kind, name)


def service_servers(G: nx.MultiDiGraph) -> dict[str, list[str]]:
    """Return service -> its server nodes, sorted.

    Read from ``send`` edges (attribute ``services``, the services the call goes through: the
    edge's target serves them) and from a service member's ``servers`` attribute.
    """
    out: dict[str, set[str]] = {}
    # The collector names services and servers by ROS name ("/map/get", "/map_server"); member
    # ids ("service:/map/get") are accepted too.
    for _u, v, key, data in G.edges(keys=True, data=True):
        if key == FLOW and data.get("kind") == "send":
            for label, kind in (("services", "service"), ("actions", "action")):
                for s in data.get(label, ()) or ():
                    out.setdefault(_as_id(kind, s), set()).add(v)
    for m, data in G.nodes(data=True):
        if data.get("kind") in SIDE_KINDS:
            for node in data.get("servers", ()) or ():
                out.setdefault(m, set()).add(_as_id("node", node))
    return {s: sorted(n for n in nodes if n in G) for s, nodes in out.items()}


def _nearest_free(taken: set[int], target: float) -> int:
    """Return the free integer row nearest to ``target`` (ties: the upper one)."""
    base = round(target)
    for d in range(len(taken) + 2):
        for r in (base - d, base + d) if d else (base,):
            if r not in taken:
                return r
    raise AssertionError("unreachable")


def _layers_for_new(D: nx.DiGraph, fixed: dict[str, int], new: Iterable[str]) -> dict[str, int]:
    """Return layers of the ``new`` members; ``fixed`` layers of placed members stay."""
    new = set(new)
    layer = dict(fixed)
    topo = [m for m in nx.lexicographical_topological_sort(D) if m in new]
    for m in topo:  # longest path from the sources (topological order: preds come first)
        layer[m] = max((layer[p] + 1 for p in D.predecessors(m)), default=0)
    for m in reversed(topo):  # a source sits just before the first of what it feeds
        if D.in_degree(m) == 0:
            layer[m] = max(0, min((layer[s] for s in D.successors(m)), default=1) - 1)
    return {m: layer[m] for m in new}


def place(G: nx.MultiDiGraph, layout: Layout | None = None) -> Layout:
    """Return ``layout`` extended with positions for the members of ``G`` it does not have yet.

    Parameters
    ----------
    G : MultiDiGraph
        The model graph (members of any kind; only the system-graph members are placed).
    layout : Layout, optional
        The layout so far (not modified). Its members keep their positions.
    """
    out = layout.copy() if layout is not None else Layout()
    D = flow_dag(G)
    new = [m for m in D if m not in out.layer]
    layers = _layers_for_new(D, out.layer, new)
    taken: dict[int, set[int]] = {}
    for m, lay in out.layer.items():
        taken.setdefault(lay, set()).add(out.row[m])
    U = D.to_undirected(as_view=True)
    for m in sorted(new, key=lambda m: (layers[m], m)):
        lay = layers[m]
        rows = [out.row[n] for n in U.neighbors(m) if n in out.row]
        target = sum(rows) / len(rows) if rows else (max(taken.get(lay, {-1})) + 1)
        r = _nearest_free(taken.setdefault(lay, set()), target)
        taken[lay].add(r)
        out.layer[m], out.row[m] = lay, r
        out.pos[m] = (lay * COL, r * ROW)
    _place_services(G, out)
    return out


def _place_services(G: nx.MultiDiGraph, out: Layout) -> None:
    servers = service_servers(G)
    services = sorted(m for m, k in G.nodes(data="kind") if k in SIDE_KINDS)
    by_server: dict[str, list[str]] = {}
    for s in services:
        placed = [n for n in servers.get(s, ()) if n in out.layer]
        if placed and (s not in out.pos or s in out.loose):
            by_server.setdefault(placed[0], []).append(s)
    occupied = {p for m, p in out.pos.items() if m not in out.layer}
    for server, group in sorted(by_server.items()):
        x0, y0 = out.pos[server]
        k = 0
        for s in group:
            while True:
                # Stack below-right of the server, in the gap between two layers.
                p = (x0 + COL / 2, y0 + ROW / 4 + k * SERVICE_STEP)
                k += 1
                if p not in occupied:
                    break
            out.pos[s] = p
            occupied.add(p)
            out.loose.discard(s)
    # Services whose server is unknown: a column right of everything, until the server shows up.
    right = (max((lay for lay in out.layer.values()), default=-1) + 1) * COL
    k = 0
    for s in services:
        if s in out.pos:
            continue
        while (right, k * SERVICE_STEP) in occupied:
            k += 1
        out.pos[s] = (right, k * SERVICE_STEP)
        occupied.add(out.pos[s])
        out.loose.add(s)


def tree_layout(T: nx.DiGraph, root: str, dx: float = 170.0, dy: float = 110.0) -> dict[str, Pos]:
    """Return a top-down tidy layout of tree ``T`` (parent -> child) below ``root``.

    Leaves take consecutive columns in sorted depth-first order; a parent sits centred above its
    children. Members of ``T`` not reachable from ``root`` are laid out as further trees to the right.
    """
    pos: dict[str, Pos] = {}
    next_col = [0.0]

    def visit(v: str, depth: int) -> float:
        kids = sorted(c for c in T.successors(v) if c not in pos)
        pos[v] = (0.0, depth * dy)  # mark visited (guards against a malformed tree with cycles)
        if not kids:
            x = next_col[0]
            next_col[0] += dx
        else:
            xs = [visit(c, depth + 1) for c in kids]
            x = (xs[0] + xs[-1]) / 2
        pos[v] = (x, depth * dy)
        return x

    roots = [root] if root in T else []
    roots += sorted(m for m in T if T.in_degree(m) == 0 and m != root)
    for r in roots:
        if r not in pos:
            visit(r, 0)
    for m in sorted(T):  # anything left (cycles): its own column
        if m not in pos:
            visit(m, 0)
    return pos
