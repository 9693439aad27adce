"""Structural trouble in the ROS graph: one name on two nodes, subscribers without a publisher.

Incompatible QoS has its own plugin, ``qos_compat``."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

import networkx as nx

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.records import Alert


class GraphAnomalies(Plugin):
    """Alerts on:

    * two nodes with one name (node attribute ``instances`` > 1, as the collector counts them): error;
    * a subscriber whose topic has had no publisher for ``grace_s``: warn on the subscriber. The
      grace starts again whenever many nodes appear in one sample (at least ``burst_min`` and
      ``burst_ratio`` of the nodes): a system still being discovered (bring-up, or the monitor
      attaching to 500 nodes) shows subscribers seconds before their publishers.

    A topic is checked when it or the subscriber is watched; topics in ``ignore_topics`` never.
    """

    name = "graph_anomalies"
    kinds = ("node", "topic")
    settings: ClassVar[dict[str, Any]] = {
        "grace_s": 5.0, "ignore_topics": [], "duplicates": True, "no_publisher": True,
        "recheck_s": 10.0, "burst_min": 5, "burst_ratio": 0.05,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        if s["duplicates"]:
            for node in ctx.watched("node"):
                n = ctx.attr(node, "instances", 1)
                if isinstance(n, int) and n > 1:
                    yield ctx.alert(node, "error", f"{n} nodes share this name", symptom="duplicate_name",
                                    instances=n)
        orphan_since = ctx.state.setdefault("orphan_since", {})
        if discovery_burst(ctx.graph, ctx.diff.added_members, s["burst_min"], s["burst_ratio"]):
            ctx.state["settled_from"] = ctx.t
        settled_from = ctx.state.get("settled_from", -float("inf"))
        orphans = set()
        for topic, orphan, subs in _analyse(ctx):
            if orphan and s["no_publisher"]:
                orphans.add(topic)
                since = max(orphan_since.setdefault(topic, ctx.t), settled_from)
                if ctx.t - since >= s["grace_s"]:
                    for v in subs:
                        yield ctx.alert(v, "warn", f"subscribes to {topic} which has had no publisher for "
                                        f"{ctx.t - since:.0f} s", symptom="no_publisher", topic=topic)
        for topic in set(orphan_since) - orphans:
            del orphan_since[topic]


def _analyse(ctx: PluginContext) -> list[tuple[str, bool, list[str]]]:
    """Per topic with watched subscribers: orphaned?, the subscribers.

    The structure only changes with the graph, so this is redone only when the diff or the
    watchlist changed, or every ``recheck_s``; cheap on 1,000 members.
    """
    cached = ctx.state.get("analysis")
    if cached is not None and not ctx.diff and cached[0] == ctx.watch and ctx.t < cached[1]:
        return cached[2]
    ignore = {t if t.startswith("topic:") else f"topic:{t}" for t in ctx.settings["ignore_topics"]}
    out = []
    for topic in ctx.members("topic"):
        if topic in ignore:
            continue
        pubs = ctx.publishers(topic)
        subs = [v for v in ctx.subscribers(topic) if topic in ctx.watch or v in ctx.watch]
        if not subs:
            continue
        out.append((topic, not pubs, subs))
    ctx.state["analysis"] = (ctx.watch, ctx.t + ctx.settings["recheck_s"], out)
    return out


def discovery_burst(G: nx.MultiDiGraph, added: Any, least: int, ratio: float) -> bool:
    """Return True if the ``added`` members hold at least ``least`` nodes and ``ratio`` of the
    nodes of ``G``: the graph is still being discovered."""
    n = sum(1 for m in added if str(m).startswith("node:"))
    if n < least:  # the usual sample: no need to count the graph's nodes
        return False
    return n >= ratio * sum(1 for _, kind in G.nodes(data="kind") if kind == "node")
