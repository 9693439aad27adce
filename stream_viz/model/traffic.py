"""When each topic carried messages: spans of time, kept by the shadow, read by the RCA.

A fault travels along a topic only while the topic carries messages: a teleop topic whose
joystick is never held, or a jog command sent once a session, carries nothing from a node that
dies while it is idle. Every sample, a topic whose collector window (``rate_hz`` over the last
``window`` seconds) holds a message was carrying over that window; consecutive windows make one
span. The spans sit in the seen graph's ``G.graph[TRAFFIC]`` (topic → list of (start, end)),
with an empty list for a topic measured and never seen carrying; a topic not measured has none.
"""

from __future__ import annotations

import math

import networkx as nx

from stream_viz.model.theta import SCHEMAS

TRAFFIC = "traffic"  # G.graph key: topic -> spans it carried messages in
SPANS_KEPT = 32  # per topic, the newest
RATE = SCHEMAS["topic"].index("rate_hz")


def note_traffic(spans: dict[str, list[tuple[float, float]]], G: nx.MultiDiGraph, t: float,
                 window: float) -> None:
    """Add the sample of ``G`` at ``t`` to ``spans`` (changed in place): a topic with a measured
    rate above 0 carried from ``t - window`` to ``t``; one measured at 0 gets its (empty) entry.

    Parameters
    ----------
    spans : dict
        Topic → spans so far, oldest first, at most `SPANS_KEPT` each.
    G : MultiDiGraph
        The live model at ``t`` (topics with θ).
    t : float
        The sample time.
    window : float
        The collector's rate window (s).
    """
    for m, a in G._node.items():  # the attribute dicts: every topic, every sample
        theta = a.get("theta")
        if theta is None or a.get("kind") != "topic":
            continue
        rate = float(theta[RATE])
        if math.isnan(rate):
            continue
        mine = spans.setdefault(m, [])
        if rate <= 0:
            continue
        lo = t - window
        if mine and mine[-1][1] >= lo:
            mine[-1] = (mine[-1][0], t)
        else:
            mine.append((lo, t))
            del mine[:-SPANS_KEPT]


def idle(G: nx.MultiDiGraph, topic: str, lo: float, hi: float) -> bool:
    """True when ``topic`` is known to have carried no message from ``lo`` to ``hi`` (it was
    measured, and none of its spans meets the interval); False when it carried one, or is not
    known (not measured, or a graph without `TRAFFIC`)."""
    spans = G.graph.get(TRAFFIC, {}).get(topic)
    if spans is None:
        return False
    return not any(a <= hi and b >= lo for a, b in spans)


def measured(G: nx.MultiDiGraph, topic: str) -> bool:
    """True when the traffic of ``topic`` is measured (its rate read): a change of what it carries
    would show on it."""
    return topic in G.graph.get(TRAFFIC, {})
