"""The system graph laid out by Graphviz ``dot`` (as ``rqt_graph`` does): layers left to right,
crossings minimised, namespace (or process) groups kept together as clusters.

We write the DOT text ourselves (members and edges sorted by id, so the same system gives the
same text and ``dot`` the same picture whatever the discovery order), run the ``dot`` executable
(Debian ``graphviz``) and read its JSON output. One scene unit is one point: each member's box
is as wide as the viewer draws its label, so neighbouring labels do not overlap.
"""

from __future__ import annotations

import json
import shutil
import subprocess
from collections.abc import Mapping

import networkx as nx

from stream_viz.errors import OutputError
from stream_viz.model.graph import flow_edges
from stream_viz.viz.layout_groups import short_label

CHAR_W = 6.5  # width of one label character in the viewer (scene units at zoom 1)
BOX_PAD = 14.0  # the viewer's label frame: margins and stroke
BOX_H = 26.0
RANK_SEP = 0.3  # inches between layers
NODE_SEP = 0.12  # inches between members of one layer
# Above this many members, dot's crossing reduction and coordinate pass are bounded (else a
# 300-member system takes tens of seconds): fewer passes, a slightly busier picture.
FAST_ABOVE = 150
TIMEOUT_S = 120.0
# Above this many members dot takes tens of seconds (a 2,000-member generated system: ~20 s), and
# the monitor waits for it: such a graph gets the simple layout (`stream_viz.viz.layout.place`).
MAX_MEMBERS = 1500
# A dense graph takes dot minutes even in fast mode (125 discs with 1,800 edges: 11 s, the full
# mode > 120 s): the condensed graph of a randomly wired system. Above this many edges per member
# the simple layout is used.
MAX_EDGES_PER_MEMBER = 6


def dot_executable() -> str | None:
    """Return the path of Graphviz's ``dot``, or None when it is not installed."""
    return shutil.which("dot")


def dot_source(
    G: nx.MultiDiGraph,
    members: list[str],
    group_of: Mapping[str, str],
    beside: Mapping[str, str],
    dag: nx.DiGraph | None = None,
) -> str:
    """Return the DOT text laying out ``members`` of ``G`` (sorted) left to right.

    Members are named ``n<i>`` by their index in ``members``; a group becomes cluster
    ``cluster_<j>`` (groups sorted). ``beside`` maps a member to the one it is drawn next to
    (a service to its server): an invisible edge keeps it in the next layer, near its server.
    Edges not in ``dag`` (the edges that close cycles, `stream_viz.viz.layout.flow_dag`) are
    drawn but do not rank: dot's own cycle breaking (depth first) can stretch a graph with
    calls back upstream over hundreds of layers.
    """
    index = {m: i for i, m in enumerate(members)}
    keep = set(index)
    edges = sorted({(index[u], index[v]) for u, v, _ in flow_edges(G) if u in keep and v in keep and u != v})
    # Dense graphs too: a condensed 1,000-node system (125 groups, 1,800 edges) took > 120 s in full.
    fast = len(members) > FAST_ABOVE or len(edges) > 2 * FAST_ABOVE
    lines = ["digraph system {",
             f"graph [rankdir=LR, ranksep={RANK_SEP}, nodesep={NODE_SEP}, "
             f"newrank=true, splines=false{', mclimit=0.1, nslimit=1' if fast else ''}];",
             "node [shape=box, fixedsize=true, label=\"\"];"]

    def node(m: str) -> str:
        w = (CHAR_W * len(short_label(G, m, group_of.get(m))) + BOX_PAD) / 72.0
        return f"n{index[m]} [width={w:.3f}, height={BOX_H / 72.0:.3f}];"

    groups = sorted(set(group_of.values()))
    for j, g in enumerate(groups):
        # the label only reserves room above the box for the viewer's group caption
        lines.append(f"subgraph cluster_{j} {{ label=\" \"; fontsize=14; margin=10;")
        lines += [node(m) for m in members if group_of.get(m) == g]
        lines.append("}")
    lines += [node(m) for m in members if m not in group_of]
    ranked = None if dag is None else {(index[u], index[v]) for u, v in dag.edges if u in keep and v in keep}
    lines += [f"n{u} -> n{v};" if ranked is None or (u, v) in ranked else f"n{u} -> n{v} [constraint=false];"
              for u, v in edges]
    lines += [f"n{index[a]} -> n{index[m]} [style=invis, weight=4];"
              for m, a in sorted(beside.items()) if m in keep and a in keep]
    lines.append("}")
    return "\n".join(lines)


def run_dot(source: str, exe: str | None = None) -> dict:
    """Run ``dot -Tjson0`` on ``source``; return the parsed output (OutputError if it fails)."""
    exe = exe or dot_executable()
    if exe is None:
        raise OutputError("Graphviz 'dot' is not installed (Debian package graphviz)")
    try:
        out = subprocess.run([exe, "-Tjson0"], input=source, capture_output=True, text=True,
                             timeout=TIMEOUT_S, check=True).stdout
        return json.loads(out)
    except (OSError, subprocess.SubprocessError, ValueError) as e:
        raise OutputError(f"Graphviz dot failed to lay out the system graph: {e}") from e


def read_positions(
    out: Mapping, members: list[str], groups: list[str]
) -> tuple[dict[str, tuple[float, float]], dict[str, tuple[float, float, float, float]]]:
    """Return member -> (x, y) and group -> (x0, y0, x1, y1) from dot's JSON, y pointing down
    (the viewer's), the drawing's top-left corner at the origin."""
    x0, _y0, _x1, y1 = (float(v) for v in out["bb"].split(","))
    pos, boxes = {}, {}
    for obj in out.get("objects", []):
        name = obj.get("name", "")
        if name.startswith("n") and "pos" in obj:
            x, y = (float(v) for v in obj["pos"].split(","))
            pos[members[int(name[1:])]] = (round(x - x0, 1), round(y1 - y, 1))
        elif name.startswith("cluster_") and "bb" in obj:
            a, b, c, d = (float(v) for v in obj["bb"].split(","))
            boxes[groups[int(name[8:])]] = (round(a - x0, 1), round(y1 - d, 1),
                                            round(c - x0, 1), round(y1 - b, 1))
    return pos, boxes
