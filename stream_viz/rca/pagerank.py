"""Baseline: Personalized PageRank over the symptomatic part of the graph, as MicroRCA ranks.

The graph holds the symptomatic members (of ``M_j``) and the candidate nodes, with the causal
edges between them reversed (effect → cause), so random walks flow towards causes. The walk
restarts at a member in proportion to its alert relevance (count × severity). Only nodes are
ranked. The iteration is a sparse numpy power iteration with networkx's semantics (dangling mass
goes back to the personalization), because networkx's own ``pagerank`` needs scipy.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np

from stream_viz.rca.causal import causes, is_node
from stream_viz.rca.trajectories import Context, RootCause, _with_trajectories


def personalized_pagerank(
    nodes: list[str],
    edges: list[tuple[str, str, float]],
    personalization: Mapping[str, float],
    alpha: float = 0.85,
    max_iter: int = 100,
    tol: float = 1e-10,
) -> dict[str, float]:
    """Return the PageRank of ``nodes`` on the weighted directed ``edges`` ``(u, v, w)``.

    Same definition as ``networkx.pagerank(G, alpha, personalization, weight="weight")``:
    out-weights normalised per node, dangling nodes jump by the personalization vector, which
    is uniform when it sums to 0.
    """
    n = len(nodes)
    if n == 0:
        return {}
    idx = {m: i for i, m in enumerate(nodes)}
    p = np.array([max(0.0, float(personalization.get(m, 0.0))) for m in nodes])
    p = p / p.sum() if p.sum() > 0 else np.full(n, 1.0 / n)
    if edges:
        src = np.array([idx[u] for u, _, _ in edges])
        dst = np.array([idx[v] for _, v, _ in edges])
        w = np.array([w for _, _, w in edges], dtype=float)
    else:
        src = dst = np.zeros(0, dtype=int)
        w = np.zeros(0)
    out = np.bincount(src, weights=w, minlength=n)
    dangling = out == 0
    wn = np.divide(w, out[src], out=np.zeros_like(w), where=out[src] > 0)
    r = np.full(n, 1.0 / n)
    for _ in range(max_iter):
        prev = r
        flow = np.bincount(dst, weights=prev[src] * wn, minlength=n)
        r = alpha * (flow + prev[dangling].sum() * p) + (1.0 - alpha) * p
        if np.abs(r - prev).sum() < n * tol:
            break
    return {m: float(r[i]) for m, i in idx.items()}


def rank_pagerank(ctx: Context) -> list[RootCause]:
    """MicroRCA's ranking on the same symptoms, returned like the other rankers."""
    G, s = ctx.G, ctx.symptoms
    members = set(s.times) | set(ctx.views)
    edges = []
    for m in members:
        for c in causes(G, m):
            if c in members:
                edges.append((m, c, 1.0))  # reversed: effect → cause
    for n, v in ctx.views.items():  # charged symptoms: the topic points at its publisher
        for x in v.own:
            if x != n and not is_node(G, x):
                edges.append((x, n, 1.0))
    pers = {m: s.relevance.get(m, 0.0) for m in members}
    for n, v in ctx.views.items():
        pers[n] = pers.get(n, 0.0) + v.evidence
    pr = personalized_pagerank(sorted(members), sorted(set(edges)), pers, ctx.settings.pagerank_alpha)
    cands = [(pr[n], v.onset, n) for n, v in ctx.views.items()]
    top = max((x for x, _, _ in cands), default=0.0) or 1.0
    return _with_trajectories(ctx, [(x / top, o, n) for x, o, n in cands], "pagerank")
