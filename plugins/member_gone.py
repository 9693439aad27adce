"""Nodes that left the graph, processes that died or restarted, nodes marked not alive."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.records import Alert


class MemberGone(Plugin):
    """Alerts when a process dies (``exit`` event: error on its node(s), and on the process when
    it has no node), restarts (``restart`` event: warn), a node leaves the graph without its
    process having been seen to exit (``left_severity``), or a node carries ``alive=False``
    (its process is gone while DDS still lists it: error, every sample while it lasts).

    Alerts whether or not the member is watched unless ``watched_only``: a death is evidence,
    not an attribute to screen.
    """

    name = "member_gone"
    kinds = ("node", "process")
    settings: ClassVar[dict[str, Any]] = {"left_severity": "warn", "watched_only": False}

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        exited = ctx.state.setdefault("exited", set())

        def ok(m: str) -> bool:
            return not ctx.settings["watched_only"] or m in ctx.watch

        said: set[str] = set()
        for e in ctx.events:
            if e.kind == "exit":
                for m in _exited_members(ctx, e):
                    exited.add(m)
                    if m in said or not ok(m):
                        continue
                    said.add(m)
                    sev = "error" if ctx.kind(m) == "node" else e.level
                    yield ctx.alert(m, sev, f"process died: {e.text or 'exited'}", symptom="exit",
                                    process=e.data.get("process", e.member),
                                    clean=not e.data.get("still_listed", ()))
            elif e.kind == "restart" and ok(e.member):
                yield ctx.alert(e.member, "warn", f"restarted: {e.text or 'new process'}", symptom="restart",
                                **e.data)
        for m in sorted(ctx.diff.removed_members):
            if ctx.kind(m) == "node" and m not in exited and ok(m):
                yield ctx.alert(m, ctx.settings["left_severity"], "left the graph", symptom="left")
        exited.difference_update(ctx.diff.added_members)  # back again: a later departure is news
        for m in ctx.members("node"):
            if ctx.attr(m, "alive") is False and m not in said and ok(m):
                yield ctx.alert(m, "error", "not alive", symptom="not_alive")


def _exited_members(ctx: PluginContext, e: Any) -> list[str]:
    """The members an ``exit`` event is reported on: a process's nodes, else the member itself.

    The collector sends one exit event per node of the process and one for the process.
    """
    if ctx.kind(e.member) != "process":
        return [e.member]
    nodes = set(ctx.nodes_of(e.member, by_pid=True)) | set(e.data.get("nodes", ()))
    return sorted(nodes) or [e.member]
