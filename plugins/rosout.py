"""/rosout ERROR and FATAL lines, as alerts on the node that logged them."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.endpoints import named_topics, receives
from stream_viz.detect.startup import STARTUP_S, bring_up_note, hold_back, starting
from stream_viz.records import SEVERITY_RANK as RANK
from stream_viz.records import Alert

STAMP_SLACK_S = 1.0  # s a line may be stamped before the last call and still be on this clock
WAIT_S = 5.0  # longest a line waits for its node to be discovered (its bring-up judged then)


class Rosout(Plugin):
    """One alert per logging member and sample: its worst level (≥ ``min_level``), the count and
    the first line. Alerts whether or not the member is watched unless ``watched_only``.

    Lines a node logs in its process's first ``startup_s`` are its bring-up (waiting for a peer
    that is not up yet): no alert; a later alert of the node counts them. A line can come before
    its node is discovered (a node that complains as it starts): a line of a node never in the
    model waits until it is, at most ``WAIT_S``, so its process's start is known when judged.
    """

    name = "rosout"
    kinds = ("node",)
    settings: ClassVar[dict[str, Any]] = {"min_level": "error", "watched_only": False,
                                          "startup_s": STARTUP_S}

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        floor = RANK.get(s["min_level"], RANK["error"])
        seen: dict[str, list] = {}
        known = ctx.state.setdefault("known", set())  # nodes in the model at some time
        known.update(m for m in ctx.diff.added_members if m.startswith("node:"))
        waiting = ctx.state.get("waiting", [])  # (when first seen, line) of nodes not discovered yet
        ctx.state["waiting"] = []
        lines = [*waiting, *((ctx.t, e) for e in ctx.events if e.kind == "log")]
        for at, e in lines:
            if RANK.get(e.level, -1) < floor:
                continue
            if s["watched_only"] and e.member not in ctx.watch:
                continue
            if e.member not in known and ctx.t - at < WAIT_S:
                ctx.state["waiting"].append((at, e))
                continue
            if starting(ctx, e.member, e.t, s["startup_s"]):
                hold_back(ctx, e.member)
                continue
            seen.setdefault(e.member, []).append(e)
        # Lines came since the last call: a stamp far outside that is another computer's clock.
        prev = ctx.t - ctx.since_last_call()
        for member, evs in sorted(seen.items()):
            worst = max(evs, key=lambda e: RANK[e.level])
            more = f" (+{len(evs) - 1} more)" if len(evs) > 1 else ""
            more += bring_up_note(ctx, member)
            first = min(e.t for e in evs)
            began = {"since": first} if prev - STAMP_SLACK_S <= first <= ctx.t else {}
            named = _named_inputs(ctx, member, evs)
            yield ctx.alert(member, worst.level, f"logged {worst.level.upper()}: {evs[0].text}{more}",
                            symptom="log", lines=len(evs), **began, **({"names": named} if named else {}))


def _named_inputs(ctx: PluginContext, member: str, evs: list) -> list[str]:
    """The nodes ``member``'s lines name (the collector's ``nodes``) that it depends on: a
    publisher of a topic it reads, a server it calls. "Robot pose is 1.5 s old (amcl)" is about
    the localiser, whose silence may look healthy (it was deactivated): the RCA charges it. So are
    the publishers of a topic it reads that a line names (`named_topics`): "Rejecting
    /odometry/gps: position jump 400012 m" is about what its publisher sent — unless its QoS
    matches none of theirs (`receives`): "No point cloud on /lidar/points" is its own doing."""
    named = {n for e in evs for n in e.data.get("nodes", ()) if isinstance(n, str)} - {member}
    read = ctx.subscribed_topics(member)
    said = named_topics(" ".join(e.text for e in evs),
                        [t.removeprefix("topic:") for t in read if receives(ctx, member, t)],
                        member.removeprefix("node:").rsplit("/", 1)[0])
    named |= {p for t in said for p in ctx.publishers("topic:" + t)} - {member}
    if not named:
        return []
    inputs = {p for t in read for p in ctx.publishers(t)}
    return sorted(named & (inputs | set(ctx.called_servers(member))))
