"""Root-cause analysis: subgraph growth, symptom correlation, fault trajectories, baselines.

Pure functions over plain data (networkx graphs, numpy arrays, dataclasses); see docs/rca.md.
"""

from __future__ import annotations

from stream_viz.rca.engine import RcaEngine, RcaResult, analyze
from stream_viz.rca.episodes import Evidence
from stream_viz.rca.incidents import Incident
from stream_viz.rca.settings import RcaSettings
from stream_viz.rca.subgraph import Iteration, SubgraphState, grow, initial_state
from stream_viz.rca.trajectories import RootCause

__all__ = [
    "Evidence",
    "Incident",
    "Iteration",
    "RcaEngine",
    "RcaResult",
    "RcaSettings",
    "RootCause",
    "SubgraphState",
    "analyze",
    "grow",
    "initial_state",
]
