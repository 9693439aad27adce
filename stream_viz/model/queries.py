"""Queries of the paper's §3.2.3: predecessors and successors, and the layer subgraphs."""

from __future__ import annotations

from typing import Literal

import networkx as nx

Which = Literal["all", "active", "passive"]


def _keep(G: nx.MultiDiGraph, member: str, which: Which) -> bool:
    if which == "all":
        return True
    return G.nodes[member]["active"] == (which == "active")


def predecessors(G: nx.MultiDiGraph, member: str, which: Which = "all", layer: int = 0) -> list[str]:
    """Return the members ``m`` with an edge ``((m, member), layer)``, sorted.

    Parameters
    ----------
    G : MultiDiGraph
        The model graph.
    member : str
        The member asked about.
    which : {"all", "active", "passive"}
        Keep all predecessors, only active ones (nodes) or only passive ones.
    layer : int
        The edge layer (0: data flow; i ≥ 1: tree ``T_i``).
    """
    return sorted(
        {u for u, _, k in G.in_edges(member, keys=True) if k == layer and _keep(G, u, which)}
    )


def successors(G: nx.MultiDiGraph, member: str, which: Which = "all", layer: int = 0) -> list[str]:
    """Return the members ``m`` with an edge ``((member, m), layer)``, sorted (see `predecessors`)."""
    return sorted(
        {v for _, v, k in G.out_edges(member, keys=True) if k == layer and _keep(G, v, which)}
    )


def layer_subgraph(G: nx.MultiDiGraph, layer: int = 0) -> nx.MultiDiGraph:
    """Return the edge-induced subgraph of one layer (``G_0`` or ``T_i``) as a copy."""
    edges = [(u, v, k) for u, v, k in G.edges(keys=True) if k == layer]
    return G.edge_subgraph(edges).copy()


def tree(G: nx.MultiDiGraph, layer: int = 1) -> nx.DiGraph:
    """Return tree ``T_layer`` as a simple DiGraph (parent → child), member attributes kept."""
    T = nx.DiGraph(layer_subgraph(G, layer))
    return T
