"""Nodes whose process died uncleanly, restart loops, nodes marked not alive, nodes gone unseen."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any, ClassVar

from stream_viz.detect.api import Plugin, PluginContext
from stream_viz.detect.exits import (
    CleanExits,
    error_exits,
    exited_0,
    forget_clean_exits,
    killed,
    note_clean_exits,
)
from stream_viz.records import Alert, Event

AFTER_GOODBYE = ("after its nodes left the graph: an uncaught exception (its traceback is on its stderr), "
                 "or a stop its code does not catch")


class MemberGone(Plugin):
    """Alerts on a node's departure only when it is not a clean one, and on restart loops.

    * exit (error): the node's process ended while DDS still listed the node (the collector's
      ``still_listed``: a crash or a kill), or ended with an error after the node left the graph
      (a code other than 0 and the stop signals, no other process with nodes ending within 2 s:
      a Python node's uncaught exception; data ``after_goodbye``, said once those 2 s have
      passed, `stream_viz.detect.exits.error_exits`); a node that deregisters and then its
      process ends with code 0, with a stop signal or together with others left cleanly and
      raises nothing; a process without nodes raises nothing; so does a process that exited
      with code 0 (``exit_code`` in the event, where the collector reads exit codes), its
      nodes listed or not; data ``killed``: killed by a signal
      another process sends (SIGKILL, SIGTERM, SIGINT, SIGHUP: `stream_viz.detect.exits.killed`),
      which none of its inputs can have caused; data ``last_words`` (not when killed so): the
      node of the process that logged last as it died, its line and time (the collector's,
      `stream_viz.collect.last_words`), said in the text;
    * restart: the node runs in a new process. One restart is news only as a respawn (the node
      changed process between two samples, or its last process crashed): warn. A node that keeps
      reappearing is one symptom, ``restarted N times in M s`` over ``loop_window_s``: warn from
      2, error from ``loop_min``, fatal from ``loop_fatal`` restarts; all its alerts hold one
      episode for ``loop_window_s`` (``episode_hold_s``). A node that lived ``cycle_life_s`` in
      its process, left it cleanly and was away ``cycle_away_s`` before it came back ran its
      course (a tool an operator closes and opens again, a job run again): no restart;
    * not alive (error, every sample while it lasts): DDS lists the node, its process is gone —
      at once after an unclean exit seen, else once it lasted ``not_alive_s``: a process that
      ended before it was ever read may have ended cleanly (a one-shot job), and on a loaded
      computer its node's deregistration reaches the graph a sample or two later; never after
      an exit with code 0 (its nodes stay listed until their lease ends: no goodbye was sent);
    * left (``left_severity``): the node left the graph and its process cannot be seen (no
      pid): clean or not cannot be told. A node of a known process that leaves deregistered
      (destroyed on purpose, or its process is ending cleanly) and raises nothing; so does one
      listed for less than ``brief_s`` (a spawner, a CLI call, gone before its process was
      found): a node whose process died stays listed until its DDS lease ends (Fast DDS: 20 s),
      so one that left sooner deregistered.

    Alerts whether or not the member is watched unless ``watched_only``: a death is evidence,
    not an attribute to screen.
    """

    name = "member_gone"
    kinds = ("node", "process")
    settings: ClassVar[dict[str, Any]] = {
        "left_severity": "warn", "watched_only": False,
        "loop_window_s": 60.0, "loop_min": 3, "loop_fatal": 6,
        "cycle_life_s": 30.0, "cycle_away_s": 5.0, "brief_s": 10.0, "not_alive_s": 3.0,
    }

    def check(self, ctx: PluginContext) -> Iterator[Alert]:
        s = ctx.settings
        exited = ctx.state.setdefault("exited", set())  # nodes whose process end was seen
        crashed = ctx.state.setdefault("crashed", {})  # node -> when its process died uncleanly
        hold = {"episode_hold_s": s["loop_window_s"]}

        def ok(m: str) -> bool:
            return not s["watched_only"] or m in ctx.watch

        clean = ctx.state.setdefault("clean", {})  # exited with code 0, still listed
        note_clean_exits(ctx, clean)
        said: set[str] = set()
        for e in ctx.events:
            if e.kind != "exit":
                continue
            # Code 0 (when the collector can read codes): it ended on purpose, without the goodbye.
            unclean = set() if exited_0(e) else set(e.data.get("still_listed", ()))
            words = _last_words(e)
            text = f"process died: {e.text or 'exited'}{_said(words)}"
            for m in _exited_members(ctx, e):
                exited.add(m)
                if m not in unclean or m in said:
                    continue  # deregistered before its process ended: a clean exit
                crashed[m] = ctx.t
                if ok(m):
                    said.add(m)
                    yield ctx.alert(m, "error", text, symptom="exit", process=e.data.get("process", e.member),
                                    clean=False, killed=killed(e), **hold, **words)
        for e, left in error_exits(ctx.events, ctx.t, ctx.state.setdefault("error_exits", {})):
            words = _last_words(e)
            text = f"process died: {e.text or 'exited'}, {AFTER_GOODBYE}{_said(words)}"
            for m in left:
                if m in said or not ok(m):
                    continue
                crashed[m] = ctx.t
                said.add(m)
                yield ctx.alert(m, "error", text, symptom="exit", process=e.member, clean=False, killed=False,
                                after_goodbye=True, **hold, **words)
        for m, restarts, respawn in _restarts(ctx, crashed, clean):
            sev = _restart_severity(s, len(restarts), respawn)
            if sev is not None and ok(m):
                yield ctx.alert(m, sev, _restart_text(ctx, m, restarts), symptom="restart",
                                restarts=len(restarts), window_s=ctx.t - restarts[0], pid=ctx.attr(m, "pid"),
                                **hold)
        listed = _listed_since(ctx)
        for m in sorted(ctx.diff.removed_members):
            brief = ctx.t - listed.pop(m, float("-inf")) < s["brief_s"]
            if ctx.kind(m) == "node" and m not in exited and ok(m) and not _pid_known(ctx, m) and not brief:
                yield ctx.alert(m, s["left_severity"], "left the graph; its process is not visible here",
                                symptom="left")
        exited.difference_update(ctx.diff.added_members)  # back again: a later departure is news
        forget_clean_exits(ctx, clean)  # after the restarts: a new process ends its clean exit
        dead = ctx.state.get("dead_since", {})
        ctx.state["dead_since"] = dead = {m: dead.get(m, ctx.t) for m in ctx.members("node")
                                          if ctx.attr(m, "alive") is False}
        for m, since in dead.items():
            if m in said or m in clean or not ok(m):  # clean: its exited process, still listed
                continue
            if m not in crashed and ctx.t - since < s["not_alive_s"]:
                continue
            yield ctx.alert(m, "error", "not alive", symptom="not_alive", **hold)


def _listed_since(ctx: PluginContext) -> dict[str, float]:
    """When each node joined the graph (-inf for those listed at the monitor's first sample:
    they may have been listed long before), kept in the plugin state."""
    since = ctx.state.get("listed")
    if since is None:
        since = ctx.state["listed"] = dict.fromkeys(ctx.members("node"), float("-inf"))
    for m in ctx.diff.added_members:
        if ctx.kind(m) == "node":
            since.setdefault(m, ctx.t)
    return since


def _exited_members(ctx: PluginContext, e: Event) -> list[str]:
    """The nodes an ``exit`` event concerns: a process's nodes, or the node itself.

    The collector sends one exit event per node of the process and one for the process.
    """
    if ctx.kind(e.member) != "process":
        return [e.member]
    return sorted(set(ctx.nodes_of(e.member, by_pid=True)) | set(e.data.get("nodes", ())))


def _restarts(ctx: PluginContext, crashed: dict[str, float],
              clean: CleanExits) -> list[tuple[str, list[float], bool]]:
    """Return ``(node, its restart times within loop_window_s, respawn?)`` per node that started
    again in a new process since the last sample.

    A new process of a node shows as a new pid (the pid it was last seen with is kept for
    ``loop_window_s`` after it left, so a node that left cleanly and came back counts), or, while
    the old one is still listed (a crashed process stays in DDS until its lease ends, and its pid
    may stay on the name), as one more ``instances`` of the name; a new pid that follows such a
    rise is that same process, not another. ``respawn``: the collector saw the node change
    process between two samples, or its last process crashed.
    """
    window = ctx.settings["loop_window_s"]
    seen = ctx.state.setdefault("seen", {})  # node -> (pid, instances, last seen, seen with that pid since)
    pending = ctx.state.setdefault("pending", {})  # node -> times of rises whose pid is not seen yet
    times = ctx.state.setdefault("restarts", {})  # node -> restart times
    moved = {e.member for e in ctx.events if e.kind == "restart"}
    out = []
    for m in ctx.members("node"):
        pid, inst = ctx.attr(m, "pid"), ctx.attr(m, "instances", 1)
        inst = inst if isinstance(inst, int) else 1
        old = seen.get(m)
        keep = pid if pid is not None or old is None else old[0]
        seen[m] = (keep, inst, ctx.t, old[3] if old is not None and keep == old[0] else ctx.t)
        if old is None:
            continue
        waiting = [x for x in pending.get(m, ()) if ctx.t - x <= window]
        new_pid = m in moved or (pid is not None and old[0] is not None and pid != old[0])
        if new_pid and _ran_its_course(ctx, old, crashed.get(m), clean.get(m)):
            continue
        rises = 0 if m in ctx.diff.added_members else max(0, inst - old[1])
        if rises:
            waiting += [ctx.t] * (rises - new_pid)
            new = rises
        elif new_pid and waiting:
            waiting.pop(0)  # the process a rise of instances already counted
            new = 0
        else:
            new = int(new_pid)
        pending[m] = waiting
        if new:
            recent = [x for x in times.get(m, ()) if ctx.t - x <= window] + [ctx.t] * new
            times[m] = recent
            out.append((m, recent, m in moved or ctx.t - crashed.get(m, -window) <= window))
    for m in [m for m, (_, _, last, _) in seen.items() if ctx.t - last > window]:
        del seen[m]  # gone longer than a loop lasts: forget it
        times.pop(m, None)
        pending.pop(m, None)
    return out


def _ran_its_course(ctx: PluginContext, old: tuple, crashed_at: float | None,
                    clean_exit: tuple[int | None, float] | None = None) -> bool:
    """True when a node's last process held it for ``cycle_life_s`` until it left cleanly (no
    crash seen since) and the node was away for ``cycle_away_s`` before this new process: a
    clean end, not a loop (a crash loop's lives are short or end uncleanly). A process that
    exited with code 0 (``clean_exit``: its pid, when) ended its node then, though DDS listed
    the node until its lease ended."""
    s = ctx.settings
    pid, _, last, since = old
    if clean_exit is not None and clean_exit[0] == pid:
        last = min(last, clean_exit[1])
    clean = crashed_at is None or crashed_at < since
    return clean and last - since >= s["cycle_life_s"] and ctx.t - last >= s["cycle_away_s"]


def _restart_severity(s: dict[str, Any], n: int, respawn: bool) -> str | None:
    """warn for a respawn or a second restart, error from ``loop_min``, fatal from ``loop_fatal``."""
    if n >= s["loop_fatal"]:
        return "fatal"
    if n >= s["loop_min"]:
        return "error"
    return "warn" if n >= 2 or respawn else None


def _restart_text(ctx: PluginContext, node: str, restarts: list[float]) -> str:
    pid = ctx.attr(node, "pid")
    if len(restarts) == 1:
        return f"restarted: now in process {pid}"
    return f"restarted {len(restarts)} times in {ctx.t - restarts[0]:.0f} s (now in process {pid})"


def _last_words(e: Event) -> dict[str, Any]:
    """The exit's last words as alert data, unless another process killed it (the node's
    callback did not end it then)."""
    said = e.data.get("last_words")
    return {"last_words": said} if isinstance(said, dict) and not killed(e) else {}


def _said(words: dict[str, Any]) -> str:
    """The alert text's part for `_last_words`' data."""
    said = words.get("last_words")
    if not said:
        return ""
    node = str(said.get("node", "")).removeprefix("node:")
    return f"; its last words, {node}: \"{said.get('text', '')}\""


def _pid_known(ctx: PluginContext, node: str) -> bool:
    """True when the process ``node`` was last seen in is known (a local one).

    Its departure is then a clean one: had the process died with the node still listed, the
    collector would have said so in an exit event (and the node would be in ``exited``); so the
    node deregistered, and its process ended cleanly or runs on.
    """
    last = ctx.state.get("seen", {}).get(node)
    return last is not None and last[0] is not None
