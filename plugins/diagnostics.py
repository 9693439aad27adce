"""/diagnostics statuses WARN, ERROR and STALE, as alerts on the node each status is about."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.lifecycle import transitions
from stream_viz.detect.startup import STARTUP_S, standing, starting
from stream_viz.records import SEVERITY_RANK as RANK
from stream_viz.records import Alert, Event

INF = float("inf")
TRANSITION_GRACE_S = 2.0  # a status stops within this of its node's transition (a 1 Hz updater)
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
    """One alert per member a status is about and sample: its worst status (WARN→warn,
    ERROR→error, STALE→``stale_severity``), the statuses named in the message.

    The collector maps a status to a node by its name, then its hardware id, then its publisher
    (``mapped_by`` in the event, `stream_viz.collect.diagnostics`); ``hardware`` (a list of
    ``"<hardware id>=<node name>"``) maps the hardware ids the system does not tell, where the
    collector fell back to the publisher or to nothing. The alert says how it was mapped
    (``mapped_by`` of its worst status; each status's in ``statuses``).

    A WARN a status shows in its first ``learn_s`` seconds, and keeps, is its normal (a GPS
    without a fix indoors, a frequency check set too tight, an optional device unplugged: robots
    run with standing warnings): no alert while it stays WARN; a status that was OK then warns is
    news, as is any ERROR or STALE (``learn_s`` 0: every WARN alerts). A status that warned and
    went back to OK by itself warns again without an alert: its warning comes and goes. A new
    WARN counts once it has held ``warn_hold_s`` (robots warn for a while and recover by
    themselves: a tank or battery running low until refilled, a temperature peak); a STALE at
    once; an ERROR once the next message of its status says ERROR too, or none came within
    ``error_confirm_s`` (0: at once). An updater's frequency check reads ERROR ("no events") in
    the instant between its node being enabled and its first event, then WARN or OK: that is no
    fault, and a real one says ERROR again a period later.

    A status in its node's bring-up (the process's first ``startup_s``: a filter waiting for its
    first GPS fix, a driver opening its device) is not news, as `rosout`'s lines are not; one that
    holds alerts after it. So is a status of a node not discovered yet in the monitor's own first
    ``startup_s`` (mapped to nothing: monitor and robot started together). A STALE of a node
    whose lifecycle transition came as its statuses stopped (deactivated: its updater stops, and
    an aggregator says STALE) is the transition's.

    Event plugins alert whether or not the member is watched (``watched_only`` to change it):
    a reported fault is evidence, not an attribute to screen.
    """

    name = "diagnostics"
    kinds = ("node",)
    settings: ClassVar[dict[str, Any]] = {"stale_severity": "warn", "watched_only": False, "hardware": [],
                                          "learn_s": 10.0, "warn_hold_s": 60.0, "error_confirm_s": 3.0,
                                          "startup_s": STARTUP_S}

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        worst: dict[str, tuple[str, str, list[dict[str, Any]]]] = {}
        changed = _lifecycle(ctx)
        first = ctx.state.setdefault("first_t", ctx.t)  # the monitor's start: who says what not known yet
        live = ctx.state.setdefault("live", {})  # node -> when it last published a status of its own
        pending = ctx.state.setdefault("pending", {})  # status name -> its first ERROR, unconfirmed
        events = [e for e in ctx.events if e.kind == "diag"]
        for e in events:
            pending.pop(str(e.data.get("name", "")), None)  # a newer message of that status came
        for e in _unconfirmed(ctx, s["error_confirm_s"]) + events:
            level = diag_level(e)
            standing = _standing(ctx, e, level, s["learn_s"])  # every status: when it was first seen
            held = _warned_for(ctx, e, level)  # every status: how long it has been WARN
            began = _erred(ctx, e, level)  # every status: when its ERRORs began
            member, by = _mapped(ctx, e)
            if level != "stale" and e.data.get("publisher") == member:  # not an aggregator's copy
                live[member] = max(e.t, live.get(member, e.t))
            if level == "ok" or (level == "warn" and (standing or held < s["warn_hold_s"])):
                continue
            if began is not None and not _confirmed(ctx, e, began, s["error_confirm_s"]):
                continue
            if s["watched_only"] and member not in ctx.watch:
                continue
            if starting(ctx, member, e.t, s["startup_s"]) or (by == "none" and e.t - first < s["startup_s"]):
                continue  # its bring-up: waiting for a fix, a device, a peer (as rosout's lines)
            if level == "stale" and changed.get(member, -INF) >= live.get(member, INF) - TRANSITION_GRACE_S:
                continue  # deactivated as its statuses stopped: an aggregator's STALE is the transition's
            sev = s["stale_severity"] if level == "stale" else level
            sev = sev if sev in RANK else "warn"
            prev_sev, prev_by, statuses = worst.get(member, ("info", by, []))
            later = began is not None and began < e.t  # confirmed after its first ERROR
            statuses.append({"name": e.data.get("name", ""), "level": level, "text": e.text,
                             "mapped_by": by, **({"since": began} if later else {})})
            if RANK[sev] > RANK[prev_sev]:
                prev_sev, prev_by = sev, by
            worst[member] = (prev_sev, prev_by, statuses)
        for member, (sev, by, statuses) in sorted(worst.items()):
            texts = [st["text"] for st in statuses]  # the collector's "<name>: <LEVEL> <message>"
            more = f" (+{len(texts) - 3} more)" if len(texts) > 3 else ""
            # An ERROR confirmed a message later began with its first: the RCA's order of symptoms.
            began = [st["since"] for st in statuses if "since" in st]
            yield ctx.alert(member, sev, "diagnostics " + "; ".join(texts[:3]) + more + f" (mapped by {by})",
                            symptom="diagnostics", statuses=statuses, mapped_by=by,
                            **({"since": min(began)} if began and min(began) < ctx.t else {}))


def _erred(ctx: PluginContext, e: Event, level: str) -> float | None:
    """When ``e``'s status began its run of ERRORs (``e``'s own time for a first one); None when
    ``e`` is no ERROR, which ends the run. Called for every status message."""
    runs = ctx.state.setdefault("erred", {})  # status name -> when its ERRORs began
    name = str(e.data.get("name", ""))
    if level != "error":
        runs.pop(name, None)
        return None
    return runs.setdefault(name, e.t)


def _confirmed(ctx: PluginContext, e: Event, began: float, confirm_s: float) -> bool:
    """True when the ERROR ``e`` counts: an ERROR of its status came before it (``began``
    earlier), or it waited ``confirm_s`` with no newer message (`_unconfirmed`); else it waits."""
    pending = ctx.state["pending"]
    if confirm_s <= 0 or began < e.t or e.data.get("waited"):
        pending.pop(str(e.data.get("name", "")), None)  # its first, in this sample too
        return True
    pending[str(e.data.get("name", ""))] = e
    return False


def _unconfirmed(ctx: PluginContext, confirm_s: float) -> list[Event]:
    """The first ERRORs of statuses that said nothing more for ``confirm_s``: they count now."""
    pending: dict[str, Event] = ctx.state.get("pending", {})
    due = [n for n, e in pending.items() if ctx.t - e.t >= confirm_s]
    return [Event(ctx.t, e.kind, e.member, e.level, e.text, {**e.data, "waited": True})
            for e in (pending.pop(n) for n in due)]


def _lifecycle(ctx: PluginContext) -> dict[str, float]:
    """Node → the time of its newest lifecycle transition (a message on its ``…/transition_event``
    topic), kept across samples."""
    newest: dict[str, float] = ctx.state.setdefault("transitions", {})
    for node, at in transitions(ctx):
        newest[node] = max(at, newest.get(node, -INF))
    return newest


def _standing(ctx: PluginContext, e: Event, level: str, learn_s: float) -> bool:
    """True when a WARN is the normal of ``e``'s status: it warned within ``learn_s`` of when it was
    first seen, at any level (`standing`, per status name; called for every status), or its
    warning comes and goes."""
    name = str(e.data.get("name", ""))
    warned = standing(ctx.state, name, e.t, "warn" if level == "warn" else None, learn_s)
    return warned or _recurring(ctx, name, level)


def _warned_for(ctx: PluginContext, e: Event, level: str) -> float:
    """Seconds ``e``'s status has been WARN without a break (0 at its first WARN; -1 when not WARN)."""
    since = ctx.state.setdefault("warn_since", {})  # status name -> time its WARN began
    name = str(e.data.get("name", ""))
    if level != "warn":
        since.pop(name, None)
        return -1.0
    return e.t - since.setdefault(name, e.t)


def _recurring(ctx: PluginContext, name: str, level: str) -> bool:
    """True for a WARN of a status that warned before and went back to OK by itself: its warning
    comes and goes (a battery dipping under load, a busy link), a pattern of its own, shown once."""
    runs = ctx.state.setdefault("warn_runs", {})  # status name -> (warning now, recovered before)
    warning, recovered = runs.get(name, (False, False))
    if level == "warn":
        runs[name] = (True, recovered)
        return recovered
    runs[name] = (False, recovered or (warning and level == "ok"))
    return False


def _mapped(ctx: PluginContext, e: Event) -> tuple[str, str]:
    """The member a status is about and how it was mapped: the collector's mapping, unless it
    fell back to the publisher (or nothing) and the configured ``hardware`` table knows its id."""
    by = str(e.data.get("mapped_by") or "publisher")
    if by in ("publisher", "none"):
        hw = str(e.data.get("hardware_id", "") or "").strip()
        table = dict(item.partition("=")[::2] for item in ctx.settings["hardware"])
        target = table.get(hw, "").strip() if hw else ""
        if target:
            member = target if target.startswith("node:") else "node:" + ("/" + target.lstrip("/"))
            if ctx.attr(member, "kind") == "node":
                return member, "hardware_id"
    return e.member, by
