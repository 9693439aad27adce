"""A topic's endpoints with their QoS, as the plugins read them from the model."""

from __future__ import annotations

import re

from stream_viz.detect.api import PluginContext
from stream_viz.model.qos import compatibility


def endpoints(ctx: PluginContext, topic: str) -> tuple[dict[str, list[dict]], dict[str, list[dict]]]:
    """Publisher and subscriber nodes of ``topic`` with their QoS dicts.

    From the topic attribute ``qos`` (one ``{"node", "role", "reliability", …}`` per endpoint, as
    the collector writes it), else the data-flow edge's ``qos``; a node with neither has none.
    """
    pubs: dict[str, list[dict]] = {u: [] for u in ctx.publishers(topic)}
    subs: dict[str, list[dict]] = {v: [] for v in ctx.subscribers(topic)}
    for q in ctx.attr(topic, "qos") or ():
        if not isinstance(q, dict):
            continue
        side = pubs if q.get("role") == "pub" else subs if q.get("role") == "sub" else None
        node = str(q.get("node", ""))
        member = node if node.startswith("node:") else f"node:{node}"
        if side is not None and member in side:
            side[member].append(q)
    for side, edge in ((pubs, lambda u: (u, topic)), (subs, lambda v: (topic, v))):
        for m in side:
            q = ctx.flow_edge(*edge(m)).get("qos")
            if not side[m] and isinstance(q, dict):
                side[m] = [q]
    return pubs, subs


def receives(ctx: PluginContext, node: str, topic: str) -> bool:
    """False when ``node``'s subscription to ``topic`` matches none of its publishers' QoS
    (`stream_viz.model.qos.compatibility` errs for every pair): it receives nothing. True when
    either side's QoS is unknown."""
    pubs, subs = endpoints(ctx, topic)
    mine, theirs = subs.get(node, []), [q for qs in pubs.values() for q in qs]
    return not (mine and theirs) or any(compatibility(p, q)[0] != "error" for p in theirs for q in mine)


def named_topics(text: str, topics: list[str], namespace: str) -> list[str]:
    """Return those of ``topics`` (full names) that ``text`` names: in full, or relative to
    ``namespace`` (the logging node's; in the root namespace only a relative name with a ``/``),
    as a whole name (not part of a longer one)."""
    out = []
    for t in topics:
        forms = [t]
        ns = namespace.rstrip("/") + "/"
        rel = t[len(ns):] if t.startswith(ns) else ""
        if "/" in rel or (rel and ns != "/"):  # a bare word of the root namespace ("scan") is any word
            forms.append(rel)
        if any(re.search(rf"(?<![\w/~]){re.escape(f)}(?![\w/])", text) for f in forms):
            out.append(t)
    return out
