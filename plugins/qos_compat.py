"""Incompatible QoS between a topic's publishers and a subscription, as ros2doctor checks it.

ros2doctor's ``QoSCompatibilityCheck`` calls ``rclpy.qos.qos_check_compatible(pub, sub)`` for
every publisher/subscription pair of every topic, which is rmw's ``qos_profile_check_compatible``
(rmw_dds_common, Jazzy). `stream_viz.model.qos.compatibility` is the same rules on the
collector's plain QoS dicts (``stream_viz.collect.rosgraph.qos_dict``), with the same reasons:

errors (DDS will not match the two: the subscription receives nothing from that publisher)
  * best-effort publisher, reliable subscription;
  * volatile publisher, transient-local subscription;
  * the subscription has a deadline and the publisher none (unspecified), or a shorter one;
  * automatic liveliness publisher, manual-by-topic subscription;
  * the subscription has a liveliness lease duration and the publisher none, or a shorter one;

warnings, only without errors (the policy of an end is ``system_default`` or ``unknown``, so
compatibility cannot be told): reliability, durability, liveliness.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.endpoints import endpoints
from stream_viz.model.ids import name_of
from stream_viz.model.qos import compatibility
from stream_viz.records import Alert


class QosCompat(Plugin):
    """Alerts on a subscription whose QoS cannot match its topic's publishers (`compatibility`).

    On the subscriber node, ``error`` when it matches none of the publishers (it receives
    nothing: the misconfigured end is the cause of its silence), ``warn`` when it matches only
    some; the reasons and the publishers in the data. With ``warnings``, rmw's warnings (policies
    it cannot judge) are ``info`` alerts. A topic is checked when it or the subscriber is
    watched; topics in ``ignore_topics`` never. Rechecked when the graph, the watchlist or an
    endpoint's QoS (the graph's ``qos_version``: a subscription re-created with another QoS) changed,
    or every ``recheck_s`` (the QoS of new endpoints may come a sample late).
    """

    name = "qos_compat"
    kinds = ("node", "topic")
    settings: ClassVar[dict[str, Any]] = {"ignore_topics": [], "warnings": False, "recheck_s": 10.0}

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        for topic, sub, level, mismatched, total, reasons in _analyse(ctx):
            if level == "warning":
                if ctx.settings["warnings"]:
                    yield ctx.alert(sub, "info", f"QoS on {name_of(topic)} cannot be judged: "
                                    + "; ".join(reasons),
                                    symptom="qos_unknown", topic=topic, publishers=mismatched,
                                    reasons=reasons)
                continue
            nothing = len(mismatched) == total
            what = ("receives nothing" if nothing
                    else f"receives from {total - len(mismatched)} of {total} publishers")
            yield ctx.alert(sub, "error" if nothing else "warn",
                            f"QoS incompatible on {name_of(topic)}, {what}: " + "; ".join(reasons),
                            symptom="qos_incompatible", topic=topic, publishers=mismatched,
                            reasons=reasons, receives_nothing=nothing)


def _analyse(ctx: PluginContext) -> list[tuple[str, str, str, list[str], int, list[str]]]:
    """``(topic, subscriber, level, mismatched publishers, publishers, reasons)`` per subscriber
    with an error (or a warning), cached until the graph, the watchlist or a QoS changes."""
    def compute() -> list[tuple[str, str, str, list[str], int, list[str]]]:
        ignore = ctx.topic_ids(ctx.settings["ignore_topics"])
        topics = [t for t in ctx.members("topic") if t not in ignore]
        return [row for topic in topics for row in _mismatches(ctx, topic)]

    return ctx.structural(compute, ctx.settings["recheck_s"], token=ctx.graph.graph.get("qos_version"))


def _mismatches(ctx: PluginContext, topic: str) -> list[tuple[str, str, str, list[str], int, list[str]]]:
    """The rows of `_analyse` for one topic: its watched subscribers that some publisher cannot serve."""
    pubs, subs = endpoints(ctx, topic)
    out = []
    for sub in sorted(subs):
        if not (topic in ctx.watch or sub in ctx.watch) or not pubs:
            continue
        found: dict[str, list[tuple[str, list[str]]]] = {}
        for pub, pqs in pubs.items():
            for pq in pqs:
                for sq in subs[sub]:
                    level, why = compatibility(pq, sq)
                    if level != "ok":
                        found.setdefault(pub, []).append((level, why))
        errors = sorted(p for p, r in found.items() if any(lv == "error" for lv, _ in r))
        level = "error" if errors else "warning" if found else "ok"
        if level == "ok":
            continue
        chosen = errors or sorted(found)
        reasons = sorted({f"{p}: {w}" for p in chosen for lv, why in found[p] if lv == level for w in why})
        out.append((topic, sub, level, chosen, len(pubs), reasons))
    return out

