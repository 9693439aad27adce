"""Lifecycle transitions as the graph shows them: a message on a node's ``…/transition_event``."""

from __future__ import annotations

from collections.abc import Iterator

from stream_viz.detect.api import PluginContext


def transitions(ctx: PluginContext) -> Iterator[tuple[str, float]]:
    """Yield ``(node, time)`` of each lifecycle node's newest transition (its ``…/transition_event``
    topic's newest message, from its age), this sample; the topics are found once per graph."""
    topics = ctx.structural(lambda: [m for m in ctx.members("topic") if m.endswith("/transition_event")],
                            key="lifecycle")
    for topic in topics:
        age = ctx.value(topic, "age_s")
        if age == age:
            for node in ctx.publishers(topic):
                yield node, ctx.t - age
