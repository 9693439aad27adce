"""Top-down aggregation ψ_i(v) = Σ_{c ∈ C_i(v)} (ψ_i(c) + θ(c)) over a tree layer."""

from __future__ import annotations

from collections.abc import Mapping

import networkx as nx
import numpy as np

from stream_viz.model.queries import tree


def psi(G: nx.MultiDiGraph, theta: Mapping[str, np.ndarray], layer: int = 1) -> dict[str, np.ndarray]:
    """Return ψ_layer(v) for every member of tree ``T_layer``.

    Parameters
    ----------
    G : MultiDiGraph
        The model graph.
    theta : mapping of member id to 1-D array
        θ of the members, all of one length (one schema); a member missing here adds zeros.
    layer : int
        The tree layer (1: the process tree).

    Returns
    -------
    dict
        Member id to the accumulated vector of its descendants (a leaf gets zeros).
    """
    T = tree(G, layer)
    if not theta:
        dim = 0
    else:
        dim = len(next(iter(theta.values())))
    zero = np.zeros(dim)
    out: dict[str, np.ndarray] = {}
    # Children before parents: reverse topological order is the DFS post-order of the paper.
    for v in reversed(list(nx.topological_sort(T))):
        acc = zero.copy()
        for c in T.successors(v):
            acc += out[c] + np.asarray(theta.get(c, zero), dtype=float)
        out[v] = acc
    return out
