"""Explicit positions of the system graph and the process tree.

The system graph is laid out by Graphviz ``dot`` (`layered`, :mod:`stream_viz.viz.layout_dot`):
left to right from sources to sinks, crossings minimised, namespaces as groups, the same picture
for the same system. During a run `settle` keeps the picture still: it lays the graph out again
only once its members and edges have stopped changing for a few samples, and meanwhile puts new
members in a provisional column on the right. Services have no layer-0 edges (a call is a
``send`` edge client -> server); each service is drawn right of its server.

`place` is the layout of our own (layers by longest path, rows near placed neighbours, a placed
member never moves): used where ``dot`` is not installed, and as the baseline of
``bench/bench_layout.py``.
"""

from __future__ import annotations

import sys
from collections.abc import Iterable
from dataclasses import dataclass, field, replace

import networkx as nx

from stream_viz.errors import OutputError
from stream_viz.model.graph import FLOW, flow_edges
from stream_viz.model.ids import make_id
from stream_viz.viz import layout_dot
from stream_viz.viz.layout_groups import member_groups

COL = 200.0  # horizontal distance between layers
ROW = 70.0  # vertical distance between rows
SERVICE_STEP = 36.0  # vertical distance between services stacked at one server
FLOW_KINDS = ("node", "topic", "action")  # members placed in layers
SIDE_KINDS = ("service",)  # members placed beside their server

SETTLE_SAMPLES = 3  # samples a changed structure must stay unchanged before it is laid out again

Pos = tuple[float, float]
Box = tuple[float, float, float, float]
Structure = tuple[tuple[str, ...], tuple[tuple[str, str], ...]]


@dataclass
class Layout:
    """Positions of the system graph's members, the groups' boxes, and what they were made for."""

    layer: dict[str, int] = field(default_factory=dict)
    row: dict[str, int] = field(default_factory=dict)
    pos: dict[str, Pos] = field(default_factory=dict)
    # Services placed without a known server (they move once, when the server is known).
    loose: set[str] = field(default_factory=set)
    group_of: dict[str, str] = field(default_factory=dict)  # member -> its group (drawn as a box)
    boxes: dict[str, Box] = field(default_factory=dict)  # group -> (x0, y0, x1, y1)
    grouping: str = "namespace"
    key: Structure | None = None  # the structure laid out
    pending: Structure | None = None  # a changed structure waiting to settle, and for how long
    pending_n: int = 0

    def copy(self) -> Layout:
        """Return an independent copy."""
        return replace(self, layer=dict(self.layer), row=dict(self.row), pos=dict(self.pos),
                       loose=set(self.loose), group_of=dict(self.group_of), boxes=dict(self.boxes))

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


def structure(G: nx.MultiDiGraph) -> Structure:
    """Return what the layout depends on: the drawn members and their flow edges, sorted."""
    members = display_members(G)
    keep = set(members)
    edges = sorted({(u, v) for u, v, _ in flow_edges(G) if u in keep and v in keep and u != v})
    return tuple(members), tuple(edges)


def layered(G: nx.MultiDiGraph, grouping: str = "namespace") -> Layout:
    """Return the layout of ``G`` by Graphviz ``dot``; where dot is missing or fails, `place`.

    Members and edges are handed to dot sorted by id: the same system gets the same positions
    whatever order it was discovered in. ``grouping``: ``namespace``, ``process`` or ``none``.
    """
    members = display_members(G)
    group_of = member_groups(G, members, grouping)
    beside = {s: servers[0] for s, servers in service_servers(G).items() if servers and s in G}
    exe = layout_dot.dot_executable()
    key = structure(G)
    if len(members) > layout_dot.MAX_MEMBERS:
        _warn(f"more than {layout_dot.MAX_MEMBERS} members: the system graph uses the simple layout")
    elif len(key[1]) > layout_dot.MAX_EDGES_PER_MEMBER * max(1, len(members)):
        _warn("a graph this dense takes dot minutes: it uses the simple layout")
    elif exe is not None:
        try:
            out = layout_dot.run_dot(layout_dot.dot_source(G, members, group_of, beside, flow_dag(G)), exe)
            groups = sorted(set(group_of.values()))
            pos, boxes = layout_dot.read_positions(out, members, groups)
            if set(pos) == set(members):
                return Layout(pos=pos, group_of=group_of, boxes=boxes, grouping=grouping, key=key)
        except OutputError as e:
            _warn(str(e))
    else:
        _warn("Graphviz 'dot' not found (Debian package graphviz): the system graph uses the simple layout")
    return replace(place(G), grouping=grouping, key=key)


_warned: set[str] = set()


def _warn(msg: str) -> None:
    if msg not in _warned:  # once per process, not once per layout
        _warned.add(msg)
        print(f"stream-viz: {msg}", file=sys.stderr)


def provisional(G: nx.MultiDiGraph, layout: Layout) -> Layout:
    """Return ``layout`` plus the members of ``G`` it lacks, stacked in sorted order in a column
    right of everything (until the next `layered`); placed members do not move."""
    new = [m for m in display_members(G) if m not in layout.pos]
    if not new:
        return layout
    out = layout.copy()
    xs = [p[0] for p in layout.pos.values()] + [b[2] for b in layout.boxes.values()]
    ys = [p[1] for p in layout.pos.values()]
    x = (max(xs) + COL) if xs else 0.0
    y0 = min(ys) if ys else 0.0
    taken = {p for p in layout.pos.values()}
    k = 0
    for m in new:
        while (x, y0 + k * ROW / 2) in taken:
            k += 1
        out.pos[m] = (x, y0 + k * ROW / 2)
        k += 1
    return out


def settle(G: nx.MultiDiGraph, layout: Layout | None, after: int = SETTLE_SAMPLES,
           grouping: str = "namespace") -> Layout:
    """Return the layout to draw ``G`` with at this sample (call once per sample).

    The first call lays ``G`` out. Later, an unchanged structure keeps the layout (the very same
    object); a changed one is laid out again once it has stayed the same for ``after``
    consecutive calls; until then its new members get provisional places (`provisional`).
    """
    key = structure(G)
    if layout is None or layout.key is None or grouping != layout.grouping:
        return layered(G, grouping)
    if key == layout.key:
        return layout
    n = layout.pending_n + 1 if key == layout.pending else 1
    if n >= after:
        return layered(G, grouping)
    out = provisional(G, layout)
    out = out.copy() if out is layout else out
    out.pending, out.pending_n = key, n
    return out


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
