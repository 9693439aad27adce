"""A graph view's plain arrays (`system_arrays` and the like) as Rerun's graph archetypes.

Rerun converts a Python list of edges one pair at a time; a two-column array, and numpy colours,
radii and positions, go over in bulk. The Arrow data logged is the same either way.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
import rerun as rr


def edge_array(edges: Sequence[tuple[str, str]]) -> np.ndarray:
    """Return ``edges`` (pairs of member ids) as an ``(n, 2)`` object array."""
    out = np.empty((len(edges), 2), dtype=object)
    if len(edges):
        out[:] = edges
    return out


def graph_archetypes(a: Mapping[str, Any], show_labels: bool) -> tuple[rr.GraphNodes, rr.GraphEdges]:
    """Return ``GraphNodes`` and directed ``GraphEdges`` of arrays ``a`` (``ids``, ``colors``,
    ``radii``, ``positions``, ``edges``; ``labels`` if present)."""
    n = len(a["ids"])
    nodes = rr.GraphNodes(a["ids"], labels=a.get("labels"),
                          colors=np.asarray(a["colors"], dtype=np.uint8).reshape(n, -1 if n else 3),
                          radii=np.asarray(a["radii"], dtype=np.float32),
                          positions=np.asarray(a["positions"], dtype=np.float32).reshape(n, 2),
                          show_labels=show_labels)
    return nodes, rr.GraphEdges(edge_array(a["edges"]), graph_type=rr.GraphType.Directed)
