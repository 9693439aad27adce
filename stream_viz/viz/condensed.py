"""``/condensed``: the system graph of a large system, condensed around what went wrong.

At 1,000 nodes the full graph (``/system``) is a carpet of unreadable labels. The condensed graph
draws each group (ROS namespace, else the node's process; the process under ``--group-by
process``) as one disc labelled with its name and size, ``/perception (84 nodes)``, with one edge per
pair of groups that exchange data, while the members that matter are drawn in full: the alerted
and gone members, the RCA's top trajectory and root causes (the *focus*), and the direct
neighbours of the trajectory and root causes. A group some of whose members are drawn in full
keeps the rest as one disc, ``/perception (80 of 84 nodes)``. Pure functions over plain data;
`DrawnCondensed` logs the result.
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import networkx as nx
import rerun as rr

from stream_viz.errors import ModelError
from stream_viz.model.graph import FLOW, PROCESS_TREE, flow_edges
from stream_viz.model.ids import kind_of, name_of
from stream_viz.viz import paths, style
from stream_viz.viz.layout import Layout, display_members, service_servers, settle
from stream_viz.viz.layout_groups import full_label, member_groups
from stream_viz.viz.system import changed_fields, graph_update

CONDENSE_ABOVE = 300  # members (nodes, topics, services, actions) above which `auto` condenses
MODES = ("auto", "on", "off")
GROUP_PREFIX = "group:"  # node id of a condensed group in /condensed (not a member id)
GROUP_COLOR = (160, 172, 196)  # light slate: its label is read on the viewer's dark background
GROUP_RADIUS = 18.0
TRAJECTORY_TOP = 3  # root causes whose member is in the focus (the top one's trajectory too)


def group_id(group: str) -> str:
    """Return the node id of a condensed group in ``/condensed`` (``group:/perception``)."""
    return f"{GROUP_PREFIX}{group}"


def condense_groups(G: nx.MultiDiGraph, members: Iterable[str],
                    grouping: str = "namespace") -> dict[str, str]:
    """Return member -> the group it is condensed into, for the ``members`` of ``G`` that have one.

    Parameters
    ----------
    G : MultiDiGraph
        The model graph (flow edges, process tree).
    members : iterable of str
        The members drawn (`stream_viz.viz.layout.display_members`).
    grouping : str
        ``namespace`` (the default; a node outside any namespace group is condensed with its
        process, else a flat system would not condense at all), ``process``, or ``none`` (as
        ``namespace``: the condensed graph needs groups, whatever the boxes of ``/system``).

    A topic, service or action outside a group joins the group of the nodes it connects when
    they are all in one (a process's internal topic); one between groups belongs to none.
    """
    members = list(members)
    out = {} if grouping == "process" else member_groups(G, members, "namespace")
    out.update(process_groups(G, [m for m in members if m not in out and kind_of(m) == "node"]))
    servers = service_servers(G)
    for m in members:
        if m in out or kind_of(m) == "node" or m not in G:
            continue
        ends = {x for x, keys in G._pred[m].items() if FLOW in keys}
        ends |= {x for x, keys in G._succ[m].items() if FLOW in keys}
        ends |= set(servers.get(m, ()))
        groups = {out.get(x) for x in ends if kind_of(x) == "node"}
        if len(groups) == 1 and None not in groups:
            out[m] = groups.pop()
    return out


def process_groups(G: nx.MultiDiGraph, nodes: Iterable[str]) -> dict[str, str]:
    """Return node -> its process's group name, for the ``nodes`` whose process hosts two or more
    of them: the process name (``component_container``), with the pid when several processes of
    that name host nodes (``python3 1001``: one disc each, not one disc for every Python node)."""
    proc_of: dict[str, str] = {}
    for n in nodes:
        if n in G:
            procs = [u for u, _, k in G.in_edges(n, keys=True) if k == PROCESS_TREE]
            if procs:
                proc_of[n] = min(procs)
    hosted: dict[str, int] = {}
    for p in proc_of.values():
        hosted[p] = hosted.get(p, 0) + 1
    name = {p: str(G.nodes[p].get("name") or "pid") for p in hosted}
    named: dict[str, int] = {}
    for p in hosted:
        named[name[p]] = named.get(name[p], 0) + 1
    label = {p: name[p] if named[name[p]] == 1 else f"{name[p]} {G.nodes[p].get('pid', name_of(p))}"
             for p in hosted}
    return {n: label[p] for n, p in proc_of.items() if hosted[p] > 1}


def focus_members(
    G: nx.MultiDiGraph,
    status: Mapping[str, str] | None = None,
    root_causes: Sequence[Mapping[str, Any]] = (),
    gone: Collection[str] = (),
) -> set[str]:
    """Return the members drawn in full whatever their group: alerted (``status``: member ->
    severity; an alerted process stands for its nodes), gone, the top root causes and the top
    trajectory. Members that are not drawn (hosts, the root) are left out."""
    out: set[str] = set()
    for m in [*(status or {}), *gone, *diagnosis_core(root_causes)]:
        try:
            kind = kind_of(m)
        except ModelError:
            continue
        if kind == "process" and m in G:
            out |= {v for _, v, k in G.out_edges(m, keys=True) if k == PROCESS_TREE and kind_of(v) == "node"}
        elif kind in style.KIND_COLOR and kind not in ("process", "host", "root"):
            out.add(m)
    return out


def diagnosis_core(root_causes: Sequence[Mapping[str, Any]]) -> list[str]:
    """Return the top trajectory (first symptom -> root cause) and the other top root causes."""
    top = root_causes[0] if root_causes else None
    trajectory = list(top.get("trajectory") or [top["member"]]) if top else []
    return list(dict.fromkeys([*trajectory, *(rc["member"] for rc in root_causes[:TRAJECTORY_TOP])]))


def with_neighbours(G: nx.MultiDiGraph, members: Iterable[str]) -> set[str]:
    """Return ``members`` and their direct data-flow neighbours in ``G`` (both directions)."""
    out = set(members)
    for m in list(out):
        if m in G:
            out |= {x for x, keys in G._succ[m].items() if FLOW in keys}
            out |= {x for x, keys in G._pred[m].items() if FLOW in keys}
    return out


@dataclass
class Condensed:
    """What ``/condensed`` draws: members in full, groups as one disc each, and the edges.

    ``groups`` maps a group's node id (`group_id`) to ``(group, nodes condensed into it, nodes
    of the group)`` (its topics and services go with them); ``edges`` are pairs of drawn ids
    (members or group ids), sorted.
    """

    members: list[str] = field(default_factory=list)
    groups: dict[str, tuple[str, int, int]] = field(default_factory=dict)
    edges: list[tuple[str, str]] = field(default_factory=list)


def condense(G: nx.MultiDiGraph, group_of: Mapping[str, str], full: Collection[str],
             members: Iterable[str] | None = None) -> Condensed:
    """Return the condensed graph of ``G``: each group drawn as one disc, but ``full`` in full.

    Parameters
    ----------
    G : MultiDiGraph
        The model graph; its flow edges are condensed.
    group_of : mapping
        Member -> group (`condense_groups`). A member without a group is drawn in full, except a
        topic, service or action between two groups that is not in ``full``: it is left out and
        its publishers' discs get an edge to its subscribers' (one edge per pair).
    full : collection of str
        Members drawn in full (the focus and its neighbours, `with_neighbours`).
    members : iterable of str, optional
        The members to draw (default: `display_members` of ``G``).

    Returns
    -------
    Condensed
        Members drawn in full (sorted), the groups' discs, the edges between drawn ids without
        self-loops (a group's internal edges vanish into its disc).
    """
    members = display_members(G) if members is None else sorted(members)
    full = set(full)
    rep: dict[str, str | None] = {}
    total: dict[str, int] = {}  # nodes per group: a roboticist counts nodes, not their topics
    hidden: dict[str, int] = {}
    for m in members:
        g = group_of.get(m)
        node = int(kind_of(m) == "node")
        if g is not None:
            total[g] = total.get(g, 0) + node
        if m in full:
            rep[m] = m
        elif g is not None:
            rep[m] = group_id(g)
            hidden[g] = hidden.get(g, 0) + node
        elif kind_of(m) == "node":
            rep[m] = m  # a node of no group: nothing to condense it into
        else:
            rep[m] = None  # between groups: replaced by edges from its publishers to its subscribers
    edges: set[tuple[str, str]] = set()
    passing: dict[str, tuple[set[str], set[str]]] = {}
    for u, v, _ in flow_edges(G):
        if u not in rep or v not in rep:
            continue
        ru, rv = rep[u], rep[v]
        if ru is None and rv is not None:
            passing.setdefault(u, (set(), set()))[1].add(rv)
        elif rv is None and ru is not None:
            passing.setdefault(v, (set(), set()))[0].add(ru)
        elif ru is not None and rv is not None and ru != rv:
            edges.add((ru, rv))
    for ins, outs in passing.values():
        edges |= {(a, b) for a in ins for b in outs if a != b}
    drawn = {r for r in rep.values() if r is not None}
    groups = {group_id(g): (g, n, total[g]) for g, n in sorted(hidden.items())}
    return Condensed(members=sorted(drawn - set(groups)), groups=groups,
                     edges=sorted(e for e in edges if e[0] in drawn and e[1] in drawn))


def group_label(group: str, condensed: int, total: int) -> str:
    """Return a group disc's label: ``/perception (84 nodes)``; ``(80 of 84 nodes)`` when some are
    drawn apart; ``(topics)`` when only topics or services are left in it."""
    if condensed == 0:
        return f"{group} (topics)"
    return f"{group} ({condensed} nodes)" if condensed == total else f"{group} ({condensed} of {total} nodes)"


def condensed_graph(G: nx.MultiDiGraph, c: Condensed) -> nx.MultiDiGraph:
    """Return ``c`` as a model-like graph for the layout (`stream_viz.viz.layout.settle`): groups
    are laid out like nodes, each label as wide as drawn."""
    C = nx.MultiDiGraph()
    for m in c.members:
        C.add_node(m, kind=kind_of(m), label=full_label(G, m))
    for gid, (g, n, total) in c.groups.items():
        C.add_node(gid, kind="node", label=group_label(g, n, total))
    for u, v in c.edges:
        C.add_edge(u, v, key=FLOW, kind="pub")
    return C


def condensed_arrays(G: nx.MultiDiGraph, c: Condensed, layout: Layout, gone: Collection[str] = (),
                     status: Mapping[str, str] | None = None, root_causes: Sequence[Mapping[str, Any]] = ()
                     ) -> dict[str, list]:
    """Return the plain arrays drawn at ``/condensed``: members coloured as in ``/system`` (kind,
    alert severity, gone grey), the top root cause cyan and its trajectory magenta, groups slate
    and larger the more members they hold."""
    status = status or {}
    top = root_causes[0] if root_causes else None
    trajectory = set(top.get("trajectory") or []) if top else set()
    ids, labels, colors, radii, positions = [], [], [], [], []
    for m in c.members:
        kind = kind_of(m)
        is_gone = m in gone or bool(G.nodes[m].get("gone")) if m in G else True
        if is_gone:
            color = style.GONE_COLOR
        elif top is not None and m == top["member"]:
            color = style.ROOT_CAUSE_COLOR
        elif m in status:
            color = style.SEVERITY_COLOR.get(status[m], style.KIND_COLOR[kind])
        elif m in trajectory:
            color = style.TRAJECTORY_COLOR
        else:
            color = style.KIND_COLOR[kind]
        ids.append(m)
        labels.append(full_label(G, m) + (style.GONE_SUFFIX if is_gone else ""))
        colors.append(color)
        radii.append(style.KIND_RADIUS[kind])
        positions.append(layout.pos[m])
    for gid, (g, n, total) in c.groups.items():
        ids.append(gid)
        labels.append(group_label(g, n, total))
        colors.append(GROUP_COLOR)
        radii.append(GROUP_RADIUS * (1.0 + 0.25 * min(4, len(str(n)) - 1)))  # 1, 10, 100+: grows with size
        positions.append(layout.pos[gid])
    return {"ids": ids, "labels": labels, "colors": colors, "radii": radii, "positions": positions,
            "edges": list(c.edges)}


def is_condensed(mode: str, members: int, above: int = CONDENSE_ABOVE) -> bool:
    """Return True if a system of ``members`` drawn members gets the condensed graph (``mode``:
    ``auto`` above ``above`` members, ``on`` always, ``off`` never)."""
    if mode not in MODES:
        raise ValueError(f"condensed view {mode!r}: expected one of {', '.join(MODES)}")
    return mode == "on" or (mode == "auto" and members > above)


class DrawnCondensed:
    """The ``/condensed`` entity of a recording stream: its own layout (kept while the condensed
    structure stays, `settle`), and what it shows, so that only changed fields are logged.
    `forget` when the sink starts empty (a new file part)."""

    def __init__(self) -> None:
        self.layout: Layout | None = None
        self.arrays: Mapping[str, Any] | None = None
        self.key: Any = None
        self._groups: tuple[Any, list[str], dict[str, str]] | None = None  # (structure, members, groups)

    def forget(self) -> None:
        self.arrays, self.key = None, None

    def log(self, rec: Any, G: nx.MultiDiGraph, grouping: str, gone: Collection[str],
            status: Mapping[str, str], root_causes: Sequence[Mapping[str, Any]], key: Any = None,
            structure: int | None = None) -> bool:
        """Log ``/condensed`` for ``G`` if ``key`` (what it is drawn from) changed; return True if
        anything was logged. ``structure`` (`stream_viz.viz.recorder.Recorder.system`): while it
        is the same, the members and their groups (``G``'s structure alone) are not found again."""
        if key is not None and key == self.key and (self.layout is None or self.layout.pending is None):
            return False
        if structure is None or self._groups is None or self._groups[0] != (structure, grouping):
            members = display_members(G)
            groups = condense_groups(G, members, grouping)
            self._groups = None if structure is None else ((structure, grouping), members, groups)
        else:
            _, members, groups = self._groups
        # Neighbours of the diagnosis only: with those of every alerted member too, a crash that
        # silences 30 topics downstream drew 100 members in full, unreadable again.
        full = focus_members(G, status, root_causes, gone) | with_neighbours(G, diagnosis_core(root_causes))
        c = condense(G, groups, full & set(members), members)
        self.layout = settle(condensed_graph(G, c), self.layout, grouping="none")
        a = condensed_arrays(G, c, self.layout, gone, status, root_causes)
        fields = changed_fields(self.arrays, a)
        if fields:
            rec.log(paths.CONDENSED, *graph_update(a, fields, show_labels=True))
        self.arrays, self.key = a, key
        return bool(fields)


def log_condensed(rec: rr.RecordingStream, G: nx.MultiDiGraph, grouping: str = "namespace",
                  gone: Collection[str] = (), status: Mapping[str, str] | None = None,
                  root_causes: Sequence[Mapping[str, Any]] = ()) -> dict[str, list]:
    """Log the condensed graph of ``G`` at ``/condensed`` at the stream's current time (laid out
    afresh); return the arrays logged."""
    d = DrawnCondensed()
    d.log(rec, G, grouping, gone, status or {}, root_causes)
    return dict(d.arrays or {})
