"""Structural trouble in the ROS graph: one name on two nodes, subscribers without a publisher.

Incompatible QoS has its own plugin, ``qos_compat``."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

import networkx as nx

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.exits import error_exits, exited_0, forget_clean_exits, note_clean_exits
from stream_viz.records import Alert


class GraphAnomalies(Plugin):
    """Alerts on:

    * two nodes with one name (node attribute ``instances`` > 1, as the collector counts them) for
      ``duplicate_s``: error. Longer than a DDS lease (Fast DDS: 20 s): a node restarted by its
      launcher shows twice until its old instance's lease ends, when the old process ended
      without saying goodbye (the blind shuttle's operator console, relaunched);
    * a subscriber whose topic has had no publisher for ``grace_s``, when that is a fault: its
      publisher died uncleanly (its process ended while DDS listed it, or it was seen not alive).
      A topic whose publishers left cleanly (deregistered: a job done, a node destroyed on
      purpose, an on-demand publisher that comes and goes; not a process that then ended alone
      with an error) is healthy. So is, by default, a topic
      that never had a publisher: robots subscribe to what only an operator or a tool publishes
      (``/initialpose``, ``/joy``, a console that joins later); ``never_published`` alerts on
      those too (to find a remapping typo: nobody provides what it waits for). Warn on the
      subscriber.
      The grace starts again whenever many nodes appear in one sample (at least ``burst_min``
      and ``burst_ratio`` of the nodes): a system still being discovered (bring-up, or the
      monitor attaching to 500 nodes) shows subscribers seconds before their publishers.

    A topic is checked when it or the subscriber is watched; topics in ``ignore_topics`` never.
    """

    name = "graph_anomalies"
    kinds = ("node", "topic")
    settings: ClassVar[dict[str, Any]] = {
        "grace_s": 5.0, "ignore_topics": [], "duplicates": True, "duplicate_s": 25.0, "no_publisher": True,
        "never_published": False,
        "recheck_s": 10.0, "burst_min": 5, "burst_ratio": 0.05,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        if s["duplicates"]:
            twins = ctx.state.get("twins", {})  # node -> since when it has shown twice
            ctx.state["twins"] = twins = {
                node: twins.get(node, ctx.t) for node in ctx.watched("node")
                if isinstance(n := ctx.attr(node, "instances", 1), int) and n > 1}
            for node, since in twins.items():
                if ctx.t - since >= s["duplicate_s"]:
                    n = ctx.attr(node, "instances")
                    yield ctx.alert(node, "error", f"{n} nodes share this name (for {ctx.t - since:.0f} s)",
                                    symptom="duplicate_name", instances=n)
        orphan_since = ctx.state.setdefault("orphan_since", {})
        if discovery_burst(ctx.graph, ctx.diff.added_members, s["burst_min"], s["burst_ratio"]):
            ctx.state["settled_from"] = ctx.t
        settled_from = ctx.state.get("settled_from", -float("inf"))
        orphans = set()
        had, died = _publishers_seen(ctx)
        for topic, orphan, subs in _analyse(ctx):
            if orphan and s["no_publisher"]:
                orphans.add(topic)
                since = max(orphan_since.setdefault(topic, ctx.t), settled_from)
                why = orphan_fault(had.get(topic), died, s["never_published"])
                if why is not None and ctx.t - since >= s["grace_s"]:
                    for v in subs:
                        yield ctx.alert(v, "warn", f"subscribes to {topic} which has had no publisher for "
                                        f"{ctx.t - since:.0f} s{why}", symptom="no_publisher", topic=topic)
        for topic in set(orphan_since) - orphans:
            del orphan_since[topic]


def _publishers_seen(ctx: PluginContext) -> tuple[dict[str, list[str]], set[str]]:
    """Return topic → its publishers when it last had any, and the nodes seen to die uncleanly.

    A node died uncleanly when an ``exit`` event says its process ended while DDS still listed it,
    or it is marked ``alive=False``, unless its process exited with code 0 (``exit_code``), or
    its process ended alone with an error after it left (`error_exits`: a Python node's uncaught
    exception); it is forgiven when it appears again.
    """
    had = ctx.state.setdefault("had_publishers", {})
    died = ctx.state.setdefault("died", set())
    clean = ctx.state.setdefault("clean", {})  # exited with code 0, still listed
    died.difference_update(ctx.diff.added_members)
    for e in ctx.events:
        if e.kind == "exit" and not exited_0(e):
            died.update(e.data.get("still_listed", ()))
    for _, left in error_exits(ctx.events, ctx.t, ctx.state.setdefault("error_exits", {})):
        died.update(left)
    note_clean_exits(ctx, clean)
    forget_clean_exits(ctx, clean)
    died.update(m for m in ctx.members("node") if ctx.attr(m, "alive") is False and m not in clean)
    if ctx.diff or "had_publishers_at" not in ctx.state:  # publishers change only with the graph
        ctx.state["had_publishers_at"] = ctx.t
        for topic in ctx.members("topic"):
            pubs = ctx.publishers(topic)
            if pubs:
                had[topic] = pubs
        for topic in ctx.diff.removed_members & had.keys():
            del had[topic]  # gone with all its endpoints: a new one of that name starts afresh
    return had, died


def orphan_fault(had: list[str] | None, died: set[str], never: bool = False) -> str | None:
    """Why a topic without a publisher is a fault (a phrase for the alert), or None if it is not.

    ``had``: its publishers when it last had any (None: never since it was seen); ``died``: the
    nodes seen to die uncleanly; ``never``: a topic that never had a publisher is a fault. A topic
    whose publishers all left cleanly is not a fault.
    """
    if had is None:
        return "" if never else None
    dead = [p.removeprefix("node:") for p in had if p in died]
    return f" since its publisher {', '.join(dead)} died" if dead else None


def _analyse(ctx: PluginContext) -> list[tuple[str, bool, list[str]]]:
    """Per topic with watched subscribers: orphaned?, the subscribers.

    The structure only changes with the graph, so this is redone only when the diff or the
    watchlist changed, or every ``recheck_s``; cheap on 1,000 members.
    """
    def compute() -> list[tuple[str, bool, list[str]]]:
        ignore = ctx.topic_ids(ctx.settings["ignore_topics"])
        out = []
        for topic in ctx.members("topic"):
            subs = [v for v in ctx.subscribers(topic) if topic in ctx.watch or v in ctx.watch]
            if subs and topic not in ignore:
                out.append((topic, not ctx.publishers(topic), subs))
        return out

    return ctx.structural(compute, ctx.settings["recheck_s"])


def discovery_burst(G: nx.MultiDiGraph, added: Any, least: int, ratio: float) -> bool:
    """Return True if the ``added`` members hold at least ``least`` nodes and ``ratio`` of the
    nodes of ``G``: the graph is still being discovered."""
    n = sum(1 for m in added if str(m).startswith("node:"))
    if n < least:  # the usual sample: no need to count the graph's nodes
        return False
    return n >= ratio * sum(1 for _, kind in G.nodes(data="kind") if kind == "node")
