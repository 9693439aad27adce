"""Groups of the system graph drawn as labelled boxes: ROS namespaces (default), processes or hosts.

A member's namespace group is the first segment of its name when the name has more (``/amr1/scan``
-> ``/amr1``), for namespaces that hold a ROS node (topic names alone, ``/t/a``, ``/t/b``, make
no group); a group of one member is not drawn. A node's process group is the name of the
process hosting it (topics and services belong to no process). Inside a namespace box a label
drops the prefix the box already shows.
"""

from __future__ import annotations

from collections.abc import Iterable

import networkx as nx

from stream_viz.model.graph import PROCESS_TREE
from stream_viz.model.ids import kind_of, name_of

GROUPINGS = ("namespace", "process", "host", "none")


def namespace_of(name: str) -> str | None:
    """Return the top namespace of a ROS name (``/amr1/camera/image`` -> ``/amr1``), or None."""
    parts = [p for p in name.split("/") if p]
    return f"/{parts[0]}" if len(parts) > 1 else None


def member_groups(G: nx.MultiDiGraph, members: Iterable[str], by: str = "namespace") -> dict[str, str]:
    """Return member -> group for the ``members`` of ``G`` in a group of two or more.

    Parameters
    ----------
    by : str
        ``namespace``, ``process`` (the hosting process's name, else ``pid <n>``), ``host`` (the
        computer a node runs on, with several: collect/hosts.py) or ``none``.
    """
    out: dict[str, str] = {}
    for m in members:
        g = None
        if by == "namespace":
            g = namespace_of(name_of(m))
        elif by == "process" and kind_of(m) == "node" and m in G:
            procs = [u for u, _, k in G.in_edges(m, keys=True) if k == PROCESS_TREE]
            if procs:
                p = min(procs)
                g = str(G.nodes[p].get("name") or f"pid {name_of(p)}")
        elif by == "host" and kind_of(m) == "node" and m in G:
            g = G.nodes[m].get("host")
        if g is not None:
            out[m] = g
    sizes: dict[str, int] = {}
    for g in out.values():
        sizes[g] = sizes.get(g, 0) + 1
    with_node = {g for m, g in out.items() if kind_of(m) == "node"}
    return {m: g for m, g in out.items() if sizes[g] > 1 and g in with_node}


def full_label(G: nx.MultiDiGraph, m: str) -> str:
    """Return a member's label: its ``label`` attribute, else its name."""
    if m in G:
        return str(G.nodes[m].get("label") or name_of(m))
    return name_of(m)


def short_label(G: nx.MultiDiGraph, m: str, group: str | None) -> str:
    """Return the label drawn inside ``group``: without the namespace the box shows."""
    label = full_label(G, m)
    if group and group.startswith("/") and label.startswith(group + "/"):
        return label[len(group) + 1:]
    return label
