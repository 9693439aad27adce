"""The system model G = (M, E, θ) of the paper's §3.1–3.2, as plain networkx data."""

from __future__ import annotations

from stream_viz.model.aggregate import psi
from stream_viz.model.diff import GraphDiff, diff
from stream_viz.model.graph import (
    ACTIVE_KINDS,
    FLOW_KINDS,
    PASSIVE_KINDS,
    add_flow_edge,
    add_member,
    add_tree_edge,
    flow_edges,
    is_active,
    members_of_kind,
    new_graph,
)
from stream_viz.model.ids import ROOT, kind_of, make_id, name_of
from stream_viz.model.queries import layer_subgraph, predecessors, successors, tree

__all__ = [
    "ACTIVE_KINDS", "FLOW_KINDS", "PASSIVE_KINDS", "ROOT", "GraphDiff",
    "add_flow_edge", "add_member", "add_tree_edge", "diff", "flow_edges", "is_active",
    "kind_of", "layer_subgraph", "make_id", "members_of_kind", "name_of", "new_graph",
    "predecessors", "psi", "successors", "tree",
]
