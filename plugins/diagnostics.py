"""/diagnostics statuses WARN, ERROR and STALE, as alerts on the node that reported them."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.records import SEVERITY_RANK as RANK
from stream_viz.records import Alert, Event

# DiagnosticStatus levels: OK=0, WARN=1, ERROR=2, STALE=3.
_BY_NUMBER = {0: "ok", 1: "warn", 2: "error", 3: "stale"}


def diag_level(event: Event) -> str:
    """Return ``ok``, ``warn``, ``error`` or ``stale`` for a ``diag`` event."""
    raw = event.data.get("level")
    if isinstance(raw, bytes) and len(raw) == 1:
        raw = raw[0]
    if isinstance(raw, int) and raw in _BY_NUMBER:
        return _BY_NUMBER[raw]
    if isinstance(raw, str) and raw.lower() in ("ok", "warn", "error", "stale"):
        return raw.lower()
    return {"info": "ok", "warn": "warn", "error": "error", "fatal": "error"}.get(event.level, "ok")


class Diagnostics(Plugin):
    """One alert per reporting member and sample: its worst status (WARN→warn, ERROR→error,
    STALE→``stale_severity``), the statuses named in the message.

    Event plugins alert whether or not the member is watched (``watched_only`` to change it):
    a reported fault is evidence, not an attribute to screen.
    """

    name = "diagnostics"
    kinds = ("node",)
    settings: ClassVar[dict[str, Any]] = {"stale_severity": "warn", "watched_only": False}

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        worst: dict[str, tuple[str, list[str]]] = {}
        for e in ctx.events:
            if e.kind != "diag" or (s["watched_only"] and e.member not in ctx.watch):
                continue
            level = diag_level(e)
            if level == "ok":
                continue
            sev = s["stale_severity"] if level == "stale" else level
            sev = sev if sev in RANK else "warn"
            member = _named_node(ctx, e) or e.member
            prev_sev, texts = worst.get(member, ("info", []))
            texts.append(f"{e.data.get('name', '')}: {level.upper()} {e.text}".strip())
            worst[member] = (sev if RANK[sev] > RANK[prev_sev] else prev_sev, texts)
        for member, (sev, texts) in sorted(worst.items()):
            more = f" (+{len(texts) - 3} more)" if len(texts) > 3 else ""
            yield ctx.alert(member, sev, "diagnostics " + "; ".join(texts[:3]) + more,
                            symptom="diagnostics", statuses=len(texts))


def _named_node(ctx: PluginContext, e: Event) -> str | None:
    """The node a status is about when its hardware_id or name is a node of the graph.

    An aggregator or monitor node often publishes the statuses of others: the fault is in the
    node the status names, not in the publisher.
    """
    for key in ("hardware_id", "name"):
        value = str(e.data.get(key, "") or "").strip()
        if not value:
            continue
        member = "node:" + (value if value.startswith("/") else "/" + value)
        if ctx.attr(member, "kind") == "node":
            return member
    return None
