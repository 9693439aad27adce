"""How readable a drawn graph is: edge crossings and total edge length of straight-line edges.

The viewer draws every edge as a straight segment between its ends' positions, so these count
what a person sees (long edges routed around members are not drawn as such).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np

Pos = tuple[float, float]


def _segments(pos: Mapping[str, Pos], edges: Iterable[tuple[str, str]]) -> tuple[list, np.ndarray]:
    """Return the drawn pairs (each unordered pair once, sorted) and their segments (x0, y0, x1, y1)."""
    pairs = sorted({tuple(sorted((u, v))) for u, v in edges if u in pos and v in pos and u != v})
    seg = np.array([[*pos[u], *pos[v]] for u, v in pairs], dtype=float).reshape(-1, 4)
    return pairs, seg


def edge_crossings(pos: Mapping[str, Pos], edges: Iterable[tuple[str, str]]) -> int:
    """Return the number of pairs of edges whose straight segments cross.

    Edges sharing an end never count; segments that only touch or overlap collinearly do not
    count either (a proper crossing: each segment's ends lie strictly on both sides of the other).

    Parameters
    ----------
    pos : mapping
        Member -> (x, y).
    edges : iterable of (u, v)
        Drawn edges; both directions of a pair are one segment.
    """
    keys, s = _segments(pos, edges)
    if len(keys) < 2:
        return 0
    p, r = s[:, :2], s[:, 2:] - s[:, :2]
    total = 0
    for i in range(len(keys) - 1):
        # orientation of the other segments' ends relative to segment i, and vice versa
        q, d = p[i + 1:], r[i + 1:]
        o1 = np.sign(_cross(r[i], q - p[i]))
        o2 = np.sign(_cross(r[i], q + d - p[i]))
        o3 = np.sign(_cross_rows(d, p[i] - q))
        o4 = np.sign(_cross_rows(d, p[i] + r[i] - q))
        hit = (o1 * o2 < 0) & (o3 * o4 < 0)
        a, b = keys[i]
        shared = np.array([a in k or b in k for k in keys[i + 1:]])
        total += int(np.count_nonzero(hit & ~shared))
    return total


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[0] * b[:, 1] - a[1] * b[:, 0]


def _cross_rows(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]


def edge_length(pos: Mapping[str, Pos], edges: Iterable[tuple[str, str]]) -> float:
    """Return the summed Euclidean length of the edges' straight segments (each pair once)."""
    _, seg = _segments(pos, edges)
    return float(np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]).sum())
